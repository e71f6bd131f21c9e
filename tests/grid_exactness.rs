//! The grid returns exactly what brute force returns: the same sphere and the
//! same t for `closest_hit`, the same answer for `any_hit`, over random scenes
//! built to stress the traversal and random rays built to stress the walk.

use glam::{Vec3, Vec3Swizzles};
use proptest::prelude::*;
use voxtrace::geometry::{Ellipsoid, Ray};
use voxtrace::index::{Answered, BruteForce, EmptySpace, SphereIndex, VoxelHashGrid};

/// The crate's generator with f32 helpers: scenes come from a seed
/// proptest shrinks over.
struct Rng(voxtrace::rng::Rng);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(voxtrace::rng::Rng::new(seed))
    }
    fn next(&mut self) -> u64 {
        self.0.next_u64()
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }
    fn log_range(&mut self, lo: f32, hi: f32) -> f32 {
        (lo.ln() + (hi.ln() - lo.ln()) * self.unit()).exp()
    }
    fn point(&mut self, half: f32) -> Vec3 {
        Vec3::new(
            self.range(-half, half),
            self.range(-half, half),
            self.range(-half, half),
        )
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    /// Radii log-uniform over four decades, heavily overlapping.
    Mixed,
    /// Dense clumps far apart.
    Clustered,
    /// A few huge spheres among many tiny ones.
    HugeAndTiny,
    /// Centres exactly on lattice points (integers), radii under half a cell.
    OnCorners,
    /// Ellipsoids, some very flat.
    Ellipsoids,
    /// One sphere of radius 10⁵ beside tiny ones (10⁻³..10⁻²): rays from
    /// its far side reach them from 10⁸ radii, beyond f32's near frame.
    FarAndTiny,
    /// Spheres on the surface of a hollow ball: rays cross its empty inside.
    HollowShell,
    /// Clumps far apart in empty space, each of its own sphere size (two
    /// decades between them), moved by up to 10⁴: several levels, each in
    /// clumps of its own, which the grid's gate answers for.
    Islands,
    /// A mixed scene scaled by 10^±4 and moved by up to 10⁵.
    Rescaled,
}

fn scene(kind: Kind, seed: u64) -> Vec<Ellipsoid<f32>> {
    let mut rng = Rng::new(seed);
    let n = 150 + rng.below(150);
    let mut shapes = Vec::with_capacity(n);
    let sphere = |c: Vec3, r: f32| Ellipsoid::new(c, Vec3::splat(r));
    match kind {
        Kind::Mixed => {
            for _ in 0..n {
                shapes.push(sphere(rng.point(20.0), rng.log_range(1e-3, 10.0)));
            }
        }
        Kind::Clustered => {
            let centres: Vec<Vec3> = (0..4).map(|_| rng.point(200.0)).collect();
            for _ in 0..n {
                let c = centres[rng.below(centres.len())] + rng.point(1.0);
                shapes.push(sphere(c, rng.log_range(0.01, 0.3)));
            }
        }
        Kind::HugeAndTiny => {
            for _ in 0..3 {
                shapes.push(sphere(rng.point(50.0), rng.range(20.0, 60.0)));
            }
            for _ in 0..n {
                shapes.push(sphere(rng.point(50.0), rng.log_range(1e-3, 1e-2)));
            }
        }
        Kind::OnCorners => {
            for _ in 0..n {
                let c = rng.point(6.0).round();
                let r = [0.45, 0.25, 0.125, 1.9, 0.9][rng.below(5)];
                shapes.push(sphere(c, r));
            }
        }
        Kind::Ellipsoids => {
            for _ in 0..n {
                let scale = Vec3::new(
                    rng.log_range(0.01, 2.0),
                    rng.log_range(0.01, 2.0),
                    rng.log_range(0.01, 2.0),
                );
                let flip = Vec3::new(if rng.below(2) == 0 { 1.0 } else { -1.0 }, 1.0, 1.0);
                shapes.push(Ellipsoid::new(rng.point(10.0), scale * flip));
            }
        }
        Kind::FarAndTiny => {
            shapes.push(sphere(Vec3::new(0.0, -1.0e5 - 3.0, 0.0), 1.0e5));
            for _ in 0..n {
                shapes.push(sphere(rng.point(3.0), rng.log_range(1e-3, 1e-2)));
            }
        }
        Kind::HollowShell => {
            for _ in 0..n {
                let c = rng.point(1.0).normalize_or(Vec3::Y) * 5.0;
                shapes.push(sphere(c, rng.log_range(0.05, 0.4)));
            }
        }
        Kind::Islands => {
            let shift = rng.point(1.0) * 10f32.powf(rng.range(0.0, 4.0));
            let clumps: Vec<(Vec3, f32, f32)> = (0..3 + rng.below(4))
                .map(|_| {
                    let size = rng.log_range(0.003, 0.3);
                    (rng.point(30.0) + shift, rng.range(0.5, 3.0), size)
                })
                .collect();
            for _ in 0..n {
                let (centre, reach, size) = clumps[rng.below(clumps.len())];
                let c = centre + rng.point(1.0).normalize_or(Vec3::X) * rng.range(0.0, reach);
                shapes.push(sphere(c, size * rng.range(0.8, 1.2)));
            }
        }
        Kind::Rescaled => {
            let scale = 10f32.powf(rng.range(-4.0, 4.0));
            let shift = rng.point(1.0) * 10f32.powf(rng.range(0.0, 5.0));
            for _ in 0..n {
                let c = rng.point(20.0) * scale + shift;
                shapes.push(sphere(c, rng.log_range(1e-3, 10.0) * scale));
            }
        }
    }
    shapes
}

/// The half-size of a box that holds every sphere.
fn extent(shapes: &[Ellipsoid<f32>]) -> f32 {
    shapes
        .iter()
        .map(|s| (s.center.abs() + s.scale.abs()).max_element())
        .fold(1.0, f32::max)
}

/// A random ray of one of the awkward kinds.
fn ray(rng: &mut Rng, shapes: &[Ellipsoid<f32>]) -> Ray<f32> {
    let half = extent(shapes);
    let origin = rng.point(half);
    let pick = &shapes[rng.below(shapes.len())];
    let sign = |rng: &mut Rng, v: f32| if rng.below(2) == 0 { v } else { -v };
    match rng.below(6) {
        // From a random point (often inside a sphere) towards a sphere.
        0 => Ray::new(origin, pick.center - origin + rng.point(0.01)),
        // Axis-parallel, with signed zeros in the other components.
        1 => {
            let mut d = [sign(rng, 0.0), sign(rng, 0.0), sign(rng, 0.0)];
            d[rng.below(3)] = sign(rng, 1.0);
            let o = if rng.below(2) == 0 {
                origin
            } else {
                pick.center.round()
            };
            Ray::new(o, Vec3::from_array(d))
        }
        // Through a lattice point (integers are lattice points of every level
        // with cells of at most one; multiples of 4 of most others).
        2 => {
            let lattice = rng.point(half).round() * if rng.below(2) == 0 { 1.0 } else { 4.0 };
            let o = if rng.below(2) == 0 {
                origin.round()
            } else {
                origin
            };
            Ray::new(o, lattice - o)
        }
        // Grazing: passes a sphere's rim at 1e-7 to 1e-2 radii, from near or far.
        3 => {
            let d = rng.point(1.0).normalize_or(Vec3::X);
            let side = d.any_orthonormal_vector();
            let r = pick.scale.abs().max_element();
            let miss = 1.0 + sign(rng, 1.0) * 10f32.powf(-rng.range(2.0, 7.0));
            let back = rng.log_range(r * 1.5, 2.0 * half);
            let o = pick.center + side * (r * miss) - d * back;
            Ray::new(o, d)
        }
        // Along a diagonal through a sphere's centre, from far outside.
        4 => {
            let d = Vec3::new(sign(rng, 1.0), sign(rng, 1.0), sign(rng, 1.0));
            Ray::new(pick.center - d * half, d)
        }
        // Anything.
        _ => Ray::new(origin, rng.point(1.0)),
    }
}

fn check(shapes: &[Ellipsoid<f32>], seed: u64, rays: usize) {
    let brute = BruteForce::new(shapes);
    let grid = VoxelHashGrid::new(shapes);
    // The same walks compiled for the build's own target, where `grid` runs
    // the CPU's wider vectors.
    let baseline = VoxelHashGrid::new(shapes).with_baseline_vectors();
    let probing = VoxelHashGrid::new(shapes).with_empty_space(EmptySpace::ProbeEveryCell);
    let mut rng = Rng::new(seed ^ 0x5eed);
    for _ in 0..rays {
        let ray = ray(&mut rng, shapes);
        for (t_min, t_max) in [(0.0, f32::INFINITY), (1.0, f32::INFINITY), (0.0, 1.0)] {
            let want = brute.closest_hit(&ray, t_min, t_max);
            assert_eq!(
                grid.closest_hit(&ray, t_min, t_max),
                want,
                "closest_hit {ray:?} in ({t_min}, {t_max})"
            );
            assert_eq!(baseline.closest_hit(&ray, t_min, t_max), want);
            assert_eq!(probing.closest_hit(&ray, t_min, t_max), want);
        }
        for t_max in [1.0, 0.5, f32::INFINITY] {
            let want = brute.any_hit(&ray, t_max);
            assert_eq!(
                grid.any_hit(&ray, t_max),
                want,
                "any_hit {ray:?} to {t_max}"
            );
            assert_eq!(baseline.any_hit(&ray, t_max), want);
            assert_eq!(probing.any_hit(&ray, t_max), want);
        }
    }
}

const ALL_KINDS: [Kind; 9] = [
    Kind::Mixed,
    Kind::Clustered,
    Kind::HugeAndTiny,
    Kind::OnCorners,
    Kind::Ellipsoids,
    Kind::FarAndTiny,
    Kind::HollowShell,
    Kind::Islands,
    Kind::Rescaled,
];

/// Clumps of their own sizes in empty space are where the gate pays: most
/// such scenes get one, answering for two levels or more.
#[test]
fn islands_are_gated() {
    let gated = (0..20)
        .filter(|&seed| VoxelHashGrid::new(&scene(Kind::Islands, seed)).gated_levels() >= 2)
        .count();
    assert!(gated >= 10, "{gated} of 20 scenes gated");
}

/// Tiny spheres at the origin and others 10⁹ away: two levels whose cells
/// differ by 2^19 and lie 2^26 of the finest apart, both gated, the gate's
/// cubes far coarser than either (its marking shifts by some 26 bits), and
/// the answers brute force's.
#[test]
fn levels_far_apart_at_far_different_scales_are_gated_exactly() {
    let mut rng = Rng::new(5);
    let mut shapes = Vec::new();
    for _ in 0..100 {
        shapes.push(Ellipsoid::new(rng.point(1e-13), Vec3::splat(1e-15)));
        let far = Vec3::new(1e9, 0.0, 0.0) + rng.point(2000.0);
        shapes.push(Ellipsoid::new(far, Vec3::splat(rng.range(50.0, 100.0))));
    }
    assert_eq!(VoxelHashGrid::new(&shapes).gated_levels(), 2);
    check(&shapes, 5, 300);
}

fn kinds() -> impl Strategy<Value = Kind> {
    proptest::sample::select(ALL_KINDS.to_vec())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(160))]

    #[test]
    fn grid_agrees_with_brute_force(kind in kinds(), seed in any::<u64>()) {
        check(&scene(kind, seed), seed, 300);
    }
}

/// Rays from the eye through a pixel grid, as the renderer shoots them.
#[test]
fn eye_rays_agree_on_every_kind_of_scene() {
    for (i, kind) in ALL_KINDS.into_iter().enumerate() {
        let shapes = scene(kind, 7 + i as u64);
        let brute = BruteForce::new(&shapes);
        let grid = VoxelHashGrid::new(&shapes);
        for y in 0..64 {
            for x in 0..64 {
                let dir = Vec3::new(x as f32 / 32.0 - 1.0, 1.0 - y as f32 / 32.0, -1.0);
                for dir in [dir, -dir, dir.zxy()] {
                    let ray = Ray::new(Vec3::ZERO, dir);
                    assert_eq!(
                        grid.closest_hit(&ray, 1.0, f32::INFINITY),
                        brute.closest_hit(&ray, 1.0, f32::INFINITY),
                        "{kind:?} {dir}"
                    );
                }
            }
        }
    }
}

/// A bundle of rays from one origin, of one of the kinds packets meet.
fn bundle(rng: &mut Rng, shapes: &[Ellipsoid<f32>]) -> (Vec3, Vec<Vec3>) {
    let half = extent(shapes);
    let pick = shapes[rng.below(shapes.len())];
    let origin = match rng.below(4) {
        0 => Vec3::ZERO,
        1 => rng.point(half),
        // Inside a sphere.
        2 => pick.center,
        // On a lattice point.
        _ => rng.point(half).round(),
    };
    // Whole packets of 64, partial ones, and more than one.
    let count = [64, 64, 128, 16, 7, 1, 40, 100][rng.below(8)];
    let toward = (pick.center - origin).normalize_or(Vec3::NEG_Z);
    let side = toward.any_orthonormal_vector();
    let up = toward.cross(side);
    let spread = rng.log_range(1e-6, 0.5);
    let dirs = (0..count)
        .map(|i| match rng.below(8) {
            // Through an 8×8 tile around the picked sphere, like neighbouring
            // pixels, quarter by quarter as the renderer lists them.
            0..=4 => {
                let quarter = i / 16 % 4;
                let x = (quarter % 2 * 4 + i % 4) as f32 - 3.5;
                let y = (quarter / 2 * 4 + i / 4 % 4) as f32 - 3.5;
                toward + (side * x + up * y) * spread
            }
            // Axis-parallel with signed zeros, as far as the sign of travel goes.
            5 => {
                let mut d = [0.0f32; 3];
                let a = toward.abs();
                let axis = if a.x >= a.y && a.x >= a.z {
                    0
                } else if a.y >= a.z {
                    1
                } else {
                    2
                };
                d[axis] = toward[axis].signum();
                for (k, v) in d.iter_mut().enumerate() {
                    if k != axis && rng.below(2) == 0 {
                        *v = -0.0;
                    }
                }
                Vec3::from_array(d)
            }
            // Through a lattice point.
            6 => rng.point(half).round() - origin,
            // Anywhere: the bundle loses its common direction.
            _ => rng.point(1.0),
        })
        .collect();
    (origin, dirs)
}

fn check_packets(shapes: &[Ellipsoid<f32>], seed: u64, bundles: usize) {
    let brute = BruteForce::new(shapes);
    let grid = VoxelHashGrid::new(shapes);
    let baseline = VoxelHashGrid::new(shapes).with_baseline_vectors();
    let probing = VoxelHashGrid::new(shapes).with_empty_space(EmptySpace::ProbeEveryCell);
    let mut rng = Rng::new(seed ^ 0xb0b);
    for _ in 0..bundles {
        let (origin, dirs) = bundle(&mut rng, shapes);
        for (t_min, t_max) in [
            (0.0, f32::INFINITY),
            (1.0, f32::INFINITY),
            (0.0, 1.0),
            (-0.5, f32::INFINITY),
        ] {
            let want: Vec<_> = dirs
                .iter()
                .map(|&d| brute.closest_hit(&Ray::new(origin, d), t_min, t_max))
                .collect();
            for index in [&grid, &baseline, &probing] {
                let mut got = vec![None; dirs.len()];
                let answered = index.closest_hits(origin, &dirs, t_min, t_max, &mut got);
                assert_eq!(answered, Answered::All);
                assert_eq!(got, want, "from {origin} in ({t_min}, {t_max}): {dirs:?}");
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn packets_agree_with_brute_force(kind in kinds(), seed in any::<u64>()) {
        check_packets(&scene(kind, seed), seed, 40);
    }
}

/// Eye rays in 8×8 pixel tiles, as the renderer traces them, at a resolution
/// where a tile is a small fraction of a cell and where it spans several.
#[test]
fn eye_tiles_agree_on_every_kind_of_scene() {
    for (i, kind) in ALL_KINDS.into_iter().enumerate() {
        let shapes = scene(kind, 11 + i as u64);
        let brute = BruteForce::new(&shapes);
        let grid = VoxelHashGrid::new(&shapes);
        for pixels in [64, 1024] {
            let step = 2.0 / pixels as f32;
            for ty in (0..pixels).step_by(8 * pixels / 64) {
                for tx in (0..pixels).step_by(8 * pixels / 64) {
                    let (tx, ty) = (tx as u32, ty as u32);
                    let tile = voxtrace::render::tiles(tx + 8, ty..ty + 8)
                        .last()
                        .expect("a tile");
                    let dirs: Vec<Vec3> = tile
                        .iter()
                        .map(|&(x, y)| {
                            let (x, y) = (x as f32, y as f32);
                            Vec3::new(-1.0 + (x + 0.5) * step, -1.0 + (y + 0.5) * step, -1.0)
                        })
                        .collect();
                    let mut got = vec![None; dirs.len()];
                    let answered =
                        grid.closest_hits(Vec3::ZERO, &dirs, 1.0, f32::INFINITY, &mut got);
                    assert_eq!(answered, Answered::All);
                    for (d, hit) in dirs.iter().zip(&got) {
                        let want = brute.closest_hit(&Ray::new(Vec3::ZERO, *d), 1.0, f32::INFINITY);
                        assert_eq!(*hit, want, "{kind:?} {d}");
                    }
                }
            }
        }
    }
}

/// Shadow rays of a tile's hit points toward one light, as the renderer
/// casts them: origins on (or just off) the surfaces a tile of eye rays
/// meets, or scattered, and a light near, far, inside a sphere or on a
/// lattice point.
fn shadow_bundle(rng: &mut Rng, shapes: &[Ellipsoid<f32>]) -> (Vec3, Vec<Vec3>) {
    let half = extent(shapes);
    let pick = shapes[rng.below(shapes.len())];
    let light = match rng.below(5) {
        0 => rng.point(half),
        1 => rng.point(1.0) * half * 100.0,
        2 => pick.center,
        3 => rng.point(half).round(),
        _ => pick.center + rng.point(1.0) * pick.scale.abs().max_element() * 3.0,
    };
    let (origin, dirs) = bundle(rng, shapes);
    let count = dirs.len();
    let origins = (0..count)
        .map(|i| match rng.below(6) {
            // Where the eye ray meets something (the nearest hit), nudged
            // off the surface, as shading spawns it.
            0..=3 => {
                let ray = Ray::new(origin, dirs[i]);
                let t = BruteForce::new(shapes)
                    .closest_hit(&ray, 0.0, f32::INFINITY)
                    .map_or(1.0, |h| h.t);
                ray.at(t) + (light - ray.at(t)) * 1e-4
            }
            // On a lattice point.
            4 => rng.point(half).round(),
            // Anywhere.
            _ => rng.point(half),
        })
        .collect();
    (light, origins)
}

fn check_shadow_packets(shapes: &[Ellipsoid<f32>], seed: u64, bundles: usize) {
    let brute = BruteForce::new(shapes);
    let grid = VoxelHashGrid::new(shapes);
    let baseline = VoxelHashGrid::new(shapes).with_baseline_vectors();
    let probing = VoxelHashGrid::new(shapes).with_empty_space(EmptySpace::ProbeEveryCell);
    let mut rng = Rng::new(seed ^ 0x5ad0);
    for _ in 0..bundles {
        let (light, origins) = shadow_bundle(&mut rng, shapes);
        let want: Vec<bool> = origins
            .iter()
            .map(|&o| brute.any_hit(&Ray::new(o, light - o), 1.0))
            .collect();
        for index in [&grid, &baseline, &probing] {
            let mut got = vec![false; origins.len()];
            assert_eq!(
                index.any_hits_toward(light, &origins, &mut got),
                Answered::All
            );
            assert_eq!(got, want, "toward {light} from {origins:?}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn shadow_packets_agree_with_brute_force(kind in kinds(), seed in any::<u64>()) {
        check_shadow_packets(&scene(kind, seed), seed, 40);
    }
}

/// The shadow bundles above do block and do get through, on every kind of
/// scene, so the property tests both answers.
#[test]
fn shadow_bundles_are_both_blocked_and_lit() {
    for (i, kind) in ALL_KINDS.into_iter().enumerate() {
        let shapes = scene(kind, 23 + i as u64);
        let grid = VoxelHashGrid::new(&shapes);
        let mut rng = Rng::new(99 + i as u64);
        let (mut blocked, mut lit) = (0, 0);
        for _ in 0..40 {
            let (light, origins) = shadow_bundle(&mut rng, &shapes);
            let mut got = vec![false; origins.len()];
            assert_eq!(
                grid.any_hits_toward(light, &origins, &mut got),
                Answered::All
            );
            blocked += got.iter().filter(|&&b| b).count();
            lit += got.iter().filter(|&&b| !b).count();
        }
        assert!(
            blocked > 50 && lit > 50,
            "{kind:?}: {blocked} blocked, {lit} lit"
        );
    }
}

/// `n` unit spheres at one point in front of the eye: every one lies in the
/// same cells, so a packet of eye rays through them tests all of them.
fn hot_cell(n: usize) -> Vec<Ellipsoid<f32>> {
    vec![Ellipsoid::new(Vec3::new(0.0, 0.0, -5.0), Vec3::ONE); n]
}

/// A packet whose candidates would cost more than the index's budget of
/// tests is given up, so that the renderer can look at its deadline between
/// single rays; well below the budget it is answered, and exactly.
#[test]
fn a_packet_over_a_hot_cell_gives_up_past_the_test_budget() {
    let budget = voxtrace::limits::PACKET_TESTS as usize;
    let dirs: Vec<Vec3> = (0..64)
        .map(|i| Vec3::new((i % 8) as f32 * 0.01, (i / 8) as f32 * 0.01, -1.0))
        .collect();
    for (spheres, expected) in [(budget / 64, Answered::All), (budget, Answered::GaveUp)] {
        let shapes = hot_cell(spheres);
        let (brute, grid) = (BruteForce::new(&shapes), VoxelHashGrid::new(&shapes));
        let mut hits = vec![None; dirs.len()];
        let answered = grid.closest_hits(Vec3::ZERO, &dirs, 1.0, f32::INFINITY, &mut hits);
        assert_eq!(answered, expected, "{spheres} spheres in one cell");
        if expected == Answered::All {
            for (d, hit) in dirs.iter().zip(&hits) {
                let want = brute.closest_hit(&Ray::new(Vec3::ZERO, *d), 1.0, f32::INFINITY);
                assert_eq!(*hit, want);
                assert!(want.is_some());
            }
        }
    }
}

/// Whatever the budget, a call that says it answered every ray answered
/// each exactly: giving up never leaves a wrong answer standing as a right
/// one. `gave_up` counts the calls given up.
fn check_budgeted_packets(shapes: &[Ellipsoid<f32>], seed: u64, tests: u64, gave_up: &mut usize) {
    let brute = BruteForce::new(shapes);
    let grid = VoxelHashGrid::new(shapes).with_packet_tests(tests);
    let mut rng = Rng::new(seed ^ 0xb4d6);
    for _ in 0..10 {
        let (origin, dirs) = bundle(&mut rng, shapes);
        let mut got = vec![None; dirs.len()];
        match grid.closest_hits(origin, &dirs, 0.0, f32::INFINITY, &mut got) {
            Answered::All => {
                for (d, hit) in dirs.iter().zip(&got) {
                    assert_eq!(
                        *hit,
                        brute.closest_hit(&Ray::new(origin, *d), 0.0, f32::INFINITY)
                    );
                }
            }
            Answered::GaveUp => *gave_up += 1,
        }
        let (light, origins) = shadow_bundle(&mut rng, shapes);
        let mut got = vec![false; origins.len()];
        match grid.any_hits_toward(light, &origins, &mut got) {
            Answered::All => {
                for (&o, &b) in origins.iter().zip(&got) {
                    assert_eq!(b, brute.any_hit(&Ray::new(o, light - o), 1.0));
                }
            }
            Answered::GaveUp => *gave_up += 1,
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn packets_answered_within_any_budget_are_exact(
        kind in kinds(),
        seed in any::<u64>(),
        tests in 1u64..400,
    ) {
        check_budgeted_packets(&scene(kind, seed), seed, tests, &mut 0);
    }
}

/// The budgets above both give up and answer, on every kind of scene.
#[test]
fn small_budgets_both_give_up_and_answer() {
    for (i, kind) in ALL_KINDS.into_iter().enumerate() {
        let shapes = scene(kind, 31 + i as u64);
        let (mut small, mut ample) = (0, 0);
        check_budgeted_packets(&shapes, 5, 4, &mut small);
        check_budgeted_packets(&shapes, 5, 1 << 40, &mut ample);
        assert!(
            small > 0 && ample == 0,
            "{kind:?}: {small} given up at 4 tests, {ample} at 2^40"
        );
    }
}

/// The grid with a light buffer for `light` answers every shadow ray toward
/// it as brute force does, in packets and one at a time; returns whether it
/// built the buffer.
fn check_light_buffer(shapes: &[Ellipsoid<f32>], light: Vec3, origins: &[Vec3]) -> bool {
    let brute = BruteForce::new(shapes);
    let grid = VoxelHashGrid::new(shapes).with_lights(&[light]);
    let want: Vec<bool> = origins
        .iter()
        .map(|&o| brute.any_hit(&Ray::new(o, light - o), 1.0))
        .collect();
    let mut got = vec![false; origins.len()];
    assert_eq!(
        grid.any_hits_toward(light, origins, &mut got),
        Answered::All
    );
    assert_eq!(got, want, "toward {light} from {origins:?}");
    for (&o, &want) in origins.iter().zip(&want) {
        assert_eq!(
            grid.any_hit_toward(light, o),
            want,
            "toward {light} from {o}"
        );
    }
    grid.light_buffers().lights == 1
}

/// Lights get buffers in turn while their bytes fit the index's budget: the
/// same lights, and bytes, as building each alone and keeping the longest
/// run of them that fits, and never more than the budget.
#[test]
fn light_buffers_stay_within_their_budget_light_by_light() {
    let mut rng = voxtrace::rng::Rng::new(11);
    let mut coordinate = || rng.range(-10.0, 10.0) as f32;
    let shapes: Vec<Ellipsoid<f32>> = (0..20_000)
        .map(|_| {
            let center = Vec3::new(coordinate(), coordinate(), coordinate());
            Ellipsoid::new(center, Vec3::splat(0.05))
        })
        .collect();
    let lights: Vec<Vec3> = (0..12)
        .map(|i| Vec3::new(30.0 - 5.0 * i as f32, 20.0, 40.0 - 3.0 * i as f32))
        .collect();
    let budget = (voxtrace::limits::LIGHT_BUFFER_BYTES_PER_SPHERE * shapes.len())
        .max(voxtrace::limits::LIGHT_BUFFER_MIN_BYTES);
    let alone: Vec<usize> = (lights.iter())
        .map(|&l| {
            VoxelHashGrid::new(&shapes)
                .with_lights(&[l])
                .light_buffers()
                .bytes
        })
        .collect();
    assert!(
        alone.iter().all(|&b| b > 0),
        "every light gets a buffer alone"
    );
    let mut want = (0, 0);
    for &bytes in &alone {
        if want.1 + bytes > budget {
            break;
        }
        want = (want.0 + 1, want.1 + bytes);
    }
    assert!(
        0 < want.0 && want.0 < lights.len(),
        "the budget cuts the run: {want:?}"
    );
    let together = VoxelHashGrid::new(&shapes)
        .with_lights(&lights)
        .light_buffers();
    assert_eq!((together.lights, together.bytes), want);
    assert!(together.bytes <= budget);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn light_buffers_agree_with_brute_force(kind in kinds(), seed in any::<u64>()) {
        let shapes = scene(kind, seed);
        let mut rng = Rng::new(seed ^ 0x11b);
        for _ in 0..8 {
            let (light, origins) = shadow_bundle(&mut rng, &shapes);
            check_light_buffer(&shapes, light, &origins);
        }
    }
}

/// The property above is not vacuous: on every kind of scene most lights get
/// a buffer, and its rays are both blocked and lit.
#[test]
fn light_buffers_are_built_and_answer_both_ways() {
    for (i, kind) in ALL_KINDS.into_iter().enumerate() {
        let shapes = scene(kind, 41 + i as u64);
        let mut rng = Rng::new(7 + i as u64);
        let (mut built, mut blocked, mut lit) = (0, 0, 0);
        for _ in 0..20 {
            let (light, origins) = shadow_bundle(&mut rng, &shapes);
            if check_light_buffer(&shapes, light, &origins) {
                built += 1;
                let grid = VoxelHashGrid::new(&shapes).with_lights(&[light]);
                for &o in &origins {
                    if grid.any_hit_toward(light, o) {
                        blocked += 1;
                    } else {
                        lit += 1;
                    }
                }
            }
        }
        assert!(
            built >= 10 && blocked >= 10 && lit >= 10,
            "{kind:?}: {built} buffers, {blocked} blocked, {lit} lit"
        );
    }
}

/// Spheres in a row seen end-on from the light share a texel, more of them
/// than a list keeps: rays from behind the kept ones go to the walk, and
/// every answer is still brute force's.
#[test]
fn light_buffer_lists_cut_short_fall_back_to_the_walk() {
    let light = Vec3::new(0.0, 0.0, 10.0);
    let mut shapes: Vec<Ellipsoid<f32>> = (0..200)
        .map(|i| Ellipsoid::new(Vec3::new(0.0, 0.0, -(i as f32) * 0.05), Vec3::splat(0.02)))
        .collect();
    // Spread elsewhere, so that the texels are small.
    let mut rng = Rng::new(5);
    shapes.extend(
        (0..400).map(|_| Ellipsoid::new(rng.point(5.0) - Vec3::Z * 5.0, Vec3::splat(0.02))),
    );
    let origins: Vec<Vec3> = (0..400)
        .map(|i| {
            let z = -(i as f32) * 0.025 - 0.011;
            Vec3::new(rng.range(-0.03, 0.03), rng.range(-0.03, 0.03), z)
        })
        .collect();
    assert!(check_light_buffer(&shapes, light, &origins));
}
