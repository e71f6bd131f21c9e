//! The gate: one coarse occupancy over the levels, which a single ray asks
//! before it walks them.
//!
//! Each level crosses empty space with its own proximity clouds
//! ([`super::occupancy`]), so a ray through a scene of several levels crosses
//! the same empty space once per level: where clumps stand alone in empty
//! space, a ray that passes between them costs several times what one walk
//! would. The gate is a lattice of cubes over the levels' boxes, a cube
//! marked where an occupied cell of a level it answers for meets it, with
//! proximity clouds per heading of its own. One walk of it, a few leaps,
//! finds where the ray first enters a marked cube; those levels are then
//! walked from there, or not at all. A level whose cells fill space (dust
//! through the whole view) is left to its own walk ([`MOST_MARKED`]).
//!
//! Each cube also keeps which levels' cells meet it, a bit per level. An
//! eye packet crosses the lattice layer by layer ([`Gate::packet_spans`])
//! and walks each gated level only over the layers where it meets that
//! level's cubes: where each clump holds spheres of one size, a packet
//! through one clump walks that clump's level alone.
//!
//! # Why the levels miss nothing
//! Every sphere a level holds lies in its occupied cells, and every occupied
//! cell within marked cubes (a cell's box marks every cube it meets, in exact
//! binary arithmetic: both lattices are anchored at multiples of powers of
//! two). The gate walk leaps only over boxes of unmarked cubes, whatever
//! rounding does to its choice of cube (the argument of [`super::walk`]'s
//! leaps), and the t it returns is the t at which the ray leaves those boxes,
//! lowered by [`Gate::margin`], a bound on that t's rounding. So the levels'
//! walks, started there less their own slack, visit every cell they would
//! have visited from the start, as far as any hit.

use super::occupancy::{Heading, Occupancy, HEADINGS, MAX_GROUPS, SMALL_SCENE_GROUPS};
use super::ray_set::{set_bits, RaySet};
use super::slab::{Packet, PlaneCells, Rect};
use super::walk::{first_axis, floor_to_int, greater, step_of, Ray64};
use super::Level;

/// The gate walk's t rounds by a few units in the last place of the
/// magnitudes it is computed from; the margin takes 2^-44 of them.
const MARGIN: f64 = 1.0 / (1u64 << 44) as f64;
/// A level whose occupied cells meet more than this share of the cubes is
/// walked without the gate: where it fills space (dust through the whole
/// view), a ray meets a marked cube at once and the gate only costs.
const MOST_MARKED: f64 = 1.0 / 16.0;

/// Most layers of cubes a packet's rays may cross for the gate to be asked
/// about them: a lattice long on one axis is left to the levels' walks.
const PACKET_LAYERS: i64 = 512;
/// Most cubes one layer's rectangle of a packet may span for the gate to
/// look at each.
const PACKET_CUBES: i64 = 64;

/// Levels a cube's mask tells apart: level i answers to bit [`slot`]`(i)`,
/// the levels from the eighth on sharing the last.
const SLOTS: usize = 8;

/// The bit of a cube's mask that answers for level `i`.
#[inline(always)]
fn slot(i: usize) -> usize {
    i.min(SLOTS - 1)
}

/// Bytes a gate holds per cube: a proximity cloud's byte per heading, and
/// the mask of the levels whose cells meet it.
pub const BYTES_PER_CUBE: usize = HEADINGS + 1;

/// Cubes marked over the levels' boxes, and how far unmarked space reaches
/// ahead of each.
pub struct Gate {
    /// The low corner of cube (0, 0, 0), a multiple of `side`.
    origin: [f64; 3],
    /// The high corner of the lattice.
    far: [f64; 3],
    /// Cube side, a power of two.
    side: f64,
    per_side: f64,
    dims: [i64; 3],
    /// A cube's clouds: groups of one cube (`shift` 0).
    clouds: Occupancy,
    /// Per cube (x fastest), bit [`slot`]`(i)` set where gated level i's
    /// occupied cells meet it: a cube is marked where its mask is not 0.
    met: Vec<u8>,
    /// The largest magnitude of the lattice's coordinates.
    extent: f64,
    /// The gated levels' largest slack ([`Level::slack`]): the gate is
    /// asked about the span the widest of their walks would search.
    pub slack: f64,
    /// Bit i set where the gate answers for level i.
    gated: u64,
}

/// Where along a packet each gated level may hold its hits ([`Gate::packet_spans`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PacketSpans([Option<[f64; 2]>; SLOTS]);

impl PacketSpans {
    const EVERYWHERE: PacketSpans = PacketSpans([Some([f64::NEG_INFINITY, f64::INFINITY]); SLOTS]);
    const NOWHERE: PacketSpans = PacketSpans([None; SLOTS]);

    /// The planes across the packet's axis (coordinates times its step, the
    /// lesser first) between which gated level `level` may hold its rays'
    /// hits; None where it holds none of them.
    #[inline(always)]
    pub fn of(&self, level: usize) -> Option<[f64; 2]> {
        self.0[slot(level)]
    }
}

/// The cubes: where cube (0, 0, 0) starts, their side, how many a side.
#[derive(Clone, Copy, Debug)]
struct Lattice {
    /// A multiple of `side`.
    origin: [f64; 3],
    /// A power of two.
    side: f64,
    dims: [i64; 3],
}

impl Lattice {
    /// Cubes over the levels' boxes, as fine as their finest cell where no
    /// more than `budget` of them cover the boxes, else coarser.
    fn over(levels: &[Level], budget: i64) -> Self {
        let lo = [0, 1, 2].map(|a| levels.iter().map(|l| l.origin[a]).fold(f64::MAX, f64::min));
        let hi = [0, 1, 2].map(|a| levels.iter().map(|l| l.far[a]).fold(f64::MIN, f64::max));
        let at = |side: f64| {
            let origin = lo.map(|x| (x / side).floor() * side);
            let dims = [0, 1, 2].map(|a| ((hi[a] - origin[a]) / side).floor() as i64 + 1);
            Lattice { origin, side, dims }
        };
        let mut side = levels.iter().map(|l| l.cell).fold(f64::MAX, f64::min);
        while at(side).count() > budget as usize {
            side *= 2.0;
        }
        at(side)
    }

    fn count(&self) -> usize {
        self.dims.iter().product::<i64>() as usize
    }

    /// Sets `meets` (one per cube, x fastest) where one of `level`'s
    /// occupied cells meets the cube, and returns how many cubes it set;
    /// None, leaving off, once that passes `most`.
    ///
    /// Both lattices lie at multiples of powers of two, the cubes' origin a
    /// multiple of the cell where the cell is no wider than a cube, the
    /// level's a multiple of the cube where it is wider: so a cell's cube is
    /// its index shifted down (a cell lies in one cube), or a wide cell's
    /// cubes its index shifted up, in integers.
    fn mark(
        &self,
        level: &Level,
        offset: [i64; 3],
        meets: &mut [bool],
        most: usize,
    ) -> Option<usize> {
        let dims = self.dims;
        let fine = level.cell <= self.side;
        let shift = (self.side / level.cell).log2().abs() as u32;
        // `offset` ([`Lattice::offset`]) counts cells where they are no
        // wider than a cube, else cubes; `span` is how many cubes a wide
        // cell spans a side.
        let span = 1i64
            .checked_shl(shift)
            .filter(|&s| s > 0)
            .unwrap_or(i64::MAX);
        let mut set = 0;
        for c in level.table.occupied_cells() {
            let range = |a: usize| {
                let (first, last) = if fine {
                    let cube = (offset[a] + c[a]).checked_shr(shift).unwrap_or(0);
                    (cube, cube)
                } else {
                    let first = offset[a].saturating_add(c[a].saturating_mul(span));
                    (first, first.saturating_add(span - 1))
                };
                (first.min(dims[a] - 1), last.min(dims[a] - 1))
            };
            let [(x0, x1), (y0, y1), (z0, z1)] = [range(0), range(1), range(2)];
            for z in z0..=z1 {
                for y in y0..=y1 {
                    let row = ((z * dims[1] + y) * dims[0]) as usize;
                    for m in &mut meets[row + x0 as usize..=row + x1 as usize] {
                        set += usize::from(!*m);
                        *m = true;
                    }
                }
            }
            if set > most {
                return None;
            }
        }
        Some(set)
    }

    /// Where `level`'s cell (0, 0, 0) lies in the lattice, in cells where
    /// they are no wider than a cube, else in cubes: an integer, as both
    /// origins lie at multiples of that unit. None where it is not one that
    /// an `i64` holds with room (origins some 2^62 units apart), which
    /// leaves the scene without a gate.
    fn offset(&self, level: &Level) -> Option<[i64; 3]> {
        let unit = level.cell.min(self.side);
        let offsets = [0, 1, 2].map(|a| (level.origin[a] - self.origin[a]) / unit);
        let exact = |x: f64| x == x.trunc() && (0.0..(1u64 << 62) as f64).contains(&x);
        offsets
            .iter()
            .all(|&x| exact(x))
            .then(|| offsets.map(|x| x as i64))
    }
}

impl Gate {
    /// The gate over those of `levels` (holding `spheres` spheres) whose
    /// occupied cells meet at most [`MOST_MARKED`] of its cubes; None where
    /// fewer than two do, whose own clouds already answer for the space
    /// around them.
    pub fn over(levels: &[Level], spheres: usize) -> Option<Gate> {
        if levels.len() < 2 {
            return None;
        }
        let lattice = Lattice::over(
            levels,
            (spheres as i64).clamp(SMALL_SCENE_GROUPS, MAX_GROUPS),
        );
        let count = lattice.count();
        let mut met = vec![0u8; count];
        let (mut gated, mut slack) = (0u64, 0.0f64);
        let mut meets = vec![false; count];
        for (i, level) in levels.iter().enumerate().take(u64::BITS as usize) {
            let offset = lattice.offset(level)?;
            meets.fill(false);
            let most = (MOST_MARKED * count as f64) as usize;
            if lattice.mark(level, offset, &mut meets, most).is_none() {
                continue;
            }
            gated |= 1 << i;
            slack = slack.max(level.slack);
            for (m, _) in met.iter_mut().zip(&meets).filter(|(_, &o)| o) {
                *m |= 1 << slot(i);
            }
        }
        (gated.count_ones() >= 2).then(|| Gate::new(lattice, met, gated, slack))
    }

    /// The gate of the cubes of `lattice` with the levels' masks `met` (x
    /// fastest; see [`Gate::met`]), answering for the levels of the bits of
    /// `gated`, whose largest slack is `slack`.
    fn new(lattice: Lattice, met: Vec<u8>, gated: u64, slack: f64) -> Self {
        let Lattice { origin, side, dims } = lattice;
        let far = [0, 1, 2].map(|a| origin[a] + dims[a] as f64 * side);
        let extent = (origin.iter().chain(&far)).fold(0.0f64, |m, x| m.max(x.abs()));
        let occupied: Vec<u8> = (met.iter())
            .map(|&m| if m != 0 { 0 } else { u8::MAX })
            .collect();
        Gate {
            origin,
            far,
            side,
            per_side: 1.0 / side,
            dims,
            clouds: Occupancy::of_groups(0, dims, &occupied),
            met,
            extent,
            slack,
            gated,
        }
    }

    /// How many levels the gate answers for.
    pub fn gated_levels(&self) -> usize {
        self.gated.count_ones() as usize
    }

    /// Whether the gate answers for level `i`'s space.
    #[inline(always)]
    pub fn gates(&self, i: usize) -> bool {
        i < u64::BITS as usize && self.gated >> i & 1 == 1
    }

    pub fn bytes(&self) -> usize {
        self.clouds.bytes() + self.met.len()
    }

    /// A t at or before the first at which the ray, within [t_lo, t_hi],
    /// enters a marked cube; None if it enters none there.
    ///
    /// The per-axis arrays are written out rather than built with
    /// `[0, 1, 2].map(..)`, which is not always inlined here.
    #[inline(always)]
    pub fn first_marked(&self, ray: &Ray64, t_lo: f64, t_hi: f64) -> Option<f64> {
        let margin = self.margin(ray);
        if !margin.is_finite() {
            return Some(t_lo);
        }
        let (t0, t1) = self.clip(ray, t_lo, t_hi)?;
        let step = [step_of(ray.d[0]), step_of(ray.d[1]), step_of(ray.d[2])];
        let heading = Heading::of(step);
        // The t at which the ray leaves cube index i on axis a (+∞ if never).
        let crossing = |a: usize, i: i64| {
            if step[a] == 0 {
                return f64::INFINITY;
            }
            let plane = self.origin[a] + (i + i64::from(step[a] > 0)) as f64 * self.side;
            (plane - ray.o[a]) * ray.inv[a]
        };
        // The cube holding the ray's point at t on axis a, within [lo, hi].
        let cube_at = |a: usize, t: f64, lo: i64, hi: i64| {
            let p = ray.o[a] + t * ray.d[a];
            floor_to_int((p - self.origin[a]) * self.per_side).clamp(lo, hi)
        };
        // Looked up a margin early, so that a start on a cube's plane
        // takes the cube before it.
        let start = t0 - margin;
        let mut c = [
            cube_at(0, start, 0, self.dims[0] - 1),
            cube_at(1, start, 0, self.dims[1] - 1),
            cube_at(2, start, 0, self.dims[2] - 1),
        ];
        let mut t_in = t0;
        loop {
            let distance = self.clouds.distance(c, heading);
            if distance == 0 {
                return Some(t_in - margin);
            }
            // Leap across the empty box of `distance` cubes a side ahead.
            let r = i64::from(distance) - 1;
            let last = [c[0] + step[0] * r, c[1] + step[1] * r, c[2] + step[2] * r];
            let exits = [
                crossing(0, last[0]),
                crossing(1, last[1]),
                crossing(2, last[2]),
            ];
            let a = first_axis(&exits);
            let t_exit = exits[a];
            // Finite: the ray moves along some axis, whose crossing is least.
            if t_exit > t1 {
                return None;
            }
            for k in 0..3 {
                c[k] = if k == a {
                    last[k] + step[k]
                } else {
                    cube_at(k, t_exit, c[k].min(last[k]), c[k].max(last[k]))
                };
                if c[k] < 0 || c[k] >= self.dims[k] {
                    return None;
                }
            }
            t_in = t_exit;
        }
    }

    /// For each gated level, the planes across `packet`'s axis (coordinates
    /// times its step, the lesser first) between which its rays, searching
    /// from `t_min`, meet cubes that level's cells meet. Eye packets only:
    /// rays from one point (anything else is answered with every plane).
    ///
    /// The packet crosses the lattice layer by layer along its axis, as a
    /// packet crosses a level's slabs ([`super::slab`]): each layer's
    /// rectangle of cubes holds every ray's path through it, the rays'
    /// offsets widened by a bound on the rounding of its corners (at most
    /// [`MARGIN`] of the magnitudes involved, times the steepest slope; far
    /// below a cube where the gate answers at all). A hit of gated level i
    /// lies in a cube its cells meet (module docs), so in a layer where its
    /// ray meets a cube whose mask holds [`slot`]`(i)`; the planes returned
    /// for the level are the first and last such layers' outer planes,
    /// widened by the levels' slack and by a cube against their own
    /// rounding. A level in a clump of its own is walked over that clump's
    /// layers only, not wherever the packet meets another level's cubes.
    /// Where a layer's rectangle holds only unmarked cubes, the gate's
    /// clouds along the packet's heading say how far unmarked space reaches
    /// ahead of them, and the layers the rays cross within that reach are
    /// passed in one step ([`Gate::within_reach`]).
    #[inline(never)]
    pub fn packet_spans(&self, packet: &Packet, t_min: f64) -> PacketSpans {
        let everywhere = PacketSpans::EVERYWHERE;
        let (k, step) = (packet.axis(), packet.step());
        let range = packet.slope_range(RaySet::ALL.groups());
        let magnitude = self.extent + packet.origin.iter().map(|x| x.abs()).sum::<f64>();
        let rounding = MARGIN * magnitude * (1.0 + range.steepest());
        let from_one_point_ahead = t_min >= 0.0 && packet.spread() == 0.0;
        if !(from_one_point_ahead && rounding < self.side / 4.0) {
            return everywhere;
        }
        let Some((first, last)) = self.layers_ahead(packet) else {
            return PacketSpans::NOWHERE;
        };
        if (last - first).abs() + 1 > PACKET_LAYERS {
            return everywhere;
        }
        // Each layer's rectangle, between the planes it lies between.
        let range = range.widened(rounding);
        let cubes = PlaneCells::of_lattice(&self.origin, self.per_side, self.dims, packet);
        let plane = |i: i64| self.origin[k] + i as f64 * self.side - packet.origin[k];
        // Per slot, the first and last layer where the packet meets its cubes.
        let mut met_in: [Option<(i64, i64)>; SLOTS] = [None; SLOTS];
        // The first ray's heading: a leap checks that every ray stays within
        // the reach of the boxes ahead along it, whichever way the others go.
        let lead = packet.unit[0];
        let heading = Heading::of([step_of(lead.x), step_of(lead.y), step_of(lead.z)]);
        // Layer s lies between planes s and s + 1, which ever comes first.
        let mut entry = cubes.at(&range, plane(first + i64::from(step < 0)));
        let mut s = first;
        while (last - s) * step >= 0 {
            let exit = cubes.at(&range, plane(s + i64::from(step > 0)));
            let rect = Rect::between(&entry, &exit);
            let Some(clear) = self.clear_within(k, s, &rect, heading) else {
                return everywhere;
            };
            if clear >= 2 {
                // Every cube up to `clear − 1` layers ahead of the rectangle's,
                // and as far across it along the heading, is unmarked: leap
                // over those layers where the rays stay within that reach.
                let ahead = i64::from(clear) - 1;
                let far = s + ahead * step;
                let far = if step > 0 {
                    far.min(last)
                } else {
                    far.max(last)
                };
                let far_exit = cubes.at(&range, plane(far + i64::from(step > 0)));
                let across = Rect::between(&entry, &far_exit);
                if Self::within_reach(&rect, &across, ahead, heading, k) {
                    entry = far_exit;
                    s = far + step;
                    continue;
                }
            }
            entry = exit;
            // A rectangle of unmarked cubes meets no level.
            if clear == 0 {
                let Some(met) = self.met_within(k, s, &rect) else {
                    return everywhere;
                };
                for slot in set_bits(u64::from(met)) {
                    let (from, _) = met_in[slot].unwrap_or((s, s));
                    met_in[slot] = Some((from, s));
                }
            }
            s += step;
        }
        // Layer s lies between planes s and s + 1: coordinates times the
        // step, the lesser first.
        let ends = |s: i64| {
            let [a, b] = [s, s + 1].map(|i| (self.origin[k] + i as f64 * self.side) * step as f64);
            [a.min(b), a.max(b)]
        };
        let widen = self.slack + self.side;
        PacketSpans(
            met_in.map(|layers| {
                layers.map(|(from, to)| [ends(from)[0] - widen, ends(to)[1] + widen])
            }),
        )
    }

    /// The first and last layer of cubes across `packet`'s axis that its
    /// rays may cross: from the origin's (less one, against rounding) on, in
    /// their direction. None where the lattice lies behind the origin.
    fn layers_ahead(&self, packet: &Packet) -> Option<(i64, i64)> {
        let (k, step) = (packet.axis(), packet.step());
        let top = self.dims[k] - 1;
        let origin_layer = floor_to_int((packet.origin[k] - self.origin[k]) * self.per_side)
            .clamp(-1, top + 1)
            - step;
        let (first, last) = if step > 0 {
            (origin_layer.max(0), top)
        } else {
            (origin_layer.min(top), 0)
        };
        ((last - first) * step >= 0).then_some((first, last))
    }

    /// The levels' masks of the cubes of layer `s` across axis `k` within
    /// `rect` (cubes within the lattice), joined; None where the rectangle
    /// spans more than [`PACKET_CUBES`] cubes.
    fn met_within(&self, k: usize, s: i64, rect: &Rect) -> Option<u8> {
        // The clouds' groups are the cubes, in the same order.
        Self::fold_layer(k, s, rect, 0, |met, c| met | self.met[self.clouds.index(c)])
    }

    /// `f` folded over the cubes of layer `s` across axis `k` within `rect`,
    /// from `init`; None where the rectangle spans more than
    /// [`PACKET_CUBES`] cubes.
    #[inline(always)]
    fn fold_layer<T>(
        k: usize,
        s: i64,
        rect: &Rect,
        init: T,
        mut f: impl FnMut(T, [i64; 3]) -> T,
    ) -> Option<T> {
        let (lo, hi) = (rect.lo, rect.hi);
        if (hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) > PACKET_CUBES {
            return None;
        }
        let [u, v] = [(k + 1) % 3, (k + 2) % 3];
        let mut c = [s; 3];
        let mut acc = init;
        for cu in lo[0]..=hi[0] {
            for cv in lo[1]..=hi[1] {
                (c[u], c[v]) = (cu, cv);
                acc = f(acc, c);
            }
        }
        Some(acc)
    }

    /// The least distance of the clouds along `heading` over the cubes of
    /// layer `s` across axis `k` within `rect`: 0 where one of them is
    /// marked, else `n ≥ 1` such that every cube ahead of one of them along
    /// the heading within chessboard distance `n − 1` is unmarked. None
    /// where the rectangle spans more than [`PACKET_CUBES`] cubes.
    fn clear_within(&self, k: usize, s: i64, rect: &Rect, heading: Heading) -> Option<u8> {
        Self::fold_layer(k, s, rect, u8::MAX, |clear, c| {
            clear.min(self.clouds.distance(c, heading))
        })
    }

    /// Whether the rectangle `across` lies within `ahead` cubes of `rect`
    /// along `heading` on both axes across `k` (and nowhere behind it).
    /// The boxes of side `ahead + 1` ahead of `rect`'s cubes then cover
    /// every cube of `across` in the layers they reach: a cube up to
    /// `ahead` beyond `rect` on an axis lies that far ahead of `rect`'s
    /// last cube there, one within it ahead of itself.
    fn within_reach(rect: &Rect, across: &Rect, ahead: i64, heading: Heading, k: usize) -> bool {
        (0..2).all(|j| {
            if heading.sign((k + 1 + j) % 3) > 0 {
                across.lo[j] >= rect.lo[j] && across.hi[j] <= rect.hi[j] + ahead
            } else {
                across.hi[j] <= rect.hi[j] && across.lo[j] >= rect.lo[j] - ahead
            }
        })
    }

    /// A bound on the rounding of the gate walk's t, with room: each t is a
    /// plane's `(origin − o)·(1/d) + i·(side/d)`, a few roundings of
    /// magnitudes up to the lattice's coordinates and the ray's origin over
    /// the direction, and the start is looked up at a point a few roundings
    /// from the one at that t. Infinite (no gating) for a direction whose
    /// reciprocal overflows.
    #[inline(always)]
    fn margin(&self, ray: &Ray64) -> f64 {
        let mut reach = self.extent;
        let mut most = 1.0 / ray.length;
        for a in 0..3 {
            reach += ray.o[a].abs();
            if ray.d[a] != 0.0 {
                most = greater(most, ray.inv[a].abs());
            }
        }
        MARGIN * reach * most
    }

    /// The part of [t_lo, t_hi] the ray spends in the lattice's box.
    #[inline(always)]
    fn clip(&self, ray: &Ray64, t_lo: f64, t_hi: f64) -> Option<(f64, f64)> {
        super::walk::clip_to_box(&self.origin, &self.far, ray, t_lo, t_hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use glam::DVec3;

    /// The spans of t in [t_lo, t_hi] the ray spends in each marked cube,
    /// by clipping it to every marked cube's box.
    fn marked_spans<'a>(
        gate: &'a Gate,
        marked: &'a [bool],
        ray: &'a Ray64,
        t_lo: f64,
        t_hi: f64,
    ) -> impl Iterator<Item = (f64, f64)> + 'a {
        let [nx, ny, _] = gate.dims;
        (marked.iter().enumerate())
            .filter(|(_, &m)| m)
            .filter_map(move |(i, _)| {
                let i = i as i64;
                let c = [i % nx, i / nx % ny, i / (nx * ny)];
                let lo = [0, 1, 2].map(|a| gate.origin[a] + c[a] as f64 * gate.side);
                let hi = lo.map(|x| x + gate.side);
                super::super::walk::clip_to_box(&lo, &hi, ray, t_lo, t_hi)
            })
    }

    /// The first t in [t_lo, t_hi] at which the ray is in a marked cube.
    fn first_by_brute_force(
        gate: &Gate,
        marked: &[bool],
        ray: &Ray64,
        t_lo: f64,
        t_hi: f64,
    ) -> Option<f64> {
        marked_spans(gate, marked, ray, t_lo, t_hi)
            .map(|(t0, _)| t0)
            .reduce(f64::min)
    }

    /// A lattice of cubes from 2^-20 to 2^19 a side, of 1 to `most` a side,
    /// its corner up to some 10^4 from the origin.
    fn random_lattice(rng: &mut Rng, most: u64) -> Lattice {
        let side = 2f64.powi((rng.next_u64() % 40) as i32 - 20);
        let dims = [0; 3].map(|_| 1 + (rng.next_u64() % most) as i64);
        let shift = 10f64.powi((rng.next_u64() % 5) as i32) * (rng.unit() - 0.5);
        let origin = [0; 3].map(|_| ((shift + rng.unit()) / side).floor() * side);
        Lattice { origin, side, dims }
    }

    /// At random scales and places, the gate's t comes no later than the
    /// first marked cube's, and it says "none" for most rays that meet none.
    #[test]
    fn the_first_marked_cube_is_never_passed() {
        let mut rng = Rng::new(11);
        let (mut clear, mut said_clear) = (0, 0);
        for case in 0..300 {
            let lattice = random_lattice(&mut rng, 10);
            let Lattice { origin, side, dims } = lattice;
            let density = [0.002, 0.02, 0.1, 0.3][case % 4];
            let marked: Vec<bool> = (0..lattice.count()).map(|_| rng.unit() < density).collect();
            let met = marked.iter().map(|&m| u8::from(m) * 0b11).collect();
            let gate = Gate::new(lattice, met, 0b11, 0.0);
            let size = dims.map(|d| d as f64 * side);
            for _ in 0..50 {
                let place = |rng: &mut Rng| {
                    DVec3::from_array(
                        [0, 1, 2].map(|a| origin[a] + (rng.unit() * 1.6 - 0.3) * size[a]),
                    )
                };
                let o = place(&mut rng);
                let mut d = place(&mut rng) - o;
                if rng.unit() < 0.2 {
                    d[(rng.next_u64() % 3) as usize] = 0.0;
                }
                let Some(ray) = Ray64::from_f64(o, d) else {
                    continue;
                };
                let (t_lo, t_hi) = (rng.unit() * 0.5 - 0.25, [1.0, 3.0, f64::INFINITY][case % 3]);
                let want = first_by_brute_force(&gate, &marked, &ray, t_lo, t_hi);
                let got = gate.first_marked(&ray, t_lo, t_hi);
                match want {
                    Some(t) => assert!(got.is_some_and(|g| g <= t), "{got:?} after {t}"),
                    None => {
                        clear += 1;
                        said_clear += usize::from(got.is_none());
                    }
                }
            }
        }
        assert!(said_clear * 10 >= clear * 9, "{said_clear} of {clear}");
    }

    /// The planes along the packet's axis (times its step) where `ray`
    /// enters and leaves each marked cube, from t = 0 on.
    fn marked_planes(
        gate: &Gate,
        marked: &[bool],
        ray: &Ray64,
        axis: usize,
        step: f64,
    ) -> Vec<f64> {
        marked_spans(gate, marked, ray, 0.0, f64::INFINITY)
            .flat_map(|(t0, t1)| [t0, t1].map(|t| (ray.o[axis] + t * ray.d[axis]) * step))
            .collect()
    }

    /// At random scales and places, every point at which a packet's ray is
    /// in a cube a level's cells meet lies between the planes the gate gives
    /// that level for the packet, and it says "nowhere" for most packets
    /// that meet none of the level's cubes, whatever they meet of the
    /// other's.
    #[test]
    fn a_packets_cubes_of_each_level_lie_between_its_planes() {
        let mut rng = Rng::new(12);
        let (mut clear, mut said_clear, mut asked) = (0, 0, 0);
        for case in 0..300 {
            let lattice = random_lattice(&mut rng, 12);
            let Lattice { origin, side, dims } = lattice;
            let density = [0.002, 0.02, 0.1][case % 3];
            // Two levels, the cubes each meets drawn apart.
            let marked: [Vec<bool>; 2] =
                [0, 1].map(|_| (0..lattice.count()).map(|_| rng.unit() < density).collect());
            let met = (marked[0].iter().zip(&marked[1]))
                .map(|(&a, &b)| u8::from(a) | u8::from(b) << 1)
                .collect();
            let gate = Gate::new(lattice, met, 0b11, side * rng.unit());
            let size = dims.map(|d| d as f64 * side);
            let place = |rng: &mut Rng, a: usize, wide: f64| {
                origin[a] + (rng.unit() * (1.0 + 2.0 * wide) - wide) * size[a]
            };
            for _ in 0..20 {
                let eye = DVec3::from_array([0, 1, 2].map(|a| place(&mut rng, a, 1.0)));
                let aim = DVec3::from_array([0, 1, 2].map(|a| place(&mut rng, a, 0.2)));
                // A tile of rays fanning out from the eye, a random spread.
                let fan = (aim - eye).length() * [1e-3, 0.05, 0.3][case % 3];
                Packet::with_spare(|packet| {
                    for ray in packet.rays.iter_mut() {
                        let jitter = DVec3::from_array([0; 3].map(|_| rng.unit() - 0.5)) * fan;
                        *ray = Ray64::from_f64(eye, aim + jitter - eye).expect("a direction");
                    }
                    if !packet.aim(eye.to_array()) {
                        return;
                    }
                    let (axis, step) = (packet.axis(), packet.step() as f64);
                    let spans = gate.packet_spans(packet, 0.0);
                    asked += 1;
                    for (level, marked) in marked.iter().enumerate() {
                        let planes: Vec<f64> = (packet.rays.iter())
                            .flat_map(|ray| marked_planes(&gate, marked, ray, axis, step))
                            .collect();
                        match spans.of(level) {
                            Some([lo, hi]) => assert!(
                                planes.iter().all(|&p| lo <= p && p <= hi),
                                "level {level}: {planes:?} outside {lo}..{hi}"
                            ),
                            None => {
                                assert!(planes.is_empty(), "level {level}: {planes:?} said clear")
                            }
                        }
                        if planes.is_empty() {
                            clear += 1;
                            said_clear += usize::from(spans.of(level).is_none());
                        }
                    }
                });
            }
        }
        assert!(asked > 3000, "{asked} packets");
        assert!(said_clear * 4 >= clear * 3, "{said_clear} of {clear}");
    }
}
