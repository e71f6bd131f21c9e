//! `voxtrace gen`: random scenes for benchmarks and tests, streamed out in
//! the classic dialect so that ten million spheres need no more memory than
//! one.
//!
//! Every sphere lies inside the default camera's view frustum (eye at the
//! origin looking down −z through the plane z = −1 spanning [−1, 1]²), between
//! the depths [`Z_NEAR`] and [`Z_FAR`], and radii are chosen so that a primary
//! ray crosses about [`COVERAGE`] spheres on average: most rays hit something
//! whatever the sphere count.

pub use crate::rng::Rng;
use crate::scene::{write_light, write_sphere, Light, Material, Sphere};
use glam::DVec3;
use std::f64::consts::PI;
use std::io::{self, Write};

/// The nearest depth a sphere centre may have.
pub const Z_NEAR: f64 = 2.0;
/// The farthest.
pub const Z_FAR: f64 = 50.0;
/// Fraction of the frustum's half-width the centres stay within.
const WIDTH: f64 = 0.95;
/// Mean number of spheres (or, clustered, clumps) a primary ray crosses.
const COVERAGE: f64 = 4.0;
/// Ratio of the largest to the smallest radius of a mixed scene.
const MIXED_DECADES: f64 = 3.0;
/// Fraction of a clump's volume its spheres fill.
const CLUMP_FILL: f64 = 0.2;
/// The range of clump radii of [`Distribution::Clumps`].
const CLUMP_RADII: (f64, f64) = (0.15, 1.0);
/// The range of fills of its clumps: sphere sizes differ up to (hi/lo)^⅓ ≈
/// 2× from this alone, and up to 10× with the radii and populations.
const CLUMP_FILLS: (f64, f64) = (0.02, 0.3);
/// Fraction of its spheres strewn through the frustum as dust.
const DUST: f64 = 0.02;
/// The floor sphere's radius, and how far below the eye its top lies.
const FLOOR_RADIUS: f64 = 1000.0;
const FLOOR_DROP: f64 = 3.0;

/// How sphere sizes and positions are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Distribution {
    /// Uniform in the frustum, radii within ±20 % of one size.
    Uniform,
    /// Uniform in the frustum, radii log-uniform over three decades.
    Mixed,
    /// Dense round clumps (√n of them) in empty space.
    Clustered,
    /// About ∛n clumps of very unequal population (weights u³) and radii
    /// (log-uniform over [`CLUMP_RADII`]), each with its own sphere size from
    /// its own fill, 2 % dust through the frustum, and a floor sphere of
    /// radius 1000 under it all.
    Clumps,
    /// Like uniform, but radii within ±20 % of a size whose diameter is a
    /// power of four: where fixed size bands would split them in two.
    Straddle,
}

impl Distribution {
    /// Its name (see [`crate::names`]).
    pub fn name(self) -> &'static str {
        crate::names::Named::name(self)
    }
}

#[derive(Clone, Debug)]
pub struct GenOptions {
    pub spheres: usize,
    pub distribution: Distribution,
    pub seed: u64,
    pub width: u32,
    pub height: u32,
    /// Fraction of spheres stretched into ellipsoids.
    pub ellipsoids: f64,
    /// Fraction of spheres made of glass.
    pub glass: f64,
}

/// The lights every generated scene has (three, above and around the view).
pub fn lights() -> [Light; 3] {
    let light = |x, y, z, i| Light {
        position: DVec3::new(x, y, z),
        intensity: DVec3::splat(i),
    };
    [
        light(-30.0, 40.0, 10.0, 0.6),
        light(35.0, 25.0, -10.0, 0.4),
        light(0.0, -20.0, -60.0, 0.3),
    ]
}

/// The frustum's volume between the two depths.
fn frustum_volume() -> f64 {
    (2.0 * WIDTH).powi(2) * (Z_FAR.powi(3) - Z_NEAR.powi(3)) / 3.0
}

/// The radius at which `count` balls spread through the frustum are crossed
/// `coverage` times by a ray on average: count·πr²·L / V = coverage.
fn covering_radius(count: f64, coverage: f64) -> f64 {
    (coverage * frustum_volume() / (count * PI * (Z_FAR - Z_NEAR))).sqrt()
}

/// A point uniform in the frustum's volume: depth with density ∝ z².
fn frustum_point(rng: &mut Rng) -> DVec3 {
    let (a, b) = (Z_NEAR.powi(3), Z_FAR.powi(3));
    let z = (a + (b - a) * rng.unit()).cbrt();
    let half = WIDTH * z;
    DVec3::new(rng.range(-half, half), rng.range(-half, half), -z)
}

/// A point uniform in the unit ball.
fn ball_point(rng: &mut Rng) -> DVec3 {
    loop {
        let p = DVec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        if p.length_squared() <= 1.0 {
            return p;
        }
    }
}

/// `x` to `digits` significant decimal digits, so the file stays short.
fn round_to(x: f64, digits: i32) -> f64 {
    if x == 0.0 {
        return 0.0;
    }
    let scale = 10f64.powi(digits - 1 - x.abs().log10().floor() as i32);
    (x * scale).round() / scale
}

/// One clump of [`Distribution::Clumps`].
struct Clump {
    centre: DVec3,
    radius: f64,
    sphere_radius: f64,
    /// The clump's share of the spheres, summed over it and the clumps before it.
    cumulative_weight: f64,
}

/// Places spheres one at a time; holds only the clumps in memory.
struct Placer {
    distribution: Distribution,
    radius: f64,
    clumps: Vec<DVec3>,
    clump_radius: f64,
    sized_clumps: Vec<Clump>,
}

impl Placer {
    fn new(options: &GenOptions, rng: &mut Rng) -> Self {
        let n = options.spheres.max(1) as f64;
        let mut placer = Placer {
            distribution: options.distribution,
            radius: covering_radius(n, COVERAGE),
            clumps: Vec::new(),
            clump_radius: 0.0,
            sized_clumps: Vec::new(),
        };
        match options.distribution {
            Distribution::Uniform => {}
            Distribution::Mixed => {
                // Log-uniform r over [a, k·a] has E[r²] = a²(k² − 1)/(2 ln k);
                // choose a so that E[r²] is the covering radius squared.
                let k = 10f64.powf(MIXED_DECADES);
                placer.radius /= ((k * k - 1.0) / (2.0 * k.ln())).sqrt();
            }
            Distribution::Clustered => {
                let count = n.sqrt().round().max(1.0);
                placer.clump_radius = covering_radius(count, COVERAGE / 2.0);
                // Whole clumps in front of the near depth.
                let nearest = Z_NEAR + placer.clump_radius;
                placer.clumps = (0..count as usize)
                    .map(|_| {
                        let p = frustum_point(rng);
                        DVec3::new(p.x, p.y, p.z.min(-nearest))
                    })
                    .collect();
                let per_clump = n / count;
                placer.radius = placer.clump_radius * (CLUMP_FILL / per_clump).cbrt();
            }
            Distribution::Clumps => {
                placer.sized_clumps = sized_clumps(n * (1.0 - DUST), rng);
                placer.radius = covering_radius(n * DUST, COVERAGE / 8.0);
            }
            Distribution::Straddle => {
                // The nearest diameter 4^k to the covering one.
                let k = (2.0 * placer.radius).log(4.0).round();
                placer.radius = 0.5 * 4f64.powf(k);
            }
        }
        placer
    }

    /// Centre and radius of the next sphere.
    fn place(&self, rng: &mut Rng) -> (DVec3, f64) {
        match self.distribution {
            Distribution::Uniform => (frustum_point(rng), self.radius * rng.range(0.8, 1.2)),
            Distribution::Mixed => {
                let decades = MIXED_DECADES * rng.unit();
                (frustum_point(rng), self.radius * 10f64.powf(decades))
            }
            Distribution::Clustered => {
                let clump = self.clumps[(rng.next_u64() % self.clumps.len() as u64) as usize];
                let centre = clump + ball_point(rng) * self.clump_radius;
                (centre, self.radius * rng.range(0.8, 1.2))
            }
            Distribution::Clumps => {
                if rng.unit() < DUST {
                    return (frustum_point(rng), self.radius * rng.range(0.8, 1.2));
                }
                let u = rng.unit();
                let k = self
                    .sized_clumps
                    .partition_point(|c| c.cumulative_weight <= u)
                    .min(self.sized_clumps.len() - 1);
                let clump = &self.sized_clumps[k];
                let centre = clump.centre + ball_point(rng) * clump.radius;
                (centre, clump.sphere_radius * rng.range(0.8, 1.2))
            }
            Distribution::Straddle => (frustum_point(rng), self.radius * rng.range(0.8, 1.2)),
        }
    }
}

/// ∛n clumps for `spheres` spheres: populations by weights u³, radii
/// log-uniform, each clump's sphere size set by its own fill.
fn sized_clumps(spheres: f64, rng: &mut Rng) -> Vec<Clump> {
    let count = spheres.cbrt().round().max(1.0) as usize;
    let log = |(lo, hi): (f64, f64), rng: &mut Rng| lo * (hi / lo).powf(rng.unit());
    let drafts: Vec<(DVec3, f64, f64, f64)> = (0..count)
        .map(|_| {
            let radius = log(CLUMP_RADII, rng);
            let p = frustum_point(rng);
            let centre = DVec3::new(p.x, p.y, p.z.min(-(Z_NEAR + radius)));
            (centre, radius, log(CLUMP_FILLS, rng), rng.unit().powi(3))
        })
        .collect();
    let total: f64 = drafts
        .iter()
        .map(|d| d.3)
        .sum::<f64>()
        .max(f64::MIN_POSITIVE);
    let mut cumulative = 0.0;
    drafts
        .into_iter()
        .map(|(centre, radius, fill, weight)| {
            cumulative += weight / total;
            // m balls of radius s fill `fill` of the clump: m·s³ = fill·R³.
            let members = (spheres * weight / total).max(1.0);
            Clump {
                centre,
                radius,
                sphere_radius: radius * (fill / members).cbrt(),
                cumulative_weight: cumulative,
            }
        })
        .collect()
}

fn material(rng: &mut Rng, glass: bool) -> Material {
    let mut color = DVec3::new(rng.unit(), rng.unit(), rng.unit()).map(|c| round_to(c, 2));
    if glass {
        color = DVec3::splat(0.1);
    }
    Material {
        color,
        ambient: 0.2,
        diffuse: if glass { 0.1 } else { 0.7 },
        specular: 0.5,
        reflect: if glass || rng.unit() < 0.2 { 0.2 } else { 0.0 },
        shininess: 50.0,
        refract: if glass { 0.8 } else { 0.0 },
        ior: if glass { 0.67 } else { 1.0 },
    }
}

/// Writes a whole scene to `out`, one line at a time.
pub fn generate(options: &GenOptions, out: &mut impl Write) -> io::Result<()> {
    let mut rng = Rng::new(options.seed);
    writeln!(
        out,
        "# voxtrace gen: {} {} spheres, seed {}",
        options.distribution.name(),
        options.spheres,
        options.seed
    )?;
    writeln!(out, "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1")?;
    writeln!(out, "RES {} {}", options.width, options.height)?;
    writeln!(out, "BACK 0.05 0.05 0.1\nAMBIENT 0.4 0.4 0.4")?;
    for (i, light) in lights().iter().enumerate() {
        write_light(out, &format!("l{i}"), light)?;
    }
    let placer = Placer::new(options, &mut rng);
    let mut first = 0;
    if options.distribution == Distribution::Clumps && options.spheres > 0 {
        let floor = Sphere {
            center: DVec3::new(0.0, -FLOOR_RADIUS - FLOOR_DROP, -(Z_NEAR + Z_FAR) / 2.0),
            scale: DVec3::splat(FLOOR_RADIUS),
            material: material(&mut rng, false),
        };
        write_sphere(out, "floor", &floor)?;
        first = 1;
    }
    for i in first..options.spheres {
        let (centre, radius) = placer.place(&mut rng);
        let mut scale = DVec3::splat(radius);
        if rng.unit() < options.ellipsoids {
            // Squash two axes, keeping the bounding radius.
            scale.y *= rng.range(0.3, 1.0);
            scale.z *= rng.range(0.3, 1.0);
        }
        let glass = rng.unit() < options.glass;
        let sphere = Sphere {
            center: centre.map(|c| round_to(c, 7)),
            scale: scale.map(|s| round_to(s, 4)),
            material: material(&mut rng, glass),
        };
        write_sphere(out, &format!("s{i}"), &sphere)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene;

    fn options(distribution: Distribution, spheres: usize) -> GenOptions {
        GenOptions {
            spheres,
            distribution,
            seed: 3,
            width: 64,
            height: 48,
            ellipsoids: 0.3,
            glass: 0.1,
        }
    }

    #[test]
    fn generated_scenes_parse_and_lie_in_the_view() {
        for d in [
            Distribution::Uniform,
            Distribution::Mixed,
            Distribution::Clustered,
            Distribution::Clumps,
            Distribution::Straddle,
        ] {
            let mut text = Vec::new();
            generate(&options(d, 2000), &mut text).unwrap();
            let scene = scene::parse(&text).unwrap();
            assert_eq!(scene.spheres.len(), 2000);
            assert_eq!(scene.lights.len(), 3);
            assert_eq!((scene.camera.width, scene.camera.height), (64, 48));
            for s in scene
                .spheres
                .iter()
                .filter(|s| s.bounding_radius() < FLOOR_RADIUS)
            {
                let c = s.center;
                assert!(c.z < -1.0, "in front of the near plane: {c}");
                assert!(c.x.abs() < -c.z + 10.0 && c.y.abs() < -c.z + 10.0, "{c}");
            }
            let radii: Vec<f64> = scene.spheres.iter().map(|s| s.bounding_radius()).collect();
            let (lo, hi) = radii
                .iter()
                .fold((f64::MAX, 0f64), |(lo, hi), &r| (lo.min(r), hi.max(r)));
            match d {
                Distribution::Mixed => assert!(hi / lo > 300.0, "{lo} {hi}"),
                Distribution::Clumps => assert!(hi == FLOOR_RADIUS, "{lo} {hi}"),
                _ => assert!(hi / lo < 1.6, "{lo} {hi}"),
            }
            assert!(scene.spheres.iter().any(|s| s.material.refract > 0.0));
            assert!(scene.spheres.iter().any(|s| s.scale.y != s.scale.x));
        }
    }

    #[test]
    fn clumps_have_sizes_of_their_own_and_straddle_sits_on_a_power_of_four() {
        let radii = |d: Distribution| {
            let mut text = Vec::new();
            generate(&options(d, 20_000), &mut text).unwrap();
            let scene = scene::parse(&text).unwrap();
            let mut r: Vec<f64> = scene.spheres.iter().map(|s| s.scale.x).collect();
            r.sort_by(f64::total_cmp);
            r
        };
        let clumps = radii(Distribution::Clumps);
        assert_eq!(clumps.last(), Some(&FLOOR_RADIUS));
        // Sphere sizes across clumps span far more than one clump's ±20 %.
        let (p5, p95) = (clumps[clumps.len() / 20], clumps[clumps.len() * 19 / 20]);
        assert!(p95 / p5 > 3.0, "{p5} {p95}");
        let straddle = radii(Distribution::Straddle);
        let edge = 4f64.powf((2.0 * straddle[straddle.len() / 2]).log(4.0).round());
        let below = straddle.iter().filter(|&&r| 2.0 * r < edge).count();
        assert!(below > 5_000 && below < 15_000, "{below} below {edge}");
    }

    #[test]
    fn the_same_seed_gives_the_same_bytes() {
        let mut a = Vec::new();
        let mut b = Vec::new();
        generate(&options(Distribution::Clustered, 100), &mut a).unwrap();
        generate(&options(Distribution::Clustered, 100), &mut b).unwrap();
        assert_eq!(a, b);
    }
}
