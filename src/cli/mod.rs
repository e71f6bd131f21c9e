//! The command line: argument parsing, dispatch, and exit codes.
//! Each subcommand's arguments live next to the code that runs it.

mod bench;
mod gen;
mod load;
mod output_path;
mod refusal;
mod render;
mod scene_input;
mod serve;

use clap::{Parser, Subcommand};
use std::fmt;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "voxtrace",
    version,
    about = "A fast, exact ray tracer for spheres and ellipsoids"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene file to PPM or PNG.
    Render(render::RenderArgs),
    /// Serve renders over HTTP: POST a scene to /render, get a PNG.
    Serve(serve::ServeArgs),
    /// Load-test the render service (closed or open loop) and report throughput and latency.
    Load(load::LoadArgs),
    /// Write a random scene (uniform, mixed or clustered) in the classic dialect.
    Gen(gen::GenArgs),
    /// Measure parse, index build and ray speed against brute force.
    Bench(bench::BenchArgs),
    /// Render a fixed suite under variants and report speed against error.
    Report(crate::tools::report::ReportArgs),
}

/// Why a command failed; decides the exit code.
#[derive(Debug)]
pub enum CliError {
    /// The scene text is invalid (exit code 2).
    Scene {
        path: String,
        error: crate::scene::SceneError,
    },
    /// The arguments make no sense together (exit code 2).
    Usage(String),
    /// The arguments parse, but what they ask is refused (exit code 2).
    Refused(refusal::Refusal),
    /// Anything else: files, rendering, encoding (exit code 1).
    Failed(String),
}

impl CliError {
    fn exit_code(&self) -> ExitCode {
        match self {
            CliError::Scene { .. } | CliError::Usage(_) | CliError::Refused(_) => ExitCode::from(2),
            CliError::Failed(_) => ExitCode::from(1),
        }
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CliError::Scene { path, error } => write!(f, "{path}: {error}"),
            CliError::Usage(why) | CliError::Failed(why) => write!(f, "{why}"),
            CliError::Refused(refusal) => write!(f, "{refusal}"),
        }
    }
}

/// Runs the command line and returns the process's exit code: 0 on success,
/// 2 for a scene or usage error or a refusal, 1 for any other failure.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
        }
    };
    let result = match cli.command {
        Command::Render(args) => render::run(args),
        Command::Serve(args) => serve::run(args),
        Command::Load(args) => load::run(args),
        Command::Gen(args) => gen::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Report(args) => {
            crate::tools::report::run(args).map_err(|e| CliError::Failed(e.to_string()))
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("voxtrace: {e}");
            e.exit_code()
        }
    }
}

/// A rayon pool of `threads` threads (all cores when `None`).
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool, CliError> {
    if threads == Some(0) {
        return Err(CliError::Usage("--threads must be at least 1".into()));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .map_err(|e| CliError::Failed(format!("cannot start the render threads: {e}")))
}
