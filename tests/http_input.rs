//! What `POST /render` makes of the ways clients send a scene and say what
//! they want: a `curl -F` form, a `curl -d` body that lost its line breaks,
//! `Expect: 100-continue` to a request that will be refused, query typos,
//! and `Accept`. Spoken over raw TCP to the in-process server.

use voxtrace::service::ServiceConfig;

mod support;
use support::{sample, start, Client};

/// The boundary curl 8 writes.
const CURL_BOUNDARY: &str = "------------------------a6abca43715a41";

/// A `multipart/form-data` body as `curl -F NAME=@FILE` writes it for each
/// `(name, filename, content)`, with its Content-Type header line.
fn curl_form(parts: &[(&str, &str, &[u8])]) -> (String, Vec<u8>) {
    let mut body = Vec::new();
    for (name, filename, content) in parts {
        body.extend_from_slice(
            format!(
                "--{CURL_BOUNDARY}\r\nContent-Disposition: form-data; name=\"{name}\"; \
                 filename=\"{filename}\"\r\nContent-Type: text/plain\r\n\r\n"
            )
            .as_bytes(),
        );
        body.extend_from_slice(content);
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(format!("--{CURL_BOUNDARY}--\r\n").as_bytes());
    let header = format!("Content-Type: multipart/form-data; boundary={CURL_BOUNDARY}");
    (header, body)
}

/// A request head with `Expect: 100-continue` that announces `length`
/// body bytes and sends none of them.
fn expecting_continue(method: &str, target: &str, headers: &str, length: usize) -> Vec<u8> {
    format!(
        "{method} {target} HTTP/1.1\r\nHost: t\r\n{headers}Expect: 100-continue\r\n\
         Content-Length: {length}\r\n\r\n"
    )
    .into_bytes()
}

#[test]
fn a_curl_form_renders_the_same_png_as_the_raw_body() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());
    let scene = sample("testSample.txt");
    let raw = client.request("POST", "/render", &[], &scene);
    assert_eq!(raw.status, 200, "{}", raw.text());

    let (content_type, form) = curl_form(&[("scene", "testSample.txt", &scene)]);
    let reply = client.request("POST", "/render", &[&content_type], &form);
    assert_eq!(reply.status, 200, "{}", reply.text());
    assert_eq!(reply.header("content-type"), Some("image/png"));
    assert!(
        reply.body == raw.body,
        "the form's PNG differs from the raw body's"
    );

    // A browser's form: another boundary, quoted, with a preamble-free body.
    let browser = format!(
        "------WebKitFormBoundaryx\r\nContent-Disposition: form-data; name=\"file\"; \
         filename=\"s.txt\"\r\nContent-Type: application/octet-stream\r\n\r\n{}\r\n\
         ------WebKitFormBoundaryx--\r\n",
        String::from_utf8(scene).unwrap()
    );
    let reply = client.request(
        "POST",
        "/render",
        &["Content-Type: multipart/form-data; boundary=\"----WebKitFormBoundaryx\""],
        browser.as_bytes(),
    );
    assert_eq!(reply.status, 200, "{}", reply.text());
    assert!(reply.body == raw.body, "the browser form's PNG differs");
}

#[test]
fn malformed_forms_get_400_naming_the_fault() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());
    let scene = sample("testSample.txt");
    let json = "Accept: application/json";
    let refused = |client: &mut Client, content_type: &str, body: &[u8], says: &str| {
        let reply = client.request("POST", "/render", &[content_type, json], body);
        assert_eq!(reply.status, 400, "{says}: {}", reply.text());
        let body = reply.json();
        assert_eq!(body["error"], "form", "{says}");
        let message = body["message"].as_str().unwrap().to_owned();
        assert!(message.contains(says), "{message:?} does not say {says:?}");
    };

    let (content_type, form) = curl_form(&[("scene", "testSample.txt", &scene)]);
    refused(
        &mut client,
        "Content-Type: multipart/form-data",
        &form,
        "needs a boundary=",
    );
    let (_, two) = curl_form(&[("scene", "a.txt", &scene), ("other", "b.txt", b"NEAR 1")]);
    refused(
        &mut client,
        &content_type,
        &two,
        "2 file parts (\"scene\", \"other\")",
    );
    refused(
        &mut client,
        &content_type,
        &form[..form.len() - 10],
        "closing line",
    );
    refused(&mut client, &content_type, &scene, "has no line");
    let with_field = [
        &form[..form.len() - CURL_BOUNDARY.len() - 6],
        format!(
            "--{CURL_BOUNDARY}\r\nContent-Disposition: form-data; name=\"spp\"\r\n\r\n4\r\n\
             --{CURL_BOUNDARY}--\r\n"
        )
        .as_bytes(),
    ]
    .concat();
    refused(
        &mut client,
        &content_type,
        &with_field,
        "fields beside the scene file (\"spp\")",
    );
    // Each body was read to its end: the connection still serves.
    assert_eq!(client.request("GET", "/healthz", &[], b"").status, 200);
}

#[test]
fn a_body_without_line_breaks_gets_the_curl_hint() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());
    let hint = "hint: the body has no line breaks; `curl -d` strips them: \
                send the file with `--data-binary @FILE`";
    let flattened: Vec<u8> = sample("testSample.txt")
        .into_iter()
        .filter(|b| !matches!(b, b'\r' | b'\n'))
        .collect();
    let expected = voxtrace::scene::parse(&flattened).unwrap_err();
    let reply = client.request(
        "POST",
        "/render",
        &["Content-Type: application/x-www-form-urlencoded"],
        &flattened,
    );
    assert_eq!(reply.status, 400);
    let line = voxtrace::scene::line_text(&flattened, expected.line);
    let shown = voxtrace::scene::Diagnostic::new(&expected, "request body", line.as_deref());
    assert_eq!(reply.text(), format!("{shown}\n{hint}\n"));
    let reply = client.request("POST", "/render", &["Accept: application/json"], &flattened);
    let body = reply.json();
    assert_eq!(body["error"], "scene");
    assert_eq!(body["message"], format!("{expected}\n{hint}"));

    let broken = String::from_utf8(sample("testSample.txt"))
        .unwrap()
        .replace("LEFT -1", "LEFT abc");
    let reply = client.request("POST", "/render", &[], broken.as_bytes());
    assert_eq!(reply.status, 400);
    assert!(!reply.text().contains("hint"), "{}", reply.text());
}

#[test]
fn refusals_the_head_decides_come_without_100_continue() {
    let server = start(ServiceConfig {
        max_body: 1000,
        ..ServiceConfig::default()
    });
    for (request, status) in [
        (expecting_continue("PUT", "/render", "", 500), 405),
        (expecting_continue("POST", "/nowhere", "", 500), 404),
        (expecting_continue("POST", "/healthz", "", 500), 405),
        (expecting_continue("POST", "/render?depht=3", "", 500), 400),
        (
            expecting_continue("POST", "/render", "Accept: text/html\r\n", 500),
            406,
        ),
        (expecting_continue("POST", "/render", "", 5000), 413),
    ] {
        let mut client = Client::connect(server.addr());
        client.send(&request);
        // The first answer is the final one: no `100 Continue` before it.
        let reply = client.read_reply(false);
        let line = String::from_utf8_lossy(&request[..20]).into_owned();
        assert_eq!(reply.status, status, "{line}: {}", reply.text());
        assert_eq!(reply.header("connection"), Some("close"), "{line}");
        assert!(client.closed(), "{line}");
        if status == 405 {
            assert!(reply.header("allow").is_some(), "{line}");
        }
    }
    let mut client = Client::connect(server.addr());
    client.send(&expecting_continue("PUT", "/render", "", 500));
    assert_eq!(client.read_reply(false).header("allow"), Some("POST"));

    // A request that will be served is still asked for its body.
    let scene = sample("testShadow.txt");
    let mut client = Client::connect(server.addr());
    client.send(&expecting_continue("POST", "/render", "", scene.len()));
    assert_eq!(client.read_reply(false).status, 100);
}

#[test]
fn unknown_and_repeated_query_parameters_are_refused_by_name() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());
    let scene = sample("testShadow.txt");
    let message = |client: &mut Client, target: &str| {
        let reply = client.request("POST", target, &["Accept: application/json"], &scene);
        assert_eq!(reply.status, 400, "{target}");
        assert_eq!(reply.json()["error"], "query", "{target}");
        reply.json()["message"].as_str().unwrap().to_owned()
    };
    let typo = message(&mut client, "/render?spp=2&depht=3");
    assert!(
        typo.starts_with("unknown query parameter \"depht\" (did you mean \"depth\"?);"),
        "{typo}"
    );
    let short = message(&mut client, "/render?sp=2");
    assert!(short.contains("\"sp\" (did you mean \"spp\"?)"), "{short}");
    let far = message(&mut client, "/render?quality=9");
    assert!(
        far.contains("\"quality\"; the parameters are format, spp, depth, region, rules"),
        "{far}"
    );
    let twice = message(&mut client, "/render?spp=2&spp=3");
    assert_eq!(twice, "query parameter \"spp\" is given more than once");
    // Encoded as a form encodes it, a known name is still known.
    let encoded = client.request(
        "POST",
        "/render?sp%70=2&region=0%2C0%2C10%2C10",
        &[],
        &scene,
    );
    assert_eq!(encoded.status, 200, "{}", encoded.text());
}

#[test]
fn accept_chooses_the_image_type_unless_format_is_given() {
    let server = start(ServiceConfig::default());
    let mut client = Client::connect(server.addr());
    let scene = sample("testShadow.txt");
    let ppm = client.request("POST", "/render?format=ppm", &[], &scene);
    assert_eq!(ppm.status, 200);
    let png = client.request("POST", "/render", &[], &scene);
    assert_eq!(png.header("content-type"), Some("image/png"));
    assert_eq!(png.header("vary"), Some("Accept"));

    for accept in [
        "image/x-portable-pixmap",
        "image/png;q=0.5, image/x-portable-pixmap",
        "image/png;q=0, */*",
        "image/x-portable-pixmap, application/json",
    ] {
        let reply = client.request("POST", "/render", &[&format!("Accept: {accept}")], &scene);
        assert_eq!(reply.status, 200, "{accept}: {}", reply.text());
        assert_eq!(
            reply.header("content-type"),
            Some("image/x-portable-pixmap"),
            "{accept}"
        );
        assert!(reply.body.starts_with(b"P6\n"), "{accept}");
        assert!(reply.body == ppm.body, "{accept}: not the PPM");
    }
    // Two Accept lines are one list (RFC 9110 §5.3).
    let two_lines = client.request(
        "POST",
        "/render",
        &["Accept: image/png;q=0", "Accept: */*"],
        &scene,
    );
    assert_eq!(
        two_lines.header("content-type"),
        Some("image/x-portable-pixmap")
    );
    for accept in [
        "image/*",
        "*/*",
        "application/json",
        "image/png;q=0.9, */*;q=0.1",
    ] {
        let reply = client.request("POST", "/render", &[&format!("Accept: {accept}")], &scene);
        assert_eq!(reply.header("content-type"), Some("image/png"), "{accept}");
        assert!(reply.body == png.body, "{accept}: not the PNG");
    }

    // The explicit `format=` wins over Accept.
    let reply = client.request(
        "POST",
        "/render?format=png",
        &["Accept: image/x-portable-pixmap"],
        &scene,
    );
    assert_eq!(reply.header("content-type"), Some("image/png"));
    let reply = client.request("POST", "/render?format=ppm", &["Accept: text/html"], &scene);
    assert_eq!(reply.status, 200);

    let refused = client.request("POST", "/render", &["Accept: text/html"], &scene);
    assert_eq!(refused.status, 406);
    assert!(
        refused
            .text()
            .contains("it sends image/png, image/x-portable-pixmap"),
        "{}",
        refused.text()
    );
    let refused = client.request(
        "POST",
        "/render",
        &["Accept: image/*;q=0, application/json"],
        &scene,
    );
    assert_eq!(
        (refused.status, refused.json()["error"].as_str()),
        (406, Some("not_acceptable"))
    );
}
