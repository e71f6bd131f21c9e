//! Whether a render should build the grid's light buffers.
//!
//! A buffer is built over every sphere, and pays back per shadow ray it
//! answers: a render casts about one shadow ray per light per eye hit (and
//! more from reflections). So what decides is the eye hits a render will
//! make against the spheres the buffers hold, not its samples: a scene
//! whose spheres fill the view (uniform, clustered at 10⁶ and 1024²: 0.9
//! and 0.8 eye hits a sphere) gains 0.1–0.3 s of a 1.3–1.7 s render from
//! them, while one most of whose rays miss (thin strands, knots of a
//! fractal: 0.05 a sphere) loses 0.1–0.2 s of a 0.7–1.0 s render building
//! buffers few rays read (docs/index.md, "Light buffers where they pay").
//!
//! The hits are estimated from a sparse lattice of eye rays traced against
//! the grid before the buffers are built: a few thousand rays, a fraction
//! of what one light's buffer costs. They are traced before the render's
//! stop flag runs, so each checks the render's deadline itself: a scene
//! whose rays are slow stops the estimate at the deadline, one ray late at
//! most, and the render that follows stops at its own checks.

use super::region::Region;
use super::{first_hit, Deadline, PixelSampler};
use crate::geometry::{Real, Vec3Ops, V3};
use crate::index::VoxelHashGrid;
use crate::scene::Scene;
use rayon::prelude::*;

/// Eye hits per sphere from which the buffers pay.
const HITS_PER_SPHERE: f64 = 0.5;
/// Most eye rays traced to estimate the hit fraction.
const PROBE_RAYS: u64 = 4_096;
/// The probe traces at most this share of the region's pixels.
const PROBE_SHARE: u64 = 4;

/// Whether the light buffers pay for a render of `samples` samples over
/// `region` of `scene`, whose spheres `grid` holds, to stop at `deadline`.
pub(super) fn pay<R: Real>(
    scene: &Scene,
    region: Region,
    samples: u64,
    grid: &VoxelHashGrid<R>,
    deadline: Option<&Deadline>,
) -> bool {
    let wanted = HITS_PER_SPHERE * scene.spheres.len() as f64;
    // Even if every sample hit, too few.
    if (samples as f64) < wanted {
        return false;
    }
    let Some(fraction) = eye_hit_fraction(scene, region, grid, deadline) else {
        return false;
    };
    samples as f64 * fraction >= wanted
}

/// The share of the corner eye rays of a lattice of `region`'s pixels
/// that hit a sphere beyond the image plane, as the renderer's first hit
/// does; None if `deadline` comes first.
fn eye_hit_fraction<R: Real>(
    scene: &Scene,
    region: Region,
    grid: &VoxelHashGrid<R>,
    deadline: Option<&Deadline>,
) -> Option<f64> {
    let probes = PROBE_RAYS.min(region.pixels() / PROBE_SHARE).max(1);
    // Every `stride`-th pixel of every `stride`-th row.
    let stride = ((region.pixels() as f64 / probes as f64).sqrt().ceil() as u32).max(1);
    let columns: Vec<u32> = region.columns().step_by(stride as usize).collect();
    let rows: Vec<u32> = region.rows().step_by(stride as usize).collect();
    let sampler = PixelSampler::new(&scene.camera, 1);
    let eye = V3::<R>::from_dvec3(glam::DVec3::ZERO);
    let come = || deadline.is_some_and(Deadline::has_come);
    let hits: Option<usize> = (rows.par_iter())
        .map(|&y| {
            let mut hits = 0;
            for &x in &columns {
                if come() {
                    return None;
                }
                hits += usize::from(first_hit(grid, &sampler, eye, x, y).is_some());
            }
            Some(hits)
        })
        .sum();
    Some(hits? as f64 / (rows.len() * columns.len()).max(1) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{RenderOptions, Rendered};
    use std::fmt::Write;

    /// A scene at `res`² of `n` spheres of radius `radius` on a lattice in
    /// front of the eye, `spread` times as wide as the view.
    fn lattice_scene(res: u32, n: usize, radius: f64, spread: f64) -> Scene {
        let mut text = format!(
            "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES {res} {res}\n\
             BACK 0 0 0\nAMBIENT 0.2 0.2 0.2\nLIGHT l 0 10 0 1 1 1\nOUTPUT o.ppm\n"
        );
        let side = (n as f64).sqrt().ceil() as usize;
        for i in 0..n {
            let (x, y) = ((i % side) as f64, (i / side) as f64);
            let at = |v: f64| spread * (2.0 * (v + 0.5) / side as f64 - 1.0) * 5.0;
            writeln!(
                text,
                "SPHERE s{i} {} {} -5 {radius} {radius} {radius} 1 0 0 0.5 0.5 0 0 1",
                at(x),
                at(y)
            )
            .unwrap();
        }
        crate::scene::parse(text).unwrap()
    }

    fn buffered(scene: &Scene) -> usize {
        let options = RenderOptions::default();
        let Rendered { stats, .. } = crate::render::render_scene(scene, &options, &|_| {}).unwrap();
        stats.light_buffers.lights
    }

    #[test]
    fn a_view_full_of_spheres_gets_buffers_and_one_mostly_empty_does_not() {
        // 64² samples, 1024 spheres: 4 samples a sphere either way.
        let full = lattice_scene(64, 1024, 0.2, 1.0);
        assert_eq!(buffered(&full), 1);
        // The same spheres, tiny, spread over nine times the view: few hit.
        let sparse = lattice_scene(64, 1024, 0.01, 3.0);
        assert_eq!(buffered(&sparse), 0);
    }

    /// The estimate stops at the render's deadline: where it has come
    /// (or its token is cancelled), the buffers are not built.
    #[test]
    fn a_deadline_come_stops_the_estimate() {
        use std::time::{Duration, Instant};
        let full = lattice_scene(64, 1024, 0.2, 1.0);
        let grid = VoxelHashGrid::new(&crate::render::shapes_of::<f32>(&full));
        let region = Region::whole(64, 64);
        assert!(pay(&full, region, 4096, &grid, None));
        let later = Deadline::at(Instant::now() + Duration::from_secs(3600));
        assert!(pay(&full, region, 4096, &grid, Some(&later)));
        let come = Deadline::at(Instant::now());
        assert!(!pay(&full, region, 4096, &grid, Some(&come)));
        let token = crate::render::CancelToken::new();
        token.cancel();
        let cancelled = later.or_cancel(&token);
        assert!(!pay(&full, region, 4096, &grid, Some(&cancelled)));
    }

    #[test]
    fn more_spheres_than_samples_get_no_buffers_without_a_probe() {
        let crowded = lattice_scene(16, 1024, 0.2, 1.0);
        assert_eq!(buffered(&crowded), 0);
    }
}
