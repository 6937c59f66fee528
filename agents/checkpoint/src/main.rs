//! `checkpoint`: the checkpoint sensor agent (thesis section 4.3.2.1,
//! Appendix A). Event-driven; the work is done when a camera frame arrives.
//!
//! Inputs:
//! * `frames` (`nerve::RingNotice`): camera frames, `rgb8` (a camera's
//!   `frames`) or `hsi8` (the image agent's `hsi`), read in place;
//! * `ir` (`nerve::IrSighting`): the IR agent's `sighting` — which
//!   checkpoint is near and which of its transmitters are received;
//! * `pose` (`nerve::PoseEstimate`): the odometry agent's `pose`, to place
//!   what is seen in the world and to be corrected;
//! * `head` (`nerve::HeadState`, optional): the head's pan, added to bearings;
//!   while the head is turning (measured pan more than 1.5° from its
//!   set-point) a frame's tubes are still reported but correct nothing: the
//!   pan of a moving head at the frame's instant is known only roughly
//!   (figure `moving`: frames taken so).
//!
//! Outputs:
//! * `sighting` (`nerve::CheckpointSighting`): each tube seen with a
//!   trusted range (not cut by the frame's border, within `range_min_m` …
//!   `range_max_m`): id, IR transmitters, range, bearing, world position and
//!   facing direction, target or not; and a known checkpoint the IR names
//!   but no ranged tube shows, without range (`from_camera = 0`);
//! * `correction` (`nerve::PoseCorrection`): the corrected pose at the
//!   frame's instant, when a known checkpoint is seen, named by a fresh IR
//!   code or (unless `require_ir`) by where its tube falls (at most every
//!   `correction_interval_ms` per checkpoint; never when parameter `correct`
//!   is false — the run "without checkpoints").
//!
//! Arguments after `--`: `--config FILE` (camera, colours, IR cones, known
//! checkpoints; see `nerve_checkpoint::config`) and `--calibration FILE`
//! (Appendix A; without it the pinhole term alone is used, said once at
//! start).

use agent_sdk::memory::{MemorySetup, PixelFormat, RingInput};
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use clap::Parser;
use nerve_checkpoint::appendix_a::Model;
use nerve_checkpoint::bands::{Pixels, Tube, TubeFinder};
use nerve_checkpoint::config::{Calibration, SensorConfig};
use nerve_checkpoint::locate::{Pose, wrap_angle};
use nerve_checkpoint::sensor::{FrameInput, Sensor, SensorSettings};
use shm_schemas::payloads::{CheckpointSighting, HeadState, IrSighting, PoseCorrection, PoseEstimate};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// The agent's own options (after `--`).
#[derive(Debug, Clone, Parser)]
#[command(name = "nerve-checkpoint --", about = "checkpoint sensor options")]
struct Args {
    /// Sensor configuration: camera, tube colours, IR cones, known checkpoints.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Appendix A calibration (written by `nerve calibrate checkpoint` or nerve-checkpoint-fit).
    #[arg(long)]
    calibration: Option<PathBuf>,
}

/// A head state older than this is not trusted, ns.
const HEAD_FRESH_NS: u64 = 500_000_000;
/// A head farther than this from its set-point is turning, radians (1.5°).
const HEAD_SETTLED_RAD: f64 = 0.026;
/// A pose older than this is not used, ns.
const POSE_FRESH_NS: u64 = 1_000_000_000;

#[derive(Debug, Default)]
struct Counters {
    frames: AtomicU64,
    tubes: AtomicU64,
    sightings: AtomicU64,
    corrections: AtomicU64,
    rejected: AtomicU64,
    moving: AtomicU64,
}

struct Checkpoint {
    frames: RingInput,
    ir: Input<IrSighting>,
    pose: Input<PoseEstimate>,
    head: Input<HeadState>,
    sighting_out: Output<CheckpointSighting>,
    correction_out: Output<PoseCorrection>,
    min_pixels: Param<u64>,
    correct: Param<bool>,
    ir_fresh_ms: Param<u64>,
    gate_m: Param<f64>,
    max_jump_m: Param<f64>,
    range_min_m: Param<f64>,
    range_max_m: Param<f64>,
    interval_ms: Param<u64>,
    ir_margin_deg: Param<f64>,
    require_ir: Param<bool>,
    sensor: Sensor,
    finder: TubeFinder,
    counters: Arc<Counters>,
    last_ir: Option<IrSighting>,
    last_pose: Option<PoseEstimate>,
    /// The head's measured pan, whether it had settled, and when it was read.
    pan: Option<(f64, bool, u64)>,
    warned_no_pose: bool,
}

fn in_range(lo: f64, hi: f64) -> impl Fn(&f64) -> Result<(), String> + Send + Sync + 'static {
    move |v| if (lo..=hi).contains(v) { Ok(()) } else { Err(format!("{v} is outside {lo} … {hi}")) }
}

impl Checkpoint {
    fn settings(&self) -> SensorSettings {
        SensorSettings {
            correct: self.correct.get(),
            ir_fresh_ns: self.ir_fresh_ms.get().saturating_mul(1_000_000),
            gate_m: self.gate_m.get(),
            max_jump_m: self.max_jump_m.get(),
            range_min_m: self.range_min_m.get(),
            range_max_m: self.range_max_m.get(),
            interval_ns: self.interval_ms.get().saturating_mul(1_000_000),
            ir_margin_rad: self.ir_margin_deg.get().to_radians(),
            require_ir: self.require_ir.get(),
        }
    }

    fn fresh_pose(&self, now: u64) -> Option<Pose> {
        let p = self.last_pose?;
        (now.saturating_sub(p.stamp_ns) <= POSE_FRESH_NS && p.x.is_finite() && p.y.is_finite() && p.theta.is_finite())
            .then_some(Pose { x: p.x, y: p.y, theta: p.theta })
    }

    /// Handles the tubes of one frame taken at `stamp`, `width` pixels wide.
    fn on_frame(
        &mut self,
        tubes: &[Tube],
        width: usize,
        stamp: u64,
        now: u64,
        head_moving: bool,
    ) -> Result<(), AgentError> {
        let pose = self.fresh_pose(now);
        if pose.is_none() && !tubes.is_empty() && !self.warned_no_pose {
            tracing::warn!(
                "no fresh pose on input `pose`: tubes are reported only when the IR names a known checkpoint, \
                 and no correction is made; connect odometry/pose checkpoint/pose"
            );
            self.warned_no_pose = true;
        }
        let input = FrameInput {
            tubes,
            width_px: width,
            stamp_ns: stamp,
            now_ns: now,
            pose,
            ir: self.last_ir,
            pan_rad: self.pan.filter(|(_, _, t)| now.saturating_sub(*t) <= HEAD_FRESH_NS).map_or(0.0, |(p, _, _)| p),
        };
        let mut settings = self.settings();
        settings.correct &= !head_moving;
        let out = self.sensor.frame(&input, &settings);
        self.counters.tubes.fetch_add(out.ranged as u64, Ordering::Relaxed);
        for sg in &out.sightings {
            self.sighting_out.send(*sg)?;
            self.counters.sightings.fetch_add(1, Ordering::Relaxed);
            tracing::debug!(
                checkpoint = sg.checkpoint_id,
                target = sg.is_target,
                range_m = sg.range_m,
                bearing_rad = sg.bearing_rad,
                "tube seen"
            );
        }
        for (id, why) in &out.rejected {
            let n = self.counters.rejected.fetch_add(1, Ordering::Relaxed) + 1;
            if n.is_power_of_two() {
                tracing::warn!(checkpoint = id, rejected = n, "correction rejected: {why}");
            }
        }
        if let Some(c) = out.correction {
            self.correction_out.send(c.payload)?;
            let n = self.counters.corrections.fetch_add(1, Ordering::Relaxed) + 1;
            tracing::info!(
                checkpoint = c.payload.checkpoint_id,
                corrections = n,
                dx = c.payload.x - c.from.x,
                dy = c.payload.y - c.from.y,
                dtheta_deg = wrap_angle(c.payload.theta - c.from.theta).to_degrees(),
                range_m = c.payload.range_m,
                bearing_deg = f64::from(c.payload.bearing_rad).to_degrees(),
                heading_corrected = c.correction.heading_corrected,
                "pose correction sent"
            );
        }
        Ok(())
    }
}

impl Agent for Checkpoint {
    const KIND: &'static str = "checkpoint";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let config = match &args.config {
            Some(p) => SensorConfig::load(p).map_err(|e| AgentError::Config(e.to_string()))?,
            None => SensorConfig::default(),
        };
        let calibration = match &args.calibration {
            Some(p) => Some(Calibration::load(p).map_err(|e| AgentError::Config(e.to_string()))?),
            None => None,
        };
        if config.checkpoints.is_empty() {
            tracing::warn!("no known checkpoints (-- --config FILE with [[checkpoint]] tables): no pose corrections");
        }
        let model = match &calibration {
            Some(c) => c.model(),
            None => {
                // pinhole alone, for a 320-pixel frame; the sim's tubes have bands 0.2 m apart
                let f = 160.0 / (config.camera.hfov_deg.to_radians() / 2.0).tan();
                tracing::warn!(
                    focal_px = f,
                    "no Appendix A calibration (-- --calibration FILE): ranging with the pinhole term alone, D = 0.2 m"
                );
                Model::pinhole(0.2 * f)
            }
        };
        let counters = Arc::new(Counters::default());
        let c2 = counters.clone();
        setup.figures(move || {
            let g = |a: &AtomicU64| a.load(Ordering::Relaxed).to_string();
            vec![
                ("frames".into(), g(&c2.frames)),
                ("tubes".into(), g(&c2.tubes)),
                ("sightings".into(), g(&c2.sightings)),
                ("corrections".into(), g(&c2.corrections)),
                ("rejected".into(), g(&c2.rejected)),
                ("moving".into(), g(&c2.moving)),
            ]
        });
        Ok(Checkpoint {
            frames: setup.ring_input("frames")?,
            ir: setup.input("ir")?,
            pose: setup.input("pose")?,
            head: setup.input("head")?,
            sighting_out: setup.output("sighting")?,
            correction_out: setup.output("correction")?,
            min_pixels: setup.param_checked("min_pixels", 20u64, |v| {
                if *v >= 1 { Ok(()) } else { Err("min_pixels is at least 1".into()) }
            }),
            correct: setup.param("correct", true),
            ir_fresh_ms: setup.param("ir_fresh_ms", 400u64),
            gate_m: setup.param_checked("gate_m", 1.5, in_range(0.0, 10.0)),
            max_jump_m: setup.param_checked("max_jump_m", 2.5, in_range(0.0, 50.0)),
            range_min_m: setup.param_checked("range_min_m", 0.5, in_range(0.0, 20.0)),
            range_max_m: setup.param_checked("range_max_m", 3.5, in_range(0.0, 20.0)),
            interval_ms: setup.param("correction_interval_ms", 500u64),
            ir_margin_deg: setup.param_checked("ir_margin_deg", 5.0, in_range(0.0, 45.0)),
            require_ir: setup.param("require_ir", false),
            sensor: Sensor::new(config, model),
            finder: TubeFinder::default(),
            counters,
            last_ir: None,
            last_pose: None,
            pan: None,
            warned_no_pose: false,
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        if let Some((_, s)) = self.ir.latest() {
            self.last_ir = Some(s);
        }
        if let Some((_, p)) = self.pose.latest() {
            self.last_pose = Some(p);
        }
        if let Some((_, h)) = self.head.latest()
            && h.pan_rad.is_finite()
        {
            let settled = !h.target_pan_rad.is_finite() || (h.pan_rad - h.target_pan_rad).abs() <= HEAD_SETTLED_RAD;
            self.pan = Some((h.pan_rad, settled, now));
        }
        let (finder, colors, min_px) =
            (&mut self.finder, self.sensor.config().tube.colors(), self.min_pixels.get() as usize);
        let read = self.frames.latest_with(|meta, px| {
            let format = match meta.format() {
                Some(PixelFormat::Rgb8) => Pixels::Rgb8,
                Some(PixelFormat::Hsi8) => Pixels::Hsi8,
                _ => {
                    return Err(format!(
                        "frames of pixel format code {} are neither rgb8 nor hsi8; connect `frames` to a camera's `frames` or the image agent's `hsi`",
                        meta.format_code
                    ));
                }
            };
            let (w, h) = (meta.width as usize, meta.height as usize);
            finder.find(px, format, w, h, &colors, min_px).map(|t| (t, w, meta.stamp_ns)).map_err(|e| e.to_string())
        });
        let (tubes, width, stamp) = match read {
            Ok(None) => return Ok(()), // woken by the IR, the pose or the head
            Ok(Some(Ok(x))) => x,
            Ok(Some(Err(e))) => return Err(AgentError::Other(e)),
            Err(e) => return Err(e.into()),
        };
        self.counters.frames.fetch_add(1, Ordering::Relaxed);
        let moving = self.pan.is_some_and(|(_, settled, t)| !settled && now.saturating_sub(t) <= HEAD_FRESH_NS);
        if moving {
            self.counters.moving.fetch_add(1, Ordering::Relaxed);
        }
        self.on_frame(&tubes, width, stamp, now, moving)
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Checkpoint>()
}

#[cfg(test)]
mod tests {
    //! The agent's glue, through the SDK's harness: its arguments and their
    //! refusals, a step woken by the pose or the IR alone (no frame: nothing
    //! is seen, nothing sent), the figures and a refused parameter. Finding
    //! and placing tubes is tested in the library.

    use super::*;
    use agent_sdk::testing::Harness;

    #[test]
    fn a_missing_config_file_is_refused_with_its_path() {
        let missing = std::env::temp_dir().join(format!("nerve-no-such-checkpoints-{}.toml", std::process::id()));
        let e = Harness::<Checkpoint>::builder()
            .args(["--config", missing.to_str().expect("a UTF-8 temp path")])
            .start()
            .expect_err("no such file")
            .to_string();
        assert!(e.contains(&missing.display().to_string()), "names the file: {e}");
        let e = Harness::<Checkpoint>::builder().args(["--calibrate", "x"]).start().expect_err("misspelt").to_string();
        assert!(e.contains("--calibrate") && e.contains("nerve-checkpoint -- --help"), "{e}");
    }

    #[test]
    fn without_a_frame_nothing_is_seen_and_the_ranges_are_checked() {
        let mut h = Harness::<Checkpoint>::new().expect("the checkpoint sensor starts without a config");
        h.send("pose", PoseEstimate { x: 1.0, stamp_ns: h.now_ns(), ..Default::default() }).expect("pose");
        h.send(
            "ir",
            IrSighting { seen: 1, checkpoint_id: 2, transmitters: 1, stamp_ns: h.now_ns(), ..Default::default() },
        )
        .expect("ir");
        h.step().expect("a step woken by the pose and the IR");
        assert!(h.output::<CheckpointSighting>("sighting").expect("sighting").is_empty());
        assert!(h.output::<PoseCorrection>("correction").expect("correction").is_empty());
        assert_eq!(h.param("frames").as_deref(), Ok("0"), "no frame was read");

        let e = h.set_param("range_max_m", "25").expect_err("out of range");
        assert!(e.contains("outside"), "{e}");
        h.set_param("range_max_m", "4").expect("in range");
        assert_eq!(h.param("range_max_m").as_deref(), Ok("4"));
        assert!(h.set_param("frames", "3").expect_err("a figure").contains("read-only"));
    }
}
