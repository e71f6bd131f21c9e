//! A second, plain renderer of the classic dialect, written from the rules
//! of `docs/scene-format.md` and `render::Rules` alone: f64, every sphere
//! tested with the textbook quadratic, fixed epsilons, no index, no packets,
//! no error bounds. It is slow and fragile at extreme scales, and on the
//! course's scenes it is an oracle that shares no code with the renderer but
//! the parser: what both draw is what the rules say.

use glam::DVec3;
use voxtrace::scene::{Scene, Sphere};

/// Bounces of reflection, as the classic dialect's default.
const DEPTH: u32 = 3;
/// Hits nearer than this along a unit direction are the surface the ray left.
const SELF_HIT: f64 = 1e-7;

/// The image, 8-bit RGB top row first, under the default rules or (`ucla`)
/// the older keys' rules: outward normals on inside hits, reflected rays
/// cut at t = 1.
pub fn render(scene: &Scene, ucla: bool) -> Vec<u8> {
    let c = &scene.camera;
    let mut rgb = Vec::with_capacity((c.width * c.height * 3) as usize);
    for row in 0..c.height {
        for column in 0..c.width {
            let dir = DVec3::new(
                c.left + f64::from(column) / f64::from(c.width) * (c.right - c.left),
                c.top - f64::from(row) / f64::from(c.height) * (c.top - c.bottom),
                -c.near,
            );
            let colour = trace(scene, DVec3::ZERO, dir, 1.0, 0, ucla).unwrap_or(scene.background);
            rgb.extend(
                colour
                    .to_array()
                    .map(|v| (255.0 * v.clamp(0.0, 1.0)).floor() as u8),
            );
        }
    }
    rgb
}

/// The colour along `o + t·d`, t > `t_min`; `None` when it meets nothing.
fn trace(scene: &Scene, o: DVec3, d: DVec3, t_min: f64, depth: u32, ucla: bool) -> Option<DVec3> {
    let (k, t) = nearest(scene, o, d, t_min, f64::INFINITY)?;
    let sphere = &scene.spheres[k];
    let m = &sphere.material;
    let p = o + d * t;
    let outward = ((p - sphere.center) / (sphere.scale * sphere.scale)).normalize();
    let inside = outward.dot(d) > 0.0;
    let n = if inside && !ucla { -outward } else { outward };
    let view = -d.normalize();
    let mut colour = m.ambient * scene.ambient * m.color;
    for light in &scene.lights {
        let to_light = light.position - p;
        let l = to_light.normalize();
        let n_dot_l = n.dot(l);
        let cut = SELF_HIT / to_light.length();
        if n_dot_l <= 0.0 || nearest(scene, p, to_light, cut, 1.0).is_some() {
            continue;
        }
        let r = n * (2.0 * n_dot_l) - l;
        let spec = r.dot(view).max(0.0).powf(m.shininess);
        colour +=
            light.intensity * (m.diffuse * n_dot_l * m.color + DVec3::splat(m.specular * spec));
    }
    if m.reflect > 0.0 && depth < DEPTH {
        let unit = d.normalize();
        let mirrored = unit - n * (2.0 * unit.dot(n));
        let cut = if ucla { 1.0 } else { SELF_HIT };
        let seen = trace(scene, p, mirrored, cut, depth + 1, ucla).unwrap_or(DVec3::ZERO);
        colour += m.reflect * seen;
    }
    Some(colour)
}

/// The nearest sphere and t in (t_min, t_max) along `o + t·d`.
fn nearest(scene: &Scene, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<(usize, f64)> {
    scene
        .spheres
        .iter()
        .enumerate()
        .filter_map(|(k, s)| hit(s, o, d, t_min, t_max).map(|t| (k, t)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// The first root in (t_min, t_max) of the ray against the ellipsoid.
fn hit(s: &Sphere, o: DVec3, d: DVec3, t_min: f64, t_max: f64) -> Option<f64> {
    let f = (o - s.center) / s.scale;
    let e = d / s.scale;
    let (a, b, c) = (e.dot(e), f.dot(e), f.dot(f) - 1.0);
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    [(-b - root) / a, (-b + root) / a]
        .into_iter()
        .find(|&t| t > t_min && t < t_max)
}
