//! What `voxtrace serve` tells of itself: `/metrics` read by the Prometheus
//! project's own OpenMetrics parser after requests of every outcome, the
//! access log, and the line it prints when it stops.

use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use voxtrace::service::{AccessLogTarget, ServiceConfig};

mod support;
use support::{sample, start, Client, Reply};

/// A scene that renders in a moment: few pixels, one sphere, one light.
fn small_scene() -> Vec<u8> {
    b"NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 32 32\n\
      SPHERE s 0 0 -4 1 1 1 1 0 0 0.2 0.6 0.2 0 10\n\
      LIGHT l 0 5 0 1 1 1\n"
        .to_vec()
}

/// A service whose limits the requests below run into: images over
/// 64 × 64 pixels are refused, and a render gets 2 s (the small scene takes
/// well under a millisecond; the nested glass never ends).
fn limited() -> ServiceConfig {
    ServiceConfig {
        max_pixels: 64 * 64,
        render_timeout: std::time::Duration::from_secs(2),
        threads: voxtrace::threads::Threads::exactly(1).unwrap(),
        ..ServiceConfig::default()
    }
}

/// The requests each test makes, on one kept-alive connection (so each is
/// counted and timed before the next is read), with the status each gets:
/// a render, a malformed scene, an unknown path, a refusal for a limit, a
/// refusal for the time budget, a health check.
fn make_requests(client: &mut Client) -> Vec<(&'static str, u16, Reply)> {
    let big = b"NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 100 100\n".to_vec();
    let asked: [(&str, &str, Vec<u8>, u16); 6] = [
        ("POST", "/render", small_scene(), 200),
        ("POST", "/render", b"BAKC 1 1 1\n".to_vec(), 400),
        ("GET", "/nowhere", Vec::new(), 404),
        ("POST", "/render", big, 422),
        ("POST", "/render?depth=64", support::nested_glass(), 504),
        ("GET", "/healthz", Vec::new(), 200),
    ];
    asked
        .into_iter()
        .map(|(method, target, body, expected)| {
            let reply = client.request(method, target, &[], &body);
            assert_eq!(
                reply.status,
                expected,
                "{method} {target}: {}",
                reply.text()
            );
            (method, expected, reply)
        })
        .collect()
}

/// A Python that has the Prometheus client library, the parser's home.
fn python_with_parser() -> PathBuf {
    let candidates = std::env::var_os("VOXTRACE_PYTHON")
        .map(PathBuf::from)
        .into_iter()
        .chain(["python3".into(), "/usr/bin/python3".into()]);
    for python in candidates {
        let found = Command::new(&python)
            .args(["-c", "import prometheus_client.openmetrics.parser"])
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if found {
            return python;
        }
    }
    panic!(
        "no python3 with prometheus_client: install Debian's python3-prometheus-client \
         (scripts/test does) or set VOXTRACE_PYTHON"
    );
}

/// `text` parsed by `prometheus_client.openmetrics.parser`, as JSON.
fn parse_openmetrics(text: &str) -> Vec<Value> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/support/openmetrics.py");
    let mut child = Command::new(python_with_parser())
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(text.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}\n{text}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice::<Value>(&out.stdout)
        .unwrap()
        .as_array()
        .unwrap()
        .clone()
}

fn family<'a>(families: &'a [Value], name: &str) -> &'a Value {
    families
        .iter()
        .find(|f| f["name"] == name)
        .unwrap_or_else(|| panic!("no family {name}"))
}

fn samples<'a>(family: &'a Value, name: &'a str) -> impl Iterator<Item = &'a Value> {
    family["samples"]
        .as_array()
        .unwrap()
        .iter()
        .filter(move |s| s["name"] == name)
}

fn label_names(sample: &Value) -> BTreeSet<String> {
    sample["labels"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect()
}

/// The one sample of `name` whose labels include `labels`.
fn value(family: &Value, name: &str, labels: &[(&str, &str)]) -> f64 {
    let found: Vec<f64> = samples(family, name)
        .filter(|s| labels.iter().all(|(k, v)| s["labels"][k] == *v))
        .map(|s| s["value"].as_f64().unwrap())
        .collect();
    assert_eq!(found.len(), 1, "{name} {labels:?}: {found:?}");
    found[0]
}

/// Per label set (without `le`), the histogram's buckets in order of `le`:
/// every one at most the next, the last `+Inf` and equal to `_count`.
fn check_histogram(family: &Value) -> f64 {
    let name = family["name"].as_str().unwrap();
    let mut buckets: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for s in samples(family, &format!("{name}_bucket")) {
        let mut labels = s["labels"].as_object().unwrap().clone();
        let le = labels.remove("le").unwrap();
        let le: f64 = le.as_str().unwrap().parse().unwrap();
        let key = serde_json::to_string(&labels).unwrap();
        buckets
            .entry(key)
            .or_default()
            .push((le, s["value"].as_f64().unwrap()));
    }
    assert!(!buckets.is_empty(), "{name} has no buckets");
    let mut total = 0.0;
    for (labels, series) in &buckets {
        let les: Vec<f64> = series.iter().map(|b| b.0).collect();
        assert!(les.windows(2).all(|w| w[0] < w[1]), "{labels}: {les:?}");
        assert_eq!(les.last(), Some(&f64::INFINITY), "{labels}");
        let counts: Vec<f64> = series.iter().map(|b| b.1).collect();
        assert!(
            counts.windows(2).all(|w| w[0] <= w[1]),
            "{labels}: {counts:?}"
        );
        let count = samples(family, &format!("{name}_count"))
            .find(|s| {
                let labels_of = serde_json::to_string(&s["labels"]).unwrap();
                labels_of == *labels
            })
            .unwrap_or_else(|| panic!("no _count for {labels}"))["value"]
            .as_f64()
            .unwrap();
        assert_eq!(counts.last(), Some(&count), "{labels}");
        total += count;
    }
    total
}

#[test]
#[ignore = "needs Python's prometheus_client: scripts/test installs it and runs this"]
fn metrics_after_every_kind_of_answer_parse_as_openmetrics_with_prometheus_names() {
    let server = start(limited());
    let mut client = Client::connect(server.addr());
    let made = make_requests(&mut client);
    let scrape = client.request("GET", "/metrics", &[], b"");
    assert_eq!(scrape.status, 200);
    assert_eq!(
        scrape.header("content-type"),
        Some("application/openmetrics-text; version=1.0.0; charset=utf-8")
    );
    let families = parse_openmetrics(&scrape.text());

    let types: BTreeMap<&str, &str> = families
        .iter()
        .map(|f| (f["name"].as_str().unwrap(), f["type"].as_str().unwrap()))
        .collect();
    let mut expected = vec![
        ("voxtrace_build_info", "gauge"),
        ("voxtrace_http_requests", "counter"),
        ("voxtrace_http_request_duration_seconds", "histogram"),
        ("voxtrace_errors", "counter"),
        ("voxtrace_render_refusals", "counter"),
        ("voxtrace_renders", "counter"),
        ("voxtrace_render_seconds", "histogram"),
        ("voxtrace_rays", "counter"),
        ("voxtrace_renders_abandoned", "counter"),
        ("voxtrace_renders_stopped", "counter"),
        ("voxtrace_render_overshoot_max_seconds", "gauge"),
        ("voxtrace_write_timeouts", "counter"),
        ("voxtrace_render_queue_depth", "gauge"),
        ("voxtrace_renders_in_flight", "gauge"),
        ("voxtrace_body_bytes", "gauge"),
        ("voxtrace_memory_charged_bytes", "gauge"),
        ("voxtrace_memory_budget_bytes", "gauge"),
        ("voxtrace_open_connections", "gauge"),
        ("voxtrace_access_log_dropped_lines", "counter"),
    ];
    if cfg!(target_os = "linux") {
        expected.extend([
            ("process_cpu_seconds", "counter"),
            ("process_resident_memory_bytes", "gauge"),
            ("process_virtual_memory_bytes", "gauge"),
            ("process_open_fds", "gauge"),
            ("process_max_fds", "gauge"),
            ("process_threads", "gauge"),
            ("process_start_time_seconds", "gauge"),
        ]);
    }
    for (name, kind) in expected {
        assert_eq!(types.get(name), Some(&kind), "{name} in {types:?}");
    }

    let build = family(&families, "voxtrace_build_info");
    let version = env!("CARGO_PKG_VERSION");
    assert_eq!(
        value(build, "voxtrace_build_info", &[("version", version)]),
        1.0
    );

    // Both HTTP families carry exactly the conventional labels, and count
    // each request made once: the scrape itself is not in its own answer.
    let http_labels: BTreeSet<String> = ["code", "handler", "method"].map(String::from).into();
    let requests = family(&families, "voxtrace_http_requests");
    let counted: f64 = samples(requests, "voxtrace_http_requests_total")
        .inspect(|s| assert_eq!(label_names(s), http_labels, "{s}"))
        .map(|s| s["value"].as_f64().unwrap())
        .sum();
    assert_eq!(counted, made.len() as f64);
    let durations = family(&families, "voxtrace_http_request_duration_seconds");
    assert_eq!(durations["unit"], "seconds");
    for s in samples(durations, "voxtrace_http_request_duration_seconds_count") {
        assert_eq!(label_names(s), http_labels, "{s}");
    }
    assert_eq!(check_histogram(durations), made.len() as f64);
    for (method, code, _) in &made {
        let code = code.to_string();
        let labels = [("method", *method), ("code", code.as_str())];
        let n = made
            .iter()
            .filter(|(m, c, _)| m == method && c.to_string() == code)
            .count();
        let name = "voxtrace_http_requests_total";
        assert_eq!(value(requests, name, &labels), n as f64);
    }
    let render_504 = [("handler", "/render"), ("method", "POST"), ("code", "504")];
    let name = "voxtrace_http_request_duration_seconds_sum";
    assert!(
        value(durations, name, &render_504) >= 2.0,
        "the 504 ran its budget"
    );
    check_histogram(family(&families, "voxtrace_render_seconds"));

    // A limit and the time budget are told apart.
    let refusals = family(&families, "voxtrace_render_refusals");
    let name = "voxtrace_render_refusals_total";
    assert_eq!(value(refusals, name, &[("reason", "limit")]), 1.0);
    assert_eq!(value(refusals, name, &[("reason", "time_budget")]), 1.0);
    for reason in ["busy", "memory", "draining"] {
        assert_eq!(value(refusals, name, &[("reason", reason)]), 0.0);
    }

    // Rays by kind add up to what the render said it traced.
    let rays = family(&families, "voxtrace_rays");
    let kinds: BTreeSet<&str> = samples(rays, "voxtrace_rays_total")
        .map(|s| s["labels"]["kind"].as_str().unwrap())
        .collect();
    assert_eq!(
        kinds,
        BTreeSet::from(["eye", "reflection", "refraction", "shadow"])
    );
    let traced: f64 = samples(rays, "voxtrace_rays_total")
        .map(|s| s["value"].as_f64().unwrap())
        .sum();
    let header = made[0].2.header("x-rays").unwrap();
    assert_eq!(traced, header.parse::<f64>().unwrap());
    assert_eq!(
        value(rays, "voxtrace_rays_total", &[("kind", "eye")]),
        1024.0
    );

    if cfg!(target_os = "linux") {
        let rss = family(&families, "process_resident_memory_bytes");
        assert!(value(rss, "process_resident_memory_bytes", &[]) > 1e6);
        let fds = family(&families, "process_open_fds");
        assert!(value(fds, "process_open_fds", &[]) >= 3.0);
    }
}

/// One line of the access log, taken apart as a combined-format parser
/// does: `peer - - [time] "request" code bytes "referer" "agent" seconds`.
#[derive(Debug)]
struct LogLine {
    peer: String,
    time: String,
    request: String,
    code: u16,
    bytes: u64,
    agent: String,
    seconds: f64,
}

fn not_combined<T>(line: &str) -> T {
    panic!("not a combined log line: {line:?}")
}

fn parse_log_line(line: &str) -> LogLine {
    let (peer, rest) = line
        .split_once(" - - [")
        .unwrap_or_else(|| not_combined(line));
    let (time, rest) = rest
        .split_once("] \"")
        .unwrap_or_else(|| not_combined(line));
    let (request, rest) = rest.split_once("\" ").unwrap_or_else(|| not_combined(line));
    let mut words = rest.splitn(3, ' ');
    let code = words
        .next()
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| not_combined(line));
    let bytes = words
        .next()
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| not_combined(line));
    let quoted = words.next().unwrap_or_else(|| not_combined(line));
    let parts: Vec<&str> = quoted.split('"').collect();
    // "referer" "agent" seconds → ["", referer, " ", agent, " seconds"]
    assert_eq!(parts.len(), 5, "{line:?}");
    let seconds = parts[4]
        .trim()
        .parse()
        .unwrap_or_else(|_| not_combined(line));
    let time_ok = time.len() == 26
        && time.ends_with(" +0000")
        && time.as_bytes()[2] == b'/'
        && time.as_bytes()[6] == b'/'
        && time.as_bytes()[11] == b':';
    assert!(time_ok, "time {time:?} in {line:?}");
    LogLine {
        peer: peer.to_owned(),
        time: time.to_owned(),
        request: request.to_owned(),
        code,
        bytes,
        agent: parts[3].to_owned(),
        seconds,
    }
}

fn temp_log(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxtrace-metrics-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    let _ = std::fs::remove_file(&path);
    path
}

#[test]
fn the_access_log_has_one_combined_line_per_request() {
    let path = temp_log("access.log");
    let server = start(ServiceConfig {
        access_log: Some(AccessLogTarget::File(path.clone())),
        ..limited()
    });
    let mut client = Client::connect(server.addr());
    let made = make_requests(&mut client);
    let head = client.request("HEAD", "/healthz", &["User-Agent: probe \"1\""], b"");
    assert_eq!(head.status, 200);
    drop(client);
    // A request line that is not HTTP: answered 400 with no request to name.
    let mut garbage = Client::connect(server.addr());
    garbage.send(b"NOT HTTP AT ALL\r\n\r\n");
    assert_eq!(garbage.read_reply(false).status, 400);
    drop(garbage);
    // Stopping writes out what the log has queued.
    server.stop();

    let text = std::fs::read_to_string(&path).unwrap();
    let lines: Vec<LogLine> = text.lines().map(parse_log_line).collect();
    assert_eq!(lines.len(), made.len() + 2, "{text}");
    let targets = [
        "POST /render HTTP/1.1",
        "POST /render HTTP/1.1",
        "GET /nowhere HTTP/1.1",
        "POST /render HTTP/1.1",
        "POST /render?depth=64 HTTP/1.1",
        "GET /healthz HTTP/1.1",
    ];
    for ((line, (_, code, reply)), target) in lines.iter().zip(&made).zip(targets) {
        assert_eq!(line.peer, "127.0.0.1");
        assert_eq!((line.request.as_str(), line.code), (target, *code));
        assert_eq!(line.bytes, reply.body.len() as u64, "{line:?}");
        assert!(line.seconds >= 0.0);
    }
    assert!(
        lines[4].seconds >= 2.0,
        "the 504 ran its budget: {:?}",
        lines[4]
    );
    let head_line = &lines[made.len()];
    assert_eq!(
        (head_line.request.as_str(), head_line.code, head_line.bytes),
        ("HEAD /healthz HTTP/1.1", 200, 0)
    );
    assert_eq!(head_line.agent, "probe \\x221\\x22");
    let garbage_line = &lines[made.len() + 1];
    assert_eq!(
        (garbage_line.request.as_str(), garbage_line.code),
        ("-", 400)
    );
    assert!(!lines[0].time.is_empty());
    std::fs::remove_file(&path).unwrap();
}

#[cfg(target_os = "linux")]
#[test]
fn a_log_that_cannot_be_written_drops_lines_and_serving_goes_on() {
    let server = start(ServiceConfig {
        access_log: Some(AccessLogTarget::File("/dev/full".into())),
        ..ServiceConfig::default()
    });
    let addr = server.addr();
    let mut client = Client::connect(addr);
    for _ in 0..5 {
        assert_eq!(client.request("GET", "/healthz", &[], b"").status, 200);
    }
    let render = client.request("POST", "/render", &[], &small_scene());
    assert_eq!(render.status, 200);
    // Each scrape is a request of its own, whose line is dropped too: at
    // least the six lines above.
    let dropped = "voxtrace_access_log_dropped_lines_total";
    support::wait_until(addr, dropped, |n| n >= 6);
    assert_eq!(client.request("GET", "/healthz", &[], b"").status, 200);
}

#[test]
fn an_access_log_that_cannot_be_opened_stops_serve_with_a_message() {
    let out = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .args(["serve", "--addr", "127.0.0.1:0"])
        .args(["--access-log", "/nonexistent-voxtrace-dir/access.log"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("cannot open the access log /nonexistent-voxtrace-dir/access.log"),
        "{stderr}"
    );
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[test]
fn sigterm_prints_what_was_served_after_the_log_on_stdout() {
    let mut server = support::ServeProcess::start(&["--threads", "1", "--access-log", "-"]);
    let addr = server.addr;
    let mut client = Client::connect(addr);
    assert_eq!(client.request("GET", "/healthz", &[], b"").status, 200);
    let render = client.request("POST", "/render", &[], &sample("testSample.txt"));
    assert_eq!(render.status, 200);
    assert_eq!(client.request("GET", "/nowhere", &[], b"").status, 404);
    drop(client);
    server.signal(libc::SIGTERM);
    let (status, stdout) = server.wait_for_exit();
    assert_eq!(status.code(), Some(0), "{stdout}");
    let lines: Vec<&str> = stdout.lines().collect();
    let logged: Vec<LogLine> = lines
        .iter()
        .filter(|l| l.contains(" - - ["))
        .map(|l| parse_log_line(l))
        .collect();
    let codes: Vec<u16> = logged.iter().map(|l| l.code).collect();
    assert_eq!(codes, [200, 200, 404], "{stdout}");
    let last = lines.last().copied().unwrap_or_default();
    let uptime = last
        .strip_prefix("served 3 requests (1 render) in ")
        .and_then(|rest| rest.strip_suffix(" s"))
        .and_then(|s| s.parse::<f64>().ok());
    assert!(uptime.is_some_and(|s| s >= 0.0), "{stdout}");
}
