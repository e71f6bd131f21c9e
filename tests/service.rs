//! `voxtrace serve` end to end: a server on an ephemeral loopback port, spoken
//! to over raw TCP so every byte of the protocol is under test.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use voxtrace::service::{ServerHandle, ServiceConfig};

mod support;
use support::{metric, sample, start, wait_for_metric, Client, Reply};

/// What `voxtrace render SCENE -o x.<ext>` writes.
fn cli_render(scene: &str, extension: &str) -> Vec<u8> {
    let dir = std::env::temp_dir().join(format!("voxtrace-service-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join(format!("{scene}.{extension}"));
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .arg("render")
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("scenes")
                .join(scene),
        )
        .arg("-o")
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let bytes = std::fs::read(&out).unwrap();
    std::fs::remove_file(&out).unwrap();
    bytes
}

/// A scene that costs as much as asked: one sphere filling the view, lit by
/// 1000 lights, so every pixel sample casts 1000 shadow rays whatever the index.
/// The image is narrow and tall: the render checks its deadline between rows,
/// so short rows keep it close to its budget even on a busy machine.
fn costly_scene() -> Vec<u8> {
    let mut text = String::from(
        "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 16 4096\nSPHERE big 0 0 -3 4 4 1 1 1 1 0.1 0.8 0.2 0 10\n",
    );
    for i in 0..1000 {
        text += &format!("LIGHT l{i} {} {} 0 0.001 0.001 0.001\n", i % 10, i / 100);
    }
    text.into_bytes()
}

#[test]
fn a_rendered_scene_equals_the_cli_output_byte_for_byte() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());
    let reply = client.request("POST", "/render", &[], &sample("testSample.txt"));
    assert_eq!(reply.status, 200, "{}", reply.text());
    assert_eq!(reply.header("content-type"), Some("image/png"));
    assert_eq!(
        reply.header("content-disposition"),
        Some("inline; filename=\"testSample.png\"")
    );
    assert_eq!(reply.header("x-image-width"), Some("600"));
    assert_eq!(reply.header("x-image-height"), Some("600"));
    assert!(reply.header("x-rays").unwrap().parse::<u64>().unwrap() >= 600 * 600);
    assert!(reply.header("x-render-ms").unwrap().parse::<f64>().unwrap() > 0.0);
    assert!(reply
        .header("access-control-expose-headers")
        .unwrap()
        .contains("X-Render-Ms"));
    let decoded = image::load_from_memory(&reply.body).unwrap();
    assert_eq!((decoded.width(), decoded.height()), (600, 600));
    assert!(
        reply.body == cli_render("testSample.txt", "png"),
        "PNG differs from the CLI's"
    );

    let ppm = client.request("POST", "/render?format=ppm", &[], &sample("testShadow.txt"));
    assert_eq!(ppm.status, 200);
    assert_eq!(ppm.header("content-type"), Some("image/x-portable-pixmap"));
    assert!(
        ppm.body == cli_render("testShadow.txt", "ppm"),
        "PPM differs from the CLI's"
    );
}

#[test]
fn scene_errors_name_line_and_column_as_text_and_json() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());
    let bad = String::from_utf8(sample("testSample.txt"))
        .unwrap()
        .replace("LEFT -1", "LEFT abc");
    let expected = voxtrace::scene::parse(&bad).unwrap_err();
    assert_eq!((expected.line, expected.column), (2, 6));

    let text = client.request("POST", "/render", &[], bad.as_bytes());
    assert_eq!(text.status, 400);
    assert_eq!(
        text.text(),
        format!(
            "{}\n --> request body:2:6\n  |\n2 | LEFT abc\n  |      ^^^\n",
            expected.kind
        )
    );

    let json = client.request(
        "POST",
        "/render",
        &["Accept: image/png, application/json"],
        bad.as_bytes(),
    );
    assert_eq!(json.status, 400);
    assert_eq!(
        json.json(),
        serde_json::json!({"error": "scene", "message": expected.to_string(), "line": 2, "column": 6})
    );

    let query = client.request(
        "POST",
        "/render?spp=0",
        &["Accept: application/json"],
        &sample("testSample.txt"),
    );
    assert_eq!(query.status, 400);
    assert_eq!(query.json()["error"], "query");
    assert!(query.json()["message"]
        .as_str()
        .unwrap()
        .contains("spp must be"));
}

#[test]
fn routes_methods_and_head() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());

    let page = client.request("GET", "/", &[], b"");
    assert_eq!(page.status, 200);
    assert!(page
        .header("content-type")
        .unwrap()
        .starts_with("text/html"));
    assert!(page
        .text()
        .contains("<script type=\"module\" src=\"/app.js\""));
    for (path, kind) in [("/style.css", "text/css"), ("/app.js", "text/javascript")] {
        let asset = client.request("GET", path, &[], b"");
        assert_eq!(asset.status, 200, "{path}");
        assert!(
            asset.header("content-type").unwrap().starts_with(kind),
            "{path}"
        );
    }

    let head = client.request("HEAD", "/", &[], b"");
    assert_eq!(head.status, 200);
    assert_eq!(
        head.header("content-length"),
        Some(page.body.len().to_string().as_str())
    );
    // The HEAD response had no body: the next reply on the connection parses.
    assert_eq!(client.request("GET", "/healthz", &[], b"").text(), "ok\n");

    let list = client.request("GET", "/scenes", &[], b"").json();
    let names: Vec<&str> = list
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert!(names.contains(&"testSample.txt") && names.contains(&"testShadow.txt"));
    let sample_entry = list
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == "testSample.txt")
        .unwrap();
    assert_eq!(sample_entry["bytes"], sample("testSample.txt").len());
    let scene = client.request("GET", "/scenes/testSample.txt", &[], b"");
    assert_eq!((scene.status, scene.body), (200, sample("testSample.txt")));
    assert_eq!(
        client
            .request("GET", "/scenes/../Cargo.toml", &[], b"")
            .status,
        404
    );

    let missing = client.request("GET", "/nowhere", &["Accept: application/json"], b"");
    assert_eq!(missing.status, 404);
    assert_eq!(missing.json()["error"], "not_found");

    let get_render = client.request("GET", "/render", &[], b"");
    assert_eq!(
        (get_render.status, get_render.header("allow")),
        (405, Some("POST"))
    );
    let post_health = client.request("POST", "/healthz", &[], b"x");
    assert_eq!(
        (post_health.status, post_health.header("allow")),
        (405, Some("GET, HEAD"))
    );

    let metrics = client.request("GET", "/metrics", &[], b"").text();
    assert!(
        metrics.contains(
            "voxtrace_http_requests_total{handler=\"/healthz\",method=\"GET\",code=\"200\"} 1\n"
        ),
        "{metrics}"
    );
    assert!(metrics.contains(
        "voxtrace_http_requests_total{handler=\"/render\",method=\"GET\",code=\"405\"} 1\n"
    ));
    assert!(metrics.contains(
        "voxtrace_http_requests_total{handler=\"other\",method=\"GET\",code=\"404\"} 1\n"
    ));
    for name in [
        "voxtrace_renders_total",
        "voxtrace_rays_total",
        "voxtrace_render_seconds_bucket",
        "voxtrace_render_queue_depth",
        "voxtrace_renders_in_flight",
        "voxtrace_open_connections 1",
    ] {
        assert!(metrics.contains(name), "{name} missing");
    }
}

#[test]
fn one_connection_serves_many_requests_until_told_to_close() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());
    for _ in 0..3 {
        assert_eq!(client.request("GET", "/healthz", &[], b"").status, 200);
        let reply = client.request("POST", "/render?spp=2", &[], &sample("testDiffuse.txt"));
        assert_eq!(
            (reply.status, reply.header("connection")),
            (200, Some("keep-alive"))
        );
    }
    // Two pipelined requests in one write get two replies in order.
    client.send(b"GET /healthz HTTP/1.1\r\nHost: t\r\n\r\nGET /scenes/testShadow.txt HTTP/1.1\r\nHost: t\r\n\r\n");
    assert_eq!(client.read_reply(false).text(), "ok\n");
    assert_eq!(client.read_reply(false).body, sample("testShadow.txt"));

    let last = client.request("GET", "/healthz", &["Connection: close"], b"");
    assert_eq!(
        (last.status, last.header("connection")),
        (200, Some("close"))
    );
    assert!(client.closed());
    let metrics = Client::connect(server.addr())
        .request("GET", "/metrics", &[], b"")
        .text();
    assert!(metrics.contains(
        "voxtrace_http_requests_total{handler=\"/render\",method=\"POST\",code=\"200\"} 3\n"
    ));
}

#[test]
fn http_framing_expect_continue_chunked_and_http10() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());
    let scene = sample("testSample.txt");
    client.send(format!("POST /render HTTP/1.1\r\nHost: t\r\nExpect: 100-continue\r\nContent-Length: {}\r\n\r\n", scene.len()).as_bytes());
    assert_eq!(client.read_reply(false).status, 100);
    client.send(&scene);
    assert_eq!(client.read_reply(false).status, 200);

    let no_length = client.request("POST", "/render", &[], b"");
    assert_eq!(no_length.status, 400, "an empty scene is a scene error");
    let said = String::from_utf8_lossy(&no_length.body);
    assert!(said.contains("the scene is empty"), "{said}");
    client.send(b"POST /render HTTP/1.1\r\nHost: t\r\n\r\n");
    assert_eq!(client.read_reply(false).status, 411);

    client.send(b"POST /render HTTP/1.1\r\nHost: t\r\nTransfer-Encoding: chunked\r\n\r\n5\r\nNEAR \r\n0\r\n\r\n");
    let chunked = client.read_reply(false);
    assert_eq!(
        (chunked.status, chunked.header("connection")),
        (411, Some("close"))
    );
    assert!(client.closed());

    let mut old = Client::connect(server.addr());
    old.send(b"GET /healthz HTTP/1.0\r\n\r\n");
    let reply = old.read_reply(false);
    assert_eq!(
        (reply.status, reply.header("connection")),
        (200, Some("close"))
    );
    assert!(old.closed());

    let mut hostless = Client::connect(server.addr());
    hostless.send(b"GET /healthz HTTP/1.1\r\n\r\n");
    assert_eq!(hostless.read_reply(false).status, 400);

    let mut garbage = Client::connect(server.addr());
    garbage.send(b"\x16\x03\x01 hello there\r\n\r\n");
    assert_eq!(garbage.read_reply(false).status, 400);
    assert!(garbage.closed());
}

#[test]
fn size_limits_give_413_431_and_422() {
    let server = start(ServiceConfig {
        max_body: 1000,
        ..ServiceConfig::default()
    });
    // 413 comes from the header alone: no body byte is ever sent.
    let mut big = Client::connect(server.addr());
    big.send(b"POST /render HTTP/1.1\r\nHost: t\r\nAccept: application/json\r\nContent-Length: 1000000000\r\n\r\n");
    let reply = big.read_reply(false);
    assert_eq!(
        (reply.status, reply.json()["error"].as_str()),
        (413, Some("body_too_large"))
    );
    assert!(big.closed());

    let mut huge_head = Client::connect(server.addr());
    let cookie = "a".repeat(20_000);
    huge_head
        .send(format!("GET /healthz HTTP/1.1\r\nHost: t\r\nCookie: {cookie}\r\n\r\n").as_bytes());
    assert_eq!(huge_head.read_reply(false).status, 431);
    let mut many_headers = Client::connect(server.addr());
    many_headers.send(
        format!(
            "GET /healthz HTTP/1.1\r\nHost: t\r\n{}\r\n",
            "X-A: 1\r\n".repeat(100)
        )
        .as_bytes(),
    );
    assert_eq!(many_headers.read_reply(false).status, 431);

    let mut client = Client::connect(server.addr());
    let wide = String::from_utf8(sample("testSample.txt"))
        .unwrap()
        .replace("RES 600 600", "RES 5000 5000");
    let reply = client.request(
        "POST",
        "/render",
        &["Accept: application/json"],
        wide.as_bytes(),
    );
    assert_eq!(
        (reply.status, reply.json()["error"].as_str()),
        (422, Some("limit"))
    );
    assert!(reply.json()["message"]
        .as_str()
        .unwrap()
        .contains("25000000 pixels"));
    let reply = client.request("POST", "/render?spp=1024", &[], &sample("testSample.txt"));
    assert_eq!(reply.status, 422);
    assert!(reply.text().contains("samples"), "{}", reply.text());
}

#[test]
fn stalled_requests_get_408() {
    let server = start(ServiceConfig {
        head_timeout: Duration::from_millis(300),
        body_timeout: Duration::from_millis(300),
        ..ServiceConfig::default()
    });
    let mut slow_head = Client::connect(server.addr());
    slow_head.send(b"GET /healthz HTTP/1.1\r\nHo");
    let started = Instant::now();
    assert_eq!(slow_head.read_reply(false).status, 408);
    assert!(started.elapsed() < Duration::from_secs(5));
    assert!(slow_head.closed());

    let mut slow_body = Client::connect(server.addr());
    slow_body.send(b"POST /render HTTP/1.1\r\nHost: t\r\nContent-Length: 100\r\n\r\nNEAR 1\n");
    assert_eq!(slow_body.read_reply(false).status, 408);
    assert!(slow_body.closed());
}

/// A server with one render slot and `queue` places, its slot held by a
/// costly render (errors asked for as JSON) until its `budget`. Returns once
/// that render runs, with the thread that gets its reply.
fn slot_held_by_costly_render(
    queue: usize,
    budget: Duration,
) -> (ServerHandle, std::thread::JoinHandle<Reply>) {
    let server = start(ServiceConfig {
        concurrent_renders: 1,
        queue,
        render_timeout: budget,
        ..ServiceConfig::default()
    });
    let addr = server.addr();
    let costly = std::thread::spawn(move || {
        Client::connect(addr).request(
            "POST",
            "/render?spp=64",
            &["Accept: application/json"],
            &costly_scene(),
        )
    });
    wait_for_metric(addr, "voxtrace_renders_in_flight", 1);
    (server, costly)
}

/// A server with one render slot and `queue` places, its slot held by a
/// render that only its client's leaving ends (its budget is longer than
/// any test): what happens meanwhile cannot race a deadline. Returns once
/// that render runs, with its client, which leaves when dropped.
fn slot_held_until_its_client_leaves(queue: usize) -> (ServerHandle, Client) {
    let server = start(ServiceConfig {
        concurrent_renders: 1,
        queue,
        render_timeout: Duration::from_secs(600),
        ..ServiceConfig::default()
    });
    let mut holder = Client::connect(server.addr());
    holder.send(&support::request_bytes(
        "POST",
        "/render?depth=64",
        &[],
        &support::nested_glass(),
    ));
    wait_for_metric(server.addr(), "voxtrace_renders_in_flight", 1);
    (server, holder)
}

#[test]
fn a_full_queue_answers_503_until_the_slot_is_free() {
    let (server, holder) = slot_held_until_its_client_leaves(0);
    let addr = server.addr();
    let turned_away = Client::connect(addr).request(
        "POST",
        "/render",
        &["Accept: application/json"],
        &sample("testSample.txt"),
    );
    assert_eq!(turned_away.status, 503);
    assert_eq!(turned_away.header("retry-after"), Some("1"));
    assert_eq!(turned_away.json()["error"], "queue_full");
    drop(holder);
    wait_for_metric(addr, "voxtrace_renders_in_flight", 0);
    let after = Client::connect(addr).request("POST", "/render", &[], &sample("testSample.txt"));
    assert_eq!(after.status, 200);
}

#[test]
fn a_costly_render_stops_at_its_budget_and_frees_its_slot() {
    let (server, costly) = slot_held_by_costly_render(0, Duration::from_millis(1500));
    let addr = server.addr();
    let started = Instant::now();
    let reply = costly.join().unwrap();
    assert_eq!(
        (reply.status, reply.json()["error"].as_str()),
        (504, Some("time_budget"))
    );
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "the render outlived its budget"
    );
    wait_for_metric(addr, "voxtrace_renders_in_flight", 0);
    // The slot is free again.
    let after = Client::connect(addr).request("POST", "/render", &[], &sample("testSample.txt"));
    assert_eq!(after.status, 200);
}

#[test]
fn a_client_that_leaves_while_queued_gives_its_place_back_and_is_never_rendered() {
    // One slot and one place in the queue. A render holds the slot until
    // its client leaves; a second client queues behind it, then leaves.
    let (server, holder) = slot_held_until_its_client_leaves(1);
    let addr = server.addr();
    let scene = sample("testSample.txt");
    let mut leaver = Client::connect(addr);
    leaver.send(&support::request_bytes("POST", "/render", &[], &scene));
    wait_for_metric(addr, "voxtrace_render_queue_depth", 1);
    // The queue is full while it waits.
    let full = Client::connect(addr).request("POST", "/render", &[], &scene);
    assert_eq!(full.status, 503);

    drop(leaver);
    // Its place is given back while the slot is still held: it no longer
    // counts against the queue, and it is never rendered.
    wait_for_metric(addr, "voxtrace_renders_abandoned_total", 1);
    wait_for_metric(addr, "voxtrace_render_queue_depth", 0);
    assert_eq!(metric(addr, "voxtrace_renders_in_flight"), Some(1));
    // The next request takes that place and gets the slot once it is free.
    let queued = std::thread::spawn(move || {
        Client::connect(addr).request("POST", "/render", &[], &sample("testSample.txt"))
    });
    wait_for_metric(addr, "voxtrace_render_queue_depth", 1);

    drop(holder);
    let reply = queued.join().unwrap();
    assert_eq!(reply.status, 200, "{}", reply.text());
    // Only that last render ran to its end: the holder's was stopped when
    // its client left (not counted as completed), the queued leaver's
    // never started.
    assert_eq!(metric(addr, "voxtrace_renders_total"), Some(1));
    let rays: u64 = reply.header("x-rays").unwrap().parse().unwrap();
    assert_eq!(support::metric_sum(addr, "voxtrace_rays_total"), rays);
    assert_eq!(metric(addr, "voxtrace_renders_abandoned_total"), Some(2));
    assert_eq!(
        metric(
            addr,
            "voxtrace_http_requests_total{handler=\"/render\",method=\"POST\",code=\"499\"}"
        ),
        Some(2)
    );
}

#[test]
fn sixteen_concurrent_clients_are_all_served_correctly() {
    let server = start(ServiceConfig::default());
    let scenes = [
        "testSample.txt",
        "testShadow.txt",
        "testSpecular.txt",
        "testReflection.txt",
    ];
    let expected: Vec<Vec<u8>> = scenes
        .iter()
        .map(|name| {
            let scene = voxtrace::scene::parse(sample(name)).unwrap();
            let options = voxtrace::render::RenderOptions::default();
            let image = voxtrace::render::render_scene(&scene, &options, &|_| {})
                .unwrap()
                .image;
            image.encode(voxtrace::output::Format::Png).unwrap()
        })
        .collect();
    let addr = server.addr();
    std::thread::scope(|s| {
        let clients: Vec<_> = (0..16)
            .map(|i| {
                let (name, expected) = (scenes[i % scenes.len()], &expected[i % scenes.len()]);
                s.spawn(move || {
                    let mut client = Client::connect(addr);
                    for _ in 0..2 {
                        let reply = client.request("POST", "/render", &[], &sample(name));
                        assert_eq!(reply.status, 200, "client {i}: {}", reply.text());
                        assert!(
                            reply.body == *expected,
                            "client {i} got a different image of {name}"
                        );
                    }
                })
            })
            .collect();
        for client in clients {
            client.join().unwrap();
        }
    });
    let metrics = Client::connect(addr)
        .request("GET", "/metrics", &[], b"")
        .text();
    assert!(metrics.contains(
        "voxtrace_http_requests_total{handler=\"/render\",method=\"POST\",code=\"200\"} 32\n"
    ));
    assert!(metrics.contains("voxtrace_renders_total 32\n"));
}

/// Whether the server has said nothing yet and kept the connection open.
fn silent_and_open(client: &Client) -> bool {
    let stream = client.reader.get_ref();
    stream.set_nonblocking(true).unwrap();
    let mut byte = [0u8; 1];
    let silent =
        matches!(stream.peek(&mut byte), Err(e) if e.kind() == std::io::ErrorKind::WouldBlock);
    stream.set_nonblocking(false).unwrap();
    silent
}

#[test]
fn idle_and_trickling_connections_do_not_hold_up_a_render() {
    // 300 connections sit idle or stop halfway through their heads, with
    // long deadlines. A normal client's render is answered while every one
    // of them is still open and unanswered: it waited for none of them.
    let server = start(ServiceConfig {
        head_timeout: Duration::from_secs(60),
        idle_timeout: Duration::from_secs(60),
        ..ServiceConfig::default()
    });
    let mut slow: Vec<Client> = (0..300).map(|_| Client::connect(server.addr())).collect();
    for client in slow.iter_mut().step_by(2) {
        client.send(b"POST /render HTTP/1.1\r\nHost: t\r\nX-Slow: ");
    }
    wait_for_metric(server.addr(), "voxtrace_open_connections", 301);
    let mut normal = Client::connect(server.addr());
    for _ in 0..3 {
        let reply = normal.request("POST", "/render", &[], &sample("testDiffuse.txt"));
        assert_eq!(reply.status, 200, "{}", reply.text());
    }
    assert!(slow.iter().all(silent_and_open));
}

#[test]
fn a_trickling_head_is_cut_at_its_deadline_with_408() {
    // A byte every 50 ms keeps every single read short; the deadline is on
    // the whole head, so the client is still cut off. The pauses are the
    // trickle under test, not a wait for the server.
    let head_timeout = Duration::from_millis(400);
    let server = start(ServiceConfig {
        head_timeout,
        ..ServiceConfig::default()
    });
    // Before connecting: the server's deadline cannot start earlier.
    let started = Instant::now();
    let mut client = Client::connect(server.addr());
    let mut sent = 0;
    for byte in b"GET /healthz HTTP/1.1\r\nX-Slow: ".iter().cycle() {
        if client.reader.get_mut().write_all(&[*byte]).is_err() {
            break;
        }
        sent += 1;
        std::thread::sleep(Duration::from_millis(50));
        if !silent_and_open(&client) {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "still reading after {sent} bytes"
        );
    }
    let cut = started.elapsed();
    let reply = client.read_reply(false);
    assert_eq!(reply.status, 408);
    assert!(client.closed());
    // How many bytes fit before the deadline depends on how promptly this
    // thread wakes; that more than one arrived, and none was answered
    // before the deadline, does not.
    assert!(
        cut >= head_timeout && sent > 1,
        "cut after {cut:?}, {sent} bytes"
    );
}

#[test]
fn an_idle_connection_is_closed_at_the_idle_deadline() {
    let server = start(ServiceConfig {
        idle_timeout: Duration::from_millis(300),
        ..ServiceConfig::default()
    });
    let mut client = Client::connect(server.addr());
    // Before the request: the connection's idling cannot start earlier.
    let started = Instant::now();
    assert_eq!(client.request("GET", "/healthz", &[], b"").status, 200);
    // Closed without a word: nothing had been asked.
    assert!(client.closed());
    let idle = started.elapsed();
    assert!(
        idle >= Duration::from_millis(300) && idle < Duration::from_secs(10),
        "closed after {idle:?}"
    );
}

#[test]
fn connections_over_the_cap_get_503_at_once() {
    let server = start(ServiceConfig {
        max_connections: 2,
        idle_timeout: Duration::from_secs(60),
        ..ServiceConfig::default()
    });
    let held: Vec<Client> = (0..2).map(|_| Client::connect(server.addr())).collect();
    let started = Instant::now();
    let mut over = Client::connect(server.addr());
    let reply = over.read_reply(false);
    assert_eq!(
        (reply.status, reply.header("retry-after")),
        (503, Some("1"))
    );
    assert!(over.closed());
    assert!(started.elapsed() < Duration::from_secs(5));
    // Once a held connection closes, its place is free again.
    drop(held);
    support::eventually("a place freed", || {
        Client::connect(server.addr())
            .request("GET", "/healthz", &[], b"")
            .status
            == 200
    });
}

#[test]
fn stopping_closes_waiting_connections_at_once() {
    let server = start(ServiceConfig {
        idle_timeout: Duration::from_secs(60),
        head_timeout: Duration::from_secs(60),
        ..ServiceConfig::default()
    });
    let mut idle = Client::connect(server.addr());
    let mut halfway = Client::connect(server.addr());
    halfway.send(b"GET /healthz HTTP/1.1\r\n");
    wait_for_metric(server.addr(), "voxtrace_open_connections", 3);
    let started = Instant::now();
    server.stop();
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "stop took {:?}",
        started.elapsed()
    );
    assert!(idle.closed() && halfway.closed());
}

/// A client that goes on sending a body the server refused from its head
/// can finish sending and reads the whole refusal and then the
/// connection's end: the server shuts its sending side and reads what
/// still comes for a while before it closes. (Closed with bytes unread, a
/// connection is reset: the client's next write fails, and some systems
/// discard the answer it has not read yet.)
#[test]
fn a_refused_body_still_being_sent_gets_its_answer_and_a_clean_close() {
    let server = start(ServiceConfig {
        max_body: 1000,
        ..ServiceConfig::default()
    });
    let mut client = Client::connect(server.addr());
    let body = vec![b'#'; 256 * 1024];
    client.send(b"POST /render HTTP/1.1\r\nHost: t\r\nContent-Length: 5000000\r\n\r\n");
    client.send(&body);
    assert_eq!(client.read_reply(false).status, 413);
    // Once answered, the server reads on: were the connection reset
    // instead, this write or the close after it would fail (a broken pipe,
    // as curl reports it).
    client.send(&body);
    client.half_close();
    assert!(client.closed());
}

#[test]
fn bodies_past_the_memory_budget_get_503_and_the_connection_stays_usable() {
    let server = start(ServiceConfig {
        max_body: 1000,
        body_memory: 1000,
        ..ServiceConfig::default()
    });
    // Half a body, then silence: its 1000 bytes are charged.
    let mut holder = Client::connect(server.addr());
    holder.send(b"POST /render HTTP/1.1\r\nHost: t\r\nContent-Length: 1000\r\n\r\nNEAR 1\n");
    wait_for_metric(server.addr(), "voxtrace_body_bytes", 1000);
    let mut client = Client::connect(server.addr());
    let scene = sample("testDiffuse.txt");
    let reply = client.request("POST", "/render", &["Accept: application/json"], &scene);
    assert_eq!(
        (reply.status, reply.header("retry-after")),
        (503, Some("1"))
    );
    assert_eq!(reply.json()["error"], "body_memory");
    // The refused body was read to its end: the next request parses.
    assert_eq!(client.request("GET", "/healthz", &[], b"").status, 200);
    drop(holder);
    wait_for_metric(server.addr(), "voxtrace_body_bytes", 0);
    assert_eq!(client.request("POST", "/render", &[], &scene).status, 200);
}

#[test]
fn a_client_reading_slowly_is_cut_off_at_the_write_deadline() {
    // 12 MB of PPM, read 64 KiB every 100 ms: every single write makes
    // progress (the whole response would take some 20 s), but the write
    // timeout bounds the whole response, so the server gives up after 1 s.
    let write_timeout = Duration::from_secs(1);
    let server = start(ServiceConfig {
        write_timeout,
        ..ServiceConfig::default()
    });
    let addr = server.addr();
    let scene = b"NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 2048 2048\n";
    let full_length = 2048 * 2048 * 3;
    let mut slow = TcpStream::connect(addr).unwrap();
    slow.set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    let mut request = format!(
        "POST /render?format=ppm HTTP/1.1\r\nHost: t\r\nContent-Length: {}\r\n\r\n",
        scene.len()
    )
    .into_bytes();
    request.extend_from_slice(scene);
    // Before sending: the server's write deadline cannot start earlier.
    let sent = Instant::now();
    slow.write_all(&request).unwrap();
    let hurry = Arc::new(AtomicBool::new(false));
    let reader = std::thread::spawn({
        let hurry = Arc::clone(&hurry);
        move || {
            let mut chunk = vec![0u8; 64 * 1024];
            let mut received = 0;
            loop {
                match slow.read(&mut chunk) {
                    Ok(0) | Err(_) => return received,
                    Ok(n) => received += n,
                }
                // The slow reading under test, not a wait for the server.
                if !hurry.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(100));
                }
            }
        }
    });
    // Others are served meanwhile.
    assert_eq!(
        Client::connect(addr)
            .request("GET", "/healthz", &[], b"")
            .status,
        200
    );
    wait_for_metric(addr, "voxtrace_write_timeouts_total", 1);
    let cut = sent.elapsed();
    // Its render (well under a second) plus the write deadline, with room
    // for a busy machine; a per-write timeout would let it run 20 s.
    assert!(
        cut >= write_timeout && cut < Duration::from_secs(8),
        "cut off after {cut:?}"
    );
    // The connection is closed: the client gets what was already in the
    // sockets' buffers, then the end, short of the whole image.
    hurry.store(true, Ordering::Relaxed);
    let received = reader.join().unwrap();
    assert!(received < full_length, "received {received} bytes");
    let mut client = Client::connect(addr);
    assert_eq!(client.request("GET", "/healthz", &[], b"").status, 200);
    // Open now: that client and the /metrics request.
    wait_for_metric(addr, "voxtrace_open_connections", 2);
}
