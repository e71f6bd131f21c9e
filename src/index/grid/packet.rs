//! Packets: rays from one origin walked through each level together.
//!
//! Eye rays leave one point in nearly the same direction, so neighbouring
//! pixels cross the same cells and meet the same candidates; walked one at a
//! time they repeat every cell step, probe and sphere fetch. A packet walks a
//! level once, slab by slab along an axis all its rays travel the same way
//! (the coherent grid traversal of Wald et al., "Ray Tracing Animated Scenes
//! using Coherent Grid Traversal", 2006). In each slab (one cell thick) the
//! rays' segments span a rectangle of cells; every candidate of the occupied
//! cells there is tested against the packet's rays, sixteen at a time in
//! lanes the compiler turns into SIMD; and the packet moves on while any of
//! its rays still wants cells that far. A layer of slabs one block thick
//! whose rectangle meets only empty blocks is crossed with one probe per
//! block, and a layer of regions (four block layers) with one probe per
//! region.
//!
//! A candidate is first tested against a cone around the packet's 64 rays,
//! then against a cone around each group of 16 (a 4×4 quarter of the tile),
//! and only the groups whose cone it may meet run the lane test.
//!
//! # Why it returns what brute force returns
//! - Every cell a ray crosses within a slab lies in the rectangle: a ray's
//!   segment in a slab is straight, and the rectangle bounds both its ends.
//! - A ray stops wanting cells under the single walk's rule: once its best t
//!   plus the level's slack lies before the slab it would enter next.
//! - Testing a ray against a sphere from a cell it never crosses can only find
//!   a true hit, which brute force finds too; the nearest (t, id) wins
//!   whatever the order of the tests.
//! - The lanes compute exactly the operations of [`crate::geometry::Ellipsoid::intersect`], in
//!   the same order (no fused multiply-adds: Rust does not contract), so every
//!   lane rounds exactly as the one-ray test does.

use super::table::{block_key, box_mask, Block, BLOCK_SHIFT};
use super::walk::Ray64;
use super::{EmptySpace, Level, VoxelHashGrid};
use crate::geometry::{Ray, Real, UnitSphereFrame, Vec3Ops, V3};
use crate::index::{Hit, SphereIndex};
use glam::DVec3;

/// Rays tested against a sphere at once: a 4×4 tile of pixels, in SIMD
/// lanes. Wider, each test would spend more lanes on rays that miss.
pub const LANES: usize = 16;
/// Groups of [`LANES`] rays per packet.
const GROUPS: usize = 4;
/// Rays per packet: an 8×8 tile of pixels (its four 4×4 quarters are the
/// groups). The walk's cost per packet grows far slower than its rays, so
/// larger packets share it among more rays; each group keeps a cone of its
/// own, so that a sphere is tested only against the groups that may hit it.
pub const RAYS: usize = GROUPS * LANES;

/// The rays of one packet, laid out for the lane-wise sphere test, and the
/// best hit of each so far.
struct Lanes<R: Real> {
    origin: V3<R>,
    /// Direction components, one array per axis.
    dir: [[R; LANES]; 3],
    best_t: [R; LANES],
    best_id: [u32; LANES],
    /// A hit counts up to and including the best t so far (so that an equal
    /// t with a lower id still wins, as in brute force): `best_t.next_up()`.
    cap: [R; LANES],
    t_min: R,
    /// The lanes whose best hit moved nearer, one bit each.
    improved: u32,
}

impl<R: Real> Lanes<R> {
    fn new(origin: V3<R>, t_min: R) -> Self {
        Lanes {
            origin,
            dir: [[R::zero(); LANES]; 3],
            best_t: [R::infinity(); LANES],
            best_id: [u32::MAX; LANES],
            cap: [R::infinity(); LANES],
            t_min,
            improved: 0,
        }
    }

    /// Sets the lanes' directions and forgets their hits.
    fn aim(&mut self, dirs: &[V3<R>], t_max: R) {
        for (i, d) in dirs.iter().enumerate().take(LANES) {
            self.dir[0][i] = d.x();
            self.dir[1][i] = d.y();
            self.dir[2][i] = d.z();
        }
        self.best_t = [R::infinity(); LANES];
        self.best_id = [u32::MAX; LANES];
        self.cap = [t_max; LANES];
        self.improved = 0;
    }

    /// [`UnitSphereFrame::intersect`] for every lane at once, keeping each lane's
    /// nearest (t, id).
    // The lane loops index several arrays in step, which is what the compiler
    // turns into SIMD.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn test(&mut self, shape: &UnitSphereFrame<R>, id: u32) {
        let s = shape.inv_scale;
        // The origin is shared, so `f` and `c` are the same for every lane.
        let f = (self.origin - shape.center) * s;
        let ff = f.dot(f);
        let c = ff - R::one();
        let mut found = [R::nan(); LANES];
        if ff > R::NEAR_FRAME {
            self.test_wide(shape, &mut found);
        } else {
            self.test_near(f, c, s, &mut found);
        }
        self.keep_nearest(&found, id);
    }

    /// The lanes of [`Self::test`] for a sphere whose frame the origin lies
    /// beyond [`Real::NEAR_FRAME`] radii in: the one-ray test in f64, lane
    /// by lane.
    #[allow(clippy::needless_range_loop)]
    #[inline(never)]
    fn test_wide(&self, shape: &UnitSphereFrame<R>, found: &mut [R; LANES]) {
        for i in 0..LANES {
            let dir = V3::<R>::new(self.dir[0][i], self.dir[1][i], self.dir[2][i]);
            let ray = Ray::new(self.origin, dir);
            found[i] = shape
                .intersect_wide(&ray, self.t_min, self.cap[i])
                .unwrap_or(R::nan());
        }
    }

    /// The lanes of [`Self::test`] in `R`: `f` and `c` are the origin in the
    /// sphere's frame and `f·f − 1`, `s` its inverse scale.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn test_near(&self, f: V3<R>, c: R, s: V3<R>, found: &mut [R; LANES]) {
        let (fx, fy, fz) = (f.x(), f.y(), f.z());
        let (sx, sy, sz) = (s.x(), s.y(), s.z());
        let one = R::one();
        for i in 0..LANES {
            let (ex, ey, ez) = (
                self.dir[0][i] * sx,
                self.dir[1][i] * sy,
                self.dir[2][i] * sz,
            );
            let a = ex * ex + ey * ey + ez * ez;
            let b = fx * ex + fy * ey + fz * ez;
            let k = b / a;
            let (lx, ly, lz) = (fx - ex * k, fy - ey * k, fz - ez * k);
            let k = (lx * ex + ly * ey + lz * ez) / a;
            let (lx, ly, lz) = (lx - ex * k, ly - ey * k, lz - ez * k);
            let disc = a * (one - (lx * lx + ly * ly + lz * lz));
            let q = -(b + disc.sqrt().copysign(b));
            let (t0, t1) = (c / q, q / a);
            let (near, far) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
            let cap = self.cap[i];
            let t = if near > self.t_min && near < cap {
                near
            } else if far > self.t_min && far < cap {
                far
            } else {
                R::nan()
            };
            // A NaN or negative discriminant: the line misses.
            found[i] = if disc >= R::zero() { t } else { R::nan() };
        }
    }

    /// Keeps each lane's nearest (t, id), given the lanes' hits with `id`.
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn keep_nearest(&mut self, found: &[R; LANES], id: u32) {
        for i in 0..LANES {
            let t = found[i];
            // NaN (no hit) fails both comparisons.
            if t < self.best_t[i] || (t == self.best_t[i] && id < self.best_id[i]) {
                self.best_t[i] = t;
                self.best_id[i] = id;
                self.cap[i] = t.next_up();
                self.improved |= 1 << i;
            }
        }
    }

    fn hit(&self, lane: usize) -> Option<Hit<R>> {
        (self.best_id[lane] != u32::MAX).then(|| Hit {
            t: self.best_t[lane],
            sphere: self.best_id[lane],
        })
    }
}

/// The packet's rays in f64 for the walk, and the axis it slabs along.
struct Packet {
    rays: [Ray64; RAYS],
    /// The rays' unit directions, for the choice of axis and the cones.
    unit: [DVec3; RAYS],
    /// An axis every ray travels along in the same direction.
    axis: usize,
    step: i64,
    /// Per ray, how far it moves across the slabs per unit along `axis`: on
    /// the two other axes (`axis + 1`, `axis + 2`, mod 3), `d_u / d_axis`.
    slope: [[f64; RAYS]; 2],
}

impl Packet {
    /// The packet of rays from `origin` along `dirs`; None when the rays
    /// share no axis of travel (or one cannot be walked): those rays go one
    /// at a time.
    fn new<R: Real>(origin: V3<R>, dirs: &[V3<R>; RAYS]) -> Option<Packet> {
        let mut walkable = true;
        let rays = std::array::from_fn(|i| {
            let ray = Ray64::new(&Ray::<R>::new(origin, dirs[i]));
            walkable &= ray.is_some();
            ray.unwrap_or_default()
        });
        if !walkable {
            return None;
        }
        let unit: [DVec3; RAYS] = rays.each_ref().map(|r| DVec3::from_array(r.d) / r.length);
        // How steeply the shallowest ray travels along each axis (0 when
        // some ray runs parallel to it or the other way).
        let first = unit[0];
        let mut steepness = [f64::INFINITY; 3];
        for u in &unit {
            for (axis, least) in steepness.iter_mut().enumerate() {
                let same_way = u[axis] != 0.0 && (u[axis] > 0.0) == (first[axis] > 0.0);
                *least = least.min(if same_way { u[axis].abs() } else { 0.0 });
            }
        }
        // The steepest axis gives the thinnest slab rectangles.
        let axis = (0..3).max_by(|&a, &b| steepness[a].total_cmp(&steepness[b]))?;
        let slope = [1, 2].map(|j| rays.each_ref().map(|r| r.d[(axis + j) % 3] / r.d[axis]));
        (steepness[axis] > 0.0).then(|| Packet {
            step: if first[axis] > 0.0 { 1 } else { -1 },
            rays,
            unit,
            axis,
            slope,
        })
    }

    /// The two axes across the slabs.
    fn cross(&self) -> [usize; 2] {
        [(self.axis + 1) % 3, (self.axis + 2) % 3]
    }

    /// The least and greatest slope of the rays in `live`, per cross axis.
    fn slope_range(&self, live: u64) -> SlopeRange {
        let mut range = SlopeRange {
            lo: [f64::INFINITY; 2],
            hi: [f64::NEG_INFINITY; 2],
        };
        for i in set_bits(live) {
            for j in 0..2 {
                let m = self.slope[j][i];
                range.lo[j] = range.lo[j].min(m);
                range.hi[j] = range.hi[j].max(m);
            }
        }
        range
    }
}

/// The spread of a set of the packet's rays across the slabs.
struct SlopeRange {
    lo: [f64; 2],
    hi: [f64; 2],
}

/// A cone from the packet's origin that holds a set of its rays (all of
/// them, or one group). A sphere whose bounding ball lies wholly outside it
/// meets none of them, so their lane tests are skipped for one scalar test.
///
/// # Why skipping is exact
/// Let V be the apex, a the unit axis and α the half-angle (every ray
/// direction d has ∠(a, d) ≤ α), so every point a ray reaches at t ≥ 0 lies
/// in the cone K = {V + x : ∠(a, x) ≤ α}. A rounded hit lies within ρ (the
/// candidate's `bound`, which holds the slack) of the centre C, so a sphere
/// can give a ray a hit only if its ball B(C, ρ) meets K.
///
/// Every point within ρ of K lies in the same cone moved back along its
/// axis, K' with apex U = V − m·a, m = ρ / sin α: the ball B(V, ρ) lies in
/// K' (V is on K''s axis at distance m from its apex, which puts it ρ from
/// K''s surface), and K' + x ⊆ K' for every direction x of K, so
/// B(V + x, ρ) ⊆ K' for every point V + x of K. With e = C − U and
/// s = a·e, C lies in K' exactly when s ≥ |e|·cos α, that is when s ≥ 0
/// and s² ≥ cos²α·|e|²: no square root. A candidate that fails it is
/// skipped.
///
/// All the packet's cones share the apex (the rays' origin), so the test
/// is written in w = C − V, computed once per candidate: s = a·w + m and
/// |e|² = |w|² + m·(2·a·w + m).
///
/// Only packets with `t_min ≥ 0` and α ≤ 60° get a cone. Rounding: for a
/// ball that meets K, C lies at least m − ρ ≥ 0.13·m from U (U is m from K,
/// and ρ = m·sin α ≤ 0.87·m), so |w| ≤ |e| + m ≤ 8.5·|e| and every term of
/// |e|² is at most about 130·|e|²; and s ≥ |e|/2 while its terms are at
/// most 16·|e|. The f64 rounding of the test is thus a few units of 1e-14
/// relative: [`CONE_MARGIN`] widens the angle and the final comparison far
/// beyond it.
#[derive(Clone, Copy)]
struct Cone {
    axis: DVec3,
    /// 1 / sin α: how far back the apex moves per unit of bound.
    inv_sin: f64,
    /// cos²α, lowered by [`CONE_MARGIN`] for the rounding of the test.
    cos2: f64,
}

/// Relative widening of the cone's angle and test, against f64 rounding.
const CONE_MARGIN: f64 = 1e-9;
/// The widest cone worth a test: cos 60°.
const MIN_CONE_COS: f64 = 0.5;

impl Cone {
    /// The cone around the unit directions `units`; None when the rays may
    /// reach behind the apex or spread too wide for a cone to pay.
    fn new(units: &[DVec3], t_min: f64) -> Option<Cone> {
        if t_min.is_nan() || t_min < 0.0 {
            return None;
        }
        let axis = units.iter().sum::<DVec3>().try_normalize()?;
        let cos = units.iter().map(|u| axis.dot(*u)).fold(1.0, f64::min) - CONE_MARGIN;
        (cos >= MIN_CONE_COS).then(|| Cone {
            axis,
            inv_sin: 1.0 / (1.0 - cos * cos).sqrt(),
            cos2: cos * cos * (1.0 - CONE_MARGIN),
        })
    }

    /// False only when no ray of the cone comes within `bound` of the
    /// candidate at `offset` from the apex.
    #[inline(always)]
    fn may_hit(&self, offset: &Offset, bound: f64) -> bool {
        let m = bound * self.inv_sin;
        let p = self.axis.dot(offset.w);
        let s = p + m;
        s >= 0.0 && s * s >= self.cos2 * (offset.w2 + m * (2.0 * p + m))
    }
}

/// A candidate's centre relative to the packet's origin, for its cone tests.
struct Offset {
    w: DVec3,
    /// |w|²
    w2: f64,
}

/// The cones of a packet: one around all its rays, one around each group.
struct Cones {
    packet: Option<Cone>,
    groups: [Option<Cone>; GROUPS],
}

impl Cones {
    fn new(packet: &Packet, t_min: f64) -> Cones {
        Cones {
            packet: Cone::new(&packet.unit, t_min),
            groups: std::array::from_fn(|g| {
                Cone::new(&packet.unit[g * LANES..(g + 1) * LANES], t_min)
            }),
        }
    }

    /// The groups among `groups` (a mask, one bit per group) whose rays may
    /// hit a candidate within `bound` of `center`.
    #[inline(always)]
    fn groups_hit(&self, origin: DVec3, center: DVec3, bound: f64, groups: u32) -> u32 {
        let w = center - origin;
        let offset = Offset {
            w,
            w2: w.length_squared(),
        };
        if self.packet.is_some_and(|c| !c.may_hit(&offset, bound)) {
            return 0;
        }
        let mut hit = 0;
        for (g, cone) in self.groups.iter().enumerate() {
            hit |= u32::from(cone.is_none_or(|c| c.may_hit(&offset, bound))) << g;
        }
        hit & groups
    }
}

/// The last spheres tested, direct-mapped: a packet meets each candidate in
/// several cells of a slab and of the slabs after it.
struct PacketMailbox([u32; MAILBOX]);

/// Slots of a packet's mailbox: a few times the spheres a packet meets.
const MAILBOX: usize = 256;

impl PacketMailbox {
    #[inline(always)]
    fn first_visit(&mut self, id: u32) -> bool {
        let slot = &mut self.0[id as usize % MAILBOX];
        let first = *slot != id;
        *slot = id;
        first
    }
}

/// A rectangle of cells across the slab axis: `[lo, hi]` on the two other axes.
#[derive(Clone, Copy)]
struct Rect {
    lo: [i64; 2],
    hi: [i64; 2],
}

/// Most blocks a layer's rectangle may cover for them all to be fetched up
/// front; a wider rectangle probes block by block.
const LAYER_BLOCKS: usize = 16;

impl Rect {
    /// The cells between two planes, from the cells each plane meets.
    fn between(a: &Rect, b: &Rect) -> Rect {
        Rect {
            lo: [a.lo[0].min(b.lo[0]), a.lo[1].min(b.lo[1])],
            hi: [a.hi[0].max(b.hi[0]), a.hi[1].max(b.hi[1])],
        }
    }
}

/// Relative widening of the rule that retires a ray, against the rounding
/// of its two sides (a few units in the last place of f64).
const RETIRE_MARGIN: f64 = 1.0 / (1u64 << 40) as f64;

/// How far along the slab axis each ray of a packet still searches this
/// level, and the nearest of those among the live rays: a ray whose best
/// t (plus the slack) lies before a slab's entry plane needs nothing beyond.
///
/// Ray i is at t = travel / |d_k| on the plane `travel` along the axis from
/// the origin, so it searches the slab entered there while
/// `travel ≤ reach_i·|d_k|`; the limit is widened by [`RETIRE_MARGIN`], as
/// retiring a ray late only costs work and retiring it early would lose hits.
struct Search {
    live: u64,
    limit: [f64; RAYS],
    nearest: f64,
}

impl Search {
    /// Brings the limits of the live rays among `rays` (a mask) up to date
    /// with their best hits. A limit only shrinks (the best t only moves
    /// nearer), so the nearest limit is kept by taking the least.
    fn update<R: Real>(
        &mut self,
        packet: &Packet,
        groups: &Groups<R>,
        reach: impl Fn(usize, R) -> f64,
        rays: u64,
    ) {
        let k = packet.axis;
        for i in set_bits(rays & self.live) {
            let limit = reach(i, best_t(groups, i)) * packet.rays[i].d[k].abs();
            let limit = limit + limit.abs() * RETIRE_MARGIN;
            self.limit[i] = limit;
            self.nearest = self.nearest.min(limit);
        }
    }

    /// Retires the rays done before `travel`; true when the live set changed.
    fn retire(&mut self, travel: f64) -> bool {
        if travel <= self.nearest {
            return false;
        }
        self.nearest = f64::INFINITY;
        for (i, &limit) in self.limit.iter().enumerate() {
            if travel > limit {
                self.live &= !(1 << i);
            } else if self.live >> i & 1 != 0 {
                self.nearest = self.nearest.min(limit);
            }
        }
        true
    }
}

/// The cells, on the two cross axes, that rays with slopes in a
/// [`SlopeRange`] meet on a plane across the slab axis, in one level.
struct PlaneCells {
    /// The origin's cross coordinates relative to the level's lattice, in cells.
    start: [f64; 2],
    inv_cell: f64,
    /// The last cell on each cross axis, as f64 (exact: it is below 2²¹).
    top: [f64; 2],
}

impl PlaneCells {
    fn new(level: &Level, packet: &Packet) -> Self {
        let cross = packet.cross();
        // Cells are powers of two, so scaling by the reciprocal is exact
        // and rounds exactly as dividing by the side would.
        let inv_cell = 1.0 / level.cell;
        PlaneCells {
            start: cross.map(|a| (packet.rays[0].o[a] - level.origin[a]) * inv_cell),
            inv_cell,
            top: cross.map(|a| (level.dims[a] - 1) as f64),
        }
    }

    /// The cells met on the plane `delta` from the origin along the slab
    /// axis: a ray's cross coordinate there is `o_u + delta·m` for its slope m.
    #[inline(always)]
    fn at(&self, range: &SlopeRange, delta: f64) -> Rect {
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
            // ⌊x⌋ clamped to [0, top]: clamped first, where truncation is
            // the floor (and a NaN becomes 0, as `floor_to_int` makes it).
            let cell = |p: f64| {
                (self.start[j] + p * self.inv_cell)
                    .max(0.0)
                    .min(self.top[j]) as i64
            };
            rect.lo[j] = cell(lo);
            rect.hi[j] = cell(hi);
        }
        rect
    }
}

impl Level {
    /// Walks the packet through this level, calling `visit` with the sphere
    /// ids of every occupied cell a still-searching ray may cross.
    ///
    /// A slab's rectangle joins the cells its two planes meet: the cross
    /// coordinate `o_u + delta·m` is bilinear in the plane and the slope, so
    /// over a slab and a set of rays its extremes lie on the planes, at the
    /// extreme slopes. Rounding is monotone, so the rectangle of a slab
    /// computed so lies inside that of the layer it belongs to.
    fn walk_packet<R: Real>(
        &self,
        packet: &Packet,
        groups: &mut Groups<R>,
        t_max: R,
        empty_space: EmptySpace,
        mut visit: impl FnMut(&[u32], &mut Groups<R>, u64),
    ) {
        let (k, step) = (packet.axis, packet.step);
        let slack: [f64; RAYS] = packet.rays.each_ref().map(|r| self.slack / r.length);
        let t_lo = groups[0].t_min.to_f64();
        // Each ray's exit from the level's box (widened by the slack), and
        // the first and last slab any ray is in, counted along the travel.
        let mut exit = [f64::NEG_INFINITY; RAYS];
        let mut live = 0u64;
        let (mut first, mut last) = (i64::MAX, i64::MIN);
        for (i, ray) in packet.rays.iter().enumerate() {
            let reach = best_t(groups, i).min(t_max).to_f64() + slack[i];
            let Some((a, b)) = self.clip(ray, t_lo - slack[i], reach) else {
                continue;
            };
            exit[i] = b;
            live |= 1 << i;
            let top = self.dims[k] - 1;
            let (sa, sb) = (
                self.cell_at(ray, a, k, 0, top),
                self.cell_at(ray, b, k, 0, top),
            );
            first = first.min(sa * step);
            last = last.max(sb * step);
        }
        if live == 0 {
            return;
        }
        let reach = |i: usize, best: R| (best.min(t_max).to_f64() + slack[i]).min(exit[i]);
        let mut search = Search {
            live,
            limit: [f64::INFINITY; RAYS],
            nearest: f64::INFINITY,
        };
        search.update(packet, groups, reach, live);
        take_improved(groups);
        // Slab s lies between planes s and s + 1; a ray entering it going
        // down the axis crosses plane s + 1 first.
        let entry_plane = |s: i64| if step > 0 { s } else { s + 1 };
        let delta = |plane: i64| self.origin[k] + plane as f64 * self.cell - packet.rays[0].o[k];
        let travel = |s: i64| delta(entry_plane(s)) * step as f64;
        let mut range = packet.slope_range(search.live);
        let cells = PlaneCells::new(self, packet);
        let (first, last) = (first * step, last * step);
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
                    self.visit_slab(k, s, Rect::between(&entry, &leaving), &blocks, &mut |ids| {
                        visit(ids, groups, search.live)
                    });
                    s += step;
                    entry = leaving;
                    // The tests may have found nearer hits.
                    let improved = take_improved(groups);
                    if improved != 0 {
                        search.update(packet, groups, reach, improved);
                    }
                    if search.retire(travel(s)) {
                        if search.live == 0 {
                            return;
                        }
                        range = packet.slope_range(search.live);
                        entry = cells.at(&range, delta(entry_plane(s)));
                    }
                }
                continue;
            };
            s = empty_until + step;
            if search.retire(travel(s)) {
                if search.live == 0 {
                    return;
                }
                range = packet.slope_range(search.live);
            }
        }
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
                let block = self.table.get(block_key(b));
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
                let mask = match self.regions.get(block_key(r)) {
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

    /// Visits the occupied cells of slab `s` within `rect`.
    fn visit_slab(
        &self,
        k: usize,
        s: i64,
        rect: Rect,
        blocks: &LayerBlocks,
        visit: &mut impl FnMut(&[u32]),
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
                        self.table.get(block_key(c.map(|x| x >> BLOCK_SHIFT)))
                    }
                };
                let bit = bit_ku | bit_on(v, cv);
                if let Some(b) = block.filter(|b| b.holds(bit)) {
                    visit(self.candidates(b.cell_index(bit)));
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

/// The positions of the bits set in `mask`, lowest first.
#[inline(always)]
fn set_bits(mut mask: u64) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            i
        })
    })
}

/// The rays of a packet, group by group.
type Groups<R> = [Lanes<R>; GROUPS];

/// Ray i's best t so far (ray i is lane i mod [`LANES`] of group i / [`LANES`]).
#[inline(always)]
fn best_t<R: Real>(groups: &Groups<R>, i: usize) -> R {
    groups[i / LANES].best_t[i % LANES]
}

/// The rays whose best hit moved nearer since the last call, as a mask.
#[inline(always)]
fn take_improved<R: Real>(groups: &mut Groups<R>) -> u64 {
    groups.iter_mut().enumerate().fold(0, |mask, (g, lanes)| {
        mask | u64::from(std::mem::take(&mut lanes.improved)) << (g * LANES)
    })
}

impl<R: Real> VoxelHashGrid<R> {
    /// [`SphereIndex::closest_hits`]: packets of [`RAYS`] rays, and rays
    /// one at a time where a packet cannot be formed.
    pub(super) fn packet_closest_hits(
        &self,
        origin: V3<R>,
        dirs: &[V3<R>],
        t_min: R,
        t_max: R,
        out: &mut [Option<Hit<R>>],
    ) {
        let mut groups: Groups<R> = std::array::from_fn(|_| Lanes::new(origin, t_min));
        for (dirs, out) in dirs.chunks(RAYS).zip(out.chunks_mut(RAYS)) {
            // A short last packet repeats its last ray in the spare lanes.
            let padded: [V3<R>; RAYS] = std::array::from_fn(|i| dirs[i.min(dirs.len() - 1)]);
            if let Some(packet) = Packet::new::<R>(origin, &padded) {
                for (g, lanes) in groups.iter_mut().enumerate() {
                    lanes.aim(&padded[g * LANES..(g + 1) * LANES], t_max);
                }
                self.trace_packet(&packet, &mut groups, t_min, t_max);
                for (i, hit) in out.iter_mut().enumerate() {
                    *hit = groups[i / LANES].hit(i % LANES);
                }
            } else {
                for (dir, hit) in dirs.iter().zip(out.iter_mut()) {
                    *hit = self.closest_hit(&Ray::new(origin, *dir), t_min, t_max);
                }
            }
        }
    }

    fn trace_packet(&self, packet: &Packet, groups: &mut Groups<R>, t_min: R, t_max: R) {
        let mut mailbox = PacketMailbox([u32::MAX; MAILBOX]);
        let origin = DVec3::from_array(packet.rays[0].o);
        let cones = Cones::new(packet, t_min.to_f64());
        let all = (1 << GROUPS) - 1;
        for &i in &self.short {
            let sphere = &self.spheres[i as usize];
            let center = sphere.frame.center.to_dvec3();
            for g in set_bits(u64::from(cones.groups_hit(
                origin,
                center,
                sphere.bound.to_f64(),
                all,
            ))) {
                groups[g].test(&sphere.frame, sphere.id);
            }
        }
        for level in &self.levels {
            level.walk_packet(
                packet,
                groups,
                t_max,
                self.empty_space,
                |ids, groups, live| {
                    // The groups with a ray still searching.
                    let searching = (0..GROUPS).fold(0, |mask, g| {
                        mask | u32::from(live >> (g * LANES) & ((1 << LANES) - 1) != 0) << g
                    });
                    for &i in ids {
                        if !mailbox.first_visit(i) {
                            continue;
                        }
                        let sphere = &self.spheres[i as usize];
                        let center = sphere.frame.center.to_dvec3();
                        let hit =
                            cones.groups_hit(origin, center, sphere.bound.to_f64(), searching);
                        for g in set_bits(u64::from(hit)) {
                            groups[g].test(&sphere.frame, sphere.id);
                        }
                    }
                },
            );
        }
    }
}
