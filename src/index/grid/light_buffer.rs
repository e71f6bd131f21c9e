//! Light buffers: for each point light, the spheres seen from it in each
//! direction (Haines & Greenberg, "The Light Buffer: A Shadow-Testing
//! Accelerator", 1986).
//!
//! A shadow ray toward a point light L ends at L, so whatever blocks it lies
//! in the direction of its origin as seen from L, and nearer to L than the
//! origin. Around each light a cube of six faces is cut into texels of
//! direction, and the spheres whose bounding balls may meet a direction
//! through a texel are listed, with how near to L each ball comes, in the
//! windows of 2×2 texels that hold it ([`footprint`]). A shadow ray looks up
//! the four windows of its texel and tests the listed spheres whose balls
//! come nearer to L than its origin, until one blocks: no walk, however far
//! the light.
//! Shadow rays from anywhere (eye hits, bounce hits) are answered alike, so
//! incoherent ones cost no more than coherent ones.
//!
//! # Why it answers what brute force answers
//! The test is the walk's own, of the ray as the renderer casts it
//! (`o + t·d` with `d = fl(L − o)`, t in (0, 1)), so only the lists' cover
//! matters. A sphere reports a hit at t only if `q = o + t·d` lies within
//! its `bound` ρ of its centre C (the pad and slack of [`super::build`]).
//! With `d = (L − o) + e`, `|e| ≤ u·|L − o|` (one rounding in the render's
//! precision, u its unit roundoff), `q − L = w + t·e` with
//! `w = (1 − t)·(o − L)`, so:
//! - `|q − L| ≤ |o − L|·(1 + u)`: a sphere whose ball comes no nearer to L
//!   than that cannot block, and a list stops at the first such sphere.
//! - Where `|q − L| ≥ m`: `|t·e| ≤ ε·|w|` with `ε = u·D / (m − u·D)` for
//!   every origin within D of L (farther ones go to the walk); with
//!   `m = D / NEAR_DIVISOR` that is 64u / (1 − 64u), 2^-18 in f32. A face
//!   coordinate `x_b / x_a` (`x_a ≥ |x| / √3` on the face of w) then moves
//!   by at most `2√3·ε / (1 − √3·ε) < 2^-16` between w, which has the
//!   origin's direction, and `q − L`; every sphere's rectangle is widened by
//!   [`WIDEN`] = 2^-14, four times that.
//! - Where `|q − L| < m`, the ball comes within m of L: such spheres are
//!   tested by every ray ([`LightBuffer::always`]), as are the grid's short
//!   list (a floor of radius 1000 would put every origin near the light) and
//!   the few spheres that would cover too many texels.
//!
//! A sphere is listed on face (a, s) (the directions with `s·x_a ≥ |x_b|,
//! |x_c|`) when its ball's box reaches `s·x_a ≥ m / 2`: a point q as above
//! has `s·q_a ≥ |q − L|·(1/√3 − ε)/(1 + ε) > m / 2` on the face of its
//! origin. Over the box's part with `s·x_a ≥ m / 2` the ratio
//! `x_b / (s·x_a)` takes its extremes at the corners, so the rectangle of
//! the corner ratios holds the face coordinates of every such q.
//!
//! # Windows
//! A sphere is listed once in each window from every other texel of its
//! rectangle's, starting at its first (along each axis): each texel it
//! covers then lies in exactly one of its windows, and that window is one
//! of the four holding the texel (from the texel itself and from the ones
//! before it along each axis), which a ray reads. A sphere about a texel
//! wide (the texels' side is the spheres' rectangles' root mean square
//! side) is listed about once, where a list per texel would list it in
//! about four: fewer entries to build and keep, for lists a ray reads
//! four of. Each listed sphere keeps the part of its window its rectangle
//! covers ([`footprint`]), which a ray's origin lies in whenever the sphere
//! can block it.
//!
//! A window's list is cut at [`MOST_LISTED`] spheres, the nearest by their
//! packed distance, and a distance no sphere left out comes nearer than is
//! kept: a ray whose origin lies beyond one of its windows', and that no
//! listed sphere blocks, goes to the walk. So a ray tests at most four
//! times that many spheres here, whatever the scene.

mod build;
mod fill;
mod footprint;
mod listed;

pub(super) use build::{farthest_from, short_marks, Scratch};

use super::{Copies, Tests};
use crate::geometry::{Ray, Real, Vec3Ops, V3};
use footprint::{Footprint, SUB, WINDOW};
use glam::DVec3;
use listed::{Listed, Steps};

/// Why a light gets no buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum NoBuffer {
    /// Its spheres do not suit one: too many that every ray would test,
    /// lists too long, or nothing to list.
    Unsuited,
    /// Its lists, counted, would take more bytes than the room it was given;
    /// it is refused before they are filled.
    NoRoom,
}

/// How far a sphere's texel rectangle is widened, in face coordinates: four
/// times the direction error of a shadow ray's points (module docs).
const WIDEN: f64 = 1.0 / (1u64 << 14) as f64;
/// `m = D / NEAR_DIVISOR`: spheres within m of the light are in every list.
const NEAR_DIVISOR: f64 = 64.0;
/// Texels a side of a tile (see [`Face::index`]).
const TILE: usize = 8;
/// Most spheres listed in one window; past them a ray may go to the walk.
const MOST_LISTED: usize = 48;

/// One sphere as the build handles it, and in the every-ray list: its
/// position in the grid's sphere array, and a distance its ball comes no
/// nearer to the light than (rounded down). The windows' lists keep it
/// packed ([`Listed`]).
#[derive(Clone, Copy, Debug, Default)]
struct Entry {
    sphere: u32,
    nearest: f32,
}

/// The texels of one face of the cube around the light, over the part of
/// the face its spheres' rectangles cover.
#[derive(Clone, Copy, Debug, Default)]
struct Face {
    /// The low corner of texel (0, 0), in face coordinates.
    lo: [f64; 2],
    /// Texels per unit of face coordinate.
    per_unit: f64,
    /// Texels along each face coordinate, a multiple of [`TILE`] (0 for a
    /// face with no sphere).
    texels: [usize; 2],
    /// The face's first texel in the buffer's texel numbering.
    first: usize,
}

impl Face {
    /// The sub-texel column (k = 0) or row (k = 1) face coordinate `x` lies
    /// in, counted from the face's first; the one expression the build and
    /// the look-ups share ([`footprint`] says why). Scaling by [`SUB`] is
    /// exact, so a texel's index is this one's quotient by it.
    #[inline(always)]
    fn fine(&self, x: f64, k: usize) -> f64 {
        ((x - self.lo[k]) * self.per_unit * SUB as f64).floor()
    }

    /// The sub-texel `uv` lies in, its column and row counted from the
    /// face's first, None outside the face's texels.
    #[inline(always)]
    fn point(&self, uv: [f64; 2]) -> Option<[usize; 2]> {
        let (x, y) = (self.fine(uv[0], 0), self.fine(uv[1], 1));
        let inside = x >= 0.0 && y >= 0.0;
        let (x, y) = (x as usize, y as usize);
        (inside && x / SUB < self.texels[0] && y / SUB < self.texels[1]).then_some([x, y])
    }

    /// The lists of the windows that hold sub-texel `point`'s texel (those
    /// from it and from the [`WINDOW`]` − 1` texels before it, along each
    /// axis), each with the point's sub-texel in that window.
    #[inline(always)]
    fn windows(&self, [x, y]: [usize; 2]) -> impl Iterator<Item = (usize, Footprint)> + Clone + '_ {
        let (i, j) = (x / SUB, y / SUB);
        (0..WINDOW * WINDOW).filter_map(move |w| {
            let (di, dj) = (w % WINDOW, w / WINDOW);
            let at = || Footprint::at(di * SUB + x % SUB, dj * SUB + y % SUB);
            (i >= di && j >= dj).then(|| (self.index(i - di, j - dj), at()))
        })
    }

    /// Texel (i, j)'s place in the buffer's numbering: tile by tile of
    /// [`TILE`]² texels, so that the texels of one sphere, and of spheres
    /// near each other, lie together in memory.
    #[inline(always)]
    fn index(&self, i: usize, j: usize) -> usize {
        let tiles_across = self.texels[0] / TILE;
        let tile = (j / TILE) * tiles_across + i / TILE;
        self.first + tile * TILE * TILE + (j % TILE) * TILE + i % TILE
    }
}

/// The shadow rays toward one point light, answered from lists.
pub(super) struct LightBuffer<R: Real> {
    light: V3<R>,
    light64: DVec3,
    /// Origins farther from the light than this go to the walk.
    farthest: f64,
    /// Spheres every ray tests, nearest first.
    always: Vec<Entry>,
    faces: [Face; 6],
    /// The window from texel k lists `entries[starts[k]..starts[k + 1]]`,
    /// packed by `steps`, nearest step first (ties by position), each with
    /// the part of the window it covers in `footprints`.
    starts: Vec<u32>,
    entries: Vec<Listed>,
    footprints: Vec<Footprint>,
    steps: Steps,
    /// The lists that were cut, by texel: each one's window's first texel
    /// and how near to the light the first sphere left out of it comes.
    /// Kept apart from the texels: few lists are cut, and a scene of small
    /// spheres spread in every direction has far more texels than entries.
    cut: Vec<LeftOut>,
}

/// A cut list's window (by its first texel), and a distance no sphere left
/// out of it comes nearer to the light than.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LeftOut {
    texel: u32,
    within: f32,
}

/// The bytes of a buffer's arrays: `always` and `entries` entries (with
/// their footprints), `starts` list starts and `cut` lists cut.
fn bytes_of(always: usize, entries: usize, starts: usize, cut: usize) -> usize {
    size_of::<Entry>() * always
        + (size_of::<Listed>() + size_of::<Footprint>()) * entries
        + size_of::<u32>() * starts
        + size_of::<LeftOut>() * cut
}

/// The face a direction `x` from the light lies in (2·axis, plus 1 on the
/// axis's negative side) and its coordinates there; None for zero.
#[inline(always)]
fn face_of(x: DVec3) -> Option<(usize, [f64; 2])> {
    let ax = x.abs();
    let a = if ax.x >= ax.y && ax.x >= ax.z {
        0
    } else if ax.y >= ax.z {
        1
    } else {
        2
    };
    let (b, c) = ((a + 1) % 3, (a + 2) % 3);
    (ax[a] > 0.0).then(|| {
        let face = 2 * a + usize::from(x[a] < 0.0);
        (face, [x[b] / ax[a], x[c] / ax[a]])
    })
}

impl<R: Real> LightBuffer<R> {
    /// The light this buffer answers for.
    pub(super) fn light(&self) -> V3<R> {
        self.light
    }

    /// Bytes the buffer holds.
    pub(super) fn bytes(&self) -> usize {
        bytes_of(
            self.always.capacity(),
            self.entries.capacity(),
            self.starts.capacity(),
            self.cut.capacity(),
        )
    }

    /// How near to the light the first sphere left out of window k's list
    /// comes: +∞ for a list shorter than the cut, or one not cut.
    fn left_out(&self, k: usize, listed: usize) -> f32 {
        if listed < MOST_LISTED {
            return f32::INFINITY;
        }
        (self.cut.binary_search_by_key(&k, |c| c.texel as usize))
            .map_or(f32::INFINITY, |i| self.cut[i].within)
    }

    /// Whether a sphere blocks the shadow ray from `origin` to the light,
    /// spending one of `budget` per test; None where the walk must say.
    #[inline]
    pub(super) fn blocked(
        &self,
        spheres: &Copies<R>,
        origin: V3<R>,
        budget: &mut impl Tests,
    ) -> Option<bool> {
        let x = origin.to_dvec3() - self.light64;
        let distance = x.length();
        // Also refuses NaN.
        if distance.partial_cmp(&self.farthest) != Some(std::cmp::Ordering::Less) {
            return None;
        }
        let (f, uv) = face_of(x)?;
        // |o − L|·(1 + u) and the rounding of `distance`, with room.
        let within = distance * (1.0 + 1.0 / (1u64 << 20) as f64);
        let ray = Ray::new(origin, self.light - origin);
        let mut blocks = |sphere: u32| {
            budget.spend(1);
            (spheres.intersect(sphere, &ray, R::zero(), R::one())).is_some()
        };
        // Every list is nearest first, so its first sphere beyond the origin
        // ends it (a window's by its packed step: a few more pass, none that
        // would block is skipped); a window's spheres are checked by their
        // footprints before they are read.
        let nearer = |e: &&Entry| f64::from(e.nearest) <= within;
        if (self.always.iter().take_while(nearer)).any(|e| blocks(e.sphere)) {
            return Some(true);
        }
        let Some(point) = self.faces[f].point(uv) else {
            return Some(false);
        };
        let (steps, reach) = (&self.steps, self.steps.step(within));
        let windows = self.faces[f].windows(point);
        let list = |k: usize| self.starts[k] as usize..self.starts[k + 1] as usize;
        for (k, at) in windows.clone() {
            let mut listed = (self.entries[list(k)].iter())
                .zip(&self.footprints[list(k)])
                .take_while(|&(&l, _)| steps.step_of(l) <= reach)
                .filter(|&(_, &part)| part.holds(at));
            if listed.any(|(&l, _)| blocks(steps.sphere(l))) {
                return Some(true);
            }
        }
        // Unblocked, answered here when no window left out a sphere nearer
        // to the light than the origin.
        let complete = |(k, _)| f64::from(self.left_out(k, list(k).len())) > within;
        { windows }.all(complete).then_some(false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faces_take_each_direction_once() {
        assert_eq!(face_of(DVec3::new(2.0, 1.0, -1.0)), Some((0, [0.5, -0.5])));
        assert_eq!(face_of(DVec3::new(0.0, -3.0, 1.5)), Some((3, [0.5, 0.0])));
        assert_eq!(face_of(DVec3::new(1.0, 1.0, -4.0)), Some((5, [0.25, 0.25])));
        assert_eq!(face_of(DVec3::ZERO), None);
    }
}
