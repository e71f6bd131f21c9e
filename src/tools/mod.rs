//! Tools around the renderer: load generation, benchmarks, scene generation.

pub mod load;
