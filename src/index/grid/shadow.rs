//! Shadow-ray packets: the rays from a tile's hit points toward one light,
//! walked together from the light.
//!
//! Shadow rays toward one point light share their end, and from a patch of
//! neighbouring hit points (the caller lists them so, see
//! [`crate::index::compact_order`]) they leave it in nearly the same
//! direction: seen from the light they are a packet like a tile's eye rays. Each is walked
//! backwards, from its end toward its origin, through the slab walk
//! ([`super::slab`]); each candidate is tested with the ray as the renderer
//! casts it (from the hit point, t in (0, 1)), lane by lane
//! ([`crate::geometry::lanes::segments_hit`]), and a ray stops at its first
//! blocker. The sphere that blocked the call's latest ray is tried on the
//! next packet (and ray) before any walk.
//!
//! Not every packet pays: a ray from deep in a dense cloud is blocked a
//! few cells from its origin, and walked alone from there it costs less
//! than its share of a packet walked from the light, which fans out over
//! hits at every depth. So each packet's first group goes one ray at a time
//! as a sample, and the rest goes together only when enough of the sample
//! reached the light.
//!
//! # Why it answers what brute force answers
//! The test is the forward one-ray test, bit for bit, so only the walk's
//! cover matters (a sphere tried before the walk blocks a ray exactly when
//! brute force's test says it does, and any blocker answers). Ray i is `o + t·d` with `o` and `d` in the render's
//! precision; walked backwards it is `e − t'·d` with `e = o + d`, the same
//! line at `t' = 1 − t`. `e` is computed exactly in f64 (a packet whose sum
//! would round is traced one ray at a time), so the walk crosses exactly the
//! cells the forward line crosses over the same stretch, (0, 1) plus the
//! level's slack at both ends. The ends `e` lie within a few units of f32
//! of the light, not on it: the slab walk widens its rectangles and its
//! retire rule by each ray's offset, and the packet's cone and its groups'
//! boxes of slopes test with their bounds grown by the largest offset.

use super::packet::{take_masks, GroupCull, PacketMailbox, ALL_GROUPS, GROUPS, LANES, RAYS};
use super::ray_set::{set_bits, RaySet};
use super::seek::SeekBlocker;
use super::slab::{Limits, Packet, PacketVisit, Searching};
use super::walk::Ray64;
use super::{Level, TestBudget, Tests, VoxelHashGrid};
use crate::geometry::lanes::{self, LaneVectors};
use crate::geometry::{bounding_box, Ray, Real, UnitSphereFrame, Vec3Ops, V3};
use crate::index::Answered;
use glam::DVec3;

/// One group of a packet's shadow rays, as the renderer casts them (from
/// the hit point, reaching the light at t = 1), and which are blocked.
struct ShadowLanes<R: Real> {
    origin: LaneVectors<R>,
    dir: LaneVectors<R>,
    /// One bit per lane.
    blocked: u32,
    /// The lanes blocked since the last look, one bit each.
    newly: u32,
}

/// Every lane's bit.
const ALL_LANES: u32 = (1 << LANES) - 1;

impl<R: Real> ShadowLanes<R> {
    fn new() -> Self {
        ShadowLanes {
            origin: [[R::zero(); LANES]; 3],
            dir: [[R::zero(); LANES]; 3],
            blocked: 0,
            newly: 0,
        }
    }

    /// Sets the lanes' rays and forgets what blocked them.
    #[inline(always)]
    fn aim(&mut self, origins: &[V3<R>], dirs: &[V3<R>]) {
        for (i, (o, d)) in origins.iter().zip(dirs).enumerate().take(LANES) {
            (self.origin[0][i], self.origin[1][i], self.origin[2][i]) = (o.x(), o.y(), o.z());
            (self.dir[0][i], self.dir[1][i], self.dir[2][i]) = (d.x(), d.y(), d.z());
        }
        self.blocked = 0;
        self.newly = 0;
    }

    /// Tests the open lanes against one candidate; true if it blocks one.
    #[inline(always)]
    fn test(&mut self, frame: &UnitSphereFrame<R>) -> bool {
        let hit = lanes::segments_hit(frame, &self.origin, &self.dir) & !self.blocked;
        self.blocked |= hit;
        self.newly |= hit;
        hit != 0
    }
}

/// A packet's shadow rays, group by group, the tests the call may still
/// make, and the sphere that blocked the call's latest ray.
struct ShadowGroups<R: Real> {
    groups: [ShadowLanes<R>; GROUPS],
    budget: TestBudget,
    last_blocker: Option<u32>,
}

impl<R: Real> Searching for ShadowGroups<R> {
    /// The walk runs from each ray's end (t' = 1 − t = 0) to its origin
    /// (t' = 1), from the end of a search up to t = 1 ([`super::search_end`]).
    fn t_min(&self) -> f64 {
        1.0 - super::search_end(R::one())
    }

    /// −∞ for a blocked ray, and for every ray once the budget is spent.
    #[inline(always)]
    fn reach(&self, i: usize) -> f64 {
        if self.budget.spent() || self.groups[i / LANES].blocked >> (i % LANES) & 1 == 1 {
            f64::NEG_INFINITY
        } else {
            1.0
        }
    }

    #[inline(always)]
    fn take_improved(&mut self) -> RaySet {
        if self.budget.spent() {
            return RaySet::ALL;
        }
        take_masks(self.groups.iter_mut().map(|lanes| &mut lanes.newly))
    }
}

/// `a + b` when f64 holds it exactly (Knuth's two-sum leaves no error).
fn exact_sum(a: f64, b: f64) -> Option<f64> {
    let s = a + b;
    let b_part = s - a;
    let error = (a - (s - b_part)) + (b - b_part);
    (error == 0.0 && s.is_finite()).then_some(s)
}

/// Aims `packet` at the rays `origins[i] + t·dirs[i]` walked from their
/// ends near `light`; false when an end is not exact in f64, a ray cannot be
/// walked or the rays share no axis of travel. Inlined into each instance
/// of the packet kernels ([`super::vectors`]), as are the other steps of
/// a shadow packet's walk.
#[inline(always)]
fn aim_shadow_packet<R: Real>(
    packet: &mut Packet,
    light: V3<R>,
    origins: &[V3<R>; RAYS],
    dirs: &[V3<R>; RAYS],
) -> bool {
    for (ray, (o, d)) in packet.rays.iter_mut().zip(origins.iter().zip(dirs)) {
        let (o, d) = (o.to_dvec3(), d.to_dvec3());
        let walked = match [0, 1, 2].map(|a| exact_sum(o[a], d[a])) {
            [Some(x), Some(y), Some(z)] => Ray64::from_f64(DVec3::new(x, y, z), -d),
            _ => None,
        };
        match walked {
            Some(r) => *ray = r,
            None => return false,
        }
    }
    packet.aim(light.to_dvec3().to_array())
}

/// How many cells across one slab a packet's rays may fan out to, per ray,
/// for the packet to be walked: wider, the rays cost less one at a time.
/// Shadow rays from a tile's hit points at different depths fan out from
/// the light, where eye rays from one tile never do. Measured on the
/// independent families at 10⁵ and 10⁶ spheres (docs/index.md): a quarter
/// of a cell per ray is best or near it on every one.
const WIDEST_CELLS_PER_RAY: f64 = 0.25;

/// The rest of a packet goes together when more than 1/`LIT_DIVISOR` of
/// its sample reached the light, else one ray at a time.
const LIT_DIVISOR: usize = 4;

/// Whether shadow rays from `origins` toward one light may fan out
/// little enough across the slabs for a packet walk: the two widest
/// sides of the origins' box, in cells of the coarsest level (None: no
/// level), span at most the cells [`WIDEST_CELLS_PER_RAY`] allows them.
/// Near the origins a packet's slab rectangles are about as wide as the
/// origins' spread seen from the light, so a packet that fails this would
/// mostly be refused by the walk, after the cost of aiming it, in every
/// level; its rays go one at a time at once. Only which exact walk runs
/// depends on it.
fn may_fan_out_little<R: Real>(origins: &[V3<R>], coarsest_cell: Option<f64>) -> bool {
    let Some(cell) = coarsest_cell else {
        return true;
    };
    let (lo, hi) = bounding_box::<R>(origins);
    let mut sides = ((hi - lo) / cell).to_array();
    sides.sort_by(f64::total_cmp);
    (sides[1] + 1.0) * (sides[2] + 1.0) <= WIDEST_CELLS_PER_RAY * origins.len() as f64
}

/// The rays of `groups` still unblocked.
fn open_rays<R: Real>(rays: &ShadowGroups<R>) -> RaySet {
    RaySet::from_lanes(rays.groups.iter().map(|lanes| !lanes.blocked & ALL_LANES))
}

impl<R: Real> VoxelHashGrid<R> {
    /// [`crate::index::SphereIndex::any_hits_toward`]: packets of
    /// [`RAYS`] consecutive rays, and rays one at a time where a packet
    /// cannot be formed, all within one [`TestBudget`].
    pub(super) fn packet_any_hits_toward(
        &self,
        light: V3<R>,
        origins: &[V3<R>],
        out: &mut [bool],
    ) -> Answered {
        Packet::with_spare(|packet| self.shadow_packets(packet, light, origins, out))
    }

    /// [`Self::packet_any_hits_toward`] with `packet` to aim
    /// ([`Self::shadow_packets_body`]), with the widest vectors the grid may
    /// use ([`super::vectors`]).
    fn shadow_packets(
        &self,
        packet: &mut Packet,
        light: V3<R>,
        origins: &[V3<R>],
        out: &mut [bool],
    ) -> Answered {
        #[cfg(target_arch = "x86_64")]
        if self.vectors.avx2() {
            // SAFETY: the function needs AVX2 alone, which `Vectors::avx2`
            // says this CPU has (only `Vectors::detect` can say so).
            return unsafe { self.shadow_packets_avx2(packet, light, origins, out) };
        }
        self.shadow_packets_body(packet, light, origins, out)
    }

    /// [`Self::shadow_packets_body`] compiled with AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn shadow_packets_avx2(
        &self,
        packet: &mut Packet,
        light: V3<R>,
        origins: &[V3<R>],
        out: &mut [bool],
    ) -> Answered {
        self.shadow_packets_body(packet, light, origins, out)
    }

    /// Each packet of [`RAYS`] rays in turn, its first group's rays one at
    /// a time as a sample of how many are lit; the rest together where the
    /// sample says enough are, and they fan out little.
    #[inline(always)]
    fn shadow_packets_body(
        &self,
        packet: &mut Packet,
        light: V3<R>,
        origins: &[V3<R>],
        out: &mut [bool],
    ) -> Answered {
        let mut rays = ShadowGroups {
            groups: std::array::from_fn(|_| ShadowLanes::new()),
            budget: TestBudget::new(self.packet_tests),
            last_blocker: None,
        };
        let coarsest_cell = self.levels.iter().map(|l| l.cell).reduce(f64::max);
        for (origins, out) in origins.chunks(RAYS).zip(out.chunks_mut(RAYS)) {
            // The first group's rays, one at a time, are the sample.
            let sampled = origins.len().min(LANES);
            for (&o, blocked) in origins.iter().zip(out.iter_mut()).take(sampled) {
                *blocked = self.shadow_ray_alone(&Ray::new(o, light - o), &mut rays);
            }
            if rays.budget.spent() {
                return Answered::GaveUp;
            }
            let lit = out[..sampled].iter().filter(|&&blocked| !blocked).count();
            let (origins, out) = (&origins[sampled..], &mut out[sampled..]);
            if origins.is_empty() {
                continue;
            }
            // Lane LANES + i holds ray i of the rest; the sample's lanes (answered
            // already) and a short packet's spare lanes repeat a ray of it.
            let padded: [V3<R>; RAYS] =
                std::array::from_fn(|i| origins[i.saturating_sub(LANES).min(origins.len() - 1)]);
            let dirs = padded.map(|o| light - o);
            if lit * LIT_DIVISOR > sampled
                && may_fan_out_little::<R>(origins, coarsest_cell)
                && aim_shadow_packet::<R>(packet, light, &padded, &dirs)
            {
                for (g, lanes) in rays.groups.iter_mut().enumerate() {
                    let lanes_of = g * LANES..(g + 1) * LANES;
                    lanes.aim(&padded[lanes_of.clone()], &dirs[lanes_of]);
                }
                // The sample's lanes are answered already.
                rays.groups[0].blocked = ALL_LANES;
                self.trace_shadow_packet(packet, &mut rays);
                for (i, blocked) in out.iter_mut().enumerate() {
                    let lane = LANES + i;
                    *blocked = rays.groups[lane / LANES].blocked >> (lane % LANES) & 1 == 1;
                }
            } else {
                for (&o, blocked) in origins.iter().zip(out.iter_mut()) {
                    *blocked = self.shadow_ray_alone(&Ray::new(o, light - o), &mut rays);
                    if rays.budget.spent() {
                        return Answered::GaveUp;
                    }
                }
            }
            if rays.budget.spent() {
                return Answered::GaveUp;
            }
        }
        Answered::All
    }

    /// Tests the short list, then walks each level with the whole packet,
    /// or group by group where the packet fans out too wide, or ray by ray
    /// where a group does.
    #[inline(always)]
    fn trace_shadow_packet(&self, packet: &Packet, rays: &mut ShadowGroups<R>) {
        let cull = GroupCull::new(packet, 0.0);
        // Shadow rays toward one light from neighbouring points (the caller
        // lists them so) are often blocked by the same sphere, and any
        // blocker answers a shadow ray: the last one, tested first with the
        // walk's own test, closes such rays before any walk. (Keeping the
        // last 4 or 8 blockers cost more than it saved.)
        if let Some(i) = rays.last_blocker {
            self.test_shadow_groups(i, &cull, rays, ALL_GROUPS);
        }
        for &i in &self.short {
            self.test_shadow_groups(i, &cull, rays, ALL_GROUPS);
        }
        for level in &self.levels {
            let open = open_rays(rays);
            if open.is_empty() || rays.budget.spent() {
                return;
            }
            if self.walk_shadow_level(level, packet, &cull, rays, open) {
                continue;
            }
            for g in 0..GROUPS {
                let among = open & RaySet::group(g);
                if !among.is_empty() && !self.walk_shadow_level(level, packet, &cull, rays, among) {
                    let ShadowGroups {
                        groups,
                        budget,
                        last_blocker,
                    } = rays;
                    self.shadow_rays_one_by_one(level, &mut groups[g], budget, last_blocker);
                }
            }
        }
    }

    /// Walks the rays `among` of the packet through `level` together,
    /// unless they fan out too wide (false).
    #[inline(always)]
    fn walk_shadow_level(
        &self,
        level: &Level,
        packet: &Packet,
        cull: &GroupCull,
        rays: &mut ShadowGroups<R>,
        among: RaySet,
    ) -> bool {
        let widest = WIDEST_CELLS_PER_RAY * f64::from(among.len());
        // A fresh mailbox: a sphere seen by an earlier walk of other
        // groups was not tested against these.
        let mut mailbox = PacketMailbox::new();
        let mut visit = ShadowCells {
            grid: self,
            mailbox: &mut mailbox,
            cull,
        };
        let limits = Limits {
            widest,
            ..Limits::NONE
        };
        level.walk_packet(packet, rays, among, limits, self.empty_space, &mut visit)
    }

    /// Tests candidate `i` against the groups among `searching` whose rays
    /// may meet it ([`GroupCull`]), spending a test per group; true if it blocks a ray.
    #[inline(always)]
    fn test_shadow_groups(
        &self,
        i: u32,
        cull: &GroupCull,
        rays: &mut ShadowGroups<R>,
        searching: u32,
    ) -> bool {
        let center = self.spheres.center(i).to_dvec3();
        let hit = cull.groups_hit(center, self.spheres.bound(i).to_f64(), searching);
        rays.budget.spend(u64::from(hit.count_ones()));
        let mut blocks = false;
        let frame = self.spheres.frame(i);
        for g in set_bits(u64::from(hit)) {
            blocks |= rays.groups[g].test(&frame);
        }
        if blocks {
            rays.last_blocker = Some(i);
        }
        blocks
    }

    /// Whether a sphere blocks `ray` (reaching the light at t = 1), tried
    /// first against the call's last blocker.
    fn shadow_ray_alone(&self, ray: &Ray<R>, rays: &mut ShadowGroups<R>) -> bool {
        let ShadowGroups {
            budget,
            last_blocker,
            ..
        } = rays;
        self.blocked_after_last(ray, last_blocker, budget, |budget| {
            self.blocker(ray, R::one(), budget)
        })
    }

    /// Whether `last_blocker` blocks `ray` (reaching the light at t = 1), or
    /// else the blocker `walk` finds; a blocker found becomes the last.
    #[inline(always)]
    fn blocked_after_last(
        &self,
        ray: &Ray<R>,
        last_blocker: &mut Option<u32>,
        budget: &mut TestBudget,
        walk: impl FnOnce(&mut TestBudget) -> Option<u32>,
    ) -> bool {
        let blocker = last_blocker
            .filter(|&b| {
                budget.spend(1);
                self.blocks(b, ray, R::one())
            })
            .or_else(|| walk(budget));
        if blocker.is_some() {
            *last_blocker = blocker;
        }
        blocker.is_some()
    }

    /// The open lanes of `lanes` through `level`, one ray at a time (each
    /// tried first against the last blocker), until `budget` is spent.
    fn shadow_rays_one_by_one(
        &self,
        level: &Level,
        lanes: &mut ShadowLanes<R>,
        budget: &mut TestBudget,
        last_blocker: &mut Option<u32>,
    ) {
        let mut open = !lanes.blocked & ALL_LANES;
        while open != 0 && !budget.spent() {
            let i = open.trailing_zeros() as usize;
            open &= open - 1;
            let origin = V3::<R>::new(lanes.origin[0][i], lanes.origin[1][i], lanes.origin[2][i]);
            let dir = V3::<R>::new(lanes.dir[0][i], lanes.dir[1][i], lanes.dir[2][i]);
            let ray = Ray::new(origin, dir);
            let Some(wide) = Ray64::new(&ray) else {
                continue;
            };
            let blocked = self.blocked_after_last(&ray, last_blocker, budget, |budget| {
                SeekBlocker::new(self, &ray, R::one(), budget).walk(level, &wide)
            });
            if blocked {
                lanes.blocked |= 1 << i;
            }
        }
    }
}

/// The groups with an unblocked ray, one bit per group.
fn open_groups<R: Real>(rays: &ShadowGroups<R>) -> u32 {
    (0..GROUPS).fold(0, |mask, g| {
        mask | u32::from(rays.groups[g].blocked != ALL_LANES) << g
    })
}

/// A shadow packet's visit of a cell: each candidate new to the mailbox
/// tested against the groups still open, which a blocker may close.
struct ShadowCells<'a, R: Real> {
    grid: &'a VoxelHashGrid<R>,
    mailbox: &'a mut PacketMailbox,
    cull: &'a GroupCull,
}

impl<R: Real> PacketVisit<ShadowGroups<R>> for ShadowCells<'_, R> {
    #[inline(always)]
    fn cell(&mut self, ids: &[u32], rays: &mut ShadowGroups<R>, mut searching: u32) {
        for &i in ids {
            if rays.budget.spent() {
                return;
            }
            // Only a new blocker can close a group.
            if self.mailbox.first_visit(i)
                && self.grid.test_shadow_groups(i, self.cull, rays, searching)
            {
                searching &= open_groups(rays);
            }
        }
    }
}
