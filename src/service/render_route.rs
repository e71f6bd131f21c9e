//! `POST /render`: scene text in, image out, within the service's limits.

use super::accept;
use super::admission::{BodyCharge, NotAdmitted};
use super::error::{ApiError, ApiErrorKind};
use super::http::{Connection, RequestHead, Response};
use super::memory_budget::{resident_bytes, Charge};
use super::query;
use super::scene_body;
use super::{ServiceConfig, State};
use crate::limits;
use crate::names::Named;
use crate::output::Format;
use crate::render::{
    render_scene, CancelToken, Deadline, Region, RegionError, RenderError, RenderOptions, Rendered,
    Rules,
};
use crate::scene::{self, Scene};
use std::panic::{self, AssertUnwindSafe};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::{Duration, Instant};

/// How often a render waiting in the queue checks that its client is still
/// there; one that left gives its place back within this time.
const QUEUE_POLL: Duration = Duration::from_millis(100);
/// How often a running render checks that its client is still there; one
/// that left has its render stopped within this time (and one ray's walk).
const CLIENT_POLL: Duration = Duration::from_millis(100);
/// How long after cancelling a render its answer may wait for the render to
/// return: the bound on a stopped render's overshoot that the service states.
const STOP_GRACE: Duration = Duration::from_millis(100);

/// The figures of a render, sent as headers and exposed to scripts.
const FIGURE_HEADERS: &str = "X-Render-Ms, X-Rays, X-Image-Width, X-Image-Height, X-Worker";

/// A query parameter `POST /render` reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Param {
    Format,
    Spp,
    Depth,
    Region,
    Rules,
}

/// The query parameters `POST /render` reads, by name.
const PARAMETERS: &[(&str, Param)] = &[
    ("format", Param::Format),
    ("spp", Param::Spp),
    ("depth", Param::Depth),
    ("region", Param::Region),
    ("rules", Param::Rules),
];

/// What the query string asks for.
#[derive(Debug, PartialEq)]
pub struct RenderQuery {
    /// `None`: as `Accept` prefers.
    pub format: Option<Format>,
    pub spp: u32,
    pub depth: Option<u32>,
    /// `region=X0,Y0,X1,Y1`: only that rectangle of the image.
    pub region: Option<Region>,
    pub rules: Rules,
}

impl RenderQuery {
    /// `format=png|ppm`, `spp=N`, `depth=N`, `region=X0,Y0,X1,Y1`,
    /// `rules=default|ucla`, each at most once; any other name is refused.
    pub fn parse(query: &str) -> Result<RenderQuery, ApiError> {
        let mut parsed = RenderQuery {
            format: None,
            spp: 1,
            depth: None,
            region: None,
            rules: Rules::default(),
        };
        let params = query::parse(query, PARAMETERS).map_err(|e| bad_query(e.to_string()))?;
        for (param, value) in params {
            let value = value.as_str();
            match param {
                Param::Format => {
                    parsed.format = match value {
                        "png" => Some(Format::Png),
                        "ppm" => Some(Format::Ppm),
                        _ => {
                            return Err(bad_query(format!(
                                "format must be png or ppm, found {value:?}"
                            )))
                        }
                    }
                }
                Param::Spp => parsed.spp = number("spp", value, 1, limits::MAX_SPP)?,
                Param::Depth => parsed.depth = Some(number("depth", value, 0, limits::MAX_DEPTH)?),
                Param::Region => {
                    let region = value
                        .parse()
                        .map_err(|e: RegionError| bad_query(e.to_string()))?;
                    parsed.region = Some(region);
                }
                Param::Rules => {
                    parsed.rules = Rules::from_name(value).map_err(|e| bad_query(e.to_string()))?
                }
            }
        }
        Ok(parsed)
    }

    /// The image's type: the one `format=` names, which wins over
    /// `Accept` (it is the more explicit of the two), else the one `accept`
    /// prefers (406 if it rules out both).
    pub fn image_format(&self, accept: Option<&str>) -> Result<Format, ApiError> {
        match self.format {
            Some(format) => Ok(format),
            None => accept::choose(accept).map_err(|e| ApiErrorKind::NotAcceptable(e).into()),
        }
    }
}

/// What a render request's head alone decides: the query and the image's
/// type, or why the request is refused (400, 406), so that a client asking
/// for `100 Continue` is told before it sends its scene.
pub fn from_head(head: &RequestHead) -> Result<(RenderQuery, Format), ApiError> {
    let query = RenderQuery::parse(&head.query)?;
    let format = query.image_format(head.list_header("accept").as_deref())?;
    Ok((query, format))
}

impl RenderQuery {
    /// What the renderer is asked for: the query's samples, depth and
    /// rules, the rest as the library's defaults.
    fn options(&self) -> RenderOptions {
        RenderOptions {
            spp: self.spp,
            depth: self.depth,
            region: self.region,
            rules: self.rules,
            ..RenderOptions::default()
        }
    }

    /// The rectangle of `scene`'s image to render: the region asked for,
    /// if it fits the image (else 400), or the whole image.
    fn region_of(&self, scene: &Scene) -> Result<Region, ApiError> {
        let (width, height) = (scene.camera.width, scene.camera.height);
        match self.region {
            Some(region) => region
                .within(width, height)
                .map_err(|e| bad_query(e.to_string())),
            None => Ok(Region::whole(width, height)),
        }
    }
}

/// A render request's answer: the encoded image and the figures the
/// service sends as headers.
#[derive(Debug)]
pub struct EncodedRender {
    pub bytes: Vec<u8>,
    pub format: Format,
    pub width: u32,
    pub height: u32,
    pub rays: u64,
}

/// One `POST /render` without HTTP, admission, memory charges or a
/// deadline: the query string and the scene text in, the encoded image out,
/// through the very steps the `POST /render` handler takes (`RenderQuery::parse`,
/// `parse_scene`, `check_limits`, the render on `pool`, `encode`), so
/// whatever the service refuses is refused here with the same error.
/// `voxtrace load --in-process` measures the service against it.
pub fn render_request(
    query: &str,
    body: &[u8],
    config: &ServiceConfig,
    pool: &rayon::ThreadPool,
) -> Result<EncodedRender, ApiError> {
    let query = RenderQuery::parse(query)?;
    let format = query.image_format(None)?;
    let scene = parse_scene(pool, body)?;
    check_limits(&scene, &query, config)?;
    let options = query.options();
    let rendered = pool
        .install(|| render_scene(&scene, &options, &|_| {}))
        .map_err(render_failed)?;
    encode(&rendered, format)
}

/// The scene of a request body, parsed on the render pool: the parser is
/// parallel, and on the pool it never starts rayon's global pool beside the
/// service's own (which would put more busy threads than `--threads` on
/// the cores). A scene that does not parse because its line breaks were
/// stripped is told so (see [`scene_body::hint`]).
fn parse_scene(pool: &rayon::ThreadPool, text: &[u8]) -> Result<Scene, ApiError> {
    pool.install(|| scene::parse(text)).map_err(|e| {
        let mut error = ApiError::scene(&e, text);
        if let (ApiErrorKind::Scene { message, shown, .. }, Some(hint)) =
            (&mut error.kind, scene_body::hint(text))
        {
            *message = format!("{message}\n{hint}");
            *shown = format!("{shown}\n{hint}");
        }
        error
    })
}

/// The answer to a render that returned an error of its own: an option it
/// refuses is the query's fault (400).
fn render_failed(error: RenderError) -> ApiError {
    match error {
        RenderError::BadOption(why) => bad_query(why),
        RenderError::BadRegion(why) => bad_query(why.to_string()),
        other => ApiErrorKind::Encode(other.to_string()).into(),
    }
}

/// The image in the asked-for format, with its figures.
fn encode(rendered: &Rendered, format: Format) -> Result<EncodedRender, ApiError> {
    let bytes = rendered
        .image
        .encode(format)
        .map_err(|e| ApiErrorKind::Encode(e.to_string()))?;
    Ok(EncodedRender {
        bytes,
        format,
        width: rendered.image.width,
        height: rendered.image.height,
        rays: rendered.stats.rays.total(),
    })
}

fn number(key: &str, value: &str, low: u32, high: u32) -> Result<u32, ApiError> {
    crate::bounded::parse(key, value, low..=high).map_err(|e| bad_query(e.to_string()))
}

fn bad_query(message: String) -> ApiError {
    ApiErrorKind::Query(message).into()
}

/// A region outside the image: 400. A scene that parses but is more than
/// this service renders (the region's pixels, when one is asked for): 422.
fn check_limits(
    scene: &Scene,
    query: &RenderQuery,
    config: &ServiceConfig,
) -> Result<(), ApiError> {
    let region = query.region_of(scene)?;
    let pixels = region.pixels();
    let too_much = |what: String| Err(ApiErrorKind::Limit(what).into());
    if pixels > config.max_pixels {
        return too_much(format!(
            "the image has {pixels} pixels ({}×{}); this service renders at most {}",
            region.width(),
            region.height(),
            config.max_pixels
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
/// budget. `None` means the client left while the render waited or ran, so
/// there is nobody to answer.
pub fn handle(
    state: &State,
    conn: &Connection,
    head: &RequestHead,
    body: Vec<u8>,
    charge: BodyCharge,
) -> Result<Option<Response>, ApiError> {
    let config = &state.config;
    let (query, format) = from_head(head)?;
    let text = scene_body::scene_text(head, &body).map_err(ApiErrorKind::Form)?;
    if state.draining() {
        return Err(ApiErrorKind::Draining.into());
    }
    let place = state
        .admission
        .reserve()
        .map_err(|_| ApiError::from(ApiErrorKind::QueueFull))?;
    // A client that leaves while its request waits for a slot gives its
    // place back then, and its scene is neither parsed nor rendered.
    let may_probe = head.minor_version >= 1;
    let queued = Instant::now();
    let deadline = queued + config.render_timeout;
    let ticket = match place.enter(deadline, QUEUE_POLL, || conn.client_gone(may_probe)) {
        Ok(ticket) => ticket,
        Err(NotAdmitted::Abandoned) => {
            state.metrics.render_abandoned();
            return Ok(None);
        }
        Err(NotAdmitted::QueueFull) => return Err(ApiErrorKind::QueueFull.into()),
        Err(NotAdmitted::WaitedTooLong) => {
            return Err(ApiErrorKind::QueueTimeout {
                waited_ms: queued.elapsed().as_millis(),
            }
            .into())
        }
    };
    // The budget runs from here: parsing, indexing and tracing all count.
    let budget = Budget::from_now(config.render_timeout);
    // Parsed once the slot is taken, so at most one parsed scene per slot
    // is held (the waiting requests hold only their bodies, within their
    // budget), and a waiting request is never stuck in a parse queued on
    // the busy render pool, where its client's leaving would go unseen.
    let scene = parse_scene(&state.pool, text)?;
    drop((body, charge));
    check_limits(&scene, &query, config)?;
    let region = query.region_of(&scene)?;
    let held = charge_render(state, &scene, &region, format)?;
    if budget.spent() {
        return Err(budget.stopped(state));
    }
    let options = query.options();
    let name = download_name(&scene, format);
    let started = Instant::now();
    let watched = watched_render(state, conn, may_probe, scene, options, held, &budget);
    // The render has stopped (or, stopped but stuck under another render's
    // work on a pool thread, gives its memory back when that ends): the
    // slot is free for the next render; encoding runs on this thread.
    drop(ticket);
    let (rendered, mut held) = match watched {
        Watched::Done(rendered, held) => (rendered, held),
        Watched::Gone => {
            state.metrics.render_abandoned();
            return Ok(None);
        }
        Watched::OutOfTime => return Err(budget.stopped(state)),
        Watched::Failed(error) => return Err(render_failed(error)),
    };
    let elapsed = started.elapsed();
    state.metrics.render(elapsed, rendered.stats.rays);
    let encoded = encode(&rendered, format)?;
    drop(rendered);
    // Only the encoded image is held from here until it is written.
    held.shrink_to(encoded.bytes.len() as u64);
    Ok(Some(image_response(
        encoded,
        &name,
        &state.worker,
        elapsed,
        held,
    )))
}

/// The 200 answer: the image, its download name, and its figures as headers.
fn image_response(
    encoded: EncodedRender,
    name: &str,
    worker: &str,
    elapsed: Duration,
    held: Charge,
) -> Response {
    let EncodedRender {
        bytes,
        format,
        width,
        height,
        rays,
    } = encoded;
    let mut response = Response::new(200, format.mime_type(), bytes)
        .with_header(
            "Content-Disposition",
            format!("inline; filename=\"{name}\""),
        )
        .with_header("Cache-Control", "no-store")
        .with_header("Vary", "Accept")
        .with_header("X-Render-Ms", format_ms(elapsed))
        .with_header("X-Rays", rays.to_string())
        .with_header("X-Image-Width", width.to_string())
        .with_header("X-Image-Height", height.to_string())
        .with_header("X-Worker", worker.to_owned())
        .with_header("Access-Control-Expose-Headers", FIGURE_HEADERS);
    response.hold = Some(held);
    response
}

/// A render's time budget: from when it takes its slot, through parsing,
/// indexing and tracing.
struct Budget {
    started: Instant,
    length: Duration,
}

impl Budget {
    fn from_now(length: Duration) -> Self {
        Budget {
            started: Instant::now(),
            length,
        }
    }

    fn end(&self) -> Instant {
        self.started + self.length
    }

    fn spent(&self) -> bool {
        Instant::now() >= self.end()
    }

    /// The answer to a render stopped at the budget's end, counted.
    fn stopped(&self, state: &State) -> ApiError {
        let elapsed = self.started.elapsed();
        state
            .metrics
            .render_stopped(elapsed.saturating_sub(self.length));
        ApiErrorKind::TimeBudget {
            budget_ms: self.length.as_millis(),
            elapsed_ms: elapsed.as_millis(),
        }
        .into()
    }
}

/// How a watched render ended.
enum Watched {
    /// With the charge of its memory.
    Done(Rendered, Charge),
    /// Its client left; it was stopped.
    Gone,
    /// It ran out of its time budget; it was stopped.
    OutOfTime,
    Failed(RenderError),
}

/// Runs the render on the pool while this (handler) thread keeps its clock:
/// at the budget's end, or once the client is found gone, it cancels the
/// render, whose rays then stop within one walk, and returns once the
/// render has returned, or [`STOP_GRACE`] after the cancel at the latest.
/// The render can outlast that only when a pool thread that waited for its
/// work picked up another render meanwhile (as rayon threads do while they
/// wait): it returns once that one does, and gives back `held`, which it
/// keeps until then, and the scene. A panic in the render is passed on here.
fn watched_render(
    state: &State,
    conn: &Connection,
    may_probe: bool,
    scene: Scene,
    options: RenderOptions,
    held: Charge,
    budget: &Budget,
) -> Watched {
    let token = CancelToken::new();
    let options = RenderOptions {
        deadline: Some(Deadline::on_cancel(&token)),
        ..options
    };
    let (done, finished) = mpsc::sync_channel(1);
    state.pool.spawn(move || {
        let result =
            panic::catch_unwind(AssertUnwindSafe(|| render_scene(&scene, &options, &|_| {})));
        // Nobody may wait any more: then the charge is given back here,
        // once the memory it stands for is.
        let _ = done.send((result, held));
    });
    let mut stopped: Option<(Watched, Instant)> = None;
    loop {
        let wait = match &stopped {
            Some((_, at)) => (*at + STOP_GRACE).saturating_duration_since(Instant::now()),
            None => budget
                .end()
                .saturating_duration_since(Instant::now())
                .min(CLIENT_POLL),
        };
        match finished.recv_timeout(wait) {
            Ok((Err(panicked), _)) => panic::resume_unwind(panicked),
            Ok((Ok(Ok(rendered)), held)) => return Watched::Done(rendered, held),
            Ok((Ok(Err(error)), _)) => {
                return stopped.map_or(Watched::Failed(error), |(why, _)| why);
            }
            Err(RecvTimeoutError::Disconnected) => unreachable!("the render always answers"),
            Err(RecvTimeoutError::Timeout) => {
                if let Some((why, _)) = stopped {
                    return why;
                }
                let why = if budget.spent() {
                    Watched::OutOfTime
                } else if conn.client_gone(may_probe) {
                    Watched::Gone
                } else {
                    continue;
                };
                token.cancel();
                stopped = Some((why, Instant::now()));
            }
        }
    }
}

/// Charges what the render will hold to the memory budget before it
/// starts: the parsed scene with its f32 copy and index, the framebuffer,
/// and the largest encoding of the image, which is held until written.
/// NotAdmitted (with the part that does not fit) if the budget or the measured
/// resident set has no room.
fn charge_render(
    state: &State,
    scene: &Scene,
    region: &Region,
    format: Format,
) -> Result<Charge, ApiError> {
    let scene_bytes = scene_bytes(scene);
    let image_bytes = 3 * region.pixels() + encoded_bound(region, format);
    let bytes = scene_bytes + image_bytes;
    let limit = state.memory.limit();
    let resident = || {
        let rss = resident_bytes()?;
        if rss.saturating_add(bytes) <= limit {
            return Some(rss);
        }
        // Freed memory that malloc still holds counts as resident: give it
        // back first, so that only memory in use refuses a request.
        super::memory::trim();
        resident_bytes()
    };
    state.memory.take(bytes, resident).ok_or_else(|| {
        let free = limit.saturating_sub(state.memory.used().max(resident_bytes().unwrap_or(0)));
        if scene_bytes > free {
            ApiErrorKind::SceneMemory { bytes: scene_bytes }.into()
        } else {
            ApiErrorKind::ResponseMemory { bytes }.into()
        }
    })
}

/// What a scene holds once parsed and indexed, in bytes: the scene, its f32
/// shapes, and the index with what its build needs (the light buffers' build
/// works after the grid's, within the grid's build allowance).
fn scene_bytes(scene: &Scene) -> u64 {
    let per_sphere = std::mem::size_of::<crate::scene::Sphere>()
        + std::mem::size_of::<crate::geometry::Ellipsoid<f32>>()
        + limits::INDEX_BUILD_BYTES_PER_SPHERE
        + limits::LIGHT_BUFFER_BYTES_PER_SPHERE;
    let lights = scene.lights.len() * std::mem::size_of::<crate::scene::Light>();
    (scene.spheres.len() * per_sphere + lights + limits::LIGHT_BUFFER_MIN_BYTES) as u64
}

/// The largest encoding of the image of `region`, in bytes. A PPM is its
/// pixels and a short header. A PNG's deflate stream may store what it
/// cannot compress, at 5 bytes per stored block of at most 65,535 bytes,
/// after a filter byte per row, inside chunks of 12 bytes each.
fn encoded_bound(region: &Region, format: Format) -> u64 {
    let (width, height) = (u64::from(region.width()), u64::from(region.height()));
    let raw = 3 * width * height;
    match format {
        Format::Ppm => raw + 32,
        Format::Png => {
            let filtered = raw + height;
            filtered + 5 * filtered.div_ceil(65_535) + 12 * filtered.div_ceil(8 * 1024) + 1024
        }
    }
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
                format: None,
                spp: 1,
                depth: None,
                region: None,
                rules: Rules::Default,
            }
        );
        assert_eq!(
            RenderQuery::parse("format=ppm&spp=4&depth=0&rules=ucla").unwrap(),
            RenderQuery {
                format: Some(Format::Ppm),
                spp: 4,
                depth: Some(0),
                region: None,
                rules: Rules::Ucla,
            }
        );
        for bad in [
            "format=gif",
            "spp=0",
            "spp=1025",
            "spp=two",
            "depth=-1",
            "depth=65",
            "region=1,2,3",
            "region=a,b,c,d",
            "rules=UCLA",
            "rules=",
        ] {
            let e = RenderQuery::parse(bad).unwrap_err();
            assert_eq!((e.kind.status(), e.kind.name()), (400, "query"), "{bad}");
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
            format: None,
            spp: 4,
            depth: None,
            region: None,
            rules: Rules::Default,
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
            check_limits(&scene, &query, &small)
                .unwrap_err()
                .kind
                .status(),
            422
        );
        let few_samples = ServiceConfig {
            max_samples: 600 * 600 * 3,
            ..config.clone()
        };
        assert_eq!(
            check_limits(&scene, &query, &few_samples)
                .unwrap_err()
                .kind
                .name(),
            "limit"
        );
        let few_spheres = ServiceConfig {
            max_spheres: 2,
            ..config
        };
        assert!(check_limits(&scene, &query, &few_spheres)
            .unwrap_err()
            .kind
            .to_string()
            .contains("3 spheres"));
    }
}
