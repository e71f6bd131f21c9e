//! The command line: argument parsing, dispatch, and exit codes.
//! Each subcommand's arguments live next to the code that runs it.

mod bench;
mod choice;
mod gen;
mod load;
mod output_path;
mod refusal;
mod render;
mod report;
mod scene_input;
mod serve;

use crate::threads::Threads;
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
    Report(report::ReportArgs),
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
    run(std::env::args_os())
}

/// [`main`] on the arguments `args`, the program's name first.
pub fn run<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
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
        Command::Report(args) => report::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("voxtrace: {e}");
            e.exit_code()
        }
    }
}

/// The pool a command runs in: `--threads` threads, or one per core.
fn thread_pool(threads: Option<Threads>) -> Result<rayon::ThreadPool, CliError> {
    crate::threads::pool(threads.unwrap_or_default()).map_err(|e| CliError::Failed(e.to_string()))
}
