//! The ground-truth log: one CSV row per simulation step.
//!
//! Columns: `t` (s), `x`, `y` (m), `theta` (rad), `v` (m/s), `omega`
//! (rad/s), `wheel_left`, `wheel_right` (wheel surface speeds, m/s),
//! `enc_left`, `enc_right` (counts), `collisions` (count so far),
//! `in_contact` (0/1), `pan`, `tilt` (rad), `arm_shoulder`, `arm_elbow`,
//! `arm_gripper` (rad; 0 without an arm), `gripper` (`open`, `closing`,
//! `holding`, `missed`), `held` (the checkpoint id of the tube held, empty
//! when none). Readers find columns by name (the last five came with the
//! arm), so more columns may follow.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use nerve_devices::GripperPhase;

use crate::sim::Truth;

/// The header line.
pub const TRUTH_HEADER: &str = "t,x,y,theta,v,omega,wheel_left,wheel_right,enc_left,enc_right,collisions,\
                                in_contact,pan,tilt,arm_shoulder,arm_elbow,arm_gripper,gripper,held";

/// The word for a gripper phase in the truth log.
pub fn gripper_word(phase: GripperPhase) -> &'static str {
    match phase {
        GripperPhase::Open => "open",
        GripperPhase::Closing => "closing",
        GripperPhase::Holding => "holding",
        GripperPhase::Missed => "missed",
    }
}

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
            "{:.3},{:.5},{:.5},{:.5},{:.4},{:.4},{:.4},{:.4},{},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{},{}",
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
            t.head.1,
            t.arm[0],
            t.arm[1],
            t.arm[2],
            gripper_word(t.gripper),
            t.held.map(|id| id.to_string()).unwrap_or_default()
        )
        .map_err(|source| TruthError { path: self.path.clone(), source })
    }

    /// Flushes buffered rows to the file.
    pub fn flush(&mut self) -> Result<(), TruthError> {
        self.out.flush().map_err(|source| TruthError { path: self.path.clone(), source })
    }
}
