//! voxtrace: a fast, exact ray tracer for spheres and ellipsoids.
//!
//! Data flows one way: scene text → [`scene::Scene`] → an index
//! ([`index::SphereIndex`]) → [`render`] → [`output::Image`] → PNG/PPM, over
//! the command line ([`cli`]) or HTTP.

pub mod cli;
pub mod geometry;
pub mod index;
pub mod limits;
pub mod names;
pub mod output;
pub mod render;
pub mod rng;
pub mod scene;
pub mod service;
pub mod threads;
pub mod tools;
