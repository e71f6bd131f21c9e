//! From a scene and an index to an image: camera rays, the two shading models,
//! recursion, and parallel rows.

mod camera;
mod deadline;
mod light_buffers;
mod region;
mod rules;
mod shading;

pub use camera::PixelSampler;
pub use deadline::{CancelToken, Deadline};
pub use region::{Region, RegionError};
pub use rules::Rules;

use crate::geometry::{Ellipsoid, Ray, Real, SurfacePoint, Vec3Ops, V3};
use crate::index::{Answered, BruteForce, LightBuffers, SphereIndex, VoxelHashGrid};
use crate::limits;
use crate::output::Image;
use crate::scene::{Dialect, Scene};
use deadline::{Stop, Stopped};
use glam::DVec3;
use rayon::prelude::*;
use shading::Tracer;
use std::fmt;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Which specular highlight to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpecularModel {
    /// `max(0, R·V)^n`, R the light mirrored about the normal (the classic model's own).
    Phong,
    /// `max(0, N·H)^n`, H halfway between light and viewer (the browser model's own).
    Blinn,
}

/// Which candidate search to use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IndexKind {
    /// The multi-resolution voxel hash grid, with a light buffer per light
    /// (as many as [`crate::limits::LIGHT_BUFFER_BYTES_PER_SPHERE`] allows,
    /// for renders whose eye rays hit at least half as many times as there
    /// are spheres) that answers shadow rays toward it.
    #[default]
    Grid,
    /// The grid alone: shadow rays walk it too (for measuring the buffers).
    Walk,
    /// Test every sphere (the exactness oracle).
    Brute,
}

#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Samples per pixel: 1 is the course's corner sample; more are stratified and jittered.
    pub spp: u32,
    /// Bounces of reflection/refraction; `None` uses the dialect's default.
    pub depth: Option<u32>,
    /// Overrides the dialect's specular model.
    pub specular: Option<SpecularModel>,
    /// Stop recursing once a ray's weight cannot change an 8-bit output value.
    pub adaptive_cutoff: bool,
    pub index: IndexKind,
    /// Which of the course's two rule sets to follow.
    pub rules: Rules,
    /// Recompute in f64 the f32 hit points of spheres whose reach dwarfs
    /// the point (`geometry::ellipsoid`); no effect in f64.
    pub refine: bool,
    /// Give up once this instant has passed ([`RenderError::TimedOut`]) or
    /// its token is cancelled ([`RenderError::Cancelled`]).
    pub deadline: Option<Deadline>,
    /// Render only this rectangle of the image (`None`: all of it).
    pub region: Option<Region>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            spp: 1,
            depth: None,
            specular: None,
            adaptive_cutoff: false,
            index: IndexKind::default(),
            rules: Rules::default(),
            refine: true,
            deadline: None,
            region: None,
        }
    }
}

impl RenderOptions {
    pub fn depth_for(&self, dialect: Dialect) -> u32 {
        self.depth.unwrap_or(match dialect {
            Dialect::Classic => limits::DEFAULT_CLASSIC_DEPTH,
            Dialect::Browser => limits::DEFAULT_BROWSER_DEPTH,
        })
    }
}

/// Rays traced, by why they were traced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    pub eye: u64,
    pub shadow: u64,
    pub reflection: u64,
    pub refraction: u64,
}

impl RayCounts {
    pub fn total(&self) -> u64 {
        self.eye + self.shadow + self.reflection + self.refraction
    }
}

impl std::ops::AddAssign for RayCounts {
    fn add_assign(&mut self, other: RayCounts) {
        self.eye += other.eye;
        self.shadow += other.shadow;
        self.reflection += other.reflection;
        self.refraction += other.refraction;
    }
}

#[derive(Clone, Copy, Debug, Default)]
pub struct RenderStats {
    pub rays: RayCounts,
    /// Of `rays`, those traced in packets (the eye rays of a tile, or its
    /// shadow rays toward one light, together).
    pub in_packets: RayCounts,
    /// Time to build the index.
    pub build_time: Duration,
    /// Time to trace every pixel.
    pub render_time: Duration,
    /// The index's light buffers (counted in `build_time`).
    pub light_buffers: LightBuffers,
}

impl RenderStats {
    pub fn mrays_per_second(&self) -> f64 {
        self.rays.total() as f64 / self.render_time.as_secs_f64().max(1e-9) / 1e6
    }
}

#[derive(Debug)]
pub struct Rendered {
    pub image: Image,
    pub stats: RenderStats,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RenderError {
    /// The render passed its deadline and was abandoned.
    TimedOut,
    /// The render's cancel token was cancelled.
    Cancelled,
    /// An option outside what the renderer accepts.
    BadOption(String),
    /// A region that is empty or not inside the image.
    BadRegion(RegionError),
}

impl fmt::Display for RenderError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RenderError::TimedOut => write!(f, "the render exceeded its time budget"),
            RenderError::Cancelled => write!(f, "the render was cancelled"),
            RenderError::BadOption(why) => write!(f, "{why}"),
            RenderError::BadRegion(why) => write!(f, "{why}"),
        }
    }
}

impl std::error::Error for RenderError {}

/// Called from the render threads with the number of rows finished so far.
pub type Progress<'a> = &'a (dyn Fn(u32) + Sync);

/// Renders `scene` in f32 with the index `options.index` names, on the
/// current rayon pool.
pub fn render_scene(
    scene: &Scene,
    options: &RenderOptions,
    progress: Progress,
) -> Result<Rendered, RenderError> {
    render_in::<f32>(scene, options, progress)
}

/// Renders in the precision `R`: f32 is the fast path, f64 the reference.
pub fn render_in<R: Real>(
    scene: &Scene,
    options: &RenderOptions,
    progress: Progress,
) -> Result<Rendered, RenderError> {
    check_options(options)?;
    let started = Instant::now();
    let shapes = shapes_of::<R>(scene);
    let index = match options.index {
        IndexKind::Grid => Box::new(grid_for(scene, options, &shapes)),
        kind => build_index(&shapes, &[], kind),
    };
    render_with(
        scene,
        &shapes,
        &*index,
        options,
        started.elapsed(),
        progress,
    )
}

/// The scene's spheres in the precision `R`, in id order (converted in
/// parallel, each thread writing its share in place).
fn shapes_of<R: Real>(scene: &Scene) -> Vec<Ellipsoid<R>> {
    scene
        .spheres
        .par_iter()
        .map(Ellipsoid::from_sphere)
        .collect()
}

/// The grid over `shapes` for a render of `scene`, with a light buffer per
/// light where the buffers pay for it ([`light_buffers::pay`]).
fn grid_for<R: Real>(
    scene: &Scene,
    options: &RenderOptions,
    shapes: &[Ellipsoid<R>],
) -> VoxelHashGrid<R> {
    let grid = VoxelHashGrid::new(shapes);
    let Ok(region) = region_of(scene, options) else {
        // Refused when the render starts.
        return grid;
    };
    let samples = region.pixels() * u64::from(options.spp);
    match light_buffers::pay(scene, region, samples, &grid, options.deadline.as_ref()) {
        true => grid.with_lights(&light_positions::<R>(scene)),
        false => grid,
    }
}

/// The scene's light positions in the precision `R`, as shading casts
/// shadow rays toward them.
pub(crate) fn light_positions<R: Real>(scene: &Scene) -> Vec<V3<R>> {
    (scene.lights.iter())
        .map(|l| V3::<R>::from_dvec3(l.position))
        .collect()
}

/// The index `kind` names, built over `shapes`, for shadow rays toward
/// `lights`. One dynamic call per ray is noise next to the walk and the
/// sphere tests behind it.
pub fn build_index<'s, R: Real>(
    shapes: &'s [Ellipsoid<R>],
    lights: &[V3<R>],
    kind: IndexKind,
) -> Box<dyn SphereIndex<R> + 's> {
    match kind {
        IndexKind::Grid => Box::new(VoxelHashGrid::new(shapes).with_lights(lights)),
        IndexKind::Walk => Box::new(VoxelHashGrid::new(shapes)),
        IndexKind::Brute => Box::new(BruteForce::new(shapes)),
    }
}

/// The nearest sphere along each pixel's corner eye ray (the spp-1 ray), row
/// by row from the top, searched with the index `kind` in the precision `R`.
/// It is what the renderer's first hit sees, without shading: the report's
/// hit-mismatch rate and the hard-case tests compare these maps.
pub fn eye_hit_map<R: Real>(scene: &Scene, kind: IndexKind) -> Vec<Option<u32>> {
    eye_hit_map_from::<R>(scene, kind, DVec3::ZERO)
}

/// [`eye_hit_map`] with the eye moved to `eye` (the image plane moves with
/// it), for checking that translating a whole scene leaves the map alone.
pub fn eye_hit_map_from<R: Real>(scene: &Scene, kind: IndexKind, eye: DVec3) -> Vec<Option<u32>> {
    let shapes = shapes_of::<R>(scene);
    let index = build_index(&shapes, &[], kind);
    let sampler = PixelSampler::new(&scene.camera, 1);
    let (width, height) = (scene.camera.width, scene.camera.height);
    let origin = V3::<R>::from_dvec3(eye);
    (0..width * height)
        .into_par_iter()
        .map(|i| first_hit(&*index, &sampler, origin, i % width, i / width).map(|hit| hit.sphere))
        .collect()
}

/// The first hit of the eye ray from `eye` through the centre of pixel
/// (x, y), as the renderer asks for it: the nearest beyond the image plane.
fn first_hit<R: Real, I: SphereIndex<R> + ?Sized>(
    index: &I,
    sampler: &PixelSampler,
    eye: V3<R>,
    x: u32,
    y: u32,
) -> Option<crate::index::Hit<R>> {
    let dir = sampler.direction(f64::from(x), f64::from(y));
    index.closest_hit(
        &Ray::new(eye, V3::<R>::from_dvec3(dir)),
        R::one(),
        R::infinity(),
    )
}

/// Refuses settings out of their bounds with the words the command line and
/// the service use for them ([`crate::bounded::OutOfRange`]).
fn check_options(options: &RenderOptions) -> Result<(), RenderError> {
    let within = |name: &str, value: u32, range: std::ops::RangeInclusive<u32>| {
        if range.contains(&value) {
            return Ok(());
        }
        let found = value.to_string();
        let name = name.to_owned();
        Err(RenderError::BadOption(
            crate::bounded::OutOfRange { name, range, found }.to_string(),
        ))
    };
    within("spp", options.spp, 1..=limits::MAX_SPP)?;
    match options.depth {
        Some(depth) => within("depth", depth, 0..=limits::MAX_DEPTH),
        None => Ok(()),
    }
}

/// Traces every pixel of `scene` against `index`, rows in parallel. The
/// output depends only on the inputs, not on the thread count or schedule.
pub fn render_with<R: Real, I: SphereIndex<R> + ?Sized>(
    scene: &Scene,
    shapes: &[Ellipsoid<R>],
    index: &I,
    options: &RenderOptions,
    build_time: Duration,
    progress: Progress,
) -> Result<Rendered, RenderError> {
    let stop = Stop::new(options.deadline.as_ref());
    let at = options.deadline.as_ref().and_then(Deadline::instant);
    let stop = &stop;
    std::thread::scope(|s| {
        // The timer that raises the stop flag at the deadline, so the rays
        // never read the clock.
        if let Some(at) = at {
            s.spawn(move || stop.expire_at(at));
        }
        let rendered = trace_all(scene, shapes, index, options, build_time, progress, stop);
        stop.end();
        rendered
    })
}

/// [`render_with`] under `stop`.
fn trace_all<R: Real, I: SphereIndex<R> + ?Sized>(
    scene: &Scene,
    shapes: &[Ellipsoid<R>],
    index: &I,
    options: &RenderOptions,
    build_time: Duration,
    progress: Progress,
    stop: &Stop,
) -> Result<Rendered, RenderError> {
    let started = Instant::now();
    let region = region_of(scene, options)?;
    let tracer = Tracer::new(scene, shapes, index, options, stop);
    let sampler = PixelSampler::new(&scene.camera, options.spp);
    let width = region.width() as usize;
    let mut rgb = vec![0u8; width * region.height() as usize * 3];
    let totals = Mutex::new(TracedRays::default());
    let rows_done = AtomicU32::new(0);
    rgb.par_chunks_mut(width * 3 * BAND_ROWS as usize)
        .enumerate()
        .for_each(|(band, out)| {
            let mut counts = TracedRays::default();
            let start = region.y0 + band as u32 * BAND_ROWS;
            let rows = start..(start + BAND_ROWS).min(region.y1);
            let columns = region.columns();
            render_band(
                &tracer,
                &sampler,
                columns,
                rows.clone(),
                out,
                &mut counts,
                stop,
            );
            // A poisoned lock only means another band panicked, which
            // propagates anyway; its counts are still sound to add to.
            *totals.lock().unwrap_or_else(|e| e.into_inner()) += counts;
            progress(rows_done.fetch_add(rows.len() as u32, Ordering::Relaxed) + rows.len() as u32);
        });
    match stop.outcome() {
        Some(Stopped::TimedOut) => return Err(RenderError::TimedOut),
        Some(Stopped::Cancelled) => return Err(RenderError::Cancelled),
        None => {}
    }
    let totals = totals.into_inner().unwrap_or_else(|e| e.into_inner());
    Ok(Rendered {
        image: Image::from_rgb(region.width(), region.height(), rgb),
        stats: RenderStats {
            rays: totals.rays,
            in_packets: totals.in_packets,
            build_time,
            render_time: started.elapsed(),
            light_buffers: index.light_buffers(),
        },
    })
}

/// The rectangle `options` asks for, checked against the image; the whole
/// image if none.
fn region_of(scene: &Scene, options: &RenderOptions) -> Result<Region, RenderError> {
    let (width, height) = (scene.camera.width, scene.camera.height);
    options
        .region
        .unwrap_or(Region::whole(width, height))
        .within(width, height)
        .map_err(RenderError::BadRegion)
}

/// Side of the square tiles of pixels whose eye rays are traced together:
/// a tile gives [`crate::index::PACKET_RAYS`] rays per sample.
pub const TILE: u32 = crate::index::PACKET_TILE_SIDE as u32;
/// Side of the squares a tile is cut into, listed one after another: each
/// square's rays are one group of a packet, with a cone of its own.
pub const GROUP: u32 = crate::index::PACKET_GROUP_SIDE as u32;
/// Rows per band, the unit of parallel work.
pub const BAND_ROWS: u32 = 32;
/// Columns per block of tiles, the pixels whose shadow rays are traced
/// together: a band is traced block by block, so a block is as tall as its
/// band, and as wide so that a full block is square.
pub const BLOCK_COLUMNS: u32 = BAND_ROWS;

/// The tiles of the band of rows `rows` (at most [`BAND_ROWS`] of them) in
/// the order they are traced, each as its pixels (column, row): tiles row by
/// row within blocks of [`BLOCK_COLUMNS`] columns, blocks left to right, and
/// a tile's pixels group by group ([`GROUP`]×[`GROUP`] squares, row by
/// row), row by row within a group.
/// Consecutive packets then stay close on the image, so the cells and
/// spheres one fetches are still in cache for the next, a tile row above or
/// below included; and each run of [`GROUP`]² pixels is a compact square.
pub fn tiles(width: u32, rows: std::ops::Range<u32>) -> impl Iterator<Item = Vec<(u32, u32)>> {
    tile_blocks(0..width, rows).flatten()
}

/// The tiles of [`tiles`], block by block: each item is the tiles of one
/// block of [`BLOCK_COLUMNS`] columns of the band, whose shadow rays are
/// traced together. `columns` are the image columns rendered (all of them,
/// or a region's).
pub fn tile_blocks(
    columns: std::ops::Range<u32>,
    rows: std::ops::Range<u32>,
) -> impl Iterator<Item = Vec<Vec<(u32, u32)>>> {
    let end = columns.end;
    columns.step_by(BLOCK_COLUMNS as usize).map(move |x0| {
        rows.clone()
            .step_by(TILE as usize)
            .flat_map(|y0| {
                (x0..(x0 + BLOCK_COLUMNS).min(end))
                    .step_by(TILE as usize)
                    .map(move |t0| tile_pixels(t0, y0, end, rows.end))
            })
            .collect()
    })
}

/// The pixels of the tile whose top-left corner (lowest column and row) is
/// (x0, y0), group by group, clipped to columns below `width` and rows below `end`.
fn tile_pixels(x0: u32, y0: u32, width: u32, end: u32) -> Vec<(u32, u32)> {
    let mut pixels = Vec::with_capacity((TILE * TILE) as usize);
    for gy in (0..TILE).step_by(GROUP as usize) {
        for gx in (0..TILE).step_by(GROUP as usize) {
            let (x, y) = (x0 + gx, y0 + gy);
            for row in y..(y + GROUP).min(end) {
                pixels.extend((x..(x + GROUP).min(width)).map(|column| (column, row)));
            }
        }
    }
    pixels
}

/// The rays a block, a band or a render traced: all of them, and those in
/// packets.
#[derive(Default)]
struct TracedRays {
    rays: RayCounts,
    in_packets: RayCounts,
}

impl std::ops::AddAssign for TracedRays {
    fn add_assign(&mut self, other: TracedRays) {
        self.rays += other.rays;
        self.in_packets += other.in_packets;
    }
}

/// Renders the band of rows `rows`, columns `columns`, into `out`, block by
/// block (see [`tile_blocks`]), until `stop` says to stop. The blocks are
/// traced in parallel: a band is too coarse a unit on its own, for where
/// the picture is costly in one band (a floor's reflections, a dense clump)
/// the last band would leave every thread but one idle while it finishes.
fn render_band<R: Real, I: SphereIndex<R> + ?Sized>(
    tracer: &Tracer<R, I>,
    sampler: &PixelSampler,
    columns: std::ops::Range<u32>,
    rows: std::ops::Range<u32>,
    out: &mut [u8],
    counts: &mut TracedRays,
    stop: &Stop,
) {
    let (x0, width) = (columns.start, columns.len() as u32);
    let blocks: Vec<Vec<Vec<(u32, u32)>>> = tile_blocks(columns, rows.clone()).collect();
    let colored: Vec<Option<(Vec<[u8; 3]>, TracedRays)>> = (blocks.par_iter())
        .map_init(BlockRays::default, |block, tiles| {
            render_block(tracer, sampler, tiles, block, stop)
        })
        .collect();
    for (tiles, colored) in blocks.iter().zip(colored) {
        let Some((colors, block_counts)) = colored else {
            return;
        };
        *counts += block_counts;
        for (&(x, y), color) in tiles.iter().flatten().zip(colors) {
            let at = (((y - rows.start) * width + x - x0) * 3) as usize;
            out[at..at + 3].copy_from_slice(&color);
        }
    }
}

/// The colours of one block's pixels (tile by tile, in each tile's pixel
/// order) and the rays they took, or None if told to stop. A tile's eye
/// rays go to the index together, sample by sample across its pixels
/// (neighbouring rays, which a packet walks at once); then the shadow rays
/// of the whole block's hits toward each light together (the index finds
/// the coherent packets among them); and each pixel then combines its own
/// samples in order, exactly as one pixel at a time would.
fn render_block<R: Real, I: SphereIndex<R> + ?Sized>(
    tracer: &Tracer<R, I>,
    sampler: &PixelSampler,
    tiles: &[Vec<(u32, u32)>],
    block: &mut BlockRays<R>,
    stop: &Stop,
) -> Option<(Vec<[u8; 3]>, TracedRays)> {
    let mut counts = TracedRays::default();
    block.aim(sampler, tiles);
    if !block.trace(tracer, &mut counts, stop) {
        return None;
    }
    let mut colors = Vec::with_capacity(tiles.iter().map(Vec::len).sum());
    for (tile, &start) in tiles.iter().zip(&block.starts) {
        for p in 0..tile.len() {
            if stop.now() {
                return None;
            }
            let samples = (0..sampler.spp() as usize).map(|s| start + s * tile.len() + p);
            let color = sampler.combine(samples.map(|i| block.shade(tracer, i, &mut counts.rays)));
            colors.push(to_bytes(color));
        }
    }
    Some((colors, counts))
}

/// The eye rays of one block of tiles, their hits, and what their shadow
/// rays found, reused block after block.
#[derive(Default)]
struct BlockRays<R: Real> {
    /// Tile by tile, sample-major within a tile: sample s of pixel p of a
    /// tile of n pixels starting at `start` is `dirs[start + s·n + p]`.
    dirs: Vec<V3<R>>,
    /// Where each tile's rays start.
    starts: Vec<usize>,
    hits: Vec<Option<crate::index::Hit<R>>>,
    surfaces: Vec<Option<SurfacePoint<R>>>,
    /// Row i (one entry per light) says which of hit i's shadow rays are blocked.
    blocked: Vec<bool>,
    samples: Vec<DVec3>,
}

impl<R: Real> BlockRays<R> {
    /// The eye rays of the tiles `tiles`.
    fn aim(&mut self, sampler: &PixelSampler, tiles: &[Vec<(u32, u32)>]) {
        let spp = sampler.spp() as usize;
        self.dirs.clear();
        self.starts.clear();
        for tile in tiles {
            let (start, n) = (self.dirs.len(), tile.len());
            self.starts.push(start);
            self.dirs.resize(start + n * spp, V3::<R>::ZERO);
            for (p, &(x, y)) in tile.iter().enumerate() {
                self.samples.clear();
                sampler.directions(x, y, &mut self.samples);
                for (s, &d) in self.samples.iter().enumerate() {
                    self.dirs[start + s * n + p] = V3::<R>::from_dvec3(d);
                }
            }
        }
    }

    /// Traces the eye rays tile by tile, then the shadow rays of all their
    /// hits toward each light. False if told to stop.
    fn trace<I: SphereIndex<R> + ?Sized>(
        &mut self,
        tracer: &Tracer<R, I>,
        counts: &mut TracedRays,
        stop: &Stop,
    ) -> bool {
        self.hits.clear();
        self.hits.resize(self.dirs.len(), None);
        let ends = self.starts.iter().skip(1).copied().chain([self.dirs.len()]);
        for (start, end) in self.starts.iter().copied().zip(ends) {
            let (dirs, hits) = (&self.dirs[start..end], &mut self.hits[start..end]);
            if !eye_hits(tracer, dirs, hits, &mut counts.in_packets, stop) {
                return false;
            }
        }
        self.surfaces.clear();
        self.surfaces.extend(
            self.dirs
                .iter()
                .zip(&self.hits)
                .map(|(&dir, hit)| hit.map(|hit| tracer.eye_surface(dir, hit))),
        );
        let TracedRays { rays, in_packets } = counts;
        tracer.eye_shadows(
            &self.hits,
            &self.surfaces,
            &mut self.blocked,
            rays,
            in_packets,
        )
    }

    /// The colour seen along eye ray i.
    fn shade<I: SphereIndex<R> + ?Sized>(
        &self,
        tracer: &Tracer<R, I>,
        i: usize,
        counts: &mut RayCounts,
    ) -> DVec3 {
        let hit = self.hits[i].zip(self.surfaces[i]);
        let lights = tracer.light_count();
        let shadows = &self.blocked[i * lights..(i + 1) * lights];
        tracer.shade_eye(self.dirs[i], hit, shadows, counts)
    }
}

/// The nearest hits of the eye rays `dirs` into `hits`, in packets (the
/// ones the index would cut the list into itself) or, where the index gave
/// up on a packet, one at a time ([`Stop::in_packets`]); `packed` counts the
/// rays traced in packets. `false` if told to stop.
fn eye_hits<R: Real, I: SphereIndex<R> + ?Sized>(
    tracer: &Tracer<R, I>,
    dirs: &[V3<R>],
    hits: &mut [Option<crate::index::Hit<R>>],
    packed: &mut RayCounts,
    stop: &Stop,
) -> bool {
    let traced = stop.in_packets(dirs.len(), |rays, together| {
        if together {
            tracer.eye_hits(&dirs[rays.clone()], &mut hits[rays])
        } else {
            hits[rays.start] = tracer.eye_hit(dirs[rays.start]);
            Answered::All
        }
    });
    traced.map(|n| packed.eye += n).is_some()
}

/// Clamps to [0, 1] and quantises as the course did: `floor(255·c)`.
/// (A NaN stays NaN through `clamp`, and `as u8` turns it into 0.)
fn to_bytes(color: glam::DVec3) -> [u8; 3] {
    color
        .to_array()
        .map(|c| (255.0 * c.clamp(0.0, 1.0)).floor() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_every_pixel_of_a_band_once() {
        for (width, rows) in [(1024, 0..32), (37, 64..91), (3, 5..6), (64, 0..32)] {
            let mut seen = vec![0u32; (width * rows.len() as u32) as usize];
            for tile in tiles(width, rows.clone()) {
                assert!(!tile.is_empty() && tile.len() <= (TILE * TILE) as usize);
                // A tile lies in a TILE × TILE square, its groups in turn.
                let (x0, y0) = (tile[0].0 / TILE * TILE, tile[0].1);
                let group =
                    |(x, y): (u32, u32)| ((y - y0) / GROUP) * (TILE / GROUP) + (x - x0) / GROUP;
                for &(x, y) in &tile {
                    assert!(x >= x0 && x < x0 + TILE && y >= y0 && y < y0 + TILE);
                    seen[((y - rows.start) * width + x) as usize] += 1;
                }
                // Group by group, row by row within a group.
                let order = |&p: &(u32, u32)| (group(p), p.1, p.0);
                assert!(tile.windows(2).all(|p| order(&p[0]) < order(&p[1])));
            }
            assert!(seen.iter().all(|&n| n == 1), "{width} {rows:?}");
        }
    }

    /// The single-ray path a slow scene switches to gives the packets'
    /// image and counts, byte for byte.
    #[test]
    fn single_eye_rays_give_the_image_packets_give() {
        let mut scenes =
            vec![crate::scene::parse(include_bytes!("../../scenes/testSample.txt")).unwrap()];
        scenes.extend(
            crate::tools::report::suite::generated()
                .into_iter()
                .filter(|s| s.name == "gen/glass_balls")
                .map(|s| s.scene),
        );
        assert_eq!(scenes.len(), 2);
        for scene in &scenes {
            for spp in [1, 3] {
                let options = RenderOptions {
                    spp,
                    ..RenderOptions::default()
                };
                let shapes = shapes_of::<f32>(scene);
                let index = build_index(&shapes, &light_positions::<f32>(scene), IndexKind::Grid);
                let render = |stop: &Stop| {
                    trace_all(
                        scene,
                        &shapes,
                        &*index,
                        &options,
                        Duration::ZERO,
                        &|_| {},
                        stop,
                    )
                    .unwrap()
                };
                let packets = render(&Stop::new(None));
                let stop = Stop::new(None);
                stop.force_single_rays();
                let single = render(&stop);
                assert_eq!(packets.image, single.image, "spp {spp}");
                assert_eq!(packets.stats.rays, single.stats.rays);
                // Eye rays and their shadow rays go in packets; the shadow
                // rays of reflected and refracted hits one at a time.
                let (p, s) = (packets.stats.in_packets, single.stats.in_packets);
                assert_eq!(p.eye, packets.stats.rays.eye);
                assert!(p.shadow > 0 && p.shadow <= packets.stats.rays.shadow);
                assert_eq!(s, RayCounts::default());
            }
        }
    }

    /// Where the index gives up on packets, their rays go one at a time
    /// and the image is the same, byte for byte.
    #[test]
    fn packets_the_index_gives_up_on_give_the_same_image() {
        let scene = crate::scene::parse(include_bytes!("../../scenes/thousands.txt")).unwrap();
        let shapes = shapes_of::<f32>(&scene);
        let options = RenderOptions::default();
        let render = |index: &VoxelHashGrid<f32>| {
            let stop = Stop::new(None);
            trace_all(
                &scene,
                &shapes,
                index,
                &options,
                Duration::ZERO,
                &|_| {},
                &stop,
            )
            .unwrap()
        };
        let whole = render(&VoxelHashGrid::new(&shapes));
        let starved = render(&VoxelHashGrid::new(&shapes).with_packet_tests(16));
        assert_eq!(whole.image, starved.image);
        assert_eq!(whole.stats.rays, starved.stats.rays);
        assert_eq!(whole.stats.in_packets.eye, whole.stats.rays.eye);
        let (eye, shadow) = (
            starved.stats.in_packets.eye,
            starved.stats.in_packets.shadow,
        );
        assert!(
            eye > 0 && eye < whole.stats.in_packets.eye,
            "{eye} eye rays in packets"
        );
        assert!(
            shadow > 0 && shadow < whole.stats.in_packets.shadow,
            "{shadow} shadow rays"
        );
    }

    /// Without reflection or refraction every ray is an eye ray or one of
    /// its shadow rays, and all of them go in packets.
    #[test]
    fn every_ray_of_a_scene_without_bounces_goes_in_packets() {
        let mut scene = crate::scene::parse(include_bytes!("../../scenes/testSample.txt")).unwrap();
        for sphere in &mut scene.spheres {
            (sphere.material.reflect, sphere.material.refract) = (0.0, 0.0);
        }
        let stats = render_scene(&scene, &RenderOptions::default(), &|_| {})
            .unwrap()
            .stats;
        assert!(stats.rays.shadow > 0);
        assert_eq!(stats.in_packets, stats.rays);
    }

    /// Light buffers are built where the render's eye hits reach half the
    /// spheres ([`light_buffers`]), and the images agree either way.
    #[test]
    fn light_buffers_are_built_where_the_eye_hits_reach_half_the_spheres() {
        // A wall of spheres filling the view (a few spheres would all be the grid's short list).
        let mut text = String::from(
            "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4 4\nBACK 0 0 0\nAMBIENT 0.2 0.2 0.2\n\
             LIGHT a 0 10 -5 1 1 1\nLIGHT b -10 0 0 0.5 0.5 0.5\n",
        );
        for i in 0..300 {
            let (x, y, z) = (i % 10, i / 10 % 10, i / 100);
            text += &format!(
                "SPHERE s{i} {} {} {} 0.45 0.45 0.45 0.5 0.5 0.5 0.2 0.6 0.4 0.3 40\n",
                x as f64 * 0.9 - 4.05,
                y as f64 * 0.9 - 4.05,
                -4.0 - z as f64 * 0.9
            );
        }
        let mut scene = crate::scene::parse(text).unwrap();
        let lights = scene.lights.len();
        let render = |scene: &Scene, spp| {
            let options = RenderOptions {
                spp,
                ..RenderOptions::default()
            };
            render_scene(scene, &options, &|_| {}).unwrap()
        };
        // 100 samples, then 200 (most of them hits), against 150 eye hits wanted.
        (scene.camera.width, scene.camera.height) = (10, 10);
        let (few, more) = (render(&scene, 1), render(&scene, 2));
        assert_eq!(few.stats.light_buffers.lights, 0);
        assert_eq!(more.stats.light_buffers.lights, lights);
        let walked = RenderOptions {
            spp: 2,
            index: IndexKind::Walk,
            ..RenderOptions::default()
        };
        let walked = render_scene(&scene, &walked, &|_| {}).unwrap();
        assert_eq!(walked.stats.light_buffers.lights, 0);
        assert_eq!(walked.image, more.image);
    }

    #[test]
    fn settings_out_of_bounds_are_refused_in_the_cli_s_words() {
        let scene = crate::scene::parse(include_bytes!("../../scenes/testSample.txt")).unwrap();
        let refused = |options: RenderOptions| match render_scene(&scene, &options, &|_| {}) {
            Err(RenderError::BadOption(why)) => why,
            other => panic!("not refused: {:?}", other.map(|r| r.stats)),
        };
        let spp = RenderOptions {
            spp: 0,
            ..RenderOptions::default()
        };
        assert_eq!(
            refused(spp),
            format!(
                "spp must be a whole number from 1 to {}, found \"0\"",
                limits::MAX_SPP
            )
        );
        let depth = RenderOptions {
            depth: Some(limits::MAX_DEPTH + 1),
            ..RenderOptions::default()
        };
        assert_eq!(
            refused(depth),
            format!(
                "depth must be a whole number from 0 to {}, found \"{}\"",
                limits::MAX_DEPTH,
                limits::MAX_DEPTH + 1
            )
        );
    }

    #[test]
    fn a_full_tile_is_square_groups_row_by_row() {
        let tile = tiles(64, 0..32).next().unwrap();
        assert_eq!(tile.len(), crate::index::PACKET_RAYS);
        let per_row = TILE / GROUP;
        for (g, group) in tile.chunks((GROUP * GROUP) as usize).enumerate() {
            let (gx, gy) = ((g as u32 % per_row) * GROUP, (g as u32 / per_row) * GROUP);
            for (i, &(x, y)) in group.iter().enumerate() {
                assert_eq!((x, y), (gx + i as u32 % GROUP, gy + i as u32 / GROUP));
            }
        }
    }
}
