//! `deploy/cluster.sh`: three workers behind nginx. A tiled remote render
//! through it is byte for byte the local render, also when a worker is
//! killed (SIGKILL) or told to stop (SIGTERM) in the middle of it, and
//! `down` leaves no process behind.
//!
//! These need nginx, which `scripts/test` installs when it is missing, and
//! run there: `cargo test --release --test cluster -- --ignored`.
#![cfg(all(target_os = "linux", target_env = "gnu"))]

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod support;
use support::{metric, signal_process, PATIENCE};

/// Spheres and image side of the generated scene: 10^5 spheres, small
/// enough an image that each render takes a second or two on one core.
const SPHERES: &str = "100000";
const SIDE: &str = "192";

fn voxtrace(args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "voxtrace {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!(
        "voxtrace-cluster-test-{}-{name}",
        std::process::id()
    ))
}

/// A generated scene of [`SPHERES`] spheres, and its local render at `spp`.
fn scene_and_local_render(tag: &str, spp: &str) -> (PathBuf, Vec<u8>) {
    let scene = temp(&format!("{tag}.txt"));
    let scene_arg = scene.to_str().unwrap();
    voxtrace(&[
        "gen",
        "--spheres",
        SPHERES,
        "--seed",
        "5",
        "--res",
        SIDE,
        SIDE,
        "-o",
        scene_arg,
    ]);
    let local = temp(&format!("{tag}-local.png"));
    voxtrace(&[
        "render",
        scene_arg,
        "--spp",
        spp,
        "-o",
        local.to_str().unwrap(),
    ]);
    let bytes = std::fs::read(&local).unwrap();
    std::fs::remove_file(local).unwrap();
    (scene, bytes)
}

struct Worker {
    pid: u32,
    url: String,
}

/// A cluster started by `deploy/cluster.sh up`, taken down when dropped.
struct Cluster {
    dir: PathBuf,
    front: String,
    workers: Vec<Worker>,
    nginx: u32,
}

fn cluster_sh(dir: &Path, args: &[&str]) -> Output {
    Command::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/cluster.sh"))
        .args(args)
        .env("VOXTRACE_CLUSTER_DIR", dir)
        .env("VOXTRACE_BIN", env!("CARGO_BIN_EXE_voxtrace"))
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

impl Cluster {
    fn up(tag: &str, workers: usize) -> Cluster {
        let dir = temp(tag);
        let n = workers.to_string();
        let out = cluster_sh(&dir, &["up", &n, "--", "--threads", "1"]);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "up: {stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let mut lines = stdout.lines();
        let front = lines.next().unwrap().to_owned();
        assert!(front.starts_with("http://127.0.0.1:"), "{stdout}");
        let workers: Vec<Worker> = lines
            .map(|l| {
                let mut words = l.split(' ');
                assert_eq!(words.next(), Some("worker"), "{l}");
                Worker {
                    pid: words.next().unwrap().parse().unwrap(),
                    url: words.next().unwrap().to_owned(),
                }
            })
            .collect();
        assert_eq!(workers.len(), 3, "{stdout}");
        let nginx = std::fs::read_to_string(dir.join("nginx.pid"))
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        Cluster {
            dir,
            front,
            workers,
            nginx,
        }
    }

    /// Every process of the cluster: the workers, nginx's master and its workers.
    fn processes(&self) -> Vec<u32> {
        let children =
            std::fs::read_to_string(format!("/proc/{}/task/{}/children", self.nginx, self.nginx))
                .unwrap_or_default();
        let mut pids: Vec<u32> = self.workers.iter().map(|w| w.pid).collect();
        pids.push(self.nginx);
        pids.extend(
            children
                .split_whitespace()
                .map(|p| p.parse::<u32>().unwrap()),
        );
        pids
    }

    fn down(&self) {
        let pids = self.processes();
        assert!(pids.len() > 4, "nginx has no worker process: {pids:?}");
        let out = cluster_sh(&self.dir, &["down"]);
        assert!(
            out.status.success(),
            "down: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let left: Vec<u32> = pids.into_iter().filter(|&p| alive(p)).collect();
        assert!(left.is_empty(), "down left {left:?} running");
        assert!(!self.dir.exists());
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = cluster_sh(&self.dir, &["down"]);
    }
}

/// Whether `pid` runs: it exists and is not a zombie (one that has exited
/// and waits for its parent, here init, to collect it).
fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| s.rsplit_once(") ").map(|(_, rest)| !rest.starts_with('Z')))
        .unwrap_or(false)
}

fn remote_args<'a>(scene: &'a str, front: &'a str, spp: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "render",
        scene,
        "--remote",
        front,
        "--spp",
        spp,
        "--tiles",
        "24",
        "--in-flight",
        "6",
        "--stats",
        "-o",
        out,
    ]
}

#[test]
#[ignore = "needs nginx: scripts/test installs it and runs these"]
fn a_tiled_render_through_three_workers_is_the_local_render_and_down_leaves_nothing() {
    let cluster = Cluster::up("plain", 3);
    for spp in ["1", "3"] {
        let (scene, local) = scene_and_local_render(&format!("plain-{spp}"), spp);
        let out = temp(&format!("plain-{spp}-remote.png"));
        let done = voxtrace(&remote_args(
            scene.to_str().unwrap(),
            &cluster.front,
            spp,
            out.to_str().unwrap(),
        ));
        assert!(
            std::fs::read(&out).unwrap() == local,
            "spp {spp}: the tiled image differs"
        );
        let stats = String::from_utf8_lossy(&done.stderr);
        assert!(stats.contains("tiles   25  retries 0"), "{stats}");
        let workers = stats
            .lines()
            .filter(|l| l.starts_with("worker  worker-"))
            .count();
        assert!(
            workers >= 2,
            "least_conn used {workers} worker(s):\n{stats}"
        );
        std::fs::remove_file(out).unwrap();
        std::fs::remove_file(scene).unwrap();
    }
    cluster.down();
}

/// Starts a tiled render, waits until `victim` is rendering one of its
/// tiles, sends it `signal`, and checks the render still completes with
/// the local image's bytes.
fn render_while_signalling(tag: &str, signal: libc::c_int) -> Cluster {
    let cluster = Cluster::up(tag, 3);
    let (scene, local) = scene_and_local_render(tag, "4");
    let out = temp(&format!("{tag}-remote.png"));
    let mut render = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .args(remote_args(
            scene.to_str().unwrap(),
            &cluster.front,
            "4",
            out.to_str().unwrap(),
        ))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let victim = &cluster.workers[1];
    let addr = victim.url.trim_start_matches("http://").parse().unwrap();
    support::eventually("the worker renders a tile", || {
        metric(addr, "voxtrace_renders_in_flight").is_some_and(|n| n >= 1)
    });
    signal_process(victim.pid, signal);
    let started = Instant::now();
    let status = loop {
        if let Some(status) = render.try_wait().unwrap() {
            break status;
        }
        assert!(
            started.elapsed() < 4 * PATIENCE,
            "the tiled render never finished"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut render.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(status.success(), "{stderr}");
    assert!(
        std::fs::read(&out).unwrap() == local,
        "the tiled image differs\n{stderr}"
    );
    assert!(stderr.contains("tiles   25"), "{stderr}");
    std::fs::remove_file(out).unwrap();
    std::fs::remove_file(scene).unwrap();
    support::eventually("the signalled worker exits", || !alive(victim.pid));
    cluster
}

#[test]
#[ignore = "needs nginx: scripts/test installs it and runs these"]
fn a_worker_killed_mid_render_loses_no_tile() {
    render_while_signalling("killed", libc::SIGKILL).down();
}

#[test]
#[ignore = "needs nginx: scripts/test installs it and runs these"]
fn a_worker_told_to_stop_mid_render_drains_and_loses_no_tile() {
    let cluster = render_while_signalling("drained", libc::SIGTERM);
    let log = std::fs::read_to_string(cluster.dir.join("logs/worker-2.log")).unwrap();
    assert!(log.contains("SIGTERM: draining"), "{log}");
    assert!(log.contains("stopped on SIGTERM: drained"), "{log}");
    cluster.down();
}
