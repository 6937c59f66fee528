//! `odometry`: dead reckoning in the world frame with checkpoint
//! corrections (thesis Fig. 4-8 and 4-9, "odometer"). Event-driven.
//!
//! Inputs:
//! * `odom` (`nerve::Odometry`): the motor agent's `odom` — its increments
//!   move the estimate;
//! * `correction` (`nerve::PoseCorrection`): the checkpoint sensor's
//!   `correction` — the estimate jumps (logged, counted).
//!
//! Output `pose` (`nerve::PoseEstimate`), once per odometry report: the
//! world-frame pose, speeds, the corrections so far and the last
//! checkpoint. The algorithm is the library `nerve_odometry`.
//!
//! Arguments after `--`: `--start X,Y,THETA_DEG` (the start pose in the
//! world, default 0,0,0). Parameters: `max_jump_m` (3.0), `two_checkpoints`
//! (true), `min_baseline_m` (2.0), `max_heading_fix_deg` (35); read-only
//! figures `corrections`, `rejected`, `resets`.

use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use clap::Parser;
use nerve_odometry::{DeadReckoning, Pose, Settings, Step};
use shm_schemas::payloads::{Odometry, PoseCorrection, PoseEstimate};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// The agent's own options (after `--`).
#[derive(Debug, Clone, Parser)]
#[command(name = "nerve-odometry --", about = "odometry options")]
struct Args {
    /// Start pose in the world: X,Y,THETA_DEG.
    #[arg(long, value_parser = parse_pose, allow_hyphen_values = true)]
    start: Option<Pose>,
}

fn parse_pose(s: &str) -> Result<Pose, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|_| format!("{x:?} is not a number")))
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [x, y, deg] if v.iter().all(|a| a.is_finite()) => Ok(Pose { x: *x, y: *y, theta: deg.to_radians() }),
        _ => Err("write X,Y,THETA_DEG, e.g. -4,0,0".into()),
    }
}

#[derive(Debug, Default)]
struct Counters {
    corrections: AtomicU64,
    rejected: AtomicU64,
    resets: AtomicU64,
}

struct OdometryAgent {
    odom: Input<Odometry>,
    correction: Input<PoseCorrection>,
    pose_out: Output<PoseEstimate>,
    max_jump_m: Param<f64>,
    two_checkpoints: Param<bool>,
    min_baseline_m: Param<f64>,
    max_heading_fix_deg: Param<f64>,
    dr: DeadReckoning,
    counters: Arc<Counters>,
    errors: u64,
}

fn in_range(lo: f64, hi: f64) -> impl Fn(&f64) -> Result<(), String> + Send + Sync + 'static {
    move |v| if (lo..=hi).contains(v) { Ok(()) } else { Err(format!("{v} is outside {lo} … {hi}")) }
}

impl OdometryAgent {
    fn settings(&self) -> Settings {
        Settings {
            max_jump_m: self.max_jump_m.get(),
            two_checkpoints: self.two_checkpoints.get(),
            min_baseline_m: self.min_baseline_m.get(),
            max_heading_fix_rad: self.max_heading_fix_deg.get().to_radians(),
            ..Settings::default()
        }
    }
}

impl Agent for OdometryAgent {
    const KIND: &'static str = "odometry";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let start = args.start.unwrap_or_default();
        let counters = Arc::new(Counters::default());
        let c2 = counters.clone();
        setup.figures(move || {
            let g = |a: &AtomicU64| a.load(Ordering::Relaxed).to_string();
            vec![
                ("corrections".into(), g(&c2.corrections)),
                ("rejected".into(), g(&c2.rejected)),
                ("resets".into(), g(&c2.resets)),
            ]
        });
        Ok(OdometryAgent {
            odom: setup.input("odom")?,
            correction: setup.input("correction")?,
            pose_out: setup.output("pose")?,
            max_jump_m: setup.param_checked("max_jump_m", 3.0, in_range(0.0, 100.0)),
            two_checkpoints: setup.param("two_checkpoints", true),
            min_baseline_m: setup.param_checked("min_baseline_m", 2.0, in_range(0.0, 100.0)),
            max_heading_fix_deg: setup.param_checked("max_heading_fix_deg", 35.0, in_range(0.0, 90.0)),
            dr: DeadReckoning::new(start, Settings::default()),
            counters,
            errors: 0,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let p = self.dr.pose();
        tracing::info!(x = p.x, y = p.y, theta_deg = p.theta.to_degrees(), "dead reckoning from the start pose");
        Ok(())
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let s = self.settings();
        self.dr.set_settings(s);
        // odometry first, so that a correction finds the estimate of its instant
        let mut reports: Vec<(String, Odometry)> = Vec::new();
        self.odom.drain(|m, o| reports.push((m.sender.to_string(), *o)));
        reports.sort_by_key(|(_, o)| o.stamp_ns);
        let mut published = None;
        for (sender, o) in &reports {
            match self.dr.on_odometry(o, sender) {
                Ok(Step::Reset { jump_m }) => {
                    let n = self.counters.resets.fetch_add(1, Ordering::Relaxed) + 1;
                    tracing::warn!(
                        jump_m,
                        resets = n,
                        "the motor's odometry jumped (restarted?): increments start again"
                    );
                }
                Ok(Step::Stale) | Ok(Step::First) | Ok(Step::Moved) => {}
                Err(e) => {
                    self.errors += 1;
                    if self.errors.is_power_of_two() {
                        tracing::warn!(errors = self.errors, "{e}");
                    }
                    continue;
                }
            }
            published = Some(self.dr.estimate());
        }
        let mut corrections: Vec<(String, PoseCorrection)> = Vec::new();
        self.correction.drain(|m, c| corrections.push((m.sender.to_string(), *c)));
        for (sender, c) in &corrections {
            let before = self.dr.pose();
            match self.dr.apply_correction(c, sender) {
                Ok(a) => {
                    let n = self.counters.corrections.fetch_add(1, Ordering::Relaxed) + 1;
                    let p = self.dr.pose();
                    tracing::info!(
                        checkpoint = c.checkpoint_id,
                        corrections = n,
                        jump_m = a.jump_m,
                        dtheta_deg = a.dtheta.to_degrees(),
                        heading_from_two = a.heading_from_two,
                        from_x = before.x,
                        from_y = before.y,
                        to_x = p.x,
                        to_y = p.y,
                        "pose corrected"
                    );
                    published = Some(self.dr.estimate());
                }
                Err(e) => {
                    let n = self.counters.rejected.fetch_add(1, Ordering::Relaxed) + 1;
                    if n.is_power_of_two() {
                        tracing::warn!(checkpoint = c.checkpoint_id, rejected = n, "{e}");
                    }
                }
            }
        }
        if let Some(p) = published {
            self.pose_out.send(p)?;
        }
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<OdometryAgent>()
}

#[cfg(test)]
mod tests {
    //! The agent's glue, through the SDK's harness: `--start`, odometry and
    //! corrections to `pose` through `step`, the figures, a refused
    //! correction, a refused parameter and a refused argument. The dead
    //! reckoning itself is tested in the library.

    use super::*;
    use agent_sdk::testing::Harness;
    use shm_schemas::payloads::PoseSource;
    use shm_schemas::payloads::navigation::CORRECTS_POSITION;
    use std::f64::consts::FRAC_PI_2;

    fn odom(x: f64, stamp_ns: u64) -> Odometry {
        Odometry { x, y: 0.0, theta: 0.0, v: 0.0, omega: 0.0, stamp_ns }
    }

    fn correction(x: f64, y: f64, stamp_ns: u64) -> PoseCorrection {
        PoseCorrection {
            x,
            y,
            checkpoint_x: x + 1.0,
            checkpoint_y: y,
            stamp_ns,
            range_m: 1.0,
            fields: CORRECTS_POSITION,
            source: PoseSource::Checkpoint as u8,
            checkpoint_id: 1,
            ..Default::default()
        }
    }

    #[test]
    fn odometry_moves_the_start_pose_and_a_correction_moves_the_estimate() {
        let mut h =
            Harness::<OdometryAgent>::builder().args(["--start", "1,2,90"]).start().expect("the odometry agent starts");
        let t0 = h.now_ns();
        h.send_from("odom", "motor", odom(0.0, t0)).expect("odom");
        h.step().expect("step");
        let p = h.output::<PoseEstimate>("pose").expect("pose");
        let p = p.last().expect("a pose per odometry report");
        assert!((p.x, p.y) == (1.0, 2.0) && (p.theta - FRAC_PI_2).abs() < 1e-9, "the start pose: {p:?}");

        // half a metre ahead in the motor's frame: north in the world
        let t1 = t0 + 100_000_000;
        h.send_from("odom", "motor", odom(0.5, t1)).expect("odom");
        h.step().expect("step");
        let p = *h.output::<PoseEstimate>("pose").expect("pose").last().expect("pose");
        assert!((p.x - 1.0).abs() < 1e-9 && (p.y - 2.5).abs() < 1e-9, "{p:?}");

        h.send_from("correction", "checkpoint", correction(1.2, 2.5, t1)).expect("correction");
        h.step().expect("step");
        let p = *h.output::<PoseEstimate>("pose").expect("pose").last().expect("a corrected pose");
        assert!((p.x - 1.2).abs() < 1e-9 && (p.y - 2.5).abs() < 1e-9, "{p:?}");
        assert_eq!((p.corrections, p.last_checkpoint), (1, 1));
        assert_eq!(h.param("corrections").as_deref(), Ok("1"));

        // a correction farther than max_jump_m is refused and counted; no pose goes out
        h.send_from("correction", "checkpoint", correction(40.0, 2.5, t1)).expect("correction");
        h.step().expect("step");
        assert!(h.output::<PoseEstimate>("pose").expect("pose").is_empty());
        assert_eq!(h.param("rejected").as_deref(), Ok("1"));
        assert!(h.set_param("rejected", "0").expect_err("a figure").contains("read-only"));

        let e = h.set_param("max_jump_m", "500").expect_err("out of range");
        assert!(e.contains("outside"), "{e}");
    }

    #[test]
    fn a_bad_start_pose_is_refused_with_what_to_write() {
        let e =
            Harness::<OdometryAgent>::builder().args(["--start", "north"]).start().expect_err("not a pose").to_string();
        assert!(e.contains("agent \"odometry\"") && e.contains("--start"), "{e}");
        assert!(e.contains("X,Y,THETA_DEG") || e.contains("not a number"), "says what to write: {e}");
        assert!(e.contains("nerve-odometry -- --help"), "{e}");
    }
}
