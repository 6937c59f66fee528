//! The PNG of the `images` scenario: paced announce→read latency against
//! the number of readers, one panel per resolution, one line per transport
//! (median thick with dots, latency to the last reader thin with crosses),
//! latency axis logarithmic.

use crate::images::{ImagesReport, TRANSPORTS};
use crate::plot::{draw_legend, draw_transport, log_range, us_label};
use anyhow::{Result, anyhow};
use plotters::prelude::*;
use std::path::Path;

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
    let y_range = log_range(&ys);
    let xmax = paced.iter().map(|r| r.readers).max().unwrap_or(8) as f64 + 0.5;
    // the figure's set-up (font, background, file) is nerve_plot_font::figure's
    Ok(nerve_plot_font::figure::write_png_with(path, (1400, 520), |root| {
        let title = format!(
            "frame announce → read, {} fps paced, readers in separate processes ({} CPUs)",
            report.rate_fps, report.head.machine.nproc
        );
        let root = root.titled(&title, ("sans-serif", 20)).map_err(|x| e(&x))?;
        let panels = root.split_evenly((1, resolutions.len()));
        for (panel, res) in panels.iter().zip(&resolutions) {
            let mut chart = ChartBuilder::on(panel)
                .caption(*res, ("sans-serif", 18))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(0.5f64..xmax, y_range.clone().log_scale())
                .map_err(|x| e(&x))?;
            chart
                .configure_mesh()
                .x_desc("readers")
                .y_desc("µs (thick: median; thin: last reader)")
                .x_label_formatter(&|v| format!("{v:.0}"))
                .y_label_formatter(&us_label)
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
                draw_transport(&mut chart, t, &pts).map_err(|x| e(&x))?;
            }
            draw_legend(&mut chart, 14).map_err(|x| e(&x))?;
        }
        Ok(())
    })?)
}
