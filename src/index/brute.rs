use super::{Hit, SphereIndex};
use crate::geometry::{Ellipsoid, Ray, Real};

/// Tests every sphere. O(n) per ray; the reference for exactness.
pub struct BruteForce<'a, R: Real> {
    shapes: &'a [Ellipsoid<R>],
}

impl<'a, R: Real> BruteForce<'a, R> {
    pub fn new(shapes: &'a [Ellipsoid<R>]) -> Self {
        BruteForce { shapes }
    }
}

impl<R: Real> SphereIndex<R> for BruteForce<'_, R> {
    fn closest_hit(&self, ray: &Ray<R>, t_min: R, t_max: R) -> Option<Hit<R>> {
        let mut best: Option<Hit<R>> = None;
        let mut t_max = t_max;
        for (id, shape) in self.shapes.iter().enumerate() {
            if let Some(t) = shape.intersect(ray, t_min, t_max) {
                // Ids rise, so a later sphere at exactly the same t never wins.
                best = Some(Hit {
                    t,
                    sphere: id as u32,
                });
                t_max = t;
            }
        }
        best
    }

    fn any_hit(&self, ray: &Ray<R>, t_max: R) -> bool {
        self.shapes
            .iter()
            .any(|s| s.intersect(ray, R::zero(), t_max).is_some())
    }
}
