//! A worker told to stop (SIGTERM) drains: `/healthz` and new renders get
//! 503, every render it had admitted is answered in full, and it exits 0
//! with a line saying so.
#![cfg(all(target_os = "linux", target_env = "gnu"))]

use std::thread;

mod support;
use support::{sample, wait_until, Client, ServeProcess};

/// Costly enough (some 0.5 s each on one thread of the development
/// machine) that four of them in a row outlast the checks made while they
/// run by far.
const QUERY: &str = "/render?spp=32";

#[test]
fn sigterm_with_renders_in_flight_loses_none_of_them() {
    let mut server = ServeProcess::start(&["--threads", "1", "--renders", "1", "--queue", "8"]);
    let addr = server.addr;
    let scene = sample("testSample.txt");
    let expected = Client::connect(addr).request("POST", QUERY, &[], &scene);
    assert_eq!(expected.status, 200);
    let clients: Vec<_> = (0..4)
        .map(|_| {
            let scene = scene.clone();
            thread::spawn(move || Client::connect(addr).request("POST", QUERY, &[], &scene))
        })
        .collect();
    wait_until(addr, "voxtrace_renders_in_flight", |n| n == 1);
    wait_until(addr, "voxtrace_render_queue_depth", |n| n == 3);
    server.signal(libc::SIGTERM);
    support::eventually("/healthz says the worker drains", || {
        let reply = Client::connect(addr).request("GET", "/healthz", &[], b"");
        reply.status == 503 && reply.text() == "draining\n"
    });
    let refused =
        Client::connect(addr).request("POST", QUERY, &["Accept: application/json"], &scene);
    assert_eq!(refused.status, 503);
    assert_eq!(refused.json()["error"], "draining");
    assert_eq!(refused.header("retry-after"), Some("1"));
    for client in clients {
        let reply = client.join().unwrap();
        assert_eq!(reply.status, 200, "{}", reply.text());
        assert!(
            reply.body == expected.body,
            "a drained render's image differs"
        );
    }
    let (status, stdout) = server.wait_for_exit();
    assert_eq!(status.code(), Some(0), "{stdout}");
    assert!(stdout.contains("SIGTERM: draining"), "{stdout}");
    assert!(
        stdout.contains("stopped on SIGTERM: drained, 4 admitted renders finished"),
        "{stdout}"
    );
}

#[test]
fn sigint_on_an_idle_worker_stops_it_at_once_with_exit_code_0() {
    let mut server = ServeProcess::start(&["--threads", "1"]);
    let idle = Client::connect(server.addr);
    server.signal(libc::SIGINT);
    let (status, stdout) = server.wait_for_exit();
    assert_eq!(status.code(), Some(0), "{stdout}");
    assert!(
        stdout.contains("stopped on SIGINT: drained, 0 admitted renders"),
        "{stdout}"
    );
    drop(idle);
}
