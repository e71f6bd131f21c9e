//! Tools around the renderer: scene generation, benchmarks, load generation, the accuracy report.

pub mod bench;
pub mod gen;
pub mod load;
pub mod report;
