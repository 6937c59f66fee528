//! `look`: the look-around agent. It sweeps H1's head through a list of pan
//! angles, dwelling at each once the head has got there, so that the camera
//! sees beside the robot's path (see the `nerve_look` library for the sweep).
//!
//! Inputs (all optional):
//! * `head` (`nerve::HeadState`): the head agent's `state`; with it a step's
//!   dwell starts when the measured pan has settled, without it after the
//!   travel time at 90°/s;
//! * `sighting` (`nerve::CheckpointSighting`): the checkpoint sensor's
//!   sightings; when the target (the tube upside down) is seen, the sweep
//!   stops and the head keeps looking at it — at its world position through
//!   `pose`, else at its last bearing — until it has not been seen for
//!   `hold_ms`, so the sensor keeps seeing it as the robot comes near;
//! * `pose` (`nerve::PoseEstimate`): the odometry's `pose`.
//!
//! Output `cmd` (`nerve::HeadCommand`): the pan set-point, tilt 0, every
//! cycle (periodic, 100 ms); connect it to the head agent's `cmd`.
//!
//! Parameters: `pans_deg` (`"0,-50,0,50"`: the angles, positive to the left,
//! within ±100°; with a 60° camera they cover ±80°), `dwell_ms` (600), `settle_deg` (2), `enabled` (true; when
//! false the head is sent straight ahead), `hold_ms` (3000). Read-only
//! figures `steps` and `holding` (1 while looking at the target).

use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use nerve_look::{Sweep, SweepSettings, parse_pans_deg};
use shm_schemas::payloads::{CheckpointSighting, HeadCommand, HeadState, PoseEstimate};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// The head board's pan limit, degrees.
const PAN_LIMIT_DEG: f64 = 100.0;
/// A head report older than this is not used, ns.
const HEAD_FRESH_NS: u64 = 500_000_000;

struct Look {
    head: Input<HeadState>,
    sighting: Input<CheckpointSighting>,
    pose: Input<PoseEstimate>,
    hold_ms: Param<u64>,
    /// The target's world position and bearing when last seen, and when.
    target: Option<(f64, f64, f64, u64)>,
    last_pose: Option<PoseEstimate>,
    holding: Arc<AtomicU64>,
    cmd: Output<HeadCommand>,
    pans_deg: Param<String>,
    dwell_ms: Param<u64>,
    settle_deg: Param<f64>,
    enabled: Param<bool>,
    sweep: Option<Sweep>,
    last_head: Option<(f64, u64)>,
    steps: Arc<AtomicU64>,
}

impl Agent for Look {
    const KIND: &'static str = "look";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(100))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let steps = Arc::new(AtomicU64::new(0));
        let holding = Arc::new(AtomicU64::new(0));
        let (s2, h2) = (steps.clone(), holding.clone());
        setup.figures(move || {
            vec![
                ("steps".into(), s2.load(Ordering::Relaxed).to_string()),
                ("holding".into(), h2.load(Ordering::Relaxed).to_string()),
            ]
        });
        Ok(Look {
            head: setup.input("head")?,
            sighting: setup.input("sighting")?,
            pose: setup.input("pose")?,
            hold_ms: setup
                .param_checked("hold_ms", 3000u64, |v| agent_sdk::params::in_range("hold_ms", *v, &(0..=60_000), "ms")),
            target: None,
            last_pose: None,
            holding,
            cmd: setup.output("cmd")?,
            pans_deg: setup.param_checked("pans_deg", "0,-50,0,50".to_owned(), |s: &String| {
                parse_pans_deg(s, PAN_LIMIT_DEG).map(|_| ())
            }),
            dwell_ms: setup.param_checked("dwell_ms", 600u64, |v| {
                agent_sdk::params::in_range("dwell_ms", *v, &(0..=60_000), "ms")
            }),
            settle_deg: setup.param_checked("settle_deg", 2.0, |v: &f64| {
                if v.is_finite() && *v > 0.0 && *v <= 30.0 { Ok(()) } else { Err(format!("{v} is outside 0 … 30°")) }
            }),
            enabled: setup.param("enabled", true),
            sweep: None,
            last_head: None,
            steps,
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        if let Some((_, h)) = self.head.latest()
            && h.pan_rad.is_finite()
        {
            self.last_head = Some((h.pan_rad, now));
        }
        if let Some((_, p)) = self.pose.latest()
            && p.x.is_finite()
            && p.y.is_finite()
            && p.theta.is_finite()
        {
            self.last_pose = Some(p);
        }
        let mut seen = None;
        self.sighting.drain(|_, s| {
            if s.is_target == 1 && s.from_camera == 1 && s.x.is_finite() && s.y.is_finite() && s.bearing_rad.is_finite()
            {
                seen = Some((s.x, s.y, f64::from(s.bearing_rad)));
            }
        });
        if let Some((x, y, b)) = seen {
            self.target = Some((x, y, b, now));
        }
        let hold_ns = self.hold_ms.get().saturating_mul(1_000_000);
        let gaze = self.target.filter(|t| now.saturating_sub(t.3) <= hold_ns).map(|(x, y, b, _)| {
            let pan = match self.last_pose {
                Some(p) => nerve_look::wrap_angle((y - p.y).atan2(x - p.x) - p.theta),
                None => b,
            };
            pan.clamp(-PAN_LIMIT_DEG.to_radians(), PAN_LIMIT_DEG.to_radians())
        });
        self.holding.store(u64::from(gaze.is_some()), Ordering::Relaxed);
        let pan = if let (true, Some(g)) = (self.enabled.get(), gaze) {
            self.sweep = None; // the sweep starts again from its first angle
            g
        } else if self.enabled.get() {
            let settings = SweepSettings {
                // the parameter was checked when set
                pans_rad: parse_pans_deg(&self.pans_deg.get(), PAN_LIMIT_DEG).unwrap_or_else(|_| vec![0.0]),
                dwell_ns: self.dwell_ms.get().saturating_mul(1_000_000),
                settle_rad: self.settle_deg.get().to_radians(),
                ..SweepSettings::default()
            };
            let measured = self.last_head.filter(|(_, t)| now.saturating_sub(*t) <= HEAD_FRESH_NS).map(|(p, _)| p);
            let sweep = self.sweep.get_or_insert_with(|| Sweep::new(now));
            let pan = sweep.update(&settings, now, measured);
            self.steps.store(sweep.steps(), Ordering::Relaxed);
            pan
        } else {
            self.sweep = None;
            0.0
        };
        self.cmd.send(HeadCommand { pan_rad: pan, tilt_rad: 0.0, stamp_ns: now })?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Look>()
}
