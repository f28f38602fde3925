//! The differentiable tile-based CPU splat rasterizer.
