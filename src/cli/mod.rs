//! The command line: argument parsing, dispatch, and exit codes.
//! Each subcommand's arguments live next to the code that runs it.

mod bench;
mod choice;
mod completions;
mod cores;
mod examples;
mod gen;
mod heap;
mod load;
mod output_path;
mod progress;
mod refusal;
mod remote;
mod render;
mod report;
mod scene_input;
mod serve;
mod signals;
mod size;
mod summary;

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
    #[command(after_help = examples::help(examples::RENDER))]
    Render(render::RenderArgs),
    /// Serve renders over HTTP: POST a scene to /render, get a PNG.
    #[command(after_help = examples::help(examples::SERVE))]
    Serve(serve::ServeArgs),
    /// Load-test the render service (closed or open loop) and report throughput and latency.
    #[command(after_help = examples::help(examples::LOAD))]
    Load(load::LoadArgs),
    /// Write a random scene (uniform, mixed or clustered) in the classic dialect.
    #[command(after_help = examples::help(examples::GEN))]
    Gen(gen::GenArgs),
    /// Measure parse, index build and ray speed against brute force.
    #[command(after_help = examples::help(examples::BENCH))]
    Bench(bench::BenchArgs),
    /// Render a fixed suite under variants and report speed against error.
    #[command(after_help = examples::help(examples::REPORT))]
    Report(report::ReportArgs),
    /// Write the shell completion script for bash, zsh, fish, elvish or PowerShell.
    #[command(after_help = examples::help(examples::COMPLETIONS))]
    Completions(completions::CompletionsArgs),
}

/// Why a command failed. Every failure of every command is one of these,
/// and [`CliError::exit_code`] alone decides the process's exit code.
#[derive(Debug)]
pub enum CliError {
    /// The scene text is invalid.
    Scene(Box<scene_input::BadScene>),
    /// The arguments make no sense together.
    Usage(String),
    /// The arguments parse, but what they ask is refused.
    Refused(refusal::Refusal),
    /// A file or stream (`what`: its path, or "standard output") could not be read.
    Read {
        what: String,
        error: std::io::Error,
    },
    /// A file or stream could not be written.
    Write {
        what: String,
        error: std::io::Error,
    },
    Encode(crate::output::EncodeError),
    Json(serde_json::Error),
    Pool(crate::threads::PoolError),
    Render(crate::render::RenderError),
    Bench(crate::tools::bench::BenchError),
    Report(crate::tools::report::ReportError),
    Url(crate::tools::load::UrlError),
    Duration(crate::tools::load::DurationError),
    Load(crate::tools::load::LoadError),
    /// A load run went to its end, but failed as a whole.
    LoadFailed(crate::tools::load::RunFailure),
    Serve(crate::service::BindError),
    Remote(crate::remote::RemoteError),
    /// The service stopped serving.
    Serving(std::io::Error),
}

impl CliError {
    /// 2 when the input is at fault (arguments, scene text, a refusal),
    /// 1 when the machine, the network or the work itself failed.
    fn exit_code(&self) -> ExitCode {
        use crate::render::RenderError;
        use crate::service::BindError;
        use crate::tools::bench::BenchError;
        use crate::tools::load::LoadError;
        let usage = match self {
            CliError::Scene(_) | CliError::Usage(_) | CliError::Refused(_) => true,
            CliError::Url(_) | CliError::Duration(_) => true,
            CliError::Read { .. } | CliError::Write { .. } | CliError::Serving(_) => false,
            CliError::Encode(_) | CliError::Json(_) | CliError::Pool(_) => false,
            CliError::Render(e) => {
                matches!(e, RenderError::BadOption(_) | RenderError::BadRegion(_))
            }
            CliError::Remote(e) => e.is_input_error(),
            CliError::Bench(e) => matches!(e, BenchError::Scene(..)),
            CliError::Report(_) => false,
            CliError::Load(e) => match e {
                LoadError::NoConcurrency
                | LoadError::BadRate
                | LoadError::InProcessWithoutScene => true,
                LoadError::Resolve { .. } | LoadError::NoAddress(_) | LoadError::Pool(_) => false,
            },
            CliError::LoadFailed(failure) => failure.is_input_error(),
            CliError::Serve(e) => match e {
                BindError::Config(_) | BindError::Resolve { .. } | BindError::NoAddress(_) => true,
                BindError::Listen { .. } | BindError::Pool(_) | BindError::AccessLog { .. } => {
                    false
                }
            },
        };
        ExitCode::from(if usage { 2 } else { 1 })
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CliError::Scene(bad) => write!(f, "{bad}"),
            CliError::Usage(why) => write!(f, "{why}"),
            CliError::Refused(refusal) => write!(f, "{refusal}"),
            CliError::Read { what, error } => write!(f, "cannot read {what}: {error}"),
            CliError::Write { what, error } => write!(f, "cannot write {what}: {error}"),
            CliError::Encode(e) => write!(f, "{e}"),
            CliError::Json(e) => write!(f, "cannot write JSON: {e}"),
            CliError::Pool(e) => write!(f, "{e}"),
            CliError::Render(e) => write!(f, "{e}"),
            CliError::Bench(e) => write!(f, "{e}"),
            CliError::Report(e) => write!(f, "{e}"),
            CliError::Url(e) => write!(f, "{e}"),
            CliError::Duration(e) => write!(f, "{e}"),
            CliError::Load(e) => write!(f, "{e}"),
            CliError::LoadFailed(e) => write!(f, "{e}"),
            CliError::Serve(e) => write!(f, "{e}"),
            CliError::Remote(e) => write!(f, "{e}"),
            CliError::Serving(e) => write!(f, "the service stopped: {e}"),
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
    if matches!(cli.command, Command::Render(_) | Command::Bench(_)) {
        heap::keep_freed_memory();
    }
    let result = match cli.command {
        Command::Render(args) => render::run(args),
        Command::Serve(args) => serve::run(args),
        Command::Load(args) => load::run(args),
        Command::Gen(args) => gen::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Report(args) => report::run(args),
        Command::Completions(args) => completions::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("voxtrace: {e}");
            e.exit_code()
        }
    }
}

/// The pool a command runs in: `--threads` threads, or one per core; a
/// count over the cores is warned about.
fn thread_pool(threads: Option<Threads>) -> Result<rayon::ThreadPool, CliError> {
    cores::warn_if_oversubscribed(threads);
    crate::threads::pool(threads.unwrap_or_default()).map_err(CliError::Pool)
}
