//! `voxtrace load`.

use super::CliError;
use crate::limits::{DEFAULT_LOAD_GRACE_MS, DEFAULT_LOAD_MAX_CONNECTIONS};
use crate::tools::load::{self, LoadConfig, TextReport, Until, Url};
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

#[derive(clap::Args)]
pub struct LoadArgs {
    /// Where to send requests (http:// only).
    #[arg(long, default_value = "http://127.0.0.1:8080/render")]
    url: String,
    /// Scene file to POST as the body; without it, requests are GETs.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Connections: closed loop, requests in flight; open loop, connections to start with.
    #[arg(long, short, default_value_t = 1)]
    concurrency: usize,
    /// Open loop: most connections to open, one more whenever a request falls due with all busy.
    #[arg(long, default_value_t = DEFAULT_LOAD_MAX_CONNECTIONS)]
    max_connections: usize,
    /// How long to run, e.g. 30s or 500ms (default 10s unless --requests).
    #[arg(long, short, conflicts_with = "requests")]
    duration: Option<String>,
    /// How many requests to send.
    #[arg(long, short = 'n')]
    requests: Option<u64>,
    /// Requests per second on a fixed schedule (open loop); latency counts from each request's due time.
    #[arg(long, short)]
    rate: Option<f64>,
    /// With --duration: how long requests in flight at its end may take to finish before they count as unfinished.
    #[arg(long, default_value_t = format!("{DEFAULT_LOAD_GRACE_MS}ms"))]
    grace: String,
    /// Longest wait for one response, e.g. 30s.
    #[arg(long, default_value = "30s")]
    timeout: String,
    /// Print one JSON object instead of the text report.
    #[arg(long)]
    json: bool,
    /// Do the service's work (parse, render, encode) in this process instead
    /// of over HTTP: the baseline the service is measured against.
    #[arg(long)]
    in_process: bool,
}

/// Runs the load, prints the report, warns when the open loop fell short
/// of its rate, and fails when the run did (nothing succeeded, or
/// transport errors dominated).
pub fn run(args: LoadArgs) -> Result<(), CliError> {
    let config = config(&args)?;
    let report = load::run(&config).map_err(CliError::Load)?;
    let text = if args.json {
        report.to_json(&config).to_string()
    } else {
        TextReport {
            report: &report,
            config: &config,
        }
        .to_string()
    };
    match writeln!(std::io::stdout().lock(), "{text}") {
        // A closed pipe (`| head`) is the reader's choice, not a failure.
        Err(error) if error.kind() != std::io::ErrorKind::BrokenPipe => {
            return Err(CliError::Write {
                what: "the report".into(),
                error,
            })
        }
        _ => {}
    }
    if let Some(shortfall) = report.shortfall(config.max_connections()) {
        eprintln!("voxtrace: {shortfall}");
    }
    report.verdict().map_err(CliError::LoadFailed)
}

fn config(args: &LoadArgs) -> Result<LoadConfig, CliError> {
    let url = Url::parse(&args.url).map_err(CliError::Url)?;
    let body = match &args.scene {
        Some(path) => Some(std::fs::read(path).map_err(|error| CliError::Read {
            what: path.display().to_string(),
            error,
        })?),
        None => None,
    };
    let duration = |text: &str| load::parse_duration(text).map_err(CliError::Duration);
    let until = match (args.requests, &args.duration) {
        (Some(n), _) => Until::Requests(n),
        (None, Some(d)) => Until::Elapsed(duration(d)?),
        (None, None) => Until::Elapsed(Duration::from_secs(10)),
    };
    Ok(LoadConfig {
        url,
        body,
        concurrency: args.concurrency,
        max_connections: args.max_connections,
        until,
        rate: args.rate,
        grace: duration(&args.grace)?,
        timeout: duration(&args.timeout)?,
        in_process: args.in_process,
        progress: !args.json,
    })
}
