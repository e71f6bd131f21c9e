//! The course's reference images: every key must be reproduced with at least
//! 99.9% of pixels within one level in every channel (tests/fixtures/reference/README.md).

use std::path::{Path, PathBuf};
use voxtrace::render::{render_scene, RenderOptions};
use voxtrace::scene;

fn reference_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/reference")
}

fn render(path: &Path) -> voxtrace::output::Image {
    let text = std::fs::read(path).unwrap();
    let scene = scene::parse(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    render_scene(&scene, &RenderOptions::default(), &|_| {})
        .unwrap()
        .image
}

#[test]
fn classic_keys_match_within_one_level() {
    let keys = reference_dir().join("classic/keys");
    let mut checked = 0;
    for entry in std::fs::read_dir(&keys).expect("tests/fixtures/reference/classic/keys") {
        let key_path = entry.unwrap().path();
        let name = key_path.file_stem().unwrap().to_str().unwrap().to_owned();
        let key = image::open(&key_path).unwrap().to_rgb8();
        let ours = render(&reference_dir().join(format!("classic/scenes/{name}.txt")));
        assert_eq!((ours.width, ours.height), key.dimensions(), "{name}");
        let total = (ours.width * ours.height) as usize;
        let (mut exact, mut within_one, mut worst) = (0, 0, 0);
        for (a, b) in ours.rgb.chunks(3).zip(key.as_raw().chunks(3)) {
            let d = a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
            exact += usize::from(d == 0);
            within_one += usize::from(d <= 1);
            worst = worst.max(d);
        }
        println!(
            "{name}: {exact}/{total} exact, {within_one}/{total} within 1 level, worst {worst}"
        );
        assert!(
            within_one * 1000 >= total * 999,
            "{name}: only {within_one}/{total} within 1 level"
        );
        checked += 1;
    }
    assert_eq!(checked, 7, "all seven keys");
}

#[test]
fn every_reference_scene_renders() {
    for dialect in ["classic", "tinygraphics"] {
        for entry in std::fs::read_dir(reference_dir().join(dialect).join("scenes")).unwrap() {
            let path = entry.unwrap().path();
            let image = render(&path);
            assert!(image.width > 0 && image.height > 0, "{}", path.display());
        }
    }
}
