//! `voxtrace bench`.

use super::CliError;
use crate::threads::Threads;
use crate::tools::bench::{
    bench_file, bench_text, builtin_names, builtin_scene, markdown_table, BenchResult,
};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Scene files to measure instead of the built-in set
    /// (uniform, mixed, clustered, clumps and straddle scenes of 10³, 10⁵ and 10⁶ spheres
    /// at 1024×1024).
    #[arg(long, num_args = 1..)]
    scene: Vec<PathBuf>,
    /// Print a JSON list instead of a table.
    #[arg(long)]
    json: bool,
    /// Threads, at least 1 (default: all cores).
    #[arg(long)]
    threads: Option<Threads>,
    /// Skip the baselines (the grid probing every cell, and brute force).
    #[arg(long)]
    no_baselines: bool,
}

pub fn run(args: BenchArgs) -> Result<(), CliError> {
    let pool = super::thread_pool(args.threads)?;
    let mut results: Vec<BenchResult> = Vec::new();
    pool.install(|| -> Result<(), CliError> {
        if args.scene.is_empty() {
            for (name, distribution, spheres) in builtin_names() {
                eprintln!("bench: {name}");
                let text = builtin_scene(distribution, spheres);
                let result =
                    bench_text(&name, &text, !args.no_baselines).map_err(CliError::Bench)?;
                results.push(result);
            }
        } else {
            for path in &args.scene {
                eprintln!("bench: {}", path.display());
                results.push(bench_file(path, !args.no_baselines).map_err(CliError::Bench)?);
            }
        }
        Ok(())
    })?;
    if args.json {
        let json = serde_json::to_string_pretty(&results).map_err(CliError::Json)?;
        println!("{json}");
    } else {
        println!("threads: {}\n", pool.current_num_threads());
        print!("{}", markdown_table(&results));
    }
    Ok(())
}
