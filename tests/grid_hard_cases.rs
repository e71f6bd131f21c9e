//! Scenes that break naive grids. Each must give brute force's answers, and
//! finish in a time far beyond what it needs (only to catch a hang).

use glam::{DVec3, Vec3};
use std::time::{Duration, Instant};
use voxtrace::geometry::{Ellipsoid, Ray};
use voxtrace::index::{BruteForce, EmptySpace, SphereIndex, VoxelHashGrid};
use voxtrace::rng::Rng;

const GENEROUS: Duration = Duration::from_secs(60);

fn point(rng: &mut Rng, lo: f64, hi: f64) -> Vec3 {
    Vec3::new(
        rng.range(lo, hi) as f32,
        rng.range(lo, hi) as f32,
        rng.range(lo, hi) as f32,
    )
}

/// Compares `rays` random rays (origins in [lo, hi]³) against brute force.
fn agree(shapes: &[Ellipsoid<f32>], rays: usize, lo: f64, hi: f64) {
    let started = Instant::now();
    let grid = VoxelHashGrid::new(shapes);
    let brute = BruteForce::new(shapes);
    let mut rng = Rng::new(42);
    for _ in 0..rays {
        let origin = point(&mut rng, lo, hi);
        let target = if rng.unit() < 0.5 {
            shapes[(rng.next_u64() % shapes.len() as u64) as usize].center
        } else {
            point(&mut rng, lo, hi)
        };
        let ray = Ray::new(origin, target - origin);
        assert_eq!(
            grid.closest_hit(&ray, 0.0, f32::INFINITY),
            brute.closest_hit(&ray, 0.0, f32::INFINITY),
            "{ray:?}"
        );
        assert_eq!(grid.any_hit(&ray, 1.0), brute.any_hit(&ray, 1.0), "{ray:?}");
    }
    assert!(started.elapsed() < GENEROUS, "took {:?}", started.elapsed());
}

#[test]
fn one_huge_sphere_among_a_hundred_thousand_tiny_ones() {
    let mut rng = Rng::new(1);
    let mut shapes: Vec<Ellipsoid<f32>> = (0..100_000)
        .map(|_| Ellipsoid::new(point(&mut rng, -50.0, 50.0), Vec3::splat(1e-2)))
        .collect();
    // A planet of radius 1e4 whose surface runs through the middle of the cloud.
    shapes.insert(
        50_000,
        Ellipsoid::new(Vec3::new(0.0, -1e4, 0.0), Vec3::splat(1e4)),
    );
    let grid = VoxelHashGrid::new(&shapes);
    assert_eq!(grid.short_list_len(), 1, "every ray tests the planet");
    // The tiny spheres get the same grid they would get without it.
    let without: Vec<Ellipsoid<f32>> = [&shapes[..50_000], &shapes[50_001..]].concat();
    assert_eq!(grid.levels(), VoxelHashGrid::new(&without).levels());
    agree(&shapes, 400, -50.0, 50.0);
}

#[test]
fn a_hundred_thousand_spheres_packed_into_one_small_region() {
    let mut rng = Rng::new(2);
    let shapes: Vec<Ellipsoid<f32>> = (0..100_000)
        .map(|_| Ellipsoid::new(point(&mut rng, 0.0, 0.05), Vec3::splat(2e-3)))
        .collect();
    agree(&shapes, 400, -0.02, 0.07);
}

/// Two dense clumps a million cells apart: in f64 (whose rounding allows
/// cells of side 1 a million units out) a ray between them crosses millions
/// of empty cells, whichever way the walk treats empty space.
#[test]
fn a_ray_crossing_millions_of_empty_cells() {
    let far = 1e6;
    let clump = |at: DVec3| {
        (0..1000).map(move |i| {
            let offset = DVec3::new((i % 10) as f64, (i / 10 % 10) as f64, (i / 100) as f64);
            Ellipsoid::new(at + offset * 0.5, DVec3::splat(0.4))
        })
    };
    let shapes: Vec<Ellipsoid<f64>> = clump(DVec3::ZERO)
        .chain(clump(DVec3::new(far, 0.0, 0.0)))
        .chain(clump(DVec3::splat(far)))
        .collect();
    let brute = BruteForce::new(&shapes);
    for mode in [EmptySpace::SkipBlocks, EmptySpace::ProbeEveryCell] {
        let grid = VoxelHashGrid::new(&shapes).with_empty_space(mode);
        let info = grid.levels();
        assert_eq!(info.len(), 1);
        assert!(
            info[0].cell <= 1.0 && info[0].dims[0] > 1_000_000,
            "{info:?}"
        );
        let started = Instant::now();
        for (origin, dir) in [
            (DVec3::new(6.0, 0.5, 0.5), DVec3::new(1.0, 0.0, -0.0)),
            (DVec3::splat(6.0), DVec3::splat(1.0)),
            (DVec3::new(far - 1.0, 0.5, 0.5), DVec3::new(-1.0, -0.0, 0.0)),
        ] {
            let ray = Ray::new(origin, dir);
            let hit = grid.closest_hit(&ray, 0.0, f64::INFINITY);
            assert!(hit.is_some());
            assert_eq!(hit, brute.closest_hit(&ray, 0.0, f64::INFINITY));
            assert!(grid.any_hit(&ray, f64::INFINITY));
            assert!(!grid.any_hit(&ray, 0.5 * far));
        }
        assert!(started.elapsed() < GENEROUS);
    }
}

#[test]
fn an_empty_scene_is_never_hit() {
    let shapes: Vec<Ellipsoid<f32>> = Vec::new();
    let grid = VoxelHashGrid::new(&shapes);
    assert!(grid.levels().is_empty());
    let ray = Ray::new(Vec3::ZERO, Vec3::NEG_Z);
    assert_eq!(grid.closest_hit(&ray, 0.0, f32::INFINITY), None);
    assert!(!grid.any_hit(&ray, f32::INFINITY));
}

#[test]
fn duplicates_resolve_to_the_lowest_id() {
    let mut rng = Rng::new(3);
    let mut shapes: Vec<Ellipsoid<f32>> = (0..200)
        .map(|_| Ellipsoid::new(point(&mut rng, -5.0, 5.0), Vec3::splat(0.3)))
        .collect();
    let twin = Ellipsoid::new(Vec3::new(0.0, 0.0, -3.0), Vec3::splat(0.5));
    for _ in 0..1000 {
        shapes.push(twin);
    }
    shapes.insert(17, twin);
    let grid = VoxelHashGrid::new(&shapes);
    let ray = Ray::new(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0));
    let hit = grid.closest_hit(&ray, 0.0, f32::INFINITY).unwrap();
    assert_eq!(
        Some(hit),
        BruteForce::new(&shapes).closest_hit(&ray, 0.0, f32::INFINITY)
    );
    assert!(hit.sphere <= 17);
    agree(&shapes, 300, -6.0, 6.0);
}

/// Spheres packed on nested shells, their cells barely wider than they
/// are: the level outgrows the index's bytes per sphere at its own cells
/// and is built coarser, within them, with brute force's answers still.
#[test]
fn spheres_packed_on_shells_within_the_index_bytes_per_sphere() {
    let mut rng = Rng::new(5);
    let n = 80_000;
    let shapes: Vec<Ellipsoid<f32>> = (0..n)
        .map(|i| {
            let v = point(&mut rng, -1.0, 1.0).normalize_or(Vec3::X);
            let radius = 1.0 + 0.5 * (i % 3) as f32;
            Ellipsoid::new(v * radius, Vec3::splat(0.011 + 0.003 * rng.unit() as f32))
        })
        .collect();
    let grid = VoxelHashGrid::new(&shapes);
    let most = voxtrace::limits::INDEX_BYTES_PER_SPHERE * n;
    assert!(grid.bytes() <= most, "{} bytes a sphere", grid.bytes() / n);
    agree(&shapes, 400, -2.5, 2.5);
}
