//! Tools around the renderer: the scene generator and the benchmark.

pub mod bench;
pub mod gen;
