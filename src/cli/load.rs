//! `voxtrace load`.

use super::CliError;
use crate::tools::load::{self, LoadConfig, Until, Url};
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
    /// Connections (closed loop: requests in flight).
    #[arg(long, short, default_value_t = 1)]
    concurrency: usize,
    /// How long to run, e.g. 30s or 500ms (default 10s unless --requests).
    #[arg(long, short, conflicts_with = "requests")]
    duration: Option<String>,
    /// How many requests to send.
    #[arg(long, short = 'n')]
    requests: Option<u64>,
    /// Requests per second on a fixed schedule (open loop); latency counts from each request's due time.
    #[arg(long, short)]
    rate: Option<f64>,
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

pub fn run(args: LoadArgs) -> Result<(), CliError> {
    let url = Url::parse(&args.url).map_err(CliError::Url)?;
    let body = match &args.scene {
        Some(path) => Some(std::fs::read(path).map_err(|error| CliError::Read {
            what: path.display().to_string(),
            error,
        })?),
        None => None,
    };
    let until = match (args.requests, &args.duration) {
        (Some(n), _) => Until::Requests(n),
        (None, Some(d)) => Until::Elapsed(load::parse_duration(d).map_err(CliError::Duration)?),
        (None, None) => Until::Elapsed(Duration::from_secs(10)),
    };
    let config = LoadConfig {
        url,
        body,
        concurrency: args.concurrency,
        until,
        rate: args.rate,
        timeout: load::parse_duration(&args.timeout).map_err(CliError::Duration)?,
        in_process: args.in_process,
        progress: !args.json,
    };
    let report = load::run(&config).map_err(CliError::Load)?;
    let text = if args.json {
        report.to_json(&config).to_string()
    } else {
        let mode = match config.rate {
            Some(rate) => format!("open loop at {rate} req/s"),
            None => "closed loop".to_owned(),
        };
        let target = if config.in_process {
            "in process".to_owned()
        } else {
            args.url.clone()
        };
        format!(
            "target    {target}  ({mode}, {} connections)\n{report}",
            config.concurrency
        )
    };
    match writeln!(std::io::stdout().lock(), "{text}") {
        // A closed pipe (`| head`) is the reader's choice, not a failure.
        Err(error) if error.kind() != std::io::ErrorKind::BrokenPipe => Err(CliError::Write {
            what: "the report".into(),
            error,
        }),
        _ => Ok(()),
    }
}
