//! The figure of `nerve calibrate checkpoint` (Appendix A of the thesis),
//! as PNG and SVG, drawn like the demo's figures ([`crate::plot`]):
//!
//! * top: the distance each sample's pixel distance `d` gives against the
//!   true distance, for the pinhole term alone (`D·f/d`) and for the fitted
//!   model, with the line `estimated = true`;
//! * bottom: the residuals (estimated − true, millimetres) of both against
//!   the true distance.
//!
//! The legend gives each one's RMS error over the samples. The module knows
//! nothing of the model: the caller hands it, per sample, the true distance
//! and the two estimates.

use crate::DemoError;
use crate::plot::Figures;
use nerve_plot_font::figure::{DrawResult, Figure, write_png_and_svg};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// One calibration sample as the figure shows it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationPoint {
    /// True distance (camera to the tube's near surface), metres.
    pub true_m: f64,
    /// What the pinhole term alone gives, metres.
    pub pinhole_m: f64,
    /// What the fitted model gives, metres (`None` where it is not defined).
    pub fitted_m: Option<f64>,
}

const PINHOLE: RGBColor = RGBColor(210, 120, 20);
const FITTED: RGBColor = RGBColor(30, 90, 200);
const IDENTITY: RGBColor = RGBColor(120, 120, 120);

/// Root-mean-square of `e`, `None` when empty.
fn rms(e: impl Iterator<Item = f64>) -> Option<f64> {
    let (n, s) = e.fold((0usize, 0.0), |(n, s), x| (n + 1, s + x * x));
    (n > 0).then(|| (s / n as f64).sqrt())
}

/// RMS error of the pinhole term and of the fitted model over `points`, metres.
pub fn rms_errors(points: &[CalibrationPoint]) -> (Option<f64>, Option<f64>) {
    (
        rms(points.iter().map(|p| p.pinhole_m - p.true_m)),
        rms(points.iter().filter_map(|p| p.fitted_m.map(|f| f - p.true_m))),
    )
}

fn mm(rms: Option<f64>) -> String {
    rms.map_or_else(|| "-".into(), |r| format!("{:.1} mm", r * 1000.0))
}

/// (low, high) of `values`, padded by 5 % (at least `min_pad`).
fn padded(values: impl Iterator<Item = f64>, min_pad: f64) -> (f64, f64) {
    let (lo, hi) =
        values.filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(min_pad);
    (lo - pad, hi + pad)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    points: &[CalibrationPoint],
    title: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let root = root.titled(title, ("sans-serif", 20)).map_err(e)?;
    let (top, bottom) = root.split_vertically(root.dim_in_pixel().1 * 3 / 5);
    let (rms_pinhole, rms_fitted) = rms_errors(points);
    let pinhole_label = format!("pinhole term D·f/d (RMS {})", mm(rms_pinhole));
    let fitted_label = format!("fitted model (RMS {})", mm(rms_fitted));
    let fitted: Vec<(f64, f64)> = points.iter().filter_map(|p| p.fitted_m.map(|f| (p.true_m, f))).collect();
    let pinhole: Vec<(f64, f64)> = points.iter().map(|p| (p.true_m, p.pinhole_m)).collect();

    // (a) estimated against true distance
    let (x0, x1) = padded(points.iter().map(|p| p.true_m), 0.05);
    let (y0, y1) = padded(pinhole.iter().chain(&fitted).map(|p| p.1).chain([x0, x1]), 0.05);
    let mut chart = ChartBuilder::on(&top)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("true distance (m)")
        .y_desc("(a) estimated distance (m)")
        .light_line_style(RGBColor(238, 238, 238))
        .draw()
        .map_err(e)?;
    chart
        .draw_series(std::iter::once(PathElement::new(vec![(x0, x0), (x1, x1)], IDENTITY.stroke_width(1))))
        .map_err(e)?
        .label("estimated = true")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], IDENTITY.stroke_width(1)));
    chart
        .draw_series(pinhole.iter().map(|p| Circle::new(*p, 3, PINHOLE.stroke_width(1))))
        .map_err(e)?
        .label(pinhole_label.clone())
        .legend(|(x, y)| Circle::new((x + 9, y), 4, PINHOLE.stroke_width(2)));
    chart
        .draw_series(fitted.iter().map(|p| Cross::new(*p, 3, FITTED.stroke_width(1))))
        .map_err(e)?
        .label(fitted_label.clone())
        .legend(|(x, y)| Cross::new((x + 9, y), 4, FITTED.stroke_width(2)));
    nerve_plot_font::figure::legend(&mut chart, SeriesLabelPosition::UpperLeft, 13).map_err(e)?;

    // (b) residuals, millimetres
    let res = |v: &[(f64, f64)]| -> Vec<(f64, f64)> {
        v.iter().zip(points).map(|(p, q)| (q.true_m, (p.1 - q.true_m) * 1000.0)).collect()
    };
    let pinhole_res = res(&pinhole);
    let fitted_res: Vec<(f64, f64)> =
        points.iter().filter_map(|p| p.fitted_m.map(|f| (p.true_m, (f - p.true_m) * 1000.0))).collect();
    let (r0, r1) = padded(pinhole_res.iter().chain(&fitted_res).map(|p| p.1).chain([0.0]), 1.0);
    let mut chart = ChartBuilder::on(&bottom)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, r0..r1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("true distance (m)")
        .y_desc("(b) estimated − true (mm)")
        .light_line_style(RGBColor(238, 238, 238))
        .draw()
        .map_err(e)?;
    chart
        .draw_series(std::iter::once(PathElement::new(vec![(x0, 0.0), (x1, 0.0)], IDENTITY.stroke_width(1))))
        .map_err(e)?;
    chart
        .draw_series(pinhole_res.iter().map(|p| Circle::new(*p, 3, PINHOLE.stroke_width(1))))
        .map_err(e)?
        .label(pinhole_label)
        .legend(|(x, y)| Circle::new((x + 9, y), 4, PINHOLE.stroke_width(2)));
    chart
        .draw_series(fitted_res.iter().map(|p| Cross::new(*p, 3, FITTED.stroke_width(1))))
        .map_err(e)?
        .label(fitted_label)
        .legend(|(x, y)| Cross::new((x + 9, y), 4, FITTED.stroke_width(2)));
    nerve_plot_font::figure::legend(&mut chart, SeriesLabelPosition::UpperRight, 13).map_err(e)?;
    Ok(())
}

/// Writes `fit.png` and `fit.svg` into `dir`.
pub fn write_fit(dir: &Path, points: &[CalibrationPoint], title: &str) -> Result<Figures, DemoError> {
    if points.is_empty() {
        return Err(DemoError::Format {
            path: dir.join("fit.png"),
            problem: "no calibration samples to draw; collect or give some first".into(),
        });
    }
    let files = write_png_and_svg(&dir.join("fit"), (1000, 900), &Fit { points, title })?;
    Ok(Figures { files: files.into() })
}

/// The fit against the pinhole term, and their residuals.
struct Fit<'a> {
    points: &'a [CalibrationPoint],
    title: &'a str,
}

impl Figure for Fit<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        Ok(draw(root, self.points, self.title)?)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn rms_of_both_estimates() {
        let pts = [
            CalibrationPoint { true_m: 1.0, pinhole_m: 1.03, fitted_m: Some(1.0) },
            CalibrationPoint { true_m: 2.0, pinhole_m: 1.97, fitted_m: None },
        ];
        let (p, f) = rms_errors(&pts);
        assert!((p.unwrap() - 0.03).abs() < 1e-12);
        assert_eq!(f, Some(0.0));
        assert_eq!(rms_errors(&[]), (None, None));
    }

    #[test]
    fn writes_a_png_and_an_svg() {
        let dir = std::env::temp_dir().join(format!("nerve-calplot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let pts: Vec<CalibrationPoint> = (0..40)
            .map(|i| {
                let z = 0.9 + 0.065 * f64::from(i);
                CalibrationPoint { true_m: z, pinhole_m: z * 1.01, fitted_m: Some(z + 0.002) }
            })
            .collect();
        let figs = write_fit(&dir, &pts, "test").unwrap();
        assert_eq!(figs.files.len(), 2);
        for f in &figs.files {
            assert!(std::fs::metadata(f).unwrap().len() > 5_000, "{} is too small", f.display());
        }
        let svg = std::fs::read_to_string(dir.join("fit.svg")).unwrap();
        assert!(svg.contains("<svg") && svg.contains("fitted model"), "the svg has the legend");
        assert!(write_fit(&dir, &[], "empty").is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
