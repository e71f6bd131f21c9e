//! Amanatides & Woo's 3D-DDA over one level, in f64.
//!
//! The walk keeps the integer cell and, per axis, the t at which the ray
//! crosses the next cell boundary. That t is always recomputed from the
//! integer index, `(origin − o)/d + i·(h/d)`, never accumulated, so it
//! cannot drift over a million cells. An axis the ray runs parallel to (d = ±0)
//! never steps: its next crossing is +∞. Empty space is crossed a box at
//! a time: the empty groups of blocks ahead of the walk's one (as far as the
//! level's proximity cloud for the ray's heading says) or an empty region
//! (4×4×4 blocks) in one step, the walk moving to the first cell beyond the
//! box along the ray. Inside an occupied region the walk steps block by
//! block over the region's empty blocks, a DDA over its mask (as the
//! hierarchical DDA of NanoVDB steps a node's children), and finds its cell
//! again only where it enters an occupied block or leaves the region: a
//! block step costs about what one cell step does, where finding the cell
//! costs several.
//!
//! On a level whose cells list many spheres, each reference keeps the
//! octants of its cell its sphere overlaps, and the walk offers a visit only
//! the spheres in the octants the ray crosses ([`super::octant`]).

use super::occupancy::Heading;
use super::octant::{OctantRay, Octants, FILTERED_FROM};
use super::table::{block_key, cell_bit, Block, BlockKey, Region, BLOCK_SHIFT, BLOCK_SIDE};
use super::{EmptySpace, Level, Vectors};
use crate::geometry::{Ray, Real, Vec3Ops};
use glam::DVec3;

/// A ray in f64, with its length for turning distances into t.
#[derive(Clone, Copy, Default)]
pub struct Ray64 {
    pub o: [f64; 3],
    pub d: [f64; 3],
    pub inv: [f64; 3],
    pub length: f64,
}

impl Ray64 {
    /// None for a zero, infinite or NaN direction, which hits nothing.
    pub fn new<R: Real>(ray: &Ray<R>) -> Option<Ray64> {
        Ray64::from_f64(ray.origin.to_dvec3(), ray.dir.to_dvec3())
    }

    /// The ray `o + t·d`; None as for [`Ray64::new`].
    pub fn from_f64(o: DVec3, d: DVec3) -> Option<Ray64> {
        let length = d.length();
        (length > 0.0 && length.is_finite() && o.is_finite()).then(|| Ray64 {
            o: o.to_array(),
            d: d.to_array(),
            inv: d.recip().to_array(),
            length,
        })
    }
}

/// What a walk does in each occupied cell it reaches.
pub trait Visit {
    /// Offered, nearest cell first, the cell's spheres the ray can meet
    /// there (every one, or those in the octants it crosses: [`super::octant`]);
    /// returns the t beyond which nothing more is wanted.
    ///
    /// Generic over the iterator, so the walk of a level without octants
    /// runs a visit that never looks for them.
    fn cell(&mut self, spheres: impl Iterator<Item = u32>) -> f64;
}

/// The spheres of a cell in octants the ray crosses there.
#[inline(always)]
fn in_octants<'a>(
    ids: &'a [u32],
    octants: &'a [Octants],
    crossed: Octants,
) -> impl Iterator<Item = u32> + 'a {
    (ids.iter().zip(octants))
        .filter(move |(_, o)| o.meets(crossed))
        .map(|(&i, _)| i)
}

/// The per-axis constants a ray's walk through a level steps with.
struct Axes {
    /// −1, 0 or 1: which way the ray's cell index moves on each axis.
    step: [i64; 3],
    /// 1 where the ray travels up the axis, else 0: the next plane it
    /// crosses from cell `c` is plane `c + up`.
    up: [i64; 3],
    /// The t of the level's plane 0, `(origin − o)/d`, or +∞ where d = ±0
    /// (the ray never crosses that axis's planes): a crossing's t is
    /// `plane0 + i·per_plane`, with no branch on the direction.
    plane0: [f64; 3],
    /// `cell / d` (exact: the cell is a power of two), or 0 where d = ±0.
    per_plane: [f64; 3],
    /// The cell's place in its block (0 or 3) just after a step along the
    /// axis has entered a new block.
    block_entry: [i64; 3],
    /// The cell index one step beyond the level along the direction of
    /// travel (−1 or the cells per axis): the walk leaves the level when it
    /// gets there, so one comparison bounds a step.
    exit: [i64; 3],
    /// How a step along the axis moves the cell's bit in its block's mask
    /// ([`cell_bit`]), while it stays in the block.
    bit_step: [i32; 3],
    /// Which of the level's proximity clouds the walk reads.
    heading: Heading,
}

impl Axes {
    /// Inlined into each walk: out of line, its per-axis arrays go through memory.
    #[inline(always)]
    fn new(ray: &Ray64, level: &Level) -> Self {
        let inv = [0, 1, 2].map(|a| if ray.d[a] == 0.0 { 0.0 } else { ray.inv[a] });
        let step = ray.d.map(step_of);
        Axes {
            step,
            up: ray.d.map(|d| (d > 0.0) as i64),
            plane0: [0, 1, 2].map(|a| {
                if ray.d[a] == 0.0 {
                    f64::INFINITY
                } else {
                    (level.origin[a] - ray.o[a]) * inv[a]
                }
            }),
            per_plane: inv.map(|inv| level.cell * inv),
            block_entry: ray.d.map(|d| if d > 0.0 { 0 } else { BLOCK_SIDE - 1 }),
            exit: [0, 1, 2].map(|a| if ray.d[a] > 0.0 { level.dims[a] } else { -1 }),
            bit_step: [0, 1, 2].map(|a| (step[a] as i32) << (a as u32 * BLOCK_SHIFT)),
            heading: Heading::of(step),
        }
    }

    /// Whether a step along `axis` that arrived at cell index `c` crossed
    /// into a new block.
    #[inline(always)]
    fn entered_block(&self, axis: usize, c: i64) -> bool {
        c & (BLOCK_SIDE - 1) == self.block_entry[axis]
    }

    /// The t at which the ray leaves cell `c` across a plane of `axis`
    /// (+∞ if it never does). The plane between cells `i − 1` and `i` lies
    /// at `origin + i·cell`, crossed at `(origin − o)/d + i·(cell/d)`: two
    /// roundings on the level's own scale, whatever the cell's index.
    #[inline(always)]
    fn crossing(&self, axis: usize, c: i64) -> f64 {
        let i = c + self.up[axis];
        self.plane0[axis] + i as f64 * self.per_plane[axis]
    }

    /// For each axis, the t at which the ray leaves the cell one step from
    /// `c` along it: what [`advance`] moves into the next crossing
    /// when it steps that way.
    #[inline(always)]
    fn crossings_after(&self, c: &[i64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|k| self.crossing(k, c[k] + self.step[k]))
    }
}

/// Cells per region side, as a power of two (a region is 4×4×4 blocks).
const REGION_SHIFT: u32 = 2 * BLOCK_SHIFT;

/// A box of empty cells ahead of the walk's cell: groups of `1 << shift`
/// cells a side, from the group holding it to `radius` groups beyond it
/// along each axis, in the direction the ray moves (up an axis it does not
/// move along, which it never leaves that way).
#[derive(Clone, Copy)]
struct Empty {
    shift: u32,
    radius: i64,
}

/// The empty space the walk's cell starts: a box crossed in one leap, or an
/// empty block of an occupied region, whose mask of occupied blocks
/// [`Level::cross_blocks`] steps over.
#[derive(Clone, Copy)]
enum EmptyAhead {
    Box(Empty),
    InRegion { blocks: u64 },
}

impl Empty {
    /// The group of `1 << shift` cells a side holding the walk's cell, alone.
    fn group(shift: u32) -> Self {
        Empty { shift, radius: 0 }
    }

    /// Whether the box is the walk's block alone.
    #[inline(always)]
    fn is_one_block(self) -> bool {
        self.shift == BLOCK_SHIFT && self.radius == 0
    }
}

/// The last group looked up: a ray crosses several cells of a block, and
/// several blocks of a region, one after another.
struct Cached<V> {
    key: BlockKey,
    value: V,
}

impl<V: Copy + Default> Cached<V> {
    fn new() -> Self {
        Cached {
            key: BlockKey::MAX,
            value: V::default(),
        }
    }

    /// The value for `key`, from `lookup` (absent: the default) unless it was the last one.
    #[inline(always)]
    fn get(&mut self, key: BlockKey, lookup: impl FnOnce(BlockKey) -> Option<V>) -> V {
        if key != self.key {
            self.key = key;
            self.value = lookup(key).unwrap_or_default();
        }
        self.value
    }
}

/// ⌊x⌋ as an integer (saturating), without the libm call `f64::floor`
/// becomes on CPUs the build does not assume SSE4.1 for.
#[inline(always)]
pub(super) fn floor_to_int(x: f64) -> i64 {
    let truncated = x as i64;
    truncated - i64::from((truncated as f64) > x)
}

/// −1, 0 or 1 as a direction's component goes down, nowhere or up an axis.
#[inline(always)]
pub(super) fn step_of(d: f64) -> i64 {
    i64::from(d > 0.0) - i64::from(d < 0.0)
}

/// The lesser of `a` and `b`: `b` only where it compares below `a`, so a NaN
/// `b` never wins. One comparison and a select: `f64::min` pays for its NaN
/// rule on every call, which the walks' per-ray loops feel.
#[inline(always)]
pub(super) fn lesser<T: PartialOrd>(a: T, b: T) -> T {
    if b < a {
        b
    } else {
        a
    }
}

/// The greater of `a` and `b`: `b` only where it compares above `a` (see [`lesser`]).
#[inline(always)]
pub(super) fn greater<T: PartialOrd>(a: T, b: T) -> T {
    if b > a {
        b
    } else {
        a
    }
}

/// The axis whose next crossing comes first (the lowest of equal ones),
/// without branches: which axis a ray steps along next is as good as
/// random, and a mispredicted branch costs more than the selects.
#[inline(always)]
pub(super) fn first_axis(t: &[f64; 3]) -> usize {
    let one_first = t[1] < t[0];
    let earlier = if one_first { t[1] } else { t[0] };
    if t[2] < earlier {
        2
    } else {
        usize::from(one_first)
    }
}

/// [`Level::step`] for the walk's inner loop, with `after` (from
/// [`Axes::crossings_after`]) kept beside `t_next`: the crossing a step
/// moves into `t_next` was found when the walk last stepped that way, off
/// the chain from one step to the next, and each axis's cell and crossings
/// are updated where the ray steps and kept where it does not by selects
/// on constant indices, not through an index by the axis. The same cells
/// and crossings as [`Level::step`] (the same expressions); an axis not
/// stepped along never reaches its exit, so checking all three stops where
/// it does. Returns the axis stepped and whether the step entered a new
/// block.
#[inline(always)]
fn advance(
    axes: &Axes,
    c: &mut [i64; 3],
    t_next: &mut [f64; 3],
    after: &mut [f64; 3],
    limit: f64,
) -> Option<(usize, bool)> {
    let a = first_axis(t_next);
    // `t_next[a]`, compared as `first_axis` compares.
    let t = lesser(lesser(t_next[0], t_next[1]), t_next[2]);
    if t > limit {
        return None;
    }
    let mut entered = false;
    for k in 0..3 {
        let here = k == a;
        let moved = c[k] + axes.step[k];
        let beyond = axes.crossing(k, moved + axes.step[k]);
        entered |= here & (moved & (BLOCK_SIDE - 1) == axes.block_entry[k]);
        c[k] = if here { moved } else { c[k] };
        t_next[k] = if here { after[k] } else { t_next[k] };
        after[k] = if here { beyond } else { after[k] };
    }
    if (0..3).any(|k| c[k] == axes.exit[k]) {
        return None;
    }
    Some((a, entered))
}

/// The part of [t_lo, t_hi] the ray spends inside the box `lo..hi`.
///
/// Without branches: where d = ±0 its reciprocal is ±∞, so the slab
/// between the box's planes gives t = ±∞ (the whole line, or none of it)
/// and a start on a plane gives 0·∞ = NaN, which the comparisons of
/// [`greater`] and [`lesser`] ignore: the span stays unclipped on that
/// side, as the ray lies in the box's closed slab. Each plane is taken as
/// near or far by the direction's sign, so a NaN never swaps them.
#[inline(always)]
pub(super) fn clip_to_box(
    lo: &[f64; 3],
    hi: &[f64; 3],
    ray: &Ray64,
    t_lo: f64,
    t_hi: f64,
) -> Option<(f64, f64)> {
    let (t0, t1, meets) = span_in_box(lo, hi, ray, t_lo, t_hi);
    meets.then_some((t0, t1))
}

/// [`clip_to_box`] as the span's ends and whether it is the ray's part in
/// the box, for loops over many rays that keep a branch out of each.
#[inline(always)]
pub(super) fn span_in_box(
    lo: &[f64; 3],
    hi: &[f64; 3],
    ray: &Ray64,
    t_lo: f64,
    t_hi: f64,
) -> (f64, f64, bool) {
    let (mut t0, mut t1) = (t_lo, t_hi);
    for a in 0..3 {
        let up = ray.inv[a] >= 0.0;
        let planes = if up { (lo[a], hi[a]) } else { (hi[a], lo[a]) };
        (t0, t1) = between_planes(planes, ray, a, (t0, t1));
    }
    // t0 = +∞: parallel to a plane outside the box, which t0 ≤ t1 misses
    // only where every other reciprocal overflowed too (t1 = +∞).
    (t0, t1, t0 <= t1 && t0 < f64::INFINITY)
}

/// The part of `span` (a range of t) the ray spends between two planes
/// across `axis`, the one it crosses first (`near`) and the other (`far`),
/// as a range of t that is empty where it ends before it starts.
#[inline(always)]
pub(super) fn between_planes(
    (near, far): (f64, f64),
    ray: &Ray64,
    axis: usize,
    (t_lo, t_hi): (f64, f64),
) -> (f64, f64) {
    (
        greater(t_lo, (near - ray.o[axis]) * ray.inv[axis]),
        lesser(t_hi, (far - ray.o[axis]) * ray.inv[axis]),
    )
}

impl Level {
    /// The part of [t_lo, t_hi] the ray spends inside this level's box
    /// ([`clip_to_box`]).
    #[inline(always)]
    pub(super) fn clip(&self, ray: &Ray64, t_lo: f64, t_hi: f64) -> Option<(f64, f64)> {
        clip_to_box(&self.origin.to_array(), &self.far, ray, t_lo, t_hi)
    }

    /// The planes of this level's box across `axis` that a ray going along
    /// it by `step` (±1) crosses first and last.
    #[inline(always)]
    pub(super) fn planes_across(&self, axis: usize, step: i64) -> (f64, f64) {
        if step > 0 {
            (self.origin[axis], self.far[axis])
        } else {
            (self.far[axis], self.origin[axis])
        }
    }

    /// The cell holding the ray's point at `t`, clamped to `[lo, hi]` per axis.
    #[inline(always)]
    pub(super) fn cell_at(&self, ray: &Ray64, t: f64, axis: usize, lo: i64, hi: i64) -> i64 {
        self.slab_at(ray.o[axis] + t * ray.d[axis], axis, lo, hi)
    }

    /// The index along `axis` of the cells holding coordinate `p` on it,
    /// clamped to `[lo, hi]`: monotone in `p`.
    #[inline(always)]
    pub(super) fn slab_at(&self, p: f64, axis: usize, lo: i64, hi: i64) -> i64 {
        floor_to_int((p - self.origin[axis]) * self.per_cell).clamp(lo, hi)
    }

    /// The ray as the octants of this level's cells see it, for a walk
    /// from cell `c` ([`OctantRay`]).
    #[inline(always)]
    fn octant_ray(&self, ray: &Ray64, axes: &Axes, c: [i64; 3]) -> OctantRay {
        // Along an axis the ray does not move on, the walk's cell index never
        // changes: the half its coordinate lies in, as the build finds it.
        let still_upper = [0, 1, 2].map(|a| {
            if axes.step[a] != 0 {
                return 0;
            }
            let half = floor_to_int((ray.o[a] - self.origin[a]) * (2.0 * self.per_cell));
            u8::from(half > 2 * c[a]) << a
        });
        OctantRay::new(
            axes.step,
            axes.per_plane,
            still_upper[0] | still_upper[1] | still_upper[2],
        )
    }

    /// Offers `visit` the spheres of occupied cell `cell` (at `c`): on a
    /// level whose references keep octants (`FILTERED`), in a cell of
    /// several spheres, those in the octants the ray crosses.
    #[inline(always)]
    fn visit_cell<const FILTERED: bool>(
        &self,
        octant_ray: &OctantRay,
        t_next: &[f64; 3],
        cell: usize,
        visit: &mut impl Visit,
    ) -> f64 {
        let references = self.references(cell);
        let ids = &self.ids[references.clone()];
        if !FILTERED || ids.len() < FILTERED_FROM {
            return visit.cell(ids.iter().copied());
        }
        let octants = &self.octants[references];
        visit.cell(in_octants(ids, octants, octant_ray.crossed(t_next)))
    }

    /// Visits, nearest first, the occupied cells the ray crosses within
    /// [t_lo, t_hi], offering `visit` each one's spheres ([`Visit`]); the
    /// walk stops before entering a cell that starts beyond the t it returns.
    /// Runs the instance compiled for `vectors` ([`super::vectors`]), which
    /// must be the grid's.
    ///
    /// Out of line: inlined into a search, the instance with octants
    /// ([`Self::walk_clipped`]) cost mixed 10⁵'s single eye rays 3% more
    /// instructions.
    #[inline(never)]
    pub fn walk(
        &self,
        ray: &Ray64,
        (t_lo, t_hi): (f64, f64),
        empty_space: EmptySpace,
        vectors: Vectors,
        visit: &mut impl Visit,
    ) {
        #[cfg(target_arch = "x86_64")]
        if vectors.avx2() {
            // SAFETY: the function needs AVX2 alone, which `Vectors::avx2`
            // says this CPU has (only `Vectors::detect` can say so).
            return unsafe { self.walk_avx2(ray, (t_lo, t_hi), empty_space, visit) };
        }
        // Elsewhere the build's own target is the only instance.
        #[cfg(not(target_arch = "x86_64"))]
        let _ = vectors;
        self.walk_clipped(ray, (t_lo, t_hi), empty_space, visit)
    }

    /// [`Self::walk_clipped`] compiled with AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn walk_avx2(
        &self,
        ray: &Ray64,
        span: (f64, f64),
        empty_space: EmptySpace,
        visit: &mut impl Visit,
    ) {
        self.walk_clipped(ray, span, empty_space, visit)
    }

    /// [`Self::walk`] from the ray's clip to the level's box. A level whose
    /// references keep no octants is walked by an instance that never asks
    /// for them, so that it costs what a walk without the filter would.
    #[inline(always)]
    fn walk_clipped(
        &self,
        ray: &Ray64,
        (t_lo, t_hi): (f64, f64),
        empty_space: EmptySpace,
        visit: &mut impl Visit,
    ) {
        let Some(span) = self.clip(ray, t_lo, t_hi) else {
            return;
        };
        if self.octants.is_empty() {
            self.walk_span::<false>(ray, span, empty_space, visit)
        } else {
            self.walk_span::<true>(ray, span, empty_space, visit)
        }
    }

    /// [`Self::walk`] over the part `(t0, limit)` of the ray in the level's
    /// box, passing over spheres outside the octants the ray crosses if
    /// `FILTERED`.
    #[inline(always)]
    fn walk_span<const FILTERED: bool>(
        &self,
        ray: &Ray64,
        (t0, limit): (f64, f64),
        empty_space: EmptySpace,
        visit: &mut impl Visit,
    ) {
        // Finite, so that `t > limit` also stops at an axis never crossed (+∞).
        let mut limit = limit.min(f64::MAX);
        let axes = Axes::new(ray, self);
        let mut c = [0; 3];
        let mut t_next = [0.0; 3];
        for a in 0..3 {
            c[a] = self.cell_at(ray, t0, a, 0, self.dims[a] - 1);
            t_next[a] = axes.crossing(a, c[a]);
        }
        let octant_ray = if FILTERED {
            self.octant_ray(ray, &axes, c)
        } else {
            OctantRay::UNUSED
        };
        if empty_space == EmptySpace::ProbeEveryCell {
            return self.walk_probing::<FILTERED>(&axes, &octant_ray, c, t_next, limit, visit);
        }
        let mut region = Cached::<Region>::new();
        // Each axis's crossing after its next ([`advance`]), and whether it
        // is behind the cell: found again only when the walk next steps a
        // cell, not after each leap across empty space.
        let mut after = axes.crossings_after(&c);
        let mut behind = false;
        // The occupied block the walk is in; None until it is looked up.
        let mut block: Option<Block> = None;
        // The walk's cell's bit in its block's mask, kept as the walk steps.
        let mut bit = 0;
        loop {
            let cells = match block {
                Some(cells) => cells,
                None => {
                    let b = c.map(|v| v >> BLOCK_SHIFT);
                    match self.enter_block(c, b, axes.heading, &mut region) {
                        Ok(cells) => {
                            bit = cell_bit(c);
                            *block.insert(cells)
                        }
                        Err(EmptyAhead::InRegion { blocks }) => {
                            if !self.cross_blocks(ray, &axes, &mut c, &mut t_next, limit, blocks) {
                                return;
                            }
                            behind = true;
                            continue;
                        }
                        Err(EmptyAhead::Box(empty)) if empty.is_one_block() => {
                            if !self.step_out_of_block(&axes, &mut c, &mut t_next, limit) {
                                return;
                            }
                            behind = true;
                            continue;
                        }
                        Err(EmptyAhead::Box(empty)) => {
                            if !self.leave_empty(ray, &axes, &mut c, &mut t_next, limit, empty) {
                                return;
                            }
                            behind = true;
                            continue;
                        }
                    }
                }
            };
            if cells.holds(bit) {
                let cell = cells.cell_index(bit);
                let wanted = self.visit_cell::<FILTERED>(&octant_ray, &t_next, cell, visit);
                limit = limit.min(wanted);
            }
            if behind {
                (after, behind) = (axes.crossings_after(&c), false);
            }
            let Some((a, entered)) = advance(&axes, &mut c, &mut t_next, &mut after, limit) else {
                return;
            };
            if entered {
                block = None;
            } else {
                bit = bit.wrapping_add_signed(axes.bit_step[a]);
            }
        }
    }

    /// The occupied block at block coordinates `b` the walk enters at cell
    /// `c`, or the empty space it starts to cross. Empty space at three
    /// scales: the empty groups ahead of `c`'s in the level's proximity
    /// cloud for the ray's `heading`, a region (4×4×4 blocks) with no
    /// occupied block, and an empty block of an occupied region (with the
    /// region's mask, which [`Self::cross_blocks`] steps over). An occupied
    /// block is found from the region too, without another probe.
    #[inline(always)]
    fn enter_block(
        &self,
        c: [i64; 3],
        b: [i64; 3],
        heading: Heading,
        region: &mut Cached<Region>,
    ) -> Result<Block, EmptyAhead> {
        let distance = self.occupancy.distance(c, heading);
        if distance > 0 {
            return Err(EmptyAhead::Box(Empty {
                shift: self.occupancy.shift,
                radius: i64::from(distance) - 1,
            }));
        }
        let region = region.get(block_key(b.map(|v| v >> BLOCK_SHIFT)), |k| {
            self.table.region(k)
        });
        if region.blocks == 0 {
            return Err(EmptyAhead::Box(Empty::group(REGION_SHIFT)));
        }
        let bit = cell_bit(b);
        if !region.holds(bit) {
            return Err(EmptyAhead::InRegion {
                blocks: region.blocks,
            });
        }
        Ok(self.table.block_in(region, bit))
    }

    /// [`Self::walk`] one cell at a time, probing the block table in each.
    fn walk_probing<const FILTERED: bool>(
        &self,
        axes: &Axes,
        octant_ray: &OctantRay,
        mut c: [i64; 3],
        mut t_next: [f64; 3],
        mut limit: f64,
        visit: &mut impl Visit,
    ) {
        loop {
            if let Some(b) = self.table.get(c.map(|v| v >> BLOCK_SHIFT)) {
                if b.holds(cell_bit(c)) {
                    let cell = b.cell_index(cell_bit(c));
                    let wanted = self.visit_cell::<FILTERED>(octant_ray, &t_next, cell, visit);
                    limit = limit.min(wanted);
                }
            }
            if self.step(axes, &mut c, &mut t_next, limit).is_none() {
                return;
            }
        }
    }

    /// Moves to the next cell along the ray, across a plane of the axis it
    /// returns; None when that cell starts beyond `limit` (finite) or lies
    /// outside the level.
    #[inline(always)]
    fn step(
        &self,
        axes: &Axes,
        c: &mut [i64; 3],
        t_next: &mut [f64; 3],
        limit: f64,
    ) -> Option<usize> {
        let a = first_axis(t_next);
        if t_next[a] > limit {
            return None;
        }
        c[a] += axes.step[a];
        if c[a] == axes.exit[a] {
            return None;
        }
        t_next[a] = axes.crossing(a, c[a]);
        Some(a)
    }

    /// Moves from cell `c` of an empty block to the first cell the ray
    /// enters beyond the block, one cell step at a time. False when that
    /// lies beyond `limit` (finite) or outside the level. A ray crosses a
    /// block in a few steps, each a fraction of what [`Self::leave_empty`]
    /// costs, so a cloud's group of one empty block is crossed this way.
    #[inline(always)]
    fn step_out_of_block(
        &self,
        axes: &Axes,
        c: &mut [i64; 3],
        t_next: &mut [f64; 3],
        limit: f64,
    ) -> bool {
        loop {
            let Some(a) = self.step(axes, c, t_next, limit) else {
                return false;
            };
            if axes.entered_block(a, c[a]) {
                return true;
            }
        }
    }

    /// Moves from cell `c`, in an empty block of an occupied region whose
    /// occupied blocks are `blocks`, block by block across the region's
    /// empty blocks, to the first cell the ray enters of an occupied block or
    /// beyond the region. False when that lies beyond `limit` (finite) or
    /// outside the level. Each block is left as [`Self::leave_empty`] leaves
    /// a box of one block (the same exit t and axis), so the blocks crossed
    /// are those its leaps would cross; the cell is found once, at the end,
    /// as past a box of all the blocks crossed ([`Self::land_past`]).
    fn cross_blocks(
        &self,
        ray: &Ray64,
        axes: &Axes,
        c: &mut [i64; 3],
        t_next: &mut [f64; 3],
        limit: f64,
        blocks: u64,
    ) -> bool {
        let mut b = c.map(|v| v >> BLOCK_SHIFT);
        let region = b.map(|v| v >> BLOCK_SHIFT);
        // The block's last cell along each axis's direction of travel.
        let last_on = |a: usize, b: i64| ((b + axes.up[a]) << BLOCK_SHIFT) - axes.up[a];
        let mut exits = [
            axes.crossing(0, last_on(0, b[0])),
            axes.crossing(1, last_on(1, b[1])),
            axes.crossing(2, last_on(2, b[2])),
        ];
        loop {
            let a = first_axis(&exits);
            let t_exit = exits[a];
            if t_exit > limit {
                return false;
            }
            let mut next = b;
            next[a] += axes.step[a];
            let left_region = next[a] >> BLOCK_SHIFT != region[a];
            if !left_region && blocks >> cell_bit(next) & 1 == 0 {
                b = next;
                exits[a] = axes.crossing(a, last_on(a, b[a]));
                continue;
            }
            // The blocks crossed since `c` end at block `b`'s last cells.
            let exit = BoxExit {
                last: [0, 1, 2].map(|k| last_on(k, b[k])),
                axis: a,
                t: t_exit,
            };
            return self.land_past(ray, axes, c, t_next, exit);
        }
    }

    /// Moves from cell `c` across the empty box ahead of it to the first
    /// cell the ray enters beyond the box. False when that lies beyond
    /// `limit` (finite) or outside the level.
    fn leave_empty(
        &self,
        ray: &Ray64,
        axes: &Axes,
        c: &mut [i64; 3],
        t_next: &mut [f64; 3],
        limit: f64,
        empty: Empty,
    ) -> bool {
        let (shift, r) = (empty.shift, empty.radius);
        // The box's last cell along each axis's direction of travel: of the
        // groups from the walk's group g to g + r ahead, the last cell of
        // g + r going up, the first of g − r going down.
        let last_on = |a: usize| {
            let up = axes.up[a];
            (((c[a] >> shift) + axes.step[a] * r + up) << shift) - up
        };
        // Written out rather than `[0, 1, 2].map(..)`, which is not always inlined.
        let last = [last_on(0), last_on(1), last_on(2)];
        let exits = [
            axes.crossing(0, last[0]),
            axes.crossing(1, last[1]),
            axes.crossing(2, last[2]),
        ];
        let a = first_axis(&exits);
        let t_exit = exits[a];
        // The walk's limit is finite, so this also stops at +∞ (no exit).
        if t_exit > limit {
            return false;
        }
        let exit = BoxExit {
            last,
            axis: a,
            t: t_exit,
        };
        self.land_past(ray, axes, c, t_next, exit)
    }

    /// Moves the walk from cell `c` to the first cell past the empty box it
    /// leaves at `exit`. False outside the level.
    #[inline(always)]
    fn land_past(
        &self,
        ray: &Ray64,
        axes: &Axes,
        c: &mut [i64; 3],
        t_next: &mut [f64; 3],
        exit: BoxExit,
    ) -> bool {
        let BoxExit { last, axis: a, t } = exit;
        for k in 0..3 {
            c[k] = if k == a {
                last[k] + axes.step[k]
            } else if axes.step[k] == 0 {
                c[k]
            } else {
                // Between the ray's cell and the box's last along k: only
                // rounding could put the exit point outside.
                self.cell_at(ray, t, k, c[k].min(last[k]), c[k].max(last[k]))
            };
            if c[k] < 0 || c[k] >= self.dims[k] {
                return false;
            }
            t_next[k] = axes.crossing(k, c[k]);
        }
        true
    }
}

/// Where the ray leaves an empty box ahead of the walk's cell: the box's
/// last cell along each axis's direction of travel, and the axis and t of
/// the plane it leaves across.
#[derive(Clone, Copy)]
struct BoxExit {
    last: [i64; 3],
    axis: usize,
    t: f64,
}

#[cfg(test)]
mod tests {
    use super::{first_axis, Ray64};
    use crate::index::grid::tests::scattered;
    use crate::index::grid::{Level, VoxelHashGrid};
    use glam::{DVec3, Vec3};
    use proptest::prelude::*;

    /// The clip as the box's three slabs say it, axis by axis, with a
    /// branch for a ray parallel to a slab's planes.
    fn clip_by_cases(level: &Level, ray: &Ray64, t_lo: f64, t_hi: f64) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = (t_lo, t_hi);
        for a in 0..3 {
            let (lo, hi) = (level.origin[a], level.far[a]);
            if ray.d[a] == 0.0 {
                if !(ray.o[a] >= lo && ray.o[a] <= hi) {
                    return None;
                }
            } else {
                let (ta, tb) = ((lo - ray.o[a]) * ray.inv[a], (hi - ray.o[a]) * ray.inv[a]);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        (t0 <= t1).then_some((t0, t1))
    }

    fn a_level() -> VoxelHashGrid<f32> {
        VoxelHashGrid::new(&scattered(7, 200, 3.0, Vec3::splat(0.25)))
    }

    proptest! {
        /// The branch-free clip gives what the axis-by-axis cases give,
        /// rays parallel to the planes (d = +0 or −0) and starting on them
        /// included, for directions whose reciprocal is finite.
        #[test]
        fn clip_agrees_with_the_slab_cases(
            place in prop::array::uniform3(0usize..5),
            offset in prop::array::uniform3(-3.0f64..3.0),
            dir in prop::array::uniform3(prop_oneof![
                Just(0.0f64), Just(-0.0f64), -2.0f64..2.0, 1e-30f64..1e-20
            ]),
            t_lo in -5.0f64..1.0,
            t_hi in prop_oneof![Just(f64::INFINITY), 1.0f64..20.0],
        ) {
            let grid = a_level();
            let level = &grid.levels[0];
            // On the box's low or high plane, inside, below or above it.
            let o = DVec3::from_array(std::array::from_fn(|a| {
                let (lo, hi) = (level.origin[a], level.far[a]);
                [lo, hi, (lo + hi) / 2.0 + offset[a], lo - 1.0 - offset[a].abs(), hi + 1.0][place[a]]
            }));
            let Some(ray) = Ray64::from_f64(o, DVec3::from_array(dir)) else {
                return Ok(());
            };
            prop_assert_eq!(level.clip(&ray, t_lo, t_hi), clip_by_cases(level, &ray, t_lo, t_hi));
        }
    }

    /// The first of the smallest, over every order of equal, unequal and
    /// infinite crossings.
    #[test]
    fn first_axis_is_the_lowest_axis_of_the_earliest_crossing() {
        let values = [-1.0, 0.0, 0.5, 1.0, f64::INFINITY];
        for &x in &values {
            for &y in &values {
                for &z in &values {
                    let t = [x, y, z];
                    let earliest = x.min(y).min(z);
                    let want = t.iter().position(|&v| v == earliest).unwrap();
                    assert_eq!(first_axis(&t), want, "{t:?}");
                }
            }
        }
    }
}
