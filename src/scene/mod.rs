//! The scene: its text format (two dialects), its model, and validation.
//!
//! `parse` turns text into a [`Scene`] or a [`SceneError`] that names the line
//! and column, refusing what the renderer cannot represent (`bounds`);
//! `read` does the same from a stream, within size limits; `write` turns a
//! scene back into classic text.

mod binary;
mod bounds;
mod builder;
mod decimal;
mod diagnostic;
mod error;
mod keyword;
mod lines;
mod parse;
mod read;
mod tokens;
mod write;

pub use diagnostic::Diagnostic;
pub use error::{Length, SceneError, SceneErrorKind};
pub use keyword::{COLUMNS_FIELD, ROWS_FIELD};
pub use lines::line_text;
pub use parse::{image_side, parse};
pub use read::{read, read_expecting, ReadError, TooLarge};
pub use write::{write_light, write_scene, write_sphere};

use glam::DVec3;

/// Which of the two known variants of the format a file is written in. The
/// dialect also picks the shading model (see `render::shading`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dialect {
    /// The course's original format: named SPHERE/LIGHT lines, Phong shading.
    Classic,
    /// The later browser variant: unnamed lines, Blinn shading blended by reflectivity.
    Browser,
}

/// The image plane at z = −near, spanning [left, right] × [bottom, top],
/// sampled by `width` × `height` pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub near: f64,
    pub left: f64,
    pub right: f64,
    pub bottom: f64,
    pub top: f64,
    pub width: u32,
    pub height: u32,
}

/// How a sphere's surface responds to light. Colours are linear RGB in [0, ∞).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub color: DVec3,
    pub ambient: f64,
    pub diffuse: f64,
    pub specular: f64,
    pub reflect: f64,
    /// The specular exponent `n`.
    pub shininess: f64,
    pub refract: f64,
    /// The ratio n₁/n₂ used when a ray enters the sphere; leaving uses its inverse.
    pub ior: f64,
}

/// The unit sphere scaled by `scale` (per axis, non-zero) then moved to `center`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    pub center: DVec3,
    pub scale: DVec3,
    pub material: Material,
}

impl Sphere {
    /// The radius of the smallest sphere around `center` that contains this ellipsoid.
    pub fn bounding_radius(&self) -> f64 {
        self.scale.abs().max_element()
    }
}

/// A point light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    pub position: DVec3,
    pub intensity: DVec3,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub dialect: Dialect,
    pub camera: Camera,
    pub spheres: Vec<Sphere>,
    pub lights: Vec<Light>,
    pub background: DVec3,
    pub ambient: DVec3,
    /// The OUTPUT file name, if the scene names one.
    pub output: Option<String>,
}
