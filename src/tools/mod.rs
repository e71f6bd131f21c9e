//! Tools around the renderer: measurements and reports.

pub mod report;
