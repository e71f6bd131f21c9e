//! Where in a window a listed sphere may block: the window of
//! [`WINDOW`]×[`WINDOW`] texels cut into sub-texels, [`SUB`] a texel side,
//! and the rectangle of them the sphere's rectangle of directions covers,
//! in two bytes beside its entry.
//!
//! A list belongs to a window of texels (`super::Face::windows` says
//! which), and lists every sphere listed there, so a ray reads spheres
//! whose rectangles cover other parts of the window: some four listed for
//! each one its direction meets, with windows about twice a sphere wide.
//! The footprint lets a ray skip those on two bytes it reads in order,
//! without loading the sphere; with sub-texels a quarter of a texel's side
//! w, the area where rays test a sphere shrinks from its window's, about
//! (2w)², toward (s + w/4)².
//!
//! # Why no blocker is skipped
//! A ray is looked up by its origin's face coordinates, and every sphere
//! that can block it has a rectangle holding them (the widening of
//! [`super::WIDEN`]). The sub-texel of a coordinate and the sub-texels of
//! a rectangle's edges come from one expression, `⌊(x − lo)·per_unit·SUB⌋`
//! (`Face::fine`), monotone in x, so a coordinate between a rectangle's
//! edges has a sub-texel between theirs: the ray's point lies in the
//! footprint of every sphere whose rectangle holds it, in the one window
//! of its four that lists the sphere (`Span::for_each`).

/// Sub-texels a texel side: a power of two, so that the scaling by it is
/// exact.
pub(super) const SUB: usize = 4;
/// Texels a window side: a sphere is listed in the windows at every other
/// texel from its first, so a ray reads the two windows along each axis
/// that hold its texel.
pub(super) const WINDOW: usize = 2;
/// Sub-texels a window side: one bit each in a byte.
const ACROSS: usize = SUB * WINDOW;

/// A rectangle of a window's sub-texels: columns in the low byte, rows in
/// the high one, a bit each.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Footprint(u16);

/// The bits `lo..=hi` of a byte (`lo ≤ hi < ACROSS`).
fn run(lo: usize, hi: usize) -> u16 {
    ((1u16 << (hi + 1)) - 1) & !((1u16 << lo) - 1)
}

impl Footprint {
    /// Columns `cols[0]..=cols[1]` of rows `rows[0]..=rows[1]`.
    #[inline(always)]
    pub(super) fn of(cols: [usize; 2], rows: [usize; 2]) -> Self {
        Footprint(run(cols[0], cols[1]) | run(rows[0], rows[1]) << ACROSS)
    }

    /// The one sub-texel in column `col` and row `row`.
    #[inline(always)]
    pub(super) fn at(col: usize, row: usize) -> Self {
        Footprint(1 << col | 1 << (row + ACROSS))
    }

    /// Its bits, for the build's shared lists.
    pub(super) fn bits(self) -> u16 {
        self.0
    }

    pub(super) fn from_bits(bits: u16) -> Self {
        Footprint(bits)
    }

    /// Whether this rectangle holds `point`'s sub-texel.
    #[inline(always)]
    pub(super) fn holds(self, point: Footprint) -> bool {
        self.0 & point.0 == point.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every run `lo..=hi` of sub-texels along one side of a window.
    fn runs() -> impl Iterator<Item = [usize; 2]> + Clone {
        (0..ACROSS).flat_map(|lo| (lo..ACROSS).map(move |hi| [lo, hi]))
    }

    #[test]
    fn a_rectangle_holds_exactly_its_sub_texels() {
        let rectangles = runs().flat_map(|cols| runs().map(move |rows| (cols, rows)));
        for (cols, rows) in rectangles {
            let rect = Footprint::of(cols, rows);
            for (col, row) in (0..ACROSS).flat_map(|col| (0..ACROSS).map(move |row| (col, row))) {
                let inside =
                    (cols[0]..=cols[1]).contains(&col) && (rows[0]..=rows[1]).contains(&row);
                assert_eq!(
                    rect.holds(Footprint::at(col, row)),
                    inside,
                    "{cols:?} {rows:?}"
                );
            }
        }
    }
}
