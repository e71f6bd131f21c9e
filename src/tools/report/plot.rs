//! Time against error, one panel per scene family and reference, with the
//! Pareto front (no variant both faster and more accurate) drawn as a line.
//!
//! Each variant is a numbered marker, named in full in the legend beside
//! its panel; numbers are placed where they overlap no other. Both axes
//! are logarithmic with ticks at 1, 2 and 5 of each decade in range, so
//! every axis has some; an error of exactly zero (the reference itself, and
//! anything identical to it) has no place on a log axis and is drawn in a
//! strip of its own under the panel, on the same time axis.

use super::{Against, Report, ReportError};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

pub const FILE_NAME: &str = "time-vs-error.svg";
/// Pixels: the width of the plot, one panel's height, the chart's part of
/// the width (the legend takes the rest), the zero strip's height.
const WIDTH: u32 = 1200;
const PANEL_HEIGHT: u32 = 430;
const CHART_WIDTH: u32 = 760;
const STRIP_HEIGHT: u32 = 80;
/// Font size of marker numbers, and the width of one of their digits.
const LABEL_SIZE: u32 = 12;
const DIGIT_WIDTH: i32 = 7;

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// One variant in one panel.
struct Point {
    number: usize,
    ms: f64,
    rmse: f64,
    label: String,
    pareto: bool,
}

fn err(e: impl std::fmt::Display) -> ReportError {
    ReportError::Plot(e.to_string())
}

pub fn draw(report: &Report, path: &Path) -> Result<(), ReportError> {
    let families = report.families();
    let panels = (families.len() * 2).max(1) as u32;
    let root = SVGBackend::new(path, (WIDTH, PANEL_HEIGHT * panels)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let areas = root.split_evenly((panels as usize, 1));
    let mut areas = areas.into_iter();
    for family in families {
        let summaries = report.summarize(family);
        for (against, what) in [
            (
                Against::Reference,
                "against f64 at depth 16, full resolution",
            ),
            (
                Against::SampledReference,
                "against f64 with 256 samples per pixel, reduced resolution",
            ),
        ] {
            let area = areas.next().expect("one panel per family and reference");
            let points: Vec<Point> = summaries
                .iter()
                .filter(|s| report.variants[s.variant].against == against)
                .enumerate()
                .map(|(i, s)| Point {
                    number: i + 1,
                    ms: s.seconds * 1e3,
                    rmse: s.mean_rmse,
                    label: report.variants[s.variant].label.clone(),
                    pareto: s.pareto,
                })
                .collect();
            let caption = format!("{}: {what}", family.title());
            panel(area, &caption, &points)?;
        }
    }
    root.present().map_err(err)
}

fn panel(area: Area<'_>, caption: &str, points: &[Point]) -> Result<(), ReportError> {
    let (chart, legend_area) = area.split_horizontally(CHART_WIDTH);
    let height = chart.dim_in_pixel().1;
    let (main, strip) = chart.split_vertically(height - STRIP_HEIGHT);
    let (t_lo, t_hi) = bounds(points.iter().map(|p| p.ms));
    let nonzero: Vec<&Point> = points.iter().filter(|p| p.rmse > 0.0).collect();
    let (e_lo, e_hi) = bounds(nonzero.iter().map(|p| p.rmse));
    let mut c = ChartBuilder::on(&main)
        .caption(caption, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(
            (t_lo..t_hi).log_scale().with_key_points(ticks(t_lo, t_hi)),
            (e_lo..e_hi).log_scale().with_key_points(ticks(e_lo, e_hi)),
        )
        .map_err(err)?;
    c.configure_mesh()
        .x_desc("time, summed over the family's scenes (ms, log)")
        .y_desc("mean RMSE (8-bit levels, log)")
        .x_label_formatter(&|v| number(*v))
        .y_label_formatter(&|v| number(*v))
        .draw()
        .map_err(err)?;
    let mut front: Vec<(f64, f64)> = nonzero
        .iter()
        .filter(|p| p.pareto)
        .map(|p| (p.ms, p.rmse))
        .collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    c.draw_series(LineSeries::new(front, RED.stroke_width(2)))
        .map_err(err)?;
    let mut placed = vec![];
    for p in &nonzero {
        let at = c.backend_coord(&(p.ms, p.rmse));
        draw_marker(&c, (p.ms, p.rmse), at, p, &mut placed)?;
    }
    zero_strip(&strip, (t_lo, t_hi), points)?;
    legend(&legend_area, points)
}

/// The variants with an error of exactly zero, on the panel's time axis.
fn zero_strip(
    strip: &Area<'_>,
    (t_lo, t_hi): (f64, f64),
    points: &[Point],
) -> Result<(), ReportError> {
    let mut c = ChartBuilder::on(strip)
        .margin_left(10)
        .margin_right(10)
        .x_label_area_size(24)
        .y_label_area_size(64)
        .build_cartesian_2d(
            (t_lo..t_hi).log_scale().with_key_points(ticks(t_lo, t_hi)),
            0.0..1.0f64,
        )
        .map_err(err)?;
    c.configure_mesh()
        .x_label_formatter(&|v| number(*v))
        .y_labels(3)
        .y_label_formatter(&|v| {
            if (v - 0.5).abs() < 0.01 {
                "RMSE 0".into()
            } else {
                String::new()
            }
        })
        .disable_x_mesh()
        .disable_y_mesh()
        .label_style(("sans-serif", 12))
        .draw()
        .map_err(err)?;
    let mut placed = vec![];
    for p in points.iter().filter(|p| p.rmse == 0.0) {
        let at = c.backend_coord(&(p.ms, 0.5));
        draw_marker(&c, (p.ms, 0.5), at, p, &mut placed)?;
    }
    Ok(())
}

/// A marker and its number, the number where it overlaps none of `placed`
/// (pixel boxes of numbers drawn before).
fn draw_marker<'a, X, Y>(
    c: &ChartContext<'_, SVGBackend<'a>, Cartesian2d<X, Y>>,
    at: (f64, f64),
    pixel: (i32, i32),
    p: &Point,
    placed: &mut Vec<(i32, i32, i32, i32)>,
) -> Result<(), ReportError>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let text = p.number.to_string();
    let w = DIGIT_WIDTH * text.len() as i32;
    let h = LABEL_SIZE as i32;
    let candidates = [
        (6, -14),
        (6, 2),
        (-6 - w, -14),
        (-6 - w, 2),
        (-w / 2, -20),
        (-w / 2, 8),
        (10, -26),
        (-10 - w, -26),
        (10, 14),
        (-10 - w, 14),
    ];
    let clear = |&(dx, dy): &(i32, i32)| {
        let b = (
            pixel.0 + dx,
            pixel.1 + dy,
            pixel.0 + dx + w,
            pixel.1 + dy + h,
        );
        placed
            .iter()
            .all(|q| b.2 <= q.0 || q.2 <= b.0 || b.3 <= q.1 || q.3 <= b.1)
    };
    let (dx, dy) = candidates
        .iter()
        .copied()
        .find(|o| clear(o))
        .unwrap_or((6, -14 - 12 * placed.len() as i32 % 48));
    placed.push((
        pixel.0 + dx,
        pixel.1 + dy,
        pixel.0 + dx + w,
        pixel.1 + dy + h,
    ));
    let style = if p.pareto {
        RED.filled()
    } else {
        BLUE.stroke_width(1)
    };
    let marker = EmptyElement::at(at)
        + Circle::new((0, 0), 4, style)
        + Text::new(text, (dx, dy), ("sans-serif", LABEL_SIZE));
    c.plotting_area().draw(&marker).map_err(err)
}

/// Every variant of the panel by number, in full.
fn legend(area: &Area<'_>, points: &[Point]) -> Result<(), ReportError> {
    let font = ("sans-serif", 13);
    let mut y = 34;
    area.draw(&Text::new(
        "● on the Pareto front (red line)   ○ not",
        (8, 12),
        font,
    ))
    .map_err(err)?;
    for p in points {
        let style = if p.pareto {
            RED.filled()
        } else {
            BLUE.stroke_width(1)
        };
        area.draw(&Circle::new((14, y + 6), 4, style))
            .map_err(err)?;
        let zero = if p.rmse == 0.0 { "  (exact)" } else { "" };
        area.draw(&Text::new(
            format!("{:>2}  {}{zero}", p.number, p.label),
            (26, y),
            font,
        ))
        .map_err(err)?;
        y += 19;
    }
    Ok(())
}

/// A tick label: a few significant digits, no trailing zeros.
fn number(v: f64) -> String {
    if v >= 100.0 {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    }
}

/// Ticks at 1, 2 and 5 of each decade within [lo, hi]; every digit when
/// that gives fewer than three; and five values evenly spread, to two
/// significant digits, when even that does.
fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let within = |steps: &[f64]| -> Vec<f64> {
        let mut out = vec![];
        let mut decade = 10f64.powi(lo.log10().floor() as i32);
        while decade <= hi {
            out.extend(
                steps
                    .iter()
                    .map(|s| s * decade)
                    .filter(|&v| v >= lo && v <= hi),
            );
            decade *= 10.0;
        }
        out
    };
    let coarse = within(&[1.0, 2.0, 5.0]);
    if coarse.len() >= 3 {
        return coarse;
    }
    let fine = within(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    if fine.len() >= 3 {
        return fine;
    }
    (1..=5)
        .map(|k| {
            let v = lo + (hi - lo) * f64::from(k) / 6.0;
            let unit = 10f64.powi(v.log10().floor() as i32 - 1);
            (v / unit).round() * unit
        })
        .filter(|&v| v >= lo && v <= hi)
        .collect()
}

/// A logarithmic axis range around `values`, with some room on both sides.
fn bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !lo.is_finite() || hi <= 0.0 {
        return (0.01, 1.0);
    }
    (lo / 1.6, hi * 1.6)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_axis_gets_at_least_three_ticks() {
        for (lo, hi) in [(0.01, 1.0), (150.0, 260.0), (0.3, 0.5), (12.0, 30000.0)] {
            let t = ticks(lo, hi);
            assert!(t.len() >= 3, "{lo}..{hi}: {t:?}");
            assert!(t.iter().all(|&v| v >= lo && v <= hi));
        }
    }
}
