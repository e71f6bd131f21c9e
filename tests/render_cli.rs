//! `voxtrace render` end to end: output naming and formats, standard input,
//! the summary line, `--size`, the `--threads` warning, determinism across
//! thread counts, antialiasing; shell completions and the help's examples.

mod support;

use std::path::Path;
use std::process::Command;
use support::cli::{stderr, voxtrace_in};

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
        "with a light buffer",
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

#[test]
fn an_output_name_of_no_known_format_is_refused_before_any_work() {
    let dir = temp_dir("extension");
    let scene = scene_path("testShadow.txt");
    for (output, scene) in [
        ("x.jpg", scene.as_str()),
        ("x", scene.as_str()),
        ("x.jpg", "/nonexistent/scene.txt"),
    ] {
        let out = voxtrace(&dir, &["render", scene, "-o", output]);
        assert_eq!(out.status.code(), Some(2), "{output}");
        assert_eq!(
            String::from_utf8_lossy(&out.stderr),
            format!("voxtrace: {output}: cannot tell the image format from the name; voxtrace writes .png and .ppm (or PNG to standard output with -o -)\n")
        );
        assert!(!dir.join(output).exists());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_scene_from_standard_input_renders_the_bytes_of_the_file() {
    let dir = temp_dir("stdin");
    let scene = scene_path("testShadow.txt");
    let text = std::fs::read(&scene).unwrap();
    let from_file = voxtrace(&dir, &["render", &scene, "-o", "file.png"]);
    assert!(from_file.status.success());
    let piped = voxtrace_in(&dir, &["render", "-", "-o", "-"], Some(&text));
    assert!(piped.status.success(), "{}", stderr(&piped));
    assert_eq!(piped.stdout, std::fs::read(dir.join("file.png")).unwrap());
    // Without -o: the scene's OUTPUT name, or render.ppm when it has none.
    let unnamed = String::from_utf8(text.clone())
        .unwrap()
        .replace("OUTPUT", "# OUTPUT");
    let out = voxtrace_in(&dir, &["render", "-"], Some(unnamed.as_bytes()));
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(std::fs::read(dir.join("render.ppm"))
        .unwrap()
        .starts_with(b"P6\n"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_render_ends_with_one_summary_line_unless_quiet() {
    let dir = temp_dir("summary");
    let scene = scene_path("testShadow.txt");
    let out = voxtrace(&dir, &["render", &scene, "-o", "a.png", "--stats"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let summary = stderr.lines().last().unwrap();
    let (head, rest) = summary.split_once(", 1 spp, ").unwrap();
    assert_eq!(head, "rendered a.png: 600×600", "{stderr}");
    let (time, rays) = rest.split_once(", ").unwrap();
    let (value, unit) = time.split_once(' ').unwrap();
    assert!(
        value.parse::<f64>().is_ok() && ["ms", "s"].contains(&unit),
        "{time}"
    );
    // The count --stats prints in full, with a metric prefix.
    let total: f64 = stderr
        .split("total ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(rays, format!("{:.1} k rays", total / 1e3), "{stderr}");

    for quiet in ["--quiet", "-q"] {
        let out = voxtrace(&dir, &["render", &scene, "-o", "b.png", quiet]);
        assert!(out.status.success());
        assert_eq!(String::from_utf8_lossy(&out.stderr), "", "{quiet}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--size` keeps the camera's window: a preview at a quarter of RES samples
/// the very points of every fourth pixel of the full image.
#[test]
fn size_overrides_res_and_keeps_the_field_of_view() {
    let dir = temp_dir("size");
    let scene = scene_path("testShadow.txt");
    let render = |size: &str, name: &str| {
        let out = voxtrace(&dir, &["render", &scene, "--size", size, "-o", name, "-q"]);
        assert!(out.status.success(), "{}", stderr(&out));
        image::open(dir.join(name)).unwrap().to_rgb8()
    };
    let wide = render("64x48", "wide.ppm");
    assert_eq!(wide.dimensions(), (64, 48));
    let full = render("600x600", "full.png");
    let preview = render("150", "preview.png");
    assert_eq!(preview.dimensions(), (150, 150), "RES's aspect kept");
    for (x, y, pixel) in preview.enumerate_pixels() {
        assert_eq!(pixel, full.get_pixel(4 * x, 4 * y), "({x}, {y})");
    }
    let out = voxtrace(&dir, &["render", &scene, "--size", "0x10"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("the number of columns must be between 1 and 16384, found 0"),
        "{}",
        stderr(&out)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn threads_beyond_the_cores_are_warned_about() {
    let dir = temp_dir("cores");
    let scene = scene_path("testAmbient.txt");
    let cores = std::thread::available_parallelism().unwrap().get();
    let run = |threads: usize| {
        let threads = threads.to_string();
        let out = voxtrace(
            &dir,
            &["render", &scene, "--threads", &threads, "-q", "-o", "a.png"],
        );
        assert!(out.status.success());
        stderr(&out)
    };
    assert_eq!(
        run(cores + 1),
        format!("voxtrace: warning: --threads {} is more than the {cores} cores here; the extra threads take turns on them and only add overhead (leave --threads out for one per core)\n", cores + 1)
    );
    assert_eq!(run(cores), "");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn completions_are_a_script_the_shell_parses() {
    let dir = temp_dir("completions");
    let out = voxtrace(&dir, &["completions", "bash"]);
    assert!(out.status.success());
    let script = dir.join("voxtrace.bash");
    std::fs::write(&script, &out.stdout).unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    for word in ["render", "--size", "--quiet", "completions"] {
        assert!(text.contains(word), "{word}");
    }
    let checked = Command::new("bash")
        .arg("-n")
        .arg(&script)
        .output()
        .unwrap();
    assert!(checked.status.success(), "{}", stderr(&checked));
    for shell in ["zsh", "fish", "elvish", "powershell"] {
        let out = voxtrace(&dir, &["completions", shell]);
        assert!(out.status.success() && !out.stdout.is_empty(), "{shell}");
    }
    assert_eq!(
        voxtrace(&dir, &["completions", "tcsh"]).status.code(),
        Some(2)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn every_command_s_help_ends_with_examples() {
    let dir = temp_dir("help");
    for command in [
        "render",
        "serve",
        "load",
        "gen",
        "bench",
        "report",
        "completions",
    ] {
        let out = voxtrace(&dir, &[command, "--help"]);
        assert!(out.status.success());
        let help = String::from_utf8_lossy(&out.stdout);
        let examples = help
            .split("Examples:\n")
            .nth(1)
            .unwrap_or_else(|| panic!("{command}: {help}"));
        assert!(
            examples.contains(&format!("  voxtrace {command}")),
            "{command}: {examples}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
