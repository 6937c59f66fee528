//! The Appendix A calibration's results (`nerve calibrate checkpoint`): the
//! launcher hands over the samples it took in the simulator or read from a
//! file ([`SampleSet`]); [`report`] fits the checkpoint sensor's distance
//! model (`nerve_checkpoint::appendix_a`), writes the calibration the agent
//! reads, `samples.csv` and the fit figure ([`crate::calibration_plot`]);
//! [`describe`] says what came out.

use crate::DemoError;
use crate::calibration_plot::{CalibrationPoint, write_fit};
use nerve_checkpoint::appendix_a::{Fit, FitOptions, Model, Sample, fit};
use nerve_checkpoint::config::Calibration;
use std::path::Path;

/// The samples to fit, and where they came from.
#[derive(Debug, Clone)]
pub struct SampleSet {
    /// The samples `(d, Z)`.
    pub samples: Vec<Sample>,
    /// D, metres between the band centres.
    pub band_spacing_m: f64,
    /// f, the camera's focal length in pixels.
    pub focal_px: f64,
    /// Where they came from, for the messages and the files' comments.
    pub source: String,
}

/// Fits, writes the calibration `out` (and checks it with the agent's
/// loader), `DIR/samples.csv` and the figures `DIR/fit.png|svg`.
pub fn report(set: &SampleSet, dir: &Path, out: &Path) -> Result<Fit, DemoError> {
    let f = fit(&set.samples, set.band_spacing_m * set.focal_px, &FitOptions::default())
        .map_err(|source| DemoError::Fit { context: format!("cannot fit the {}", set.source), source })?;
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .map_err(|source| DemoError::Record { context: format!("cannot create {}", parent.display()), source })?;
    }
    Calibration::from_fit(set.band_spacing_m, set.focal_px, &f).save(out)?;
    // what the checkpoint agent does with `-- --calibration FILE`
    Calibration::load(out).map_err(|source| DemoError::Calibration {
        context: "the checkpoint agent would refuse the calibration just written".into(),
        source,
    })?;
    write_samples_csv(&dir.join("samples.csv"), set)?;
    let title = format!(
        "Appendix A calibration: {} samples, {} (D = {} m, f = {:.1} px)",
        set.samples.len(),
        set.source,
        set.band_spacing_m,
        set.focal_px
    );
    write_fit(dir, &points(&set.samples, &f.model), &title)?;
    Ok(f)
}

/// Each sample's true distance and what the pinhole term and the model make of its `d`.
fn points(samples: &[Sample], model: &Model) -> Vec<CalibrationPoint> {
    samples
        .iter()
        .map(|s| CalibrationPoint {
            true_m: s.z_m,
            pinhole_m: model.df / s.d_px,
            fitted_m: model.distance(s.d_px).ok(),
        })
        .collect()
}

/// `samples.csv`, readable again with `--samples` (and by `nerve-checkpoint-fit`).
fn write_samples_csv(path: &Path, set: &SampleSet) -> Result<(), DemoError> {
    let mut text = format!(
        "# Appendix A calibration samples ({}), written by `nerve calibrate checkpoint`\n\
         # band_spacing_m = {}, focal_px = {}: refit with\n\
         #   nerve calibrate checkpoint --samples {} --band-spacing {} --focal {}\n\
         d_px,z_m\n",
        set.source,
        set.band_spacing_m,
        set.focal_px,
        path.display(),
        set.band_spacing_m,
        set.focal_px
    );
    for s in &set.samples {
        text += &format!("{},{}\n", s.d_px, s.z_m);
    }
    std::fs::write(path, text)
        .map_err(|source| DemoError::Record { context: format!("cannot write {}", path.display()), source })
}

/// The lines that say the fit, its RMS errors and what [`report`] wrote.
pub fn describe(f: &Fit, dir: &Path, out: &Path) -> Vec<String> {
    let mut lines = Vec::new();
    lines.push(format!(
        "fitted {} samples (d {:.1} … {:.1} px): h = {:.3} px, alpha = [{}]",
        f.samples,
        f.d_range_px.0,
        f.d_range_px.1,
        f.model.h_px,
        f.model.alpha.iter().map(|x| format!("{x:.6e}")).collect::<Vec<_>>().join(", ")
    ));
    lines.push(format!(
        "RMS error over the samples: pinhole term {:.1} mm, fitted model {:.1} mm",
        f.pinhole_rms_m * 1000.0,
        f.rms_m * 1000.0
    ));
    lines.push(format!("wrote {}", out.display()));
    for name in ["samples.csv", "fit.png", "fit.svg"] {
        lines.push(format!("  {}", dir.join(name).display()));
    }
    lines.push(format!("use it: nerve start checkpoint --name checkpoint -- --calibration {}", out.display()));
    lines
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use nerve_checkpoint::config::SampleFile;
    use nerve_sim::focal_length_px;

    #[test]
    fn a_samples_file_is_fitted_written_and_plotted() {
        let dir = std::env::temp_dir().join(format!("nerve-calib-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let df = 0.2 * focal_length_px(60f64.to_radians());
        let truth = Model { df, h_px: 3.0, alpha: [20.0, -150.0, 700.0, -2000.0] };
        let samples: Vec<Sample> = (0..30)
            .map(|i| {
                let d = 16.0 + 2.0 * f64::from(i);
                Sample { d_px: d, z_m: truth.distance(d).unwrap() }
            })
            .collect();
        let set = SampleSet { samples, band_spacing_m: 0.2, focal_px: df / 0.2, source: "a test".into() };
        let out = dir.join("cal").join("calibration.toml");
        let f = report(&set, &dir, &out).unwrap();
        assert!(f.rms_m < 1e-4 && f.pinhole_rms_m > 0.005, "fit {} pinhole {}", f.rms_m, f.pinhole_rms_m);
        let cal = Calibration::load(&out).unwrap();
        assert_eq!(cal.samples, Some(30));
        // samples.csv reads back as the samples it was written from
        let again = SampleFile::load(&dir.join("samples.csv"), Some((0.2, df / 0.2))).unwrap();
        assert_eq!(again.samples, set.samples);
        for f in ["fit.png", "fit.svg"] {
            assert!(std::fs::metadata(dir.join(f)).unwrap().len() > 5_000, "{f}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
