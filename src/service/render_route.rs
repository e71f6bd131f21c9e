//! `POST /render`: scene text in, image out, within the service's limits.

use super::admission::{Charge, Refused};
use super::error::ApiError;
use super::http::{Connection, Response};
use super::{ServiceConfig, State};
use crate::limits;
use crate::output::Format;
use crate::render::{render_scene, RenderError, RenderOptions};
use crate::scene::{self, Scene};
use std::time::{Duration, Instant};

/// How often a render waiting in the queue checks that its client is still
/// there; one that left gives its place back within this time.
const QUEUE_POLL: Duration = Duration::from_millis(100);

/// The figures of a render, sent as headers and exposed to scripts.
const FIGURE_HEADERS: &str = "X-Render-Ms, X-Rays, X-Image-Width, X-Image-Height";

/// What the query string asks for.
#[derive(Debug, PartialEq)]
pub struct RenderQuery {
    pub format: Format,
    pub spp: u32,
    pub depth: Option<u32>,
}

impl RenderQuery {
    /// `format=png|ppm`, `spp=N`, `depth=N`; other parameters are ignored.
    pub fn parse(query: &str) -> Result<RenderQuery, ApiError> {
        let mut parsed = RenderQuery {
            format: Format::Png,
            spp: 1,
            depth: None,
        };
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
            match key {
                "format" => {
                    parsed.format = match value {
                        "png" => Format::Png,
                        "ppm" => Format::Ppm,
                        _ => {
                            return Err(bad_query(format!(
                                "format must be png or ppm, found {value:?}"
                            )))
                        }
                    }
                }
                "spp" => parsed.spp = number(key, value, 1, limits::MAX_SPP)?,
                "depth" => parsed.depth = Some(number(key, value, 0, limits::MAX_DEPTH)?),
                _ => {}
            }
        }
        Ok(parsed)
    }
}

fn number(key: &str, value: &str, low: u32, high: u32) -> Result<u32, ApiError> {
    value
        .parse::<u32>()
        .ok()
        .filter(|n| (low..=high).contains(n))
        .ok_or_else(|| {
            bad_query(format!(
                "{key} must be a whole number from {low} to {high}, found {value:?}"
            ))
        })
}

fn bad_query(message: String) -> ApiError {
    ApiError::new(400, "query", message)
}

/// A scene that parses but is more than this service renders: 422.
fn check_limits(
    scene: &Scene,
    query: &RenderQuery,
    config: &ServiceConfig,
) -> Result<(), ApiError> {
    let pixels = u64::from(scene.camera.width) * u64::from(scene.camera.height);
    let too_much = |what: String| Err(ApiError::new(422, "limit", what));
    if pixels > config.max_pixels {
        return too_much(format!(
            "the image has {pixels} pixels ({}×{}); this service renders at most {}",
            scene.camera.width, scene.camera.height, config.max_pixels
        ));
    }
    if scene.spheres.len() > config.max_spheres {
        return too_much(format!(
            "the scene has {} spheres; this service renders at most {}",
            scene.spheres.len(),
            config.max_spheres
        ));
    }
    let samples = pixels * u64::from(query.spp);
    if samples > config.max_samples {
        return too_much(format!(
            "{pixels} pixels × {} samples = {samples} samples; this service traces at most {}",
            query.spp, config.max_samples
        ));
    }
    Ok(())
}

/// A download name from the scene's OUTPUT: its file name's stem, reduced to
/// characters that need no quoting, with the format's extension.
fn download_name(scene: &Scene, format: Format) -> String {
    let stem: String = scene
        .output
        .as_deref()
        .and_then(|name| std::path::Path::new(name).file_stem())
        .and_then(|stem| stem.to_str())
        .unwrap_or("render")
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .take(100)
        .collect();
    let stem = if stem.trim_matches('.').is_empty() {
        "render".to_owned()
    } else {
        stem
    };
    format!("{stem}.{}", format.extension())
}

/// Renders the scene of `body`, which `charge` holds against the body
/// budget. `None` means the client left while the render waited, so there
/// is nobody to answer.
pub fn handle(
    state: &State,
    conn: &Connection,
    query: &str,
    body: Vec<u8>,
    charge: Charge,
) -> Result<Option<Response>, ApiError> {
    let config = &state.config;
    let busy = |_| ApiError::busy(limits::RETRY_AFTER_S);
    let query = RenderQuery::parse(query)?;
    let place = state.admission.reserve().map_err(busy)?;
    // A client that leaves while its request waits for a slot gives its
    // place back then, and its scene is neither parsed nor rendered.
    let deadline = Instant::now() + config.render_timeout;
    let ticket = match place.enter(deadline, QUEUE_POLL, || conn.peer_closed()) {
        Ok(ticket) => ticket,
        Err(Refused::Abandoned) => {
            state.metrics.render_abandoned();
            return Ok(None);
        }
        Err(refused) => return Err(busy(refused)),
    };
    // Parsed once the slot is taken, so at most one parsed scene per slot
    // is held (the waiting requests hold only their bodies, within their
    // budget), and a waiting request is never stuck in a parse queued on
    // the busy render pool, where its client's leaving would go unseen.
    // The parser is parallel: it runs on the render pool too, so the
    // service never starts rayon's global pool beside its own (which would
    // put twice as many busy threads as `--threads` on the cores).
    let scene = state
        .pool
        .install(|| scene::parse(&body))
        .map_err(|e| ApiError::scene(&e))?;
    drop((body, charge));
    check_limits(&scene, &query, config)?;
    let options = RenderOptions {
        spp: query.spp,
        depth: query.depth,
        deadline: Some(Instant::now() + config.render_timeout),
        ..RenderOptions::default()
    };
    let started = Instant::now();
    let rendered = state
        .pool
        .install(|| render_scene(&scene, &options, &|_| {}))
        .map_err(|e| match e {
            RenderError::TimedOut => ApiError::new(
                422,
                "time_budget",
                format!(
                    "the render did not finish within its budget of {} ms",
                    config.render_timeout.as_millis()
                ),
            ),
            RenderError::BadOption(why) => bad_query(why),
        })?;
    let elapsed = started.elapsed();
    // Encoding runs on this handler thread: the slot is free for the next render.
    drop(ticket);
    let rays = rendered.stats.rays.total();
    state.metrics.render(elapsed, rays);

    let image = rendered
        .image
        .encode(query.format)
        .map_err(|e| ApiError::new(500, "encode", e.to_string()))?;
    Ok(Some(
        Response::new(200, query.format.mime_type(), image)
            .with_header(
                "Content-Disposition",
                format!(
                    "inline; filename=\"{}\"",
                    download_name(&scene, query.format)
                ),
            )
            .with_header("Cache-Control", "no-store")
            .with_header("X-Render-Ms", format_ms(elapsed))
            .with_header("X-Rays", rays.to_string())
            .with_header("X-Image-Width", rendered.image.width.to_string())
            .with_header("X-Image-Height", rendered.image.height.to_string())
            .with_header("Access-Control-Expose-Headers", FIGURE_HEADERS),
    ))
}

fn format_ms(d: Duration) -> String {
    format!("{:.3}", d.as_secs_f64() * 1e3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn query_defaults_and_bounds() {
        assert_eq!(
            RenderQuery::parse("").unwrap(),
            RenderQuery {
                format: Format::Png,
                spp: 1,
                depth: None
            }
        );
        assert_eq!(
            RenderQuery::parse("format=ppm&spp=4&depth=0&x=1").unwrap(),
            RenderQuery {
                format: Format::Ppm,
                spp: 4,
                depth: Some(0)
            }
        );
        for bad in [
            "format=gif",
            "spp=0",
            "spp=1025",
            "spp=two",
            "depth=-1",
            "depth=65",
        ] {
            let e = RenderQuery::parse(bad).unwrap_err();
            assert_eq!((e.status, e.kind), (400, "query"), "{bad}");
        }
    }

    #[test]
    fn download_names_never_carry_a_path_or_quotes() {
        let mut scene = scene::parse(include_bytes!("../../scenes/testSample.txt")).unwrap();
        assert_eq!(download_name(&scene, Format::Png), "testSample.png");
        scene.output = Some("../../etc/pass\"wd x.ppm".into());
        assert_eq!(download_name(&scene, Format::Ppm), "pass_wd_x.ppm");
        scene.output = None;
        assert_eq!(download_name(&scene, Format::Png), "render.png");
    }

    #[test]
    fn limits_are_checked_before_rendering() {
        let scene = scene::parse(include_bytes!("../../scenes/testSample.txt")).unwrap();
        let query = RenderQuery {
            format: Format::Png,
            spp: 4,
            depth: None,
        };
        let config = ServiceConfig {
            max_pixels: 600 * 600,
            max_samples: 600 * 600 * 4,
            ..ServiceConfig::default()
        };
        assert_eq!(check_limits(&scene, &query, &config), Ok(()));
        let small = ServiceConfig {
            max_pixels: 1000,
            ..config.clone()
        };
        assert_eq!(
            check_limits(&scene, &query, &small).unwrap_err().status,
            422
        );
        let few_samples = ServiceConfig {
            max_samples: 600 * 600 * 3,
            ..config.clone()
        };
        assert_eq!(
            check_limits(&scene, &query, &few_samples).unwrap_err().kind,
            "limit"
        );
        let few_spheres = ServiceConfig {
            max_spheres: 2,
            ..config
        };
        assert!(check_limits(&scene, &query, &few_spheres)
            .unwrap_err()
            .message
            .contains("3 spheres"));
    }
}
