//! `voxtrace gen`.

use super::choice::choice;
use super::CliError;
use crate::limits;
use crate::scene;
use crate::tools::gen::{generate, Distribution, GenOptions};
use std::io::{BufWriter, Write};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct GenArgs {
    /// Number of spheres.
    #[arg(long)]
    spheres: usize,
    /// How sizes and positions are drawn.
    #[arg(long, value_parser = choice(distribution_help), default_value_t = Distribution::Uniform)]
    dist: Distribution,
    /// Random seed; the same seed gives the same file.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Image width and height.
    #[arg(long, num_args = 2, value_names = ["W", "H"], default_values_t = [1024, 1024])]
    res: Vec<u32>,
    /// Fraction of spheres stretched into ellipsoids.
    #[arg(long, default_value_t = 0.0)]
    ellipsoids: f64,
    /// Fraction of spheres made of glass.
    #[arg(long, default_value_t = 0.0)]
    glass: f64,
    /// Output scene file (`-` for stdout).
    #[arg(short, long)]
    output: PathBuf,
}

fn distribution_help(distribution: Distribution) -> &'static str {
    match distribution {
        Distribution::Uniform => "Uniform in the frustum, radii within ±20 % of one size",
        Distribution::Mixed => "Uniform in the frustum, radii log-uniform over three decades",
        Distribution::Clustered => "Dense round clumps (√n of them) in empty space",
        Distribution::Clumps => "About ∛n clumps of very unequal population (weights u³) and radii (log-uniform over [`CLUMP_RADII`]), each with its own sphere size from its own fill, 2 % dust through the frustum, and a floor sphere of radius 1000 under it all",
        Distribution::Straddle => "Like uniform, but radii within ±20 % of a size whose diameter is a power of four: where fixed size bands would split them in two",
    }
}

pub fn run(args: GenArgs) -> Result<(), CliError> {
    let fraction = |name: &str, f: f64| {
        if (0.0..=1.0).contains(&f) {
            Ok(f)
        } else {
            Err(CliError::Usage(format!("--{name} must be between 0 and 1")))
        }
    };
    let side = |field, value| {
        scene::image_side(field, f64::from(value))
            .map_err(|e| CliError::Usage(format!("--res: {e}")))
    };
    let width = side(scene::COLUMNS_FIELD, args.res[0])?;
    let height = side(scene::ROWS_FIELD, args.res[1])?;
    if args.spheres > limits::MAX_SPHERES {
        return Err(CliError::Usage(format!(
            "--spheres must be at most {}",
            limits::MAX_SPHERES
        )));
    }
    let options = GenOptions {
        spheres: args.spheres,
        distribution: args.dist,
        seed: args.seed,
        width,
        height,
        ellipsoids: fraction("ellipsoids", args.ellipsoids)?,
        glass: fraction("glass", args.glass)?,
    };
    let display = args.output.display().to_string();
    let failed = |error| CliError::Write {
        what: display.clone(),
        error,
    };
    if display == "-" {
        let mut out = BufWriter::new(std::io::stdout().lock());
        generate(&options, &mut out)
            .and_then(|()| out.flush())
            .map_err(failed)
    } else {
        let file = std::fs::File::create(&args.output).map_err(failed)?;
        let mut out = BufWriter::with_capacity(1 << 20, file);
        generate(&options, &mut out)
            .and_then(|()| out.flush())
            .map_err(failed)
    }
}
