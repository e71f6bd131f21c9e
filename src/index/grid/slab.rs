//! The slab walk: a packet of rays from (nearly) one point through one level.
//!
//! Eye rays leave one point in nearly the same direction, so neighbouring
//! pixels cross the same cells and meet the same candidates; walked one at a
//! time they repeat every cell step, probe and sphere fetch. A packet walks a
//! level once, slab by slab along an axis all its rays travel the same way
//! (the coherent grid traversal of Wald et al., "Ray Tracing Animated Scenes
//! using Coherent Grid Traversal", 2006). In each slab (one cell thick) the
//! rays' segments span a rectangle of cells; the walk hands the candidates
//! of the occupied cells there to its caller, and moves on while any of its
//! rays still wants cells that far. A layer of slabs one block thick whose
//! rectangle meets only empty blocks is crossed with one probe per block,
//! and a layer of regions (four block layers) with one probe per region.
//!
//! The rays need not start on one point: shadow rays toward a light start
//! within a few f32 units of it (see [`super::shadow`]). Each ray's start
//! is the packet's origin plus a small offset, and the rectangles and the
//! rule that retires a ray widen by the offsets.
//!
//! # Why it visits every cell a ray needs
//! - Every cell a ray crosses within a slab lies in the rectangle: a ray's
//!   segment in a slab is straight, and the rectangle bounds both its ends.
//! - A ray stops wanting cells under the single walk's rule: once its reach
//!   (best t, or the end of its search) plus the level's slack lies before
//!   the slab it would enter next.
//! - Testing a ray against a sphere from a cell it never crosses can only find
//!   a true hit, which brute force finds too; the nearest (t, id) wins
//!   whatever the order of the tests.

use super::packet::{GROUPS, GROUPS_A_ROW, GROUP_SIDE, LANES, RAYS};
use super::ray_set::{set_bits, RaySet, WORDS};
use super::table::{block_key, box_mask, Block, BLOCK_SHIFT};
use super::walk::{between_planes, greater, lesser, span_in_box, Ray64};
use super::{EmptySpace, Level};
use glam::DVec3;

/// What the slab walk needs to know of the rays it carries.
pub(super) trait Searching {
    /// The t each ray's search starts from (the same for all).
    fn t_min(&self) -> f64;
    /// How far ray `i` still searches, in t: its best hit or the end of its
    /// search; −∞ once it needs nothing more.
    fn reach(&self, i: usize) -> f64;
    /// Every ray's [`Searching::reach`], at once.
    fn reaches(&self) -> [f64; RAYS] {
        std::array::from_fn(|i| self.reach(i))
    }
    /// The rays whose reach moved nearer since the last call.
    fn take_improved(&mut self) -> RaySet;
}

/// What a packet's walk does in each occupied cell it reaches.
///
/// A trait rather than a closure: its method is inlined into the walk, and
/// so into each instance of the kernel that walks ([`super::vectors`]),
/// where a closure's body is a function of its own, compiled once with the
/// build's own instructions.
pub(super) trait PacketVisit<S> {
    /// Offered the sphere ids of an occupied cell that the rays of the
    /// groups among `searching` (one bit each) may cross.
    fn cell(&mut self, ids: &[u32], rays: &mut S, searching: u32);
}

/// The packet's rays in f64 for the walk, and the axis it slabs along.
pub(super) struct Packet {
    /// The point the rays start from, or start near.
    pub origin: [f64; 3],
    pub rays: [Ray64; RAYS],
    /// The rays' unit directions, for the choice of axis and the cones.
    pub unit: [DVec3; RAYS],
    /// `1 / |d|` per ray: a t per unit of distance along it.
    inv_length: [f64; RAYS],
    /// An axis every ray travels along in the same direction.
    axis: usize,
    step: i64,
    /// Per ray, how far it moves across the slabs per unit along `axis`: on
    /// the two other axes (`axis + 1`, `axis + 2`, mod 3), `d_u / d_axis`,
    /// computed as `d_u · (1 / d_axis)`.
    slope: [[f64; RAYS]; 2],
    /// Per ray, where it crosses a plane across the slabs relative to where
    /// a ray with its slopes from `origin` would, per cross axis: with δ its
    /// start minus the origin, `δ_u − δ_axis·slope` (widened by
    /// [`OFFSET_MARGIN`] toward each side). Zero for rays from the origin.
    offset_lo: [[f64; RAYS]; 2],
    offset_hi: [[f64; RAYS]; 2],
    /// Per ray, `|δ_axis|` (widened): how much farther along the axis it
    /// may search than a ray from the origin.
    lead: [f64; RAYS],
    /// Per ray, `|d_axis|`: how far along the axis it moves per unit of t.
    travel: [f64; RAYS],
    /// The largest `|δ|` (widened).
    spread: f64,
    /// Per group of [`LANES`] rays, the range of its rays' slopes and offsets.
    group_ranges: [SlopeRange; GROUPS],
    /// Whether the rays are a tile of eye rays from the origin, as the
    /// renderer hands them ([`crate::render::tiles`]: group by group, each
    /// row by row), so that the rays at [`TILE_CORNERS`] have the least
    /// and greatest slopes. A hint for the walk: it changes work, not answers.
    tile: bool,
}

/// The rays at a tile's four corners: the first of the first group, the
/// last of the first row of the last group of the first row of groups, the
/// first of the last row of the first group of the last row, the last of
/// the last.
const TILE_CORNERS: [usize; 4] = {
    let row = GROUPS_A_ROW;
    [
        0,
        (row - 1) * LANES + GROUP_SIDE - 1,
        row * (row - 1) * LANES + GROUP_SIDE * (GROUP_SIDE - 1),
        RAYS - 1,
    ]
};

/// Relative widening of the start offsets against their own rounding: a
/// few f64 roundings of values themselves a few f32 units of the origin.
const OFFSET_MARGIN: f64 = 1e-12;

thread_local! {
    /// The packet a thread's last walk used, kept for its next one.
    static SPARE: std::cell::Cell<Option<Box<Packet>>> = const { std::cell::Cell::new(None) };
}

impl Packet {
    /// Calls `f` with a packet to aim, the thread's spare one if it has one:
    /// a packet is some 40 KB, and filling a fresh one for every packet
    /// cost more than a scene of few candidates spends on the rays.
    pub fn with_spare<T>(f: impl FnOnce(&mut Packet) -> T) -> T {
        let mut packet = SPARE.take().unwrap_or_else(|| Box::new(Packet::new()));
        let result = f(&mut packet);
        SPARE.set(Some(packet));
        result
    }

    /// A packet to aim (see [`Packet::aim`]).
    fn new() -> Packet {
        Packet {
            origin: [0.0; 3],
            rays: [Ray64::default(); RAYS],
            unit: [DVec3::ZERO; RAYS],
            inv_length: [0.0; RAYS],
            axis: 0,
            step: 1,
            slope: [[0.0; RAYS]; 2],
            offset_lo: [[0.0; RAYS]; 2],
            offset_hi: [[0.0; RAYS]; 2],
            lead: [0.0; RAYS],
            travel: [0.0; RAYS],
            spread: 0.0,
            group_ranges: [SlopeRange::EMPTY; GROUPS],
            tile: false,
        }
    }

    /// Makes this the packet of the rays now in `rays`, which start at or
    /// near `origin`; false when they share no axis of travel (those rays
    /// go one at a time). Reused packet after packet, as it is large.
    /// Inlined into each instance of the packet kernels ([`super::vectors`]).
    #[inline(always)]
    pub fn aim(&mut self, origin: [f64; 3]) -> bool {
        self.tile = false;
        // Each ray's unit direction, by a reciprocal and products where a
        // division each would do (the cones widen their angle far beyond
        // the rounding this adds, and the cells' pad covers the walk's f64
        // rounding many times over); in the same pass, how steeply the
        // shallowest ray travels along each axis (0 when some ray runs
        // parallel to it or the other way), from whether all rays go up it,
        // or all down, and their least slant: without a branch per ray (a
        // NaN goes neither way).
        let (mut all_up, mut all_down) = ([true; 3], [true; 3]);
        let mut least = [f64::INFINITY; 3];
        for i in 0..RAYS {
            let r = &self.rays[i];
            let inv_length = 1.0 / r.length;
            let unit = DVec3::from_array(r.d) * inv_length;
            for axis in 0..3 {
                all_up[axis] &= unit[axis] > 0.0;
                all_down[axis] &= unit[axis] < 0.0;
                least[axis] = lesser(least[axis], unit[axis].abs());
            }
            (self.inv_length[i], self.unit[i]) = (inv_length, unit);
        }
        let steepness: [f64; 3] = std::array::from_fn(|axis| {
            let same_way = all_up[axis] || all_down[axis];
            if same_way {
                least[axis]
            } else {
                0.0
            }
        });
        // The steepest axis gives the thinnest slab rectangles.
        let axis = (0..3)
            .max_by(|&a, &b| steepness[a].total_cmp(&steepness[b]))
            .unwrap_or(0);
        // No axis every ray travels the same way (never NaN: `lesser`
        // keeps the least slant a number), or one along which a ray moves
        // so little that its reciprocal overflowed (the slopes need it).
        if steepness[axis] <= 0.0 || !self.rays.iter().all(|r| r.inv[axis].is_finite()) {
            return false;
        }
        self.origin = origin;
        self.axis = axis;
        self.step = if all_up[axis] { 1 } else { -1 };
        let [u, v] = self.cross();
        for i in 0..RAYS {
            let r = &self.rays[i];
            self.slope[0][i] = r.d[u] * r.inv[axis];
            self.slope[1][i] = r.d[v] * r.inv[axis];
            self.travel[i] = r.d[axis].abs();
        }
        self.measure_offsets();
        self.group_ranges = std::array::from_fn(|g| self.range_of(g * LANES..(g + 1) * LANES));
        true
    }

    /// [`Packet::aim`] for a tile of eye rays from `origin` (see
    /// [`Packet::tile`]).
    #[inline(always)]
    pub fn aim_tile(&mut self, origin: [f64; 3]) -> bool {
        let aimed = self.aim(origin);
        self.tile = aimed && self.spread == 0.0;
        aimed
    }

    /// Fills in how far each ray starts from the origin (see the fields).
    fn measure_offsets(&mut self) {
        let widen = |x: f64| x.abs() * OFFSET_MARGIN;
        let [u, v] = self.cross();
        self.spread = 0.0;
        for i in 0..RAYS {
            let delta = DVec3::from_array(self.rays[i].o) - DVec3::from_array(self.origin);
            (self.offset_lo[0][i], self.offset_hi[0][i]) = (0.0, 0.0);
            (self.offset_lo[1][i], self.offset_hi[1][i]) = (0.0, 0.0);
            self.lead[i] = 0.0;
            if delta == DVec3::ZERO {
                continue;
            }
            for (j, a) in [u, v].into_iter().enumerate() {
                let c = delta[a] - delta[self.axis] * self.slope[j][i];
                self.offset_lo[j][i] = c - widen(c);
                self.offset_hi[j][i] = c + widen(c);
            }
            let along = delta[self.axis].abs();
            self.lead[i] = along + widen(along);
            let length = delta.length();
            self.spread = self.spread.max(length + widen(length));
        }
    }

    /// How far from the origin a ray may start.
    pub fn spread(&self) -> f64 {
        self.spread
    }

    /// The axis every ray travels along the same way.
    pub fn axis(&self) -> usize {
        self.axis
    }

    /// +1 where the rays go up [`Packet::axis`], −1 where they go down.
    pub fn step(&self) -> i64 {
        self.step
    }

    /// The two axes across the slabs.
    fn cross(&self) -> [usize; 2] {
        [(self.axis + 1) % 3, (self.axis + 2) % 3]
    }

    /// The least and greatest slopes of the rays at [`TILE_CORNERS`], per
    /// cross axis: those of every ray of a tile ([`Packet::tile`]).
    fn corner_slopes(&self) -> SlopeRange {
        self.range_of(TILE_CORNERS.into_iter())
    }

    /// The least and greatest slopes and start offsets, per cross axis, of
    /// the rays of `groups` (one bit per group): a range that holds those of
    /// any of their rays, found from the groups' ranges ([`Packet::aim`]) at
    /// the cost of a group rather than of a ray. It may be wider than the
    /// live rays' own (a group's rays retire one by one), so the slabs'
    /// rectangles may hold more cells, never fewer.
    pub(super) fn slope_range(&self, groups: u32) -> SlopeRange {
        set_bits(u64::from(groups))
            .map(|g| self.group_ranges[g])
            .fold(SlopeRange::EMPTY, |range, group| range.join(&group))
    }

    /// The least and greatest slope of group `g`'s rays on cross axis `j`.
    pub(super) fn group_slopes(&self, g: usize, j: usize) -> (f64, f64) {
        let range = &self.group_ranges[g];
        (range.lo[j], range.hi[j])
    }

    /// [`Packet::slope_range`] of the rays `rays`.
    #[inline(always)]
    fn range_of(&self, rays: impl Iterator<Item = usize>) -> SlopeRange {
        let mut range = SlopeRange::EMPTY;
        for i in rays {
            for j in 0..2 {
                let m = self.slope[j][i];
                range.lo[j] = lesser(range.lo[j], m);
                range.hi[j] = greater(range.hi[j], m);
                range.offset_lo[j] = lesser(range.offset_lo[j], self.offset_lo[j][i]);
                range.offset_hi[j] = greater(range.offset_hi[j], self.offset_hi[j][i]);
            }
        }
        range
    }
}

/// The spread of a set of the packet's rays across the slabs.
#[derive(Clone, Copy)]
pub(super) struct SlopeRange {
    lo: [f64; 2],
    hi: [f64; 2],
    /// The least and greatest start offsets (see [`Packet::offset_lo`]).
    offset_lo: [f64; 2],
    offset_hi: [f64; 2],
}

impl SlopeRange {
    /// The range of no rays, which joins any range to that range.
    const EMPTY: SlopeRange = SlopeRange {
        lo: [f64::INFINITY; 2],
        hi: [f64::NEG_INFINITY; 2],
        offset_lo: [f64::INFINITY; 2],
        offset_hi: [f64::NEG_INFINITY; 2],
    };

    /// The range of the rays of both.
    fn join(&self, other: &SlopeRange) -> SlopeRange {
        SlopeRange {
            lo: [0, 1].map(|j| lesser(self.lo[j], other.lo[j])),
            hi: [0, 1].map(|j| greater(self.hi[j], other.hi[j])),
            offset_lo: [0, 1].map(|j| lesser(self.offset_lo[j], other.offset_lo[j])),
            offset_hi: [0, 1].map(|j| greater(self.offset_hi[j], other.offset_hi[j])),
        }
    }

    /// The same slopes, the offsets widened by `by` each way.
    pub(super) fn widened(&self, by: f64) -> SlopeRange {
        SlopeRange {
            offset_lo: self.offset_lo.map(|x| x - by),
            offset_hi: self.offset_hi.map(|x| x + by),
            ..*self
        }
    }

    /// The greatest slope's magnitude.
    pub(super) fn steepest(&self) -> f64 {
        (self.lo.iter().chain(&self.hi)).fold(0.0, |m, x| greater(m, x.abs()))
    }
}

/// A rectangle of cells across the slab axis: `[lo, hi]` on the two other axes.
#[derive(Clone, Copy)]
pub(super) struct Rect {
    pub lo: [i64; 2],
    pub hi: [i64; 2],
}

/// Most blocks a layer's rectangle may cover for them all to be fetched up
/// front; a wider rectangle probes block by block.
const LAYER_BLOCKS: usize = 64;

impl Rect {
    /// The cells between two planes, from the cells each plane meets.
    #[inline(always)]
    pub(super) fn between(a: &Rect, b: &Rect) -> Rect {
        Rect {
            lo: [a.lo[0].min(b.lo[0]), a.lo[1].min(b.lo[1])],
            hi: [a.hi[0].max(b.hi[0]), a.hi[1].max(b.hi[1])],
        }
    }
}

/// How far a packet walk through a level may go.
#[derive(Clone, Copy, Debug)]
pub(super) struct Limits {
    /// The most cells one slab's rectangle may span: past it the walk
    /// gives up (the rays fan out too wide to share it).
    pub widest: f64,
    /// The planes across the packet's axis (coordinates times its step,
    /// the lesser first) between which the walk looks: it walks the slabs
    /// that meet them and no others.
    pub along: [f64; 2],
}

impl Limits {
    /// Every slab, however wide.
    pub const NONE: Limits = Limits {
        widest: f64::INFINITY,
        along: [f64::NEG_INFINITY, f64::INFINITY],
    };
}

/// Relative widening of the rule that retires a ray, against the rounding
/// of its two sides (a few units in the last place of f64).
const RETIRE_MARGIN: f64 = 1.0 / (1u64 << 40) as f64;

/// How far along the slab axis each ray of a packet still searches this
/// level, and the nearest of those among the live rays, in all and per
/// group: a ray whose best t (plus the slack) lies before a slab's entry
/// plane needs nothing beyond.
///
/// Ray i is at t = travel / |d_k| on the plane `travel` along the axis from
/// the origin, so it searches the slab entered there while
/// `travel ≤ reach_i·|d_k|`; the limit is widened by [`RETIRE_MARGIN`], as
/// retiring a ray late only costs work and retiring it early would lose hits.
struct Search {
    live: RaySet,
    /// The groups with a live ray, one bit each: kept as `live` changes,
    /// for every occupied cell's visit to be handed them.
    groups: u32,
    limit: [f64; RAYS],
    /// The nearest limit of each group's live rays, and of all of them:
    /// kept as limits shrink, so that a retirement need look only into the
    /// groups with a ray done.
    group_nearest: [f64; GROUPS],
    nearest: f64,
}

impl Search {
    /// The search of the rays `live`, none of them limited yet.
    fn new(live: RaySet) -> Self {
        Search {
            live,
            groups: live.groups(),
            limit: [f64::INFINITY; RAYS],
            group_nearest: [f64::INFINITY; GROUPS],
            nearest: f64::INFINITY,
        }
    }

    /// Brings the limits of the live rays among `rays` up to date
    /// with their best hits. A limit only shrinks (the best t only moves
    /// nearer), so the nearest limits are kept by taking the least.
    /// Inlined, as [`Level::walk_packet`] is.
    #[inline(always)]
    fn update(&mut self, packet: &Packet, reach: impl Fn(usize) -> f64, rays: RaySet) {
        let limit_of = |i: usize| {
            // A ray that starts ahead of the origin along the axis by δ
            // meets each plane δ sooner than the origin's travel says.
            let limit = reach(i) * packet.travel[i] + packet.lead[i];
            // A done ray's limit is −∞, which no margin may turn into NaN.
            if limit.is_finite() {
                limit + limit.abs() * RETIRE_MARGIN
            } else {
                limit
            }
        };
        let rays = rays & self.live;
        for w in 0..WORDS {
            let word = rays.word(w);
            if word != u64::MAX {
                // Part of a word (the rays a visit's tests moved nearer, or
                // a quarter's at the start of its walk): ray by ray.
                for i in set_bits(word).map(|bit| w * 64 + bit) {
                    let limit = limit_of(i);
                    self.limit[i] = limit;
                    let g = &mut self.group_nearest[i / LANES];
                    *g = lesser(*g, limit);
                    self.nearest = lesser(self.nearest, limit);
                }
                continue;
            }
            // A whole word (the start of a whole packet's walk): every ray,
            // group by group.
            for g in w * 64 / LANES..(w + 1) * 64 / LANES {
                let mut nearest = self.group_nearest[g];
                for i in g * LANES..(g + 1) * LANES {
                    let limit = limit_of(i);
                    self.limit[i] = limit;
                    nearest = lesser(nearest, limit);
                }
                self.group_nearest[g] = nearest;
                self.nearest = lesser(self.nearest, nearest);
            }
        }
    }

    /// Retires the rays done before `travel`, looking only into the groups
    /// whose nearest limit lies before it; true when the live set changed.
    /// Inlined: left to the compiler, it went out of line in some builds
    /// and not others, and the eye packets' code around it changed with it
    /// (clustered 10⁵ 8% more instructions than inlined).
    #[inline(always)]
    fn retire(&mut self, travel: f64) -> bool {
        if travel <= self.nearest {
            return false;
        }
        self.nearest = f64::INFINITY;
        for g in set_bits(u64::from(self.groups)) {
            if travel > self.group_nearest[g] {
                let (mut nearest, mut lanes) = (f64::INFINITY, self.live.lanes(g));
                for lane in set_bits(u64::from(lanes)) {
                    let i = g * LANES + lane;
                    let limit = self.limit[i];
                    if travel > limit {
                        self.live.remove(i);
                        lanes &= !(1 << lane);
                    } else {
                        nearest = lesser(nearest, limit);
                    }
                }
                self.group_nearest[g] = nearest;
                if lanes == 0 {
                    self.groups &= !(1 << g);
                }
            }
            self.nearest = lesser(self.nearest, self.group_nearest[g]);
        }
        true
    }
}

/// The cells, on the two cross axes, that rays with slopes in a
/// [`SlopeRange`] meet on a plane across the slab axis, in one lattice
/// (a level's cells, or the gate's cubes).
pub(super) struct PlaneCells {
    /// The origin's cross coordinates relative to the lattice, in cells.
    start: [f64; 2],
    inv_cell: f64,
    /// The last cell on each cross axis, as f64 (exact: it is below 2²¹).
    top: [f64; 2],
}

impl PlaneCells {
    fn new(level: &Level, packet: &Packet) -> Self {
        PlaneCells::of_lattice(&level.origin.to_array(), level.per_cell, level.dims, packet)
    }

    /// The cells of the lattice whose cell (0, 0, 0) starts at `origin`,
    /// `per_cell` of them a unit, `dims` a side.
    pub(super) fn of_lattice(
        origin: &[f64; 3],
        per_cell: f64,
        dims: [i64; 3],
        packet: &Packet,
    ) -> Self {
        let cross = packet.cross();
        // Cells are powers of two, so scaling by the reciprocal is exact
        // and rounds exactly as dividing by the side would.
        PlaneCells {
            start: cross.map(|a| (packet.origin[a] - origin[a]) * per_cell),
            inv_cell: per_cell,
            top: cross.map(|a| (dims[a] - 1) as f64),
        }
    }

    /// The cells met on the plane `delta` from the origin along the slab
    /// axis: a ray's cross coordinate there is `o_u + delta·m + c` for its
    /// slope m and start offset c.
    #[inline(always)]
    pub(super) fn at(&self, range: &SlopeRange, delta: f64) -> Rect {
        let mut rect = Rect {
            lo: [0; 2],
            hi: [0; 2],
        };
        for j in 0..2 {
            let (lo, hi) = if delta >= 0.0 {
                (delta * range.lo[j], delta * range.hi[j])
            } else {
                (delta * range.hi[j], delta * range.lo[j])
            };
            let (lo, hi) = (lo + range.offset_lo[j], hi + range.offset_hi[j]);
            // ⌊x⌋ clamped to [0, top]: clamped first, where truncation is
            // the floor (and a NaN becomes 0, as `floor_to_int` makes it).
            let cell = |p: f64| {
                let x = greater(0.0, self.start[j] + p * self.inv_cell);
                lesser(self.top[j], x) as i64
            };
            rect.lo[j] = cell(lo);
            rect.hi[j] = cell(hi);
        }
        rect
    }

    /// How many cells the rectangle of one slab spans at most, for rays
    /// with slopes and offsets in `range` between the planes `ends` (its
    /// width grows linearly with the distance from the origin, so it is
    /// widest at one end).
    fn widest(&self, range: &SlopeRange, ends: [f64; 2]) -> f64 {
        let far = ends[0].abs().max(ends[1].abs());
        let cells = |j: usize| {
            let width = far * (range.hi[j] - range.lo[j]) + range.offset_hi[j] - range.offset_lo[j];
            width * self.inv_cell + 1.0
        };
        cells(0) * cells(1)
    }
}

impl Level {
    /// Walks the rays `among` of the packet through this level,
    /// offering `visit` the sphere ids of every occupied cell a
    /// still-searching ray may cross within the slabs that meet
    /// `limits.along`, and the groups (one bit each) with a ray still
    /// searching. False, walking nothing, when those rays fan out
    /// across more than `limits.widest` cells of one slab: so wide a
    /// rectangle would visit more cells than the rays one at a time.
    ///
    /// A slab's rectangle joins the cells its two planes meet: the cross
    /// coordinate `o_u + delta·m` is bilinear in the plane and the slope, so
    /// over a slab and a set of rays its extremes lie on the planes, at the
    /// extreme slopes. Rounding is monotone, so the rectangle of a slab
    /// computed so lies inside that of the layer it belongs to.
    ///
    /// Inlined into each caller, so that each instance of a caller's kernel
    /// ([`super::vectors`]) compiles the walk with its own instructions.
    #[inline(always)]
    pub(super) fn walk_packet<S: Searching>(
        &self,
        packet: &Packet,
        rays: &mut S,
        among: RaySet,
        limits: Limits,
        empty_space: EmptySpace,
        visit: &mut impl PacketVisit<S>,
    ) -> bool {
        let (k, step) = (packet.axis, packet.step);
        let slack: [f64; RAYS] = packet.inv_length.map(|inv| self.slack * inv);
        let t_lo = rays.t_min();
        // Each ray's exit from the level's box (widened by the slack), and
        // the first and last slab any ray is in, counted along the travel.
        // A tile whose corner rays stay within the box's sides between its
        // two planes across the axis leaves it through those planes: the two
        // give each ray's span in the box, for a third of the work. Should a
        // ray leave through a side after all, its span only runs on past the
        // box, and the walk goes on through the edge cells (the rectangles
        // keep to the level): more cells, never fewer, so the same answers.
        let mut exit = [f64::NEG_INFINITY; RAYS];
        let across_only = packet.tile && self.holds_between_planes(packet);
        let (live, first_along, last_along) = if across_only {
            self.enter_box::<true>(packet, &rays.reaches(), among, t_lo, &slack, &mut exit)
        } else {
            self.enter_box::<false>(packet, &rays.reaches(), among, t_lo, &slack, &mut exit)
        };
        let first_along = greater(first_along, limits.along[0]);
        let last_along = lesser(last_along, limits.along[1]);
        if live.is_empty() || first_along > last_along {
            return true;
        }
        let top = self.dims[k] - 1;
        let slab_of = |p: f64| self.slab_at(p * step as f64, k, 0, top) * step;
        let (first, last) = (slab_of(first_along), slab_of(last_along));
        let reach = |i: usize, rays: &S| lesser(rays.reach(i) + slack[i], exit[i]);
        let mut search = Search::new(live);
        // At the start a ray's reach is its exit (`clip` ends there, or sooner).
        search.update(packet, |i| exit[i], live);
        rays.take_improved();
        // Slab s lies between planes s and s + 1; a ray entering it going
        // down the axis crosses plane s + 1 first.
        let entry_plane = |s: i64| if step > 0 { s } else { s + 1 };
        let delta = |plane: i64| self.origin[k] + plane as f64 * self.cell - packet.origin[k];
        let travel = |s: i64| delta(entry_plane(s)) * step as f64;
        let mut range = packet.slope_range(search.groups);
        let cells = PlaneCells::new(self, packet);
        let (first, last) = (first * step, last * step);
        let ends = [delta(entry_plane(first)), delta(entry_plane(last + step))];
        if cells.widest(&range, ends) > limits.widest {
            return false;
        }
        let mut blocks = LayerBlocks {
            state: LayerState::Empty,
            lo: [0; 2],
            width: 0,
            blocks: [None; LAYER_BLOCKS],
        };
        // The last slab of the aligned run of 2^shift slabs that s is in (or of the walk).
        let run_end = |s: i64, shift: u32| {
            if step > 0 {
                (s | ((1 << shift) - 1)).min(last)
            } else {
                (s >> shift << shift).max(last)
            }
        };
        let mut region_end = first - step;
        let mut s = first;
        while s * step <= last * step {
            let mut entry = cells.at(&range, delta(entry_plane(s)));
            // The rest of the layer of slabs one block thick that s is in.
            let layer_end = run_end(s, BLOCK_SHIFT);
            let empty_until = if s * step > region_end * step {
                // Entering a layer of regions: crossed at once when its
                // rectangle meets no occupied block.
                region_end = run_end(s, 2 * BLOCK_SHIFT);
                let exit = cells.at(&range, delta(entry_plane(region_end + step)));
                let rect = Rect::between(&entry, &exit);
                (!self.any_block_in(k, [s, region_end], rect)).then_some(region_end)
            } else {
                None
            };
            let empty_until = empty_until.or_else(|| {
                let layer_exit = cells.at(&range, delta(entry_plane(layer_end + step)));
                let rect = Rect::between(&entry, &layer_exit);
                self.layer_blocks(k, s, rect, empty_space, &mut blocks);
                (blocks.state == LayerState::Empty).then_some(layer_end)
            });
            let Some(empty_until) = empty_until else {
                while s * step <= layer_end * step {
                    let leaving = cells.at(&range, delta(entry_plane(s + step)));
                    let rect = Rect::between(&entry, &leaving);
                    self.visit_slab(k, s, rect, &blocks, (visit, rays, search.groups));
                    s += step;
                    entry = leaving;
                    // The tests may have found nearer hits.
                    let improved = rays.take_improved();
                    if !improved.is_empty() {
                        search.update(packet, |i| reach(i, rays), improved);
                    }
                    if search.retire(travel(s)) {
                        if search.live.is_empty() {
                            return true;
                        }
                        range = packet.slope_range(search.groups);
                        entry = cells.at(&range, delta(entry_plane(s)));
                    }
                }
                continue;
            };
            s = empty_until + step;
            if search.retire(travel(s)) {
                if search.live.is_empty() {
                    return true;
                }
                range = packet.slope_range(search.groups);
            }
        }
        true
    }

    /// Clips each ray among `among` to the level's box (to its two planes
    /// across the packet's axis alone if `ACROSS`) within its search from
    /// `t_lo` to `reach`, both widened by its `slack`, and writes where it
    /// leaves to `exit`. Returns the rays that meet the box, and their
    /// first and last points along the axis times its step: the slab of a
    /// point is monotone in its coordinate, so the extreme points give the
    /// extreme slabs, with two look-ups instead of two a ray.
    #[inline(always)]
    fn enter_box<const ACROSS: bool>(
        &self,
        packet: &Packet,
        reach: &[f64; RAYS],
        among: RaySet,
        t_lo: f64,
        slack: &[f64; RAYS],
        exit: &mut [f64; RAYS],
    ) -> (RaySet, f64, f64) {
        let (k, step) = (packet.axis, packet.step as f64);
        // `(o_k + t·d_k)·step`, exactly: the step is ±1 and `d_k·step` is
        // the ray's travel along the axis.
        let along = |i: usize, t: f64| packet.rays[i].o[k] * step + t * packet.travel[i];
        // Every ray goes the packet's way along its axis: the same two planes.
        let planes = self.planes_across(k, packet.step);
        let clip = |i: usize| {
            let ray = &packet.rays[i];
            let (from, to) = (t_lo - slack[i], reach[i] + slack[i]);
            if ACROSS {
                let (a, b) = between_planes(planes, ray, k, (from, to));
                (a, b, a <= b)
            } else {
                span_in_box(&self.origin.to_array(), &self.far, ray, from, to)
            }
        };
        let mut live = [0; WORDS];
        let (mut first_along, mut last_along) = (f64::INFINITY, f64::NEG_INFINITY);
        for (w, live) in live.iter_mut().enumerate() {
            let among = among.word(w);
            if among != u64::MAX {
                // Part of a word (a quarter's rays, or a shadow packet's
                // still unblocked): ray by ray.
                for bit in set_bits(among) {
                    let i = w * 64 + bit;
                    let (a, b, meets) = clip(i);
                    if meets {
                        exit[i] = b;
                        *live |= 1 << bit;
                        first_along = lesser(first_along, along(i, a));
                        last_along = greater(last_along, along(i, b));
                    }
                }
                continue;
            }
            // A whole word (a walk of the whole packet): each ray kept or
            // not by a select rather than a branch, as which rays a
            // packet's clip keeps is as good as random.
            for bit in 0..64 {
                let i = w * 64 + bit;
                let (a, b, meets) = clip(i);
                exit[i] = if meets { b } else { f64::NEG_INFINITY };
                *live |= u64::from(meets) << bit;
                let (a, b) = if meets {
                    (along(i, a), along(i, b))
                } else {
                    (f64::INFINITY, f64::NEG_INFINITY)
                };
                first_along = lesser(first_along, a);
                last_along = greater(last_along, b);
            }
        }
        (RaySet::from_words(live), first_along, last_along)
    }

    /// Whether the rays from the packet's origin with its corner rays'
    /// slopes ([`Packet::corner_slopes`]) stay within this level's box on
    /// the two cross axes between the box's planes across the packet's axis
    /// (or from the origin on, where that lies between them). The cross
    /// coordinates are affine in the distance travelled along the axis, so
    /// the extremes lie at the two ends and the extreme slopes.
    fn holds_between_planes(&self, packet: &Packet) -> bool {
        let range = packet.corner_slopes();
        let (k, step) = (packet.axis, packet.step as f64);
        let o = packet.origin;
        let (entry, exit) = self.planes_across(k, packet.step);
        let ends = [greater(0.0, (entry - o[k]) * step), (exit - o[k]) * step];
        (0..2).all(|j| {
            let u = (k + 1 + j) % 3;
            ends.iter().all(|&travel| {
                let (a, b) = (
                    o[u] + travel * step * range.lo[j],
                    o[u] + travel * step * range.hi[j],
                );
                lesser(a, b) >= self.origin[u] && greater(a, b) <= self.far[u]
            })
        })
    }

    /// Fetches the blocks of a layer's rectangle into `layer`, once for all
    /// the layer's slabs.
    fn layer_blocks(
        &self,
        k: usize,
        s: i64,
        rect: Rect,
        empty_space: EmptySpace,
        layer: &mut LayerBlocks,
    ) {
        let (u, v) = ((k + 1) % 3, (k + 2) % 3);
        let lo = rect.lo.map(|c| c >> BLOCK_SHIFT);
        let hi = rect.hi.map(|c| c >> BLOCK_SHIFT);
        let width = hi[1] - lo[1] + 1;
        if ((hi[0] - lo[0] + 1) * width) as usize > LAYER_BLOCKS
            || empty_space == EmptySpace::ProbeEveryCell
        {
            layer.state = LayerState::ProbeEach;
            return;
        }
        let mut any = false;
        let mut slot = layer.blocks.iter_mut();
        for bu in lo[0]..=hi[0] {
            for bv in lo[1]..=hi[1] {
                let mut b = [0; 3];
                b[k] = s >> BLOCK_SHIFT;
                b[u] = bu;
                b[v] = bv;
                let block = self.table.get(b);
                any |= block.is_some();
                if let Some(slot) = slot.next() {
                    *slot = block;
                }
            }
        }
        (layer.lo, layer.width) = (lo, width);
        layer.state = if any {
            LayerState::Fetched
        } else {
            LayerState::Empty
        };
    }

    /// Whether any block is occupied among the slabs `slabs` (both ends
    /// inside one layer of regions along axis `k`) within `rect`: one region
    /// probe per 16×16 cells of the rectangle.
    fn any_block_in(&self, k: usize, slabs: [i64; 2], rect: Rect) -> bool {
        let (u, v) = ((k + 1) % 3, (k + 2) % 3);
        let side = 1 << BLOCK_SHIFT;
        let [lo, hi] = [rect.lo, rect.hi].map(|c| c.map(|c| c >> BLOCK_SHIFT));
        let blocks = slabs.map(|s| s >> BLOCK_SHIFT);
        let region = |b: i64| b >> BLOCK_SHIFT;
        for ru in region(lo[0])..=region(hi[0]) {
            for rv in region(lo[1])..=region(hi[1]) {
                let mut r = [0; 3];
                r[k] = region(blocks[0]);
                r[u] = ru;
                r[v] = rv;
                let mask = match self.table.region(block_key(r)).map(|r| r.blocks) {
                    None => continue,
                    Some(u64::MAX) => return true,
                    Some(mask) => mask,
                };
                // The blocks of this region in the slabs and the rectangle,
                // in the region's own coordinates.
                let (mut from, mut to) = ([0; 3], [0; 3]);
                let local = |b: i64, r: i64| (b - r * side).clamp(0, side - 1);
                (from[k], to[k]) = (
                    local(blocks[0].min(blocks[1]), r[k]),
                    local(blocks[0].max(blocks[1]), r[k]),
                );
                (from[u], to[u]) = (local(lo[0], ru), local(hi[0], ru));
                (from[v], to[v]) = (local(lo[1], rv), local(hi[1], rv));
                if mask & box_mask(from, to) != 0 {
                    return true;
                }
            }
        }
        false
    }

    /// Offers `visit` the occupied cells of slab `s` within `rect`, with
    /// the rays and their groups still searching. Inlined, as
    /// [`Self::walk_packet`] is.
    #[inline(always)]
    fn visit_slab<S>(
        &self,
        k: usize,
        s: i64,
        rect: Rect,
        blocks: &LayerBlocks,
        (visit, rays, groups): (&mut impl PacketVisit<S>, &mut S, u32),
    ) {
        let (u, v) = ((k + 1) % 3, (k + 2) % 3);
        // A cell's bit in its block, axis by axis (see `cell_bit`).
        let side = (1 << BLOCK_SHIFT) - 1;
        let bit_on = |axis: usize, c: i64| ((c & side) as u32) << (BLOCK_SHIFT as usize * axis);
        let bit_k = bit_on(k, s);
        for cu in rect.lo[0]..=rect.hi[0] {
            let bit_ku = bit_k | bit_on(u, cu);
            // The row of the layer's blocks this cu lies in, offset so that
            // adding cv's block gives its slot.
            let row = ((cu >> BLOCK_SHIFT) - blocks.lo[0]) * blocks.width - blocks.lo[1];
            for cv in rect.lo[1]..=rect.hi[1] {
                let block = match blocks.state {
                    LayerState::Fetched => blocks.blocks[(row + (cv >> BLOCK_SHIFT)) as usize],
                    _ => {
                        let mut c = [0; 3];
                        (c[k], c[u], c[v]) = (s, cu, cv);
                        self.table.get(c.map(|x| x >> BLOCK_SHIFT))
                    }
                };
                let bit = bit_ku | bit_on(v, cv);
                if let Some(b) = block.filter(|b| b.holds(bit)) {
                    visit.cell(self.candidates(b.cell_index(bit)), rays, groups);
                }
            }
        }
    }
}

/// What a layer's rectangle holds.
#[derive(Clone, Copy, PartialEq, Eq)]
enum LayerState {
    /// Only empty blocks: the layer is crossed without a look inside.
    Empty,
    /// Its blocks are in [`LayerBlocks::blocks`].
    Fetched,
    /// Too many blocks to fetch up front (or every cell is to be probed).
    ProbeEach,
}

/// The blocks of the current layer's rectangle. One per packet walk, reused
/// layer after layer.
struct LayerBlocks {
    state: LayerState,
    /// The rectangle's first block on the two cross axes.
    lo: [i64; 2],
    /// Blocks per row on the second cross axis.
    width: i64,
    /// Row-major over the rectangle from `lo` (when `Fetched`).
    blocks: [Option<Block>; LAYER_BLOCKS],
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::packet::TILE_SIDE;
    use crate::index::grid::tests::scattered;
    use crate::index::grid::VoxelHashGrid;
    use crate::rng::Rng;
    use glam::Vec3;

    /// Aims `packet` at a tile of eye rays from `eye` toward `aim`, `pixel`
    /// apart, in the renderer's order ([`crate::render::tiles`]).
    fn aim_tile(packet: &mut Packet, eye: DVec3, aim: DVec3, pixel: f64) -> bool {
        let forward = (aim - eye).normalize();
        let right = forward.any_orthonormal_vector();
        let up = forward.cross(right);
        let side = TILE_SIDE as u32;
        let pixels = crate::render::tiles(side, 0..side)
            .next()
            .expect("one tile");
        assert_eq!(pixels.len(), RAYS);
        let middle = f64::from(side - 1) / 2.0;
        for (ray, (x, y)) in packet.rays.iter_mut().zip(pixels) {
            let (x, y) = (f64::from(x) - middle, f64::from(y) - middle);
            let d = forward + (right * x + up * y) * pixel;
            *ray = Ray64::from_f64(eye, d).expect("a direction");
        }
        packet.aim_tile(eye.to_array())
    }

    /// Where a tile's corner rays say the level's box holds it between its
    /// two planes across the axis, the two planes give every ray of the tile
    /// the span the six give it; and they say so for tiles aimed well inside.
    /// The slope range of any set of live rays, found from their groups'
    /// ranges, holds each live ray's slopes and start offsets, for rays
    /// from one point and rays that start near it (as shadow rays do).
    #[test]
    fn a_live_sets_slope_range_holds_each_live_ray() {
        let mut rng = Rng::new(17);
        let unit = |rng: &mut Rng| DVec3::from_array([0; 3].map(|_| rng.range(-1.0, 1.0)));
        let mut checked = 0;
        for case in 0..300 {
            let axis = unit(&mut rng) + DVec3::new(2.0, 0.0, 0.0);
            let spread = 10f64.powf(rng.range(-5.0, -0.5));
            let near = [0.0, 1e-3][case % 2];
            Packet::with_spare(|packet| {
                for ray in packet.rays.iter_mut() {
                    let o = unit(&mut rng) * near;
                    let d = axis + unit(&mut rng) * spread;
                    *ray = Ray64::from_f64(o, d).expect("a direction");
                }
                if !packet.aim([0.0; 3]) {
                    return;
                }
                let mut live = RaySet::NONE;
                for i in 0..RAYS {
                    if rng.next_u64().is_multiple_of(5) {
                        live |= single(i);
                    }
                }
                let range = packet.slope_range(live.groups());
                for i in live.iter() {
                    for j in 0..2 {
                        let m = packet.slope[j][i];
                        assert!(range.lo[j] <= m && m <= range.hi[j], "case {case}: ray {i}");
                        assert!(range.offset_lo[j] <= packet.offset_lo[j][i]);
                        assert!(packet.offset_hi[j][i] <= range.offset_hi[j]);
                    }
                    checked += 1;
                }
            });
        }
        assert!(checked > 10_000, "{checked} rays checked");
    }

    /// The set of ray `i` alone.
    fn single(i: usize) -> RaySet {
        RaySet::from_lanes((0..GROUPS).map(|g| if g == i / LANES { 1 << (i % LANES) } else { 0 }))
    }

    #[test]
    fn a_tile_held_between_two_planes_spans_what_six_planes_give() {
        let shapes = scattered(5, 3_000, 4.0, Vec3::splat(0.04));
        let grid = VoxelHashGrid::new(&shapes);
        let mut rng = Rng::new(21);
        let mut held = 0;
        for case in 0..400 {
            let level = &grid.levels[case % grid.levels.len()];
            let size = DVec3::from_array(level.far) - level.origin;
            // Eyes in and around the box, aims within it, tiles narrow to wide.
            let place = |rng: &mut Rng, wide: f64| {
                level.origin
                    + DVec3::from_array([0; 3].map(|_| rng.range(-wide, 1.0 + wide))) * size
            };
            let eye = place(&mut rng, [0.0, 0.5, 2.0][case % 3]);
            let aim = place(&mut rng, -0.2);
            let pixel = [1e-4, 1e-2, 0.1][case / 3 % 3];
            Packet::with_spare(|packet| {
                if !aim_tile(packet, eye, aim, pixel) || !level.holds_between_planes(packet) {
                    return;
                }
                held += 1;
                for ray in &packet.rays {
                    let six = level.clip(ray, 0.0, f64::MAX);
                    let planes = level.planes_across(packet.axis, packet.step);
                    let two = between_planes(planes, ray, packet.axis, (0.0, f64::MAX));
                    let two = (two.0 <= two.1).then_some(two);
                    let (Some(six), Some(two)) = (six, two) else {
                        assert_eq!(six.is_some(), two.is_some(), "case {case}");
                        continue;
                    };
                    let tolerance = 1e-9 * two.1.abs().max(1.0);
                    assert!(
                        (six.0 - two.0).abs() <= tolerance && (six.1 - two.1).abs() <= tolerance,
                        "case {case}: six planes {six:?}, two {two:?}"
                    );
                }
            });
        }
        assert!(held > 50, "only {held} tiles held");
    }
}
