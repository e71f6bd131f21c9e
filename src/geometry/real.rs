//! The float type the geometry and the renderer are generic over, and the glam
//! vector that goes with it (`Vec3` for f32, `DVec3` for f64).

use glam::{DVec3, Vec3};
use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

pub trait Real: num_traits::Float + Debug + Default + Send + Sync + 'static {
    type Vec3: Vec3Ops<Self>;
    /// Half the distance from 1 to the next float: the unit roundoff of one operation.
    const UNIT_ROUNDOFF: Self;
    /// The largest `|f|²` the hit test computes in this precision, with `f`
    /// the ray's origin in the ellipsoid's unit-sphere frame (its distance
    /// from the centre in radii); beyond it the test runs in f64. See
    /// [`super::ellipsoid`] for why this bounds the test's error.
    const NEAR_FRAME: Self;
    /// Whether a hit point can be worth recomputing in f64 (false in f64 itself).
    const NARROW: bool;
    fn from_f64(x: f64) -> Self;
    fn to_f64(self) -> f64;
    /// The next float towards +∞ (−0 and +0 both step to the smallest positive).
    fn next_up(self) -> Self;
    fn next_down(self) -> Self;

    /// γ(n) = n·u / (1 − n·u): the bound on the relative error of n chained
    /// floating-point operations (Higham; pbrt-v4 §6.8).
    fn gamma(n: u32) -> Self {
        let nu = Self::from_f64(f64::from(n)) * Self::UNIT_ROUNDOFF;
        nu / (Self::one() - nu)
    }
}

/// The vector operations the geometry needs, with glam's own names.
pub trait Vec3Ops<R>:
    Copy
    + Debug
    + PartialEq
    + Send
    + Sync
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Mul<R, Output = Self>
    + Div<Output = Self>
    + Div<R, Output = Self>
    + Neg<Output = Self>
    + AddAssign
{
    const ZERO: Self;
    fn new(x: R, y: R, z: R) -> Self;
    fn from_dvec3(v: DVec3) -> Self;
    fn to_dvec3(self) -> DVec3;
    fn x(self) -> R;
    fn y(self) -> R;
    fn z(self) -> R;
    fn dot(self, other: Self) -> R;
    fn length_squared(self) -> R;
    fn length(self) -> R;
    fn normalize(self) -> Self;
    fn abs(self) -> Self;
    fn max_element(self) -> R;
    fn recip(self) -> Self;
    /// Applies `f` to each component.
    fn map(self, f: impl Fn(R) -> R) -> Self;
}

/// The vector type that goes with the float type `R`.
pub type V3<R> = <R as Real>::Vec3;

macro_rules! impl_real {
    ($float:ty, $vec:ty, $near_frame:expr, $narrow:expr) => {
        impl Real for $float {
            type Vec3 = $vec;
            const UNIT_ROUNDOFF: Self = <$float>::EPSILON * 0.5;
            const NEAR_FRAME: Self = $near_frame;
            const NARROW: bool = $narrow;
            #[inline]
            fn from_f64(x: f64) -> Self {
                x as $float
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline]
            fn next_up(self) -> Self {
                <$float>::next_up(self)
            }
            #[inline]
            fn next_down(self) -> Self {
                <$float>::next_down(self)
            }
        }

        impl Vec3Ops<$float> for $vec {
            const ZERO: Self = <$vec>::ZERO;
            #[inline]
            fn new(x: $float, y: $float, z: $float) -> Self {
                <$vec>::new(x, y, z)
            }
            #[inline]
            fn from_dvec3(v: DVec3) -> Self {
                <$vec>::new(v.x as $float, v.y as $float, v.z as $float)
            }
            #[inline]
            fn to_dvec3(self) -> DVec3 {
                DVec3::new(self.x as f64, self.y as f64, self.z as f64)
            }
            #[inline]
            fn x(self) -> $float {
                self.x
            }
            #[inline]
            fn y(self) -> $float {
                self.y
            }
            #[inline]
            fn z(self) -> $float {
                self.z
            }
            #[inline]
            fn dot(self, other: Self) -> $float {
                <$vec>::dot(self, other)
            }
            #[inline]
            fn length_squared(self) -> $float {
                <$vec>::length_squared(self)
            }
            #[inline]
            fn length(self) -> $float {
                <$vec>::length(self)
            }
            #[inline]
            fn normalize(self) -> Self {
                <$vec>::normalize(self)
            }
            #[inline]
            fn abs(self) -> Self {
                <$vec>::abs(self)
            }
            #[inline]
            fn max_element(self) -> $float {
                <$vec>::max_element(self)
            }
            #[inline]
            fn recip(self) -> Self {
                <$vec>::recip(self)
            }
            #[inline]
            fn map(self, f: impl Fn($float) -> $float) -> Self {
                <$vec>::new(f(self.x), f(self.y), f(self.z))
            }
        }
    };
}

impl_real!(f32, Vec3, (1u32 << 26) as f32, true);
impl_real!(f64, DVec3, f64::INFINITY, false);
