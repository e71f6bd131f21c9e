//! Regions: a rectangle of the image rendered on its own is byte for byte
//! the same crop of the whole image, in both dialects and at any spp; the
//! CLI and the service refuse regions that are malformed, empty or outside.

use std::path::Path;
use std::process::Command;
use voxtrace::output::Image;
use voxtrace::render::{render_scene, Region, RenderError, RenderOptions};
use voxtrace::scene::{self, Scene};

mod support;
use support::{start, Client};

fn fixture(path: &str) -> Scene {
    let text = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).unwrap();
    scene::parse(&text).unwrap()
}

fn render(scene: &Scene, spp: u32, region: Option<Region>) -> Result<Image, RenderError> {
    let options = RenderOptions {
        spp,
        region,
        ..RenderOptions::default()
    };
    render_scene(scene, &options, &|_| {}).map(|r| r.image)
}

fn crop(image: &Image, r: &Region) -> Image {
    let mut rgb = Vec::with_capacity(3 * r.pixels() as usize);
    for y in r.rows() {
        let at = 3 * (y * image.width + r.x0) as usize;
        rgb.extend_from_slice(&image.rgb[at..at + 3 * r.width() as usize]);
    }
    Image::from_rgb(r.width(), r.height(), rgb)
}

/// Regions that cut tiles, blocks and bands of the renderer at odd places,
/// one pixel, whole rows and columns, and the whole image.
fn regions(width: u32, height: u32) -> Vec<Region> {
    let r = |x0, y0, x1, y1| Region { x0, y0, x1, y1 };
    vec![
        r(0, 0, width, height),
        r(0, 0, 1, 1),
        r(width - 1, height - 1, width, height),
        r(3, 5, 77, 70),
        r(31, 29, 97, 101),
        r(0, 33, width, 34),
        r(50, 0, 51, height),
        r(width / 3, height / 2, width - 7, height - 3),
    ]
}

#[test]
fn a_region_is_the_crop_of_the_whole_image_in_both_dialects_at_any_spp() {
    let scenes = [
        "scenes/testSample.txt",
        "tests/fixtures/reference/tinygraphics/scenes/test_refract.txt",
        "tests/fixtures/reference/tinygraphics/scenes/test_reflection.txt",
    ];
    for path in scenes {
        let scene = fixture(path);
        for spp in [1, 3, 4] {
            let whole = render(&scene, spp, None).unwrap();
            for region in regions(scene.camera.width, scene.camera.height) {
                let part = render(&scene, spp, Some(region)).unwrap();
                assert!(
                    part == crop(&whole, &region),
                    "{path} spp {spp} region {region}"
                );
            }
        }
    }
}

#[test]
fn a_region_of_a_generated_crowd_is_its_crop() {
    let text = generated_scene(20_000, 160);
    let scene = scene::parse(&text).unwrap();
    for spp in [1, 2] {
        let whole = render(&scene, spp, None).unwrap();
        for region in regions(160, 160) {
            let part = render(&scene, spp, Some(region)).unwrap();
            assert!(part == crop(&whole, &region), "spp {spp} region {region}");
        }
    }
}

/// `voxtrace gen`'s mixed scene of `spheres` at `res`×`res`.
fn generated_scene(spheres: u32, res: u32) -> Vec<u8> {
    let out = std::env::temp_dir().join(format!("voxtrace-regions-{}.txt", std::process::id()));
    let status = Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .args(["gen", "--spheres", &spheres.to_string(), "--dist", "mixed"])
        .args([
            "--res",
            &res.to_string(),
            &res.to_string(),
            "--seed",
            "3",
            "-o",
        ])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read(&out).unwrap();
    std::fs::remove_file(&out).unwrap();
    text
}

#[test]
fn the_renderer_refuses_empty_and_outside_regions() {
    let scene = fixture("scenes/testSample.txt");
    let r = |x0, y0, x1, y1| Some(Region { x0, y0, x1, y1 });
    for bad in [
        r(5, 5, 5, 10),
        r(5, 9, 6, 3),
        r(0, 0, 601, 10),
        r(0, 599, 10, 601),
    ] {
        let error = render(&scene, 1, bad).unwrap_err();
        assert!(
            matches!(error, RenderError::BadRegion(_)),
            "{bad:?}: {error}"
        );
    }
}

fn voxtrace(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_voxtrace"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn the_cli_writes_the_region_and_refuses_bad_ones_with_exit_code_2() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/testSample.txt");
    let scene = scene.to_str().unwrap();
    let out = std::env::temp_dir().join(format!("voxtrace-region-{}.ppm", std::process::id()));
    let done = voxtrace(
        &[
            "render",
            scene,
            "--region",
            "10,20,110,70",
            "--spp",
            "4",
            "-o",
        ]
        .into_iter()
        .chain([out.to_str().unwrap()])
        .collect::<Vec<_>>(),
    );
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let ppm = std::fs::read(&out).unwrap();
    std::fs::remove_file(&out).unwrap();
    let whole = render(&fixture("scenes/testSample.txt"), 4, None).unwrap();
    let region = Region {
        x0: 10,
        y0: 20,
        x1: 110,
        y1: 70,
    };
    assert_eq!(
        ppm,
        crop(&whole, &region)
            .encode(voxtrace::output::Format::Ppm)
            .unwrap()
    );
    for (bad, says) in [
        ("10,20,110", "a region is X0,Y0,X1,Y1"),
        ("10,20,10,70", "is empty"),
        ("0,0,601,10", "outside the 600×600 image"),
    ] {
        let refused = voxtrace(&["render", scene, "--region", bad, "-o", "never-written.ppm"]);
        let stderr = String::from_utf8_lossy(&refused.stderr);
        assert_eq!(refused.status.code(), Some(2), "{bad}: {stderr}");
        assert!(stderr.contains(says), "{bad}: {stderr}");
    }
}

#[test]
fn the_service_renders_a_region_and_answers_400_to_bad_ones() {
    let server = start(voxtrace::service::ServiceConfig::default());
    let text = support::sample("testSample.txt");
    let mut client = Client::connect(server.addr());
    let reply = client.request(
        "POST",
        "/render?format=ppm&spp=3&region=100,200,250,260",
        &[],
        &text,
    );
    assert_eq!(reply.status, 200, "{}", reply.text());
    assert_eq!(reply.header("x-image-width"), Some("150"));
    assert_eq!(
        reply.header("x-worker"),
        Some(server.addr().to_string().as_str())
    );
    let whole = render(&scene::parse(&text).unwrap(), 3, None).unwrap();
    let region = Region {
        x0: 100,
        y0: 200,
        x1: 250,
        y1: 260,
    };
    assert_eq!(
        reply.body,
        crop(&whole, &region)
            .encode(voxtrace::output::Format::Ppm)
            .unwrap()
    );
    for (bad, says) in [
        ("region=1,2,3", "a region is X0,Y0,X1,Y1"),
        ("region=5,5,4,9", "is empty"),
        ("region=0,0,10,601", "outside the 600×600 image"),
    ] {
        let reply = client.request(
            "POST",
            &format!("/render?{bad}"),
            &["Accept: application/json"],
            &text,
        );
        assert_eq!(reply.status, 400, "{bad}");
        let json = reply.json();
        assert_eq!(json["error"], "query", "{bad}");
        assert!(
            json["message"].as_str().unwrap().contains(says),
            "{bad}: {json}"
        );
    }
}
