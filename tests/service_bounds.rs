//! The hard bounds of `voxtrace serve` under the attacks that used to break
//! them: renders that pinned every slot, responses nobody read, clients that
//! half-close, and one peer holding every connection it may.

mod support;

use std::net::Ipv4Addr;
use std::time::{Duration, Instant};
use support::*;
use voxtrace::service::ServiceConfig;

/// How far past its budget a stopped render may be answered here. The
/// service stops a render within one ray's walk of its budget (some
/// milliseconds; `docs/hard-bounds.md` has the figures); this allows for a
/// machine busy with other work.
const OVERSHOOT_ALLOWED: Duration = Duration::from_secs(2);

#[test]
fn four_renders_with_exponential_ray_trees_stop_at_their_budget_and_the_next_client_is_served() {
    let budget = Duration::from_millis(1000);
    let server = start(ServiceConfig {
        concurrent_renders: 4,
        render_timeout: budget,
        ..ServiceConfig::default()
    });
    let addr = server.addr();
    let pinning: Vec<_> = (0..4)
        .map(|_| {
            std::thread::spawn(move || {
                let sent = Instant::now();
                let reply = Client::connect(addr).request(
                    "POST",
                    "/render?depth=64",
                    &["Accept: application/json"],
                    &nested_glass(),
                );
                (reply, sent.elapsed())
            })
        })
        .collect();
    for attack in pinning {
        let (reply, took) = attack.join().unwrap();
        assert_eq!(
            (reply.status, reply.json()["error"].as_str()),
            (504, Some("time_budget")),
            "{}",
            reply.text()
        );
        assert!(reply.header("retry-after").is_none());
        assert!(took < budget + OVERSHOOT_ALLOWED, "answered after {took:?}");
    }
    // Every slot is free: the next client is served at once.
    wait_for_metric(addr, "voxtrace_renders_in_flight", 0);
    let next = Client::connect(addr).request("POST", "/render", &[], &sample("testSample.txt"));
    assert_eq!(next.status, 200, "{}", next.text());
    assert_eq!(metric(addr, "voxtrace_renders_stopped_total"), Some(4));
    assert_eq!(
        metric(addr, "voxtrace_errors_total{kind=\"time_budget\"}"),
        Some(4)
    );
    let overshoot = support::metric_value(addr, "voxtrace_render_overshoot_max_seconds").unwrap();
    assert!(
        Duration::from_secs_f64(overshoot) < OVERSHOOT_ALLOWED,
        "{overshoot} s"
    );
}

#[test]
fn a_client_that_leaves_mid_render_has_its_render_stopped_and_its_slot_freed() {
    // A budget no test waits for: only the client's leaving can stop it.
    let server = start(ServiceConfig {
        concurrent_renders: 1,
        queue: 0,
        render_timeout: Duration::from_secs(600),
        ..ServiceConfig::default()
    });
    let addr = server.addr();
    let mut leaver = Client::connect(addr);
    leaver.send(&request_bytes(
        "POST",
        "/render?depth=64",
        &[],
        &nested_glass(),
    ));
    wait_for_metric(addr, "voxtrace_renders_in_flight", 1);
    drop(leaver);
    wait_for_metric(addr, "voxtrace_renders_in_flight", 0);
    assert_eq!(metric(addr, "voxtrace_renders_abandoned_total"), Some(1));
    assert_eq!(
        metric(
            addr,
            "voxtrace_http_requests_total{handler=\"/render\",method=\"POST\",code=\"499\"}"
        ),
        Some(1)
    );
    let next = Client::connect(addr).request("POST", "/render", &[], &sample("testSample.txt"));
    assert_eq!(next.status, 200, "{}", next.text());
}

fn expected_png(scene: &[u8]) -> Vec<u8> {
    let parsed = voxtrace::scene::parse(scene).unwrap();
    let options = voxtrace::render::RenderOptions::default();
    let rendered = voxtrace::render::render_scene(&parsed, &options, &|_| {}).unwrap();
    rendered
        .image
        .encode(voxtrace::output::Format::Png)
        .unwrap()
}

#[test]
fn a_half_closed_post_gets_its_image() {
    let server = start(ServiceConfig::default());
    let scene = sample("testSample.txt");
    let expected = expected_png(&scene);
    for version in ["HTTP/1.1", "HTTP/1.0"] {
        let mut client = Client::connect(server.addr());
        let request = String::from_utf8(request_bytes("POST", "/render", &[], &scene)).unwrap();
        client.send(request.replacen("HTTP/1.1", version, 1).as_bytes());
        client.half_close();
        let reply = client.read_final_reply();
        assert_eq!(reply.status, 200, "{version}: {}", reply.text());
        assert!(reply.body == expected, "{version}: not the scene's image");
        assert!(client.closed());
    }
}

#[test]
fn a_half_closed_post_that_waits_for_a_slot_is_answered_once_it_has_one() {
    // The only slot is held by a render that only its client's leaving ends.
    let server = start(ServiceConfig {
        concurrent_renders: 1,
        queue: 1,
        render_timeout: Duration::from_secs(600),
        ..ServiceConfig::default()
    });
    let addr = server.addr();
    let mut holder = Client::connect(addr);
    holder.send(&request_bytes(
        "POST",
        "/render?depth=64",
        &[],
        &nested_glass(),
    ));
    wait_for_metric(addr, "voxtrace_renders_in_flight", 1);
    let scene = sample("testSample.txt");
    let mut waiting = Client::connect(addr);
    waiting.send(&request_bytes("POST", "/render", &[], &scene));
    waiting.half_close();
    // Seen waiting with its sending side shut, it is told to go on waiting
    // (an HTTP/1.1 client skips a 100 it did not ask for), not dropped.
    assert_eq!(waiting.read_reply(false).status, 100);
    drop(holder);
    let reply = waiting.read_final_reply();
    assert_eq!(reply.status, 200, "{}", reply.text());
    assert!(reply.body == expected_png(&scene));
    assert_eq!(metric(addr, "voxtrace_renders_abandoned_total"), Some(1));
}

#[test]
fn unread_responses_stay_within_the_memory_budget() {
    // 40 requests for the largest PPM (48 MiB each), whose clients never
    // read: the responses wait for a write timeout longer than the test.
    const MIB: u64 = 1024 * 1024;
    let budget = 400 * MIB;
    let server = ServeProcess::start(&[
        "--memory-budget",
        &budget.to_string(),
        "--write-timeout-ms",
        "120000",
        "--threads",
        "2",
    ]);
    let addr = server.addr;
    let scene = largest_empty_image();
    let clients: Vec<Client> = (0..40)
        .map(|_| {
            let mut client = Client::connect(addr);
            client.send(&request_bytes("POST", "/render?format=ppm", &[], &scene));
            client
        })
        .collect();
    let answered = |code| {
        format!(
            "voxtrace_http_requests_total{{handler=\"/render\",method=\"POST\",code=\"{code}\"}}"
        )
    };
    let done = |s| metric(addr, &answered(s)).unwrap_or(0);
    eventually("every request answered", || done(200) + done(503) == 40);
    let peak = server.memory("VmHWM");
    assert!(
        peak <= budget,
        "peak resident set {} MiB over a budget of {} MiB",
        peak / MIB,
        budget / MIB
    );
    let held = metric(addr, &answered(200)).unwrap();
    assert!(held >= 2, "only {held} responses held");
    assert_eq!(
        metric(addr, "voxtrace_errors_total{kind=\"response_memory\"}"),
        Some(40 - held)
    );
    drop(clients);
}

#[test]
fn a_peer_at_its_connection_limit_does_not_stop_healthz_or_another_peer() {
    let per_peer = 8;
    let server = start(ServiceConfig {
        max_connections: 64,
        max_connections_per_peer: per_peer,
        idle_timeout: Duration::from_secs(600),
        ..ServiceConfig::default()
    });
    let addr = server.addr();
    let held: Vec<Client> = (0..per_peer).map(|_| Client::connect(addr)).collect();
    // The metrics are read from the reserve once the peer is at its limit.
    wait_until(addr, "voxtrace_open_connections", |n| n > per_peer as u64);

    let over = Client::connect(addr).request(
        "POST",
        "/render",
        &["Accept: application/json"],
        &sample("testSample.txt"),
    );
    assert_eq!(
        (over.status, over.json()["error"].as_str()),
        (503, Some("peer_limit"))
    );
    assert_eq!(over.header("retry-after"), Some("1"));
    let health = Client::connect(addr).request("GET", "/healthz", &[], b"");
    assert_eq!((health.status, health.text().as_str()), (200, "ok\n"));

    let other = Ipv4Addr::new(127, 0, 0, 2);
    let mut neighbour = Client::connect_from(other, addr);
    for _ in 0..2 {
        let reply = neighbour.request("POST", "/render", &[], &sample("testDiffuse.txt"));
        assert_eq!(reply.status, 200, "{}", reply.text());
    }
    assert_eq!(
        metric(addr, "voxtrace_errors_total{kind=\"peer_limit\"}"),
        Some(1)
    );
    drop(held);
}

#[test]
fn past_the_connection_cap_healthz_is_answered_from_the_reserve() {
    let server = start(ServiceConfig {
        max_connections: 4,
        idle_timeout: Duration::from_secs(600),
        ..ServiceConfig::default()
    });
    let addr = server.addr();
    let held: Vec<Client> = (0..4)
        .map(|i| Client::connect_from(Ipv4Addr::new(127, 0, 0, 10 + i), addr))
        .collect();
    wait_until(addr, "voxtrace_open_connections", |n| n > 4);
    let health = Client::connect(addr).request("GET", "/healthz", &[], b"");
    assert_eq!(health.status, 200);
    let mut refused = Client::connect(addr);
    let render = refused.request("POST", "/render", &[], &sample("testSample.txt"));
    assert_eq!(render.status, 503);
    assert!(
        render.text().contains("too many connections"),
        "{}",
        render.text()
    );
    // One request per reserve place, then it closes.
    assert_eq!(render.header("connection"), Some("close"));
    assert!(refused.closed());
    drop(held);
}
