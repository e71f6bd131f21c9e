//! Candidate search: which sphere a ray meets first, and whether it meets any.
//!
//! The renderer sees only [`SphereIndex`]. [`VoxelHashGrid`] is the fast
//! index; [`BruteForce`] tests every sphere and is the oracle the grid is
//! checked against.

mod brute;
pub mod grid;
mod order;

pub use brute::BruteForce;
pub use grid::{EmptySpace, VoxelHashGrid, PACKET_GROUP_SIDE, PACKET_RAYS, PACKET_TILE_SIDE};
pub use order::compact_order;

use crate::geometry::{Ray, Real, V3};

/// Whether a call for many rays answered every one of them.
///
/// One call is one stretch of work nothing interrupts, so an index bounds
/// it: a call that would test more than [`crate::limits::PACKET_TESTS`]
/// candidates gives up instead, and its caller traces those rays one at a
/// time, as often as it likes to look at a deadline between them.
#[must_use]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Answered {
    /// Every ray's answer is in `out`.
    All,
    /// The rays cost too much together; `out` holds nothing to use.
    GaveUp,
}

/// The nearest sphere a ray meets and where along the ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit<R> {
    pub t: R,
    pub sphere: u32,
}

impl<R: Real> Hit<R> {
    /// The order every index agrees on: nearer first, and on an exact tie the
    /// lower sphere id, so that all indexes return the same hit.
    #[inline]
    pub fn is_before(&self, other: &Hit<R>) -> bool {
        self.t < other.t || (self.t == other.t && self.sphere < other.sphere)
    }
}

/// The light buffers an index keeps for shadow rays toward point lights.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LightBuffers {
    /// Lights with a buffer.
    pub lights: usize,
    pub bytes: usize,
}

pub trait SphereIndex<R: Real>: Sync {
    /// The nearest hit with t in the open interval (t_min, t_max).
    fn closest_hit(&self, ray: &Ray<R>, t_min: R, t_max: R) -> Option<Hit<R>>;
    /// [`Self::closest_hit`] for rays that share an origin (eye rays), into
    /// `out` (as long as `dirs`). Coherent neighbours should be adjacent:
    /// an index may trace them together.
    fn closest_hits(
        &self,
        origin: V3<R>,
        dirs: &[V3<R>],
        t_min: R,
        t_max: R,
        out: &mut [Option<Hit<R>>],
    ) -> Answered {
        for (dir, hit) in dirs.iter().zip(out) {
            *hit = self.closest_hit(&Ray::new(origin, *dir), t_min, t_max);
        }
        Answered::All
    }
    /// Whether any sphere meets the ray with t in (0, t_max). Shadow rays.
    fn any_hit(&self, ray: &Ray<R>, t_max: R) -> bool;
    /// [`Self::any_hit`] of the shadow rays toward the point `light`, into
    /// `out` (as long as `origins`): ray i is `o + t·(light − o)` with
    /// `o = origins[i]`, blocked by a hit with t in (0, 1). Rays from
    /// neighbouring points should be adjacent ([`compact_order`] lists them
    /// so): an index may trace them together.
    /// [`Self::any_hit`] of the one shadow ray `o + t·(light − o)`, t in
    /// (0, 1), with `o = origin`.
    fn any_hit_toward(&self, light: V3<R>, origin: V3<R>) -> bool {
        self.any_hit(&Ray::new(origin, light - origin), R::one())
    }
    /// The light buffers the index answers [`Self::any_hit_toward`] and
    /// [`Self::any_hits_toward`] from, where it keeps any.
    fn light_buffers(&self) -> LightBuffers {
        LightBuffers::default()
    }
    fn any_hits_toward(&self, light: V3<R>, origins: &[V3<R>], out: &mut [bool]) -> Answered {
        for (&o, blocked) in origins.iter().zip(out) {
            *blocked = self.any_hit(&Ray::new(o, light - o), R::one());
        }
        Answered::All
    }
}
