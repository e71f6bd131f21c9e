//! `voxtrace gen`, `render --index` and `bench` end to end.

use std::path::PathBuf;
use std::process::Command;

fn voxtrace(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .args(args)
        .output()
        .unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxtrace-cli-tools-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn generated_scene_renders_the_same_with_either_index() {
    let scene = scratch("mixed.txt");
    let s = scene.to_str().unwrap();
    let out = voxtrace(&[
        "gen",
        "--spheres",
        "3000",
        "--dist",
        "mixed",
        "--seed",
        "5",
        "--res",
        "80",
        "60",
        "--ellipsoids",
        "0.3",
        "--glass",
        "0.2",
        "-o",
        s,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (grid, brute) = (scratch("grid.ppm"), scratch("brute.ppm"));
    for (index, image) in [("grid", &grid), ("brute", &brute)] {
        let out = voxtrace(&["render", s, "--index", index, "-o", image.to_str().unwrap()]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let (a, b) = (
        std::fs::read(&grid).unwrap(),
        std::fs::read(&brute).unwrap(),
    );
    assert!(a.starts_with(b"P6\n80 60\n255\n"));
    assert!(a == b, "grid and brute force images differ");

    let out = voxtrace(&["bench", "--scene", s, "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let results: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let first = &results[0];
    assert_eq!(first["spheres"], 3000);
    for field in [
        "parse_s",
        "build_s",
        "index_bytes_per_sphere",
        "primary_mrays_s",
        "shadow_mrays_s",
        "shadow_walk_mrays_s",
        "light_buffer_bytes_per_sphere",
        "speedup_vs_brute",
    ] {
        assert!(first[field].as_f64().is_some_and(|v| v > 0.0), "{field}");
    }
    assert!(first["light_buffers"].as_u64().is_some_and(|n| n > 0));
}

#[test]
fn bad_arguments_exit_with_code_2() {
    let out = scratch("never.txt");
    let o = out.to_str().unwrap();
    for args in [
        vec!["gen", "--spheres", "10", "--glass", "1.5", "-o", o],
        vec!["gen", "--spheres", "10", "--dist", "spiral", "-o", o],
        vec!["gen", "--spheres", "10", "--res", "0", "10", "-o", o],
        vec!["render", o, "--index", "octree"],
    ] {
        assert_eq!(voxtrace(&args).status.code(), Some(2), "{args:?}");
    }
    let bad_scene = scratch("bad.txt");
    std::fs::write(&bad_scene, "NEAR one\n").unwrap();
    let out = voxtrace(&["bench", "--scene", bad_scene.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("line 1, column 6"));
}

/// `--threads` means the same in every command: a count of at least one,
/// all cores when left out; zero is a usage error, refused before any work
/// with the same message, and each command's help says so.
#[test]
fn every_command_refuses_zero_threads_alike() {
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/testSample.txt");
    let never = scratch("zero-threads.png");
    let n = never.to_str().unwrap();
    for command in [
        vec!["render", scene, "-o", n],
        vec!["serve", "--addr", "127.0.0.1:0"],
        vec!["bench", "--scene", scene],
        vec!["report", "--out", n],
    ] {
        let mut args = command.clone();
        args.extend(["--threads", "0"]);
        let out = voxtrace(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains(
                "invalid value '0' for '--threads <THREADS>': the thread count must be at least 1"
            ),
            "{args:?}: {stderr}"
        );
        assert!(!never.exists(), "{args:?} did work");
        let help = voxtrace(&[command[0], "--help"]);
        let help = String::from_utf8_lossy(&help.stdout);
        assert!(
            help.contains("at least 1 (default: all cores)"),
            "{}: {help}",
            command[0]
        );
    }
}

/// `load` and `serve` exit with 2 when their arguments are at fault and
/// with 1 when the machine is, each with its reason.
#[test]
fn load_and_serve_exit_codes_say_whose_fault_it_is() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let taken = taken.local_addr().unwrap().to_string();
    let missing = scratch("no-such-scene.txt");
    let missing = missing.to_str().unwrap();
    for (args, code, says) in [
        (
            vec!["load", "--url", "https://x/"],
            2,
            "only http:// URLs are supported",
        ),
        (vec!["load", "--duration", "5y"], 2, "the unit must be ms"),
        (
            vec!["load", "--concurrency", "0"],
            2,
            "--concurrency must be at least 1",
        ),
        (
            vec!["load", "--in-process", "-n", "1"],
            2,
            "--in-process needs --scene",
        ),
        (vec!["load", "--scene", missing], 1, "cannot read"),
        (
            vec!["serve", "--max-connections", "0"],
            2,
            "--max-connections must be at least 1",
        ),
        (
            vec!["serve", "--addr", "nowhere"],
            2,
            "cannot resolve nowhere",
        ),
        (vec!["serve", "--addr", &taken], 1, "cannot listen on"),
    ] {
        let out = voxtrace(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
}
