//! The report of a benchmark run: what `gast bench quality` writes next to its
//! numbers so that a run can be judged at a glance: charts (SVG and PNG) and
//! the quality benchmark's folder of tables, renders and index.

mod axis;
pub mod chart;
mod fast;
pub mod focus;
pub mod geometry;
mod glyphs;
pub mod quality;
pub mod sheet;
