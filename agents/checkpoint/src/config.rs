//! The checkpoint sensor's files, both TOML read strictly (an unknown key is
//! an error, so that a typo never silently falls back to a default):
//!
//! * the **calibration** (Appendix A): written by the fit
//!   (`nerve-checkpoint-fit`, or `nerve calibrate checkpoint`), read by the
//!   agent (`-- --calibration FILE`):
//!
//!   ```toml
//!   band_spacing_m = 0.2        # D: between the centres of the two colour bands
//!   focal_px = 277.128          # f: the camera's focal length, pixels
//!   h_px = 4.0                  # fitted
//!   alpha = [25.0, -180.0, 900.0, -2500.0]
//!   valid_d_px = [18.0, 70.0]   # optional: the pixel distances the samples covered
//!   rms_m = 0.004               # optional, informative
//!   pinhole_rms_m = 0.05        # optional, informative
//!   samples = 40                # optional, informative
//!   ```
//!
//! * the **sensor configuration** (`-- --config FILE`): the camera, the
//!   tube's colours, the IR receiver and the known checkpoints:
//!
//!   ```toml
//!   [camera]
//!   hfov_deg = 60.0
//!   [tube]
//!   radius_m = 0.05
//!   upper_hue_deg = 52.0        # yellow on top (a checkpoint)
//!   lower_hue_deg = 225.0       # blue below; the target is the other way up
//!   hue_tol_deg = 15.0
//!   sat_min = 0.5
//!   int_min = 0.08
//!   [ir]
//!   half_angle_deg = 50.0       # each transmitter's cone, half width
//!   [[checkpoint]]
//!   id = 1
//!   position = [1.2, 1.2]
//!   heading_deg = -90.0         # the direction transmitter 0 faces
//!   ```
//!
//!   and a samples file for the fit (`[[sample]] d_px = .. z_m = ..`, with
//!   `band_spacing_m` and `focal_px`), or the same as CSV (`d_px,z_m`).

use crate::appendix_a::{Fit, Model, Sample};
use crate::bands::BandColors;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Why a file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Not readable.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Not writable.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Not valid TOML, or not the schema.
    #[error("{path} is malformed: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What the parser said, with line and column.
        message: String,
    },
    /// Parses, but a value is impossible.
    #[error("{path}: {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
}

fn read(path: &Path) -> Result<String, ConfigError> {
    std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.to_owned(), source })
}

fn parse<T: serde::de::DeserializeOwned>(path: &Path, text: &str) -> Result<T, ConfigError> {
    toml::from_str(text).map_err(|e| ConfigError::Parse { path: path.to_owned(), message: e.to_string() })
}

fn invalid(path: &Path, problem: impl Into<String>) -> ConfigError {
    ConfigError::Invalid { path: path.to_owned(), problem: problem.into() }
}

fn positive(path: &Path, what: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 { Ok(()) } else { Err(invalid(path, format!("{what} = {v} must be a number above 0"))) }
}

/// The Appendix A calibration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// `D`, metres.
    pub band_spacing_m: f64,
    /// `f`, pixels.
    pub focal_px: f64,
    /// `h`, pixels.
    pub h_px: f64,
    /// `α1..α4`.
    pub alpha: [f64; 4],
    /// The pixel distances the calibration covered (informative; outside
    /// it the model extrapolates).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub valid_d_px: Option<[f64; 2]>,
    /// RMS error of the fit, metres (informative).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rms_m: Option<f64>,
    /// RMS error of the pinhole term alone, metres (informative).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pinhole_rms_m: Option<f64>,
    /// Samples fitted (informative).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples: Option<usize>,
}

impl Calibration {
    /// The pinhole model alone for a tube of band spacing `d_m` and a camera of focal length `f_px`.
    pub fn pinhole(band_spacing_m: f64, focal_px: f64) -> Self {
        Calibration {
            band_spacing_m,
            focal_px,
            h_px: 0.0,
            alpha: [0.0; 4],
            valid_d_px: None,
            rms_m: None,
            pinhole_rms_m: None,
            samples: None,
        }
    }

    /// The calibration a fit found.
    pub fn from_fit(band_spacing_m: f64, focal_px: f64, fit: &Fit) -> Self {
        Calibration {
            band_spacing_m,
            focal_px,
            h_px: fit.model.h_px,
            alpha: fit.model.alpha,
            valid_d_px: Some([fit.d_range_px.0, fit.d_range_px.1]),
            rms_m: Some(fit.rms_m),
            pinhole_rms_m: Some(fit.pinhole_rms_m),
            samples: Some(fit.samples),
        }
    }

    /// The model.
    pub fn model(&self) -> Model {
        Model { df: self.band_spacing_m * self.focal_px, h_px: self.h_px, alpha: self.alpha }
    }

    /// Reads and checks a calibration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::parse(path, &read(path)?)
    }

    /// Parses and checks calibration text (`path` names it in messages).
    pub fn parse(path: &Path, text: &str) -> Result<Self, ConfigError> {
        let c: Calibration = parse(path, text)?;
        positive(path, "band_spacing_m", c.band_spacing_m)?;
        positive(path, "focal_px", c.focal_px)?;
        if !c.h_px.is_finite() || c.alpha.iter().any(|a| !a.is_finite()) {
            return Err(invalid(path, "h_px and alpha must be finite numbers"));
        }
        if let Some([lo, hi]) = c.valid_d_px {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(invalid(path, format!("valid_d_px = [{lo}, {hi}] is not an interval")));
            }
            if c.alpha != [0.0; 4] && lo <= c.h_px {
                return Err(invalid(
                    path,
                    format!(
                        "valid_d_px starts at {lo} px, not above h_px = {} px: the model has its pole there",
                        c.h_px
                    ),
                ));
            }
        }
        Ok(c)
    }

    /// Writes the file (with a comment header saying what it is).
    pub fn save(&self, path: &Path) -> Result<(), ConfigError> {
        let body = toml::to_string(self).map_err(|e| invalid(path, format!("cannot encode: {e}")))?;
        let text = format!(
            "# Appendix A calibration of the checkpoint sensor (nerve-checkpoint):\n\
             # Z = D*f/d + a1 (d-h)^-2 + a2 (d-h)^-3 + a3 (d-h)^-4 + a4 (d-h)^-5\n{body}"
        );
        std::fs::write(path, text).map_err(|source| ConfigError::Write { path: path.to_owned(), source })
    }
}

/// A samples file for the fit.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleFile {
    /// `D`, metres.
    pub band_spacing_m: f64,
    /// `f`, pixels.
    pub focal_px: f64,
    /// The samples.
    #[serde(default, rename = "sample")]
    pub samples: Vec<Sample>,
}

impl SampleFile {
    /// Reads a samples file: TOML, or CSV (`d_px,z_m` per line, an optional
    /// header, `#` comments) with `D` and `f` given by the caller.
    pub fn load(path: &Path, csv_spacing_focal: Option<(f64, f64)>) -> Result<Self, ConfigError> {
        let text = read(path)?;
        let f = if path.extension().is_some_and(|e| e == "csv") {
            let (band_spacing_m, focal_px) = csv_spacing_focal.ok_or_else(|| {
                invalid(path, "a CSV samples file does not say D and f: give --band-spacing and --focal")
            })?;
            let mut samples = Vec::new();
            for (n, line) in text.lines().enumerate() {
                let line = line.trim();
                if line.is_empty() || line.starts_with('#') || line.starts_with("d_px") {
                    continue;
                }
                let v: Vec<&str> = line.split(',').map(str::trim).collect();
                let num = |s: &str| s.parse::<f64>().ok();
                match v.as_slice() {
                    [d, z] if num(d).is_some() && num(z).is_some() => {
                        samples.push(Sample { d_px: num(d).unwrap_or_default(), z_m: num(z).unwrap_or_default() })
                    }
                    _ => return Err(invalid(path, format!("line {}: write d_px,z_m (two numbers)", n + 1))),
                }
            }
            SampleFile { band_spacing_m, focal_px, samples }
        } else {
            parse(path, &text)?
        };
        positive(path, "band_spacing_m", f.band_spacing_m)?;
        positive(path, "focal_px", f.focal_px)?;
        Ok(f)
    }
}

fn default_hfov() -> f64 {
    60.0
}

/// `[camera]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSection {
    /// Horizontal field of view, degrees.
    #[serde(default = "default_hfov")]
    pub hfov_deg: f64,
}

impl Default for CameraSection {
    fn default() -> Self {
        CameraSection { hfov_deg: default_hfov() }
    }
}

fn d_radius() -> f64 {
    0.05
}
fn d_upper() -> f32 {
    52.0
}
fn d_lower() -> f32 {
    225.0
}
fn d_tol() -> f32 {
    15.0
}
fn d_sat() -> f32 {
    0.5
}
fn d_int() -> f32 {
    0.08
}

/// `[tube]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TubeSection {
    /// Tube radius, metres (added to the camera's range to reach the centre).
    #[serde(default = "d_radius")]
    pub radius_m: f64,
    /// Hue of the upper band of a checkpoint, degrees.
    #[serde(default = "d_upper")]
    pub upper_hue_deg: f32,
    /// Hue of the lower band, degrees.
    #[serde(default = "d_lower")]
    pub lower_hue_deg: f32,
    /// Hue tolerance, degrees.
    #[serde(default = "d_tol")]
    pub hue_tol_deg: f32,
    /// Least saturation, 0 … 1.
    #[serde(default = "d_sat")]
    pub sat_min: f32,
    /// Least intensity, 0 … 1.
    #[serde(default = "d_int")]
    pub int_min: f32,
}

impl Default for TubeSection {
    fn default() -> Self {
        TubeSection {
            radius_m: d_radius(),
            upper_hue_deg: d_upper(),
            lower_hue_deg: d_lower(),
            hue_tol_deg: d_tol(),
            sat_min: d_sat(),
            int_min: d_int(),
        }
    }
}

impl TubeSection {
    /// The colour classes of the band finder.
    pub fn colors(&self) -> BandColors {
        BandColors {
            upper_hue_deg: self.upper_hue_deg,
            lower_hue_deg: self.lower_hue_deg,
            hue_tol_deg: self.hue_tol_deg,
            sat_min: self.sat_min,
            int_min: self.int_min,
        }
    }
}

fn d_half() -> f64 {
    50.0
}

/// `[ir]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IrSection {
    /// Half width of each transmitter's cone, degrees (45 … 90).
    #[serde(default = "d_half")]
    pub half_angle_deg: f64,
}

impl Default for IrSection {
    fn default() -> Self {
        IrSection { half_angle_deg: d_half() }
    }
}

/// `[[checkpoint]]`: a checkpoint whose position is known in advance.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KnownCheckpoint {
    /// IR code.
    pub id: u8,
    /// Centre of the tube, metres, world frame.
    pub position: [f64; 2],
    /// Direction transmitter 0 faces, degrees (transmitter `i` faces `heading + i·90°`).
    #[serde(default)]
    pub heading_deg: f64,
}

/// The sensor configuration file.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorConfig {
    /// The camera.
    #[serde(default)]
    pub camera: CameraSection,
    /// The tube.
    #[serde(default)]
    pub tube: TubeSection,
    /// The IR receiver.
    #[serde(default)]
    pub ir: IrSection,
    /// IR codes of targets (their positions are not known in advance).
    #[serde(default)]
    pub target_ids: Vec<u8>,
    /// The known checkpoints.
    #[serde(default, rename = "checkpoint")]
    pub checkpoints: Vec<KnownCheckpoint>,
}

impl SensorConfig {
    /// Reads and checks a configuration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::parse(path, &read(path)?)
    }

    /// Parses and checks configuration text.
    pub fn parse(path: &Path, text: &str) -> Result<Self, ConfigError> {
        let c: SensorConfig = parse(path, text)?;
        if !(c.camera.hfov_deg > 1.0 && c.camera.hfov_deg < 179.0) {
            return Err(invalid(path, format!("camera.hfov_deg = {} is not in (1, 179)", c.camera.hfov_deg)));
        }
        if !(c.tube.radius_m.is_finite() && c.tube.radius_m >= 0.0) {
            return Err(invalid(path, "tube.radius_m must be 0 or more"));
        }
        if !(c.tube.hue_tol_deg > 0.0 && c.tube.hue_tol_deg < 90.0) {
            return Err(invalid(path, "tube.hue_tol_deg must be in (0, 90)"));
        }
        if !(45.0..=90.0).contains(&c.ir.half_angle_deg) {
            return Err(invalid(path, "ir.half_angle_deg must be in 45 … 90 (four transmitters cover the circle)"));
        }
        for (i, k) in c.checkpoints.iter().enumerate() {
            if k.id == 0 {
                return Err(invalid(path, format!("checkpoint {}: id 0 means 'none'; use 1 … 255", i + 1)));
            }
            if c.checkpoints[..i].iter().any(|o| o.id == k.id) {
                return Err(invalid(path, format!("checkpoint {}: id {} is used twice", i + 1, k.id)));
            }
            if c.target_ids.contains(&k.id) {
                return Err(invalid(path, format!("id {} is both a known checkpoint and a target", k.id)));
            }
            if !(k.position.iter().all(|v| v.is_finite()) && k.heading_deg.is_finite()) {
                return Err(invalid(path, format!("checkpoint {}: position and heading must be finite", i + 1)));
            }
        }
        Ok(c)
    }

    /// The known checkpoint of IR code `id`.
    pub fn checkpoint(&self, id: u8) -> Option<&KnownCheckpoint> {
        self.checkpoints.iter().find(|k| k.id == id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calibration_round_trips_and_is_strict() {
        let dir = std::env::temp_dir().join(format!("nerve-checkpoint-cal-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("cal.toml");
        let mut c = Calibration::pinhole(0.2, 277.0);
        c.h_px = 4.0;
        c.alpha = [1.0, 2.0, 3.0, 4.0];
        c.valid_d_px = Some([18.0, 70.0]);
        c.save(&p).unwrap();
        assert_eq!(Calibration::load(&p).unwrap(), c);
        let e =
            Calibration::parse(&p, "band_spacing_m = 0.2\nfocal_px = 277\nh_px = 0\nalpha = [0,0,0,0]\nfocus = 1\n")
                .unwrap_err();
        assert!(e.to_string().contains("focus"), "{e}");
        let e =
            Calibration::parse(&p, "band_spacing_m = 0\nfocal_px = 277\nh_px = 0\nalpha = [0,0,0,0]\n").unwrap_err();
        assert!(e.to_string().contains("band_spacing_m"), "{e}");
        let e = Calibration::parse(
            &p,
            "band_spacing_m = 0.2\nfocal_px = 277\nh_px = 30\nalpha = [1,0,0,0]\nvalid_d_px = [18, 70]\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("pole"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn sensor_config_defaults_and_checks() {
        let p = Path::new("sensor.toml");
        let c = SensorConfig::parse(p, "").unwrap();
        assert_eq!(c.camera.hfov_deg, 60.0);
        assert!(c.checkpoints.is_empty());
        let c = SensorConfig::parse(
            p,
            "target_ids = [9]\n[[checkpoint]]\nid = 1\nposition = [1.2, 1.2]\nheading_deg = -90\n\
             [[checkpoint]]\nid = 2\nposition = [6, 1.2]\n",
        )
        .unwrap();
        assert_eq!(c.checkpoint(2).map(|k| k.position), Some([6.0, 1.2]));
        for bad in [
            "[[checkpoint]]\nid = 1\nposition = [0, 0]\n[[checkpoint]]\nid = 1\nposition = [1, 0]\n",
            "[[checkpoint]]\nid = 0\nposition = [0, 0]\n",
            "[ir]\nhalf_angle_deg = 30\n",
            "[camera]\nhfov = 60\n",
            "target_ids = [1]\n[[checkpoint]]\nid = 1\nposition = [0, 0]\n",
        ] {
            assert!(SensorConfig::parse(p, bad).is_err(), "accepted: {bad}");
        }
    }

    #[test]
    fn the_shipped_configuration_of_the_cooperation_parses() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/cooperate.toml");
        let c = SensorConfig::load(&p).unwrap();
        assert_eq!(c.checkpoints.len(), 4);
        assert_eq!(c.checkpoint(3).map(|k| (k.position, k.heading_deg)), Some(([10.8, 1.2], -90.0)));
        assert_eq!(c.target_ids, vec![9]);
    }

    #[test]
    fn samples_from_toml_and_csv() {
        let dir = std::env::temp_dir().join(format!("nerve-checkpoint-samples-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let t = dir.join("s.toml");
        std::fs::write(&t, "band_spacing_m = 0.2\nfocal_px = 277\n[[sample]]\nd_px = 20\nz_m = 2.7\n").unwrap();
        let f = SampleFile::load(&t, None).unwrap();
        assert_eq!(f.samples, vec![Sample { d_px: 20.0, z_m: 2.7 }]);
        let c = dir.join("s.csv");
        std::fs::write(&c, "d_px,z_m\n# a comment\n20,2.7\n40, 1.4\n").unwrap();
        assert!(SampleFile::load(&c, None).is_err());
        let f = SampleFile::load(&c, Some((0.2, 277.0))).unwrap();
        assert_eq!(f.samples.len(), 2);
        std::fs::write(&c, "20;2.7\n").unwrap();
        assert!(SampleFile::load(&c, Some((0.2, 277.0))).unwrap_err().to_string().contains("line 1"));
        std::fs::remove_dir_all(&dir).ok();
    }
}
