//! `voxtrace render --remote`: tiles sent to a service, failures sent
//! again, the stitched image the local one byte for byte; refusals and a
//! cluster that never answers end the render with the right error.

use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::Duration;
use voxtrace::remote::{self, RemoteConfig, RemoteError};
use voxtrace::render::{render_scene, RenderOptions, Rules};
use voxtrace::service::ServiceConfig;

mod support;
use support::{sample, start};

fn config(authority: String, spp: u32, tiles: u32) -> RemoteConfig {
    RemoteConfig {
        authority,
        path: "/render".into(),
        spp,
        depth: None,
        rules: Rules::Default,
        tiles,
        in_flight: 4,
        tile_timeout: Duration::from_secs(30),
    }
}

/// A front that breaks every other connection it is given (reads the
/// request, then closes without a word) and passes the rest through to
/// `backend`, byte for byte.
fn flaky_front(backend: std::net::SocketAddr) -> (String, Arc<AtomicUsize>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let broken = Arc::new(AtomicUsize::new(0));
    let count = Arc::clone(&broken);
    thread::spawn(move || {
        for (i, client) in listener.incoming().enumerate() {
            let Ok(mut client) = client else { continue };
            if i % 2 == 0 {
                count.fetch_add(1, Ordering::Relaxed);
                let mut some = [0u8; 1024];
                let _ = client.read(&mut some);
                drop(client);
                continue;
            }
            let mut server = TcpStream::connect(backend).unwrap();
            let (mut from_client, mut to_server) =
                (client.try_clone().unwrap(), server.try_clone().unwrap());
            thread::spawn(move || {
                let _ = std::io::copy(&mut from_client, &mut to_server);
                let _ = to_server.shutdown(Shutdown::Write);
            });
            thread::spawn(move || {
                let _ = std::io::copy(&mut server, &mut client);
                let _ = client.flush();
            });
        }
    });
    (addr.to_string(), broken)
}

#[test]
fn broken_connections_are_retried_and_the_stitched_image_is_the_local_one() {
    let server = start(ServiceConfig::default());
    let (front, broken) = flaky_front(server.addr());
    let text = sample("testSample.txt");
    let scene = voxtrace::scene::parse(&text).unwrap();
    let options = RenderOptions {
        spp: 2,
        ..RenderOptions::default()
    };
    let local = render_scene(&scene, &options, &|_| {}).unwrap().image;
    let done = remote::render(&config(front, 2, 9), &text, (600, 600), &|_| {}).unwrap();
    assert!(done.image == local, "the stitched image differs");
    let stats = done.stats;
    assert_eq!(stats.tiles, 9);
    assert_eq!(stats.retries as usize, broken.load(Ordering::Relaxed));
    assert!(stats.retries >= 9, "{stats:?}");
    assert!(stats.failures.keys().all(|k| k == "broken"), "{stats:?}");
    let worker = server.addr().to_string();
    assert_eq!(stats.workers[&worker].tiles, 9, "{stats:?}");
}

/// The tiles are rendered by the rule set asked for, not the workers' default.
#[test]
fn every_tile_is_rendered_by_the_rules_asked_for() {
    let server = start(ServiceConfig::default());
    let text = sample("testImgPlane.txt");
    let scene = voxtrace::scene::parse(&text).unwrap();
    let local = |rules| {
        let options = RenderOptions {
            rules,
            ..RenderOptions::default()
        };
        render_scene(&scene, &options, &|_| {}).unwrap().image
    };
    let size = (scene.camera.width, scene.camera.height);
    let config = RemoteConfig {
        rules: Rules::Ucla,
        ..config(server.addr().to_string(), 1, 4)
    };
    let done = remote::render(&config, &text, size, &|_| {}).unwrap();
    assert!(
        done.image == local(Rules::Ucla),
        "the stitched image differs"
    );
    assert!(
        done.image != local(Rules::Default),
        "the rules make no difference here"
    );
}

#[test]
fn a_refused_tile_ends_the_render_with_the_workers_reason() {
    let server = start(ServiceConfig {
        max_spheres: 2,
        ..ServiceConfig::default()
    });
    let text = sample("testSample.txt");
    let error = remote::render(
        &config(server.addr().to_string(), 1, 4),
        &text,
        (600, 600),
        &|_| {},
    )
    .err()
    .unwrap();
    assert!(
        matches!(error, RemoteError::Refused { status: 422, .. }),
        "{error}"
    );
    assert!(error.is_input_error());
    assert!(error.to_string().contains("at most 2"), "{error}");
}

#[test]
fn a_service_that_is_not_there_makes_the_cli_give_up_with_exit_code_1() {
    // A port nobody listens on: bound, then closed.
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/testSample.txt");
    let out = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .arg("render")
        .arg(&scene)
        .args([
            "--remote",
            &format!("http://127.0.0.1:{port}"),
            "--tiles",
            "2",
            "-o",
            "never-written.png",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("failed 5 times, the last time with connect; giving up"),
        "{stderr}"
    );
}

#[test]
fn remote_only_flags_need_remote_and_local_only_flags_refuse_it() {
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/testSample.txt");
    for args in [
        vec!["--tiles", "4"],
        vec!["--remote", "http://127.0.0.1:1", "--index", "brute"],
        vec!["--remote", "http://127.0.0.1:1", "--region", "0,0,1,1"],
        vec!["--remote", "http://127.0.0.1:1", "--tiles", "0"],
        vec!["--remote", "ftp://x", "-o", "never-written.png"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
            .arg("render")
            .arg(&scene)
            .args(&args)
            .output()
            .unwrap();
        assert_eq!(
            out.status.code(),
            Some(2),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
