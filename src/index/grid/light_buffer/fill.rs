//! A light buffer's lists, filled from the windows each sphere is listed in
//! (by each window's first texel, [`super::footprint`]): a
//! counting sort, parallel over runs of spheres, each list in sphere order,
//! each longer than [`MOST_LISTED`] then cut to its nearest entries, and
//! every list then sorted nearest first.

use super::build::Span;
use super::{Entry, Face, Footprint, LeftOut, Listed, NoBuffer, Steps, MOST_LISTED};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU16, AtomicU32, Ordering::Relaxed};

/// Parts per thread in filling the lists.
const PARTS_PER_THREAD: usize = 4;
/// Lists a task of the sort takes at least.
const LISTS_PER_SORT_TASK: usize = 1 << 10;
/// Most bytes a sphere the parts' texel counts may take together.
const COUNT_BYTES_PER_SPHERE: usize = 16;

/// Where spheres are listed: a span per sphere (an empty one for a sphere
/// listed nowhere), and the spans of spheres on several faces.
pub(super) struct Placements<'a> {
    pub(super) spans: &'a [Span],
    pub(super) several: &'a [(u32, Span)],
}

impl<'a> Placements<'a> {
    /// The placements cut into `parts` runs of consecutive spheres, the
    /// spheres on several faces with the last: each window's list takes the
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
    footprints: Vec<AtomicU16>,
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

/// The windows' lists of the spheres `placements` place, cut at
/// [`MOST_LISTED`]: their starts, the entries, and the cut lists' nearest
/// distances left out. None past `most` entries before the cut.
///
/// A counting sort, parallel over runs of spheres: each part counts its
/// entries per texel, the counts become each part's places in each list,
/// and each part writes its entries there, so every pass does the same
/// work on each thread wherever the spheres' texels lie. A list kept whole
/// is written straight to its place in the buffer; a longer one goes to
/// scratch, to be cut to its nearest entries in a pass of its own. Most
/// lists are short, so most entries are written once. Each list is then
/// sorted nearest step first, ties by position.
///
/// Lists past their `bounds` are refused by the count alone, before any
/// entry is written.
pub(super) fn fill_lists(
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
    footprints.resize_with(layout.to_cut, || AtomicU16::new(0));
    let kept = layout.kept;
    let kept_entries: Vec<AtomicU32> = (0..kept).into_par_iter().map(|_| 0.into()).collect();
    let kept_footprints: Vec<AtomicU16> = (0..kept).into_par_iter().map(|_| 0.into()).collect();
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
    sort_lists(&layout.starts, whole);
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
pub(super) struct ListBounds<F> {
    pub(super) most: usize,
    pub(super) fits: F,
    pub(super) steps: Steps,
}

/// Entries and their footprints at the same places, written by the
/// parts at once.
#[derive(Clone, Copy)]
struct Filled<'a> {
    listed: &'a [AtomicU32],
    footprints: &'a [AtomicU16],
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
        u64::from(entry) << u16::BITS | u64::from(self.footprints[at].load(Relaxed))
    }
}

/// An entry and its footprint from [`Filled::word`]'s word.
fn unpack(word: u64) -> (Listed, Footprint) {
    (
        Listed::from_bits((word >> u16::BITS) as u32),
        Footprint::from_bits(word as u16),
    )
}

/// The texels' lists as a buffer keeps them: texel k lists
/// `entries[starts[k]..starts[k + 1]]` with their `footprints`, and `cut`
/// says, for each list that was cut (in texel order), how near to the light
/// the first sphere left out of it comes.
pub(super) struct Lists {
    pub(super) starts: Vec<u32>,
    pub(super) entries: Vec<Listed>,
    pub(super) footprints: Vec<Footprint>,
    pub(super) cut: Vec<LeftOut>,
}

/// How the fill shares its work: the parts of the spheres that count and
/// write entries.
#[derive(Clone, Copy, Debug)]
pub(super) struct Split {
    parts: usize,
}

impl Split {
    /// A few per thread, so that uneven ones still share the work, but no
    /// more than keep their counts within [`COUNT_BYTES_PER_SPHERE`]. A
    /// light with four texels a sphere or more (small spheres all around
    /// it) gets one part: sharing the lists by runs of texels instead, one
    /// array of counts for any number of tasks, gains there and loses more
    /// on the lights that get eight (docs/index.md, "The lists' fill shared
    /// by texels").
    pub(super) fn for_threads(spheres: usize, texels: usize, threads: usize) -> Self {
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

/// Sorts each list of `kept` (the window from texel k's at
/// `starts[k]..starts[k + 1]`) nearest step first, ties by position: a ray
/// then reads a list only as far as the spheres nearer to the light than
/// its origin, and meets them in an order independent of the threads'.
fn sort_lists(starts: &[u32], kept: Filled) {
    (starts.par_windows(2))
        .with_min_len(LISTS_PER_SORT_TASK)
        .for_each_init(Vec::new, |list, at| {
            let at = at[0] as usize..at[1] as usize;
            if at.len() < 2 {
                return;
            }
            list.clear();
            list.extend(at.clone().map(|i| kept.word(i)));
            list.sort_unstable();
            for (i, &word) in at.zip(list.iter()) {
                let (entry, footprint) = unpack(word);
                kept.put(i, entry, footprint);
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::light_buffer::SUB;

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
        Steps::new(1 << 14, 1000.0).unwrap()
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

    /// The order every list is sorted and a long one cut in: nearest step
    /// first, ties by position, and a sphere listed twice in one window
    /// (these tests place spheres on two faces at random) by its footprint.
    fn cut_order(e: &Entry, part: Footprint) -> (u32, u32, u16) {
        (step_of(e), e.sphere, part.bits())
    }

    /// A window's list: each sphere and its footprint there.
    type List = Vec<(u32, Footprint)>;

    /// Each window's list as one sphere at a time would build it: sorted
    /// nearest step first (ties by position), and a long one cut, with the
    /// floor of the first step left out, which is below every distance left
    /// out.
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
                list.sort_by_key(|&(e, part)| cut_order(&e, part));
                if list.len() > MOST_LISTED {
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
        for (spheres, seed) in [(0, 1), (7, 2), (300, 3), (3000, 4), (12000, 5)] {
            let (spans, several, entries) = placements(spheres, seed);
            let p = Placements {
                spans: &spans,
                several: &several,
            };
            let want = one_by_one(&faces, &p, &entries);
            assert!(spheres < 12000 || want.iter().any(|(_, c)| c.is_finite()));
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
                    let mine: List = (got[at.clone()].iter())
                        .zip(&footprints[at])
                        .map(|(&e, &part)| (steps().sphere(e), part))
                        .collect();
                    assert_eq!(
                        (&mine, left_out(k)),
                        (list, *within),
                        "{spheres} {split:?} {k}"
                    );
                }
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
