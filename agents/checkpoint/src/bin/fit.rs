//! `nerve-checkpoint-fit`: fits Appendix A's `h` and `α1..α4` to a samples
//! file and writes the calibration file the checkpoint agent reads.
//!
//! ```text
//! nerve-checkpoint-fit samples.toml --out calibration.toml
//! nerve-checkpoint-fit samples.csv --band-spacing 0.2 --focal 277.13 --out calibration.toml
//! ```
//!
//! It prints the RMS error of the pinhole term alone and of the fitted
//! model over the samples. Exit codes: 0 fitted and written, 1 the samples
//! could not be read or fitted, 2 bad usage.

use anyhow::Context as _;
use clap::Parser;
use nerve_checkpoint::appendix_a::{FitOptions, fit};
use nerve_checkpoint::config::{Calibration, SampleFile};
use std::path::PathBuf;
use std::process::ExitCode;

/// Fit Appendix A's distance model to calibration samples.
#[derive(Debug, Parser)]
#[command(name = "nerve-checkpoint-fit")]
struct Args {
    /// Samples: TOML (`band_spacing_m`, `focal_px`, `[[sample]] d_px z_m`) or CSV (`d_px,z_m`).
    samples: PathBuf,
    /// Where to write the calibration (TOML).
    #[arg(long)]
    out: PathBuf,
    /// D, metres (CSV samples only).
    #[arg(long)]
    band_spacing: Option<f64>,
    /// f, pixels (CSV samples only).
    #[arg(long)]
    focal: Option<f64>,
    /// Lowest h searched, pixels.
    #[arg(long)]
    h_min: Option<f64>,
    /// Highest h searched, pixels.
    #[arg(long)]
    h_max: Option<f64>,
}

fn run(args: &Args) -> anyhow::Result<()> {
    let sf = SampleFile::load(&args.samples, args.band_spacing.zip(args.focal))?;
    let opts = FitOptions { h_min_px: args.h_min, h_max_px: args.h_max, ..FitOptions::default() };
    let f = fit(&sf.samples, sf.band_spacing_m * sf.focal_px, &opts)
        .with_context(|| format!("cannot fit the samples of {}", args.samples.display()))?;
    Calibration::from_fit(sf.band_spacing_m, sf.focal_px, &f).save(&args.out)?;
    println!(
        "fitted {} samples (d {:.1} … {:.1} px): h = {:.3} px, alpha = {:?}\n\
         RMS error: pinhole {:.4} m, fitted {:.4} m\nwrote {}",
        f.samples,
        f.d_range_px.0,
        f.d_range_px.1,
        f.model.h_px,
        f.model.alpha,
        f.pinhole_rms_m,
        f.rms_m,
        args.out.display()
    );
    Ok(())
}

fn main() -> ExitCode {
    let args = match Args::try_parse() {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { ExitCode::from(2) } else { ExitCode::SUCCESS };
        }
    };
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("nerve-checkpoint-fit: {e:#}");
            ExitCode::from(1)
        }
    }
}
