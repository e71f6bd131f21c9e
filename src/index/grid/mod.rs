//! The multi-resolution voxel hash grid.
//!
//! Spheres are split into levels by size (see [`build`] for the rule). Each
//! level is a uniform grid over the bounding box of its own spheres, stored
//! sparsely: a hash table of occupied regions of 4×4×4 blocks, whose masks
//! lead to the occupied 4×4×4 blocks of cells ([`table`]), whose masks lead
//! to the occupied cells, each a run in one flat array of sphere ids (CSR),
//! each id with the octants of its cell its sphere overlaps ([`octant`]).
//! A ray walks each level with Amanatides & Woo's 3D-DDA ([`walk`]),
//! coarsest level first, jumps over empty blocks in one step, and in a cell
//! of several spheres tests only those in the octants it crosses. On a scene
//! of several levels in clumps, a single ray first asks the [`gate`] where
//! their space begins along it, and walks them from there, or not at all. Eye rays
//! of a tile ([`packet`]) and shadow rays from a tile toward one light
//! ([`shadow`]) walk each level together, slab by slab ([`slab`]).
//!
//! Exactness: every sphere is tested with the very [`Ellipsoid::intersect`]
//! brute force uses, under the same (t, id) order, and the walk visits every
//! cell a rounded hit could lie in (see the pad and slack in [`build`]), so the
//! grid returns exactly the sphere and t that [`super::BruteForce`] returns.
//! The walks also reach one step of `R` past the t they search to (and
//! start one below their t_min; `search_end` and `search_start` say why).

mod build;
mod cone;
mod copies;
mod gate;
mod light_buffer;
mod occupancy;
mod octant;
mod packet;
mod ray_set;
mod seek;
mod shadow;
mod slab;
mod slopes;
mod table;
mod vectors;
mod walk;

use super::{Answered, Hit, LightBuffers, SphereIndex};
use crate::geometry::{Ellipsoid, Ray, Real, V3};
use copies::Copies;
use gate::Gate;
use glam::DVec3;
use light_buffer::{LightBuffer, NoBuffer};
use octant::Octants;
pub use packet::{
    GROUP_SIDE as PACKET_GROUP_SIDE, RAYS as PACKET_RAYS, TILE_SIDE as PACKET_TILE_SIDE,
};
use seek::Nearest;
use table::BlockTable;
pub use vectors::Vectors;

/// How a ray crosses space no sphere occupies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum EmptySpace {
    /// One table probe per 4×4×4 block: empty blocks are crossed in one step.
    #[default]
    SkipBlocks,
    /// One table probe per cell, empty or not (kept to measure what skipping gains).
    ProbeEveryCell,
}

/// One size class: a sparse uniform grid over its spheres' bounding box.
pub struct Level {
    /// Cell side length, a power of two.
    cell: f64,
    /// `1 / cell`, exact: multiplying by it divides by the cell.
    per_cell: f64,
    /// The low corner of cell (0, 0, 0).
    origin: DVec3,
    /// Cells per axis.
    dims: [i64; 3],
    /// The high corner of the level's box: `origin + dims·cell`.
    far: [f64; 3],
    /// How far (in distance along a ray) a rounded hit of one of this level's
    /// spheres may lie before the cell the walk finds it in.
    slack: f64,
    /// Which blocks and cells are occupied (see [`table`]).
    table: BlockTable,
    /// How far empty space reaches around each group of blocks, densely.
    occupancy: occupancy::Occupancy,
    /// Occupied cell i holds `ids[cell_start[i]..cell_start[i + 1]]`, each
    /// with the octants of the cell its sphere's reach box overlaps at the
    /// same place of `octants` (empty on a level whose cells list few
    /// spheres: [`octant::LISTED_FOR_OCTANTS`]).
    cell_start: Vec<u32>,
    ids: Vec<u32>,
    octants: Vec<Octants>,
}

/// A summary of one level, for reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelInfo {
    pub cell: f64,
    pub dims: [i64; 3],
    pub occupied_cells: usize,
    pub references: usize,
}

impl Level {
    fn bytes(&self) -> usize {
        self.table.bytes()
            + self.occupancy.bytes()
            + 4 * (self.cell_start.len() + self.ids.len())
            + self.octants.len()
    }

    /// Where occupied cell `cell`'s references lie in `ids` (and `octants`).
    #[inline(always)]
    fn references(&self, cell: usize) -> std::ops::Range<usize> {
        self.cell_start[cell] as usize..self.cell_start[cell + 1] as usize
    }

    #[inline(always)]
    fn candidates(&self, cell: usize) -> &[u32] {
        &self.ids[self.references(cell)]
    }
}

pub struct VoxelHashGrid<R: Real> {
    /// The spheres in the order the levels' cells list them ([`copies`]).
    spheres: Copies<R>,
    /// The few largest spheres, which every ray tests before any level
    /// (positions in `spheres`).
    short: Vec<u32>,
    /// Coarsest first: big spheres bound the search of the small ones.
    levels: Vec<Level>,
    /// Where a single ray first meets any level's occupied space, for
    /// scenes of several levels ([`gate`]).
    gate: Option<Gate>,
    empty_space: EmptySpace,
    /// Which compiled instance of the kernels runs: never one the CPU
    /// lacks ([`Vectors`]).
    vectors: Vectors,
    /// Candidate tests one call for many rays may make ([`TestBudget`]).
    packet_tests: u64,
    lights: Vec<LightBuffer<R>>,
}

/// The t (in f64) a walk for hits whose rounded t is at most `t` must
/// reach: one step of `R` beyond `t`. A hit's t is rounded to `R`, so a
/// sphere whose rounded t ties the best one's, and whose lower id wins the
/// tie, may truly lie half a step beyond it, which on a ray much longer than
/// the spheres are wide (an origin far from them) spans several cells.
#[inline(always)]
fn search_end<R: Real>(t: R) -> f64 {
    t.next_up().to_f64()
}

/// The t a walk for hits whose rounded t is at least `t` starts from: one
/// step of `R` before it, for the same reason as [`search_end`].
#[inline(always)]
fn search_start<R: Real>(t: R) -> f64 {
    t.next_down().to_f64()
}

/// What a walk spends its candidate tests from.
pub(super) trait Tests {
    fn spend(&mut self, tests: u64);
}

/// The candidate tests one call for many rays may still make (see
/// [`Answered`]). A lane test of a group counts one, as does one ray's test.
#[derive(Clone, Copy, Debug)]
pub(super) struct TestBudget {
    left: u64,
}

impl TestBudget {
    pub(super) fn new(tests: u64) -> Self {
        TestBudget { left: tests }
    }

    #[inline(always)]
    pub(super) fn spent(&self) -> bool {
        self.left == 0
    }
}

impl Tests for TestBudget {
    #[inline(always)]
    fn spend(&mut self, tests: u64) {
        self.left = self.left.saturating_sub(tests);
    }
}

/// What a ray traced on its own spends from: nothing is counted.
struct Uncounted;

impl Tests for Uncounted {
    #[inline(always)]
    fn spend(&mut self, _: u64) {}
}

impl<R: Real> VoxelHashGrid<R> {
    /// What the levels may hold per sphere: half the index's bytes per
    /// sphere. The copies of the spheres take 24 of the rest in f32, as
    /// renders keep them (a grid in f64, as `report`'s reference renders
    /// keep it, holds twice that); the levels are held to 32 all the same,
    /// since the finer cells a wider share would keep on spheres packed on
    /// surfaces or in strands trace slower (docs/index.md, "Index bytes
    /// within 64 a sphere").
    const LEVEL_BYTES_PER_SPHERE: usize = crate::limits::INDEX_BYTES_PER_SPHERE / 2;

    /// Builds the grid in parallel on the current rayon pool.
    pub fn new(shapes: &[Ellipsoid<R>]) -> Self {
        let build::Built {
            levels,
            short,
            order,
            bound,
        } = build::levels(shapes, Self::LEVEL_BYTES_PER_SPHERE);
        let spheres = Copies::new(shapes, order, &bound);
        VoxelHashGrid {
            gate: Gate::over(&levels, spheres.len()),
            spheres,
            short,
            levels,
            empty_space: EmptySpace::default(),
            vectors: Vectors::detect(),
            packet_tests: crate::limits::PACKET_TESTS,
            lights: Vec::new(),
        }
    }

    /// The same grid with a light buffer for each of `lights`.
    ///
    /// Buffers are built light by light (each in parallel) while their
    /// bytes stay within [`crate::limits::LIGHT_BUFFER_BYTES_PER_SPHERE`] (or
    /// [`crate::limits::LIGHT_BUFFER_MIN_BYTES`] in all): the first light
    /// whose lists, counted, would not fit in what is left gets none, and
    /// neither do the lights after it, so no buffer is filled only to be
    /// dropped and the bound holds while they are built too. Shadow rays
    /// toward the other lights walk the grid. A light whose buffer would
    /// be tested in full by too many rays gets none either.
    pub fn with_lights(mut self, lights: &[V3<R>]) -> Self {
        let budget = (crate::limits::LIGHT_BUFFER_BYTES_PER_SPHERE * self.spheres.len())
            .max(crate::limits::LIGHT_BUFFER_MIN_BYTES);
        let mut used = 0;
        let mut scratch = light_buffer::Scratch::default();
        let is_short = light_buffer::short_marks(self.spheres.len(), &self.short);
        let farthest = light_buffer::farthest_from(&self.spheres, &is_short, lights);
        for (&light, farthest) in lights.iter().zip(farthest) {
            if self.light_buffer(light).is_some() {
                continue;
            }
            let room = budget - used;
            let spheres = &self.spheres;
            match LightBuffer::new(spheres, &is_short, light, farthest, room, &mut scratch) {
                Ok(buffer) => {
                    used += buffer.bytes();
                    self.lights.push(buffer);
                }
                Err(NoBuffer::NoRoom) => break,
                Err(NoBuffer::Unsuited) => continue,
            }
        }
        self
    }

    fn light_buffer(&self, light: V3<R>) -> Option<&LightBuffer<R>> {
        self.lights.iter().find(|b| b.light() == light)
    }

    /// The same grid, giving up on a call for many rays past `tests`
    /// candidate tests instead of [`crate::limits::PACKET_TESTS`].
    pub fn with_packet_tests(mut self, tests: u64) -> Self {
        self.packet_tests = tests.max(1);
        self
    }

    /// The same grid, its kernels run as compiled for the build's own
    /// target whatever the CPU offers beyond it: to check and measure
    /// both instances on one machine.
    pub fn with_baseline_vectors(mut self) -> Self {
        self.vectors = Vectors::baseline();
        self
    }

    /// The instructions the grid's kernels run on.
    pub fn vectors(&self) -> Vectors {
        self.vectors
    }

    /// The same grid, crossing empty space the way `mode` says.
    pub fn with_empty_space(mut self, mode: EmptySpace) -> Self {
        self.empty_space = mode;
        self
    }

    /// Bytes the index holds beyond the sphere array (its compact copies of
    /// the spheres included).
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(Level::bytes).sum::<usize>()
            + self.gate.as_ref().map_or(0, Gate::bytes)
            + self.spheres.bytes()
            + self.levels.capacity() * std::mem::size_of::<Level>()
            + self.short.capacity() * 4
    }

    /// How many levels a single ray walks only where the gate says their
    /// space begins ([`gate`]): 0 without a gate.
    pub fn gated_levels(&self) -> usize {
        self.gate.as_ref().map_or(0, Gate::gated_levels)
    }

    /// How many spheres every ray tests before walking any level.
    pub fn short_list_len(&self) -> usize {
        self.short.len()
    }

    pub fn levels(&self) -> Vec<LevelInfo> {
        self.levels
            .iter()
            .map(|l| LevelInfo {
                cell: l.cell,
                dims: l.dims,
                occupied_cells: l.cell_start.len() - 1,
                references: l.ids.len(),
            })
            .collect()
    }
}

impl<R: Real> SphereIndex<R> for VoxelHashGrid<R> {
    fn closest_hit(&self, ray: &Ray<R>, t_min: R, t_max: R) -> Option<Hit<R>> {
        self.closest_hit_spending(ray, t_min, t_max, &mut Uncounted)
    }

    fn closest_hits(
        &self,
        origin: V3<R>,
        dirs: &[V3<R>],
        t_min: R,
        t_max: R,
        out: &mut [Option<Hit<R>>],
    ) -> Answered {
        let answered = self.packet_closest_hits(origin, dirs, t_min, t_max, out);
        if answered == Answered::GaveUp && self.every_sphere_fits(dirs.len()) {
            for (&dir, hit) in dirs.iter().zip(out) {
                *hit = self.nearest_of_all(&Ray::new(origin, dir), t_min, t_max);
            }
            return Answered::All;
        }
        answered
    }

    fn any_hits_toward(&self, light: V3<R>, origins: &[V3<R>], out: &mut [bool]) -> Answered {
        if let Some(buffer) = self.light_buffer(light) {
            let mut budget = TestBudget::new(self.packet_tests);
            for (&o, blocked) in origins.iter().zip(out.iter_mut()) {
                *blocked = match buffer.blocked(&self.spheres, o, &mut budget) {
                    Some(b) => b,
                    None => self
                        .blocker(&Ray::new(o, light - o), R::one(), &mut budget)
                        .is_some(),
                };
                if budget.spent() {
                    return Answered::GaveUp;
                }
            }
            return Answered::All;
        }
        let answered = self.packet_any_hits_toward(light, origins, out);
        if answered == Answered::GaveUp && self.every_sphere_fits(origins.len()) {
            for (&o, blocked) in origins.iter().zip(out) {
                *blocked = self.blocked_by_any(&Ray::new(o, light - o), R::one());
            }
            return Answered::All;
        }
        answered
    }

    fn any_hit(&self, ray: &Ray<R>, t_max: R) -> bool {
        self.any_hit_spending(ray, t_max, &mut Uncounted)
    }

    fn light_buffers(&self) -> LightBuffers {
        LightBuffers {
            lights: self.lights.len(),
            bytes: self.lights.iter().map(LightBuffer::bytes).sum(),
        }
    }

    fn any_hit_toward(&self, light: V3<R>, origin: V3<R>) -> bool {
        self.light_buffer(light)
            .and_then(|b| b.blocked(&self.spheres, origin, &mut Uncounted))
            .unwrap_or_else(|| self.any_hit(&Ray::new(origin, light - origin), R::one()))
    }
}

impl<R: Real> VoxelHashGrid<R> {
    /// Whether testing every sphere for each of `rays` rays fits in a
    /// call's budget of tests. Then a call whose walks ran out of it (a
    /// small scene whose cells crowd so that the walks cost more than
    /// brute force: spheres far smaller than the rounding of their
    /// coordinates, say) answers every ray by testing every sphere, with
    /// the walks' own test and order, so the same answers and still within
    /// about twice the budget.
    fn every_sphere_fits(&self, rays: usize) -> bool {
        (rays as u64).saturating_mul(self.spheres.len() as u64) <= self.packet_tests
    }

    /// The ray's nearest hit with t in [t_min, t_max] among every sphere,
    /// with the walks' test and (t, id) order (see [`Self::every_sphere_fits`]).
    fn nearest_of_all(&self, ray: &Ray<R>, t_min: R, t_max: R) -> Option<Hit<R>> {
        let mut nearest = Nearest::new(t_max);
        for i in 0..self.spheres.len() as u32 {
            nearest.offer(&self.spheres, i, ray, t_min);
        }
        nearest.best
    }

    /// Whether any sphere meets the ray with t in (0, t_max), with the
    /// walks' test (see [`Self::every_sphere_fits`]).
    fn blocked_by_any(&self, ray: &Ray<R>, t_max: R) -> bool {
        (0..self.spheres.len() as u32).any(|i| self.blocks(i, ray, t_max))
    }

    /// [`SphereIndex::any_hit`], spending one of `budget` per test.
    pub(super) fn any_hit_spending(&self, ray: &Ray<R>, t_max: R, budget: &mut impl Tests) -> bool {
        self.blocker(ray, t_max, budget).is_some()
    }

    /// Whether sphere `i` (a position in `spheres`) meets the ray with t in (0, t_max).
    #[inline(always)]
    fn blocks(&self, i: u32, ray: &Ray<R>, t_max: R) -> bool {
        (self.spheres).intersect(i, ray, R::zero(), t_max).is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::light_buffer::{farthest_from, short_marks, NoBuffer, Scratch};
    use super::{LightBuffer, VoxelHashGrid};
    use crate::geometry::Ellipsoid;
    use glam::Vec3;

    /// `count` ellipsoids of the given semi-axes, centred uniformly in the
    /// cube of half-side `half`, drawn from `seed`.
    pub(in crate::index::grid) fn scattered(
        seed: u64,
        count: usize,
        half: f64,
        semi_axes: Vec3,
    ) -> Vec<Ellipsoid<f32>> {
        let mut rng = crate::rng::Rng::new(seed);
        let mut coordinate = || rng.range(-half, half) as f32;
        (0..count)
            .map(|_| {
                let center = Vec3::new(coordinate(), coordinate(), coordinate());
                Ellipsoid::new(center, semi_axes)
            })
            .collect()
    }

    /// The room a buffer is refused for is counted before its lists are
    /// filled, exactly: a buffer fits the bytes it holds, and not one fewer.
    #[test]
    fn a_light_buffer_fits_exactly_the_bytes_it_holds() {
        let shapes = scattered(3, 5_000, 4.0, Vec3::new(0.05, 0.08, 0.03));
        let grid = VoxelHashGrid::new(&shapes);
        let scratch = &mut Scratch::default();
        // Far off, and just outside a sphere (which every ray then tests).
        let beside = shapes[17].center + Vec3::new(0.1, 0.0, 0.0);
        for light in [Vec3::new(9.0, 7.0, 12.0), beside] {
            let is_short = short_marks(grid.spheres.len(), &grid.short);
            let farthest = farthest_from(&grid.spheres, &is_short, &[light])[0];
            let build = |room: usize, scratch: &mut Scratch| {
                LightBuffer::new(&grid.spheres, &is_short, light, farthest, room, scratch)
            };
            let bytes = build(usize::MAX, scratch).unwrap().bytes();
            assert_eq!(build(bytes, scratch).unwrap().bytes(), bytes, "{light}");
            assert_eq!(build(bytes - 1, scratch).err(), Some(NoBuffer::NoRoom));
        }
    }
}
