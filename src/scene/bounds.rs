//! What the f32 fast path can represent, checked as the scene is parsed, so
//! that a scene it would draw wrongly is refused with the line and column
//! of the value at fault instead.
//!
//! Let Λ be the largest magnitude of any length of the scene (a coordinate
//! of a centre or a light, a scale, NEAR, LEFT, RIGHT, BOTTOM, TOP), σ the
//! smallest magnitude of a scale and ν = NEAR. Every point the renderer
//! computes (a hit point is C + S⊙n, |n| = 1) lies within 2Λ of the origin
//! on each axis, so every direction it builds between two of them (a ray to
//! a light, a shadow ray) has components of at most 4Λ; eye-ray directions
//! are camera values, reflected and refracted ones are unit vectors.
//! In f32 (largest value M ≈ 3.40e38, smallest normal m ≈ 1.18e-38):
//!
//! 1. Shading normalises such directions, which squares their length:
//!    3·(4Λ)² < M needs Λ < 2.7e18. Hence [`limits::MAX_LENGTH`] = 1e18.
//!    (Past it a light goes dark: its direction normalises to NaN.)
//! 2. The hit test (`geometry::ellipsoid`) maps a ray into the unit sphere's
//!    frame, `f = (o − C)/S`, `e = d/S`, and forms `a = e·e`, `b = f·e`,
//!    `c = f·f`. With components of f and e up to 4Λ/σ, these stay finite
//!    when 3·(4Λ/σ)² < M, i.e. Λ/σ < 2.7e18: [`limits::MAX_LENGTH_RATIO`]
//!    = 1e18 between any length and the thinnest scale. For a unit direction
//!    the same bound reads 3/σ² < M, σ > 9.4e-20, and so does the normal's
//!    `normalize(n/S)`: [`limits::MIN_SCALE`] = 1e-18. (`a·(1 − |l|²)` may
//!    still overflow for a ray that misses by far, to −∞, which is a miss.)
//! 3. `a` must stay a normal float, or `b/a` and the roots lose their bits
//!    and the sphere vanishes: (|d|/s)² ≥ m for the widest scale s. Eye rays
//!    have |d| ≥ ν, so s/ν < 9.2e18, checked against the same ratio 1e18;
//!    unit directions give s < 9.2e18, within [`limits::MAX_LENGTH`].
//! 4. Rounding leaves f off by about u·|f| (u = 2⁻²⁴) along the ray; the two
//!    projections that find the closest approach `l` cut that to about
//!    u²·|f|. Across an ellipsoid whose axes differ by a factor r, |f| in the
//!    thin axis's units is about r times its size in the others, so past
//!    r ≈ 1/u² = 2.8e14 nothing of the thin axis is left. Measured against
//!    f64 with the test in f32 throughout, a plate rendered the same up to
//!    r = 1e13 and not from 1e14 on: [`limits::MAX_AXIS_RATIO`] = 1e12 keeps
//!    a factor 100. (The hit test now runs in f64 where `|f|` is large,
//!    which such a plate's is; the bound still guards the f32 shading.)

use super::error::Length;
use super::{SceneError, SceneErrorKind};
use crate::limits;

/// A length and where in the text it was given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Located {
    pub length: Length,
    pub column: usize,
}

impl Located {
    fn magnitude(&self) -> f64 {
        self.length.value.abs()
    }
}

/// The lengths of a stretch of text that the scene-wide checks compare, each
/// the first of its magnitude, so that merging in file order blames the
/// same value as one pass over the file would.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Extremes {
    longest: Option<Located>,
    thinnest: Option<Located>,
    widest: Option<Located>,
}

/// Puts the value `at` builds in `slot` if its magnitude is larger (or, with
/// `smaller`, smaller) than the kept one's; never on a tie, so that the
/// first of equal values is kept.
#[inline(always)]
fn keep(slot: &mut Option<Located>, magnitude: f64, at: impl FnOnce() -> Located, smaller: bool) {
    let better = match slot {
        None => true,
        Some(old) if smaller => magnitude < old.magnitude(),
        Some(old) => magnitude > old.magnitude(),
    };
    if better {
        *slot = Some(at());
    }
}

impl Extremes {
    /// Counts a coordinate or camera value; `at` says where it was given.
    #[inline]
    pub fn length(&mut self, value: f64, at: impl FnOnce() -> Located) {
        keep(&mut self.longest, value.abs(), at, false);
    }

    /// Counts a scale, which is a length too.
    #[inline]
    pub fn scale(&mut self, value: f64, at: impl Fn() -> Located) {
        let magnitude = value.abs();
        keep(&mut self.longest, magnitude, &at, false);
        keep(&mut self.thinnest, magnitude, &at, true);
        keep(&mut self.widest, magnitude, &at, false);
    }

    /// Adds the extremes of text that follows this one's.
    pub fn merge(&mut self, later: &Extremes) {
        for (slot, new, smaller) in [
            (&mut self.longest, later.longest, false),
            (&mut self.thinnest, later.thinnest, true),
            (&mut self.widest, later.widest, false),
        ] {
            if let Some(new) = new {
                keep(slot, new.magnitude(), || new, smaller);
            }
        }
    }

    /// The scene-wide ratios (items 2 and 3 above), once the whole scene is
    /// read; `near` is NEAR's value and place.
    pub fn check(&self, near: Located) -> Result<(), SceneError> {
        if let (Some(longest), Some(thinnest)) = (self.longest, self.thinnest) {
            check_ratio(thinnest, longest)?;
        }
        if let Some(widest) = self.widest {
            check_ratio(near, widest)?;
        }
        Ok(())
    }
}

/// `large` may be at most [`limits::MAX_LENGTH_RATIO`] times `small`; the
/// error points at whichever of the two the text gives last.
fn check_ratio(small: Located, large: Located) -> Result<(), SceneError> {
    if large.magnitude() <= small.magnitude() * limits::MAX_LENGTH_RATIO {
        return Ok(());
    }
    let at = if (large.length.line, large.column) > (small.length.line, small.column) {
        large
    } else {
        small
    };
    Err(SceneError {
        line: at.length.line,
        column: at.column,
        kind: SceneErrorKind::LengthRatio {
            small: small.length,
            large: large.length,
        },
    })
}

/// A coordinate or camera value (item 1).
pub(super) fn check_length(field: &'static str, value: f64) -> Result<(), SceneErrorKind> {
    if value.abs() > limits::MAX_LENGTH {
        return Err(SceneErrorKind::TooLong { field, value });
    }
    Ok(())
}

/// A non-zero scale (items 1 and 2).
pub(super) fn check_scale(field: &'static str, value: f64) -> Result<(), SceneErrorKind> {
    check_length(field, value)?;
    if value.abs() < limits::MIN_SCALE {
        return Err(SceneErrorKind::TooThin { field, value });
    }
    Ok(())
}

/// One ellipsoid's three scales, each with its field and byte offset
/// (item 4); the error names the thinnest axis, at its offset.
pub(super) fn check_axes(
    axes: [(f64, &'static str, usize); 3],
) -> Result<(), (usize, SceneErrorKind)> {
    let by_size =
        |a: &&(f64, &str, usize), b: &&(f64, &str, usize)| a.0.abs().total_cmp(&b.0.abs());
    // The first of equal axes: `max_by` keeps the last, so it runs backwards.
    let (Some(thin), Some(wide)) = (
        axes.iter().min_by(by_size),
        axes.iter().rev().max_by(by_size),
    ) else {
        return Ok(());
    };
    if wide.0.abs() <= thin.0.abs() * limits::MAX_AXIS_RATIO {
        return Ok(());
    }
    Err((
        thin.2,
        SceneErrorKind::AxisRatio {
            thin_field: thin.1,
            thin: thin.0,
            wide_field: wide.1,
            wide: wide.0,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(value: f64, line: usize, column: usize) -> Located {
        Located {
            length: Length {
                field: "<x>",
                value,
                line,
            },
            column,
        }
    }

    #[test]
    fn single_values_are_checked_against_the_f32_bounds() {
        assert!(check_length("<x>", -1e18).is_ok());
        assert!(matches!(
            check_length("<x>", -1.0001e18),
            Err(SceneErrorKind::TooLong { value, .. }) if value == -1.0001e18
        ));
        assert!(check_scale("<s>", -1e-18).is_ok());
        assert!(matches!(
            check_scale("<s>", 9e-19),
            Err(SceneErrorKind::TooThin { .. })
        ));
        assert!(matches!(
            check_scale("<s>", 2e18),
            Err(SceneErrorKind::TooLong { .. })
        ));
    }

    #[test]
    fn axis_ratio_blames_the_thinnest_axis() {
        assert!(check_axes([(2.0, "x", 1), (2e-12, "y", 5), (2.0, "z", 9)]).is_ok());
        let (column, kind) =
            check_axes([(2.0, "x", 1), (1.0, "y", 5), (-1e-12, "z", 9)]).unwrap_err();
        assert_eq!(column, 9);
        assert!(matches!(
            kind,
            SceneErrorKind::AxisRatio {
                thin_field: "z",
                wide_field: "x",
                ..
            }
        ));
    }

    #[test]
    fn ratios_blame_the_value_given_last_and_ties_keep_the_first() {
        let mut early = Extremes::default();
        early.scale(1e-6, || at(1e-6, 3, 20));
        early.scale(-1e-6, || at(-1e-6, 4, 20));
        let mut late = Extremes::default();
        late.length(-2e12, || at(-2e12, 9, 12));
        let near = at(1.0, 1, 6);
        assert!(early.check(near).is_ok());
        early.merge(&late);
        let e = early.check(near).unwrap_err();
        assert_eq!((e.line, e.column), (9, 12));
        assert!(matches!(
            e.kind,
            SceneErrorKind::LengthRatio { small, large } if small.line == 3 && large.value == -2e12
        ));
        // The widest scale against NEAR, NEAR given last.
        let mut wide = Extremes::default();
        wide.scale(1e9, || at(1e9, 2, 30));
        let e = wide.check(at(1e-10, 5, 6)).unwrap_err();
        assert_eq!((e.line, e.column), (5, 6));
    }
}
