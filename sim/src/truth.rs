//! The ground-truth log: one CSV row per simulation step.
//!
//! Columns: `t` (s), `x`, `y` (m), `theta` (rad), `v` (m/s), `omega`
//! (rad/s), `wheel_left`, `wheel_right` (wheel surface speeds, m/s),
//! `enc_left`, `enc_right` (counts), `collisions` (count so far),
//! `in_contact` (0/1), `pan`, `tilt` (rad).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::sim::Truth;

/// The header line.
pub const TRUTH_HEADER: &str =
    "t,x,y,theta,v,omega,wheel_left,wheel_right,enc_left,enc_right,collisions,in_contact,pan,tilt";

/// Why the truth log failed.
#[derive(Debug, thiserror::Error)]
#[error("cannot write the ground-truth log {path}: {source}")]
pub struct TruthError {
    /// The log file.
    pub path: PathBuf,
    /// OS error.
    pub source: std::io::Error,
}

/// A CSV truth log being written.
#[derive(Debug)]
pub struct TruthLog {
    path: PathBuf,
    out: BufWriter<File>,
}

impl TruthLog {
    /// Creates (truncates) the file and writes the header.
    pub fn create(path: &Path) -> Result<Self, TruthError> {
        let err = |source| TruthError { path: path.to_path_buf(), source };
        let mut out = BufWriter::new(File::create(path).map_err(err)?);
        writeln!(out, "{TRUTH_HEADER}").map_err(err)?;
        Ok(Self { path: path.to_path_buf(), out })
    }

    /// Appends one row.
    pub fn write(&mut self, t: &Truth) -> Result<(), TruthError> {
        writeln!(
            self.out,
            "{:.3},{:.5},{:.5},{:.5},{:.4},{:.4},{:.4},{:.4},{},{},{},{},{:.4},{:.4}",
            t.time,
            t.pose.x,
            t.pose.y,
            t.pose.theta,
            t.v,
            t.omega,
            t.wheel_speeds.0,
            t.wheel_speeds.1,
            t.encoders.0,
            t.encoders.1,
            t.collisions,
            u8::from(t.in_contact),
            t.head.0,
            t.head.1
        )
        .map_err(|source| TruthError { path: self.path.clone(), source })
    }

    /// Flushes buffered rows to the file.
    pub fn flush(&mut self) -> Result<(), TruthError> {
        self.out.flush().map_err(|source| TruthError { path: self.path.clone(), source })
    }
}
