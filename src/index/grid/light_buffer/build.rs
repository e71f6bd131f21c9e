//! Building a light buffer: each sphere's rectangle of directions on the
//! face it reaches (and what all of them cover, which sets the texels), the
//! texels each covers, then the texels' lists ([`super::fill`]).

use super::fill::{fill_lists, FillScratch, ListBounds, Placements, Split};
use super::{
    bytes_of, Entry, Face, Footprint, LightBuffer, NoBuffer, Steps, NEAR_DIVISOR, SUB, TILE, WIDEN,
    WINDOW,
};
use crate::geometry::{f32_at_most, Real, Vec3Ops, V3};
use crate::index::grid::Copies;
use glam::DVec3;
use rayon::prelude::*;

/// A sphere covering more texels than this is tested by every ray instead
/// of listed in each.
const WIDEST_TEXELS: usize = 4096;
/// Most spheres every ray tests: past it the light gets no buffer.
const MOST_ALWAYS: usize = 64;
/// Most texels a sphere is listed in on average: past it the light gets no
/// buffer (so the lists' memory is bounded).
const MOST_LISTED_PER_SPHERE: usize = 8;
/// Most texels per sphere.
const MOST_TEXELS_PER_SPHERE: f64 = 4.0;
/// The texel's side against the root mean square side of the spheres'
/// rectangles: about one texel per sphere, each listed in a few.
const TEXEL_PER_RECTANGLE: f64 = 1.0;
/// Spheres a task of the parallel passes takes.
const SPHERES_PER_TASK: usize = 1 << 14;

/// A rectangle in face coordinates.
#[derive(Clone, Copy, Debug)]
struct Rect {
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Rect {
    const EMPTY: Rect = Rect {
        lo: [f64::INFINITY; 2],
        hi: [f64::NEG_INFINITY; 2],
    };

    fn grow(&mut self, r: &Rect) {
        for k in 0..2 {
            self.lo[k] = self.lo[k].min(r.lo[k]);
            self.hi[k] = self.hi[k].max(r.hi[k]);
        }
    }

    fn area(&self) -> f64 {
        (self.hi[0] - self.lo[0]) * (self.hi[1] - self.lo[1])
    }

    fn is_empty(&self) -> bool {
        self.lo[0] > self.hi[0]
    }
}

/// The two other axes of each axis, in the order face coordinates take them.
const ACROSS: [[usize; 2]; 3] = [[1, 2], [2, 0], [0, 1]];

/// The rectangle on face `f` that holds the face coordinates of the box
/// `lo..hi` (relative to the light) where it reaches `s·x_a ≥ floor`,
/// widened by [`WIDEN`]; None where the box does not reach so far.
#[inline(always)]
fn rect_on(f: usize, lo: [f64; 3], hi: [f64; 3], floor: f64) -> Option<Rect> {
    let a = f / 2;
    let (near, far) = if f.is_multiple_of(2) {
        (lo[a], hi[a])
    } else {
        (-hi[a], -lo[a])
    };
    if far < floor {
        return None;
    }
    let near = near.max(floor);
    // Over x_a in [near, far] (positive), x_k / x_a is extreme at a corner.
    let (inv_near, inv_far) = (1.0 / near, 1.0 / far);
    let range = |k: usize| {
        let (l, h) = (lo[k], hi[k]);
        let low = if l < 0.0 { l * inv_near } else { l * inv_far };
        let high = if h > 0.0 { h * inv_near } else { h * inv_far };
        (
            (low - WIDEN).max(-1.0 - WIDEN),
            (high + WIDEN).min(1.0 + WIDEN),
        )
    };
    let [b, c] = ACROSS[a];
    let ((u0, u1), (v0, v1)) = (range(b), range(c));
    (u0 <= u1 && v0 <= v1).then_some(Rect {
        lo: [u0, v0],
        hi: [u1, v1],
    })
}

/// Calls `visit` with each face and rectangle of the ball `x` (from the
/// light), radius `r`. A face is skipped when every point of the ball lies
/// beyond its edge by more than [`WIDEN`]: `|q_b| ≥ |x_b| − r > (1 +
/// WIDEN)·(s·x_a + r) ≥ (1 + WIDEN)·s·q_a`, so no point there has a face
/// coordinate a ray of the face comes within 2^-16 of (module docs of the
/// light buffer).
///
/// Most balls lie well inside the face of their centre's direction: when
/// the whole box lies beyond `s·x_a ≥ m / 2` there and its rectangle stays
/// within `1 − 2·WIDEN` of the face's edges, every point of the ball has
/// face coordinates below `1/(1 + WIDEN)` in magnitude, so coordinates
/// above `1 + WIDEN` on every other face: that face alone is visited.
#[inline(always)]
fn for_each_rect(x: DVec3, r: f64, near: f64, mut visit: impl FnMut(usize, Rect)) {
    let (lo, hi) = ((x - r).to_array(), (x + r).to_array());
    let (x, ax) = (x.to_array(), x.abs().to_array());
    let a = if ax[0] >= ax[1] && ax[0] >= ax[2] {
        0
    } else if ax[1] >= ax[2] {
        1
    } else {
        2
    };
    let (f, depth) = if x[a] >= 0.0 {
        (2 * a, lo[a])
    } else {
        (2 * a + 1, -hi[a])
    };
    if depth >= near / 2.0 {
        if let Some(rect) = rect_on(f, lo, hi, near / 2.0) {
            let inner = 1.0 - 2.0 * WIDEN;
            if rect.lo.iter().chain(&rect.hi).all(|c| c.abs() < inner) {
                return visit(f, rect);
            }
        }
    }
    for (a, [b, c]) in ACROSS.into_iter().enumerate() {
        let across = ax[b].max(ax[c]) - r;
        for (f, along) in [(2 * a, x[a]), (2 * a + 1, -x[a])] {
            if across <= (1.0 + WIDEN) * (along + r) {
                if let Some(rect) = rect_on(f, lo, hi, near / 2.0) {
                    visit(f, rect);
                }
            }
        }
    }
}

/// `x` minus more than f32's rounding of it, for numbers of magnitude up to
/// 2 (face coordinates): converted to f32, still at most x.
fn below_f32(x: f64) -> f32 {
    (x - 1.0 / (1u64 << 22) as f64) as f32
}

/// A distance as f32, at most `x` (the relative rounding of the f64 it was
/// computed in included).
fn distance_below(x: f64) -> f32 {
    f32_at_most(x - x.abs() / (1u64 << 22) as f64)
}

/// One sphere as the light sees it: how near to the light its ball comes,
/// and its rectangle where it reaches one face only.
#[derive(Clone, Copy, Default)]
struct Seen {
    /// At most the true distance.
    nearest: f32,
    /// The face of `rect`, or [`NO_FACE`], or [`SEVERAL_FACES`] for a sphere
    /// whose rectangles are computed again where needed.
    face: u8,
    /// `lo` and `hi`, rounded outward to f32.
    rect: [f32; 4],
}

/// A sphere tested by every ray: in the short list, or near the light.
const NO_FACE: u8 = u8::MAX;
const SEVERAL_FACES: u8 = u8::MAX - 1;

impl Seen {
    fn of(x: DVec3, r: f64, near: f64, short: bool, cover: &mut Cover) -> Self {
        let mut seen = Seen {
            nearest: distance_below(x.length() - r),
            face: NO_FACE,
            rect: [0.0; 4],
        };
        if short || f64::from(seen.nearest) <= near {
            return seen;
        }
        for_each_rect(x, r, near, |f, rect| {
            cover.add(f, &rect);
            seen.face = if seen.face == NO_FACE {
                f as u8
            } else {
                SEVERAL_FACES
            };
            let (lo, hi) = (rect.lo.map(below_f32), rect.hi.map(|x| -below_f32(-x)));
            seen.rect = [lo[0], lo[1], hi[0], hi[1]];
        });
        seen
    }

    /// Its rectangle on one face, if it has one there and no other.
    fn one_rect(&self) -> Option<(usize, Rect)> {
        (usize::from(self.face) < 6).then(|| {
            let [u0, v0, u1, v1] = self.rect.map(f64::from);
            let rect = Rect {
                lo: [u0, v0],
                hi: [u1, v1],
            };
            (usize::from(self.face), rect)
        })
    }
}

/// What the rectangles of all spheres add up to: their area and number,
/// and each face's covered extent.
#[derive(Clone, Copy)]
struct Cover {
    area: f64,
    count: usize,
    extent: [Rect; 6],
}

impl Cover {
    fn none() -> Self {
        Cover {
            area: 0.0,
            count: 0,
            extent: [Rect::EMPTY; 6],
        }
    }

    fn add(&mut self, f: usize, r: &Rect) {
        self.area += r.area();
        self.count += 1;
        self.extent[f].grow(r);
    }

    fn merge(mut self, other: Cover) -> Self {
        self.area += other.area;
        self.count += other.count;
        for (a, b) in self.extent.iter_mut().zip(&other.extent) {
            a.grow(b);
        }
        self
    }
}

/// The texels a rectangle covers on one face, in sub-texels ([`SUB`] a
/// texel side): columns `lo[0]..=hi[0]` of rows `lo[1]..=hi[1]`.
#[derive(Clone, Copy, Default)]
pub(super) struct Span {
    pub(super) face: u8,
    pub(super) lo: [u32; 2],
    pub(super) hi: [u32; 2],
    /// False for a sphere listed in no texel.
    pub(super) listed: bool,
}

impl Span {
    pub(super) fn texels(&self) -> usize {
        let side = |k: usize| self.hi[k] as usize / SUB - self.lo[k] as usize / SUB + 1;
        if self.listed {
            side(0) * side(1)
        } else {
            0
        }
    }

    /// Calls `visit` with each window it is listed in (by the window's
    /// first texel) and its footprint there: the windows at every
    /// [`WINDOW`]th texel from its first along each axis, so that each
    /// texel it covers lies in exactly one of them, and that one is among
    /// the windows holding the texel that a ray reads (`Face::windows`).
    #[inline(always)]
    pub(super) fn for_each(&self, faces: &[Face; 6], mut visit: impl FnMut(usize, Footprint)) {
        let face = &faces[usize::from(self.face)];
        let [lo, hi] = [self.lo, self.hi].map(|e| e.map(|x| x as usize));
        // The sub-texels covered in the window from texel `i` along axis k,
        // counted from the window's first.
        let part = |k: usize, i: usize| {
            let first = i * SUB;
            let last = first + WINDOW * SUB - 1;
            [lo[k].max(first) - first, hi[k].min(last) - first]
        };
        // Face::index, split into the row's part and the column's.
        let tile_row = face.texels[0] * TILE;
        for j in (lo[1] / SUB..hi[1] / SUB + 1).step_by(WINDOW) {
            let row = face.first + j / TILE * tile_row + j % TILE * TILE;
            let rows = part(1, j);
            for i in (lo[0] / SUB..hi[0] / SUB + 1).step_by(WINDOW) {
                let footprint = Footprint::of(part(0, i), rows);
                visit(row + i / TILE * TILE * TILE + i % TILE, footprint);
            }
        }
    }
}

impl Face {
    /// The texels `rect` covers on face `f` (clamped to the face's).
    fn span(&self, f: usize, rect: &Rect) -> Span {
        let at = |x: f64, k: usize| {
            let i = self.fine(x, k);
            i.clamp(0.0, (self.texels[k] * SUB - 1) as f64) as u32
        };
        Span {
            face: f as u8,
            lo: [at(rect.lo[0], 0), at(rect.lo[1], 1)],
            hi: [at(rect.hi[0], 0), at(rect.hi[1], 1)],
            listed: true,
        }
    }

    fn texel_count(&self) -> usize {
        self.texels[0] * self.texels[1]
    }
}

/// The memory one light's build works in, which the next light's reuses:
/// fresh pages cost more to fault in (the kernel zeroes each) than the
/// passes that fill them.
#[derive(Default)]
pub(in crate::index::grid) struct Scratch {
    seen: Vec<Seen>,
    spans: Vec<Span>,
    fill: FillScratch,
}

/// Which of `spheres` spheres are in the grid's `short` list (tested by
/// every ray, listed nowhere), by position: what every light's build asks.
pub(in crate::index::grid) fn short_marks(spheres: usize, short: &[u32]) -> Vec<bool> {
    let mut is_short = vec![false; spheres];
    for &i in short {
        is_short[i as usize] = true;
    }
    is_short
}

/// For each of `lights`, how far from it the balls of `spheres` (the
/// grid's copies) reach, those of the short list (`is_short`) left out,
/// with a margin: every origin a light's buffer answers lies within it.
/// One pass over the spheres for all the lights, since it reads each
/// sphere and does little with it.
pub(in crate::index::grid) fn farthest_from<R: Real>(
    spheres: &Copies<R>,
    is_short: &[bool],
    lights: &[V3<R>],
) -> Vec<f64> {
    let lights: Vec<DVec3> = lights.iter().map(|l| l.to_dvec3()).collect();
    let none = || vec![0.0_f64; lights.len()];
    ((0..spheres.len() as u32).into_par_iter().zip(is_short))
        .filter(|(_, &short)| !short)
        .fold(none, |mut farthest, (i, _)| {
            let (center, r) = (spheres.center(i).to_dvec3(), spheres.bound(i).to_f64());
            for (farthest, &light) in farthest.iter_mut().zip(&lights) {
                *farthest = farthest.max(((center - light).abs() + r).length());
            }
            farthest
        })
        .reduce(none, |a, b| {
            a.iter().zip(&b).map(|(a, b)| a.max(*b)).collect()
        })
        .into_iter()
        .map(|farthest| farthest * (1.0 + 1.0 / 1024.0))
        .collect()
}

impl<R: Real> LightBuffer<R> {
    /// The buffer of `light` over `spheres` (the grid's copies), with the
    /// short list (`is_short`, from [`short_marks`]) tested by every ray,
    /// for origins within `farthest` of the light (from [`farthest_from`]),
    /// holding at most `room` bytes ([`LightBuffer::bytes`]).
    pub(in crate::index::grid) fn new(
        spheres: &Copies<R>,
        is_short: &[bool],
        light: V3<R>,
        farthest: f64,
        room: usize,
        scratch: &mut Scratch,
    ) -> Result<Self, NoBuffer> {
        let light64 = light.to_dvec3();
        let Scratch { seen, spans, fill } = scratch;
        let ball = |i: usize| {
            let i = i as u32;
            (
                spheres.center(i).to_dvec3() - light64,
                spheres.bound(i).to_f64(),
            )
        };
        if !(farthest.is_finite() && farthest > 0.0) {
            return Err(NoBuffer::Unsuited);
        }
        let steps = Steps::new(spheres.len(), farthest).ok_or(NoBuffer::Unsuited)?;
        let near = farthest / NEAR_DIVISOR;
        // Each sphere as the light sees it, and what their rectangles cover.
        // Every one is written below: what the light before left needs no
        // clearing.
        seen.resize(spheres.len(), Seen::default());
        let cover = (seen.par_chunks_mut(SPHERES_PER_TASK).enumerate())
            .zip(is_short.par_chunks(SPHERES_PER_TASK))
            .map(|((task, seen), is_short)| {
                let mut cover = Cover::none();
                let first = task * SPHERES_PER_TASK;
                for (k, (seen, &short)) in seen.iter_mut().zip(is_short).enumerate() {
                    let (x, r) = ball(first + k);
                    *seen = Seen::of(x, r, near, short, &mut cover);
                }
                cover
            })
            .reduce(Cover::none, Cover::merge);
        let faces = lay_out_faces(&cover, spheres.len());
        // The texels each sphere covers; none for the spheres every ray tests
        // (near the light, in the short list, or too wide) and for those on
        // several faces, placed apart.
        spans.clear();
        spans.par_extend(seen.par_iter().map(|s| {
            (s.one_rect().map(|(f, rect)| faces[f].span(f, &rect)))
                .filter(|s| s.texels() <= WIDEST_TEXELS)
                .unwrap_or_default()
        }));
        let (seen, spans) = (&seen[..], &spans[..]);
        // Spheres on several faces, listed on each (none too wide), in
        // sphere order (a parallel collect keeps it).
        let several: Vec<(u32, Span)> = (seen.par_iter().enumerate())
            .filter(|(_, s)| s.face == SEVERAL_FACES)
            .flat_map_iter(|(i, _)| {
                let (x, r) = ball(i);
                let mut rects = Vec::new();
                for_each_rect(x, r, near, |f, rect| rects.push(faces[f].span(f, &rect)));
                let wide = rects.iter().map(Span::texels).sum::<usize>() > WIDEST_TEXELS;
                rects
                    .into_iter()
                    .filter(move |_| !wide)
                    .map(move |span| (i as u32, span))
            })
            .collect();
        let placed_apart =
            |i: usize| (several.binary_search_by_key(&(i as u32), |&(j, _)| j)).is_ok();
        // The rest of those listed in no texel: every ray tests them.
        let mut always: Vec<Entry> = (seen.par_iter().zip(spans).enumerate())
            .filter(|(i, (s, span))| {
                span.texels() == 0 && !(s.face == SEVERAL_FACES && placed_apart(*i))
            })
            .map(|(i, (s, _))| Entry {
                sphere: i as u32,
                nearest: s.nearest,
            })
            .collect();
        if always.len() > MOST_ALWAYS {
            return Err(NoBuffer::Unsuited);
        }
        // Their nearest distances may be negative (the light inside a ball).
        always.sort_unstable_by(|a, b| {
            a.nearest
                .total_cmp(&b.nearest)
                .then(a.sphere.cmp(&b.sphere))
        });
        // Its bytes held are then its bytes counted.
        always.shrink_to_fit();
        let texels = faces.iter().map(Face::texel_count).sum();
        let fits = |kept: usize, cut: usize| bytes_of(always.len(), kept, texels + 1, cut) <= room;
        let entry = |i: u32| Entry {
            sphere: i,
            nearest: seen[i as usize].nearest,
        };
        let placements = Placements {
            spans,
            several: &several,
        };
        let most = MOST_LISTED_PER_SPHERE * spheres.len();
        let split = Split::for_threads(spheres.len(), texels, rayon::current_num_threads());
        let bounds = ListBounds { most, fits, steps };
        let lists = fill_lists(&faces, texels, &placements, entry, bounds, split, fill)?;
        Ok(LightBuffer {
            light,
            light64,
            farthest,
            always,
            faces,
            starts: lists.starts,
            entries: lists.entries,
            footprints: lists.footprints,
            steps,
            cut: lists.cut,
        })
    }
}

/// Each face's texels over its covered extent, square, of one side for all
/// faces: [`TEXEL_PER_RECTANGLE`] times the rectangles' root mean square
/// side, but no more than [`MOST_TEXELS_PER_SPHERE`] texels a sphere.
fn lay_out_faces(cover: &Cover, spheres: usize) -> [Face; 6] {
    let mut faces = [Face::default(); 6];
    if cover.count == 0 {
        return faces;
    }
    let covered: f64 = (cover.extent.iter())
        .filter(|e| !e.is_empty())
        .map(Rect::area)
        .sum();
    let side = ((cover.area / cover.count as f64).sqrt() * TEXEL_PER_RECTANGLE)
        .max((covered / (MOST_TEXELS_PER_SPHERE * spheres as f64)).sqrt());
    let mut first = 0;
    for (face, e) in faces.iter_mut().zip(&cover.extent) {
        if e.is_empty() {
            continue;
        }
        face.lo = e.lo;
        face.per_unit = 1.0 / side;
        face.texels = [0, 1].map(|k| {
            let texels = ((e.hi[k] - e.lo[k]) * face.per_unit) as usize + 1;
            texels.div_ceil(TILE) * TILE
        });
        face.first = first;
        first += face.texel_count();
    }
    faces
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// A point of a sphere's rectangle looks up exactly one window the
        /// sphere is listed in whose footprint holds it, at any scale and
        /// with rectangles reaching past the face's texels.
        #[test]
        fn a_point_of_a_rectangle_lies_in_its_footprint(
            scale_exp in -40i32..40,
            lo in prop::array::uniform2(-2.0f64..2.0),
            texels in prop::array::uniform2(1usize..6),
            corner in prop::array::uniform2(-0.5f64..6.5),
            size in prop::array::uniform2(0.0f64..3.0),
            at in prop::array::uniform2(0.0f64..=1.0),
        ) {
            let side = 2f64.powi(scale_exp) * 0.37;
            let face = Face {
                lo: lo.map(|x| x * side),
                per_unit: 1.0 / side,
                texels: texels.map(|t| t * TILE),
                first: 0,
            };
            let rect = Rect {
                lo: [0, 1].map(|k| face.lo[k] + corner[k] * side),
                hi: [0, 1].map(|k| face.lo[k] + (corner[k] + size[k]) * side),
            };
            let uv = [0, 1].map(|k| rect.lo[k] + at[k] * (rect.hi[k] - rect.lo[k]));
            let uv = [0, 1].map(|k| uv[k].clamp(rect.lo[k], rect.hi[k]));
            if let Some(point) = face.point(uv) {
                let mut listed = Vec::new();
                face.span(0, &rect).for_each(&[face; 6], |k, part| listed.push((k, part)));
                let holding = |&(k, at): &(usize, Footprint)| {
                    listed.iter().any(|&(l, part)| l == k && part.holds(at))
                };
                let found = face.windows(point).filter(holding).count();
                prop_assert_eq!(found, 1, "{:?}", listed);
            }
        }
    }
}
