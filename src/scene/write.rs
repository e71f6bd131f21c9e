//! Writes scenes in the classic dialect, the form `voxtrace gen` streams out.

use super::{Light, Scene, Sphere};
use std::io::{self, Write};

/// Writes a SPHERE line; the refraction pair only when the sphere refracts.
pub fn write_sphere(out: &mut impl Write, name: &str, s: &Sphere) -> io::Result<()> {
    let (c, k, m) = (s.center, s.scale, &s.material);
    write!(
        out,
        "SPHERE {name} {} {} {} {} {} {} {} {} {} {} {} {} {} {}",
        c.x,
        c.y,
        c.z,
        k.x,
        k.y,
        k.z,
        m.color.x,
        m.color.y,
        m.color.z,
        m.ambient,
        m.diffuse,
        m.specular,
        m.reflect,
        m.shininess
    )?;
    if m.refract > 0.0 {
        write!(out, " {} {}", m.refract, m.ior)?;
    }
    writeln!(out)
}

pub fn write_light(out: &mut impl Write, name: &str, l: &Light) -> io::Result<()> {
    let (p, i) = (l.position, l.intensity);
    writeln!(
        out,
        "LIGHT {name} {} {} {} {} {} {}",
        p.x, p.y, p.z, i.x, i.y, i.z
    )
}

/// Writes the whole scene in the classic dialect (names `s0…`, `l0…`).
pub fn write_scene(out: &mut impl Write, scene: &Scene) -> io::Result<()> {
    let c = &scene.camera;
    writeln!(
        out,
        "NEAR {}\nLEFT {}\nRIGHT {}\nBOTTOM {}\nTOP {}",
        c.near, c.left, c.right, c.bottom, c.top
    )?;
    writeln!(out, "RES {} {}", c.width, c.height)?;
    for (i, s) in scene.spheres.iter().enumerate() {
        write_sphere(out, &format!("s{i}"), s)?;
    }
    for (i, l) in scene.lights.iter().enumerate() {
        write_light(out, &format!("l{i}"), l)?;
    }
    let (b, a) = (scene.background, scene.ambient);
    writeln!(
        out,
        "BACK {} {} {}\nAMBIENT {} {} {}",
        b.x, b.y, b.z, a.x, a.y, a.z
    )?;
    if let Some(name) = &scene.output {
        writeln!(out, "OUTPUT {name}")?;
    }
    Ok(())
}
