//! Every limit voxtrace enforces, in one place. The CLI and the service can
//! override the ones a user may reasonably want to change.

/// Most spheres one scene may hold (the course allowed 15; we allow millions).
pub const MAX_SPHERES: usize = 20_000_000;
/// Most lights one scene may hold. Every light costs a shadow ray per hit.
pub const MAX_LIGHTS: usize = 1_000;
/// Largest image side in pixels, so a typo in RES cannot ask for terabytes.
pub const MAX_RESOLUTION: u32 = 16_384;
/// Longest line of scene text in bytes. A `voxtrace gen` line is about 110
/// bytes; the limit only has to stop a file without line ends from being
/// held whole before its first line is even looked at.
pub const MAX_LINE_BYTES: usize = 64 * 1024;
/// How far into a scene text control bytes mark it as binary data (a NUL, an
/// escape: anything below 0x20 but TAB, LF and CR, or DEL). Further in,
/// such bytes still fail as malformed tokens; only the start is worth a
/// clearer message.
pub const BINARY_SNIFF_BYTES: usize = 8 * 1024;
/// Widest stretch of a scene line an error message shows, in characters:
/// a longer line is cut around the column at fault, as compilers do, so a
/// 64 KiB line costs the terminal one line.
pub const SNIPPET_CHARS: usize = 100;
/// Columns a TAB takes where an error message shows its line, so the
/// caret under it lands where the terminal put the character at fault.
pub const SNIPPET_TAB_WIDTH: usize = 4;
/// Largest scene file `voxtrace render` reads unless told otherwise
/// (`--max-scene-bytes`): 1.5 GiB. 10^7 spheres as `voxtrace gen` writes
/// them take 1.01 GB (uniform) to 1.12 GB (mixed sizes, all ellipsoids and
/// glass), so they fit with 40 % to spare.
pub const DEFAULT_MAX_SCENE_BYTES: u64 = 3 << 29;

// ---- What the f32 fast path can represent; `scene::bounds` derives each. ----

/// Largest magnitude of any length: a coordinate, a scale, a camera value.
pub const MAX_LENGTH: f64 = 1e18;
/// Smallest magnitude of a scale.
pub const MIN_SCALE: f64 = 1e-18;
/// Largest ratio of any length of a scene to its thinnest scale, and of its
/// widest scale to NEAR.
pub const MAX_LENGTH_RATIO: f64 = 1e18;
/// Largest ratio of an ellipsoid's longest axis to its shortest.
pub const MAX_AXIS_RATIO: f64 = 1e12;

/// Candidate tests one call of the index for a packet of rays may make
/// before it gives up ([`crate::index::Answered`]): a render looks at its
/// deadline only between calls, so this bounds what one call costs. At some
/// 20–40 ns a test (16 lanes, or one ray), about a millisecond. Packets of
/// the scenes in `scenes/` and of the benchmark families at 10^6 spheres
/// make at most a few hundred; a cell of thousands of spheres at one point
/// reaches it within a slab.
pub const PACKET_TESTS: u64 = 1 << 15;

/// Default recursion depth of reflection/refraction in the classic model (the course's limit).
pub const DEFAULT_CLASSIC_DEPTH: u32 = 3;
/// Safety cap on recursion in the browser model, whose own rule (remaining
/// weight below [`BROWSER_MIN_WEIGHT`]) never stops between two perfect mirrors.
pub const DEFAULT_BROWSER_DEPTH: u32 = 16;
/// Deepest recursion a user may ask for.
pub const MAX_DEPTH: u32 = 64;
/// Most samples per pixel a user may ask for.
pub const MAX_SPP: u32 = 1_024;
/// The browser model stops recursing once the remaining weight's length falls below this.
pub const BROWSER_MIN_WEIGHT: f64 = 0.3;
/// The adaptive cut-off: a ray whose weight is below half an 8-bit level cannot change the output.
pub const ADAPTIVE_MIN_WEIGHT: f64 = 1.0 / 512.0;
/// How much larger than the hit point's own coordinates the sphere's centre
/// and reach may be before an f32 hit point is recomputed in f64: beyond it
/// the sum `centre + offset` cancels more than 4 of f32's 24 bits
/// (`geometry::ellipsoid` derives the rule).
pub const REFINE_REACH_RATIO: f64 = 16.0;
/// How far along a spawned ray, in clearances, its origin may move off a
/// refined hit before the rest of the clearance is taken along the normal
/// (`geometry::spawn`).
pub const SPAWN_MAX_TRAVEL: f64 = 8.0;

// ---- The render service (`voxtrace serve`); each has a flag of the same name. ----

/// Where the service listens: loopback only, unless told otherwise.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8080";
/// Open client connections. Each has its own small reader thread, so slow or
/// idle clients never wait behind one another or hold the render path; past
/// this a new connection gets a place in the health-check reserve, or is
/// answered 503 at once and closed.
pub const DEFAULT_MAX_CONNECTIONS: usize = 1_024;
/// Open connections from one peer address: half the cap, so one client
/// holding all it may still leaves the other half to everyone else.
pub const DEFAULT_MAX_CONNECTIONS_PER_PEER: usize = DEFAULT_MAX_CONNECTIONS / 2;
/// Connections past either cap that are still read, for a `GET /healthz`
/// or `/metrics` (anything else is refused with the cap's reason): one
/// client at its cap cannot make the service look dead to its monitors.
pub const HEALTH_RESERVE_CONNECTIONS: usize = 16;
/// How long a connection in the reserve may take to send its request head,
/// from its accept: a monitor sends at once, and the reserve must turn over.
pub const RESERVE_HEAD_TIMEOUT_MS: u64 = 250;
/// How long a connection the server ends after an answer (a refused body,
/// a bad head) goes on reading what the client still sends before it
/// closes, so that the client can finish sending and read the answer to its
/// end instead of meeting a reset: closed with bytes unread, a connection
/// is reset. Ends sooner when the client closes its side.
pub const LINGER_MS: u64 = 1_000;
/// Most bytes read and thrown away while lingering ([`LINGER_MS`]).
pub const LINGER_BYTES: usize = 8 * 1024 * 1024;
/// Renders running at once on the render pool. Each render is itself
/// parallel, so more slots do not add threads; they cover the gap between a
/// render and the next in its slot (the next waiter woken, its scene parsed),
/// during which the other renders' bands keep the pool busy. With two, the
/// service reached 0.94–0.96 of in-process throughput on a small scene at
/// saturation; with four, 0.98.
pub const DEFAULT_CONCURRENT_RENDERS: usize = 4;
/// Renders waiting for a slot; past this `POST /render` is answered 503.
pub const DEFAULT_QUEUE: usize = 64;
/// Largest request body (scene text) in bytes: some 170,000 spheres as
/// `voxtrace gen` writes them.
pub const DEFAULT_MAX_BODY: u64 = 16 * 1024 * 1024;
/// Request bodies held in memory at once, in bytes, charged as they arrive;
/// a body that would go past it is answered 503.
pub const DEFAULT_BODY_MEMORY: u64 = 256 * 1024 * 1024;
/// Everything requests make the service hold at once, in bytes: bodies,
/// parsed scenes with their indexes, framebuffers and encoded images until
/// written. A render whose image and encoding would go past it is refused
/// (503) before it starts; the process's measured resident set is held to
/// it too. Room for a dozen of the largest images (4096 × 4096, 48 MiB of
/// pixels and as much again encoded).
pub const DEFAULT_MEMORY_BUDGET: u64 = 1024 * 1024 * 1024;
/// Most bytes the index may hold per sphere once built (its copies of the
/// spheres, levels and gate), beyond a floor of a few hundred KiB a level
/// that small scenes reach: a level whose cells would list each sphere
/// too many times gets coarser cells instead.
pub const INDEX_BYTES_PER_SPHERE: usize = 64;
/// What the index of a scene costs per sphere while it is built and used,
/// for the memory budget: at most [`INDEX_BYTES_PER_SPHERE`] once built, and about as much again
/// for the pairs its build sorts (the 10^7-sphere scene peaked at some 240
/// bytes a sphere beyond its text).
pub const INDEX_BUILD_BYTES_PER_SPHERE: usize = 256;
/// Bytes per sphere the grid's light buffers may hold, all lights together
/// (about 6–10 a light on the benchmark families at 10^6 spheres, so some
/// thirteen lights get one); building one takes about 110 more for a while.
pub const LIGHT_BUFFER_BYTES_PER_SPHERE: usize = 128;
/// Bytes the light buffers may hold whatever the scene's size, so that a
/// small scene's lights get them too.
pub const LIGHT_BUFFER_MIN_BYTES: usize = 1 << 20;
/// Largest request head (request line and headers) in bytes; larger is 431.
pub const MAX_HEAD_BYTES: usize = 16 * 1024;
/// Most header lines in one request; more is 431.
pub const MAX_HEADERS: usize = 64;
/// Most parts of a `multipart/form-data` render body. One (the scene) is
/// read; the rest are counted only to name them in the refusal, so this
/// bounds that message, not the work, which the body's size already does.
pub const MAX_FORM_PARTS: usize = 16;
/// Most header lines of one form part (curl and browsers send two).
pub const MAX_PART_HEADERS: usize = 16;
/// Largest image (width × height) the service renders; larger is 422.
pub const DEFAULT_MAX_PIXELS: u64 = 4096 * 4096;
/// Largest number of camera samples (width × height × spp) per request.
pub const DEFAULT_MAX_SAMPLES: u64 = 64 * 1024 * 1024;
/// Most spheres in one scene the service accepts.
pub const DEFAULT_MAX_SERVICE_SPHERES: usize = 1_000_000;
/// Time budget of one render from the moment it starts tracing, and the
/// longest wait in the queue. Past it the render is stopped (within one
/// ray's walk) and the request answered 504 (the scene costs too much time).
pub const DEFAULT_RENDER_TIMEOUT_MS: u64 = 30_000;
/// How long a kept-alive connection may sit idle between requests.
pub const DEFAULT_IDLE_TIMEOUT_MS: u64 = 5_000;
/// Time from a request's first byte to the end of its head; past it, 408.
pub const DEFAULT_HEAD_TIMEOUT_MS: u64 = 10_000;
/// Time to receive a whole request body; past it, 408.
pub const DEFAULT_BODY_TIMEOUT_MS: u64 = 30_000;
/// Time to write one whole response: a deadline on all its writes together,
/// so a client that reads a byte at a time cannot hold a connection forever.
/// As long as a body's: the largest image (a 4096 × 4096 PPM, 48 MiB) then
/// needs a client taking 1.6 MiB/s.
pub const DEFAULT_WRITE_TIMEOUT_MS: u64 = 30_000;
/// What `Retry-After` tells a client turned away by a full queue, in seconds.
pub const RETRY_AFTER_S: u32 = 1;

// ---- What the service tells of itself: `/metrics` and the access log. ----

/// Upper bounds (seconds) of the request-duration histogram's buckets: from
/// a `/healthz` (well under a millisecond) to a render that waited its whole
/// budget in the queue and then ran its whole budget (twice
/// [`DEFAULT_RENDER_TIMEOUT_MS`]).
pub const REQUEST_SECONDS_BUCKETS: [f64; 16] = [
    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
    60.0,
];
/// Upper bounds (seconds) of the render-time histogram's buckets (index
/// build and tracing only), up to the render budget.
pub const RENDER_SECONDS_BUCKETS: [f64; 12] = [
    0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
];
/// Access-log lines waiting for the disk (or the terminal). Requests never
/// wait for the log: past this, lines are dropped and counted
/// (`voxtrace_access_log_dropped_lines_total`).
pub const ACCESS_LOG_QUEUE_LINES: usize = 1_024;
/// Longest request target, `Referer` or `User-Agent` an access-log line
/// holds, in bytes; longer ones are cut there and marked with `...`, so a
/// line (and the queue) stays small whatever a client sends.
pub const ACCESS_LOG_FIELD_BYTES: usize = 1_024;
/// How long a stopping service waits for the access log to write what it
/// has queued, in milliseconds, so a stuck disk or pipe cannot hold up its
/// exit.
pub const ACCESS_LOG_CLOSE_TIMEOUT_MS: u64 = 2_000;

// ---- Tiled remote renders (`voxtrace render --remote`) and draining. ----

/// Tiles a remote render is split into unless told otherwise: enough for a
/// handful of workers to share a frame and for a slow one to matter little.
pub const DEFAULT_TILES: u32 = 16;
/// Most tiles one remote render may ask for: each costs the workers a parse
/// and an index build of the whole scene.
pub const MAX_TILES: u32 = 4_096;
/// Tile requests in flight at once unless told otherwise.
pub const DEFAULT_TILES_IN_FLIGHT: usize = 8;
/// Most tile requests in flight at once: one client thread and connection each.
pub const MAX_TILES_IN_FLIGHT: usize = 256;
/// How long one tile request may take, from connecting to its last byte:
/// a worker's longest queue wait, render budget and response write
/// ([`DEFAULT_RENDER_TIMEOUT_MS`] and [`DEFAULT_WRITE_TIMEOUT_MS`]) end
/// within it. Past it the tile is sent again.
pub const DEFAULT_TILE_TIMEOUT_MS: u64 = 2 * DEFAULT_RENDER_TIMEOUT_MS + DEFAULT_WRITE_TIMEOUT_MS;
/// Attempts per tile before the render gives up: a render is a pure
/// function, so sending it again is safe, but a tile that fails this often
/// points at the cluster, not at bad luck.
pub const MAX_TILE_ATTEMPTS: u32 = 5;
/// Wait before a failed tile is sent again, times its attempt number.
pub const TILE_RETRY_BACKOFF_MS: u64 = 100;
/// Longest wait a worker's `Retry-After` can impose on a tile.
pub const MAX_TILE_RETRY_WAIT_MS: u64 = 5_000;
/// Largest error body read from a worker (its message, text or JSON).
pub const MAX_REMOTE_ERROR_BYTES: usize = 64 * 1024;
/// How long a worker told to stop (SIGTERM, SIGINT) may take to finish the
/// renders it has admitted: its queue wait, render and write all fit.
pub const DEFAULT_DRAIN_TIMEOUT_MS: u64 = DEFAULT_TILE_TIMEOUT_MS;

// ---- The load generator (`voxtrace load`). ----

/// How long requests still in flight when a run's window closes may take
/// to finish before they count as unfinished (`--grace`). A render of the
/// bundled samples takes tens of milliseconds; one queued behind a full
/// service can take longer and is what the grace must not wait out, since
/// the run's whole point is the window.
pub const DEFAULT_LOAD_GRACE_MS: u64 = 1_000;
/// Connections the open loop may open (`--max-connections`): half of a
/// service's default per-peer cap ([`DEFAULT_MAX_CONNECTIONS_PER_PEER`]),
/// so a run from one host never meets the cap's refusals, and enough for
/// 500 requests/s that each take half a second.
pub const DEFAULT_LOAD_MAX_CONNECTIONS: usize = DEFAULT_MAX_CONNECTIONS_PER_PEER / 2;
/// Below this share of its offered rate, the open loop warns that it fell short.
pub const LOAD_MIN_SEND_RATE_SHARE: f64 = 0.95;
/// Above this share of transport errors among its requests, a run fails
/// even if some succeeded: the figures are then the network's, not the service's.
pub const LOAD_MAX_TRANSPORT_ERROR_SHARE: f64 = 0.5;
/// How much of an error body the report shows for each status: enough
/// for the service's one-line messages.
pub const LOAD_ERROR_BODY_BYTES: usize = 200;
/// Buckets of the text report's latency histogram (as oha draws it).
pub const LOAD_HISTOGRAM_BUCKETS: usize = 11;
/// Width of the fullest bucket's bar, in characters.
pub const LOAD_HISTOGRAM_BAR: usize = 32;
