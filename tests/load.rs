//! `voxtrace load` against a real service on an ephemeral port.

use std::time::{Duration, Instant};
use voxtrace::service::{Server, ServiceConfig};
use voxtrace::tools::load::{self, LoadConfig, Until, Url};

fn serve(config: ServiceConfig) -> voxtrace::service::ServerHandle {
    let config = ServiceConfig {
        addr: "127.0.0.1:0".into(),
        ..config
    };
    Server::bind(config).unwrap().spawn().unwrap()
}

fn config(url: String, body: Option<Vec<u8>>, concurrency: usize, until: Until) -> LoadConfig {
    LoadConfig {
        url: Url::parse(&url).unwrap(),
        body,
        concurrency,
        until,
        rate: None,
        timeout: Duration::from_secs(30),
        in_process: false,
        progress: false,
    }
}

fn sample() -> Vec<u8> {
    std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/testSample.txt"
    ))
    .unwrap()
}

#[test]
fn closed_loop_counts_renders_rays_and_statuses() {
    let server = serve(ServiceConfig::default());
    let url = format!("http://{}/render?spp=1", server.addr());
    let cfg = config(url, Some(sample()), 4, Until::Requests(12));
    let report = load::run(&cfg).unwrap();
    assert_eq!(report.requests, 12);
    assert_eq!(report.status.get(&200), Some(&12));
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    assert_eq!(report.renders, 12);
    assert!(report.rays >= 12 * 600 * 600);
    assert!(report.latency.p50 > Duration::ZERO && report.latency.p50 <= report.latency.max);

    let json = report.to_json(&cfg);
    assert_eq!(json["status"]["200"], 12);
    assert_eq!(json["errors"], serde_json::json!({}));
    for key in ["p50", "p90", "p99", "p999", "max"] {
        assert!(json["latency_ms"][key].as_f64().unwrap() > 0.0, "{key}");
    }
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
    let server = serve(ServiceConfig::default());
    let healthz = format!("http://{}/healthz", server.addr());
    let window = Duration::from_millis(500);
    let started = Instant::now();
    let report = load::run(&LoadConfig {
        rate: Some(200.0),
        ..config(healthz, None, 2, Until::Elapsed(window))
    })
    .unwrap();
    // The schedule, not the machine, sets how many are sent: 200 req/s for
    // 0.5 s is 100 requests, the last due at 495 ms. How many of them are
    // answered inside the window depends on the machine; every one is
    // either counted or reported unfinished.
    assert_eq!(
        report.requests + report.unfinished,
        100,
        "200 req/s for 0.5 s"
    );
    assert_eq!(report.status.get(&200), Some(&report.requests));
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    assert_eq!(report.elapsed, window);
    // None is sent before it is due.
    assert!(started.elapsed() >= Duration::from_millis(495));

    // A POST of a broken scene: every answer a 400, none a render.
    let render = format!("http://{}/render", server.addr());
    let report = load::run(&config(
        render,
        Some(b"NEAR x\n".to_vec()),
        2,
        Until::Requests(6),
    ))
    .unwrap();
    assert_eq!((report.status.get(&400), report.renders), (Some(&6), 0));

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
}

#[test]
fn a_kept_alive_connection_closed_by_the_server_while_idle_is_replaced_not_counted_as_an_error() {
    let server = serve(ServiceConfig {
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
    assert_eq!(report.status.get(&200), Some(&6), "{report}");
    assert!(report.errors.is_empty(), "{:?}", report.errors);
}

/// In process and over HTTP, a request runs the service's one render path:
/// what the service refuses (a bad spp, a broken scene) is refused in
/// process with the same status, and nothing is rendered.
#[test]
fn in_process_refuses_what_the_service_refuses() {
    let server = serve(ServiceConfig::default());
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
