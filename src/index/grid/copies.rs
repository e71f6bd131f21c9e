//! The grid's copies of the spheres, in the order the levels' cells list
//! them (see [`super::build`]): the candidates of one cell lie together in
//! memory.
//!
//! A copy holds only what every hit test reads: the centre and one inverse
//! scale, 16 bytes in f32, so that four share a cache line and none
//! straddles two. What fewer tests read lies apart, by the same position:
//! - the bound, which only the packet walks' culls read (and the light
//!   buffers' build);
//! - the sphere's id, which a test reads only once it finds a hit (to
//!   order it among equal t as brute force does, and to report it);
//! - an ellipsoid's three inverse scales, kept only when the scene holds a
//!   shape that is not a sphere: a sphere's inverse scale is the same on
//!   every axis, so its copy rebuilds the very frame [`Ellipsoid::frame`]
//!   gives, bit for bit.
//!
//! In f32 that is 24 bytes a sphere, where a copy of the whole frame with
//! its bound and id would take 32.

use crate::geometry::{Ellipsoid, Ray, Real, UnitSphereFrame, Vec3Ops, V3};
use rayon::prelude::*;

/// What the hit test reads of one sphere.
#[derive(Clone, Copy, Debug)]
#[repr(align(16))]
struct Candidate<R: Real> {
    center: V3<R>,
    /// The inverse scale along every axis: a sphere's inverse radius (for
    /// an ellipsoid, its own three are in [`Copies::stretched`]).
    inv_scale: R,
}

/// The grid's copies of the spheres, by position (module docs).
pub(super) struct Copies<R: Real> {
    candidates: Vec<Candidate<R>>,
    /// Every copy's three inverse scales, when any shape is not a sphere;
    /// else empty.
    stretched: Vec<V3<R>>,
    /// A radius around the centre no rounded hit lies beyond (rounded up
    /// from [`super::build::Built::bound`]), for culling against a packet's
    /// cone and listing in a light's directions.
    bounds: Vec<R>,
    /// Which sphere of the scene each copy is.
    ids: Vec<u32>,
}

impl<R: Real> Copies<R> {
    /// The copies of `shapes` in the order `order` gives (a permutation of
    /// their ids), with each one's bound (by id).
    pub(super) fn new(shapes: &[Ellipsoid<R>], mut order: Vec<u32>, bound: &[f64]) -> Self {
        // Its bytes held are then its bytes counted.
        order.shrink_to_fit();
        let is_sphere = |s: &Ellipsoid<R>| {
            let v = s.inv_scale;
            v.x() == v.y() && v.y() == v.z()
        };
        let stretched = if shapes.par_iter().all(is_sphere) {
            Vec::new()
        } else {
            order
                .par_iter()
                .map(|&id| shapes[id as usize].inv_scale)
                .collect()
        };
        Copies {
            candidates: (order.par_iter())
                .map(|&id| Candidate {
                    center: shapes[id as usize].center,
                    inv_scale: shapes[id as usize].inv_scale.x(),
                })
                .collect(),
            stretched,
            bounds: (order.par_iter())
                .map(|&id| R::from_f64(bound[id as usize]).next_up())
                .collect(),
            ids: order,
        }
    }

    /// How many copies there are.
    pub(super) fn len(&self) -> usize {
        self.candidates.len()
    }

    /// The map into copy `i`'s unit-sphere frame: the one its shape's
    /// [`Ellipsoid::frame`] gives.
    #[inline(always)]
    pub(super) fn frame(&self, i: u32) -> UnitSphereFrame<R> {
        let c = &self.candidates[i as usize];
        // One comparison: among spheres alone `stretched` is empty.
        let inv_scale = match self.stretched.get(i as usize) {
            Some(&inv_scale) => inv_scale,
            None => V3::<R>::new(c.inv_scale, c.inv_scale, c.inv_scale),
        };
        UnitSphereFrame {
            center: c.center,
            inv_scale,
        }
    }

    /// Where the ray first meets copy `i` with t in (t_min, t_max): its
    /// shape's [`Ellipsoid::intersect`], bit for bit.
    ///
    /// Among spheres alone the frame is built with one inverse scale on
    /// every axis, known to be so where the inlined test uses it: the test
    /// through [`Copies::frame`], which picks the scales copy by copy, runs
    /// about 1% more instructions (docs/index.md, "The grid's copies of the
    /// spheres in 24 bytes").
    #[inline(always)]
    pub(super) fn intersect(&self, i: u32, ray: &Ray<R>, t_min: R, t_max: R) -> Option<R> {
        if !self.stretched.is_empty() {
            return self.frame(i).intersect(ray, t_min, t_max);
        }
        let c = &self.candidates[i as usize];
        let s = c.inv_scale;
        let frame = UnitSphereFrame {
            center: c.center,
            inv_scale: V3::<R>::new(s, s, s),
        };
        frame.intersect(ray, t_min, t_max)
    }

    /// Copy `i`'s centre.
    #[inline(always)]
    pub(super) fn center(&self, i: u32) -> V3<R> {
        self.candidates[i as usize].center
    }

    /// Copy `i`'s bound (see [`Copies::bounds`]).
    #[inline(always)]
    pub(super) fn bound(&self, i: u32) -> R {
        self.bounds[i as usize]
    }

    /// Which sphere of the scene copy `i` is.
    #[inline(always)]
    pub(super) fn id(&self, i: u32) -> u32 {
        self.ids[i as usize]
    }

    /// Bytes the copies hold.
    pub(super) fn bytes(&self) -> usize {
        self.candidates.capacity() * size_of::<Candidate<R>>()
            + self.stretched.capacity() * size_of::<V3<R>>()
            + self.bounds.capacity() * size_of::<R>()
            + self.ids.capacity() * size_of::<u32>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Four copies to a cache line, none straddling two.
    #[test]
    fn an_f32_candidate_is_a_quarter_of_a_cache_line() {
        assert_eq!(size_of::<Candidate<f32>>(), 16);
        assert_eq!(align_of::<Candidate<f32>>(), 16);
    }

    /// Each copy's frame is its shape's, bit for bit, among spheres alone
    /// and among spheres and ellipsoids; the ellipsoids' scales are kept
    /// only where there are some. (Four shapes or more: a parallel collect
    /// of fewer holds room for four.)
    #[test]
    fn a_copy_gives_its_shapes_frame() {
        let sphere =
            |x: f32, r: f32| Ellipsoid::<f32>::new(Vec3::new(x, 0.5, -2.0), Vec3::splat(r));
        let spheres = vec![
            sphere(1.0, 0.3),
            sphere(-7.5, 1e-3),
            sphere(3e4, 7.0),
            sphere(0.0, 2.5e-6),
        ];
        let mut mixed = spheres.clone();
        mixed.push(Ellipsoid::new(
            Vec3::new(0.0, 1.0, 2.0),
            Vec3::new(0.1, 0.2, 0.3),
        ));
        for shapes in [spheres, mixed] {
            let order: Vec<u32> = (0..shapes.len() as u32).rev().collect();
            let copies = Copies::new(&shapes, order.clone(), &vec![1.0; shapes.len()]);
            let spheres_only = shapes.len() == 4;
            assert_eq!(copies.stretched.is_empty(), spheres_only);
            let per_copy = if spheres_only { 24 } else { 36 };
            assert_eq!(copies.bytes(), per_copy * shapes.len());
            for (i, &id) in order.iter().enumerate() {
                assert_eq!(copies.frame(i as u32), shapes[id as usize].frame());
                assert_eq!(copies.id(i as u32), id);
                assert_eq!(copies.center(i as u32), shapes[id as usize].center);
            }
        }
    }

    proptest::proptest! {
        /// A copy's test answers as its shape's, bit for bit, sphere or
        /// ellipsoid, at random extreme scales and for rays from near and far.
        #[test]
        fn a_copy_is_hit_where_its_shape_is(
            scale_exp in -20i32..20,
            center in proptest::array::uniform3(-4.0f32..4.0),
            radii in proptest::array::uniform3(0.05f32..2.0),
            origin in proptest::array::uniform3(-8.0f32..8.0),
            aim in proptest::array::uniform3(-1.0f32..1.0),
            far in proptest::bool::ANY,
            stretched in proptest::bool::ANY,
        ) {
            let scale = 2f32.powi(scale_exp);
            let radii = if stretched { Vec3::from(radii) } else { Vec3::splat(radii[0]) };
            let shape = Ellipsoid::<f32>::new(Vec3::from(center) * scale, radii * scale);
            let other = Ellipsoid::<f32>::new(Vec3::splat(9.0) * scale, Vec3::splat(scale));
            let shapes = [other, shape];
            let copies = Copies::new(&shapes, vec![1, 0], &[1.0, 1.0]);
            let reach = if far { 1e4 } else { 1.0 };
            let o = Vec3::from(origin) * scale * reach;
            let ray = Ray::new(o, shape.center + Vec3::from(aim) * radii * scale - o);
            let t = copies.intersect(0, &ray, 0.0, f32::INFINITY);
            proptest::prop_assert_eq!(t.map(f32::to_bits), shape.intersect(&ray, 0.0, f32::INFINITY).map(f32::to_bits));
        }
    }
}
