//! `voxtrace completions SHELL`: the shell's completion script on stdout,
//! written by `clap_complete` from the command line's own definition.

use super::CliError;
use clap::CommandFactory;
use std::io::Write;

#[derive(clap::Args)]
pub struct CompletionsArgs {
    /// The shell to write the completion script for.
    #[arg(value_enum)]
    shell: clap_complete::Shell,
}

pub fn run(args: CompletionsArgs) -> Result<(), CliError> {
    let mut command = super::Cli::command();
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut command, "voxtrace", &mut script);
    std::io::stdout()
        .lock()
        .write_all(&script)
        .map_err(|error| CliError::Write {
            what: "<stdout>".into(),
            error,
        })
}
