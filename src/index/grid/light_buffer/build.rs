//! Building a light buffer, in four passes over the spheres: each sphere's
//! rectangle of directions on the face it reaches (and what all of them
//! cover, which sets the texels), the texels each covers, then the texels'
//! lists counted and filled in sphere order; each list is then cut to its
//! nearest [`MOST_LISTED`].

use super::{
    bytes_of, Entry, Face, Footprint, LeftOut, LightBuffer, Listed, NoBuffer, Steps, MOST_LISTED,
    NEAR_DIVISOR, SUB, TILE, WIDEN,
};
use crate::geometry::{Real, Vec3Ops, V3};
use crate::index::grid::Candidate;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, AtomicU8, Ordering::Relaxed};

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
/// Parts per thread in filling the lists.
const PARTS_PER_THREAD: usize = 4;
/// Most bytes a sphere the parts' texel counts may take together.
const COUNT_BYTES_PER_SPHERE: usize = 16;

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
    (x - x.abs() / (1u64 << 22) as f64) as f32
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
struct Span {
    face: u8,
    lo: [u32; 2],
    hi: [u32; 2],
    /// False for a sphere listed in no texel.
    listed: bool,
}

impl Span {
    fn texels(&self) -> usize {
        let side = |k: usize| self.hi[k] as usize / SUB - self.lo[k] as usize / SUB + 1;
        if self.listed {
            side(0) * side(1)
        } else {
            0
        }
    }

    /// Calls `visit` with each texel it covers and its footprint there.
    #[inline(always)]
    fn for_each(&self, faces: &[Face; 6], mut visit: impl FnMut(usize, Footprint)) {
        let face = &faces[usize::from(self.face)];
        let [lo, hi] = [self.lo, self.hi].map(|e| e.map(|x| x as usize));
        // The sub-texels covered in texel `i` along axis k: all of them but
        // in the first and last texels.
        let part = |k: usize, i: usize| {
            let first = if i == lo[k] / SUB { lo[k] % SUB } else { 0 };
            let last = if i == hi[k] / SUB {
                hi[k] % SUB
            } else {
                SUB - 1
            };
            [first, last]
        };
        // Face::index, split into the row's part and the column's.
        let tile_row = face.texels[0] * TILE;
        for j in lo[1] / SUB..hi[1] / SUB + 1 {
            let row = face.first + j / TILE * tile_row + j % TILE * TILE;
            let rows = part(1, j);
            for i in lo[0] / SUB..hi[0] / SUB + 1 {
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
    is_short: Vec<bool>,
    seen: Vec<Seen>,
    spans: Vec<Span>,
    fill: FillScratch,
}

impl<R: Real> LightBuffer<R> {
    /// The buffer of `light` over `spheres` (the grid's copies), with the
    /// grid's `short` list tested by every ray, holding at most `room`
    /// bytes ([`LightBuffer::bytes`]).
    pub(in crate::index::grid) fn new(
        spheres: &[Candidate<R>],
        short: &[u32],
        light: V3<R>,
        room: usize,
        scratch: &mut Scratch,
    ) -> Result<Self, NoBuffer> {
        let light64 = light.to_dvec3();
        let Scratch {
            is_short,
            seen,
            spans,
            fill,
        } = scratch;
        is_short.clear();
        is_short.resize(spheres.len(), false);
        for &i in short {
            is_short[i as usize] = true;
        }
        let ball = |s: &Candidate<R>| (s.frame.center.to_dvec3() - light64, s.bound.to_f64());
        // Every origin answered here lies within the listed spheres' box.
        let farthest = (spheres.par_iter().zip(&*is_short))
            .filter(|(_, &short)| !short)
            .map(|(s, _)| {
                let (x, r) = ball(s);
                (x.abs() + r).length()
            })
            .reduce(|| 0.0, f64::max)
            * (1.0 + 1.0 / 1024.0);
        if !(farthest.is_finite() && farthest > 0.0) {
            return Err(NoBuffer::Unsuited);
        }
        let steps = Steps::new(spheres.len(), farthest).ok_or(NoBuffer::Unsuited)?;
        let near = farthest / NEAR_DIVISOR;
        // Each sphere as the light sees it, and what their rectangles cover.
        seen.clear();
        seen.resize(spheres.len(), Seen::default());
        let cover = (seen.par_chunks_mut(SPHERES_PER_TASK))
            .zip(spheres.par_chunks(SPHERES_PER_TASK))
            .zip(is_short.par_chunks(SPHERES_PER_TASK))
            .map(|((seen, spheres), is_short)| {
                let mut cover = Cover::none();
                for ((seen, s), &short) in seen.iter_mut().zip(spheres).zip(is_short) {
                    let (x, r) = ball(s);
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
                let (x, r) = ball(&spheres[i]);
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

/// Where spheres are listed: a span per sphere (an empty one for a sphere
/// listed nowhere), and the spans of spheres on several faces.
struct Placements<'a> {
    spans: &'a [Span],
    several: &'a [(u32, Span)],
}

impl<'a> Placements<'a> {
    /// The placements cut into `parts` runs of consecutive spheres, the
    /// spheres on several faces with the last: each texel's list takes the
    /// parts' entries in turn, so it comes out in sphere order whatever the
    /// cut.
    fn parts(&self, parts: usize) -> Vec<Part<'a>> {
        let per_part = self.spans.len().div_ceil(parts.max(1)).max(1);
        let mut cut: Vec<Part> = (self.spans.chunks(per_part).zip((0..).step_by(per_part)))
            .map(|(spans, first)| Part {
                first,
                spans,
                several: &[],
            })
            .collect();
        match cut.last_mut() {
            Some(last) => last.several = self.several,
            None => cut.push(Part {
                first: 0,
                spans: &[],
                several: self.several,
            }),
        }
        cut
    }
}

/// Consecutive spheres' spans (the first at position `first`), and
/// spheres on several faces.
struct Part<'a> {
    first: u32,
    spans: &'a [Span],
    several: &'a [(u32, Span)],
}

impl Part<'_> {
    /// Calls `visit` with each sphere listed somewhere and its span, in
    /// sphere order, those on several faces last.
    fn for_each(&self, mut visit: impl FnMut(u32, &Span)) {
        for (span, i) in self.spans.iter().zip(self.first..) {
            if span.listed {
                visit(i, span);
            }
        }
        for (i, span) in self.several {
            visit(*i, span);
        }
    }
}

/// The fill's working memory, which the next light's reuses.
#[derive(Default)]
pub(in crate::index::grid) struct FillScratch {
    /// Per part, its entries in each texel, then where it writes the next
    /// ([`TO_CUT`]).
    counts: Vec<Vec<u32>>,
    /// The lists to be cut, in texel order.
    long: Vec<ToCut>,
    /// The entries of the lists to be cut, packed as the buffer keeps them:
    /// the parts write their own places of each list at once.
    listed: Vec<AtomicU32>,
    /// Each entry's footprint ([`Footprint`]'s bits), at the same place.
    footprints: Vec<AtomicU8>,
}

/// A list to be cut: its texel, and its entries' places `from..to` in the
/// scratch lists.
#[derive(Clone, Copy, Debug)]
struct ToCut {
    texel: usize,
    from: usize,
    to: usize,
}

/// Set in a part's place for a texel ([`FillScratch::counts`]) where the
/// list is to be cut: the place is then in the scratch lists, not the
/// buffer's.
const TO_CUT: u32 = 1 << 31;

/// The texels' lists of the spheres `placements` place, cut at
/// [`MOST_LISTED`]: their starts, the entries, and the cut lists' nearest
/// distances left out. None past `most` entries before the cut.
///
/// A counting sort, parallel over runs of spheres: each part counts its
/// entries per texel, the counts become each part's places in each list,
/// and each part writes its entries there, so every pass does the same
/// work on each thread wherever the spheres' texels lie. A list kept whole
/// is written straight to its place in the buffer; a longer one goes to
/// scratch, to be cut to its nearest entries in a pass of its own. Most
/// lists are short, so most entries are written once. A list keeps its
/// order (the spheres', which is the grid's cell order) unless it is cut.
///
/// Lists past their `bounds` are refused by the count alone, before any
/// entry is written.
fn fill_lists(
    faces: &[Face; 6],
    texels: usize,
    placements: &Placements,
    entry: impl Fn(u32) -> Entry + Sync,
    bounds: ListBounds<impl FnOnce(usize, usize) -> bool>,
    split: Split,
    scratch: &mut FillScratch,
) -> Result<Lists, NoBuffer> {
    // Places carry the flag in their top bit, and cut lists name their
    // texel in 32 bits.
    if bounds.most >= TO_CUT as usize || texels >= TO_CUT as usize {
        return Err(NoBuffer::Unsuited);
    }
    let parts = placements.parts(split.parts);
    count_entries(faces, texels, &parts, &mut scratch.counts);
    let layout = place_lists(scratch, texels, bounds.most)?;
    if !(bounds.fits)(layout.kept, scratch.long.len()) {
        return Err(NoBuffer::NoRoom);
    }
    let FillScratch {
        counts,
        long,
        listed,
        footprints,
    } = scratch;
    // Room for the most entries any light may list, so that no later
    // light's lists to be cut move them to fresh pages.
    listed.clear();
    listed.reserve(bounds.most);
    listed.resize_with(layout.to_cut, || AtomicU32::new(0));
    footprints.clear();
    footprints.reserve(bounds.most);
    footprints.resize_with(layout.to_cut, || AtomicU8::new(0));
    let kept = layout.kept;
    let kept_entries: Vec<AtomicU32> = (0..kept).into_par_iter().map(|_| 0.into()).collect();
    let kept_footprints: Vec<AtomicU8> = (0..kept).into_par_iter().map(|_| 0.into()).collect();
    let whole = Filled {
        listed: &kept_entries,
        footprints: &kept_footprints,
    };
    let cut = Filled {
        listed: &listed[..],
        footprints: &footprints[..],
    };
    let steps = &bounds.steps;
    write_entries(faces, &parts, counts, |i| steps.pack(entry(i)), whole, cut);
    let cut = cut_lists(long, cut, whole, &layout.starts, bounds.steps);
    Ok(Lists {
        starts: layout.starts,
        entries: (kept_entries.into_iter())
            .map(|e| Listed::from_bits(e.into_inner()))
            .collect(),
        footprints: (kept_footprints.into_iter())
            .map(|f| Footprint::from_bits(f.into_inner()))
            .collect(),
        cut,
    })
}

/// Each part's entries per texel, into `counts` (one vector a part).
fn count_entries(faces: &[Face; 6], texels: usize, parts: &[Part], counts: &mut Vec<Vec<u32>>) {
    counts.resize_with(parts.len(), Vec::new);
    counts.truncate(parts.len());
    (parts.par_iter().zip(counts.par_iter_mut())).for_each(|(part, counts)| {
        counts.clear();
        counts.resize(texels, 0);
        part.for_each(|_, span| span.for_each(faces, |k, _| counts[k] += 1));
    });
}

/// Where the lists go, from the parts' counts.
struct Layout {
    /// Texel k's list is `starts[k]..starts[k + 1]` of the buffer's entries.
    starts: Vec<u32>,
    /// Entries the buffer keeps.
    kept: usize,
    /// Entries of the lists to be cut, before the cut.
    to_cut: usize,
}

/// Turns each part's count per texel into its first place in that list
/// (in the buffer, or [`TO_CUT`] and in scratch for a list longer than
/// [`MOST_LISTED`], which `long` then names). None past `most` entries.
fn place_lists(scratch: &mut FillScratch, texels: usize, most: usize) -> Result<Layout, NoBuffer> {
    let FillScratch { counts, long, .. } = scratch;
    let mut starts = Vec::with_capacity(texels + 1);
    starts.push(0u32);
    long.clear();
    let (mut listed, mut kept, mut to_cut) = (0usize, 0usize, 0usize);
    for k in 0..texels {
        let n: usize = counts.iter().map(|c| c[k] as usize).sum();
        listed += n;
        if listed > most {
            return Err(NoBuffer::Unsuited);
        }
        let (mut at, flag) = if n > MOST_LISTED {
            let from = to_cut;
            to_cut += n;
            long.push(ToCut {
                texel: k,
                from,
                to: to_cut,
            });
            (from, TO_CUT)
        } else {
            (kept, 0)
        };
        for counts in counts.iter_mut() {
            let c = counts[k] as usize;
            counts[k] = at as u32 | flag;
            at += c;
        }
        kept += n.min(MOST_LISTED);
        starts.push(kept as u32);
    }
    Ok(Layout {
        starts,
        kept,
        to_cut,
    })
}

/// Every part writes its entries (sphere i's packed by `packed`), in
/// sphere order, at its `places`: into `whole` or, flagged [`TO_CUT`],
/// into `cut`.
fn write_entries(
    faces: &[Face; 6],
    parts: &[Part],
    places: &mut [Vec<u32>],
    packed: impl Fn(u32) -> Listed + Sync,
    whole: Filled,
    cut: Filled,
) {
    (parts.par_iter().zip(places.par_iter_mut())).for_each(|(part, places)| {
        part.for_each(|i, span| {
            let entry = packed(i);
            span.for_each(faces, |k, footprint| {
                let place = places[k];
                places[k] += 1;
                let to = if place & TO_CUT == 0 { whole } else { cut };
                to.put((place & !TO_CUT) as usize, entry, footprint);
            });
        });
    });
}

/// How many entries a light's lists may take: at most `most` before the
/// cut (past it, [`NoBuffer::Unsuited`]), and a number kept after it that,
/// with the lists cut, `fits` the buffer's room (`fits(kept, cut)`; else
/// [`NoBuffer::NoRoom`]), each packed by `steps`.
struct ListBounds<F> {
    most: usize,
    fits: F,
    steps: Steps,
}

/// Entries and their footprints at the same places, written by the
/// parts at once.
#[derive(Clone, Copy)]
struct Filled<'a> {
    listed: &'a [AtomicU32],
    footprints: &'a [AtomicU8],
}

impl Filled<'_> {
    fn put(&self, at: usize, entry: Listed, footprint: Footprint) {
        self.listed[at].store(entry.bits(), Relaxed);
        self.footprints[at].store(footprint.bits(), Relaxed);
    }

    /// The entry at `at` and its footprint, in one word that orders as the
    /// entry does (the footprint below it), for the cut to select by.
    fn word(&self, at: usize) -> u64 {
        let entry = self.listed[at].load(Relaxed);
        u64::from(entry) << 8 | u64::from(self.footprints[at].load(Relaxed))
    }
}

/// An entry and its footprint from [`Filled::word`]'s word.
fn unpack(word: u64) -> (Listed, Footprint) {
    (
        Listed::from_bits((word >> 8) as u32),
        Footprint::from_bits(word as u8),
    )
}

/// The texels' lists as a buffer keeps them: texel k lists
/// `entries[starts[k]..starts[k + 1]]` with their `footprints`, and `cut`
/// says, for each list that was cut (in texel order), how near to the light
/// the first sphere left out of it comes.
struct Lists {
    starts: Vec<u32>,
    entries: Vec<Listed>,
    footprints: Vec<Footprint>,
    cut: Vec<LeftOut>,
}

/// How the fill shares its work: the parts of the spheres that count and
/// write entries.
#[derive(Clone, Copy, Debug)]
struct Split {
    parts: usize,
}

impl Split {
    /// A few per thread, so that uneven ones still share the work, but no
    /// more than keep their counts within [`COUNT_BYTES_PER_SPHERE`].
    fn for_threads(spheres: usize, texels: usize, threads: usize) -> Self {
        let affordable = spheres * COUNT_BYTES_PER_SPHERE / (4 * texels.max(1));
        Split {
            parts: (PARTS_PER_THREAD * threads).min(affordable).max(1),
        }
    }
}

/// Cuts each list of `long` (its entries in `filled`) to its nearest
/// [`MOST_LISTED`], written at its start in `kept`; returns for each, in
/// the same order, a distance no sphere left out of it comes nearer than.
///
/// A packed entry orders as (step, sphere), so the cut keeps the spheres of
/// the nearest steps, ties by position (an order independent of the
/// threads'), and the first one left out has the least step of those left
/// out: [`Steps::floor_of`] of it is below all their distances.
fn cut_lists(
    long: &[ToCut],
    filled: Filled,
    kept: Filled,
    starts: &[u32],
    steps: Steps,
) -> Vec<LeftOut> {
    (long.par_iter())
        .map_init(Vec::new, |list, &ToCut { texel: k, from, to }| {
            list.clear();
            list.extend((from..to).map(|at| filled.word(at)));
            list.select_nth_unstable(MOST_LISTED);
            for (at, &word) in (starts[k] as usize..).zip(&list[..MOST_LISTED]) {
                let (entry, footprint) = unpack(word);
                kept.put(at, entry, footprint);
            }
            LeftOut {
                texel: k as u32,
                within: steps.floor_of(steps.step_of(unpack(list[MOST_LISTED]).0)),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Random rectangles of sub-texels on two faces of 16×16 texels, some
    /// spheres on both.
    fn placements(spheres: u32, seed: u64) -> (Vec<Span>, Vec<(u32, Span)>, Vec<Entry>) {
        let mut state = seed;
        let mut next = |n: u32| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) % u64::from(n)) as u32
        };
        let span = |next: &mut dyn FnMut(u32) -> u32| {
            let side = 16 * SUB as u32;
            let (face, lo) = (next(2) as u8, [next(side), next(side)]);
            let hi = lo.map(|l| (l + next(4 * SUB as u32)).min(side - 1));
            Span {
                face,
                lo,
                hi,
                listed: true,
            }
        };
        let spans: Vec<Span> = (0..spheres)
            .map(|_| match next(8) {
                0 => Span::default(),
                _ => span(&mut next),
            })
            .collect();
        let several: Vec<(u32, Span)> = (0..spheres / 10)
            .flat_map(|_| {
                let i = next(spheres);
                [(i, span(&mut next)), (i, span(&mut next))]
            })
            .collect();
        let entries = (0..spheres)
            .map(|sphere| Entry {
                sphere,
                nearest: next(1000) as f32,
            })
            .collect();
        (spans, several, entries)
    }

    /// The packing of the test lists' spheres and distances.
    fn steps() -> Steps {
        Steps::new(3000, 1000.0).unwrap()
    }

    /// Bounds no list reaches.
    fn ample() -> ListBounds<impl FnOnce(usize, usize) -> bool> {
        ListBounds {
            most: 1 << 20,
            fits: |_, _| true,
            steps: steps(),
        }
    }

    fn two_faces() -> [Face; 6] {
        let mut faces = [Face::default(); 6];
        for (f, face) in faces.iter_mut().take(2).enumerate() {
            face.texels = [16, 16];
            face.first = f * 256;
        }
        faces
    }

    /// The step an entry's distance is packed in.
    fn step_of(e: &Entry) -> u32 {
        steps().step(f64::from(e.nearest))
    }

    /// The order a long list is cut in: nearest step first, ties by
    /// position, and a sphere listed twice in one texel (these tests place
    /// spheres on two faces at random) by its footprint.
    fn cut_order(e: &Entry, part: Footprint) -> (u32, u32, u8) {
        (step_of(e), e.sphere, part.bits())
    }

    /// A texel's list: each sphere and its footprint there.
    type List = Vec<(u32, Footprint)>;

    /// Each texel's list as one sphere at a time would build it: in sphere
    /// order, spheres on several faces last; a long one sorted nearest step
    /// first (ties by position) and cut, with the floor of the first step
    /// left out, which is below every distance left out.
    fn one_by_one(faces: &[Face; 6], p: &Placements, entries: &[Entry]) -> Vec<(List, f32)> {
        let mut lists = vec![Vec::new(); 512];
        for (i, span) in p.spans.iter().enumerate().filter(|(_, s)| s.listed) {
            span.for_each(faces, |k, part| lists[k].push((entries[i], part)));
        }
        for &(i, span) in p.several {
            span.for_each(faces, |k, part| lists[k].push((entries[i as usize], part)));
        }
        (lists.into_iter())
            .map(|mut list| {
                let mut complete = f32::INFINITY;
                if list.len() > MOST_LISTED {
                    list.sort_by_key(|&(e, part)| cut_order(&e, part));
                    complete = steps().floor_of(step_of(&list[MOST_LISTED].0));
                    assert!(list[MOST_LISTED..]
                        .iter()
                        .all(|(e, _)| e.nearest >= complete));
                    list.truncate(MOST_LISTED);
                }
                (
                    list.iter().map(|&(e, part)| (e.sphere, part)).collect(),
                    complete,
                )
            })
            .collect()
    }

    /// However the spheres and texels are split, the lists are those built
    /// one sphere at a time, long lists cut included.
    #[test]
    fn lists_do_not_depend_on_how_the_work_is_split() {
        let faces = two_faces();
        for (spheres, seed) in [(0, 1), (7, 2), (300, 3), (3000, 4)] {
            let (spans, several, entries) = placements(spheres, seed);
            let p = Placements {
                spans: &spans,
                several: &several,
            };
            let want = one_by_one(&faces, &p, &entries);
            assert!(spheres < 3000 || want.iter().any(|(_, c)| c.is_finite()));
            for parts in [1, 2, 7, 64] {
                let split = Split { parts };
                let entry = |i: u32| entries[i as usize];
                let mut scratch = FillScratch::default();
                let lists = fill_lists(&faces, 512, &p, entry, ample(), split, &mut scratch);
                let Lists {
                    starts,
                    entries: got,
                    footprints,
                    cut,
                } = lists.unwrap();
                // The cut lists, in texel order, are those the reference cut.
                let cut_texels: Vec<usize> = (want.iter().enumerate())
                    .filter(|(_, (_, within))| within.is_finite())
                    .map(|(k, _)| k)
                    .collect();
                let texels: Vec<usize> = cut.iter().map(|c| c.texel as usize).collect();
                assert_eq!(texels, cut_texels, "{spheres} {split:?}");
                let left_out = |k: usize| {
                    (cut.iter().find(|c| c.texel as usize == k)).map_or(f32::INFINITY, |c| c.within)
                };
                for (k, (list, within)) in want.iter().enumerate() {
                    let at = starts[k] as usize..starts[k + 1] as usize;
                    let mut mine: List = (got[at.clone()].iter())
                        .zip(&footprints[at])
                        .map(|(&e, &part)| (steps().sphere(e), part))
                        .collect();
                    if within.is_finite() {
                        // A cut list's order is the selection's; its spheres
                        // are the reference's.
                        mine.sort_by_key(|&(i, part)| cut_order(&entries[i as usize], part));
                    }
                    assert_eq!(
                        (&mine, left_out(k)),
                        (list, *within),
                        "{spheres} {split:?} {k}"
                    );
                }
            }
        }
    }

    proptest! {
        /// A point of a sphere's rectangle looks up a texel the sphere is
        /// listed in, and lies in its footprint there, at any scale and
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
            if let Some((texel, point)) = face.texel(uv) {
                let mut found = None;
                face.span(0, &rect).for_each(&[face; 6], |k, part| {
                    if k == texel {
                        found = Some(part);
                    }
                });
                prop_assert!(found.is_some_and(|part| part.holds(point)), "{:?}", found);
            }
        }
    }

    #[test]
    fn too_many_entries_give_no_lists() {
        let faces = two_faces();
        let (spans, several, entries) = placements(300, 5);
        let p = Placements {
            spans: &spans,
            several: &several,
        };
        let entry = |i: u32| entries[i as usize];
        let split = Split { parts: 3 };
        let mut scratch = FillScratch::default();
        let bounds = ListBounds {
            most: 299,
            fits: |_, _| true,
            steps: steps(),
        };
        let fill = fill_lists(&faces, 512, &p, entry, bounds, split, &mut scratch);
        assert_eq!(fill.err(), Some(NoBuffer::Unsuited));
    }

    /// A buffer's room is checked against the entries its lists keep once
    /// cut: exactly that many fit, one fewer does not.
    #[test]
    fn lists_past_their_room_are_refused_before_they_are_filled() {
        let faces = two_faces();
        let (spans, several, entries) = placements(3000, 6);
        let p = Placements {
            spans: &spans,
            several: &several,
        };
        let want: usize = one_by_one(&faces, &p, &entries)
            .iter()
            .map(|(list, _)| list.len())
            .sum();
        let entry = |i: u32| entries[i as usize];
        let split = Split { parts: 3 };
        let mut scratch = FillScratch::default();
        let room = |kept_most: usize| ListBounds {
            most: 1 << 20,
            fits: move |kept: usize, _| kept <= kept_most,
            steps: steps(),
        };
        let short = fill_lists(&faces, 512, &p, entry, room(want - 1), split, &mut scratch);
        assert_eq!(short.err(), Some(NoBuffer::NoRoom));
        // Refused by the count: no entry was written.
        assert!(scratch.listed.is_empty());
        let lists = fill_lists(&faces, 512, &p, entry, room(want), split, &mut scratch);
        assert_eq!(lists.unwrap().entries.len(), want);
    }
}
