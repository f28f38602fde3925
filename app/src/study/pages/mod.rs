//! The studies' pages: the tables, charts and index a run of `gast bench
//! quality` writes beside its numbers (drawn with [`crate::report`]'s charts).

mod fast;
pub mod focus;
pub mod geometry;
pub mod quality;
