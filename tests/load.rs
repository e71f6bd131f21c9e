//! `voxtrace load` against a real service on an ephemeral port, and as a
//! process: its exit code, its messages and its wall time.

mod support;

use std::process::{Command, Output};
use std::time::{Duration, Instant};
use support::scripted::{self, Script};
use voxtrace::limits::DEFAULT_LOAD_MAX_CONNECTIONS;
use voxtrace::service::ServiceConfig;
use voxtrace::tools::load::{self, LoadConfig, Until, Url};

fn config(url: String, body: Option<Vec<u8>>, concurrency: usize, until: Until) -> LoadConfig {
    LoadConfig {
        url: Url::parse(&url).unwrap(),
        body,
        concurrency,
        max_connections: DEFAULT_LOAD_MAX_CONNECTIONS,
        until,
        rate: None,
        grace: Duration::from_secs(1),
        timeout: Duration::from_secs(30),
        in_process: false,
        progress: false,
    }
}

fn sample() -> Vec<u8> {
    support::sample("testSample.txt")
}

/// `voxtrace load ARGS`, with its output and how long it took.
fn voxtrace_load(args: &[&str]) -> (Output, Duration) {
    let started = Instant::now();
    let output = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .arg("load")
        .args(args)
        .output()
        .unwrap();
    (output, started.elapsed())
}

fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

fn json(output: &Output) -> serde_json::Value {
    serde_json::from_slice(&output.stdout).unwrap_or_else(|e| panic!("{e}: {}", stdout(output)))
}

/// An address nothing listens on: a port just given back by the system.
fn closed_port() -> std::net::SocketAddr {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.local_addr().unwrap()
}

#[test]
fn closed_loop_counts_renders_rays_and_statuses() {
    let server = support::start(ServiceConfig::default());
    let url = format!("http://{}/render?spp=1", server.addr());
    let cfg = config(url, Some(sample()), 4, Until::Requests(12));
    let report = load::run(&cfg).unwrap();
    assert_eq!(report.requests, 12);
    assert_eq!(report.status.get(&200), Some(&12));
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    assert_eq!(report.renders, 12);
    assert!(report.rays >= 12 * 600 * 600);
    assert!(report.latency.p50 > Duration::ZERO && report.latency.p50 <= report.latency.max);
    assert_eq!(report.verdict(), Ok(()));

    let json = report.to_json(&cfg);
    assert_eq!(json["status"]["200"], 12);
    assert_eq!(json["errors"], serde_json::json!({}));
    for key in ["p50", "p90", "p99", "p999", "max", "mean"] {
        assert!(json["latency_ms"][key].as_f64().unwrap() > 0.0, "{key}");
    }
    let counted: u64 = json["histogram"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["count"].as_u64().unwrap())
        .sum();
    assert_eq!(counted, 12);
    assert!(json["requests_per_s"].as_f64().unwrap() > 0.0);

    // The same work in process reports the same rays per render.
    let in_process = load::run(&LoadConfig {
        in_process: true,
        until: Until::Requests(2),
        ..cfg
    })
    .unwrap();
    assert_eq!(
        (in_process.renders, in_process.rays / 2),
        (2, report.rays / 12)
    );
}

#[test]
fn open_loop_keeps_its_schedule_and_counts_rejections_and_transport_errors() {
    let server = support::start(ServiceConfig::default());
    let healthz = format!("http://{}/healthz", server.addr());
    let window = Duration::from_millis(500);
    let started = Instant::now();
    let report = load::run(&LoadConfig {
        rate: Some(200.0),
        ..config(healthz, None, 2, Until::Elapsed(window))
    })
    .unwrap();
    // The schedule, not the machine, sets how many are due: 200 req/s for
    // 0.5 s is 100 requests, the last due at 495 ms. How many of them are
    // sent and answered depends on the machine; every one is counted,
    // unfinished or not sent.
    assert_eq!(report.scheduled, 100, "200 req/s for 0.5 s");
    assert_eq!(report.requests + report.unfinished + report.not_sent, 100);
    assert_eq!(report.status.get(&200), Some(&report.requests));
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    assert_eq!(report.window, window);
    assert!(report.elapsed >= window && report.elapsed <= window + report.grace);
    // None is sent before it is due.
    assert!(started.elapsed() >= Duration::from_millis(495));

    // A POST of a broken scene: every answer a 400, none a render, and
    // the run fails with the service's message.
    let render = format!("http://{}/render", server.addr());
    let report = load::run(&config(
        render,
        Some(b"NEAR x\n".to_vec()),
        2,
        Until::Requests(6),
    ))
    .unwrap();
    assert_eq!((report.status.get(&400), report.renders), (Some(&6), 0));
    assert!(
        report.status_samples[&400].contains("--> request body:1:6"),
        "{:?}",
        report.status_samples
    );
    let failure = report.verdict().unwrap_err();
    assert!(failure.is_input_error(), "{failure}");

    let addr = server.addr();
    drop(server);
    let report = load::run(&config(
        format!("http://{addr}/healthz"),
        None,
        1,
        Until::Requests(3),
    ))
    .unwrap();
    assert_eq!(report.errors.get("connect"), Some(&3));
    let failure = report.verdict().unwrap_err();
    assert!(!failure.is_input_error(), "{failure}");
}

#[test]
fn a_kept_alive_connection_closed_by_the_server_while_idle_is_replaced_not_counted_as_an_error() {
    let server = support::start(ServiceConfig {
        idle_timeout: Duration::from_millis(50),
        ..ServiceConfig::default()
    });
    let healthz = format!("http://{}/healthz", server.addr());
    // Six requests 100 ms apart, each after the server has closed the
    // connection the last one left idle. Counted by number, not by a time
    // window, so a late answer on a busy machine still counts.
    let report = load::run(&LoadConfig {
        rate: Some(10.0),
        ..config(healthz, None, 1, Until::Requests(6))
    })
    .unwrap();
    assert_eq!(report.status.get(&200), Some(&6), "{report:?}");
    assert!(report.errors.is_empty(), "{:?}", report.errors);
}

/// In process and over HTTP, a request runs the service's one render path:
/// what the service refuses (a bad spp, a broken scene) is refused in
/// process with the same status, and nothing is rendered.
#[test]
fn in_process_refuses_what_the_service_refuses() {
    let server = support::start(ServiceConfig::default());
    for (query, body) in [
        ("spp=0", sample()),
        ("spp=two", sample()),
        ("depth=65", sample()),
        ("format=gif", sample()),
        ("", b"NEAR x\n".to_vec()),
    ] {
        let url = format!("http://{}/render?{query}", server.addr());
        let over_http = config(url, Some(body), 1, Until::Requests(2));
        let in_process = LoadConfig {
            in_process: true,
            ..over_http.clone()
        };
        for cfg in [over_http, in_process] {
            let report = load::run(&cfg).unwrap();
            assert_eq!(
                (report.status.get(&400), report.renders),
                (Some(&2), 0),
                "{query} in process: {}",
                cfg.in_process
            );
        }
    }
}

/// Renders that cannot finish (nested glass at depth 64 runs until the
/// service's budget, a minute here) are in flight when the window closes:
/// the run still ends at the window plus its grace, they count as
/// unfinished, and the service, seeing its clients leave, drops them.
#[test]
fn a_run_for_a_duration_stops_at_its_window_and_grace() {
    let server = support::start(ServiceConfig {
        render_timeout: Duration::from_secs(60),
        ..ServiceConfig::default()
    });
    let scene =
        std::env::temp_dir().join(format!("voxtrace-load-glass-{}.txt", std::process::id()));
    std::fs::write(&scene, support::nested_glass()).unwrap();
    let url = format!("http://{}/render?depth=64", server.addr());
    let (output, wall) = voxtrace_load(&[
        "--url",
        &url,
        "--scene",
        scene.to_str().unwrap(),
        "--rate",
        "10",
        "-d",
        "1s",
        "--grace",
        "500ms",
        "--json",
    ]);
    let _ = std::fs::remove_file(&scene);
    // 1.5 s of window and grace, and a margin for a loaded machine that is
    // still far below the render budget the run would otherwise wait out.
    assert!(wall < Duration::from_secs(8), "took {wall:?}");
    let report = json(&output);
    assert_eq!(report["scheduled"], 10, "{report}");
    assert_eq!(report["requests"], 0, "{report}");
    let (unfinished, not_sent) = (
        report["unfinished"].as_u64().unwrap(),
        report["not_sent"].as_u64().unwrap(),
    );
    assert_eq!(unfinished + not_sent, 10, "{report}");
    assert!(unfinished >= 1, "{report}");
    // Nothing succeeded: a failure of the service, not of the input.
    assert_eq!(output.status.code(), Some(1), "{}", stderr(&output));
    assert!(
        stderr(&output).contains("unfinished"),
        "{}",
        stderr(&output)
    );
    support::wait_for_metric(server.addr(), "voxtrace_renders_in_flight", 0);
    support::wait_for_metric(server.addr(), "voxtrace_render_queue_depth", 0);
}

/// With the default flags (one connection to start with), the open loop
/// opens what it needs to keep 500 requests/s for 2 s: at least 95% of
/// the 1,000 due are sent and answered inside the window and grace.
#[test]
fn the_open_loop_reaches_500_requests_per_second_with_default_flags() {
    let server = support::start(ServiceConfig::default());
    let url = format!("http://{}/healthz", server.addr());
    let (output, _) = voxtrace_load(&["--url", &url, "--rate", "500", "-d", "2s", "--json"]);
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    let report = json(&output);
    assert_eq!(report["scheduled"], 1000);
    let sent = report["sent"].as_u64().unwrap();
    let answered = report["status"]["200"].as_u64().unwrap_or(0);
    assert!(sent >= 950 && answered >= 950, "{report}");
    assert!(!stderr(&output).contains("warning"), "{}", stderr(&output));
}

/// A server that takes 100 ms over each answer needs five connections for
/// 50 requests/s; the open loop, starting with one, opens them as requests
/// fall due. Counted by number, not in a window, so a late start on a
/// loaded machine still sends them all; at least three, so that one slow
/// wake-up of the machine cannot fail it.
#[test]
fn the_open_loop_opens_connections_as_it_needs_them() {
    let addr = scripted::serve(|_| Script::Answer(Duration::from_millis(100)));
    let report = load::run(&LoadConfig {
        rate: Some(50.0),
        ..config(format!("http://{addr}/"), None, 1, Until::Requests(50))
    })
    .unwrap();
    assert_eq!(report.status.get(&200), Some(&50), "{report:?}");
    assert!(
        (3..=50).contains(&report.connections),
        "{} connections",
        report.connections
    );
}

/// One connection at 100 ms an answer cannot send 100 requests/s: the run
/// warns with the rate it reached, and counts what it could not send.
#[test]
fn an_open_loop_short_of_its_rate_warns() {
    let addr = scripted::serve(|_| Script::Answer(Duration::from_millis(100)));
    let url = format!("http://{addr}/");
    let (output, _) = voxtrace_load(&[
        "--url",
        &url,
        "--rate",
        "100",
        "-d",
        "1s",
        "--max-connections",
        "1",
        "--json",
    ]);
    let report = json(&output);
    let not_sent = report["not_sent"].as_u64().unwrap();
    assert_eq!(report["sent"].as_u64().unwrap() + not_sent, 100, "{report}");
    assert!(not_sent >= 50, "{report}");
    let err = stderr(&output);
    assert!(err.contains("warning: sent "), "{err}");
    assert!(err.contains("of the 100 req/s offered"), "{err}");
    assert!(err.contains("--max-connections raises the cap"), "{err}");
    // What was answered succeeded: a warning, not a failure.
    assert_eq!(output.status.code(), Some(0), "{err}");
}

#[test]
fn no_server_fails_with_the_connect_error() {
    let addr = closed_port();
    let url = format!("http://{addr}/healthz");
    let (output, _) = voxtrace_load(&["--url", &url, "-n", "3"]);
    assert_eq!(output.status.code(), Some(1), "{}", stdout(&output));
    let err = stderr(&output);
    assert!(
        err.contains("no request succeeded: 3 connect errors"),
        "{err}"
    );
    assert!(err.to_lowercase().contains("connection refused"), "{err}");
    let out = stdout(&output);
    assert!(out.contains("errors     connect: 3"), "{out}");
    assert!(out.contains("status     none"), "{out}");
}

#[test]
fn only_client_errors_fail_as_the_input_with_a_sample_body() {
    let server = support::start(ServiceConfig::default());
    let scene =
        std::env::temp_dir().join(format!("voxtrace-load-broken-{}.txt", std::process::id()));
    std::fs::write(&scene, "NEAR x\n").unwrap();
    let render = format!("http://{}/render", server.addr());
    let (output, _) = voxtrace_load(&[
        "--url",
        &render,
        "--scene",
        scene.to_str().unwrap(),
        "-n",
        "3",
    ]);
    let _ = std::fs::remove_file(&scene);
    assert_eq!(output.status.code(), Some(2), "{}", stdout(&output));
    let err = stderr(&output);
    assert!(
        err.contains("no request succeeded: 3 answered 400"),
        "{err}"
    );
    assert!(
        err.contains("400: \"expected a number for the distance to the image plane"),
        "{err}"
    );
    assert!(
        stdout(&output).contains("  400      \"expected a number for the distance"),
        "{}",
        stdout(&output)
    );

    // A GET where only POST is allowed.
    let (output, _) = voxtrace_load(&["--url", &render, "-n", "2"]);
    assert_eq!(output.status.code(), Some(2), "{}", stdout(&output));
    assert!(
        stderr(&output).contains("no request succeeded: 2 answered 405"),
        "{}",
        stderr(&output)
    );
}

/// Three requests of four end without an answer: the one that succeeded
/// does not make the run a success.
#[test]
fn mostly_transport_errors_fail_the_run() {
    let addr = scripted::serve(|n| {
        if n == 0 {
            Script::Answer(Duration::ZERO)
        } else {
            Script::Hang
        }
    });
    let url = format!("http://{addr}/");
    let (output, _) = voxtrace_load(&["--url", &url, "-n", "4"]);
    assert_eq!(output.status.code(), Some(1), "{}", stdout(&output));
    let err = stderr(&output);
    assert!(err.contains("3 of 4 requests failed below HTTP"), "{err}");
    assert!(
        err.contains("closed: the server closed the connection without answering"),
        "{err}"
    );
}

#[test]
fn the_text_report_has_a_histogram_and_readable_units() {
    let server = support::start(ServiceConfig::default());
    let url = format!("http://{}/healthz", server.addr());
    let (output, _) = voxtrace_load(&["--url", &url, "-n", "20"]);
    assert_eq!(output.status.code(), Some(0), "{}", stderr(&output));
    let out = stdout(&output);
    assert!(out.contains("(closed loop, 1 connection)"), "{out}");
    assert!(out.contains("latency    mean "), "{out}");
    assert!(out.contains(" stdev "), "{out}");
    assert!(out.contains("histogram\n"), "{out}");
    let counted: u64 = out
        .lines()
        .filter(|l| l.contains(" |"))
        .map(|l| {
            let count = &l[l.find('[').unwrap() + 1..l.find(']').unwrap()];
            count.parse::<u64>().unwrap()
        })
        .sum();
    assert_eq!(counted, 20, "{out}");
    assert!(
        out.contains("received   ") && (out.contains(" KiB") || out.contains(" B =")),
        "{out}"
    );
}
