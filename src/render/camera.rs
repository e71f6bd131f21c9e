//! Eye rays: from the origin through the image plane z = −near.

use crate::rng::{Rng, GOLDEN_GAMMA};
use crate::scene::Camera;
use glam::DVec3;

/// Where in each pixel the eye rays go, and how their colours combine.
///
/// Pixel (column c, row r counted from the top) spans the image-plane square
/// whose upper-left corner is `(L + c/W·(R−L), T − r/H·(T−B))`. One sample is
/// that corner, as the course's renderer did; N samples are stratified
/// (an √N×√N jittered grid when N is square, N-rooks otherwise) and averaged.
pub struct PixelSampler {
    camera: Camera,
    spp: u32,
}

impl PixelSampler {
    pub fn new(camera: &Camera, spp: u32) -> Self {
        PixelSampler {
            camera: *camera,
            spp: spp.max(1),
        }
    }

    /// The unnormalised eye-ray direction through image position (x, y), in
    /// pixels from the upper-left corner; t = 1 lies on the near plane.
    pub fn direction(&self, x: f64, y: f64) -> DVec3 {
        let c = &self.camera;
        DVec3::new(
            c.left + x / f64::from(c.width) * (c.right - c.left),
            c.top - y / f64::from(c.height) * (c.top - c.bottom),
            -c.near,
        )
    }

    /// Samples per pixel.
    pub fn spp(&self) -> u32 {
        self.spp
    }

    /// Appends the eye-ray directions of the pixel's samples to `out`, in
    /// sample order.
    pub fn directions(&self, column: u32, row: u32, out: &mut Vec<DVec3>) {
        let (x, y) = (f64::from(column), f64::from(row));
        if self.spp == 1 {
            out.push(self.direction(x, y));
            return;
        }
        let mut rng = PixelRng::new(column, row);
        let n = self.spp;
        let side = (f64::from(n).sqrt().round() as u32).max(1);
        for i in 0..n {
            let (u, v) = if side * side == n {
                (
                    (f64::from(i % side) + rng.next()) / f64::from(side),
                    (f64::from(i / side) + rng.next()) / f64::from(side),
                )
            } else {
                // N-rooks: one sample per column stratum and one per row
                // stratum, rows paired by a cheap per-pixel shuffle.
                let j = (i + rng.offset(n)) % n;
                (
                    (f64::from(i) + rng.next()) / f64::from(n),
                    (f64::from(j) + rng.next()) / f64::from(n),
                )
            };
            out.push(self.direction(x + u, y + v));
        }
    }

    /// The pixel's colour from its samples' radiances in sample order: one
    /// sample as it is, more each clamped to [0, 1] first (so that one very
    /// bright sample cannot outweigh the rest) and averaged.
    #[inline(always)]
    pub fn combine(&self, radiances: impl IntoIterator<Item = DVec3>) -> DVec3 {
        let mut radiances = radiances.into_iter();
        if self.spp == 1 {
            return radiances.next().unwrap_or(DVec3::ZERO);
        }
        let sum = radiances.fold(DVec3::ZERO, |sum, r| sum + r.clamp(DVec3::ZERO, DVec3::ONE));
        sum / f64::from(self.spp)
    }
}

/// A generator seeded by the pixel, so images do not depend on which
/// thread renders which row.
struct PixelRng {
    rng: Rng,
    offset: Option<u32>,
}

impl PixelRng {
    fn new(column: u32, row: u32) -> Self {
        PixelRng {
            rng: Rng::new((u64::from(row) << 32 | u64::from(column)).wrapping_mul(GOLDEN_GAMMA)),
            offset: None,
        }
    }

    /// Uniform in [0, 1).
    fn next(&mut self) -> f64 {
        self.rng.unit()
    }

    /// One random shift in [0, n) per pixel, for pairing N-rooks strata.
    fn offset(&mut self, n: u32) -> u32 {
        match self.offset {
            Some(o) => o,
            None => {
                let o = (self.rng.next_u64() % u64::from(n)) as u32;
                self.offset = Some(o);
                o
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera {
            near: 1.0,
            left: -1.0,
            right: 1.0,
            bottom: -1.0,
            top: 1.0,
            width: 4,
            height: 2,
        }
    }

    #[test]
    fn one_sample_is_the_pixel_corner_with_row_zero_at_the_top() {
        let s = PixelSampler::new(&camera(), 1);
        assert_eq!(s.direction(0.0, 0.0), DVec3::new(-1.0, 1.0, -1.0));
        assert_eq!(s.direction(2.0, 1.0), DVec3::new(0.0, 0.0, -1.0));
        let mut seen = vec![];
        s.directions(3, 1, &mut seen);
        assert_eq!(seen, vec![DVec3::new(0.5, 0.0, -1.0)]);
        // One sample is the pixel's colour as it is, unclamped.
        assert_eq!(s.combine([DVec3::splat(2.0)]), DVec3::splat(2.0));
    }

    #[test]
    fn many_samples_stay_inside_the_pixel_and_cover_its_strata() {
        for spp in [4, 16, 5] {
            let s = PixelSampler::new(&camera(), spp);
            let mut dirs = vec![];
            s.directions(1, 0, &mut dirs);
            let mut xs = vec![];
            for d in dirs {
                // Pixel 1 spans x in [-0.5, 0), y in (0, 1].
                assert!((-0.5..0.0).contains(&d.x) && d.y > 0.0 && d.y <= 1.0, "{d}");
                xs.push(((d.x + 0.5) / 0.5 * spp as f64) as u32);
            }
            assert_eq!(xs.len(), spp as usize);
            if spp == 5 {
                xs.sort();
                assert_eq!(xs, vec![0, 1, 2, 3, 4], "one sample per column stratum");
            }
            // More samples are each clamped to [0, 1], then averaged.
            let bright = std::iter::repeat_n(DVec3::splat(3.0), spp as usize - 1);
            let colour = s.combine(bright.chain([DVec3::ZERO]));
            assert_eq!(colour, DVec3::splat((spp - 1) as f64 / spp as f64));
        }
    }
}
