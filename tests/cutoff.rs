//! The adaptive cut-off: a ray whose weight is below 1/512 of full scale is
//! not traced. It must leave every reference scene byte-identical, and it
//! must actually cut where weights fall.

use std::path::{Path, PathBuf};
use voxtrace::render::{render_scene, RenderOptions};
use voxtrace::scene::{self, Scene};

fn reference_scenes() -> Vec<(PathBuf, Scene)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/reference");
    let mut scenes = vec![];
    for dialect in ["classic", "tinygraphics"] {
        for entry in std::fs::read_dir(root.join(dialect).join("scenes")).unwrap() {
            let path = entry.unwrap().path();
            let scene = scene::parse(std::fs::read(&path).unwrap()).unwrap();
            scenes.push((path, scene));
        }
    }
    assert_eq!(scenes.len(), 23);
    scenes
}

fn options(depth: Option<u32>, adaptive_cutoff: bool) -> RenderOptions {
    RenderOptions {
        depth,
        adaptive_cutoff,
        ..RenderOptions::default()
    }
}

#[test]
fn cutoff_leaves_every_reference_scene_byte_identical() {
    for (path, scene) in reference_scenes() {
        for depth in [None, Some(16)] {
            let full = render_scene(&scene, &options(depth, false), &|_| {}).unwrap();
            let cut = render_scene(&scene, &options(depth, true), &|_| {}).unwrap();
            assert_eq!(cut.image, full.image, "{} depth {depth:?}", path.display());
            assert!(cut.stats.rays.total() <= full.stats.rays.total());
        }
    }
}

/// Glass at depth 16: long chains of refraction and total internal
/// reflection whose weights fall far below a level.
#[test]
fn cutoff_saves_most_rays_on_deep_glass_and_moves_at_most_one_level() {
    let glass = voxtrace::tools::report::suite::generated()
        .into_iter()
        .find(|s| s.name == "gen/glass_balls")
        .unwrap()
        .scene;
    let full = render_scene(&glass, &options(Some(16), false), &|_| {}).unwrap();
    let cut = render_scene(&glass, &options(Some(16), true), &|_| {}).unwrap();
    let (f, c) = (full.stats.rays, cut.stats.rays);
    assert_eq!(c.eye, f.eye);
    assert!(c.total() * 4 < f.total(), "{c:?} against {f:?}");
    assert!(c.refraction * 4 < f.refraction && c.reflection * 4 < f.reflection);
    let worst = full
        .image
        .rgb
        .iter()
        .zip(&cut.image.rgb)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(worst <= 1, "off by {worst} levels");
}
