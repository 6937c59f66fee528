//! Appendix A of the thesis: the distance of a checkpoint from the pixel
//! distance `d` between the centres of its two colour bands,
//!
//! ```text
//! Z = D·f/d + α1·(d−h)^−2 + α2·(d−h)^−3 + α3·(d−h)^−4 + α4·(d−h)^−5
//! ```
//!
//! where `D` is the distance between the band centres on the tube (metres),
//! `f` the camera's focal length (pixels), and `h`, `α1..α4` correct the
//! pinhole term `D·f/d` for what the pinhole model misses (lens distortion,
//! the blur and the thresholding that shift the band centres). `Z` is the
//! distance from the camera to the tube's near surface along the optical
//! axis, as measured when the calibration samples were taken (tube straight
//! ahead).
//!
//! **The fit** ([`fit`]): for a fixed `h` the model is linear in the α's,
//! so they are the linear least-squares solution of
//! `Σ α_k (d_i−h)^−(k+1) ≈ Z_i − D·f/d_i`. It is solved by a Householder QR
//! factorisation (never the normal equations, whose condition number is the
//! square of an already poor one) on a scaled basis `u = s/(d−h)`, with `s`
//! the smallest `d−h`, so that every column lies in (0, 1]. `h` is then the
//! minimiser of the residual sum of squares over a bounded interval below
//! the smallest `d` of the samples: a grid of [`FitOptions::grid`] points,
//! then a golden-section search in the cells around the best one.
//!
//! Everything is `f64`, by hand, with no linear-algebra dependency.

use serde::{Deserialize, Serialize};

/// Fewest samples [`fit`] accepts (five parameters and one degree of freedom).
pub const MIN_SAMPLES: usize = 6;
/// Fewest distinct pixel distances [`fit`] accepts.
pub const MIN_DISTINCT: usize = 5;

/// One calibration sample: the measured pixel distance and the true distance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sample {
    /// Pixel distance between the centres of the two colour bands.
    pub d_px: f64,
    /// True distance from the camera to the tube, metres.
    pub z_m: f64,
}

/// The distance model of Appendix A.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Model {
    /// `D·f`: band spacing (m) times focal length (px), metre-pixels.
    pub df: f64,
    /// `h`, pixels.
    pub h_px: f64,
    /// `α1..α4`.
    pub alpha: [f64; 4],
}

/// Why a distance cannot be computed from a pixel distance.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// `d` is zero, negative or not a number.
    #[error("pixel distance {d_px} is not a positive number; are both colour bands of the tube in view?")]
    BadPixelDistance {
        /// The pixel distance.
        d_px: f64,
    },
    /// `d ≤ h`: the correction terms have their pole at `d = h`.
    #[error(
        "pixel distance {d_px} is not above the model's h = {h_px} px: the tube is farther than the calibration reached; recalibrate with farther samples"
    )]
    NotAboveH {
        /// The pixel distance.
        d_px: f64,
        /// The model's `h`.
        h_px: f64,
    },
}

impl Model {
    /// The pinhole model alone: `Z = D·f/d`.
    pub fn pinhole(df: f64) -> Self {
        Model { df, h_px: 0.0, alpha: [0.0; 4] }
    }

    /// `Z` for pixel distance `d_px`.
    pub fn distance(&self, d_px: f64) -> Result<f64, ModelError> {
        if !d_px.is_finite() || d_px <= 0.0 {
            return Err(ModelError::BadPixelDistance { d_px });
        }
        if self.alpha == [0.0; 4] {
            return Ok(self.df / d_px);
        }
        if d_px <= self.h_px {
            return Err(ModelError::NotAboveH { d_px, h_px: self.h_px });
        }
        let x = 1.0 / (d_px - self.h_px);
        let mut z = self.df / d_px;
        let mut p = x * x;
        for a in self.alpha {
            z += a * p;
            p *= x;
        }
        Ok(z)
    }

    /// The pinhole term alone, `D·f/d`.
    pub fn pinhole_distance(&self, d_px: f64) -> Result<f64, ModelError> {
        Model::pinhole(self.df).distance(d_px)
    }
}

/// Why a fit failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Fewer samples than parameters (plus one).
    #[error("{got} calibration samples, at least {need} are needed (five parameters are fitted)")]
    TooFewSamples {
        /// Samples given.
        got: usize,
        /// Samples needed.
        need: usize,
    },
    /// Too few different pixel distances: the basis is degenerate.
    #[error(
        "only {distinct} different pixel distances among the samples, at least {need} are needed: take samples at more distances"
    )]
    TooFewDistinct {
        /// Distinct `d` values.
        distinct: usize,
        /// Needed.
        need: usize,
    },
    /// A sample with a non-finite or non-positive value.
    #[error("sample {index}: d = {d_px} px, Z = {z_m} m; both must be finite and above 0")]
    BadSample {
        /// 0-based index of the sample.
        index: usize,
        /// Its pixel distance.
        d_px: f64,
        /// Its distance.
        z_m: f64,
    },
    /// `D·f` is not a positive number.
    #[error("band spacing × focal length = {df} is not a positive number; check band_spacing_m and focal_px")]
    BadFocal {
        /// `D·f`.
        df: f64,
    },
    /// The interval given for `h` is empty or not below every sample's `d`.
    #[error(
        "the search interval for h, [{lo}, {hi}] px, is empty or reaches the smallest sample d = {d_min} px (h must stay below it)"
    )]
    BadHRange {
        /// Lower end.
        lo: f64,
        /// Upper end.
        hi: f64,
        /// Smallest `d` of the samples.
        d_min: f64,
    },
    /// No `h` in the interval gave a solvable system.
    #[error("the least-squares system is singular for every h tried: the samples do not determine the parameters")]
    Singular,
}

/// Options of [`fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Lowest `h` searched, pixels; default `−d_max` of the samples.
    pub h_min_px: Option<f64>,
    /// Highest `h` searched, pixels; default `d_min − max(1, d_min/10)`.
    pub h_max_px: Option<f64>,
    /// Grid points of the coarse search (at least 3).
    pub grid: usize,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions { h_min_px: None, h_max_px: None, grid: 240 }
    }
}

/// What [`fit`] found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// The fitted model.
    pub model: Model,
    /// RMS of `Z − model(d)` over the samples, metres.
    pub rms_m: f64,
    /// RMS of `Z − D·f/d` over the samples, metres.
    pub pinhole_rms_m: f64,
    /// Samples used.
    pub samples: usize,
    /// Smallest and largest `d` of the samples: the range the model is valid in.
    pub d_range_px: (f64, f64),
}

fn rms(samples: &[Sample], f: impl Fn(f64) -> Option<f64>) -> f64 {
    let mut s = 0.0;
    for p in samples {
        let e = f(p.d_px).map_or(f64::INFINITY, |z| p.z_m - z);
        s += e * e;
    }
    (s / samples.len().max(1) as f64).sqrt()
}

/// Fits `h` and `α1..α4` to `samples`, `D·f = df` being known.
pub fn fit(samples: &[Sample], df: f64, opts: &FitOptions) -> Result<Fit, FitError> {
    if !df.is_finite() || df <= 0.0 {
        return Err(FitError::BadFocal { df });
    }
    if samples.len() < MIN_SAMPLES {
        return Err(FitError::TooFewSamples { got: samples.len(), need: MIN_SAMPLES });
    }
    for (index, s) in samples.iter().enumerate() {
        if !(s.d_px.is_finite() && s.z_m.is_finite() && s.d_px > 0.0 && s.z_m > 0.0) {
            return Err(FitError::BadSample { index, d_px: s.d_px, z_m: s.z_m });
        }
    }
    let mut ds: Vec<f64> = samples.iter().map(|s| s.d_px).collect();
    ds.sort_by(f64::total_cmp);
    ds.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * b.abs().max(1.0));
    if ds.len() < MIN_DISTINCT {
        return Err(FitError::TooFewDistinct { distinct: ds.len(), need: MIN_DISTINCT });
    }
    let (d_min, d_max) = (ds[0], ds[ds.len() - 1]);
    let lo = opts.h_min_px.unwrap_or(-d_max);
    let hi = opts.h_max_px.unwrap_or(d_min - (d_min / 10.0).max(1.0));
    if !(lo.is_finite() && hi.is_finite() && lo < hi && hi < d_min) {
        return Err(FitError::BadHRange { lo, hi, d_min });
    }
    let rss = |h: f64| alphas_for(samples, df, h).map(|(_, r)| r);

    // coarse grid
    let n = opts.grid.max(3);
    let step = (hi - lo) / (n - 1) as f64;
    let mut best: Option<(usize, f64)> = None;
    for i in 0..n {
        let h = lo + step * i as f64;
        if let Some(r) = rss(h)
            && best.is_none_or(|(_, b)| r < b)
        {
            best = Some((i, r));
        }
    }
    let (bi, _) = best.ok_or(FitError::Singular)?;
    // golden section in the neighbouring cells
    let mut a = lo + step * bi.saturating_sub(1) as f64;
    let mut b = (lo + step * (bi + 1) as f64).min(hi);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let eval = |h: f64| rss(h).unwrap_or(f64::INFINITY);
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (eval(c), eval(d));
    for _ in 0..200 {
        if (b - a).abs() <= 1e-10 * (1.0 + a.abs()) {
            break;
        }
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = eval(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = eval(d);
        }
    }
    // the best of the refined point and the grid point (a flat valley may
    // leave the refinement no better)
    let grid_h = lo + step * bi as f64;
    let mid = 0.5 * (a + b);
    let h = if eval(mid) <= eval(grid_h) { mid } else { grid_h };
    let (alpha, _) = alphas_for(samples, df, h).ok_or(FitError::Singular)?;
    let model = Model { df, h_px: h, alpha };
    Ok(Fit {
        model,
        rms_m: rms(samples, |d| model.distance(d).ok()),
        pinhole_rms_m: rms(samples, |d| Some(df / d)),
        samples: samples.len(),
        d_range_px: (d_min, d_max),
    })
}

/// The least-squares α's for a fixed `h`, and the residual sum of squares;
/// `None` when some `d ≤ h` or the system is singular.
pub fn alphas_for(samples: &[Sample], df: f64, h: f64) -> Option<([f64; 4], f64)> {
    let s = samples.iter().map(|p| p.d_px - h).fold(f64::INFINITY, f64::min);
    if !(s > 0.0 && s.is_finite()) {
        return None;
    }
    let rows: Vec<([f64; 4], f64)> = samples
        .iter()
        .map(|p| {
            let u = s / (p.d_px - h);
            let u2 = u * u;
            ([u2, u2 * u, u2 * u2, u2 * u2 * u], p.z_m - df / p.d_px)
        })
        .collect();
    let (beta, rss) = least_squares_4(&rows)?;
    // α_k = β_k · s^(k+1): the basis was (s/(d−h))^(k+1)
    let mut alpha = [0.0; 4];
    let mut sp = s * s;
    for k in 0..4 {
        alpha[k] = beta[k] * sp;
        sp *= s;
    }
    Some((alpha, rss))
}

/// Solves `min ‖A x − b‖²` for a 4-column `A` by Householder QR; returns
/// `x` and the residual sum of squares, `None` when `A` is rank-deficient.
#[allow(clippy::needless_range_loop)] // the indices are the algorithm's
pub fn least_squares_4(rows: &[([f64; 4], f64)]) -> Option<([f64; 4], f64)> {
    let m = rows.len();
    if m < 4 {
        return None;
    }
    let mut a: Vec<[f64; 4]> = rows.iter().map(|r| r.0).collect();
    let mut b: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let scale = a.iter().flat_map(|r| r.iter()).fold(0.0f64, |m, v| m.max(v.abs()));
    if scale == 0.0 || !scale.is_finite() {
        return None;
    }
    for k in 0..4 {
        let norm = (k..m).map(|i| a[i][k] * a[i][k]).sum::<f64>().sqrt();
        if norm <= 1e-13 * scale {
            return None;
        }
        let alpha = if a[k][k] > 0.0 { -norm } else { norm };
        // v = x − alpha e1, stored in place of column k
        let mut v: Vec<f64> = (k..m).map(|i| a[i][k]).collect();
        v[0] -= alpha;
        let vv: f64 = v.iter().map(|x| x * x).sum();
        if vv == 0.0 {
            continue;
        }
        for j in k..4 {
            let dot: f64 = (k..m).map(|i| v[i - k] * a[i][j]).sum();
            let f = 2.0 * dot / vv;
            for i in k..m {
                a[i][j] -= f * v[i - k];
            }
        }
        let dot: f64 = (k..m).map(|i| v[i - k] * b[i]).sum();
        let f = 2.0 * dot / vv;
        for i in k..m {
            b[i] -= f * v[i - k];
        }
    }
    // R x = Qᵀb (upper 4 rows)
    let mut x = [0.0; 4];
    for k in (0..4).rev() {
        let mut s = b[k];
        for j in k + 1..4 {
            s -= a[k][j] * x[j];
        }
        if a[k][k].abs() <= 1e-13 * scale {
            return None;
        }
        x[k] = s / a[k][k];
    }
    let rss: f64 = b[4..].iter().map(|r| r * r).sum();
    x.iter().all(|v| v.is_finite()).then_some((x, rss))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The simulator's camera: 320 px wide, 60° field of view; bands 0.2 m apart.
    fn df() -> f64 {
        0.2 * 160.0 / (30f64.to_radians().tan())
    }

    fn truth() -> Model {
        Model { df: df(), h_px: 4.0, alpha: [25.0, -180.0, 900.0, -2500.0] }
    }

    /// Deterministic noise in −1 … 1 (no random dependency).
    fn noise(i: usize) -> f64 {
        let x = ((i as f64 + 1.0) * 12.9898).sin() * 43758.5453;
        2.0 * (x - x.floor()) - 1.0
    }

    fn samples(model: &Model, n: usize, noise_m: f64) -> Vec<Sample> {
        // distances 0.8 … 3 m, as in the thesis
        (0..n)
            .map(|i| {
                let z_true = 0.8 + 2.2 * i as f64 / (n - 1) as f64;
                // invert the model numerically for d (monotone over the range)
                let (mut lo, mut hi) = (model.h_px + 1e-6, 500.0);
                for _ in 0..200 {
                    let mid = 0.5 * (lo + hi);
                    if model.distance(mid).unwrap() > z_true { lo = mid } else { hi = mid }
                }
                Sample { d_px: 0.5 * (lo + hi), z_m: z_true + noise_m * noise(i) }
            })
            .collect()
    }

    #[test]
    fn least_squares_solves_an_exact_system() {
        let x = [1.0, -2.0, 0.5, 3.0];
        let rows: Vec<([f64; 4], f64)> = (0..10)
            .map(|i| {
                let t = i as f64 * 0.3 + 0.1;
                let r = [1.0, t, t * t, t.sin()];
                (r, r.iter().zip(x).map(|(a, b)| a * b).sum())
            })
            .collect();
        let (got, rss) = least_squares_4(&rows).unwrap();
        for k in 0..4 {
            assert!((got[k] - x[k]).abs() < 1e-9, "{got:?}");
        }
        assert!(rss < 1e-20);
        // two equal columns: rank-deficient
        let rows: Vec<([f64; 4], f64)> = (0..10).map(|i| ([1.0, i as f64, i as f64, 2.0], 1.0)).collect();
        assert_eq!(least_squares_4(&rows), None);
    }

    #[test]
    fn fit_recovers_known_parameters_from_exact_samples() {
        let t = truth();
        let s = samples(&t, 40, 0.0);
        let f = fit(&s, df(), &FitOptions::default()).unwrap();
        assert!((f.model.h_px - t.h_px).abs() < 0.05, "h = {} (want {})", f.model.h_px, t.h_px);
        for k in 0..4 {
            let rel = (f.model.alpha[k] - t.alpha[k]).abs() / t.alpha[k].abs();
            assert!(rel < 0.05, "alpha{} = {} (want {})", k + 1, f.model.alpha[k], t.alpha[k]);
        }
        assert!(f.rms_m < 1e-6, "rms {}", f.rms_m);
        assert!(f.pinhole_rms_m > 0.01, "the test model must differ from the pinhole: {}", f.pinhole_rms_m);
        // the fitted model reproduces the truth everywhere in the sampled range
        for d in [20.0, 30.0, 45.0, 60.0] {
            let (a, b) = (f.model.distance(d).unwrap(), t.distance(d).unwrap());
            assert!((a - b).abs() < 1e-5, "d {d}: {a} vs {b}");
        }
    }

    #[test]
    fn fit_with_small_noise_stays_close_and_beats_the_pinhole() {
        let t = truth();
        let s = samples(&t, 60, 0.005);
        let f = fit(&s, df(), &FitOptions::default()).unwrap();
        assert!(f.rms_m < 0.006, "rms {}", f.rms_m);
        // judged against the truth on distances the samples did not contain
        let check = samples(&t, 23, 0.0);
        let err = |m: &dyn Fn(f64) -> f64| {
            (check.iter().map(|p| (m(p.d_px) - p.z_m).powi(2)).sum::<f64>() / check.len() as f64).sqrt()
        };
        let fitted = err(&|d| f.model.distance(d).unwrap());
        let pinhole = err(&|d| df() / d);
        assert!(fitted < 0.01, "fitted model off by {fitted} m");
        assert!(fitted < pinhole / 3.0, "fitted {fitted} m, pinhole {pinhole} m");
        assert!(f.rms_m < f.pinhole_rms_m);
    }

    #[test]
    fn pinhole_samples_give_a_negligible_correction() {
        let p = Model::pinhole(df());
        let s = samples(&p, 30, 0.0);
        let f = fit(&s, df(), &FitOptions::default()).unwrap();
        for d in [20.0, 40.0, 65.0] {
            assert!((f.model.distance(d).unwrap() - df() / d).abs() < 1e-6);
        }
    }

    #[test]
    fn bad_input_is_refused_with_a_reason() {
        let s = samples(&truth(), 10, 0.0);
        assert_eq!(fit(&s[..5], df(), &FitOptions::default()), Err(FitError::TooFewSamples { got: 5, need: 6 }));
        let same: Vec<Sample> = (0..8).map(|i| Sample { d_px: 20.0 + (i % 2) as f64, z_m: 2.0 }).collect();
        assert!(matches!(fit(&same, df(), &FitOptions::default()), Err(FitError::TooFewDistinct { distinct: 2, .. })));
        let mut bad = s.clone();
        bad[3].z_m = -1.0;
        assert!(matches!(fit(&bad, df(), &FitOptions::default()), Err(FitError::BadSample { index: 3, .. })));
        bad[3].z_m = f64::NAN;
        assert!(matches!(fit(&bad, df(), &FitOptions::default()), Err(FitError::BadSample { index: 3, .. })));
        assert!(matches!(fit(&s, 0.0, &FitOptions::default()), Err(FitError::BadFocal { .. })));
        // h may not reach the smallest d
        let o = FitOptions { h_max_px: Some(1000.0), ..Default::default() };
        assert!(matches!(fit(&s, df(), &o), Err(FitError::BadHRange { .. })));
        // the model refuses d ≤ h and nonsense
        let m = truth();
        assert_eq!(m.distance(3.0), Err(ModelError::NotAboveH { d_px: 3.0, h_px: 4.0 }));
        assert!(matches!(m.distance(0.0), Err(ModelError::BadPixelDistance { .. })));
        assert!(matches!(m.distance(f64::NAN), Err(ModelError::BadPixelDistance { .. })));
        assert!(m.err_is_actionable());
    }

    impl Model {
        fn err_is_actionable(&self) -> bool {
            self.distance(1.0).err().is_some_and(|e| e.to_string().contains("recalibrate"))
        }
    }
}
