//! `voxtrace render --remote URL`: the frame in tiles on a render service
//! or a cluster of them, stitched into the file a local render writes.

use super::output_path::{refuse_overwriting, Destination};
use super::progress::Progress;
use super::render::{write_image, RenderArgs};
use super::scene_input::read_scene_text;
use super::summary;
use super::CliError;
use crate::limits;
use crate::remote::{self, RemoteConfig, TiledStats};
use crate::tools::load::Url;
use std::time::Duration;

/// How a remote render is cut up and sent; only with `--remote`.
#[derive(clap::Args)]
pub struct TilingArgs {
    /// About how many tiles to cut the frame into.
    #[arg(long, requires = "remote", default_value_t = limits::DEFAULT_TILES,
          value_parser = clap::value_parser!(u32).range(1..=i64::from(limits::MAX_TILES)))]
    tiles: u32,
    /// Tile requests in flight at once.
    #[arg(long, requires = "remote", default_value_t = limits::DEFAULT_TILES_IN_FLIGHT,
          value_parser = in_flight)]
    in_flight: usize,
    /// How long one tile request may take, in milliseconds, before it is sent again.
    #[arg(long, requires = "remote", default_value_t = limits::DEFAULT_TILE_TIMEOUT_MS,
          value_parser = clap::value_parser!(u64).range(1..))]
    tile_timeout_ms: u64,
}

fn in_flight(text: &str) -> Result<usize, String> {
    text.parse::<usize>()
        .ok()
        .filter(|n| (1..=limits::MAX_TILES_IN_FLIGHT).contains(n))
        .ok_or_else(|| format!("a whole number from 1 to {}", limits::MAX_TILES_IN_FLIGHT))
}

/// Renders on the service at `url`; `given` is `-o`'s destination, if any.
pub fn run(args: &RenderArgs, url: &str, given: Option<Destination>) -> Result<(), CliError> {
    let url = Url::parse(url).map_err(CliError::Url)?;
    let (text, scene) = read_scene_text(&args.scene, args.max_scene_bytes)?;
    let destination = given.unwrap_or_else(|| Destination::default_for(&scene, &args.scene));
    refuse_overwriting(&destination, &args.scene)?;
    let path = url.target.split('?').next().unwrap_or("/");
    let config = RemoteConfig {
        authority: url.authority.clone(),
        path: if path == "/" {
            "/render".into()
        } else {
            path.into()
        },
        spp: args.spp,
        depth: args.depth,
        rules: args.rules,
        tiles: args.tiling.tiles,
        in_flight: args.tiling.in_flight,
        tile_timeout: Duration::from_millis(args.tiling.tile_timeout_ms),
    };
    let size = (scene.camera.width, scene.camera.height);
    drop(scene);
    let tiles = remote::plan(size.0, size.1, config.tiles).len() as u32;
    let progress = Progress::new(tiles, "tiles", args.quiet);
    let rendered = remote::render(&config, &text, size, &|done| progress.update(done))
        .map_err(CliError::Remote)?;
    progress.finish();
    write_image(&rendered.image, &destination)?;
    if args.stats {
        print_stats(&rendered.stats);
    }
    if !args.quiet {
        let stats = &rendered.stats;
        let work = format!("{} tiles on {} workers", stats.tiles, stats.workers.len());
        let line = summary::line(&destination.name(), size, args.spp, stats.elapsed, &work);
        eprintln!("{line}");
    }
    Ok(())
}

fn print_stats(stats: &TiledStats) {
    eprintln!("elapsed {:10.2} ms", stats.elapsed.as_secs_f64() * 1e3);
    let failures: Vec<String> = stats
        .failures
        .iter()
        .map(|(why, n)| format!("{n} × {why}"))
        .collect();
    eprintln!(
        "tiles   {}  retries {}{}",
        stats.tiles,
        stats.retries,
        if failures.is_empty() {
            String::new()
        } else {
            format!("  ({})", failures.join(", "))
        }
    );
    for (worker, time) in &stats.workers {
        eprintln!(
            "worker  {worker}  {} tiles  {:.2} ms rendering",
            time.tiles, time.render_ms
        );
    }
}
