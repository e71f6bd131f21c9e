//! Whole images are byte-identical with the grid and with brute force: every
//! reference scene, and generated scenes with ellipsoids and glass.

use std::path::Path;
use voxtrace::render::{render_scene, IndexKind, RenderOptions};
use voxtrace::scene::{self, Scene};
use voxtrace::tools::gen::{generate, Distribution, GenOptions};

fn image(scene: &Scene, index: IndexKind) -> Vec<u8> {
    let options = RenderOptions {
        index,
        ..RenderOptions::default()
    };
    render_scene(scene, &options, &|_| {}).unwrap().image.rgb
}

fn assert_identical(name: &str, scene: &Scene) {
    let grid = image(scene, IndexKind::Grid);
    assert!(
        grid == image(scene, IndexKind::Brute),
        "{name}: grid and brute force differ"
    );
}

#[test]
fn the_grid_is_the_default() {
    assert_eq!(IndexKind::default(), IndexKind::Grid);
}

#[test]
fn every_reference_scene_is_byte_identical() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/reference");
    let mut checked = 0;
    for dialect in ["classic", "tinygraphics"] {
        for entry in std::fs::read_dir(root.join(dialect).join("scenes")).unwrap() {
            let path = entry.unwrap().path();
            let scene = scene::parse(std::fs::read(&path).unwrap()).unwrap();
            assert_identical(&path.display().to_string(), &scene);
            checked += 1;
        }
    }
    assert!(checked >= 7);
}

#[test]
fn generated_scenes_are_byte_identical() {
    for (i, distribution) in [
        Distribution::Uniform,
        Distribution::Mixed,
        Distribution::Clustered,
    ]
    .into_iter()
    .enumerate()
    {
        let options = GenOptions {
            spheres: 1500,
            distribution,
            seed: 10 + i as u64,
            width: 96,
            height: 96,
            ellipsoids: 0.3,
            glass: 0.2,
        };
        let mut text = Vec::new();
        generate(&options, &mut text).unwrap();
        let scene = scene::parse(&text).unwrap();
        assert_identical(distribution.name(), &scene);
    }
}
