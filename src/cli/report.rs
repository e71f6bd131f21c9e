//! `voxtrace report`.

use super::choice::choice;
use super::CliError;
use crate::names::Named;
use crate::threads::Threads;
use crate::tools::report::{self, Family, ReportConfig};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ReportArgs {
    /// Where report.md and the plot go.
    #[arg(long, default_value = "docs/report")]
    out: PathBuf,
    /// The course's reference scenes (with classic/ and tinygraphics/).
    #[arg(long, default_value = "tests/fixtures/reference")]
    reference: PathBuf,
    /// The hard-case scenes.
    #[arg(long, default_value = "scenes/hard")]
    hard: PathBuf,
    /// Timed repetitions of each variant (the median is reported).
    #[arg(long, default_value_t = 3)]
    reps: u32,
    /// Longest image side for the antialiasing part (its reference traces 256
    /// samples per pixel, so it runs at reduced resolution).
    #[arg(long, default_value_t = 96)]
    aa_size: u32,
    /// Render threads, at least 1 (default: all cores).
    #[arg(long)]
    threads: Option<Threads>,
    /// Which scene families to render (default: all).
    #[arg(
        long,
        value_parser = choice(family_help),
        value_delimiter = ',',
        default_values_t = Family::ALL.to_vec()
    )]
    families: Vec<Family>,
}

fn family_help(family: Family) -> &'static str {
    match family {
        Family::Reference => "The course's scenes, both dialects (`tests/fixtures/reference`)",
        Family::Hard => "`scenes/hard`: the numerical traps",
        Family::Generated => "Built here, deterministically: reflection and glass at depth",
    }
}

pub fn run(args: ReportArgs) -> Result<(), CliError> {
    let config = ReportConfig {
        out: args.out,
        reference: args.reference,
        hard: args.hard,
        reps: args.reps,
        aa_size: args.aa_size,
        families: args.families,
    };
    let pool = super::thread_pool(args.threads)?;
    pool.install(|| report::run(&config))
        .map_err(CliError::Report)
}
