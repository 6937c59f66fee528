//! The checkpoint sensor's work on one camera frame, without ports: from
//! the tubes found in it, the latest IR report and pose estimate to the
//! sightings and the pose correction the agent sends (see [`crate::locate`]
//! for the geometry).
//!
//! Per frame ([`Sensor::frame`]):
//!
//! 1. every tube not cut by the frame's border is ranged; only ranges in
//!    `range_min_m … range_max_m` are trusted;
//! 2. a fresh IR code of a known checkpoint names the upright tube placed
//!    nearest its known position (within `max_jump_m`); a fresh IR code of
//!    a target names the nearest upside-down tube;
//! 3. a known checkpoint the IR names but no ranged tube shows becomes a
//!    sighting without range (`from_camera = 0`, range and bearing 0);
//!    every ranged tube becomes a sighting: id (IR, else the known
//!    checkpoint within `gate_m` of where it falls, else 0), world position
//!    (the known one for a known checkpoint), facing direction (the IR
//!    cone's centre, else the direction from the tube to the robot);
//! 4. the tube the IR names — or, unless `require_ir`, a tube named by
//!    where it falls (the only known checkpoint within `gate_m`, none other
//!    within twice that; the IR's range, 2 m, is shorter than the camera's)
//!    — if it is a known checkpoint and a pose is known, corrects the pose
//!    (bounded by the IR cone when the IR named it) — unless corrections are off, the last one
//!    of that checkpoint is more recent than `interval`, or the correction
//!    would move the pose more than `max_jump_m` (rejected, with the reason).

use crate::appendix_a::Model;
use crate::bands::Tube;
use crate::config::SensorConfig;
use crate::locate::{
    Camera, Correction, Observation, Pose, correct_pose, identify, ir_cone, observe, place, wrap_angle,
};
use shm_schemas::payloads::navigation::{CORRECTS_HEADING, CORRECTS_POSITION};
use shm_schemas::payloads::{CheckpointSighting, IrSighting, PoseCorrection, PoseSource};
use std::collections::BTreeMap;
use std::f64::consts::PI;

/// The sensor's run-time settings (the agent's parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorSettings {
    /// Send corrections at all.
    pub correct: bool,
    /// An IR report older than this names nothing, ns.
    pub ir_fresh_ns: u64,
    /// A tube without IR code is a known checkpoint this close to where it falls, metres.
    pub gate_m: f64,
    /// Farthest a correction may move the pose (and an IR-named tube may
    /// fall from its checkpoint), metres.
    pub max_jump_m: f64,
    /// Nearest range trusted, metres.
    pub range_min_m: f64,
    /// Farthest range trusted, metres.
    pub range_max_m: f64,
    /// Least time between two corrections by one checkpoint, ns.
    pub interval_ns: u64,
    /// Slack of the IR cone, radians.
    pub ir_margin_rad: f64,
    /// Correct only by checkpoints the IR names (not by those named by
    /// where their tube falls).
    pub require_ir: bool,
}

impl Default for SensorSettings {
    fn default() -> Self {
        SensorSettings {
            correct: true,
            ir_fresh_ns: 400_000_000,
            gate_m: 1.5,
            max_jump_m: 2.5,
            range_min_m: 0.5,
            range_max_m: 3.5,
            interval_ns: 500_000_000,
            ir_margin_rad: 5f64.to_radians(),
            require_ir: false,
        }
    }
}

/// One frame's facts.
#[derive(Debug, Clone, Copy)]
pub struct FrameInput<'a> {
    /// The tubes found in it.
    pub tubes: &'a [Tube],
    /// Its width, pixels.
    pub width_px: usize,
    /// Its stamp (the instant of the observation), ns.
    pub stamp_ns: u64,
    /// Now, ns (freshness of the IR report).
    pub now_ns: u64,
    /// The pose estimate, if fresh.
    pub pose: Option<Pose>,
    /// The latest IR report.
    pub ir: Option<IrSighting>,
    /// The head's pan, radians.
    pub pan_rad: f64,
}

/// A correction to send.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corrected {
    /// The payload.
    pub payload: PoseCorrection,
    /// The estimate it corrects.
    pub from: Pose,
    /// The geometry's verdict.
    pub correction: Correction,
}

/// What one frame gives.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameOutput {
    /// Tubes ranged (trusted ranges).
    pub ranged: usize,
    /// The sightings to send.
    pub sightings: Vec<CheckpointSighting>,
    /// The correction to send, if any.
    pub correction: Option<Corrected>,
    /// Corrections refused: checkpoint and why.
    pub rejected: Vec<(u8, String)>,
}

/// The sensor: configuration, Appendix A model, and when each checkpoint corrected last.
#[derive(Debug, Clone)]
pub struct Sensor {
    config: SensorConfig,
    model: Model,
    last_correction: BTreeMap<u8, u64>,
}

impl Sensor {
    /// A sensor of `config` ranging with `model`.
    pub fn new(config: SensorConfig, model: Model) -> Self {
        Sensor { config, model, last_correction: BTreeMap::new() }
    }

    /// The configuration.
    pub fn config(&self) -> &SensorConfig {
        &self.config
    }

    /// Works on one frame.
    pub fn frame(&mut self, f: &FrameInput<'_>, s: &SensorSettings) -> FrameOutput {
        let mut out = FrameOutput::default();
        let camera = Camera { width_px: f.width_px as f64, hfov_rad: self.config.camera.hfov_deg.to_radians() };
        let seen: Vec<Observation> = f
            .tubes
            .iter()
            .filter(|t| !t.clipped)
            .filter_map(|t| observe(t, &camera, &self.model, f.pan_rad, self.config.tube.radius_m).ok())
            .filter(|o| o.range_m >= s.range_min_m && o.range_m <= s.range_max_m)
            .collect();
        out.ranged = seen.len();
        let ir = f
            .ir
            .filter(|r| r.seen == 1 && r.checkpoint_id != 0 && f.now_ns.saturating_sub(r.stamp_ns) <= s.ir_fresh_ns);
        let half_angle = self.config.ir.half_angle_deg.to_radians();
        let nearest = |upright: bool| {
            (0..seen.len())
                .filter(|i| seen[*i].upright == upright)
                .min_by(|a, b| seen[*a].range_m.total_cmp(&seen[*b].range_m))
        };
        // which tube the IR code names
        let named: Option<(usize, u8)> = ir.and_then(|r| {
            let id = r.checkpoint_id;
            let i = if let Some(k) = self.config.checkpoint(id) {
                match &f.pose {
                    Some(p) => identify(p, &seen, (k.position[0], k.position[1]), s.max_jump_m),
                    None => nearest(true),
                }
            } else if self.config.target_ids.contains(&id) {
                nearest(false)
            } else {
                None
            };
            i.map(|i| (i, id))
        });
        // a known checkpoint the IR names but the camera does not range (it
        // is to the side, or nearer than the camera's range): reported
        // without range, so that the map builder records it all the same
        if let (Some(r), None) = (ir, named) {
            let cone = self
                .config
                .checkpoint(r.checkpoint_id)
                .and_then(|k| ir_cone(k.heading_deg.to_radians(), r.transmitters, half_angle).map(|c| (*k, c)));
            if let Some((k, c)) = cone {
                out.sightings.push(CheckpointSighting {
                    stamp_ns: f.stamp_ns,
                    x: k.position[0],
                    y: k.position[1],
                    facing_rad: c.centre as f32,
                    checkpoint_id: k.id,
                    transmitters: r.transmitters,
                    from_ir: 1,
                    ..Default::default()
                });
            }
        }
        for (i, o) in seen.iter().enumerate() {
            let by_ir = named.filter(|(n, _)| *n == i).map(|(_, id)| id);
            let placed = f.pose.as_ref().map(|p| place(p, o));
            let phi = f.pose.as_ref().map(|p| wrap_angle(p.theta + o.bearing_rad + PI));
            // by where it falls: the one known checkpoint within gate_m, no other within twice that
            let by_map = || -> Option<u8> {
                let (x, y) = placed?;
                if !o.upright {
                    return None;
                }
                let mut near: Vec<(u8, f64)> = self
                    .config
                    .checkpoints
                    .iter()
                    .map(|k| (k.id, (k.position[0] - x).hypot(k.position[1] - y)))
                    .filter(|(_, d)| *d <= 2.0 * s.gate_m)
                    .collect();
                near.sort_by(|a, b| a.1.total_cmp(&b.1));
                match near.as_slice() {
                    [(id, d)] if *d <= s.gate_m => Some(*id),
                    _ => None,
                }
            };
            let by_pos = if by_ir.is_none() { by_map() } else { None };
            let id = by_ir.or(by_pos).unwrap_or(0);
            let known = self.config.checkpoint(id).filter(|_| o.upright).copied();
            let (x, y) = match (known, placed) {
                (Some(k), _) => (k.position[0], k.position[1]),
                (None, Some(xy)) => xy,
                (None, None) => continue, // nowhere to put it
            };
            let cone = match (by_ir, known, ir) {
                (Some(_), Some(k), Some(r)) => ir_cone(k.heading_deg.to_radians(), r.transmitters, half_angle),
                _ => None,
            };
            out.sightings.push(CheckpointSighting {
                stamp_ns: f.stamp_ns,
                x,
                y,
                range_m: o.range_m as f32,
                bearing_rad: o.bearing_rad as f32,
                facing_rad: cone.map(|c| c.centre).or(phi).unwrap_or(0.0) as f32,
                checkpoint_id: id,
                transmitters: if by_ir.is_some() { ir.map_or(0, |r| r.transmitters) } else { 0 },
                from_ir: u8::from(by_ir.is_some()),
                from_camera: 1,
                is_target: u8::from(!o.upright),
                reserved: [0; 7],
            });

            // the correction: a known checkpoint the IR names (or, unless
            // require_ir, its position alone does), and a pose to correct
            let (Some(k), Some(est)) = (known, f.pose) else { continue };
            let named = by_ir.is_some() || (by_pos.is_some() && !s.require_ir);
            if !named || !s.correct || out.correction.is_some() {
                continue;
            }
            if self.last_correction.get(&id).is_some_and(|t| f.stamp_ns.saturating_sub(*t) < s.interval_ns) {
                continue;
            }
            let c = correct_pose(&est, (k.position[0], k.position[1]), o, cone, s.ir_margin_rad);
            let jump = (c.pose.x - est.x).hypot(c.pose.y - est.y);
            if jump > s.max_jump_m {
                out.rejected.push((id, format!("it would move the pose {jump:.2} m (max_jump_m {})", s.max_jump_m)));
                continue;
            }
            self.last_correction.insert(id, f.stamp_ns);
            let fields = CORRECTS_POSITION | if c.heading_corrected { CORRECTS_HEADING } else { 0 };
            out.correction = Some(Corrected {
                payload: PoseCorrection {
                    x: c.pose.x,
                    y: c.pose.y,
                    theta: c.pose.theta,
                    checkpoint_x: k.position[0],
                    checkpoint_y: k.position[1],
                    stamp_ns: f.stamp_ns,
                    range_m: o.range_m as f32,
                    bearing_rad: o.bearing_rad as f32,
                    fields,
                    source: PoseSource::Checkpoint as u8,
                    checkpoint_id: id,
                    reserved: [0; 5],
                },
                from: est,
                correction: c,
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::SensorConfig;
    use std::path::Path;

    const MS: u64 = 1_000_000;

    fn config() -> SensorConfig {
        SensorConfig::parse(
            Path::new("test.toml"),
            "target_ids = [9]\n\
             [[checkpoint]]\nid = 1\nposition = [1.2, 1.2]\nheading_deg = -90\n\
             [[checkpoint]]\nid = 2\nposition = [6.0, 1.2]\nheading_deg = -90\n",
        )
        .unwrap()
    }

    fn camera() -> Camera {
        Camera { width_px: 320.0, hfov_rad: 60f64.to_radians() }
    }

    /// The tube the simulator's camera shows of a tube at `cp` seen from `truth` (pinhole).
    fn tube_of(truth: &Pose, cp: (f64, f64), upright: bool) -> Tube {
        let (dx, dy) = (cp.0 - truth.x, cp.1 - truth.y);
        let a = wrap_angle(dy.atan2(dx) - truth.theta);
        let depth = (dx.hypot(dy) - 0.05) * a.cos();
        let f = camera().focal_px();
        let d = (0.2 * f / depth) as f32;
        let col = (160.0 - f * a.tan()) as f32;
        let (u, l) = if upright { (100.0, 100.0 + d) } else { (100.0 + d, 100.0) };
        Tube { col, upper_row: u, lower_row: l, d_px: d, upright, pixels: (100, 100), clipped: false }
    }

    fn sensor() -> Sensor {
        Sensor::new(config(), Model::pinhole(0.2 * camera().focal_px()))
    }

    fn ir(id: u8, tx: u8, stamp_ns: u64) -> IrSighting {
        IrSighting { seq: 1, stamp_ns, seen: 1, checkpoint_id: id, transmitters: tx, reserved: [0; 5] }
    }

    #[test]
    fn a_named_checkpoint_corrects_a_drifted_pose() {
        let truth = Pose { x: 0.5, y: 0.0, theta: 0.0 };
        let est = Pose { x: 0.2, y: 0.3, theta: 0.0 };
        let tubes = [tube_of(&truth, (1.2, 1.2), true)];
        let f = FrameInput {
            tubes: &tubes,
            width_px: 320,
            stamp_ns: 1000 * MS,
            now_ns: 1010 * MS,
            pose: Some(est),
            ir: Some(ir(1, 0b0001, 1000 * MS)),
            pan_rad: 0.0,
        };
        let mut s = sensor();
        let out = s.frame(&f, &SensorSettings::default());
        assert_eq!(out.ranged, 1);
        let sg = out.sightings[0];
        assert_eq!((sg.checkpoint_id, sg.from_ir, sg.is_target, sg.x, sg.y), (1, 1, 0, 1.2, 1.2));
        assert!((f64::from(sg.facing_rad) + PI / 2.0).abs() < 1e-6, "transmitter 0 faces -90°");
        let c = out.correction.expect("a correction");
        assert!((c.payload.x - truth.x).abs() < 0.01 && (c.payload.y - truth.y).abs() < 0.01, "{c:?}");
        assert_eq!((c.payload.checkpoint_id, c.payload.fields), (1, CORRECTS_POSITION));
        assert_eq!((c.payload.checkpoint_x, c.payload.checkpoint_y), (1.2, 1.2));
        // the next frame 100 ms later: within the interval, no second correction
        let f2 = FrameInput { stamp_ns: 1100 * MS, now_ns: 1110 * MS, ..f };
        assert!(s.frame(&f2, &SensorSettings::default()).correction.is_none());
        // after the interval: again
        let f3 = FrameInput { stamp_ns: 1600 * MS, now_ns: 1610 * MS, ir: Some(ir(1, 1, 1600 * MS)), ..f };
        assert!(s.frame(&f3, &SensorSettings::default()).correction.is_some());
        // corrections off: the sighting, no correction
        let f4 = FrameInput { stamp_ns: 3000 * MS, now_ns: 3000 * MS, ir: Some(ir(1, 1, 3000 * MS)), ..f };
        let off = SensorSettings { correct: false, ..SensorSettings::default() };
        let out = s.frame(&f4, &off);
        assert_eq!((out.sightings.len(), out.correction.is_none()), (1, true));
    }

    #[test]
    fn without_a_fresh_ir_code_the_tube_is_named_by_position() {
        let truth = Pose { x: 4.5, y: -0.2, theta: 0.3 };
        let tubes = [tube_of(&truth, (6.0, 1.2), true)];
        let f = FrameInput {
            tubes: &tubes,
            width_px: 320,
            stamp_ns: 5000 * MS,
            now_ns: 5000 * MS,
            pose: Some(Pose { x: 4.6, ..truth }),
            ir: Some(ir(2, 1, 4000 * MS)), // a second old
            pan_rad: 0.0,
        };
        let out = sensor().frame(&f, &SensorSettings::default());
        assert_eq!(out.sightings.len(), 1);
        assert_eq!((out.sightings[0].checkpoint_id, out.sightings[0].from_ir), (2, 0));
        let c = out.correction.expect("named by position: a correction");
        assert!((c.payload.x - truth.x).abs() < 0.02 && (c.payload.y - truth.y).abs() < 0.02, "{c:?}");
        // unless the IR is required
        let strict = SensorSettings { require_ir: true, ..SensorSettings::default() };
        assert!(sensor().frame(&f, &strict).correction.is_none());
        // no pose and no IR: nowhere to put it
        let out = sensor().frame(&FrameInput { pose: None, ..f }, &SensorSettings::default());
        assert!(out.sightings.is_empty());
    }

    #[test]
    fn a_checkpoint_heard_but_not_seen_is_reported_without_range() {
        let f = FrameInput {
            tubes: &[],
            width_px: 320,
            stamp_ns: 7,
            now_ns: 7,
            pose: None,
            ir: Some(ir(2, 0b0011, 7)),
            pan_rad: 0.0,
        };
        let out = sensor().frame(&f, &SensorSettings::default());
        assert_eq!(out.sightings.len(), 1);
        let sg = out.sightings[0];
        assert_eq!((sg.checkpoint_id, sg.from_ir, sg.from_camera, sg.x, sg.y, sg.range_m), (2, 1, 0, 6.0, 1.2, 0.0));
        assert!((f64::from(sg.facing_rad) + PI / 4.0).abs() < 1e-6, "between transmitters 0 (-90°) and 1 (0°)");
        assert!(out.correction.is_none());
        // an unknown code or a target's: nothing
        assert!(
            sensor().frame(&FrameInput { ir: Some(ir(9, 1, 7)), ..f }, &SensorSettings::default()).sightings.is_empty()
        );
    }

    #[test]
    fn the_target_is_placed_from_the_pose() {
        let truth = Pose { x: 12.8, y: -1.2, theta: -PI / 2.0 };
        let tubes =
            [tube_of(&truth, (12.8, -3.0), false), Tube { clipped: true, ..tube_of(&truth, (12.9, -3.0), true) }];
        let f = FrameInput {
            tubes: &tubes,
            width_px: 320,
            stamp_ns: 0,
            now_ns: 0,
            pose: Some(truth),
            ir: None,
            pan_rad: 0.0,
        };
        let out = sensor().frame(&f, &SensorSettings::default());
        assert_eq!((out.ranged, out.sightings.len()), (1, 1), "the clipped tube is not ranged");
        let t = out.sightings[0];
        assert_eq!((t.is_target, t.checkpoint_id), (1, 0));
        assert!((t.x - 12.8).abs() < 0.01 && (t.y + 3.0).abs() < 0.01, "{t:?}");
        assert!((f64::from(t.facing_rad) - PI / 2.0).abs() < 0.01, "facing the robot, north");
    }

    #[test]
    fn a_wild_correction_is_rejected() {
        let truth = Pose { x: 0.5, y: 0.0, theta: 0.0 };
        let tubes = [tube_of(&truth, (1.2, 1.2), true)];
        // the estimate is 2 m off, the IR names checkpoint 1 but the tube falls 2 m from it
        let f = FrameInput {
            tubes: &tubes,
            width_px: 320,
            stamp_ns: 0,
            now_ns: 0,
            pose: Some(Pose { x: 2.5, y: 0.0, theta: 0.0 }),
            ir: Some(ir(1, 1, 0)),
            pan_rad: 0.0,
        };
        let tight = SensorSettings { max_jump_m: 1.0, ..SensorSettings::default() };
        let out = sensor().frame(&f, &tight);
        assert!(out.correction.is_none());
        let cam: Vec<_> = out.sightings.iter().filter(|s| s.from_camera == 1).collect();
        assert_eq!(cam[0].from_ir, 0, "too far from checkpoint 1 to be the one the IR names");
        // the IR's checkpoint is reported on its own, without range
        assert!(out.sightings.iter().any(|s| s.from_camera == 0 && s.checkpoint_id == 1));
    }
}
