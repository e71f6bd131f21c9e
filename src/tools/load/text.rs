//! The text report of a run, laid out for a terminal.

use super::report::LoadReport;
use super::units;
use super::{LoadConfig, Until};
use std::fmt;

/// A report with the configuration that produced it.
pub struct TextReport<'a> {
    pub report: &'a LoadReport,
    pub config: &'a LoadConfig,
}

impl fmt::Display for TextReport<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.target(f)?;
        self.requests(f)?;
        self.latency(f)?;
        self.answers(f)?;
        let r = self.report;
        write!(
            f,
            "received   {} = {}/s",
            units::bytes(r.bytes as f64),
            units::bytes(r.per_second(r.bytes))
        )
    }
}

impl TextReport<'_> {
    fn target(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (r, config) = (self.report, self.config);
        let target = if config.in_process {
            "in process".to_owned()
        } else {
            format!("http://{}{}", config.url.authority, config.url.target)
        };
        let connections = units::count(r.connections as u64, "connection");
        let mode = match r.rate {
            Some(rate) => format!(
                "open loop at {rate} req/s, {connections} opened of at most {}",
                config.max_connections()
            ),
            None => format!("closed loop, {connections}"),
        };
        writeln!(f, "target     {target}  ({mode})")
    }

    fn requests(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = self.report;
        let (requests, elapsed) = (r.requests, units::duration(r.elapsed));
        match r.successes() {
            0 => writeln!(f, "requests   {requests} in {elapsed}, none succeeded")?,
            ok => writeln!(
                f,
                "requests   {requests} in {elapsed} = {:.1} req/s, {ok} succeeded ({:.1}%)",
                r.requests_per_s(),
                100.0 * ok as f64 / requests as f64
            )?,
        }
        if let (Some(rate), Some(send_rate)) = (r.rate, r.send_rate) {
            writeln!(
                f,
                "sent       {} of {} due = {send_rate:.1} of {rate} req/s",
                r.sent(),
                r.scheduled
            )?;
        }
        if let Until::Elapsed(_) = self.config.until {
            writeln!(
                f,
                "           {} unfinished (no answer by the end of the {} grace), {} not sent",
                r.unfinished,
                units::duration(r.grace),
                r.not_sent
            )?;
        }
        if r.renders > 0 {
            writeln!(
                f,
                "renders    {} = {:.2} renders/s, {:.2} Mrays/s",
                r.renders,
                r.renders_per_s(),
                r.mrays_per_s()
            )?;
        }
        Ok(())
    }

    fn latency(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = self.report;
        if r.requests == 0 {
            return writeln!(f, "latency    no request ended");
        }
        writeln!(
            f,
            "latency    mean {}  stdev {}",
            units::duration(r.latency.mean),
            units::duration(r.latency.stdev)
        )?;
        writeln!(f, "           {}", r.latency)?;
        for (status, latency) in &r.latency_by_status {
            writeln!(f, "  {status}      {latency}")?;
        }
        writeln!(f, "histogram")?;
        writeln!(f, "{}", r.histogram)
    }

    fn answers(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = self.report;
        let status: Vec<String> = r.status.iter().map(|(s, n)| format!("{s}: {n}")).collect();
        writeln!(f, "status     {}", none_or(status))?;
        for (status, body) in &r.status_samples {
            writeln!(f, "  {status}      \"{body}\"")?;
        }
        if r.missing_retry_after > 0 {
            writeln!(f, "503s without Retry-After: {}", r.missing_retry_after)?;
        }
        let errors: Vec<String> = r.errors.iter().map(|(e, n)| format!("{e}: {n}")).collect();
        writeln!(f, "errors     {}", none_or(errors))?;
        for (name, detail) in &r.error_samples {
            writeln!(f, "  {name:<8} {detail}")?;
        }
        Ok(())
    }
}

fn none_or(items: Vec<String>) -> String {
    if items.is_empty() {
        "none".into()
    } else {
        items.join("  ")
    }
}
