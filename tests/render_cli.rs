//! `voxtrace render` end to end: output naming and formats, determinism
//! across thread counts, antialiasing.

use std::path::Path;
use std::process::Command;

fn voxtrace(dir: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

fn scene_path(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name)
        .to_str()
        .unwrap()
        .to_owned()
}

fn temp_dir(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("voxtrace-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn without_o_writes_the_scenes_output_name_as_ppm_in_the_current_directory() {
    let dir = temp_dir("naming");
    let out = voxtrace(&dir, &["render", &scene_path("testSample.txt")]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ppm = std::fs::read(dir.join("testSample.ppm")).unwrap();
    assert!(ppm.starts_with(b"P6\n600 600\n255\n"));
    assert_eq!(ppm.len(), "P6\n600 600\n255\n".len() + 600 * 600 * 3);

    // No OUTPUT line: the scene file's stem.
    let text = std::fs::read_to_string(scene_path("testSample.txt"))
        .unwrap()
        .replace("OUTPUT testSample.ppm", "");
    std::fs::write(dir.join("unnamed.txt"), text).unwrap();
    assert!(voxtrace(&dir, &["render", "unnamed.txt"]).status.success());
    let unnamed = std::fs::read(dir.join("unnamed.ppm")).unwrap();
    assert_eq!(unnamed, ppm, "same scene, same bytes");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn png_to_a_file_and_to_stdout_decode_to_the_same_pixels_as_the_ppm() {
    let dir = temp_dir("formats");
    let scene = scene_path("testShadow.txt");
    assert!(voxtrace(&dir, &["render", &scene, "-o", "a.PNG"])
        .status
        .success());
    assert!(voxtrace(&dir, &["render", &scene, "-o", "a.ppm"])
        .status
        .success());
    let stdout = voxtrace(&dir, &["render", &scene, "-o", "-"]);
    assert!(stdout.status.success());
    let file_png = std::fs::read(dir.join("a.PNG")).unwrap();
    assert_eq!(stdout.stdout, file_png);
    let decoded = image::load_from_memory(&file_png).unwrap().to_rgb8();
    let ppm = image::open(dir.join("a.ppm")).unwrap().to_rgb8();
    assert_eq!(decoded, ppm);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn same_bytes_whatever_the_thread_count() {
    let dir = temp_dir("threads");
    let scene = scene_path("refraction.txt");
    for threads in ["1", "2", "3"] {
        let out = voxtrace(
            &dir,
            &[
                "render",
                &scene,
                "--spp",
                "2",
                "--depth",
                "5",
                "--threads",
                threads,
                "-o",
                &format!("t{threads}.ppm"),
            ],
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let one = std::fs::read(dir.join("t1.ppm")).unwrap();
    assert_eq!(one, std::fs::read(dir.join("t2.ppm")).unwrap());
    assert_eq!(one, std::fs::read(dir.join("t3.ppm")).unwrap());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn stats_count_rays_by_kind() {
    let dir = temp_dir("stats");
    let out = voxtrace(
        &dir,
        &[
            "render",
            &scene_path("testReflection.txt"),
            "--stats",
            "-o",
            "r.png",
        ],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success());
    for word in [
        "parse",
        "build",
        "render",
        "eye 360000",
        "shadow",
        "reflection",
        "refraction 0",
        "Mrays/s",
    ] {
        assert!(stderr.contains(word), "{word} missing from:\n{stderr}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// With several samples the silhouette of a sphere gets intermediate levels
/// that the single corner sample cannot produce.
#[test]
fn more_samples_antialias_edges() {
    use voxtrace::render::{render_scene, RenderOptions};
    let scene =
        voxtrace::scene::parse(std::fs::read(scene_path("testAmbient.txt")).unwrap()).unwrap();
    let levels = |spp| {
        let options = RenderOptions {
            spp,
            ..RenderOptions::default()
        };
        let image = render_scene(&scene, &options, &|_| {}).unwrap().image;
        let mut seen: Vec<[u8; 3]> = image.rgb.chunks(3).map(|p| [p[0], p[1], p[2]]).collect();
        seen.sort();
        seen.dedup();
        seen.len()
    };
    // Ambient-only flat discs on white: one colour per sphere plus the background.
    assert_eq!(levels(1), 4);
    assert!(levels(16) > 20, "edges blend");
}
