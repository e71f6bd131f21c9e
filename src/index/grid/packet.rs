//! Eye-ray packets: rays from one origin walked through each level together.
//!
//! A packet is a 16×16 tile of pixels' rays. Each level is walked once for
//! all of them ([`super::slab`]); every candidate of the cells the walk
//! hands over is tested first against a cone around the packet's 256 rays
//! ([`super::cone`]), then against the box of slopes of each group of 16 (a
//! 4×4 square, [`super::slopes`]), and only the groups whose box it may
//! meet run the lane test ([`crate::geometry::lanes`]), which rounds exactly as the one-ray
//! test does. The nearest (t, id) per ray wins whatever the order of the
//! tests, so a packet returns what brute force returns.

use super::cone::PacketCone;
use super::ray_set::{set_bits, RaySet};
use super::slab::{Limits, Packet, PacketVisit, Searching};
use super::slopes::GroupSlopes;
use super::walk::Ray64;
use super::{Level, TestBudget, Tests, VoxelHashGrid};
use crate::geometry::lanes::{self, LaneVectors};
use crate::geometry::{Ray, Real, UnitSphereFrame, Vec3Ops, V3};
use crate::index::{Answered, Hit};
use glam::DVec3;

pub use crate::geometry::lanes::LANES;
/// Pixels a side of a packet's square tile.
pub const TILE_SIDE: usize = 16;
/// Pixels a side of a group's square within the tile: its [`LANES`] rays.
pub const GROUP_SIDE: usize = 4;
/// Groups a row of a tile.
pub(super) const GROUPS_A_ROW: usize = TILE_SIDE / GROUP_SIDE;
/// Groups of [`LANES`] rays per packet.
pub const GROUPS: usize = GROUPS_A_ROW * GROUPS_A_ROW;
/// Every group of a packet, one bit each.
pub(super) const ALL_GROUPS: u32 = u32::MAX >> (32 - GROUPS);
/// Rays per packet: a tile of [`TILE_SIDE`]² pixels, group by group. The
/// walk's cost per packet grows far slower than its rays, so larger packets
/// share it among more rays; each group keeps a box of slopes of its own, so that a
/// sphere is tested only against the groups that may hit it.
pub const RAYS: usize = GROUPS * LANES;
// A group is one lane test's rays, a packet whole words of a `RaySet`, and
// a tile's groups split into four quarters.
const _: () = assert!(
    GROUP_SIDE * GROUP_SIDE == LANES && RAYS.is_multiple_of(64) && GROUPS_A_ROW.is_multiple_of(2)
);

/// The groups of each quarter of a tile (top left, top right, bottom left,
/// bottom right), one bit per group: the groups lie row by row.
pub(super) const QUARTER_GROUPS: [u32; 4] = {
    let mut quarters = [0; 4];
    let mut g = 0;
    while g < GROUPS {
        let (row, column) = (g / GROUPS_A_ROW, g % GROUPS_A_ROW);
        let half = GROUPS_A_ROW / 2;
        quarters[(row / half) * 2 + column / half] |= 1 << g;
        g += 1;
    }
    quarters
};

/// One group of a packet's rays, laid out for the lane test, and the best
/// hit of each so far.
struct Lanes<R: Real> {
    origin: V3<R>,
    dir: LaneVectors<R>,
    best_t: [R; LANES],
    best_id: [u32; LANES],
    /// A hit counts up to and including the best t so far (so that an equal
    /// t with a lower id still wins, as in brute force): `best_t.next_up()`,
    /// and the search's `t_max` before any hit.
    cap: [R; LANES],
    t_min: R,
    /// The lanes whose best hit moved nearer, one bit each.
    improved: u32,
}

impl<R: Real> Lanes<R> {
    fn new(origin: V3<R>, t_min: R) -> Self {
        Lanes {
            origin,
            dir: [[R::zero(); LANES]; 3],
            best_t: [R::infinity(); LANES],
            best_id: [u32::MAX; LANES],
            cap: [R::infinity(); LANES],
            t_min,
            improved: 0,
        }
    }

    /// Sets the lanes' directions and forgets their hits.
    fn aim(&mut self, dirs: &[V3<R>], t_max: R) {
        for (i, d) in dirs.iter().enumerate().take(LANES) {
            self.dir[0][i] = d.x();
            self.dir[1][i] = d.y();
            self.dir[2][i] = d.z();
        }
        self.best_t = [R::infinity(); LANES];
        self.best_id = [u32::MAX; LANES];
        self.cap = [t_max; LANES];
        self.improved = 0;
    }

    /// Tests every lane against one candidate, keeping each lane's nearest
    /// (t, id); `id` gives the candidate's, read only once a lane finds a
    /// hit as near as its best.
    #[inline(always)]
    fn test(&mut self, frame: &UnitSphereFrame<R>, id: impl FnOnce() -> u32) {
        let found =
            lanes::hits_from_one_origin(frame, self.origin, &self.dir, self.t_min, &self.cap);
        // Most tests find no lane a nearer hit: one pass of compares without
        // a branch a lane tells so (NaN, no hit, compares false).
        let nearer =
            (found.iter().zip(&self.best_t)).fold(false, |any, (&t, &best)| any | (t <= best));
        if !nearer {
            return;
        }
        let id = id();
        for (i, &t) in found.iter().enumerate() {
            // NaN (no hit) fails both comparisons.
            if t < self.best_t[i] || (t == self.best_t[i] && id < self.best_id[i]) {
                self.best_t[i] = t;
                self.best_id[i] = id;
                self.cap[i] = t.next_up();
                self.improved |= 1 << i;
            }
        }
    }

    /// The t lane `lane`'s walk must reach: [`super::search_end`] of its
    /// best t, which once it has a hit is its cap (the next step up), and of
    /// `t_max` (the cap) before.
    #[inline(always)]
    fn search_end(&self, lane: usize) -> f64 {
        if self.best_id[lane] == u32::MAX {
            super::search_end(self.cap[lane])
        } else {
            self.cap[lane].to_f64()
        }
    }

    fn hit(&self, lane: usize) -> Option<Hit<R>> {
        (self.best_id[lane] != u32::MAX).then(|| Hit {
            t: self.best_t[lane],
            sphere: self.best_id[lane],
        })
    }
}

/// The rays of a packet, group by group (ray i is lane i mod [`LANES`] of
/// group i / [`LANES`]), and the tests the call may still make.
struct Groups<R: Real> {
    groups: [Lanes<R>; GROUPS],
    budget: TestBudget,
}

impl<R: Real> Searching for Groups<R> {
    fn t_min(&self) -> f64 {
        super::search_start(self.groups[0].t_min)
    }

    /// −∞ for every ray once the budget is spent: the walk ends.
    #[inline(always)]
    fn reach(&self, i: usize) -> f64 {
        if self.budget.spent() {
            return f64::NEG_INFINITY;
        }
        self.groups[i / LANES].search_end(i % LANES)
    }

    /// Group by group, each lane's [`Lanes::search_end`] in one pass.
    fn reaches(&self) -> [f64; RAYS] {
        let mut reach = [f64::NEG_INFINITY; RAYS];
        if self.budget.spent() {
            return reach;
        }
        for (lanes, reach) in self.groups.iter().zip(reach.chunks_exact_mut(LANES)) {
            for (lane, reach) in reach.iter_mut().enumerate() {
                *reach = lanes.search_end(lane);
            }
        }
        reach
    }

    #[inline(always)]
    fn take_improved(&mut self) -> RaySet {
        if self.budget.spent() {
            return RaySet::ALL;
        }
        take_masks(self.groups.iter_mut().map(|lanes| &mut lanes.improved))
    }
}

/// The groups' lane masks (one per group, in order) as one set of the
/// packet's rays, each left 0.
#[inline(always)]
pub(super) fn take_masks<'a>(masks: impl Iterator<Item = &'a mut u32>) -> RaySet {
    RaySet::from_lanes(masks.map(std::mem::take))
}

/// The most cells a slab's rectangle may span for a packet to walk a level
/// whole; wider, its quarters ([`QUARTER_GROUPS`]) walk it one after
/// another. Where a level's cells are small against the tile, one walk
/// offers each candidate to all sixteen groups and probes blocks
/// past the up-front fetch, where a quarter's walk does neither. Chosen on
/// clustered 10⁵ at 1024² and clustered 10⁶ at 512² (docs/index.md, "Wide
/// tiles walk by quarters").
const WIDEST_EYE_CELLS: f64 = 128.0;

/// How a packet turns a candidate away from its groups: by the cone
/// around the whole packet first (most candidates a walk hands over lie
/// beside the packet, and one test sends them off), then by each group's
/// box of slopes ([`super::slopes`]). Both see the candidate from the
/// packet's origin, with its bound grown by how far from it a ray may
/// start.
pub(super) struct GroupCull {
    origin: DVec3,
    spread: f64,
    cone: PacketCone,
    slopes: GroupSlopes,
}

impl GroupCull {
    /// Inlined into each instance of the packet kernels ([`super::vectors`]).
    #[inline(always)]
    pub(super) fn new(packet: &Packet, t_min: f64) -> Self {
        GroupCull {
            origin: DVec3::from_array(packet.origin),
            spread: packet.spread(),
            cone: PacketCone::new(packet, t_min),
            slopes: GroupSlopes::new(packet),
        }
    }

    /// The groups among `groups` (one bit each) whose rays may hit a
    /// candidate within `bound` of `center`.
    #[inline(always)]
    pub(super) fn groups_hit(&self, center: DVec3, bound: f64, groups: u32) -> u32 {
        let (w, bound) = (center - self.origin, bound + self.spread);
        if !self.cone.may_hit(w, bound) {
            return 0;
        }
        self.slopes.groups_hit(w, bound, groups)
    }
}

/// The last spheres tested, direct-mapped: a packet meets each candidate in
/// several cells of a slab and of the slabs after it.
pub(super) struct PacketMailbox([u32; MAILBOX]);

/// Slots of a packet's mailbox: a few times the spheres a packet meets.
const MAILBOX: usize = 256;

impl PacketMailbox {
    pub(super) fn new() -> Self {
        PacketMailbox([u32::MAX; MAILBOX])
    }

    /// True the first time `id` is seen (or when an evicted id comes back).
    #[inline(always)]
    pub(super) fn first_visit(&mut self, id: u32) -> bool {
        let slot = &mut self.0[id as usize % MAILBOX];
        let first = *slot != id;
        *slot = id;
        first
    }
}

/// Aims `packet` at the rays from `origin` along `dirs`; false when a ray
/// cannot be walked or the rays share no axis of travel. Inlined into each
/// instance of the packet kernel ([`super::vectors`]).
#[inline(always)]
fn aim_eye_packet<R: Real>(packet: &mut Packet, origin: V3<R>, dirs: &[V3<R>; RAYS]) -> bool {
    for (ray, &dir) in packet.rays.iter_mut().zip(dirs) {
        match Ray64::new(&Ray::<R>::new(origin, dir)) {
            Some(r) => *ray = r,
            None => return false,
        }
    }
    packet.aim_tile(origin.to_dvec3().to_array())
}

impl<R: Real> VoxelHashGrid<R> {
    /// [`crate::index::SphereIndex::closest_hits`]: packets of [`RAYS`]
    /// rays, and rays one at a time where a packet cannot be formed, all
    /// within one [`TestBudget`].
    pub(super) fn packet_closest_hits(
        &self,
        origin: V3<R>,
        dirs: &[V3<R>],
        t_min: R,
        t_max: R,
        out: &mut [Option<Hit<R>>],
    ) -> Answered {
        Packet::with_spare(|packet| self.eye_packets(packet, origin, dirs, t_min, t_max, out))
    }

    /// [`Self::packet_closest_hits`] with `packet` to aim
    /// ([`Self::eye_packets_body`]), with the widest vectors the grid may
    /// use ([`super::vectors`]).
    fn eye_packets(
        &self,
        packet: &mut Packet,
        origin: V3<R>,
        dirs: &[V3<R>],
        t_min: R,
        t_max: R,
        out: &mut [Option<Hit<R>>],
    ) -> Answered {
        #[cfg(target_arch = "x86_64")]
        if self.vectors.avx2() {
            // SAFETY: the function needs AVX2 alone, which `Vectors::avx2`
            // says this CPU has (only `Vectors::detect` can say so).
            return unsafe { self.eye_packets_avx2(packet, origin, dirs, t_min, t_max, out) };
        }
        self.eye_packets_body(packet, origin, dirs, t_min, t_max, out)
    }

    /// [`Self::eye_packets_body`] compiled with AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn eye_packets_avx2(
        &self,
        packet: &mut Packet,
        origin: V3<R>,
        dirs: &[V3<R>],
        t_min: R,
        t_max: R,
        out: &mut [Option<Hit<R>>],
    ) -> Answered {
        self.eye_packets_body(packet, origin, dirs, t_min, t_max, out)
    }

    /// Aims and traces each packet of [`RAYS`] rays in turn; the rays of a
    /// packet that cannot be aimed go one at a time.
    #[inline(always)]
    fn eye_packets_body(
        &self,
        packet: &mut Packet,
        origin: V3<R>,
        dirs: &[V3<R>],
        t_min: R,
        t_max: R,
        out: &mut [Option<Hit<R>>],
    ) -> Answered {
        let mut rays = Groups {
            groups: std::array::from_fn(|_| Lanes::new(origin, t_min)),
            budget: TestBudget::new(self.packet_tests),
        };
        for (dirs, out) in dirs.chunks(RAYS).zip(out.chunks_mut(RAYS)) {
            // A short last packet repeats its last ray in the spare lanes.
            let padded: [V3<R>; RAYS] = std::array::from_fn(|i| dirs[i.min(dirs.len() - 1)]);
            if aim_eye_packet::<R>(packet, origin, &padded) {
                for (g, lanes) in rays.groups.iter_mut().enumerate() {
                    lanes.aim(&padded[g * LANES..(g + 1) * LANES], t_max);
                }
                self.trace_packet(packet, &mut rays, t_min);
                for (lanes, out) in rays.groups.iter().zip(out.chunks_mut(LANES)) {
                    for (lane, hit) in out.iter_mut().enumerate() {
                        *hit = lanes.hit(lane);
                    }
                }
            } else {
                for (dir, hit) in dirs.iter().zip(out.iter_mut()) {
                    let ray = Ray::new(origin, *dir);
                    *hit = self.closest_hit_spending(&ray, t_min, t_max, &mut rays.budget);
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

    fn trace_packet(&self, packet: &Packet, groups: &mut Groups<R>, t_min: R) {
        let mut mailbox = PacketMailbox::new();
        let cull = GroupCull::new(packet, t_min.to_f64());
        for &i in &self.short {
            self.test_eye_groups(i, &cull, groups, ALL_GROUPS);
        }
        if groups.budget.spent() {
            return;
        }
        // Where each gated level may hold the packet's hits: None for nowhere.
        let gate = self.gate.as_ref();
        let spans = gate.map(|gate| gate.packet_spans(packet, t_min.to_f64()));
        for (i, level) in self.levels.iter().enumerate() {
            let along = match (gate, &spans) {
                (Some(gate), Some(spans)) if gate.gates(i) => spans.of(i),
                _ => Some(Limits::NONE.along),
            };
            let Some(along) = along else {
                continue;
            };
            self.walk_level(level, packet, groups, along, &mut mailbox, &cull);
            if groups.budget.spent() {
                return;
            }
        }
    }

    /// Walks the packet through `level` within the planes `along`
    /// ([`Self::walk_level_body`]), with the widest vectors the grid may
    /// use ([`super::vectors`]). Out of line: inlined into
    /// [`Self::trace_packet`], the walk came out dearer on every file.
    #[inline(never)]
    fn walk_level(
        &self,
        level: &Level,
        packet: &Packet,
        groups: &mut Groups<R>,
        along: [f64; 2],
        mailbox: &mut PacketMailbox,
        cull: &GroupCull,
    ) {
        #[cfg(target_arch = "x86_64")]
        if self.vectors.avx2() {
            // SAFETY: the function needs AVX2 alone, which `Vectors::avx2`
            // says this CPU has (only `Vectors::detect` can say so).
            return unsafe { self.walk_level_avx2(level, packet, groups, along, mailbox, cull) };
        }
        self.walk_level_body(level, packet, groups, along, mailbox, cull)
    }

    /// [`Self::walk_level_body`] compiled with AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn walk_level_avx2(
        &self,
        level: &Level,
        packet: &Packet,
        groups: &mut Groups<R>,
        along: [f64; 2],
        mailbox: &mut PacketMailbox,
        cull: &GroupCull,
    ) {
        self.walk_level_body(level, packet, groups, along, mailbox, cull)
    }

    /// Walks the packet through `level` within the planes `along`, testing
    /// each candidate new to the mailbox: whole, or quarter by quarter where
    /// a slab's rectangle would span more than [`WIDEST_EYE_CELLS`]. Each
    /// quarter has a mailbox of its own, as a sphere tested against one
    /// quarter's groups was not tested against another's.
    #[inline(always)]
    fn walk_level_body(
        &self,
        level: &Level,
        packet: &Packet,
        groups: &mut Groups<R>,
        along: [f64; 2],
        mailbox: &mut PacketMailbox,
        cull: &GroupCull,
    ) {
        let whole = Limits {
            along,
            widest: WIDEST_EYE_CELLS,
        };
        let apart = Limits {
            along,
            ..Limits::NONE
        };
        // The whole packet first; if refused, each quarter (one walk call,
        // so that the walk is inlined here once).
        let mut own = None;
        for part in 0..=QUARTER_GROUPS.len() {
            let (among, limits, mailbox) = match part.checked_sub(1) {
                None => (RaySet::ALL, whole, &mut *mailbox),
                Some(q) => (
                    RaySet::of_groups(QUARTER_GROUPS[q]),
                    apart,
                    own.insert(PacketMailbox::new()),
                ),
            };
            let mut visit = EyeCells {
                grid: self,
                mailbox,
                cull,
            };
            let walked =
                level.walk_packet(packet, groups, among, limits, self.empty_space, &mut visit);
            if part == 0 && walked {
                return;
            }
        }
    }

    /// Tests candidate `i` against the groups among `searching` whose rays
    /// may meet it ([`GroupCull`]), spending a test per group.
    #[inline(always)]
    fn test_eye_groups(&self, i: u32, cull: &GroupCull, rays: &mut Groups<R>, searching: u32) {
        let spheres = &self.spheres;
        let center = spheres.center(i).to_dvec3();
        let hit = cull.groups_hit(center, spheres.bound(i).to_f64(), searching);
        rays.budget.spend(u64::from(hit.count_ones()));
        let frame = spheres.frame(i);
        for g in set_bits(u64::from(hit)) {
            rays.groups[g].test(&frame, || spheres.id(i));
        }
    }
}

/// An eye packet's visit of a cell: each candidate new to the mailbox
/// tested against the groups still searching.
struct EyeCells<'a, R: Real> {
    grid: &'a VoxelHashGrid<R>,
    mailbox: &'a mut PacketMailbox,
    cull: &'a GroupCull,
}

impl<R: Real> PacketVisit<Groups<R>> for EyeCells<'_, R> {
    #[inline(always)]
    fn cell(&mut self, ids: &[u32], groups: &mut Groups<R>, searching: u32) {
        for &i in ids {
            if groups.budget.spent() {
                return;
            }
            if self.mailbox.first_visit(i) {
                self.grid.test_eye_groups(i, self.cull, groups, searching);
            }
        }
    }
}
