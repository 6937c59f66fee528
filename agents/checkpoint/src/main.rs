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
//! * `head` (`nerve::HeadState`, optional): the head's pan, added to bearings.
//!
//! Outputs:
//! * `sighting` (`nerve::CheckpointSighting`): each tube seen with a
//!   trusted range (not cut by the frame's border, within `range_min_m` …
//!   `range_max_m`): id, IR transmitters, range, bearing, world position and
//!   facing direction, target or not;
//! * `correction` (`nerve::PoseCorrection`): the corrected pose at the
//!   frame's instant, when a known checkpoint named by a fresh IR code is
//!   seen (at most every `correction_interval_ms` per checkpoint; never when
//!   parameter `correct` is false — the run "without checkpoints").
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
use nerve_checkpoint::locate::{self, Camera, Observation, Pose, correct_pose, ir_cone, observe, place, wrap};
use shm_schemas::payloads::navigation::{CORRECTS_HEADING, CORRECTS_POSITION};
use shm_schemas::payloads::{CheckpointSighting, HeadState, IrSighting, PoseCorrection, PoseEstimate, PoseSource};
use std::collections::BTreeMap;
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
    /// Appendix A calibration (written by nerve-checkpoint-fit).
    #[arg(long)]
    calibration: Option<PathBuf>,
}

/// A head state older than this is not trusted, ns.
const HEAD_FRESH_NS: u64 = 500_000_000;
/// A pose older than this is not used, ns.
const POSE_FRESH_NS: u64 = 1_000_000_000;

#[derive(Debug, Default)]
struct Counters {
    frames: AtomicU64,
    tubes: AtomicU64,
    sightings: AtomicU64,
    corrections: AtomicU64,
    rejected: AtomicU64,
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
    config: SensorConfig,
    model: Model,
    finder: TubeFinder,
    counters: Arc<Counters>,
    last_ir: Option<IrSighting>,
    last_pose: Option<PoseEstimate>,
    pan: Option<(f64, u64)>,
    last_correction: BTreeMap<u8, u64>,
    warned_no_pose: bool,
}

fn in_range(lo: f64, hi: f64) -> impl Fn(&f64) -> Result<(), String> + Send + Sync + 'static {
    move |v| if (lo..=hi).contains(v) { Ok(()) } else { Err(format!("{v} is outside {lo} … {hi}")) }
}

/// A tube measured in this frame.
struct Seen {
    tube: Tube,
    obs: Observation,
}

impl Checkpoint {
    fn fresh_pose(&self, now: u64) -> Option<(Pose, PoseEstimate)> {
        let p = self.last_pose?;
        (now.saturating_sub(p.stamp_ns) <= POSE_FRESH_NS && p.x.is_finite() && p.y.is_finite() && p.theta.is_finite())
            .then_some((Pose { x: p.x, y: p.y, theta: p.theta }, p))
    }

    fn fresh_ir(&self, now: u64) -> Option<IrSighting> {
        let s = self.last_ir?;
        let fresh = now.saturating_sub(s.stamp_ns) <= self.ir_fresh_ms.get().saturating_mul(1_000_000);
        (fresh && s.seen == 1 && s.checkpoint_id != 0).then_some(s)
    }

    fn reject(&self, why: &str, id: u8) {
        let n = self.counters.rejected.fetch_add(1, Ordering::Relaxed) + 1;
        if n.is_power_of_two() {
            tracing::warn!(checkpoint = id, rejected = n, "correction rejected: {why}");
        }
    }

    /// Handles the tubes of one frame taken at `stamp`, `width` pixels wide.
    fn on_frame(&mut self, tubes: &[Tube], width: usize, stamp: u64, now: u64) -> Result<(), AgentError> {
        let camera = Camera { width_px: width as f64, hfov_rad: self.config.camera.hfov_deg.to_radians() };
        let pan = self.pan.filter(|(_, t)| now.saturating_sub(*t) <= HEAD_FRESH_NS).map_or(0.0, |(p, _)| p);
        let (rmin, rmax) = (self.range_min_m.get(), self.range_max_m.get());
        let seen: Vec<Seen> = tubes
            .iter()
            .filter(|t| !t.clipped)
            .filter_map(|t| observe(t, &camera, &self.model, pan, self.config.tube.radius_m).ok().map(|o| (t, o)))
            .filter(|(_, o)| o.range_m >= rmin && o.range_m <= rmax)
            .map(|(t, o)| Seen { tube: *t, obs: o })
            .collect();
        self.counters.tubes.fetch_add(seen.len() as u64, Ordering::Relaxed);
        if seen.is_empty() {
            return Ok(());
        }
        let pose = self.fresh_pose(now);
        if pose.is_none() && !self.warned_no_pose {
            tracing::warn!(
                "no fresh pose on input `pose`: tubes are reported only when the IR names a known checkpoint, \
                 and no correction is made; connect odometry/pose checkpoint/pose"
            );
            self.warned_no_pose = true;
        }
        let ir = self.fresh_ir(now);
        let half_angle = self.config.ir.half_angle_deg.to_radians();
        // which tube the IR code names
        let named: Option<(usize, u8)> = ir.and_then(|s| {
            let id = s.checkpoint_id;
            if let Some(k) = self.config.checkpoint(id) {
                let obs: Vec<Observation> = seen.iter().map(|s| s.obs).collect();
                let i = match &pose {
                    Some((p, _)) => locate::identify(p, &obs, (k.position[0], k.position[1]), self.max_jump_m.get()),
                    // no pose: the nearest upright tube
                    None => (0..seen.len())
                        .filter(|i| seen[*i].obs.upright)
                        .min_by(|a, b| seen[*a].obs.range_m.total_cmp(&seen[*b].obs.range_m)),
                };
                i.map(|i| (i, id))
            } else if self.config.target_ids.contains(&id) {
                (0..seen.len())
                    .filter(|i| !seen[*i].obs.upright)
                    .min_by(|a, b| seen[*a].obs.range_m.total_cmp(&seen[*b].obs.range_m))
                    .map(|i| (i, id))
            } else {
                None
            }
        });
        for (i, s) in seen.iter().enumerate() {
            let by_ir = named.filter(|(n, _)| *n == i).map(|(_, id)| id);
            let placed = pose.as_ref().map(|(p, _)| place(p, &s.obs));
            let phi = pose.as_ref().map(|(p, _)| wrap(p.theta + s.obs.bearing_rad + std::f64::consts::PI));
            // identity: by IR, else a known checkpoint where the tube falls
            let by_map = || -> Option<u8> {
                let (x, y) = placed?;
                if !s.obs.upright {
                    return None;
                }
                self.config
                    .checkpoints
                    .iter()
                    .map(|k| (k.id, (k.position[0] - x).hypot(k.position[1] - y)))
                    .filter(|(_, d)| *d <= self.gate_m.get())
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|(id, _)| id)
            };
            let id = by_ir.or_else(by_map).unwrap_or(0);
            let known = self.config.checkpoint(id).filter(|_| s.obs.upright);
            let (x, y) = match (known, placed) {
                (Some(k), _) => (k.position[0], k.position[1]),
                (None, Some(xy)) => xy,
                (None, None) => continue, // nowhere to put it
            };
            let cone = match (by_ir, known, ir) {
                (Some(_), Some(k), Some(irs)) => ir_cone(k.heading_deg.to_radians(), irs.transmitters, half_angle),
                _ => None,
            };
            let facing = cone.map(|c| c.centre).or(phi).unwrap_or(0.0);
            let transmitters = if by_ir.is_some() { ir.map_or(0, |s| s.transmitters) } else { 0 };
            self.sighting_out.send(CheckpointSighting {
                stamp_ns: stamp,
                x,
                y,
                range_m: s.obs.range_m as f32,
                bearing_rad: s.obs.bearing_rad as f32,
                facing_rad: facing as f32,
                checkpoint_id: id,
                transmitters,
                from_ir: u8::from(by_ir.is_some()),
                from_camera: 1,
                is_target: u8::from(!s.obs.upright),
                reserved: [0; 7],
            })?;
            self.counters.sightings.fetch_add(1, Ordering::Relaxed);
            tracing::debug!(
                checkpoint = id,
                range = s.obs.range_m,
                bearing = s.obs.bearing_rad,
                d_px = s.tube.d_px,
                "tube seen"
            );

            // the correction: a known checkpoint named by the IR code, with a pose to correct
            let (Some(k), Some(_), Some((est, _))) = (known, by_ir, pose.as_ref()) else { continue };
            if !self.correct.get() {
                continue;
            }
            let interval = self.interval_ms.get().saturating_mul(1_000_000);
            if self.last_correction.get(&id).is_some_and(|t| stamp.saturating_sub(*t) < interval) {
                continue;
            }
            let c =
                correct_pose(est, (k.position[0], k.position[1]), &s.obs, cone, self.ir_margin_deg.get().to_radians());
            let jump = (c.pose.x - est.x).hypot(c.pose.y - est.y);
            if jump > self.max_jump_m.get() {
                self.reject(&format!("it would move the pose {jump:.2} m (max_jump_m {})", self.max_jump_m.get()), id);
                continue;
            }
            self.last_correction.insert(id, stamp);
            let fields = CORRECTS_POSITION | if c.heading_corrected { CORRECTS_HEADING } else { 0 };
            self.correction_out.send(PoseCorrection {
                x: c.pose.x,
                y: c.pose.y,
                theta: c.pose.theta,
                checkpoint_x: k.position[0],
                checkpoint_y: k.position[1],
                stamp_ns: stamp,
                range_m: s.obs.range_m as f32,
                bearing_rad: s.obs.bearing_rad as f32,
                fields,
                source: PoseSource::Checkpoint as u8,
                checkpoint_id: id,
                reserved: [0; 5],
            })?;
            let n = self.counters.corrections.fetch_add(1, Ordering::Relaxed) + 1;
            tracing::info!(
                checkpoint = id,
                corrections = n,
                dx = c.pose.x - est.x,
                dy = c.pose.y - est.y,
                dtheta_deg = wrap(c.pose.theta - est.theta).to_degrees(),
                range_m = s.obs.range_m,
                bearing_deg = s.obs.bearing_rad.to_degrees(),
                heading_corrected = c.heading_corrected,
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
        let args =
            Args::try_parse_from(std::iter::once("nerve-checkpoint --".to_owned()).chain(setup.args().iter().cloned()))
                .map_err(|e| AgentError::Config(e.to_string()))?;
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
            gate_m: setup.param_checked("gate_m", 0.8, in_range(0.0, 10.0)),
            max_jump_m: setup.param_checked("max_jump_m", 2.5, in_range(0.0, 50.0)),
            range_min_m: setup.param_checked("range_min_m", 0.5, in_range(0.0, 20.0)),
            range_max_m: setup.param_checked("range_max_m", 3.5, in_range(0.0, 20.0)),
            interval_ms: setup.param("correction_interval_ms", 500u64),
            ir_margin_deg: setup.param_checked("ir_margin_deg", 5.0, in_range(0.0, 45.0)),
            config,
            model,
            finder: TubeFinder::default(),
            counters,
            last_ir: None,
            last_pose: None,
            pan: None,
            last_correction: BTreeMap::new(),
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
        if let Some((_, h)) = self.head.latest() {
            if h.pan_rad.is_finite() {
                self.pan = Some((h.pan_rad, now));
            }
        }
        let (finder, colors, min_px) = (&mut self.finder, self.config.tube.colors(), self.min_pixels.get() as usize);
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
        self.on_frame(&tubes, width, stamp, now)
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Checkpoint>()
}
