//! The octants of a cell: its 2×2×2 half cells, one bit each.
//!
//! A cell lists every sphere whose reach box overlaps it, and a ray that
//! visits the cell passes through a few of its octants only: counted on the
//! benchmark families' eye rays, three in five of the spheres a single ray
//! tested lay in octants it did not cross. So each reference keeps, in one
//! byte beside its id, the octants its sphere's reach box overlaps; the walk
//! works out the octants the ray crosses while it is in the cell
//! ([`OctantRay::crossed`]), and a sphere whose octants miss those is
//! passed over before its copy is read.
//!
//! # Why no hit is lost
//! Octants are the cells of the level's lattice at half the side: a power of
//! two too, from the same origin. The build finds a box's half cells with
//! the scaling the whole cells use (by `2 / cell`, exact), and the walk
//! takes a cell's entry and mid-plane crossings back from its next crossing
//! by a cell's and half a cell's span, `|cell / d|` (exact halving): within
//! a few units in the last place of the half lattice's own crossings, far
//! within the traversal allowance of the reach boxes' pad ([`super::build`]).
//! So the argument that a sphere is listed in the cell the walk is in when
//! the ray meets its reach holds for half cells as well: where the ray meets
//! a sphere's reach box, the walk is in an octant of its cell that the
//! sphere's reference marks. Crossings at one time are taken together, so
//! a ray through an edge or corner of octants takes every octant there.

use super::walk::{greater, lesser};

/// Spheres a cell lists from which a walk passes over those outside the
/// octants it crosses: in a cell of fewer, working out the octants costs
/// more than the tests it could save (filtering cells of 2 as well, single
/// eye rays took 0.7% more instructions on mixed 10⁵, 0.1% on shell).
pub const FILTERED_FROM: usize = 3;

/// Spheres a level's cells list on average from which its references keep
/// their octants (uniform 10⁵ lists 2.3 a cell, floor 2.9, mixed 7.7, shell
/// 14.1, the clumps' level of clustered 6.9). Below it the octants cost more
/// than they save: kept on every level (and cells of 2 filtered), single eye
/// rays on uniform 10⁵ took 15% more instructions, floor 9% more, mixed
/// the same (docs/index.md, "Octants of a cell").
pub const LISTED_FOR_OCTANTS: usize = 4;

/// A ray as the octants of one level's cells see it: what finding the
/// octants it crosses in a cell takes, worked out once per walk of a level
/// that keeps octants.
pub struct OctantRay {
    /// How long the ray takes to cross a cell along each axis, `|cell / d|`,
    /// +∞ where d = ±0; and half that, kept beside it as every filtered cell
    /// asks for both (worked out there, `crossed` takes 7% more instructions).
    span: [f64; 3],
    half_span: [f64; 3],
    /// Bits of the axes the ray moves up along, and of those it moves on.
    rising: u8,
    moving: u8,
    /// Bits of the axes it does not move on where its coordinate lies in
    /// the upper half of the walk's cells.
    still_upper: u8,
}

impl OctantRay {
    /// For a walk of a level without octants, which never asks it.
    pub const UNUSED: OctantRay = OctantRay {
        span: [f64::INFINITY; 3],
        half_span: [f64::INFINITY; 3],
        rising: 0,
        moving: 0,
        still_upper: 0,
    };

    /// From the walk's step (−1, 0 or 1) and `cell / d` (0 where d = ±0) per
    /// axis, and the upper halves its coordinates lie in on the axes it does
    /// not move on.
    #[inline(always)]
    pub fn new(step: [i64; 3], per_plane: [f64; 3], still_upper: u8) -> Self {
        let span = [0, 1, 2].map(|a| {
            if step[a] == 0 {
                f64::INFINITY
            } else {
                per_plane[a].abs()
            }
        });
        let bits = |on: fn(i64) -> bool| {
            let each = [0, 1, 2].map(|a| u8::from(on(step[a])) << a);
            each[0] | each[1] | each[2]
        };
        OctantRay {
            span,
            half_span: span.map(|s| 0.5 * s),
            rising: bits(|s| s > 0),
            moving: bits(|s| s != 0),
            still_upper,
        }
    }

    /// The octants the ray crosses in the cell it leaves at the first of
    /// `t_next` (its next crossing of a plane on each axis): from when it
    /// enters the cell, the octant it starts in and each one a crossing of a
    /// mid-plane takes it to.
    ///
    /// The entry and the mid-planes' crossings are taken back from `t_next`
    /// by a cell's and half a cell's span: a few units in the last place
    /// from the lattice's own crossings, far within the traversal allowance
    /// of the reach boxes' pad ([`super::build`]).
    #[inline(never)]
    pub fn crossed(&self, t_next: &[f64; 3]) -> Octants {
        let t_out = lesser(lesser(t_next[0], t_next[1]), t_next[2]);
        // Where d = ±0 the span is +∞ and t_next too: NaN, which `greater`
        // and the comparisons below pass over.
        let entry = [0, 1, 2].map(|a| t_next[a] - self.span[a]);
        let t_in = greater(
            greater(greater(f64::NEG_INFINITY, entry[0]), entry[1]),
            entry[2],
        );
        let mid = [0, 1, 2].map(|a| t_next[a] - self.half_span[a]);
        let mut before = 0u8;
        let mut flips = 0u8;
        let mut flipped = [f64::INFINITY; 3];
        for a in 0..3 {
            before |= u8::from(mid[a] < t_in) << a;
            let inside = mid[a] >= t_in && mid[a] <= t_out;
            flips |= u8::from(inside) << a;
            flipped[a] = if inside { mid[a] } else { f64::INFINITY };
        }
        // The half it starts in on an axis it moves on: the upper one if it
        // goes up and crossed the mid-plane before t_in, or goes down and
        // crosses it from t_in on (a crossing at t_in itself counted ahead,
        // so both halves are taken).
        let start = !(before ^ self.rising) & self.moving | self.still_upper;
        // After the crossing at t_k it has crossed every one up to t_k: the
        // octants in order without sorting them (crossings at one time go
        // together, which the pad allows for too).
        let up_to = |t_k: f64| {
            let each = [0, 1, 2].map(|a| u8::from(flipped[a] <= t_k) << a);
            (each[0] | each[1] | each[2]) & flips
        };
        Octants::one(start)
            .with(Octants::one(start ^ up_to(flipped[0])))
            .with(Octants::one(start ^ up_to(flipped[1])))
            .with(Octants::one(start ^ up_to(flipped[2])))
    }
}

/// A set of a cell's octants: bit `x | y << 1 | z << 2`, each coordinate 1
/// for the cell's upper half on that axis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Octants(u8);

/// The octants in the lower half along each axis.
const LOWER: [u8; 3] = [0x55, 0x33, 0x0F];

impl Octants {
    /// The octants of cell `c` that a box of half cells `lo..=hi` (indices
    /// on the lattice of half the cell's side) overlaps, for a box that
    /// overlaps the cell.
    #[inline(always)]
    pub fn of_box(c: [i64; 3], lo: [i64; 3], hi: [i64; 3]) -> Self {
        let mut octants = u8::MAX;
        for a in 0..3 {
            let lower = if lo[a] <= 2 * c[a] { LOWER[a] } else { 0 };
            let upper = if hi[a] > 2 * c[a] { !LOWER[a] } else { 0 };
            octants &= lower | upper;
        }
        Octants(octants)
    }

    /// The one octant with upper halves on the axes whose bits `halves` sets.
    #[inline(always)]
    pub fn one(halves: u8) -> Self {
        Octants(1 << halves)
    }

    /// These and `other`.
    #[inline(always)]
    pub fn with(self, other: Octants) -> Self {
        Octants(self.0 | other.0)
    }

    /// Whether any octant is in both sets.
    #[inline(always)]
    pub fn meets(self, other: Octants) -> bool {
        self.0 & other.0 != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A coordinate's place on the lattice of half cells of side `cell`
    /// from 0, in units of half cells.
    fn in_halves(x: f64, cell: f64) -> f64 {
        x * (2.0 / cell)
    }

    proptest! {
        /// Every octant the ray's segment through a cell passes through is
        /// among those `crossed` gives, at cell sides from 2⁻³⁰ to 2³⁰ and
        /// for rays along axes; and there are at most four (a segment
        /// crosses each of the three mid-planes once at most).
        #[test]
        fn crossed_holds_every_octant_the_segment_passes_through(
            side in -30i32..30,
            cell_at in prop::array::uniform3(-(1i64 << 20)..(1i64 << 20)),
            start in prop::array::uniform3(0.0f64..1.0),
            dir in prop::array::uniform3(prop_oneof![
                Just(0.0f64), Just(-0.0f64), -1.0f64..1.0, 1e-30f64..1e-20
            ]),
            t_in_cell in 0.0f64..1.0,
        ) {
            let cell = 2f64.powi(side);
            // A ray starting in cell `cell_at`, and the cell it is in at a
            // later t, as the walk would find them (the lattice from 0).
            let o: [f64; 3] = std::array::from_fn(|a| (cell_at[a] as f64 + start[a]) * cell);
            // A ray of no direction never reaches a walk.
            let dir = if dir.iter().all(|&d| d == 0.0) { [1.0, dir[1], dir[2]] } else { dir };
            let p: [f64; 3] = std::array::from_fn(|a| o[a] + t_in_cell * cell * dir[a]);
            let c: [i64; 3] = std::array::from_fn(|a| (p[a] / cell).floor() as i64);
            let step = dir.map(|d| (d > 0.0) as i64 - (d < 0.0) as i64);
            let per_plane: [f64; 3] =
                std::array::from_fn(|a| if dir[a] == 0.0 { 0.0 } else { cell / dir[a] });
            let crossing = |a: usize, i: i64| {
                if dir[a] == 0.0 {
                    f64::INFINITY
                } else {
                    -o[a] / dir[a] + i as f64 * per_plane[a]
                }
            };
            let up = step.map(|s| i64::from(s > 0));
            let t_next: [f64; 3] = std::array::from_fn(|a| crossing(a, c[a] + up[a]));
            let still_upper = (0..3).fold(0u8, |bits, a| {
                let upper = step[a] == 0 && in_halves(o[a], cell).floor() as i64 > 2 * c[a];
                bits | u8::from(upper) << a
            });
            let crossed = OctantRay::new(step, per_plane, still_upper).crossed(&t_next);
            prop_assert!(crossed.0.count_ones() <= 4, "{:08b}", crossed.0);

            // Sample the segment between the cell's entry and exit planes,
            // passing over points within rounding of a cell's or octant's
            // face, whose side the pad settles.
            let t_in = (0..3)
                .filter(|&a| step[a] != 0)
                .map(|a| crossing(a, c[a] + 1 - up[a]))
                .fold(f64::NEG_INFINITY, f64::max);
            let t_out = t_next.iter().copied().fold(f64::INFINITY, f64::min);
            for k in 0..=64 {
                let t = t_in + (t_out - t_in) * (k as f64 / 64.0);
                let mut halves = 0u8;
                let mut clear = true;
                for a in 0..3 {
                    let h = in_halves(o[a] + t * dir[a], cell) - 2.0 * c[a] as f64;
                    clear &= (h - h.round()).abs() > 1e-6 && h > 0.0 && h < 2.0;
                    halves |= u8::from(h >= 1.0) << a;
                }
                if clear {
                    prop_assert!(
                        crossed.meets(Octants::one(halves)),
                        "t {t} halves {halves:03b} crossed {:08b}", crossed.0
                    );
                }
            }
        }
    }

    /// Every box of half cells that overlaps cell (1, 2, 3), from the half
    /// cell before it to the one after it, against the octants counted one
    /// by one.
    #[test]
    fn a_box_marks_the_octants_it_overlaps() {
        let c = [1, 2, 3];
        // Offsets from the half cell before the cell: 1 and 2 are the cell's.
        let ranges: Vec<(i64, i64)> = (0..3)
            .flat_map(|lo| (lo.max(1)..4).map(move |hi| (lo, hi)))
            .collect();
        for &(x0, x1) in &ranges {
            for &(y0, y1) in &ranges {
                for &(z0, z1) in &ranges {
                    let (lo, hi) = ([x0, y0, z0], [x1, y1, z1]);
                    let lo: [i64; 3] = std::array::from_fn(|a| lo[a] + 2 * c[a] - 1);
                    let hi: [i64; 3] = std::array::from_fn(|a| hi[a] + 2 * c[a] - 1);
                    let got = Octants::of_box(c, lo, hi);
                    for halves in 0..8u8 {
                        let inside = (0..3).all(|a| {
                            let h = 2 * c[a] + i64::from(halves >> a & 1);
                            lo[a] <= h && h <= hi[a]
                        });
                        assert_eq!(
                            got.meets(Octants::one(halves)),
                            inside,
                            "{lo:?} {hi:?} {halves}"
                        );
                    }
                }
            }
        }
    }
}
