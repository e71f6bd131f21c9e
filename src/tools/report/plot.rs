//! Time against error, one panel per scene family and reference, with the
//! Pareto front (no variant both faster and more accurate) drawn as a line.

use super::{Against, Report, ReportError};
use plotters::prelude::*;
use std::path::Path;

pub const FILE_NAME: &str = "time-vs-error.svg";
/// Where an error of exactly zero is drawn on the logarithmic axis.
const ZERO_AT: f64 = 1e-3;

fn err(e: impl std::fmt::Display) -> ReportError {
    ReportError::Plot(e.to_string())
}

pub fn draw(report: &Report, path: &Path) -> Result<(), ReportError> {
    let root = SVGBackend::new(path, (1200, 1350)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let families = report.families();
    let panels = root.split_evenly((families.len().max(1), 2));
    let mut panels = panels.iter();
    for family in families {
        let summaries = report.summarize(family);
        for (against, what) in [
            (Against::Reference, "vs f64 depth 16, full resolution"),
            (
                Against::SampledReference,
                "vs f64 spp 256, reduced resolution",
            ),
        ] {
            let area = panels.next().expect("one panel per family and reference");
            let points: Vec<(f64, f64, String, bool)> = summaries
                .iter()
                .filter(|s| report.variants[s.variant].against == against)
                .map(|s| {
                    let label = report.variants[s.variant].label.clone();
                    (s.seconds * 1e3, s.mean_rmse.max(ZERO_AT), label, s.pareto)
                })
                .collect();
            panel(area, &format!("{}: {what}", family.title()), &points)?;
        }
    }
    root.present().map_err(err)
}

fn panel(
    area: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    caption: &str,
    points: &[(f64, f64, String, bool)],
) -> Result<(), ReportError> {
    let (t_lo, t_hi) = bounds(points.iter().map(|p| p.0));
    let (e_lo, e_hi) = bounds(points.iter().map(|p| p.1));
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d((t_lo..t_hi).log_scale(), (e_lo..e_hi).log_scale())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("time, summed over the family's scenes (ms)")
        .y_desc("mean RMSE (levels; 0 drawn at 1e-3)")
        .x_labels(6)
        .y_labels(6)
        .draw()
        .map_err(err)?;
    let mut front: Vec<(f64, f64)> = points.iter().filter(|p| p.3).map(|p| (p.0, p.1)).collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(LineSeries::new(front, RED.stroke_width(2)))
        .map_err(err)?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], RED.stroke_width(2)));
    chart
        .draw_series(points.iter().map(|(t, e, label, pareto)| {
            let style = if *pareto {
                RED.filled()
            } else {
                BLUE.stroke_width(1)
            };
            EmptyElement::at((*t, *e))
                + Circle::new((0, 0), 4, style)
                + Text::new(label.clone(), (6, -12), ("sans-serif", 11))
        }))
        .map_err(err)?;
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)
}

/// A logarithmic axis range around `values`, with some room on both sides.
fn bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !lo.is_finite() || hi <= 0.0 {
        return (ZERO_AT, 1.0);
    }
    (lo / 2.0, hi * 2.0)
}
