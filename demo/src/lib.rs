//! nerve-demo: analysis and figures of nerve's demos.
//!
//! The exploration demo (`nerve demo explore`, thesis section 4.2) runs the
//! whole robot against the simulator, records it through nerve (the
//! launcher's taps on `sim/truth` and `decision/mode`) and then hands its
//! records to this crate, which builds nothing and starts nothing itself;
//! the cooperation demo (`nerve demo cooperate`, section 4.3) likewise:
//!
//! * [`truth`]: a ground-truth row, and the simulator's ground-truth CSV;
//! * [`scene`]: the world file's geometry as the analysis needs it (solid
//!   things, door openings, the target and its path);
//! * [`analysis`]: the run's verdict — doorway reached, target followed,
//!   collisions, clearance — as [`analysis::Summary`] (`summary.json`);
//! * [`cpu`]: CPU use per agent sampled during the run;
//! * [`explore`]: the exploration run's report, from the launcher's record
//!   to `log.csv`, the figures and `summary.json` (its one entry point);
//! * [`plot`]: the trajectory over the map (Fig. 4-4) and velocity, angular
//!   speed and heading against time (Fig. 4-6), as PNG and SVG;
//! * [`cooperate`]: the cooperation run's verdict and its trajectories (Fig. 4-10);
//! * [`calibration`]: the Appendix A calibration's fit and files;
//! * [`calibration_plot`]: the Appendix A fit against the pinhole term.
//!
//! The definitions of `reached_doorway` and `reached_target` are in
//! `docs/demo.md` and on [`analysis::analyse`].

pub mod analysis;
pub mod calibration;
pub mod calibration_plot;
pub mod cooperate;
pub mod cpu;
pub mod explore;
pub mod plot;
pub mod scene;
pub mod truth;

pub use analysis::{Analysis, Criteria, Summary, analyse};
pub use nerve_sim;
pub use scene::Scene;
pub use truth::{TruthRow, read_truth};

/// Why the demo's analysis failed.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    /// A file could not be read or written.
    #[error("{what} {path}: {source}")]
    Io {
        /// What was being done.
        what: &'static str,
        /// The file.
        path: std::path::PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The world file.
    #[error(transparent)]
    World(#[from] nerve_sim::WorldError),
    /// A file whose content is not what it should be.
    #[error("{path}: {problem}")]
    Format {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A record of the run (a CSV file, `summary.json`) could not be written.
    #[error("{context}")]
    Record {
        /// What was being done, and the file.
        context: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The Appendix A fit failed.
    #[error("{context}")]
    Fit {
        /// What was being fitted.
        context: String,
        /// Why it failed.
        #[source]
        source: nerve_checkpoint::appendix_a::FitError,
    },
    /// The calibration just written does not load as the checkpoint agent loads it.
    #[error("{context}")]
    Calibration {
        /// What was being checked.
        context: String,
        /// What the loader said.
        #[source]
        source: nerve_checkpoint::config::ConfigError,
    },
    /// A calibration file could not be written.
    #[error(transparent)]
    Config(#[from] nerve_checkpoint::config::ConfigError),
    /// A summary that JSON cannot hold.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// A figure could not be drawn or written.
    #[error(transparent)]
    Figure(#[from] nerve_plot_font::figure::FigureError),
}

/// Writes `summary.json` (pretty JSON and a line break) into `out`.
fn write_summary(out: &std::path::Path, summary: &impl serde::Serialize) -> Result<(), DemoError> {
    let json = serde_json::to_string_pretty(summary)?;
    std::fs::write(out.join("summary.json"), json + "\n")
        .map_err(|source| DemoError::Record { context: "cannot write summary.json".into(), source })
}
