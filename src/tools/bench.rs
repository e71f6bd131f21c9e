//! `voxtrace bench`: how fast the grid parses, builds and traces, against
//! brute force measured in the same run.
//!
//! Primary rays are the scene camera's eye rays (one per pixel, nearest hit
//! beyond the near plane); shadow rays are one per light per primary hit,
//! from the robustly offset hit point to the light. Each pass runs on all
//! threads of the current rayon pool and is timed alone (median of
//! [`REPEATS`]); building the rays is not timed. Brute force traces a random
//! sample of the pixels for [`BRUTE_SECONDS`] when a full pass would take
//! longer.

use super::gen::{generate, Distribution, GenOptions, Rng};
use crate::geometry::{spawn_origin, Ellipsoid, Ray, Vec3Ops, V3};
use crate::index::{
    compact_order, Answered, BruteForce, EmptySpace, Hit, SphereIndex, VoxelHashGrid, PACKET_RAYS,
};
use crate::render::{self, PixelSampler};
use crate::scene::{self, Scene, SceneError};
use rayon::prelude::*;
use serde::Serialize;
use std::fmt;
use std::time::{Duration, Instant};

/// Timed passes per figure; the median is reported.
pub const REPEATS: usize = 3;
/// How long brute force traces its sample of pixels.
pub const BRUTE_SECONDS: f64 = 1.5;
/// The built-in scenes: every distribution at these sphere counts.
pub const BUILTIN_COUNTS: [usize; 3] = [1_000, 100_000, 1_000_000];
/// Their image size.
pub const BUILTIN_RESOLUTION: u32 = 1024;
/// Their seed.
pub const BUILTIN_SEED: u64 = 1;

// The passes' tasks are kept small. Left to itself, rayon splits a pass
// called from within its pool into about two pieces a thread and splits a
// piece further only when another thread steals it: where the picture's
// cost lies in one part (a clump, a floor) one thread works through that
// piece alone while the others wait (docs/index.md, "The benchmark's
// passes in small tasks").

/// The most eye packets a task of the packet pass takes.
const PACKETS_A_TASK: usize = 4;
/// The most eye rays a task of the single-ray pass takes: as many as the
/// packet pass's task holds.
const RAYS_A_TASK: usize = PACKETS_A_TASK * PACKET_RAYS;
/// The most shadow batches (a block's rays toward one light) a task of the
/// shadow passes takes.
const BATCHES_A_TASK: usize = 1;

/// One scene's figures.
#[derive(Clone, Debug, Serialize)]
pub struct BenchResult {
    pub scene: String,
    pub spheres: usize,
    pub pixels: usize,
    pub parse_s: f64,
    pub build_s: f64,
    pub index_bytes_per_sphere: f64,
    pub levels: usize,
    /// The instructions the grid's kernels ran on: `baseline` (the build's
    /// own target) or `avx2`.
    pub vectors: String,
    /// Eye rays in packets of [`PACKET_RAYS`] (16×16 pixel tiles), as the renderer traces them.
    pub primary_mrays_s: f64,
    /// Eye rays one at a time.
    pub primary_single_mrays_s: f64,
    /// Seconds to build the light buffers of the scene's lights (beyond
    /// `build_s`), and their bytes per sphere, all lights together.
    pub light_buffer_s: f64,
    pub light_buffer_bytes_per_sphere: f64,
    /// Lights with a light buffer.
    pub light_buffers: usize,
    /// Shadow rays as the renderer traces them: those of one tile toward one
    /// light together, answered from the light buffers.
    pub shadow_mrays_s: f64,
    /// Shadow rays one at a time, from the light buffers.
    pub shadow_single_mrays_s: f64,
    /// Shadow rays as the renderer traces them, walking the grid (no light
    /// buffers: `--index walk`), together and one at a time.
    pub shadow_walk_mrays_s: f64,
    pub shadow_walk_single_mrays_s: f64,
    /// Primary rays when every cell costs a probe (no empty-space skipping).
    pub primary_mrays_s_probe_every_cell: Option<f64>,
    pub brute_primary_mrays_s: Option<f64>,
    /// How many pixels brute force traced to measure its speed.
    pub brute_sample: usize,
    pub speedup_vs_brute: Option<f64>,
    pub primary_hit_fraction: f64,
}

#[derive(Debug)]
pub enum BenchError {
    Read(String, std::io::Error),
    Scene(String, SceneError),
}

impl fmt::Display for BenchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BenchError::Read(path, e) => write!(f, "cannot read {path}: {e}"),
            BenchError::Scene(path, e) => write!(f, "{path}: {e}"),
        }
    }
}

impl std::error::Error for BenchError {}

/// The built-in scene `distribution` × `spheres`, as text.
pub fn builtin_scene(distribution: Distribution, spheres: usize) -> Vec<u8> {
    let options = GenOptions {
        spheres,
        distribution,
        seed: BUILTIN_SEED,
        width: BUILTIN_RESOLUTION,
        height: BUILTIN_RESOLUTION,
        ellipsoids: 0.0,
        glass: 0.0,
    };
    let mut text = Vec::with_capacity(spheres * 110 + 1024);
    generate(&options, &mut text).expect("writing to memory cannot fail");
    text
}

/// The names and texts of the built-in scenes, generated one at a time.
pub fn builtin_names() -> Vec<(String, Distribution, usize)> {
    let mut names = Vec::new();
    for spheres in BUILTIN_COUNTS {
        for d in [
            Distribution::Uniform,
            Distribution::Mixed,
            Distribution::Clustered,
            Distribution::Clumps,
            Distribution::Straddle,
        ] {
            names.push((format!("{}-{}", d.name(), spheres), d, spheres));
        }
    }
    names
}

/// Reads and benchmarks a scene file.
pub fn bench_file(path: &std::path::Path, baselines: bool) -> Result<BenchResult, BenchError> {
    let name = path.display().to_string();
    let text = std::fs::read(path).map_err(|e| BenchError::Read(name.clone(), e))?;
    bench_text(&name, &text, baselines)
}

fn median(mut samples: Vec<f64>) -> f64 {
    samples.sort_by(f64::total_cmp);
    samples[samples.len() / 2]
}

/// Runs `pass` [`REPEATS`] times and returns the median time in seconds.
fn timed(mut pass: impl FnMut()) -> f64 {
    median(
        (0..REPEATS)
            .map(|_| {
                let started = Instant::now();
                pass();
                started.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// Benchmarks one scene given as text; `baselines` adds the grid without
/// empty-space skipping and brute force.
pub fn bench_text(name: &str, text: &[u8], baselines: bool) -> Result<BenchResult, BenchError> {
    let started = Instant::now();
    let scene = scene::parse(text).map_err(|e| BenchError::Scene(name.to_owned(), e))?;
    let parse_s = started.elapsed().as_secs_f64();
    let shapes: Vec<Ellipsoid<f32>> = scene
        .spheres
        .par_iter()
        .map(Ellipsoid::from_sphere)
        .collect();
    let build_s = timed(|| drop(VoxelHashGrid::new(&shapes)));
    let grid = VoxelHashGrid::new(&shapes);
    let eye = eye_rays(&scene);

    // The passes write into answers made (and their pages touched) before
    // the timer starts, as Embree's benchmark does.
    let mut hits = vec![None; eye.len()];
    let dirs: Vec<V3<f32>> = eye.iter().map(|r| r.dir).collect();
    let primary_s = timed(|| primary_packets(&grid, &dirs, &mut hits));
    // The single rays' answers, which the probing baseline's pass writes
    // over: only their time is wanted.
    let mut single = vec![None; eye.len()];
    let single_s = timed(|| primary_pass(&grid, &eye, &mut single));
    let shadow = shadow_rays(&scene, &shapes, &eye, &hits);
    let walk_s = timed(|| {
        std::hint::black_box(shadow_packets(&grid, &shadow));
    });
    let single_walk_s = timed(|| {
        std::hint::black_box(shadow_pass(&grid, &shadow));
    });
    let lights = render::light_positions::<f32>(&scene);
    let started = Instant::now();
    let grid = grid.with_lights(&lights);
    let light_buffer_s = started.elapsed().as_secs_f64();
    let shadow_s = timed(|| {
        std::hint::black_box(shadow_packets(&grid, &shadow));
    });
    let single_shadow_s = timed(|| {
        std::hint::black_box(shadow_pass(&grid, &shadow));
    });
    let shadow_count = shadow.iter().map(|batch| batch.origins.len()).sum();
    let mrays = |rays: usize, seconds: f64| rays as f64 / seconds.max(1e-9) / 1e6;
    let probing = baselines.then(|| {
        let probing = VoxelHashGrid::new(&shapes).with_empty_space(EmptySpace::ProbeEveryCell);
        mrays(
            eye.len(),
            timed(|| primary_pass(&probing, &eye, &mut single)),
        )
    });
    let (brute_sample, brute) = if baselines {
        let (sample, seconds) = brute_rate(&shapes, &eye);
        (sample, Some(mrays(sample, seconds)))
    } else {
        (0, None)
    };
    let primary = mrays(eye.len(), primary_s);
    Ok(BenchResult {
        scene: name.to_owned(),
        spheres: shapes.len(),
        pixels: eye.len(),
        parse_s,
        build_s,
        index_bytes_per_sphere: grid.bytes() as f64 / shapes.len().max(1) as f64,
        levels: grid.levels().len(),
        vectors: grid.vectors().to_string(),
        primary_mrays_s: primary,
        primary_single_mrays_s: mrays(eye.len(), single_s),
        light_buffer_s,
        light_buffer_bytes_per_sphere: grid.light_buffers().bytes as f64
            / shapes.len().max(1) as f64,
        light_buffers: grid.light_buffers().lights,
        shadow_mrays_s: mrays(shadow_count, shadow_s),
        shadow_single_mrays_s: mrays(shadow_count, single_shadow_s),
        shadow_walk_mrays_s: mrays(shadow_count, walk_s),
        shadow_walk_single_mrays_s: mrays(shadow_count, single_walk_s),
        primary_mrays_s_probe_every_cell: probing,
        brute_primary_mrays_s: brute,
        brute_sample,
        speedup_vs_brute: brute.map(|b| primary / b),
        primary_hit_fraction: hits.iter().flatten().count() as f64 / eye.len().max(1) as f64,
    })
}

/// One eye ray per pixel, in the renderer's tile order ([`render::tiles`]),
/// so that each run of [`PACKET_RAYS`] rays is a tile (when the sides are
/// multiples of [`render::TILE`]).
fn eye_rays(scene: &Scene) -> Vec<Ray<f32>> {
    let sampler = PixelSampler::new(&scene.camera, 1);
    let (w, h) = (scene.camera.width, scene.camera.height);
    (0..h.div_ceil(render::BAND_ROWS))
        .into_par_iter()
        .flat_map_iter(|band| {
            let rows = band * render::BAND_ROWS..((band + 1) * render::BAND_ROWS).min(h);
            render::tiles(w, rows).flatten()
        })
        .map(|(x, y)| {
            let dir = sampler.direction(f64::from(x), f64::from(y));
            Ray::new(V3::<f32>::ZERO, V3::<f32>::from_dvec3(dir))
        })
        .collect()
}

/// Eye rays in packets: each run of [`PACKET_RAYS`] directions from the eye
/// traced together, their answers into `hits`.
fn primary_packets(index: &impl SphereIndex<f32>, dirs: &[V3<f32>], hits: &mut [Option<Hit<f32>>]) {
    dirs.par_chunks(PACKET_RAYS)
        .zip(hits.par_chunks_mut(PACKET_RAYS))
        .with_max_len(PACKETS_A_TASK)
        .for_each(|(dirs, out)| {
            // As the renderer does with a packet the index gives up on.
            if index.closest_hits(V3::<f32>::ZERO, dirs, 1.0, f32::INFINITY, out)
                == Answered::GaveUp
            {
                for (&dir, hit) in dirs.iter().zip(out) {
                    *hit = index.closest_hit(&Ray::new(V3::<f32>::ZERO, dir), 1.0, f32::INFINITY);
                }
            }
        });
}

/// Eye rays one at a time, their answers into `hits`.
fn primary_pass(index: &impl SphereIndex<f32>, rays: &[Ray<f32>], hits: &mut [Option<Hit<f32>>]) {
    (rays.par_iter().zip(hits))
        .with_max_len(RAYS_A_TASK)
        .for_each(|(ray, hit)| *hit = index.closest_hit(ray, 1.0, f32::INFINITY));
}

/// The shadow rays of one block's hits toward one light, as the renderer
/// hands them to the index.
struct ShadowBatch {
    light: V3<f32>,
    origins: Vec<V3<f32>>,
}

/// One ray per light per hit, from the offset hit point to the light (t = 1),
/// in batches of one block's rays toward one light ([`render::tile_blocks`]:
/// [`render::BLOCK_COLUMNS`] × [`render::BAND_ROWS`] consecutive eye rays
/// when the image's sides are multiples of them).
fn shadow_rays(
    scene: &Scene,
    shapes: &[Ellipsoid<f32>],
    eye: &[Ray<f32>],
    hits: &[Option<Hit<f32>>],
) -> Vec<ShadowBatch> {
    let lights = render::light_positions::<f32>(scene);
    let block = (render::BLOCK_COLUMNS * render::BAND_ROWS) as usize;
    eye.par_chunks(block)
        .zip(hits.par_chunks(block))
        .flat_map_iter(|(eye, hits)| {
            let surfaces: Vec<_> = eye
                .iter()
                .zip(hits)
                .filter_map(|(ray, hit)| {
                    hit.map(|h| shapes[h.sphere as usize].surface_point(ray, h.t))
                })
                .collect();
            lights
                .iter()
                .map(|&light| {
                    let origins: Vec<_> = surfaces
                        .iter()
                        .map(|s| spawn_origin(s, light - s.point))
                        .collect();
                    // In the order the renderer hands them to the index.
                    let order = compact_order::<f32>(&origins);
                    ShadowBatch {
                        light,
                        origins: order.iter().map(|&k| origins[k]).collect(),
                    }
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The shadow rays batch by batch, each batch's rays in packets of
/// [`PACKET_RAYS`], as the renderer hands them to the index.
fn shadow_packets(index: &impl SphereIndex<f32>, batches: &[ShadowBatch]) -> usize {
    batches
        .par_iter()
        .with_max_len(BATCHES_A_TASK)
        .map(|batch| {
            let mut blocked = vec![false; batch.origins.len()];
            for (origins, out) in batch
                .origins
                .chunks(PACKET_RAYS)
                .zip(blocked.chunks_mut(PACKET_RAYS))
            {
                if index.any_hits_toward(batch.light, origins, out) == Answered::GaveUp {
                    for (&o, b) in origins.iter().zip(out) {
                        *b = index.any_hit_toward(batch.light, o);
                    }
                }
            }
            blocked.iter().filter(|&&b| b).count()
        })
        .sum()
}

/// The shadow rays one at a time.
fn shadow_pass(index: &impl SphereIndex<f32>, batches: &[ShadowBatch]) -> usize {
    batches
        .par_iter()
        .with_max_len(BATCHES_A_TASK)
        .map(|batch| {
            batch
                .origins
                .iter()
                .filter(|&&o| index.any_hit_toward(batch.light, o))
                .count()
        })
        .sum()
}

/// Brute force's primary-ray speed: rays traced and seconds taken, over a
/// random sample of pixels when all of them would take too long.
fn brute_rate(shapes: &[Ellipsoid<f32>], eye: &[Ray<f32>]) -> (usize, f64) {
    let brute = BruteForce::new(shapes);
    let mut order: Vec<usize> = (0..eye.len()).collect();
    let mut rng = Rng::new(BUILTIN_SEED);
    for i in (1..order.len()).rev() {
        order.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
    }
    let budget = Duration::from_secs_f64(BRUTE_SECONDS);
    let started = Instant::now();
    let mut traced = 0;
    let chunk = 4 * rayon::current_num_threads();
    while traced < order.len() && started.elapsed() < budget {
        let end = (traced + chunk).min(order.len());
        order[traced..end].par_iter().for_each(|&i| {
            std::hint::black_box(brute.closest_hit(&eye[i], 1.0, f32::INFINITY));
        });
        traced = end;
    }
    (traced, started.elapsed().as_secs_f64())
}

/// The figures as a Markdown table.
pub fn markdown_table(results: &[BenchResult]) -> String {
    let mut out = String::from(
        "| scene | spheres | parse s | build s | index B/sphere | levels | light buffers s | B/sphere | primary Mrays/s | primary single-ray Mrays/s | shadow Mrays/s | shadow single-ray Mrays/s | shadow walked Mrays/s | primary, probe every cell | brute Mrays/s | speed-up |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in results {
        out += &format!(
            "| {} | {} | {:.3} | {:.3} | {:.1} | {} | {:.3} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} |\n",
            r.scene,
            r.spheres,
            r.parse_s,
            r.build_s,
            r.index_bytes_per_sphere,
            r.levels,
            r.light_buffer_s,
            r.light_buffer_bytes_per_sphere,
            r.primary_mrays_s,
            r.primary_single_mrays_s,
            r.shadow_mrays_s,
            r.shadow_single_mrays_s,
            r.shadow_walk_mrays_s,
            or_dash(r.primary_mrays_s_probe_every_cell, |v| format!("{v:.2}")),
            or_dash(r.brute_primary_mrays_s, |v| format!("{v:.4}")),
            or_dash(r.speedup_vs_brute, |v| format!("{v:.0}×")),
        );
    }
    out
}

fn or_dash(value: Option<f64>, show: impl Fn(f64) -> String) -> String {
    value.map_or_else(|| "—".to_owned(), show)
}
