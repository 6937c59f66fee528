//! The PNG of round-trip latency against payload size, one line per
//! transport (median solid, p99 dashed-looking thin line with crosses), both
//! axes logarithmic.

use crate::hop::{HopReport, TRANSPORTS};
use anyhow::{Result, anyhow};
use nerve_plot_font::figure::write_png_with;
use plotters::prelude::*;
use std::path::Path;

/// The colour of a transport, the same in every plot.
pub(crate) fn colour(t: &str) -> RGBColor {
    match t {
        "nerve" | "stm" => RGBColor(200, 30, 30),
        "nerve-pmqos" => RGBColor(255, 110, 80),
        "iox2-waitset" | "iox2-slice" => RGBColor(30, 90, 200),
        "iox2-waitset-pmqos" => RGBColor(110, 160, 250),
        "futex" => RGBColor(0, 0, 0),
        "futex-pmqos" => RGBColor(90, 90, 90),
        "nerve-pinned" => RGBColor(150, 0, 60),
        "futex-pinned" => RGBColor(60, 60, 160),
        "uds" => RGBColor(160, 160, 60),
        "uds-pmqos" => RGBColor(200, 200, 120),
        "iox2-listener" => RGBColor(20, 150, 60),
        "iox2-waitset-fill" => RGBColor(230, 140, 20),
        "ddsperf" => RGBColor(140, 60, 170),
        "nerve-poll" => RGBColor(240, 120, 160),
        "nerve-python" => RGBColor(230, 190, 0),
        "nerve-python-pmqos" => RGBColor(250, 225, 110),
        "iox2-poll" => RGBColor(90, 190, 210),
        "dora" | "dora-5ms" => RGBColor(110, 70, 30),
        "dora-pmqos" | "dora-5ms-pmqos" => RGBColor(185, 140, 95),
        _ => RGBColor(120, 120, 120),
    }
}

/// A logarithmic y range (µs) that holds every value of `ys`, with a margin.
pub(crate) fn log_range(ys: &[f64]) -> std::ops::Range<f64> {
    let ymax = ys.iter().copied().fold(10.0, f64::max) * 2.0;
    let ymin = ys.iter().copied().filter(|v| *v > 0.0).fold(f64::MAX, f64::min).min(ymax / 10.0) / 2.0;
    ymin.max(0.1)..ymax
}

/// Formats a value of a logarithmic µs axis.
pub(crate) fn us_label(v: &f64) -> String {
    if *v >= 10.0 { format!("{v:.0}") } else { format!("{v:.1}") }
}

/// Draws one transport: `pts` are (x, main value, second value); the main
/// values as a thick line with dots (and the legend entry), the second as a
/// thin line with crosses.
pub(crate) fn draw_transport<DB, X, Y>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>,
    label: &str,
    pts: &[(f64, f64, f64)],
) -> Result<(), String>
where
    DB: DrawingBackend,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    let c = colour(label);
    chart
        .draw_series(LineSeries::new(pts.iter().map(|p| (p.0, p.1)), c.stroke_width(3)))
        .map_err(e)?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3)));
    chart.draw_series(pts.iter().map(|p| Circle::new((p.0, p.1), 5, c.filled()))).map_err(e)?;
    chart.draw_series(LineSeries::new(pts.iter().map(|p| (p.0, p.2)), c.stroke_width(1))).map_err(e)?;
    chart.draw_series(pts.iter().map(|p| Cross::new((p.0, p.2), 5, c.stroke_width(1)))).map_err(e)?;
    Ok(())
}

/// Draws the legend in the upper left corner.
pub(crate) fn draw_legend<'a, DB, X, Y>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    font_size: u32,
) -> Result<(), String>
where
    DB: DrawingBackend + 'a,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", font_size))
        .draw()
        .map_err(|x| x.to_string())
}

/// Draws `report` into `path` (PNG, 1000x640).
pub fn hop_png(report: &HopReport, path: &Path) -> Result<()> {
    // the figure's set-up (font, background, file) is nerve_plot_font::figure's
    Ok(write_png_with(path, (1000, 640), |root| {
        let e = |x: &dyn std::fmt::Display| anyhow!("plot {}: {x}", path.display());
        let ys: Vec<f64> =
            report.results.iter().flat_map(|r| [r.rtt.p50_ns, r.rtt.p99_ns]).map(|v| v as f64 / 1e3).collect();
        let title = format!(
            "one-hop round trip, 2 processes, event-driven and polling ({} CPUs, {})",
            report.head.machine.nproc,
            report.head.machine.cpu.split_whitespace().take(4).collect::<Vec<_>>().join(" ")
        );
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d((4f64..2e7f64).log_scale(), log_range(&ys).log_scale())
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_desc("payload bytes (8 B, 320x240 RGB, 1920x1080 RGB)")
            .y_desc("round trip, µs (solid: median, thin: p99)")
            .x_label_formatter(&|v| {
                if *v >= 1e6 {
                    format!("{:.0}M", v / 1e6)
                } else if *v >= 1e3 {
                    format!("{:.0}k", v / 1e3)
                } else {
                    format!("{v:.0}")
                }
            })
            .y_label_formatter(&us_label)
            .draw()
            .map_err(|x| e(&x))?;
        for t in TRANSPORTS {
            let pts: Vec<(f64, f64, f64)> = report
                .results
                .iter()
                .filter(|r| r.transport == t)
                .map(|r| (r.size as f64, r.rtt.p50_ns as f64 / 1e3, r.rtt.p99_ns as f64 / 1e3))
                .collect();
            if pts.is_empty() {
                continue;
            }
            draw_transport(&mut chart, t, &pts).map_err(|x| e(&x))?;
        }
        draw_legend(&mut chart, 16).map_err(|x| e(&x))?;
        Ok(())
    })?)
}
