//! The two rule sets the course's expected images were made with.
//!
//! The course handed out two sets of keys that disagree on three scenes
//! (testIllum, testImgPlane, testReflection). [`Rules::Default`] is the one
//! of the scene format (`docs/scene-format.md`) and reproduces the newer set
//! (`tests/fixtures/reference/classic/keys`). [`Rules::Ucla`] reproduces the
//! older set, which follows exactly two other rules and nothing else:
//!
//! 1. a surface hit from inside keeps its outward normal for lighting (no
//!    flip toward the ray): the far wall of a sphere cut by the near plane
//!    is lit by lights beyond it, as if seen from outside, and a light at
//!    the centre of a closed sphere gives N·L < 0 on its inside wall;
//! 2. reflected rays accept only hits with t > 1 along their unit
//!    direction, as eye rays do along theirs (t = 1 is the near plane).
//!
//! Everything else is shared. Rule 1 is applied once per hit, to the
//! normal the hit carries into shading; mirror directions and spawn offsets
//! do not depend on the normal's sign, so it changes only what reads N·L or
//! N·H (diffuse, the shadow rays it asks for, Blinn highlights; Phong's
//! R·V is the same either way). Refraction still bends about the normal
//! facing the ray, and a totally internally reflected ray is a refracted
//! ray: the older keys have no glass, so nothing there says otherwise.

use crate::geometry::{Real, SurfacePoint, V3};

/// Which of the course's two rule sets to render by.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Rules {
    /// The scene format's rules: the newer keys.
    #[default]
    Default,
    /// Outward normals inside, and reflected rays cut at t = 1: the older keys.
    Ucla,
}

impl Rules {
    /// `surface` (its normal facing the ray) with the normal shading reads.
    #[inline]
    pub(super) fn shading<R: Real>(self, surface: SurfacePoint<R>) -> SurfacePoint<R> {
        match self {
            Rules::Ucla if surface.inside => SurfacePoint {
                normal: -surface.normal,
                ..surface
            },
            _ => surface,
        }
    }

    /// The normal facing the ray at a `surface` made by [`Self::shading`],
    /// for refraction.
    #[inline]
    pub(super) fn facing_normal<R: Real>(self, surface: &SurfacePoint<R>) -> V3<R> {
        match self {
            Rules::Ucla if surface.inside => -surface.normal,
            _ => surface.normal,
        }
    }

    /// The t a reflected ray's hit must exceed, along its unit direction.
    #[inline]
    pub(super) fn reflection_t_min<R: Real>(self) -> R {
        match self {
            Rules::Default => R::zero(),
            Rules::Ucla => R::one(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn hit(inside: bool) -> SurfacePoint<f32> {
        SurfacePoint {
            point: Vec3::ZERO,
            normal: Vec3::Z,
            inside,
            error: Vec3::ZERO,
            refined: false,
        }
    }

    #[test]
    fn only_ucla_turns_an_inside_normal_back_outward() {
        assert_eq!(Rules::Default.shading(hit(true)).normal, Vec3::Z);
        assert_eq!(Rules::Ucla.shading(hit(true)).normal, Vec3::NEG_Z);
        assert_eq!(Rules::Ucla.shading(hit(false)).normal, Vec3::Z);
        for rules in [Rules::Default, Rules::Ucla] {
            for inside in [false, true] {
                let shading = rules.shading(hit(inside));
                assert_eq!(rules.facing_normal(&shading), Vec3::Z);
            }
        }
    }

    #[test]
    fn only_ucla_cuts_reflected_rays_at_one() {
        assert_eq!(Rules::Default.reflection_t_min::<f32>(), 0.0);
        assert_eq!(Rules::Ucla.reflection_t_min::<f64>(), 1.0);
    }
}
