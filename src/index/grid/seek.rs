//! A single ray's searches through the levels, coarsest first: its nearest
//! hit ([`VoxelHashGrid::closest_hit_spending`]) and any sphere blocking it
//! ([`VoxelHashGrid::blocker`]). Each is a [`Visit`] the walk offers every
//! occupied cell's spheres to; a small mailbox spares the spheres a ray has
//! already met in an earlier cell.

use super::gate::Gate;
use super::walk::{greater, Ray64, Visit};
use super::{search_end, search_start, Copies, Level, Tests, VoxelHashGrid};
use crate::geometry::{Ray, Real};
use crate::index::Hit;

/// The last sphere tested per slot: a sphere spanning several cells along a
/// ray is met in consecutive cells, so a tiny direct-mapped table catches
/// almost every repeat.
struct Mailbox([u32; 16]);

impl Mailbox {
    fn new() -> Self {
        Mailbox([u32::MAX; 16])
    }

    /// True the first time `id` is seen (or when an evicted id comes back).
    #[inline(always)]
    fn first_visit(&mut self, id: u32) -> bool {
        let slot = &mut self.0[id as usize & 15];
        let first = *slot != id;
        *slot = id;
        first
    }
}

/// One ray's nearest hit so far, and the bound a candidate's t must stay
/// under to be tested against it.
pub(super) struct Nearest<R: Real> {
    pub(super) best: Option<Hit<R>>,
    /// The best t rounded up by one ulp (`t_max` before any hit): up to and
    /// including the best t, so that an equal t with a lower id still wins,
    /// as in brute force.
    cap: R,
}

impl<R: Real> Nearest<R> {
    pub(super) fn new(t_max: R) -> Self {
        Nearest {
            best: None,
            cap: t_max,
        }
    }

    /// [`search_end`] of the best t, once there is a hit: the cap is that
    /// t's next step up already (a walk asks after every occupied cell, so
    /// the step is not taken again each time).
    #[inline(always)]
    fn search_end(&self) -> Option<f64> {
        self.best.is_some().then(|| self.cap.to_f64())
    }

    /// Tests copy `i` of `spheres`, keeping its hit if it comes first in
    /// (t, id) order.
    #[inline(always)]
    pub(super) fn offer(&mut self, spheres: &Copies<R>, i: u32, ray: &Ray<R>, t_min: R) {
        let Some(t) = spheres.intersect(i, ray, t_min, self.cap) else {
            return;
        };
        let hit = Hit {
            t,
            sphere: spheres.id(i),
        };
        if self.best.is_none_or(|b| hit.is_before(&b)) {
            self.best = Some(hit);
            self.cap = t.next_up();
        }
    }
}

impl<R: Real> VoxelHashGrid<R> {
    /// [`crate::index::SphereIndex::closest_hit`], spending one of `budget`
    /// per test (a single ray's walk is never cut short: its caller looks
    /// between rays).
    pub(super) fn closest_hit_spending(
        &self,
        ray: &Ray<R>,
        t_min: R,
        t_max: R,
        budget: &mut impl Tests,
    ) -> Option<Hit<R>> {
        let wide = Ray64::new(ray)?;
        let mut seek = SeekNearest {
            grid: self,
            ray,
            t_min,
            t_max,
            nearest: Nearest::new(t_max),
            mailbox: Mailbox::new(),
            budget,
            slack: 0.0,
            from: f64::NEG_INFINITY,
        };
        for &i in &self.short {
            seek.test(i);
        }
        match &self.gate {
            None => {
                for level in &self.levels {
                    seek.walk(level, &wide);
                }
            }
            Some(gate) => seek.walk_gated(gate, &wide),
        }
        seek.nearest.best
    }

    /// A sphere (its position in `spheres`) that meets the ray with t in
    /// (0, t_max), spending one of `budget` per test.
    pub(super) fn blocker(&self, ray: &Ray<R>, t_max: R, budget: &mut impl Tests) -> Option<u32> {
        let wide = Ray64::new(ray)?;
        budget.spend(self.short.len() as u64);
        if let Some(&i) = self.short.iter().find(|&&i| self.blocks(i, ray, t_max)) {
            return Some(i);
        }
        let mut seek = SeekBlocker::new(self, ray, t_max, budget);
        match &self.gate {
            None => self.levels.iter().find_map(|level| seek.walk(level, &wide)),
            Some(gate) => seek.walk_gated(gate, &wide),
        }
    }
}

/// A single ray's search for its nearest hit, level after level: in each
/// cell a walk reaches, the spheres not tested yet.
struct SeekNearest<'a, R: Real, B: Tests> {
    grid: &'a VoxelHashGrid<R>,
    ray: &'a Ray<R>,
    t_min: R,
    t_max: R,
    nearest: Nearest<R>,
    mailbox: Mailbox,
    budget: &'a mut B,
    /// The walked level's pad in t, which the walk's end keeps beyond the best t.
    slack: f64,
    /// A t before which no level holds anything along the ray ([`super::gate`]).
    from: f64,
}

impl<R: Real, B: Tests> SeekNearest<'_, R, B> {
    #[inline(always)]
    fn test(&mut self, i: u32) {
        self.budget.spend(1);
        self.nearest
            .offer(&self.grid.spheres, i, self.ray, self.t_min);
    }

    /// Where the search starts and ends, before any level's slack: up to
    /// the best hit so far.
    fn span(&self) -> (f64, f64) {
        let best_t = self.nearest.best.map_or(self.t_max, |b| b.t);
        (search_start(self.t_min), search_end(best_t))
    }

    /// Searches every level, those `gate` answers for from where it says
    /// the ray first meets their space, or not at all; the others from the
    /// start. Out of line, so that the walk of a scene without a gate costs
    /// what it did before there was one.
    #[inline(never)]
    fn walk_gated(&mut self, gate: &Gate, wide: &Ray64) {
        // Asked once, at the first level the gate answers for.
        let mut first = None;
        for (i, level) in self.grid.levels.iter().enumerate() {
            self.from = f64::NEG_INFINITY;
            if gate.gates(i) {
                let t = *first.get_or_insert_with(|| {
                    let slack = gate.slack / wide.length;
                    let (start, end) = self.span();
                    gate.first_marked(wide, start - slack, end + slack)
                });
                match t {
                    Some(t) => self.from = t,
                    None => continue,
                }
            }
            self.walk(level, wide);
        }
    }

    /// Searches `level` (the ray `wide` in f64) up to the best hit so far.
    fn walk(&mut self, level: &Level, wide: &Ray64) {
        self.slack = level.slack / wide.length;
        let (start, end) = self.span();
        let span = (greater(start, self.from) - self.slack, end + self.slack);
        level.walk(wide, span, self.grid.empty_space, self.grid.vectors, self);
    }
}

impl<R: Real, B: Tests> Visit for SeekNearest<'_, R, B> {
    #[inline(always)]
    fn cell(&mut self, spheres: impl Iterator<Item = u32>) -> f64 {
        for i in spheres {
            if self.mailbox.first_visit(i) {
                self.test(i);
            }
        }
        let end = self.nearest.search_end();
        end.map_or(f64::INFINITY, |t| t + self.slack)
    }
}

/// A single ray's search for any sphere blocking it with t in (0, t_max),
/// level after level: a walk stops at the first cell that holds one.
pub(super) struct SeekBlocker<'a, R: Real, B: Tests> {
    grid: &'a VoxelHashGrid<R>,
    ray: &'a Ray<R>,
    t_max: R,
    mailbox: Mailbox,
    budget: &'a mut B,
    blocker: Option<u32>,
    /// A t before which no level holds anything along the ray ([`super::gate`]).
    from: f64,
}

impl<'a, R: Real, B: Tests> SeekBlocker<'a, R, B> {
    pub(super) fn new(
        grid: &'a VoxelHashGrid<R>,
        ray: &'a Ray<R>,
        t_max: R,
        budget: &'a mut B,
    ) -> Self {
        SeekBlocker {
            grid,
            ray,
            t_max,
            mailbox: Mailbox::new(),
            budget,
            blocker: None,
            from: f64::NEG_INFINITY,
        }
    }

    /// [`SeekBlocker::walk`] over every level, those `gate` answers for
    /// from where it says the ray first meets their space, or not at all
    /// (out of line, as [`SeekNearest::walk_gated`]).
    #[inline(never)]
    fn walk_gated(&mut self, gate: &Gate, wide: &Ray64) -> Option<u32> {
        // Asked once, at the first level the gate answers for.
        let mut first = None;
        (self.grid.levels.iter().enumerate()).find_map(|(i, level)| {
            self.from = f64::NEG_INFINITY;
            if gate.gates(i) {
                let t = *first.get_or_insert_with(|| {
                    let slack = gate.slack / wide.length;
                    gate.first_marked(wide, -slack, search_end(self.t_max) + slack)
                });
                self.from = t?;
            }
            self.walk(level, wide)
        })
    }

    /// A sphere of `level` (its position in the grid's spheres) that blocks
    /// the ray (`wide` in f64), spending one of the budget per test.
    pub(super) fn walk(&mut self, level: &Level, wide: &Ray64) -> Option<u32> {
        let slack = level.slack / wide.length;
        let end = search_end(self.t_max) + slack;
        let start = greater(0.0, self.from) - slack;
        level.walk(
            wide,
            (start, end),
            self.grid.empty_space,
            self.grid.vectors,
            self,
        );
        self.blocker
    }
}

impl<R: Real, B: Tests> Visit for SeekBlocker<'_, R, B> {
    #[inline(always)]
    fn cell(&mut self, spheres: impl Iterator<Item = u32>) -> f64 {
        for i in spheres {
            if self.mailbox.first_visit(i) {
                self.budget.spend(1);
                if self.grid.blocks(i, self.ray, self.t_max) {
                    self.blocker = Some(i);
                    return f64::NEG_INFINITY;
                }
            }
        }
        f64::INFINITY
    }
}
