//! What the f32 fast path can represent (`scene::bounds`): scenes just
//! inside each bound parse and render as the f64 reference does; just past
//! it they are refused at the value's line and column, through the library
//! and over HTTP, where f32 would have drawn a wrong picture (shown here by
//! rendering the same scene built without the parser).

use glam::DVec3;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use voxtrace::output::Image;
use voxtrace::render::{render_in, IndexKind, RenderOptions};
use voxtrace::scene::{parse, write_scene, Scene, SceneErrorKind as K};
use voxtrace::service::{Server, ServiceConfig};

fn load(name: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes/hard")
        .join(format!("{name}.txt"));
    parse(std::fs::read(path).unwrap()).unwrap()
}

fn text_of(scene: &Scene) -> String {
    let mut text = Vec::new();
    write_scene(&mut text, scene).unwrap();
    String::from_utf8(text).unwrap()
}

/// The scene as the parser reads it back from its text.
fn reparsed(scene: &Scene) -> Result<Scene, voxtrace::scene::SceneError> {
    parse(text_of(scene))
}

fn render<R: voxtrace::geometry::Real>(scene: &Scene) -> Image {
    let options = RenderOptions {
        index: IndexKind::Grid,
        ..RenderOptions::default()
    };
    render_in::<R>(scene, &options, &|_| {}).unwrap().image
}

/// Pixels where the fast path and the f64 reference differ by more than two
/// levels in some channel.
fn mismatches(scene: &Scene) -> usize {
    let (fast, exact) = (render::<f32>(scene), render::<f64>(scene));
    fast.rgb
        .chunks(3)
        .zip(exact.rgb.chunks(3))
        .filter(|(a, b)| a.iter().zip(*b).any(|(x, y)| x.abs_diff(*y) > 2))
        .count()
}

/// `base.txt` with mirrors, every length multiplied by `k`.
fn base_scaled(k: f64) -> Scene {
    let mut s = load("base");
    let c = &mut s.camera;
    for v in [
        &mut c.near,
        &mut c.left,
        &mut c.right,
        &mut c.bottom,
        &mut c.top,
    ] {
        *v *= k;
    }
    for sphere in &mut s.spheres {
        sphere.center *= k;
        sphere.scale *= k;
        sphere.material.reflect = 0.5;
    }
    for light in &mut s.lights {
        light.position *= k;
    }
    s
}

/// The largest length of `base.txt` is 7.1 (sphere d's z), its thinnest scale 0.25.
#[test]
fn a_scene_scaled_up_to_the_largest_length_renders_as_in_f64() {
    let inside = reparsed(&base_scaled(1e18 / 7.1)).expect("just inside");
    assert_eq!(mismatches(&inside), 0);
    let past = base_scaled(1e19);
    let e = reparsed(&past).unwrap_err();
    assert!(matches!(e.kind, K::TooLong { .. }), "{e}");
    assert!(
        mismatches(&past) > 100,
        "f32 breaks there: secondary rays underflow"
    );
}

#[test]
fn a_scene_scaled_down_to_the_thinnest_scale_renders_as_in_f64() {
    let inside = reparsed(&base_scaled(1e-18 / 0.25)).expect("just inside");
    assert_eq!(mismatches(&inside), 0);
    let past = base_scaled(1e-20);
    let e = reparsed(&past).unwrap_err();
    assert!(matches!(e.kind, K::TooThin { .. }), "{e}");
    assert!(
        mismatches(&past) > 100,
        "f32 breaks there: 1/scale² overflows"
    );
}

/// A ball of radius 0.01 over the ground, its light straight above at
/// `height`; the view frames the ground just under the ball, where its
/// shadow falls.
fn shadow_text(height: f64) -> String {
    format!(
        "NEAR 1\nLEFT -0.003\nRIGHT 0.003\nBOTTOM -0.1697\nTOP -0.1637\nRES 32 32\n\
         SPHERE ground 0 -101 -6 100 100 100 0.8 0.8 0.8 0.1 0.9 0 0 1\n\
         SPHERE ball 0 0 -6 0.01 0.01 0.01 1 0.2 0.2 0.1 0.9 0 0 1\n\
         LIGHT sun 0 {height} -6 1 1 1\nAMBIENT 1 1 1\n"
    )
}

fn dark_pixels(image: &Image) -> usize {
    image.rgb.chunks(3).filter(|p| p[0] < 60).count()
}

/// Shadow rays to a light at distance D test the ball with D/0.01 in the
/// unit sphere's frame: up to the length ratio its shadow is there.
#[test]
fn a_far_light_keeps_the_shadow_of_a_small_ball_up_to_the_length_ratio() {
    let inside = parse(shadow_text(1e16)).expect("a ratio of 1e18 is inside");
    let shadow = dark_pixels(&render::<f64>(&inside));
    assert!(shadow > 20, "the shadow is in view: {shadow}");
    assert_eq!(mismatches(&inside), 0);

    let e = parse(shadow_text(1e18)).unwrap_err();
    assert_eq!((e.line, e.column), (9, 13), "{e}");
    assert!(
        matches!(e.kind, K::LengthRatio { small, large } if small.value == 0.01 && large.value == 1e18),
        "{e}"
    );
    let mut past = inside.clone();
    past.lights[0].position.y = 1e18;
    assert_eq!(
        dark_pixels(&render::<f32>(&past)),
        0,
        "f32 loses the shadow there"
    );
    assert_eq!(dark_pixels(&render::<f64>(&past)), shadow);
}

#[test]
fn a_plate_up_to_the_axis_ratio_renders_as_in_f64() {
    let plate = |thickness: f64| {
        let mut s = load("ellipsoid_1000");
        s.spheres[0].scale.y = thickness;
        s
    };
    let inside = reparsed(&plate(2e-12)).expect("ratio 1e12 is inside");
    // The two rim pixels any ratio past 1e4 shows, tangent rays.
    assert!(mismatches(&inside) <= 2);
    let e = reparsed(&plate(1.9e-12)).unwrap_err();
    assert!(
        matches!(
            e.kind,
            K::AxisRatio {
                thin_field: "the sphere's y scale",
                ..
            }
        ),
        "{e}"
    );
}

/// The first case: one sphere at x = 1e39 blanked the whole image.
#[test]
fn a_sphere_beyond_f32_range_is_refused_rather_than_blanking_the_scene() {
    let mut scene = load("base");
    let mut far = scene.spheres[0];
    far.center = DVec3::new(1e39, 0.0, 0.0);
    scene.spheres.push(far);
    let e = reparsed(&scene).unwrap_err();
    assert_eq!(e.line, 12, "{e}");
    assert!(
        matches!(e.kind, K::TooLong { field: "the sphere's x position", value } if value == 1e39)
    );
    let blank = render::<f32>(&scene);
    assert!(blank.rgb.chunks(3).all(|p| p == [0, 0, 0]));
    assert!(mismatches(&scene) > 100);
}

/// The service answers such a scene as any other scene error: 400, with
/// the line and column.
#[test]
fn the_service_refuses_an_unrepresentable_scene_with_400_and_its_position() {
    let config = ServiceConfig {
        addr: "127.0.0.1:0".into(),
        ..ServiceConfig::default()
    };
    let server = Server::bind(config).unwrap().spawn().unwrap();
    let body = "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4 4\nLIGHT sun 1e20 0 0 1 1 1\n";
    let mut stream = TcpStream::connect(server.addr()).unwrap();
    write!(
        stream,
        "POST /render HTTP/1.1\r\nHost: test\r\nAccept: application/json\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut reply = String::new();
    stream.read_to_string(&mut reply).unwrap();
    assert!(reply.starts_with("HTTP/1.1 400"), "{reply}");
    let json: serde_json::Value =
        serde_json::from_str(reply.split("\r\n\r\n").nth(1).unwrap()).unwrap();
    assert_eq!(json["error"], "scene");
    assert_eq!(
        (json["line"].as_u64(), json["column"].as_u64()),
        (Some(7), Some(11))
    );
    assert!(
        json["message"].as_str().unwrap().contains("beyond ±1e18"),
        "{json}"
    );
    server.stop();
}
