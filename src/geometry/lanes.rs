//! The hit test of [`super::ellipsoid`] for [`LANES`] rays at once.
//!
//! An index that traces neighbouring rays together tests one sphere against
//! all of them: the rays' components sit in one array per axis, and a loop
//! over the lanes that indexes those arrays in step is what the compiler
//! turns into SIMD. Each lane computes exactly the operations of
//! [`UnitSphereFrame::intersect`], in the same order (Rust does not contract
//! `a·b + c` into a fused multiply-add), so every lane rounds exactly as the
//! one-ray test does; a lane whose ray starts beyond [`Real::NEAR_FRAME`]
//! radii runs the one-ray f64 test, as `intersect` itself would. The tests
//! below check the bits agree at random extreme scales.
//!
//! Two shapes of bundle: rays from one origin (eye rays), where the origin's
//! frame coordinates are shared by every lane, and segments with origins of
//! their own (shadow rays toward one light).

use super::{Ray, Real, UnitSphereFrame, Vec3Ops, V3};

/// Rays per bundle: a 4×4 tile of pixels. Wider, each test would spend more
/// lanes on rays that miss.
pub const LANES: usize = 16;

/// One value per lane, per axis.
pub type LaneVectors<R> = [[R; LANES]; 3];

/// [`UnitSphereFrame::intersect`] of the rays `origin + t·dir[i]`, lane `i`
/// within (t_min, cap\[i\]): each lane's t, or NaN where it misses.
#[inline(always)]
pub fn hits_from_one_origin<R: Real>(
    frame: &UnitSphereFrame<R>,
    origin: V3<R>,
    dir: &LaneVectors<R>,
    t_min: R,
    cap: &[R; LANES],
) -> [R; LANES] {
    // The origin is shared, so `f` and `c` are the same for every lane.
    let f = (origin - frame.center) * frame.inv_scale;
    let ff = f.dot(f);
    let mut found = [R::nan(); LANES];
    if ff > R::NEAR_FRAME {
        wide_lanes(frame, origin, dir, t_min, cap, &mut found);
    } else {
        let (f, c) = ([f.x(), f.y(), f.z()], ff - R::one());
        near_lanes(frame, |_| (f, c), dir, t_min, cap, &mut found);
    }
    found
}

/// [`UnitSphereFrame::intersect_wide`] lane by lane, for rays from one
/// origin: the origin's frame coordinates in f64 are found once for all
/// the lanes, and every lane asks the miss filters before the few they let
/// pass run the whole test (which asks them again: cheaper than carrying
/// each lane's `e`, `a` and `b` from the first pass). Out of line, as the
/// one-ray f64 test is: it is for spheres seen from thousands of radii away.
#[inline(never)]
fn wide_lanes<R: Real>(
    frame: &UnitSphereFrame<R>,
    origin: V3<R>,
    dir: &LaneVectors<R>,
    t_min: R,
    cap: &[R; LANES],
    found: &mut [R; LANES],
) {
    let (f, f_squared) = frame.wide_origin(origin);
    let mut open = 0u32;
    for i in 0..LANES {
        open |= u32::from(frame.wide_filters_pass(f, f_squared, lane(dir, i), t_min)) << i;
    }
    while open != 0 {
        let i = open.trailing_zeros() as usize;
        open &= open - 1;
        found[i] = frame
            .intersect_wide_from(f, f_squared, lane(dir, i), t_min, cap[i])
            .unwrap_or(R::nan());
    }
}

/// Which of the segments `origin[i] + t·dir[i]`, t in (0, 1), meet the
/// ellipsoid: [`UnitSphereFrame::intersect`] with `(0, 1)` lane by lane, one
/// bit per lane.
#[inline(always)]
pub fn segments_hit<R: Real>(
    frame: &UnitSphereFrame<R>,
    origin: &LaneVectors<R>,
    dir: &LaneVectors<R>,
) -> u32 {
    let mut f = [[R::zero(); LANES]; 3];
    let mut c = [R::zero(); LANES];
    let mut wide = 0u32;
    frame_origins(frame, origin, &mut f, &mut c, &mut wide);
    let mut found = [R::nan(); LANES];
    let lane_origin = |i: usize| ([f[0][i], f[1][i], f[2][i]], c[i]);
    near_lanes(
        frame,
        lane_origin,
        dir,
        R::zero(),
        &[R::one(); LANES],
        &mut found,
    );
    let mut hit = 0u32;
    for (i, t) in found.iter().enumerate() {
        // NaN (a miss) is not below 1.
        hit |= u32::from(*t < R::one()) << i;
    }
    // The lanes beyond the near frame take the one-ray f64 test instead.
    hit &= !wide;
    let mut far = wide;
    while far != 0 {
        let i = far.trailing_zeros() as usize;
        far &= far - 1;
        let ray = Ray::new(lane(origin, i), lane(dir, i));
        hit |= u32::from(frame.intersect_wide(&ray, R::zero(), R::one()).is_some()) << i;
    }
    hit
}

/// Lane `i` of `v` as a vector.
#[inline(always)]
fn lane<R: Real>(v: &LaneVectors<R>, i: usize) -> V3<R> {
    V3::<R>::new(v[0][i], v[1][i], v[2][i])
}

/// Each lane's origin in the frame, `f = (o − C)/S`, and `c = f·f − 1`;
/// `wide` gets the lanes whose `f·f` is beyond [`Real::NEAR_FRAME`].
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn frame_origins<R: Real>(
    frame: &UnitSphereFrame<R>,
    origin: &LaneVectors<R>,
    f: &mut LaneVectors<R>,
    c: &mut [R; LANES],
    wide: &mut u32,
) {
    let (cx, cy, cz) = (frame.center.x(), frame.center.y(), frame.center.z());
    let s = frame.inv_scale;
    let (sx, sy, sz) = (s.x(), s.y(), s.z());
    for i in 0..LANES {
        let (fx, fy, fz) = (
            (origin[0][i] - cx) * sx,
            (origin[1][i] - cy) * sy,
            (origin[2][i] - cz) * sz,
        );
        let ff = fx * fx + fy * fy + fz * fz;
        (f[0][i], f[1][i], f[2][i]) = (fx, fy, fz);
        c[i] = ff - R::one();
        *wide |= u32::from(ff > R::NEAR_FRAME) << i;
    }
}

/// The near-frame test of every lane, given lane i's frame origin `f` and
/// `c = f·f − 1` as `origin(i)` (a constant for rays from one origin): the
/// nearer root in (t_min, cap\[i\]), else the farther, else NaN.
// The lane loops index several arrays in step, which is what the compiler
// turns into SIMD.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn near_lanes<R: Real>(
    frame: &UnitSphereFrame<R>,
    origin: impl Fn(usize) -> ([R; 3], R),
    dir: &LaneVectors<R>,
    t_min: R,
    cap: &[R; LANES],
    found: &mut [R; LANES],
) {
    let s = frame.inv_scale;
    let (sx, sy, sz) = (s.x(), s.y(), s.z());
    for i in 0..LANES {
        let (f, c) = origin(i);
        let e = [dir[0][i] * sx, dir[1][i] * sy, dir[2][i] * sz];
        found[i] = near_hit(f, c, e, t_min, cap[i]);
    }
}

/// One lane of [`near_lanes`]: the operations of the one-ray test, in its
/// order, for the frame origin `f`, `c = f·f − 1` and frame direction `e`.
#[inline(always)]
fn near_hit<R: Real>(f: [R; 3], c: R, e: [R; 3], t_min: R, cap: R) -> R {
    let ([fx, fy, fz], [ex, ey, ez]) = (f, e);
    // a = e·e, b = f·e, and the closest approach l, projected twice.
    let a = ex * ex + ey * ey + ez * ez;
    let b = fx * ex + fy * ey + fz * ez;
    let k = b / a;
    let (lx, ly, lz) = (fx - ex * k, fy - ey * k, fz - ez * k);
    let k = (lx * ex + ly * ey + lz * ez) / a;
    let (lx, ly, lz) = (lx - ex * k, ly - ey * k, lz - ez * k);
    let disc = a * (R::one() - (lx * lx + ly * ly + lz * lz));
    // The roots c/q and q/a, nearer first.
    let q = -(b + disc.sqrt().copysign(b));
    let (t0, t1) = (c / q, q / a);
    let (near, far) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
    let t = if near > t_min && near < cap {
        near
    } else if far > t_min && far < cap {
        far
    } else {
        R::nan()
    };
    // A NaN or negative discriminant: the line misses.
    if disc >= R::zero() {
        t
    } else {
        R::nan()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Ellipsoid;
    use glam::Vec3;
    use proptest::prelude::*;

    /// A value log-uniform in 10^[lo, hi], from a unit in [0, 1].
    fn decades(unit: f64, lo: f64, hi: f64) -> f32 {
        10f64.powf(lo + (hi - lo) * unit) as f32
    }

    /// An ellipsoid of size 10^[−4, 4] (axes up to 100:1) up to 10⁵ sizes
    /// from the origin, and sixteen rays aimed near it from points between
    /// inside it and 10⁹ sizes away: rays on both sides of the near frame,
    /// grazing, from inside, and missing.
    fn bundle(seed: [f64; 16]) -> (Ellipsoid<f32>, Vec3, LaneVectors<f32>, LaneVectors<f32>) {
        let size = decades(seed[0], -4.0, 4.0);
        let axes = Vec3::new(
            1.0,
            decades(seed[1], -2.0, 0.0),
            decades(seed[2], -1.0, 0.0),
        );
        let centre = Vec3::new(seed[3] as f32 - 0.5, seed[4] as f32 - 0.5, 1.0)
            * size
            * decades(seed[5], -1.0, 5.0);
        let shape = Ellipsoid::new(centre, axes * size);
        let away = Vec3::new(seed[6] as f32 - 0.5, seed[7] as f32 - 0.5, 1.0).normalize();
        let start = centre + away * size * decades(seed[8], -1.0, 9.0);
        let (mut origin, mut dir) = ([[0.0; LANES]; 3], [[0.0; LANES]; 3]);
        for i in 0..LANES {
            // Origins spread around `start`, aims spread around the rim.
            let spread = decades(seed[9], -3.0, 1.0) * size;
            let jitter = |k: usize| ((i * 7 + k * 3) % 11) as f32 / 5.0 - 1.0;
            let o = start + Vec3::new(jitter(0), jitter(1), jitter(2)) * spread;
            let rim = decades(seed[10], -2.0, 0.5) * size;
            let aim = centre + Vec3::new(jitter(1), jitter(2), jitter(0)) * rim * 1.2;
            // Segments ending before, at or past the ellipsoid.
            let reach = [0.5, 1.0, 2.0, 1e3][(i + (seed[11] * 4.0) as usize) % 4];
            let d = (aim - o) * reach;
            for axis in 0..3 {
                origin[axis][i] = o[axis];
                dir[axis][i] = d[axis];
            }
        }
        (shape, start, origin, dir)
    }

    fn seeds() -> impl Strategy<Value = [f64; 16]> {
        proptest::array::uniform16(0.0..1.0f64)
    }

    /// Whether this CPU runs the lane tests compiled with AVX2, as the
    /// grid's wider kernels inline them (`index::grid::vectors`).
    #[cfg(target_arch = "x86_64")]
    fn has_avx2() -> bool {
        std::arch::is_x86_feature_detected!("avx2")
    }

    /// [`hits_from_one_origin`] compiled with AVX2 (it is inlined here).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn hits_from_one_origin_avx2(
        frame: &UnitSphereFrame<f32>,
        origin: V3<f32>,
        dir: &LaneVectors<f32>,
        t_min: f32,
        cap: &[f32; LANES],
    ) -> [f32; LANES] {
        hits_from_one_origin(frame, origin, dir, t_min, cap)
    }

    /// [`segments_hit`] compiled with AVX2 (it is inlined here).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn segments_hit_avx2(
        frame: &UnitSphereFrame<f32>,
        origin: &LaneVectors<f32>,
        dir: &LaneVectors<f32>,
    ) -> u32 {
        segments_hit(frame, origin, dir)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        /// Rays from one origin: every lane's t has the bits of the one-ray test's.
        #[test]
        fn shared_origin_lanes_equal_the_one_ray_test(seed in seeds(), t_min in -1.0..2.0f32) {
            let (shape, start, _, dir) = bundle(seed);
            let frame = shape.frame();
            let cap = std::array::from_fn(|i| [f32::INFINITY, 1.0, 0.7, 3.0][i % 4]);
            let lanes = hits_from_one_origin(&frame, start, &dir, t_min, &cap);
            #[cfg(target_arch = "x86_64")]
            if has_avx2() {
                // SAFETY: the function needs AVX2 alone, which this CPU has.
                let wide = unsafe { hits_from_one_origin_avx2(&frame, start, &dir, t_min, &cap) };
                prop_assert_eq!(wide.map(f32::to_bits), lanes.map(f32::to_bits));
            }
            for i in 0..LANES {
                let ray = Ray::new(start, lane(&dir, i));
                let want = frame.intersect(&ray, t_min, cap[i]);
                prop_assert_eq!(lanes[i].is_nan(), want.is_none(), "lane {}", i);
                if let Some(t) = want {
                    prop_assert_eq!(lanes[i].to_bits(), t.to_bits(), "lane {}", i);
                }
            }
        }

        /// Segments with origins of their own: every lane's answer is the
        /// one-ray test's over (0, 1).
        #[test]
        fn segment_lanes_equal_the_one_ray_test(seed in seeds()) {
            let (shape, _, origin, dir) = bundle(seed);
            let frame = shape.frame();
            let hit = segments_hit(&frame, &origin, &dir);
            #[cfg(target_arch = "x86_64")]
            if has_avx2() {
                // SAFETY: the function needs AVX2 alone, which this CPU has.
                prop_assert_eq!(unsafe { segments_hit_avx2(&frame, &origin, &dir) }, hit);
            }
            for i in 0..LANES {
                let ray = Ray::new(lane(&origin, i), lane(&dir, i));
                let want = frame.intersect(&ray, 0.0, 1.0).is_some();
                prop_assert_eq!(hit >> i & 1 == 1, want, "lane {}", i);
            }
        }
    }

    /// The generator reaches both sides of the near frame, hits and misses,
    /// so the properties above test what they claim to.
    #[test]
    fn bundles_cover_near_and_wide_lanes_and_hits_and_misses() {
        let (mut wide, mut near, mut hits, mut misses) = (0, 0, 0, 0);
        for k in 0..400u32 {
            let unit = |j: u32| f64::from((k * 2_654_435_761u32).rotate_left(j) % 1000) / 1000.0;
            let (shape, _, origin, dir) = bundle(std::array::from_fn(|j| unit(j as u32 * 5)));
            let frame = shape.frame();
            let hit = segments_hit(&frame, &origin, &dir);
            for i in 0..LANES {
                let ray = Ray::new(lane(&origin, i), lane(&dir, i));
                if frame.is_far(&ray) {
                    wide += 1;
                } else {
                    near += 1;
                }
                if hit >> i & 1 == 1 {
                    hits += 1;
                } else {
                    misses += 1;
                }
            }
        }
        assert!(
            wide > 500 && near > 500 && hits > 500 && misses > 500,
            "{wide} {near} {hits} {misses}"
        );
    }
}
