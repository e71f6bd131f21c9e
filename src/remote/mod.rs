//! Tiled remote renders: a frame cut into regions ([`tiles`]), each sent to
//! a render service or a load balancer in front of several ([`client`]),
//! concurrently, sent again when it fails or times out, and stitched back
//! ([`stitch`]) into the image a local render makes, byte for byte.
//!
//! Sending a tile again is safe because a render is a pure function of the
//! scene text, the options and the region: whichever worker answers, and
//! however often, the pixels are the same.

mod client;
mod error;
mod stitch;
mod tiles;

pub use client::Transport;
pub use error::RemoteError;
pub use tiles::plan;

use crate::limits;
use crate::names::Named;
use crate::output::Image;
use crate::render::{Region, Rules};
use std::collections::{BTreeMap, VecDeque};
use std::net::{SocketAddr, ToSocketAddrs};
use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

/// Where and how to render.
#[derive(Clone, Debug)]
pub struct RemoteConfig {
    /// `host:port` of the service or its load balancer.
    pub authority: String,
    /// The path requests go to, `/render` on a bare URL.
    pub path: String,
    pub spp: u32,
    pub depth: Option<u32>,
    /// The rule set every tile is rendered by.
    pub rules: Rules,
    /// About how many tiles to cut the frame into.
    pub tiles: u32,
    /// Tile requests in flight at once.
    pub in_flight: usize,
    /// Longest time one tile request may take before it is sent again.
    pub tile_timeout: Duration,
}

/// What one worker (by its `X-Worker` name) did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WorkerTime {
    pub tiles: u32,
    /// The sum of its `X-Render-Ms`.
    pub render_ms: f64,
}

#[derive(Clone, Debug, Default)]
pub struct TiledStats {
    pub tiles: u32,
    /// Tile requests sent again after a failure.
    pub retries: u32,
    /// The failures that were retried, by kind (a transport error's name or an HTTP status).
    pub failures: BTreeMap<String, u32>,
    /// By worker name; tiles answered without an `X-Worker` header under "?".
    pub workers: BTreeMap<String, WorkerTime>,
    pub elapsed: Duration,
}

pub struct TiledRender {
    pub image: Image,
    pub stats: TiledStats,
}

/// Called with the number of tiles finished so far.
pub type Progress<'a> = &'a (dyn Fn(u32) + Sync);

/// Renders the `width` × `height` frame of `scene` (its text, sent as it is)
/// through `config`'s service, tile by tile.
pub fn render(
    config: &RemoteConfig,
    scene: &[u8],
    (width, height): (u32, u32),
    progress: Progress,
) -> Result<TiledRender, RemoteError> {
    let started = Instant::now();
    let addr = resolve(&config.authority)?;
    let tiles = plan(width, height, config.tiles);
    let board = Board::new(tiles.len());
    let job = Job {
        config,
        addr,
        scene,
        tiles: &tiles,
    };
    let threads = config.in_flight.clamp(1, tiles.len());
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| job.work(&board, progress));
        }
    });
    let Board { state, .. } = board;
    let state = state.into_inner().unwrap_or_else(PoisonError::into_inner);
    if let Some(error) = state.failed {
        return Err(error);
    }
    let mut image = Image::from_rgb(width, height, vec![0; 3 * width as usize * height as usize]);
    for (tile, rgb) in tiles.iter().zip(&state.done) {
        // Every tile is done when nothing failed.
        stitch::paste(&mut image, tile, rgb.as_deref().unwrap_or_default());
    }
    let mut stats = state.stats;
    stats.tiles = tiles.len() as u32;
    stats.elapsed = started.elapsed();
    Ok(TiledRender { image, stats })
}

fn resolve(authority: &str) -> Result<SocketAddr, RemoteError> {
    authority
        .to_socket_addrs()
        .map_err(|error| RemoteError::Resolve {
            authority: authority.to_owned(),
            error,
        })?
        .next()
        .ok_or_else(|| RemoteError::NoAddress(authority.to_owned()))
}

/// The tiles still to send, what came back, and the first fatal error,
/// shared by the request threads.
struct Board {
    state: Mutex<BoardState>,
    changed: Condvar,
}

struct BoardState {
    queue: VecDeque<(usize, u32)>,
    /// Tiles not yet answered (queued, in flight, or waiting to be sent again).
    pending: usize,
    done: Vec<Option<Vec<u8>>>,
    failed: Option<RemoteError>,
    stats: TiledStats,
}

impl Board {
    fn new(tiles: usize) -> Board {
        Board {
            state: Mutex::new(BoardState {
                queue: (0..tiles).map(|t| (t, 1)).collect(),
                pending: tiles,
                done: vec![None; tiles],
                failed: None,
                stats: TiledStats::default(),
            }),
            changed: Condvar::new(),
        }
    }

    fn lock(&self) -> MutexGuard<'_, BoardState> {
        // Each update is a few field writes; a panicking holder leaves them sound.
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The next tile and its attempt number; `None` once every tile is
    /// answered or one has failed for good. A thread with nothing to send
    /// waits for a tile that fails elsewhere to come back: that happens
    /// within one tile's timeout and backoff, so the waits are bounded.
    fn next(&self) -> Option<(usize, u32)> {
        let mut state = self.lock();
        loop {
            if state.failed.is_some() || state.pending == 0 {
                return None;
            }
            if let Some(job) = state.queue.pop_front() {
                return Some(job);
            }
            state = self
                .changed
                .wait_timeout(state, Duration::from_secs(1))
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    fn finish(&self, tile: usize, rgb: Vec<u8>, worker: Option<String>, ms: f64) -> u32 {
        let mut state = self.lock();
        state.done[tile] = Some(rgb);
        state.pending -= 1;
        let entry = state
            .stats
            .workers
            .entry(worker.unwrap_or_else(|| "?".into()))
            .or_default();
        entry.tiles += 1;
        entry.render_ms += ms;
        let finished = state.done.len() - state.pending;
        drop(state);
        self.changed.notify_all();
        finished as u32
    }

    fn retry(&self, tile: usize, attempt: u32, why: String) {
        let mut state = self.lock();
        state.stats.retries += 1;
        *state.stats.failures.entry(why).or_default() += 1;
        state.queue.push_back((tile, attempt + 1));
        drop(state);
        self.changed.notify_all();
    }

    fn fail(&self, error: RemoteError) {
        self.lock().failed.get_or_insert(error);
        self.changed.notify_all();
    }
}

/// How one attempt at a tile ended.
enum Attempt {
    Done {
        rgb: Vec<u8>,
        worker: Option<String>,
        render_ms: f64,
    },
    /// Worth sending again, after at least this long.
    Again {
        why: String,
        wait: Duration,
    },
    Refused {
        status: u16,
        message: String,
    },
}

/// What every request thread shares.
struct Job<'a> {
    config: &'a RemoteConfig,
    addr: SocketAddr,
    scene: &'a [u8],
    tiles: &'a [Region],
}

impl Job<'_> {
    /// One request thread: tiles from the board until none are left.
    fn work(&self, board: &Board, progress: Progress) {
        while let Some((tile, attempt)) = board.next() {
            let region = &self.tiles[tile];
            match self.attempt(region) {
                Attempt::Done {
                    rgb,
                    worker,
                    render_ms,
                } => progress(board.finish(tile, rgb, worker, render_ms)),
                Attempt::Refused { status, message } => board.fail(RemoteError::Refused {
                    tile: *region,
                    status,
                    message,
                }),
                Attempt::Again { why, .. } if attempt >= limits::MAX_TILE_ATTEMPTS => {
                    board.fail(RemoteError::GaveUp {
                        tile: *region,
                        attempts: attempt,
                        last: why,
                    })
                }
                Attempt::Again { why, wait } => {
                    let backoff =
                        Duration::from_millis(limits::TILE_RETRY_BACKOFF_MS * u64::from(attempt));
                    std::thread::sleep(wait.max(backoff));
                    board.retry(tile, attempt, why);
                }
            }
        }
    }

    fn attempt(&self, region: &Region) -> Attempt {
        let config = self.config;
        let mut target = format!(
            "{}?region={region}&format=ppm&spp={}&rules={}",
            config.path,
            config.spp,
            config.rules.name()
        );
        if let Some(depth) = config.depth {
            target += &format!("&depth={depth}");
        }
        let header = format!("P6\n{} {}\n255\n", region.width(), region.height());
        let request = client::Request {
            addr: self.addr,
            authority: &config.authority,
            target: &target,
            body: self.scene,
            max_body: header.len() + 3 * region.pixels() as usize,
        };
        let reply = match client::post(&request, Instant::now() + config.tile_timeout) {
            Ok(reply) => reply,
            Err(transport) => {
                return Attempt::Again {
                    why: transport.name().into(),
                    wait: Duration::ZERO,
                }
            }
        };
        classify(reply, region)
    }
}

/// A worker's answer: a tile, a refusal, or a failure worth another try
/// (any 5xx, a timeout or too-many-requests, or a body that is not the tile).
fn classify(reply: client::Reply, region: &Region) -> Attempt {
    let status = reply.status;
    let retry_wait = Duration::from_secs(reply.retry_after.unwrap_or(0))
        .min(Duration::from_millis(limits::MAX_TILE_RETRY_WAIT_MS));
    if status == 200 {
        return match stitch::decode_tile(&reply.body, region) {
            Some(rgb) => Attempt::Done {
                rgb,
                worker: reply.worker,
                render_ms: reply.render_ms.unwrap_or(0.0),
            },
            None => Attempt::Again {
                why: "malformed tile".into(),
                wait: Duration::ZERO,
            },
        };
    }
    if (400..500).contains(&status) && status != 408 && status != 429 {
        let text = String::from_utf8_lossy(&reply.body);
        return Attempt::Refused {
            status,
            message: text.trim().chars().take(500).collect(),
        };
    }
    Attempt::Again {
        why: status.to_string(),
        wait: retry_wait,
    }
}
