//! `voxtrace report`.

use super::choice::choice;
use super::CliError;
use crate::names::Named;
use crate::threads::Threads;
use crate::tools::report::{self, Family, ReportConfig};
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct ReportArgs {
    /// Where report.md and the plot go.
    #[arg(long, default_value = "docs/report")]
    out: PathBuf,
    /// The course's reference scenes (with classic/ and tinygraphics/).
    /// Default: `tests/fixtures/reference` here, else in the source tree
    /// this binary was built from.
    #[arg(long, value_name = "DIR")]
    reference: Option<PathBuf>,
    /// The hard-case scenes. Default: `scenes/hard` here, else in the
    /// source tree this binary was built from.
    #[arg(long, value_name = "DIR")]
    hard: Option<PathBuf>,
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

/// Where the reference scenes ship, in voxtrace's source tree.
const REFERENCE_DIR: &str = "tests/fixtures/reference";
/// Where the hard cases ship, in voxtrace's source tree.
const HARD_DIR: &str = "scenes/hard";
/// The source tree the binary was built from: the scenes ship there, so
/// the report runs from any directory on the machine that built it.
const SOURCE_TREE: &str = env!("CARGO_MANIFEST_DIR");

/// The directory `given` with `flag`, else the first of `roots` holding
/// `shipped`; a usage error naming the flag when none does.
fn scene_dir(
    given: Option<PathBuf>,
    shipped: &str,
    flag: &str,
    roots: &[&Path],
) -> Result<PathBuf, CliError> {
    if let Some(dir) = given {
        return Ok(dir);
    }
    roots
        .iter()
        .map(|root| root.join(shipped))
        .find(|dir| dir.is_dir())
        .ok_or_else(|| {
            let looked: Vec<String> = roots
                .iter()
                .map(|root| root.join(shipped).display().to_string())
                .collect();
            CliError::Usage(format!(
                "the report needs the scenes that ship in voxtrace's source tree under {shipped}, and found none (looked in {}): pass {flag} DIR",
                looked.join(" and ")
            ))
        })
}

pub fn run(args: ReportArgs) -> Result<(), CliError> {
    let roots = [Path::new("."), Path::new(SOURCE_TREE)];
    let reference = if args.families.contains(&Family::Reference) {
        scene_dir(args.reference, REFERENCE_DIR, "--reference", &roots)?
    } else {
        args.reference.unwrap_or_default()
    };
    let config = ReportConfig {
        out: args.out,
        reference,
        hard: scene_dir(args.hard, HARD_DIR, "--hard", &roots)?,
        reps: args.reps,
        aa_size: args.aa_size,
        families: args.families,
    };
    let pool = super::thread_pool(args.threads)?;
    pool.install(|| report::run(&config))
        .map_err(CliError::Report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_dirs_come_from_the_flag_then_the_first_root_that_has_them() {
        let source = Path::new(SOURCE_TREE);
        let nowhere = Path::new("/nonexistent/voxtrace");
        let given = scene_dir(Some("mine".into()), HARD_DIR, "--hard", &[nowhere]);
        assert_eq!(given.unwrap(), PathBuf::from("mine"));
        let found = scene_dir(None, HARD_DIR, "--hard", &[nowhere, source]).unwrap();
        assert_eq!(found, source.join(HARD_DIR));
        let missing = scene_dir(None, REFERENCE_DIR, "--reference", &[nowhere]).unwrap_err();
        assert!(matches!(missing, CliError::Usage(_)));
        assert_eq!(
            missing.to_string(),
            "the report needs the scenes that ship in voxtrace's source tree under tests/fixtures/reference, and found none (looked in /nonexistent/voxtrace/tests/fixtures/reference): pass --reference DIR"
        );
    }
}
