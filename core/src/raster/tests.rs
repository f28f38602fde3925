//! Unit tests of the rasterizer.
