//! Sets of a packet's rays, one bit each.
//!
//! A packet holds [`RAYS`] rays, more than one machine word has bits for:
//! the walk keeps which rays still search, the lanes report which rays
//! found nearer hits, and both are sets of ray positions. Ray `i` is bit
//! `i % 64` of word `i / 64`, so a group of [`LANES`] rays (which divides
//! 64) lies within one word.

use super::packet::{GROUPS, LANES, RAYS};
use std::ops::{BitAnd, BitAndAssign, BitOr, BitOrAssign};

/// Words of 64 rays in a set.
pub(super) const WORDS: usize = RAYS / 64;
/// The bits of one group's lanes, at the bottom of a word.
const LANE_BITS: u64 = (1 << LANES) - 1;

/// A set of a packet's rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct RaySet([u64; WORDS]);

impl RaySet {
    pub(super) const NONE: RaySet = RaySet([0; WORDS]);
    pub(super) const ALL: RaySet = RaySet([u64::MAX; WORDS]);

    pub(super) fn is_empty(self) -> bool {
        self.0.iter().fold(0, |any, w| any | w) == 0
    }

    pub(super) fn remove(&mut self, i: usize) {
        self.0[i / 64] &= !(1 << (i % 64));
    }

    pub(super) fn len(self) -> u32 {
        self.0.iter().map(|w| w.count_ones()).sum()
    }

    /// The rays `64·w .. 64·w + 64` of the set, one bit each.
    #[inline(always)]
    pub(super) fn word(self, w: usize) -> u64 {
        self.0[w]
    }

    /// The set whose word `w` is `words[w]` ([`RaySet::word`]).
    #[inline(always)]
    pub(super) fn from_words(words: [u64; WORDS]) -> RaySet {
        RaySet(words)
    }

    /// The rays of the set, lowest first (the walks read whole words,
    /// [`RaySet::word`]; the tests list members).
    #[cfg(test)]
    pub(super) fn iter(self) -> impl Iterator<Item = usize> {
        (0..WORDS).flat_map(move |w| set_bits(self.0[w]).map(move |b| w * 64 + b))
    }

    /// Every ray of group `g`.
    pub(super) fn group(g: usize) -> RaySet {
        let mut set = RaySet::NONE;
        set.0[g * LANES / 64] = LANE_BITS << (g * LANES % 64);
        set
    }

    /// Every ray of the groups `groups` (one bit each).
    pub(super) fn of_groups(groups: u32) -> RaySet {
        set_bits(u64::from(groups)).fold(RaySet::NONE, |set, g| set | RaySet::group(g))
    }

    /// The set of the groups' lane masks, one per group in order (lane l of
    /// group g is ray `g·LANES + l`).
    #[inline(always)]
    pub(super) fn from_lanes(masks: impl Iterator<Item = u32>) -> RaySet {
        let mut set = RaySet::NONE;
        for (g, lanes) in masks.enumerate() {
            set.0[g * LANES / 64] |= (u64::from(lanes) & LANE_BITS) << (g * LANES % 64);
        }
        set
    }

    /// The groups with a ray in the set, one bit per group.
    #[inline(always)]
    pub(super) fn groups(self) -> u32 {
        (0..GROUPS).fold(0, |mask, g| mask | u32::from(self.lanes(g) != 0) << g)
    }

    /// The rays of group `g` in the set, one bit per lane.
    #[inline(always)]
    pub(super) fn lanes(self, g: usize) -> u32 {
        (self.0[g * LANES / 64] >> (g * LANES % 64) & LANE_BITS) as u32
    }
}

impl BitAnd for RaySet {
    type Output = RaySet;
    fn bitand(self, other: RaySet) -> RaySet {
        RaySet(std::array::from_fn(|w| self.0[w] & other.0[w]))
    }
}

impl BitOr for RaySet {
    type Output = RaySet;
    fn bitor(self, other: RaySet) -> RaySet {
        RaySet(std::array::from_fn(|w| self.0[w] | other.0[w]))
    }
}

impl BitAndAssign for RaySet {
    fn bitand_assign(&mut self, other: RaySet) {
        *self = *self & other;
    }
}

impl BitOrAssign for RaySet {
    fn bitor_assign(&mut self, other: RaySet) {
        *self = *self | other;
    }
}

/// The positions of the bits set in `mask`, lowest first.
#[inline(always)]
pub(super) fn set_bits(mut mask: u64) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (mask != 0).then(|| {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            i
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::grid::packet::ALL_GROUPS;
    use crate::rng::Rng;

    /// A random set, with its members listed.
    fn random_set(rng: &mut Rng) -> (RaySet, Vec<usize>) {
        let mut words = [0; WORDS];
        let mut members = Vec::new();
        let share = rng.next_u64() % 4;
        for i in 0..RAYS {
            if rng.next_u64() % 4 < share {
                words[i / 64] |= 1 << (i % 64);
                members.push(i);
            }
        }
        (RaySet::from_words(words), members)
    }

    /// Whether ray `i` is in `set`, from its words.
    fn contains(set: RaySet, i: usize) -> bool {
        set.0[i / 64] >> (i % 64) & 1 != 0
    }

    #[test]
    fn a_set_lists_and_counts_its_members() {
        let mut rng = Rng::new(7);
        for _ in 0..200 {
            let (set, members) = random_set(&mut rng);
            let listed = (0..WORDS).flat_map(|w| set_bits(set.word(w)).map(move |b| w * 64 + b));
            assert_eq!(listed.collect::<Vec<_>>(), members);
            assert_eq!(set.len() as usize, members.len());
            assert_eq!(set.is_empty(), members.is_empty());
            for i in 0..RAYS {
                assert_eq!(contains(set, i), members.contains(&i));
            }
            let mut emptied = set;
            for &i in &members {
                emptied.remove(i);
            }
            assert_eq!(emptied, RaySet::NONE);
        }
    }

    #[test]
    fn groups_and_lanes_match_the_rays_they_hold() {
        let mut rng = Rng::new(11);
        for _ in 0..200 {
            let (set, members) = random_set(&mut rng);
            let groups = set.groups();
            for g in 0..GROUPS {
                let in_group = members.iter().any(|&i| i / LANES == g);
                assert_eq!(groups >> g & 1 != 0, in_group);
                assert_eq!(set & RaySet::group(g) != RaySet::NONE, in_group);
            }
            let lanes = (0..GROUPS).map(|g| {
                (members.iter().filter(|&&i| i / LANES == g))
                    .fold(0u32, |m, &i| m | 1 << (i % LANES))
            });
            assert_eq!(RaySet::from_lanes(lanes), set);
        }
        let all = (0..GROUPS).fold(RaySet::NONE, |s, g| s | RaySet::group(g));
        assert_eq!(all, RaySet::ALL);
        for _ in 0..100 {
            let groups = rng.next_u64() as u32 & ALL_GROUPS;
            let set = RaySet::of_groups(groups);
            for i in 0..RAYS {
                assert_eq!(contains(set, i), groups >> (i / LANES) & 1 != 0);
            }
        }
    }

    #[test]
    fn and_or_of_sets_are_those_of_their_members() {
        let mut rng = Rng::new(13);
        for _ in 0..100 {
            let (a, _) = random_set(&mut rng);
            let (b, _) = random_set(&mut rng);
            for i in 0..RAYS {
                assert_eq!(contains(a & b, i), contains(a, i) && contains(b, i));
                assert_eq!(contains(a | b, i), contains(a, i) || contains(b, i));
            }
        }
    }
}
