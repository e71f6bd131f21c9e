//! Tools around the renderer: scene generation, benchmarks, load generation.

pub mod bench;
pub mod gen;
pub mod load;
