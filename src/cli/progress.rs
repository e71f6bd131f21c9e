//! The progress bar of `voxtrace render`.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// A progress bar on stderr counting `unit`s (rows, tiles), shown only on
/// a terminal, not when `quiet`, and only once the work has taken more
/// than a second.
pub struct Progress {
    bar: ProgressBar,
    started: Instant,
    terminal: bool,
}

impl Progress {
    pub fn new(total: u32, unit: &str, quiet: bool) -> Self {
        let bar =
            ProgressBar::with_draw_target(Some(u64::from(total)), ProgressDrawTarget::hidden());
        let template = format!("{{bar:40}} {{pos}}/{{len}} {unit}  {{elapsed}} (eta {{eta}})");
        if let Ok(style) = ProgressStyle::with_template(&template) {
            bar.set_style(style);
        }
        Progress {
            bar,
            started: Instant::now(),
            terminal: !quiet && std::io::stderr().is_terminal(),
        }
    }

    pub fn update(&self, done: u32) {
        if self.terminal && self.bar.is_hidden() && self.started.elapsed() > Duration::from_secs(1)
        {
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
        }
        self.bar.set_position(u64::from(done));
    }

    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
