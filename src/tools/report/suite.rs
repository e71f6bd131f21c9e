//! The scenes the report renders: the course's reference scenes, the hard
//! cases, and a few generated scenes with mirrors and glass.

use crate::scene::{self, Camera, Dialect, Light, Material, Scene, Sphere};
use glam::DVec3;
use std::fmt;
use std::path::{Path, PathBuf};

/// Scenes are grouped by where they come from; each family gets its own plot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Family {
    /// The course's scenes, both dialects (`tests/fixtures/reference`).
    Reference,
    /// `scenes/hard`: the numerical traps.
    Hard,
    /// Built here, deterministically: reflection and glass at depth.
    Generated,
}

impl Family {
    /// How the report's headings and plots call it (its name is in
    /// [`crate::names`]).
    pub fn title(self) -> &'static str {
        match self {
            Family::Reference => "reference",
            Family::Hard => "hard cases",
            Family::Generated => "generated",
        }
    }
}

pub struct SuiteScene {
    pub name: String,
    pub family: Family,
    pub scene: Scene,
}

/// Why the suite could not be loaded.
#[derive(Debug)]
pub enum SuiteError {
    Read {
        path: PathBuf,
        error: std::io::Error,
    },
    Parse {
        path: PathBuf,
        error: scene::SceneError,
    },
}

impl fmt::Display for SuiteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SuiteError::Read { path, error } => {
                write!(f, "cannot read {}: {error}", path.display())
            }
            SuiteError::Parse { path, error } => write!(f, "{}: {error}", path.display()),
        }
    }
}

/// The scene files of `dir`, sorted by name.
fn scene_files(dir: &Path) -> Result<Vec<PathBuf>, SuiteError> {
    let read = |error| SuiteError::Read {
        path: dir.to_owned(),
        error,
    };
    let mut paths = vec![];
    for entry in std::fs::read_dir(dir).map_err(read)? {
        let path = entry.map_err(read)?.path();
        if path.extension().is_some_and(|e| e == "txt") {
            paths.push(path);
        }
    }
    paths.sort();
    Ok(paths)
}

pub fn load_scene(path: &Path) -> Result<Scene, SuiteError> {
    let text = std::fs::read(path).map_err(|error| SuiteError::Read {
        path: path.to_owned(),
        error,
    })?;
    scene::parse(&text).map_err(|error| SuiteError::Parse {
        path: path.to_owned(),
        error,
    })
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Hard cases that only mean something from a moved eye (the renderer's eye
/// is the origin): they are measured by [`super::invariance`] instead.
pub fn is_moved_eye_case(name: &str) -> bool {
    name.starts_with("translated_")
}

/// Every scene of the chosen families, in a fixed order.
pub fn load(
    reference: &Path,
    hard: &Path,
    families: &[Family],
) -> Result<Vec<SuiteScene>, SuiteError> {
    let mut suite = vec![];
    if families.contains(&Family::Reference) {
        load_reference(reference, &mut suite)?;
    }
    if families.contains(&Family::Hard) {
        load_hard(hard, &mut suite)?;
    }
    if families.contains(&Family::Generated) {
        suite.extend(generated());
    }
    Ok(suite)
}

fn load_reference(reference: &Path, suite: &mut Vec<SuiteScene>) -> Result<(), SuiteError> {
    for dialect in ["classic", "tinygraphics"] {
        for path in scene_files(&reference.join(dialect).join("scenes"))? {
            suite.push(SuiteScene {
                name: format!("{dialect}/{}", stem(&path)),
                family: Family::Reference,
                scene: load_scene(&path)?,
            });
        }
    }
    Ok(())
}

fn load_hard(hard: &Path, suite: &mut Vec<SuiteScene>) -> Result<(), SuiteError> {
    for path in scene_files(hard)? {
        let name = stem(&path);
        if !is_moved_eye_case(&name) {
            suite.push(SuiteScene {
                name: format!("hard/{name}"),
                family: Family::Hard,
                scene: load_scene(&path)?,
            });
        }
    }
    Ok(())
}

fn material(color: DVec3, reflect: f64, refract: f64, ior: f64) -> Material {
    Material {
        color,
        ambient: 0.15,
        diffuse: if refract > 0.0 { 0.05 } else { 0.7 },
        specular: 0.5,
        reflect,
        shininess: 40.0,
        refract,
        ior,
    }
}

fn sphere(center: DVec3, radius: f64, material: Material) -> Sphere {
    Sphere {
        center,
        scale: DVec3::splat(radius),
        material,
    }
}

fn classic(width: u32, height: u32, spheres: Vec<Sphere>, lights: Vec<Light>) -> Scene {
    let aspect = f64::from(width) / f64::from(height);
    Scene {
        dialect: Dialect::Classic,
        camera: Camera {
            near: 1.0,
            left: -0.5 * aspect,
            right: 0.5 * aspect,
            bottom: -0.5,
            top: 0.5,
            width,
            height,
        },
        spheres,
        lights,
        background: DVec3::new(0.1, 0.12, 0.18),
        ambient: DVec3::splat(0.3),
        output: None,
    }
}

/// A small deterministic colour sequence (golden-ratio hues), so the
/// generated scenes need no random numbers.
fn palette(i: usize) -> DVec3 {
    let h = (i as f64 * 0.618_033_988_75).fract() * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    DVec3::new(r, g, b) * 0.75 + DVec3::splat(0.2)
}

/// The generated scenes: small enough for a two-core machine, deep enough
/// that recursion and glass matter; each stands on the classic ground, a
/// sphere of radius 1000, and the last two put balls of radius 0.1 on it.
pub fn generated() -> Vec<SuiteScene> {
    let light = |x, y, z, i| Light {
        position: DVec3::new(x, y, z),
        intensity: DVec3::splat(i),
    };
    let ground = || {
        sphere(
            DVec3::new(0.0, -1001.0, -8.0),
            1000.0,
            material(DVec3::splat(0.6), 0.25, 0.0, 1.0),
        )
    };

    // A 5×4 grid of balls on a reflective floor: every third a mirror.
    let mut mirror_grid = vec![ground()];
    for row in 0..4 {
        for col in 0..5 {
            let i = row * 5 + col;
            let reflect = [0.85, 0.3, 0.0][i % 3];
            let center = DVec3::new(-2.4 + 1.2 * col as f64, -0.5, -5.0 - 1.3 * row as f64);
            mirror_grid.push(sphere(center, 0.5, material(palette(i), reflect, 0.0, 1.0)));
        }
    }

    // Glass balls (two refractive indices) before a wall of coloured balls.
    let mut glass = vec![ground()];
    for i in 0..24 {
        let center = DVec3::new(
            -3.3 + 0.6 * (i % 12) as f64,
            0.2 + 0.9 * (i / 12) as f64,
            -9.0,
        );
        glass.push(sphere(center, 0.32, material(palette(i), 0.0, 0.0, 1.0)));
    }
    for (i, x) in [-1.4, 0.0, 1.4].into_iter().enumerate() {
        let ior = [1.0 / 1.5, 1.0 / 1.33, 1.0 / 1.9][i];
        glass.push(sphere(
            DVec3::new(x, -0.35, -5.0),
            0.65,
            material(DVec3::ONE, 0.1, 0.9, ior),
        ));
    }

    // Two facing, slightly tinted mirrors with balls between them: long
    // chains of reflections that fade by 0.9 per bounce.
    let mut hall = vec![
        sphere(
            DVec3::new(-2.5, 0.0, -6.0),
            1.0,
            material(DVec3::splat(0.8), 0.9, 0.0, 1.0),
        ),
        sphere(
            DVec3::new(2.5, 0.0, -6.0),
            1.0,
            material(DVec3::splat(0.8), 0.9, 0.0, 1.0),
        ),
    ];
    for s in &mut hall {
        s.scale = DVec3::new(0.05, 3.0, 4.0);
    }
    for i in 0..6 {
        let center = DVec3::new(
            -1.2 + 0.5 * i as f64,
            -0.6 + 0.25 * (i % 3) as f64,
            -5.0 - 0.6 * i as f64,
        );
        hall.push(sphere(center, 0.3, material(palette(i + 7), 0.2, 0.0, 1.0)));
    }
    hall.push(ground());

    // Balls of radius 0.1 resting on the ground, every third a mirror: the
    // ground's reach (2000) dwarfs its points (1–10), so plain f32 hit
    // points there are off by ~1e-4, 0.1% of a ball.
    let mut small_balls = vec![ground()];
    for i in 0..25 {
        let (col, row) = ((i % 5) as f64, (i / 5) as f64);
        let center = DVec3::new(-1.0 + 0.5 * col + 0.1 * row, -0.9, -3.0 - 0.7 * row);
        let reflect = [0.8, 0.0, 0.3][i % 3];
        small_balls.push(sphere(center, 0.1, material(palette(i), reflect, 0.0, 1.0)));
    }

    // Glass over the same ground, small coloured balls behind and under it.
    let mut glass_floor = vec![ground()];
    for (i, x) in [-0.8, 0.0, 0.8].into_iter().enumerate() {
        let ior = [1.0 / 1.5, 1.0 / 1.33, 1.0 / 1.9][i];
        glass_floor.push(sphere(
            DVec3::new(x, -0.7, -4.0),
            0.3,
            material(DVec3::ONE, 0.1, 0.9, ior),
        ));
    }
    for i in 0..12 {
        let center = DVec3::new(-1.1 + 0.2 * i as f64, -0.9, -5.0 - 0.15 * (i % 3) as f64);
        glass_floor.push(sphere(center, 0.1, material(palette(i + 3), 0.0, 0.0, 1.0)));
    }

    vec![
        SuiteScene {
            name: "gen/mirror_grid".into(),
            family: Family::Generated,
            scene: classic(
                240,
                160,
                mirror_grid,
                vec![light(-4.0, 6.0, 0.0, 0.7), light(5.0, 3.0, -2.0, 0.5)],
            ),
        },
        SuiteScene {
            name: "gen/glass_balls".into(),
            family: Family::Generated,
            scene: classic(240, 160, glass, vec![light(2.0, 5.0, 1.0, 0.9)]),
        },
        SuiteScene {
            name: "gen/hall_of_mirrors".into(),
            family: Family::Generated,
            scene: classic(
                200,
                160,
                hall,
                vec![light(0.0, 4.0, -3.0, 0.8), light(0.0, 0.0, 0.0, 0.3)],
            ),
        },
        SuiteScene {
            name: "gen/huge_floor".into(),
            family: Family::Generated,
            scene: classic(
                240,
                160,
                small_balls,
                vec![light(-3.0, 4.0, 0.0, 0.7), light(4.0, 2.0, -3.0, 0.5)],
            ),
        },
        SuiteScene {
            name: "gen/glass_on_huge_floor".into(),
            family: Family::Generated,
            scene: classic(240, 160, glass_floor, vec![light(1.5, 4.0, 0.0, 0.9)]),
        },
    ]
}
