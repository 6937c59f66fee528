//! The PNG of the `images` scenario: paced announce→read latency against
//! the number of readers, one panel per resolution, one line per transport
//! (median thick with dots, latency to the last reader thin with crosses),
//! latency axis logarithmic.

use crate::images::{ImagesReport, TRANSPORTS};
use anyhow::{Result, anyhow};
use plotters::prelude::*;
use std::path::Path;

fn colour(t: &str) -> RGBColor {
    match t {
        "stm" => RGBColor(200, 30, 30),
        "iox2-slice" => RGBColor(30, 90, 200),
        _ => RGBColor(120, 120, 120),
    }
}

/// Draws `report` into `path` (PNG, 1400x520).
pub fn images_png(report: &ImagesReport, path: &Path) -> Result<()> {
    let e = |x: &dyn std::fmt::Display| anyhow!("plot {}: {x}", path.display());
    let paced: Vec<_> = report.results.iter().filter(|r| r.mode == "paced").collect();
    let mut resolutions: Vec<&str> = Vec::new();
    for r in &paced {
        if !resolutions.contains(&r.resolution.as_str()) {
            resolutions.push(&r.resolution);
        }
    }
    if resolutions.is_empty() {
        return Err(anyhow!("no paced results to plot"));
    }
    let ys: Vec<f64> =
        paced.iter().flat_map(|r| [r.latency.p50_ns, r.latency_last.p50_ns]).map(|v| v as f64 / 1e3).collect();
    let ymax = ys.iter().copied().fold(10.0, f64::max) * 2.0;
    let ymin = ys.iter().copied().filter(|v| *v > 0.0).fold(f64::MAX, f64::min).min(ymax / 10.0) / 2.0;
    let xmax = paced.iter().map(|r| r.readers).max().unwrap_or(8) as f64 + 0.5;
    let root = BitMapBackend::new(path, (1400, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let title = format!(
        "frame announce → read, {} fps paced, readers in separate processes ({} CPUs)",
        report.rate_fps, report.machine.nproc
    );
    let root = root.titled(&title, ("sans-serif", 20)).map_err(|x| e(&x))?;
    let panels = root.split_evenly((1, resolutions.len()));
    for (panel, res) in panels.iter().zip(&resolutions) {
        let mut chart = ChartBuilder::on(panel)
            .caption(*res, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.5f64..xmax, (ymin.max(0.1)..ymax).log_scale())
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_desc("readers")
            .y_desc("µs (thick: median; thin: last reader)")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| if *v >= 10.0 { format!("{v:.0}") } else { format!("{v:.1}") })
            .draw()
            .map_err(|x| e(&x))?;
        for t in TRANSPORTS {
            let pts: Vec<(f64, f64, f64)> = paced
                .iter()
                .filter(|r| r.transport == t && r.resolution == *res)
                .map(|r| (r.readers as f64, r.latency.p50_ns as f64 / 1e3, r.latency_last.p50_ns as f64 / 1e3))
                .collect();
            if pts.is_empty() {
                continue;
            }
            let c = colour(t);
            chart
                .draw_series(LineSeries::new(pts.iter().map(|p| (p.0, p.1)), c.stroke_width(3)))
                .map_err(|x| e(&x))?
                .label(t)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3)));
            chart.draw_series(pts.iter().map(|p| Circle::new((p.0, p.1), 5, c.filled()))).map_err(|x| e(&x))?;
            chart.draw_series(LineSeries::new(pts.iter().map(|p| (p.0, p.2)), c.stroke_width(1))).map_err(|x| e(&x))?;
            chart.draw_series(pts.iter().map(|p| Cross::new((p.0, p.2), 5, c.stroke_width(1)))).map_err(|x| e(&x))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))?;
    Ok(())
}
