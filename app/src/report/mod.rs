//! The report of a benchmark run: what `gast bench quality` writes next to its
//! numbers so that a run can be judged at a glance. For now only the charts.

mod axis;
pub mod chart;
mod glyphs;
