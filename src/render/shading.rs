//! The two shading models and the recursion that joins them.
//!
//! Geometry runs in the precision `R`; colours are always f64 (cheap next to
//! the intersection work, and it keeps the f32/f64 comparison about geometry).

use super::deadline::Stop;
use super::{RayCounts, RenderOptions, Rules, SpecularModel};
use crate::geometry::{spawn_origin, Ellipsoid, Ray, Real, SurfacePoint, Vec3Ops, V3};
use crate::index::{compact_order, Answered, Hit, SphereIndex};
use crate::limits;
use crate::scene::{Dialect, Material, Scene};
use glam::DVec3;

/// Why a secondary ray is traced, for the statistics.
#[derive(Clone, Copy)]
enum Bounce {
    Reflection,
    Refraction,
}

/// What shading a hit knows of its shadow rays.
#[derive(Clone, Copy)]
enum Shadows<'s> {
    /// Traced already, with the hit's neighbours: entry `l` says whether
    /// the ray toward light `l` is blocked (read only where one was needed).
    Known(&'s [bool]),
    /// To be traced one at a time.
    Trace,
}

pub(super) struct Tracer<'a, R: Real, I: ?Sized> {
    scene: &'a Scene,
    shapes: &'a [Ellipsoid<R>],
    index: &'a I,
    /// Lights in the geometry's precision, those with zero intensity left out.
    lights: Vec<(V3<R>, DVec3)>,
    max_depth: u32,
    specular: SpecularModel,
    rules: Rules,
    /// Per sphere, whether its hit points are
    /// [`Ellipsoid::precise_surface_point`]s: empty when the precision rule
    /// is off, false for a sphere none of whose hits can need it.
    refine: Vec<bool>,
    /// Smallest weight worth a secondary ray, and how a weight is measured.
    min_weight: f64,
    weight_norm: fn(DVec3) -> f64,
    /// What a secondary ray that meets nothing returns.
    secondary_miss: DVec3,
    /// Checked before every shadow ray and bounce: once it is raised, they
    /// return black and the render unwinds at once (its image is dropped).
    stop: &'a Stop,
}

impl<'a, R: Real, I: SphereIndex<R> + ?Sized> Tracer<'a, R, I> {
    pub fn new(
        scene: &'a Scene,
        shapes: &'a [Ellipsoid<R>],
        index: &'a I,
        options: &RenderOptions,
        stop: &'a Stop,
    ) -> Self {
        let lights: Vec<_> = scene
            .lights
            .iter()
            .filter(|l| l.intensity != DVec3::ZERO)
            .map(|l| (V3::<R>::from_dvec3(l.position), l.intensity))
            .collect();
        let (own_specular, secondary_miss) = match scene.dialect {
            Dialect::Classic => (SpecularModel::Phong, DVec3::ZERO),
            Dialect::Browser => (SpecularModel::Blinn, scene.ambient * scene.background),
        };
        // The browser model's own rule measures the weight's length; the
        // adaptive cut-off asks whether any channel can still move a level.
        let (min_weight, weight_norm): (f64, fn(DVec3) -> f64) =
            match (scene.dialect, options.adaptive_cutoff) {
                (Dialect::Browser, _) => (limits::BROWSER_MIN_WEIGHT, DVec3::length),
                (Dialect::Classic, true) => (limits::ADAPTIVE_MIN_WEIGHT, DVec3::max_element),
                (Dialect::Classic, false) => (0.0, DVec3::max_element),
            };
        let max_depth = match scene.dialect {
            Dialect::Classic if !any_sphere_lit(scene, &lights) && !recurse_when_dark() => 0,
            _ => options.depth_for(scene.dialect),
        };
        Tracer {
            scene,
            shapes,
            index,
            lights,
            max_depth,
            specular: options.specular.unwrap_or(own_specular),
            rules: options.rules,
            refine: refinable(shapes, options.refine),
            min_weight,
            weight_norm,
            secondary_miss,
            stop,
        }
    }

    /// The nearest hits of eye rays with directions `dirs` (in the geometry's
    /// precision) beyond the near plane (t > 1), searched together, unless
    /// the index gives up on them.
    pub fn eye_hits(&self, dirs: &[V3<R>], out: &mut [Option<Hit<R>>]) -> Answered {
        self.index
            .closest_hits(V3::<R>::ZERO, dirs, R::one(), R::infinity(), out)
    }

    /// [`Self::eye_hits`] for one ray.
    pub fn eye_hit(&self, dir: V3<R>) -> Option<Hit<R>> {
        self.index
            .closest_hit(&Ray::new(V3::<R>::ZERO, dir), R::one(), R::infinity())
    }

    /// The surface point where the eye ray with direction `dir` meets `hit`.
    pub fn eye_surface(&self, dir: V3<R>, hit: Hit<R>) -> SurfacePoint<R> {
        self.surface(&Ray::new(V3::<R>::ZERO, dir), hit)
    }

    /// The surface point where `ray` meets `hit`, the index's choice, with
    /// the normal shading reads ([`Rules::shading`]).
    fn surface(&self, ray: &Ray<R>, hit: Hit<R>) -> SurfacePoint<R> {
        let k = hit.sphere as usize;
        let shape = &self.shapes[k];
        let surface = if self.refine.get(k).copied().unwrap_or(false) {
            shape.precise_surface_point(ray, hit.t)
        } else {
            shape.surface_point(ray, hit.t)
        };
        self.rules.shading(surface)
    }

    /// How many lights shading reads: the length of each hit's row of
    /// [`Self::eye_shadows`].
    pub fn light_count(&self) -> usize {
        self.lights.len()
    }

    /// Which shadow rays of the eye hits `hits` (at `surfaces`, None where
    /// a ray missed) are blocked, into `blocked`: row i (one entry per
    /// light) for hit i. The rays toward one light from all the hits are
    /// traced together, in [`compact_order`] of the hit points (one order
    /// for every light: a point's shadow rays start within a few f32 units
    /// of it). `counts` gets the rays traced and `packed` those of them
    /// traced in packets. False if told to stop.
    pub fn eye_shadows(
        &self,
        hits: &[Option<Hit<R>>],
        surfaces: &[Option<SurfacePoint<R>>],
        blocked: &mut Vec<bool>,
        counts: &mut RayCounts,
        packed: &mut RayCounts,
    ) -> bool {
        let lights = self.lights.len();
        blocked.clear();
        blocked.resize(hits.len() * lights, false);
        let lit: Vec<(usize, &SurfacePoint<R>)> = hits
            .iter()
            .zip(surfaces)
            .enumerate()
            .filter_map(|(i, (hit, surface))| {
                let (hit, surface) = (hit.as_ref()?, surface.as_ref()?);
                let m = &self.scene.spheres[hit.sphere as usize].material;
                takes_direct_light(m).then_some((i, surface))
            })
            .collect();
        // Neighbours together, so that the index's packets are coherent.
        let points: Vec<V3<R>> = lit.iter().map(|(_, surface)| surface.point).collect();
        let order = compact_order::<R>(&points);
        let (mut which, mut origins, mut out) = (Vec::new(), Vec::new(), Vec::new());
        for (l, &(position, _)) in self.lights.iter().enumerate() {
            which.clear();
            origins.clear();
            for &(i, surface) in order.iter().map(|&k| &lit[k]) {
                if faces(surface, position).is_some() {
                    which.push(i);
                    origins.push(spawn_origin(surface, position - surface.point));
                }
            }
            out.clear();
            out.resize(origins.len(), false);
            if !self.trace_shadow_rays(position, &origins, &mut out, counts, packed) {
                return false;
            }
            for (&i, &b) in which.iter().zip(&out) {
                blocked[i * lights + l] = b;
            }
        }
        true
    }

    /// Whether something lies between each of `origins` and `light`, into
    /// `out`, in packets or one ray at a time ([`Stop::in_packets`]). False
    /// if told to stop.
    fn trace_shadow_rays(
        &self,
        light: V3<R>,
        origins: &[V3<R>],
        out: &mut [bool],
        counts: &mut RayCounts,
        packed: &mut RayCounts,
    ) -> bool {
        counts.shadow += origins.len() as u64;
        let traced = self.stop.in_packets(origins.len(), |rays, together| {
            if together {
                self.index
                    .any_hits_toward(light, &origins[rays.clone()], &mut out[rays])
            } else {
                let o = origins[rays.start];
                out[rays.start] = self.index.any_hit_toward(light, o);
                Answered::All
            }
        });
        traced.map(|n| packed.shadow += n).is_some()
    }

    /// The colour seen along the eye ray with direction `dir`, whose nearest
    /// hit beyond the near plane is `hit`, at `surface`, with its shadow
    /// rays' answers `shadows` (its row of [`Self::eye_shadows`]).
    pub fn shade_eye(
        &self,
        dir: V3<R>,
        hit: Option<(Hit<R>, SurfacePoint<R>)>,
        shadows: &[bool],
        counts: &mut RayCounts,
    ) -> DVec3 {
        counts.eye += 1;
        let ray = Ray::new(V3::<R>::ZERO, dir);
        match hit {
            Some((hit, surface)) => self.shade_at(
                &ray,
                hit,
                &surface,
                0,
                DVec3::ONE,
                Shadows::Known(shadows),
                counts,
            ),
            None => match self.scene.dialect {
                Dialect::Classic => self.scene.background,
                Dialect::Browser => self.secondary_miss,
            },
        }
    }

    /// A reflected or refracted ray, which carries `weight` of the pixel,
    /// and takes the nearest hit beyond `t_min`.
    fn trace_secondary(
        &self,
        ray: &Ray<R>,
        t_min: R,
        depth: u32,
        weight: DVec3,
        counts: &mut RayCounts,
    ) -> DVec3 {
        if self.stop.now() {
            return DVec3::ZERO;
        }
        match self.index.closest_hit(ray, t_min, R::infinity()) {
            Some(hit) => {
                let surface = self.surface(ray, hit);
                self.shade_at(ray, hit, &surface, depth, weight, Shadows::Trace, counts)
            }
            None => self.secondary_miss,
        }
    }

    /// The two models share the direct light and differ in how they add
    /// ambient light and blend in the bounces:
    ///
    /// - classic: `Ka·A·O + direct + Kr·reflected + Krefract·refracted`;
    /// - browser: `surface = min(k_a·O + direct, 1)`, then
    ///   `surface + (1 − surface)⊙(k_r·reflected + k_refract·refracted)`.
    #[allow(clippy::too_many_arguments)]
    fn shade_at(
        &self,
        ray: &Ray<R>,
        hit: Hit<R>,
        surface: &SurfacePoint<R>,
        depth: u32,
        weight: DVec3,
        shadows: Shadows,
        counts: &mut RayCounts,
    ) -> DVec3 {
        let m = &self.scene.spheres[hit.sphere as usize].material;
        let dir = ray.dir.normalize();
        let direct = self.direct_light(surface, m, -dir, shadows, counts);
        match self.scene.dialect {
            Dialect::Classic => {
                let local = m.ambient * self.scene.ambient * m.color + direct;
                local + self.bounces(dir, surface, m, depth, weight, DVec3::splat, counts)
            }
            Dialect::Browser => {
                let local = (m.ambient * m.color + direct).min(DVec3::ONE);
                let open = DVec3::ONE - local;
                local + open * self.bounces(dir, surface, m, depth, weight, |k| k * open, counts)
            }
        }
    }

    /// `Σ I⊙(Kd·(N·L)·O + Ks·spec^n)` over the lights not in shadow.
    ///
    /// A light with N·L ≤ 0 is behind the surface, so the closed surface
    /// itself shadows it: no shadow ray is needed, nor any term.
    fn direct_light(
        &self,
        surface: &SurfacePoint<R>,
        m: &Material,
        view: V3<R>,
        shadows: Shadows,
        counts: &mut RayCounts,
    ) -> DVec3 {
        let mut sum = DVec3::ZERO;
        if !takes_direct_light(m) {
            return sum;
        }
        let n = surface.normal;
        for (l, &(position, intensity)) in self.lights.iter().enumerate() {
            let Some((to_light, n_dot_l)) = faces(surface, position) else {
                continue;
            };
            let blocked = match shadows {
                Shadows::Known(blocked) => blocked[l],
                Shadows::Trace => {
                    if self.stop.now() {
                        return sum;
                    }
                    self.trace_shadow_ray(surface, position, counts)
                }
            };
            if blocked {
                continue;
            }
            let spec = if m.specular > 0.0 {
                self.specular_base(n, to_light, view)
                    .to_f64()
                    .powf(m.shininess)
            } else {
                0.0
            };
            sum += intensity
                * (m.diffuse * n_dot_l.to_f64() * m.color + DVec3::splat(m.specular * spec));
        }
        sum
    }

    /// Whether something lies between the surface point and the light.
    fn trace_shadow_ray(
        &self,
        surface: &SurfacePoint<R>,
        light: V3<R>,
        counts: &mut RayCounts,
    ) -> bool {
        counts.shadow += 1;
        let origin = spawn_origin(surface, light - surface.point);
        // t = 1 is the light itself; blockers beyond it do not count.
        self.index.any_hit_toward(light, origin)
    }

    /// `max(0, R·V)` (Phong) or `max(0, N·H)` (Blinn).
    fn specular_base(&self, n: V3<R>, to_light: V3<R>, view: V3<R>) -> R {
        let base = match self.specular {
            SpecularModel::Phong => (n * (R::from_f64(2.0) * n.dot(to_light)) - to_light).dot(view),
            SpecularModel::Blinn => n.dot((to_light + view).normalize()),
        };
        base.max(R::zero())
    }

    /// The reflected and refracted contributions of a ray arriving along the
    /// unit direction `dir`, each weighted by `factor(k)` (a plain
    /// coefficient in the classic model, blended in the browser one).
    #[allow(clippy::too_many_arguments)]
    fn bounces(
        &self,
        dir: V3<R>,
        surface: &SurfacePoint<R>,
        m: &Material,
        depth: u32,
        weight: DVec3,
        factor: impl Fn(f64) -> DVec3,
        counts: &mut RayCounts,
    ) -> DVec3 {
        let mut sum = DVec3::ZERO;
        if depth >= self.max_depth {
            return sum;
        }
        let n = surface.normal;
        for (k, bounce) in [
            (m.reflect, Bounce::Reflection),
            (m.refract, Bounce::Refraction),
        ] {
            if k == 0.0 {
                continue;
            }
            let gain = factor(k);
            let next_weight = weight * gain;
            if (self.weight_norm)(next_weight) < self.min_weight || next_weight == DVec3::ZERO {
                continue;
            }
            let (out, t_min) = match bounce {
                Bounce::Reflection => {
                    counts.reflection += 1;
                    (reflect::<R>(dir, n), self.rules.reflection_t_min())
                }
                Bounce::Refraction => {
                    counts.refraction += 1;
                    let ratio = if surface.inside {
                        R::one() / R::from_f64(m.ior)
                    } else {
                        R::from_f64(m.ior)
                    };
                    // Total internal reflection sends the light back inside, with the same weight.
                    let n = self.rules.facing_normal(surface);
                    let out = refract(dir, n, ratio).unwrap_or_else(|| reflect::<R>(dir, n));
                    (out, R::zero())
                }
            };
            let next = Ray::new(spawn_origin(surface, out), out);
            sum += gain * self.trace_secondary(&next, t_min, depth + 1, next_weight, counts);
        }
        sum
    }
}

/// The unit direction from the surface point to the light at `position`
/// and its cosine with the normal, when the light is in front of the
/// surface (a light behind it is shadowed by the closed surface itself:
/// no shadow ray is needed, nor any term).
fn faces<R: Real>(surface: &SurfacePoint<R>, position: V3<R>) -> Option<(V3<R>, R)> {
    let to_light = (position - surface.point).normalize();
    let n_dot_l = surface.normal.dot(to_light);
    (n_dot_l > R::zero()).then_some((to_light, n_dot_l))
}

/// Per sphere of `shapes`, whether the precision rule may refine its hits
/// ([`Ellipsoid::may_need_refining`]); empty when `refine` is off or the
/// precision is f64 already.
fn refinable<R: Real>(shapes: &[Ellipsoid<R>], refine: bool) -> Vec<bool> {
    if !refine || !R::NARROW {
        return vec![];
    }
    shapes.iter().map(Ellipsoid::may_need_refining).collect()
}

/// Whether the material has a direct-light term at all: if not, its hits
/// need no shadow rays.
fn takes_direct_light(m: &Material) -> bool {
    m.diffuse != 0.0 || m.specular != 0.0
}

/// Whether any sphere can send light back along a secondary ray, in the
/// classic model, where such a ray that meets nothing returns black: an
/// ambient term that is not zero, or a lit light and a diffuse colour or a
/// specular term that is not. If none can, every secondary ray returns
/// exactly zero (every term of every hit is a product with a zero), and
/// adding it changes no bit of the image: such a scene is not recursed
/// into at all, however deep it asks for, and only its rays' count differs.
fn any_sphere_lit<T>(scene: &Scene, lights: &[(T, DVec3)]) -> bool {
    scene.spheres.iter().any(|sphere| {
        let m = &sphere.material;
        let ambient = m.ambient * scene.ambient * m.color;
        let direct =
            !lights.is_empty() && (m.diffuse * m.color != DVec3::ZERO || m.specular != 0.0);
        ambient != DVec3::ZERO || direct
    })
}

/// Whether to recurse into a scene no light reaches all the same: only a
/// test that checks the image does not change asks to.
fn recurse_when_dark() -> bool {
    #[cfg(test)]
    return tests::FULL_RECURSION.get();
    #[cfg(not(test))]
    false
}

/// `d` mirrored about the unit normal `n`.
fn reflect<R: Real>(d: V3<R>, n: V3<R>) -> V3<R> {
    d - n * (R::from_f64(2.0) * d.dot(n))
}

/// Snell's law for the unit direction `d` through a surface with unit normal
/// `n` facing `d`'s origin, with `ratio = n₁/n₂`; `None` on total internal reflection.
fn refract<R: Real>(d: V3<R>, n: V3<R>, ratio: R) -> Option<V3<R>> {
    let cos_i = -n.dot(d);
    let k = R::one() - ratio * ratio * (R::one() - cos_i * cos_i);
    (k >= R::zero()).then(|| (d * ratio + n * (ratio * cos_i - k.sqrt())).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3 as V;

    std::thread_local! {
        /// Set by a test to recurse into a scene no light reaches, as if
        /// it were lit, on the thread that starts the render.
        pub static FULL_RECURSION: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    }

    #[test]
    fn refraction_bends_towards_the_normal_on_entering_and_reflects_totally_past_the_critical_angle(
    ) {
        let n = V::Z;
        let d = V::new(1.0, 0.0, -1.0).normalize();
        let t = refract::<f64>(d, n, 1.0 / 1.5).unwrap();
        let sin_t = t.x / t.length();
        assert!(
            (sin_t - d.x / 1.5).abs() < 1e-12,
            "Snell: sin θt = sin θi / 1.5"
        );
        // Leaving glass at 45° (critical angle ≈ 41.8°) reflects totally.
        assert_eq!(refract::<f64>(d, n, 1.5), None);
        assert_eq!(
            refract::<f64>(-n, n, 1.5),
            Some(-n),
            "head-on passes straight"
        );
    }

    #[test]
    fn a_scene_no_light_reaches_is_not_recursed_into_and_renders_the_same() {
        use crate::render::{render_scene, RenderOptions};
        let dark = crate::scene::parse(
            "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 32 32\nBACK 0.3 0.2 0.1\n\
             SPHERE a 0 0 -4 2 2 2 1 1 1 0 0 0 1 1 1 1.5\n\
             SPHERE b 0 0 -4 1 1 1 1 1 1 0 0 0 1 1 1 1.5\n",
        )
        .unwrap();
        let render = |depth| {
            let options = RenderOptions {
                depth: Some(depth),
                ..RenderOptions::default()
            };
            render_scene(&dark, &options, &|_| {}).unwrap()
        };
        let skipped = render(12);
        assert_eq!(
            skipped.stats.rays.reflection + skipped.stats.rays.refraction,
            0
        );
        FULL_RECURSION.set(true);
        let full = render(12);
        FULL_RECURSION.set(false);
        let r = full.stats.rays;
        assert!(
            r.reflection > 2 * r.eye && r.refraction > 2 * r.eye,
            "{r:?}"
        );
        assert_eq!(skipped.image, full.image);
        assert!(render(64).stats.render_time < std::time::Duration::from_secs(5));
        // A light makes the same glass worth recursing into.
        let mut lit = dark.clone();
        lit.lights.push(crate::scene::Light {
            position: DVec3::new(0.0, 5.0, 0.0),
            intensity: DVec3::ONE,
        });
        lit.spheres[0].material.specular = 0.5;
        let options = RenderOptions {
            depth: Some(2),
            ..RenderOptions::default()
        };
        let rays = render_scene(&lit, &options, &|_| {}).unwrap().stats.rays;
        assert!(rays.reflection > 0 && rays.refraction > 0);
    }

    #[test]
    fn reflect_mirrors_about_the_normal() {
        assert_eq!(
            reflect::<f64>(V::new(1.0, -1.0, 0.0), V::Y),
            V::new(1.0, 1.0, 0.0)
        );
    }
}
