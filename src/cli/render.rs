//! `voxtrace render`.

use super::choice::choice;
use super::output_path::{refuse_overwriting, refuse_terminal, Destination};
use super::progress::Progress;
use super::scene_input::read_scene;
use super::size::Size;
use super::summary;
use super::CliError;
use crate::bounded::{self, OutOfRange};
use crate::limits;
use crate::output::Image;
use crate::render::{
    render_scene, IndexKind, Region, RenderOptions, Rendered, Rules, SpecularModel,
};
use crate::scene::Scene;
use crate::threads::Threads;
use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct RenderArgs {
    /// The scene file (either dialect); `-` reads standard input.
    pub(super) scene: PathBuf,
    /// Output file: `.png` writes PNG, `.ppm` binary PPM (any other name is
    /// refused), `-` PNG to stdout (not to a terminal). Default: the scene's
    /// OUTPUT name, reduced to a plain file name ending in `.ppm` or `.png`,
    /// or `<scene>.ppm` (`render.ppm` from stdin), in the current directory.
    /// The scene file itself is never written over.
    #[arg(short, long)]
    pub(super) output: Option<PathBuf>,
    /// Largest scene file to read, in bytes.
    #[arg(long, value_name = "BYTES", default_value_t = limits::DEFAULT_MAX_SCENE_BYTES)]
    pub(super) max_scene_bytes: u64,
    /// Samples per pixel (1 = the pixel's corner, as the course did; more = stratified, jittered).
    #[arg(long, default_value_t = 1, value_parser = spp)]
    pub(super) spp: u32,
    /// Bounces of reflection/refraction (default: 3 classic, 16 browser dialect).
    #[arg(long, value_parser = depth)]
    pub(super) depth: Option<u32>,
    /// Render at this size instead of RES (`WxH`, or `W` to keep RES's
    /// aspect), for previews; the camera's window, so the field of view, is
    /// the scene's.
    #[arg(long, value_name = "WxH", conflicts_with = "remote")]
    size: Option<Size>,
    /// Print nothing on success: no progress bar, no summary line.
    #[arg(short, long)]
    pub(super) quiet: bool,
    /// Render threads, at least 1 (default: all cores). The image does not depend on it.
    #[arg(long)]
    threads: Option<Threads>,
    /// Print parse/build/render times and rays by kind on stderr.
    #[arg(long)]
    pub(super) stats: bool,
    /// Candidate search.
    #[arg(long, value_parser = choice(index_help), default_value_t = IndexKind::default())]
    index: IndexKind,
    /// Override the dialect's specular model.
    #[arg(long, value_parser = choice(specular_help))]
    specular: Option<SpecularModel>,
    /// Stop recursing once a ray's weight cannot change the 8-bit output.
    #[arg(long)]
    adaptive: bool,
    /// Render only pixels X0..X1 × Y0..Y1 (origin top left, X1 and Y1
    /// exclusive): the same bytes as that crop of the whole image.
    #[arg(long, value_name = "X0,Y0,X1,Y1", conflicts_with = "remote")]
    region: Option<Region>,
    /// Render on a service (or a load balancer in front of several) at this
    /// http:// URL, in tiles; the image is the same as a local render's.
    #[arg(long, value_name = "URL", conflicts_with_all = ["index", "specular", "adaptive"])]
    remote: Option<String>,
    #[command(flatten)]
    pub(super) tiling: super::remote::TilingArgs,
    /// Which of the course's two key sets to reproduce.
    #[arg(long, value_parser = choice(rules_help), default_value_t = Rules::default())]
    pub(super) rules: Rules,
}

fn spp(text: &str) -> Result<u32, OutOfRange> {
    bounded::parse("spp", text, 1..=limits::MAX_SPP)
}

fn depth(text: &str) -> Result<u32, OutOfRange> {
    bounded::parse("depth", text, 0..=limits::MAX_DEPTH)
}

fn rules_help(rules: Rules) -> &'static str {
    match rules {
        Rules::Default => "The scene format's rules (the course's newer keys)",
        Rules::Ucla => {
            "Outward normals on inside hits, reflected rays cut at t = 1 (the course's older keys)"
        }
    }
}

fn index_help(index: IndexKind) -> &'static str {
    match index {
        IndexKind::Grid => {
            "The multi-resolution voxel hash grid, with a light buffer per light for shadow rays"
        }
        IndexKind::Walk => "The grid alone: shadow rays walk it too (for measuring)",
        IndexKind::Brute => "Test every sphere (the exactness oracle)",
    }
}

fn specular_help(model: SpecularModel) -> &'static str {
    match model {
        SpecularModel::Phong => {
            "`max(0, R·V)^n`, R the light mirrored about the normal (the classic model's own)"
        }
        SpecularModel::Blinn => {
            "`max(0, N·H)^n`, H halfway between light and viewer (the browser model's own)"
        }
    }
}

pub fn run(args: RenderArgs) -> Result<(), CliError> {
    let given = args.output.as_deref().map(Destination::given).transpose()?;
    if let Some(destination) = &given {
        refuse_terminal(destination)?;
    }
    if let Some(url) = &args.remote {
        return super::remote::run(&args, url, given);
    }
    let pool = super::thread_pool(args.threads)?;
    let started = Instant::now();
    let mut scene = pool.install(|| read_scene(&args.scene, args.max_scene_bytes))?;
    let parse_time = started.elapsed();
    if let Some(size) = args.size {
        let camera = &mut scene.camera;
        (camera.width, camera.height) = size
            .apply(camera.width, camera.height)
            .map_err(|e| CliError::Usage(format!("--size: {e}")))?;
    }
    let destination = given.unwrap_or_else(|| Destination::default_for(&scene, &args.scene));
    refuse_overwriting(&destination, &args.scene)?;
    let options = RenderOptions {
        spp: args.spp,
        depth: args.depth,
        specular: args.specular,
        adaptive_cutoff: args.adaptive,
        index: args.index,
        rules: args.rules,
        refine: true,
        deadline: None,
        region: args.region,
    };
    let rows = args.region.map_or(scene.camera.height, |r| r.height());
    let progress = Progress::new(rows, "rows", args.quiet);
    let rendered = pool
        .install(|| render_scene(&scene, &options, &|rows| progress.update(rows)))
        .map_err(CliError::Render)?;
    progress.finish();
    write_image(&rendered.image, &destination)?;
    if args.stats {
        print_stats(&rendered, &scene, parse_time, pool.current_num_threads());
    }
    if !args.quiet {
        let image = &rendered.image;
        let rays = format!("{} rays", summary::count(rendered.stats.rays.total()));
        let size = (image.width, image.height);
        let line = summary::line(
            &destination.name(),
            size,
            args.spp,
            started.elapsed(),
            &rays,
        );
        eprintln!("{line}");
    }
    Ok(())
}

/// Encodes `image` as `destination` asks (PNG for stdout, else the file's
/// format) and writes it.
pub(super) fn write_image(image: &Image, destination: &Destination) -> Result<(), CliError> {
    let bytes = image
        .encode(destination.format())
        .map_err(CliError::Encode)?;
    let result = match destination {
        Destination::Stdout => std::io::stdout().lock().write_all(&bytes),
        Destination::File { path, .. } => std::fs::write(path, &bytes),
    };
    result.map_err(|error| CliError::Write {
        what: destination.name(),
        error,
    })
}

fn print_stats(rendered: &Rendered, scene: &Scene, parse_time: Duration, threads: usize) {
    let s = &rendered.stats;
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    eprintln!("parse   {:10.2} ms", ms(parse_time));
    eprintln!("build   {:10.2} ms", ms(s.build_time));
    eprintln!("render  {:10.2} ms  ({threads} threads)", ms(s.render_time));
    let r = &s.rays;
    eprintln!(
        "rays    eye {}  shadow {}  reflection {}  refraction {}  total {}",
        r.eye,
        r.shadow,
        r.reflection,
        r.refraction,
        r.total()
    );
    let p = &s.in_packets;
    eprintln!(
        "packets eye {}  shadow {}  (rays handed to the index together: a tile's eye rays, its shadow rays toward one light, walked together where they pay)",
        p.eye, p.shadow
    );
    eprintln!(
        "lights  {} of {} with a light buffer ({:.1} MB): their shadow rays test its lists, the others' walk the grid",
        s.light_buffers.lights,
        scene.lights.len(),
        s.light_buffers.bytes as f64 / 1e6
    );
    eprintln!("speed   {:10.2} Mrays/s", s.mrays_per_second());
}
