//! Every command does its parallel work, scene parsing included, on the
//! pool `--threads` sizes, never on rayon's global pool (whose size no flag
//! sets, so `--threads 1` would still put every core to work). Run in a
//! process of its own: rayon's global pool can be set up once per process,
//! and here it must still be free once the commands are done.

use std::process::ExitCode;

fn scratch(name: &str) -> String {
    let dir = std::env::temp_dir().join(format!("voxtrace-threads-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name).to_string_lossy().into_owned()
}

fn run(args: &[&str]) {
    let code = voxtrace::cli::run(std::iter::once("voxtrace").chain(args.iter().copied()));
    assert_eq!(code, ExitCode::SUCCESS, "{args:?}");
}

#[test]
fn no_command_uses_the_global_pool() {
    let root = env!("CARGO_MANIFEST_DIR");
    let scene = scratch("scene.txt");
    run(&[
        "gen",
        "--spheres",
        "20000",
        "--res",
        "32",
        "24",
        "-o",
        &scene,
    ]);
    let one = ["--threads", "1"];
    run(&[&["render", &scene, "-o", &scratch("x.png")][..], &one].concat());
    run(&[
        &["bench", "--scene", &scene, "--no-baselines", "--json"][..],
        &one,
    ]
    .concat());
    let url = "http://127.0.0.1:9/render";
    run(&[
        "load",
        "--in-process",
        "--scene",
        &scene,
        "-n",
        "2",
        "--url",
        url,
        "--json",
    ]);
    let hard = format!("{root}/scenes/hard");
    let reference = format!("{root}/tests/fixtures/reference");
    run(&[
        &[
            "report",
            "--families",
            "hard",
            "--reps",
            "1",
            "--aa-size",
            "8",
        ][..],
        &[
            "--hard",
            &hard,
            "--reference",
            &reference,
            "--out",
            &scratch("report"),
        ],
        &one,
    ]
    .concat());
    assert!(
        rayon::ThreadPoolBuilder::new().build_global().is_ok(),
        "a command started rayon's global pool"
    );
}
