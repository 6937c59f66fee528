//! The target-achieving agent of robot 2 (thesis section 4.3.2.3, Fig. 4-9
//! and 4-10) as a library: follow a path of via points one after another.
//!
//! "Calculate the differential angle and distance between the robot and the
//! target coordinate. If the angle is more than ±10 degrees, the robot will
//! stop and rotate in order to face the target. Otherwise, the robot will
//! approach to the target" — and "robot 2 would not adjust its direction if
//! the angular error were within ±1 degree, in order to avoid motion
//! fluctuation", which gives the U-shaped approach of Fig. 4-10.
//!
//! [`Follower::step`], per cycle, with the pose estimate:
//!
//! * **rotate** in place (v = 0) while the heading error exceeds
//!   `rotate_above` (10°), until it is within `rotate_until` (2°); the turn
//!   rate falls with the error near the end so that it does not overshoot;
//! * **drive** otherwise, at `v_cruise` (slower near the last point), turning
//!   `ω = k_heading·error` — but not at all while the error is within
//!   `deadband` (1°);
//! * a via point is **reached** within `reach_m`, or when it was passed by
//!   (within `pass_m` and behind the robot), then the next one is taken; the
//!   last one is reached within `final_reach_m`, or, when it is the target
//!   itself (kind `target`), at `standoff_m` from it (the arm's reach), and
//!   the robot stops: **arrived**;
//! * at a via point of a checkpoint it **looks** at the checkpoint (turns
//!   to face the landmark the path gives for it, when that lies 0.3 … 3 m
//!   from the via point) and waits, still, until
//!   the odometry reports a correction by that checkpoint
//!   ([`Follower::correction_seen`]) or `look_timeout_s` passes — "it
//!   adjusted its coordinate using the checkpoint, and continued to move
//!   toward via point 2" (a fixed camera sees a checkpoint 1.6 m to the
//!   side only when it turns to it).
//!
//! Commands are rate-limited (`accel`, `alpha`) so that the motor agent,
//! which refuses jumps, accepts every one.

#![cfg_attr(test, allow(clippy::unwrap_used))]

pub use shm_schemas::geom::{Pose, wrap_angle};
use shm_schemas::payloads::{ViaKind, ViaPathBuf};
use std::f64::consts::PI;

/// Settings (the agent's parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Rotate in place above this heading error, radians (the thesis: 10°).
    pub rotate_above: f64,
    /// Stop rotating within this error, radians.
    pub rotate_until: f64,
    /// Do not steer within this error while driving, radians (the thesis: 1°).
    pub deadband: f64,
    /// Forward speed, m/s.
    pub v_cruise: f64,
    /// Least forward speed near the last point, m/s.
    pub v_min: f64,
    /// Slow down within this distance of the last point, metres.
    pub slow_within_m: f64,
    /// Turn rate when rotating in place, rad/s.
    pub omega_turn: f64,
    /// Steering gain while driving, 1/s.
    pub k_heading: f64,
    /// Largest turn rate while driving, rad/s.
    pub omega_drive_max: f64,
    /// A via point is reached within this, metres.
    pub reach_m: f64,
    /// A via point behind the robot within this is passed by, metres.
    pub pass_m: f64,
    /// The last point is reached within this, metres.
    pub final_reach_m: f64,
    /// Distance kept from a last point of kind `target`, metres.
    pub standoff_m: f64,
    /// Speed changes, m/s².
    pub accel: f64,
    /// Turn-rate changes, rad/s².
    pub alpha: f64,
    /// Look at the checkpoint at its via point, for a correction.
    pub look_at_checkpoints: bool,
    /// Longest wait for that correction, seconds.
    pub look_timeout_s: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            rotate_above: 10f64.to_radians(),
            rotate_until: 2f64.to_radians(),
            deadband: 1f64.to_radians(),
            v_cruise: 0.3,
            v_min: 0.06,
            slow_within_m: 0.8,
            omega_turn: 0.6,
            k_heading: 1.2,
            omega_drive_max: 0.5,
            reach_m: 0.25,
            pass_m: 0.6,
            final_reach_m: 0.1,
            standoff_m: 0.35,
            accel: 1.0,
            alpha: 4.0,
            look_at_checkpoints: true,
            look_timeout_s: 6.0,
        }
    }
}

/// Why a path cannot be followed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PathError {
    /// No points.
    #[error("path {path_id} has no points")]
    Empty {
        /// The path.
        path_id: u32,
    },
    /// A point that is not a number or of an unknown kind.
    #[error("path {path_id}, point {index}: {problem}")]
    BadPoint {
        /// The path.
        path_id: u32,
        /// The point.
        index: usize,
        /// What is wrong.
        problem: String,
    },
}

/// A point to reach.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Via {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
    /// What it is.
    pub kind: ViaKind,
    /// The checkpoint it belongs to, 0 for none.
    pub checkpoint: u8,
    /// The landmark it belongs to (to look at), metres, world frame.
    pub landmark: (f64, f64),
}

/// Checks a path and returns its points.
pub fn read_path(p: &ViaPathBuf) -> Result<Vec<Via>, PathError> {
    let path_id = p.path_id();
    if p.points.is_empty() {
        return Err(PathError::Empty { path_id });
    }
    p.points
        .iter()
        .enumerate()
        .map(|(index, v)| {
            let (pt, kind, checkpoint, lm) = (v.point, v.kind, v.checkpoint_id, v.landmark);
            if !(pt[0].is_finite() && pt[1].is_finite() && lm[0].is_finite() && lm[1].is_finite()) {
                return Err(PathError::BadPoint { path_id, index, problem: "not a number".into() });
            }
            let kind = ViaKind::from_code(kind).ok_or_else(|| PathError::BadPoint {
                path_id,
                index,
                problem: format!("unknown kind code {kind}"),
            })?;
            Ok(Via { x: pt[0], y: pt[1], kind, checkpoint, landmark: (lm[0], lm[1]) })
        })
        .collect()
}

/// What the follower is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// No path.
    Idle,
    /// Rotating in place to face the next point.
    Rotating,
    /// Driving toward it.
    Driving,
    /// At a checkpoint's via point: facing the checkpoint, waiting for a correction.
    Looking,
    /// The last point is reached.
    Arrived,
}

/// What a step reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// Point `index` (not the last) was reached, at `distance_m` from it.
    Reached {
        /// Its index.
        index: usize,
        /// How far from it.
        distance_m: f64,
    },
    /// The last point (`index`) was reached.
    Arrived {
        /// Its index.
        index: usize,
        /// How far from it.
        distance_m: f64,
    },
}

/// The output of one step.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Step {
    /// Forward speed, m/s.
    pub v: f64,
    /// Turn rate, rad/s.
    pub omega: f64,
    /// Heading error to the current point, radians.
    pub error: f64,
    /// What happened.
    pub events: Vec<Event>,
}

/// The via-point follower.
#[derive(Debug, Clone)]
pub struct Follower {
    settings: Settings,
    points: Vec<Via>,
    path_id: u32,
    index: usize,
    phase: Phase,
    sent: (f64, f64),
    look: Option<Look>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Look {
    checkpoint: u8,
    at: (f64, f64),
    elapsed_s: f64,
    corrected: bool,
}

fn slew(from: f64, to: f64, rate: f64, dt: f64) -> f64 {
    let d = rate * dt.max(0.0);
    to.clamp(from - d, from + d)
}

impl Follower {
    /// A follower without a path.
    pub fn new(settings: Settings) -> Self {
        Follower {
            settings,
            points: Vec::new(),
            path_id: 0,
            index: 0,
            phase: Phase::Idle,
            sent: (0.0, 0.0),
            look: None,
        }
    }

    /// Changes the settings.
    pub fn set_settings(&mut self, s: Settings) {
        self.settings = s;
    }

    /// Starts following `path` from its first point.
    pub fn follow(&mut self, path: &ViaPathBuf) -> Result<(), PathError> {
        self.points = read_path(path)?;
        self.path_id = path.path_id();
        self.index = 0;
        self.phase = Phase::Driving;
        self.look = None;
        Ok(())
    }

    /// The odometry applied a correction by `checkpoint`: a look at it ends.
    pub fn correction_seen(&mut self, checkpoint: u8) {
        if let Some(l) = self.look.as_mut().filter(|l| l.checkpoint == checkpoint) {
            l.corrected = true;
        }
    }

    /// Robot 2's own camera sees the target at `(x, y)` (in robot 2's
    /// frame, which is the frame it drives in): while it drives the last two
    /// points and the sighting lies within `max_shift_m` of the path's
    /// target, the target point moves there — robot 1's estimate of where the
    /// target stands (made with robot 1's odometry) gives way to robot 2's
    /// own. Returns whether the point moved.
    pub fn target_seen(&mut self, x: f64, y: f64, max_shift_m: f64) -> bool {
        let moving = !matches!(self.phase, Phase::Idle | Phase::Arrived);
        if !(x.is_finite() && y.is_finite() && moving) || self.index + 2 < self.points.len() {
            return false;
        }
        let Some(last) = self.points.last_mut().filter(|p| p.kind == ViaKind::Target) else { return false };
        if (last.x - x).hypot(last.y - y) > max_shift_m {
            return false;
        }
        // a running mean would lag behind; the newest, nearest sighting is the best
        (last.x, last.y, last.landmark) = (x, y, (x, y));
        true
    }

    /// Stops following (the robot stops).
    pub fn abort(&mut self) {
        self.points.clear();
        self.phase = Phase::Idle;
        self.look = None;
    }

    /// The path followed (0: none).
    pub fn path_id(&self) -> u32 {
        self.path_id
    }

    /// The point being approached.
    pub fn index(&self) -> usize {
        self.index
    }

    /// The phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The points of the path.
    pub fn points(&self) -> &[Via] {
        &self.points
    }

    fn is_last(&self) -> bool {
        self.index + 1 >= self.points.len()
    }

    /// One cycle of `dt` seconds at `pose`.
    pub fn step(&mut self, pose: &Pose, dt: f64) -> Step {
        let s = self.settings;
        let mut out = Step::default();
        let (mut v, mut omega) = (0.0, 0.0);
        if self.phase == Phase::Looking {
            match self.look.as_mut() {
                Some(l) if !l.corrected && l.elapsed_s < s.look_timeout_s => {
                    l.elapsed_s += dt.max(0.0);
                    let err = wrap_angle((l.at.1 - pose.y).atan2(l.at.0 - pose.x) - pose.theta);
                    out.error = err;
                    if err.abs() > s.rotate_until {
                        omega = (2.0 * err.abs()).clamp(0.15, s.omega_turn.max(0.15)).copysign(err);
                    }
                }
                _ => {
                    self.look = None;
                    self.phase = Phase::Driving;
                }
            }
        }
        if matches!(self.phase, Phase::Rotating | Phase::Driving) && pose.x.is_finite() && pose.y.is_finite() {
            // advance past the points reached
            while let Some(p) = self.points.get(self.index).copied() {
                let (dx, dy) = (p.x - pose.x, p.y - pose.y);
                let dist = dx.hypot(dy);
                let err = wrap_angle(dy.atan2(dx) - pose.theta);
                let last = self.is_last();
                let reached = if last {
                    if p.kind == ViaKind::Target { dist <= s.standoff_m } else { dist <= s.final_reach_m }
                } else {
                    dist <= s.reach_m || (dist <= s.pass_m && err.abs() > PI / 2.0)
                };
                if !reached {
                    break;
                }
                if last {
                    out.events.push(Event::Arrived { index: self.index, distance_m: dist });
                    self.phase = Phase::Arrived;
                    break;
                }
                out.events.push(Event::Reached { index: self.index, distance_m: dist });
                self.index += 1;
                self.phase = Phase::Driving;
                // a landmark the camera can range from here (a path without
                // landmarks, all zeros, is not looked at)
                let lm_dist = (p.landmark.0 - p.x).hypot(p.landmark.1 - p.y);
                let lookable = (0.3..=3.0).contains(&lm_dist);
                if s.look_at_checkpoints && p.kind == ViaKind::Checkpoint && p.checkpoint != 0 && lookable {
                    self.look =
                        Some(Look { checkpoint: p.checkpoint, at: p.landmark, elapsed_s: 0.0, corrected: false });
                    self.phase = Phase::Looking;
                    break;
                }
            }
        }
        if matches!(self.phase, Phase::Rotating | Phase::Driving)
            && let Some(p) = self.points.get(self.index).copied()
        {
            let (dx, dy) = (p.x - pose.x, p.y - pose.y);
            let dist = dx.hypot(dy);
            let err = wrap_angle(dy.atan2(dx) - pose.theta);
            out.error = err;
            if self.phase == Phase::Rotating && err.abs() <= s.rotate_until {
                self.phase = Phase::Driving;
            } else if self.phase == Phase::Driving && err.abs() > s.rotate_above {
                self.phase = Phase::Rotating;
            }
            match self.phase {
                Phase::Rotating => {
                    // slower near the end: ω ≥ 0.15 rad/s, ≤ omega_turn
                    let w = (2.0 * err.abs()).clamp(0.15, s.omega_turn.max(0.15));
                    omega = w.copysign(err);
                }
                _ => {
                    let to_go = if self.is_last() {
                        let stop_at = if p.kind == ViaKind::Target { s.standoff_m } else { 0.0 };
                        (dist - stop_at).max(0.0)
                    } else {
                        f64::INFINITY
                    };
                    v = if to_go < s.slow_within_m {
                        (s.v_cruise * to_go / s.slow_within_m.max(1e-6)).max(s.v_min)
                    } else {
                        s.v_cruise
                    };
                    omega = if err.abs() <= s.deadband {
                        0.0
                    } else {
                        (s.k_heading * err).clamp(-s.omega_drive_max, s.omega_drive_max)
                    };
                }
            }
        }
        // rate limits, from what was sent last
        let (v0, w0) = self.sent;
        let v = slew(v0, v, s.accel, dt);
        let omega = slew(w0, omega, s.alpha, dt);
        self.sent = (v, omega);
        out.v = v;
        out.omega = omega;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::payloads::ViaPoint;

    fn path(points: &[(f64, f64, ViaKind)]) -> ViaPathBuf {
        let mut p = ViaPathBuf::new(1, 0);
        p.points = points.iter().map(|&(x, y, k)| ViaPoint::new([x, y], k, 0, [0.0, 0.0])).collect();
        p
    }

    /// A step with the rate limits out of the way (many cycles at the same pose).
    fn settle(f: &mut Follower, pose: &Pose) -> Step {
        let mut s = f.step(pose, 0.05);
        for _ in 0..40 {
            s = f.step(pose, 0.05);
        }
        s
    }

    #[test]
    fn robot_2s_own_sighting_moves_the_target_on_the_last_legs_only() {
        let mut f = Follower::new(Settings::default());
        f.follow(&path(&[
            (2.0, 0.0, ViaKind::Waypoint),
            (4.0, 0.0, ViaKind::TargetApproach),
            (5.0, 0.0, ViaKind::Target),
        ]))
        .unwrap();
        assert!(!f.target_seen(5.2, 0.1, 1.0), "not while the first point is ahead");
        settle(&mut f, &Pose { x: 2.0, y: 0.0, theta: 0.0 });
        assert_eq!(f.index(), 1);
        assert!(!f.target_seen(6.5, 0.0, 1.0), "too far from robot 1's estimate: another tube");
        assert!(!f.target_seen(f64::NAN, 0.0, 1.0));
        assert!(f.target_seen(5.3, -0.2, 1.0));
        let last = f.points()[2];
        assert_eq!((last.x, last.y, last.landmark), (5.3, -0.2, (5.3, -0.2)));
        // the approach point stays: only the target moves
        assert_eq!((f.points()[1].x, f.points()[1].y), (4.0, 0.0));
    }

    #[test]
    fn the_rules_of_fig_4_10() {
        let mut f = Follower::new(Settings::default());
        f.follow(&path(&[(10.0, 0.0, ViaKind::Waypoint)])).unwrap();
        // 20° off: stop and rotate toward it (to the right)
        let s = settle(&mut f, &Pose { x: 0.0, y: 0.0, theta: 20f64.to_radians() });
        assert_eq!((f.phase(), s.v), (Phase::Rotating, 0.0));
        assert!(s.omega < 0.0, "{s:?}");
        // rotating goes on under 10° until 2°
        let s = settle(&mut f, &Pose { x: 0.0, y: 0.0, theta: 5f64.to_radians() });
        assert_eq!((f.phase(), s.v), (Phase::Rotating, 0.0));
        // 1.5° off: facing it; drive on, steering a little
        let s = settle(&mut f, &Pose { x: 0.0, y: 0.0, theta: 1.5f64.to_radians() });
        assert_eq!(f.phase(), Phase::Driving);
        assert!(s.v > 0.25 && s.omega < 0.0, "{s:?}");
        // 8° off while driving: steer, do not stop
        let s = settle(&mut f, &Pose { x: 0.0, y: 0.0, theta: 8f64.to_radians() });
        assert_eq!(f.phase(), Phase::Driving);
        assert!(s.v > 0.25 && s.omega < 0.0, "{s:?}");
        // 0.5° off: not worth a correction
        let s = settle(&mut f, &Pose { x: 0.0, y: 0.0, theta: 0.5f64.to_radians() });
        assert_eq!((s.omega, f.phase()), (0.0, Phase::Driving));
        assert!((s.v - 0.3).abs() < 1e-9);
    }

    #[test]
    fn commands_are_rate_limited_for_the_motor() {
        let mut f = Follower::new(Settings::default());
        f.follow(&path(&[(10.0, 0.0, ViaKind::Waypoint)])).unwrap();
        let s = f.step(&Pose::default(), 0.05);
        // 1 m/s² × 50 ms
        assert!((s.v - 0.05).abs() < 1e-9, "{s:?}");
        let s = f.step(&Pose::default(), 0.05);
        assert!((s.v - 0.10).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn bad_paths_are_refused() {
        let mut f = Follower::new(Settings::default());
        assert!(matches!(f.follow(&ViaPathBuf::default()), Err(PathError::Empty { .. })));
        let mut p = path(&[(f64::NAN, 0.0, ViaKind::Target)]);
        assert!(matches!(f.follow(&p), Err(PathError::BadPoint { index: 0, .. })));
        p.points[0].point = [1.0, 1.0];
        p.points[0].kind = 77;
        assert!(f.follow(&p).unwrap_err().to_string().contains("kind code 77"));
        assert_eq!(f.phase(), Phase::Idle);
        // idle: no motion
        let s = f.step(&Pose::default(), 0.05);
        assert_eq!((s.v, s.omega), (0.0, 0.0));
    }

    /// A unicycle driven by the follower from robot 2's start, through the
    /// via points of three checkpoints and the target's, to the target of
    /// the thesis' corridor (Fig. 4-10).
    #[test]
    fn reaches_the_target_through_three_via_points() {
        let vias = [
            (1.2, -0.4, ViaKind::Checkpoint),
            (6.0, -0.4, ViaKind::Checkpoint),
            (10.8, -0.4, ViaKind::Checkpoint),
            (12.8, -1.4, ViaKind::TargetApproach),
            (12.8, -3.0, ViaKind::Target),
        ];
        let mut f = Follower::new(Settings::default());
        f.follow(&path(&vias)).unwrap();
        let mut pose = Pose { x: -4.0, y: 0.0, theta: 0.3 };
        let dt = 0.05;
        let (mut reached, mut arrived) = (Vec::new(), None);
        let mut rotated_in_place = 0;
        let mut t = 0.0;
        while t < 300.0 && arrived.is_none() {
            let s = f.step(&pose, dt);
            for e in &s.events {
                match e {
                    Event::Reached { index, distance_m } => reached.push((*index, *distance_m)),
                    Event::Arrived { index, distance_m } => arrived = Some((*index, *distance_m, t)),
                }
            }
            if s.v == 0.0 && s.omega != 0.0 {
                rotated_in_place += 1;
            }
            // the robot: exact unicycle
            pose.theta = wrap_angle(pose.theta + s.omega * dt);
            pose.x += s.v * dt * pose.theta.cos();
            pose.y += s.v * dt * pose.theta.sin();
            t += dt;
        }
        let (index, dist, when) = arrived.expect("arrived");
        assert_eq!(index, 4);
        assert_eq!(reached.iter().map(|r| r.0).collect::<Vec<_>>(), vec![0, 1, 2, 3]);
        assert!(reached.iter().all(|r| r.1 <= 0.6), "{reached:?}");
        let to_target = (pose.x - 12.8).hypot(pose.y + 3.0);
        assert!((0.25..=0.5).contains(&to_target), "stopped {to_target} m from the target (arrived at {dist})");
        assert!(rotated_in_place > 0, "the right turn after via point 3 is a rotation in place");
        assert!(when < 150.0, "took {when} s for about 19 m at 0.3 m/s");
        // once arrived it stays stopped
        let mut s = f.step(&pose, dt);
        for _ in 0..20 {
            s = f.step(&pose, dt);
        }
        assert_eq!((s.v, s.omega, f.phase()), (0.0, 0.0, Phase::Arrived));
    }

    #[test]
    fn at_a_checkpoints_via_point_it_looks_and_waits_for_the_correction() {
        let mut p = path(&[(2.0, 0.0, ViaKind::Checkpoint), (4.0, 0.0, ViaKind::Waypoint)]);
        p.points[0].checkpoint_id = 1;
        p.points[0].landmark = [2.0, 1.6]; // the checkpoint, to the left of its via point
        p.points[1].landmark = [4.0, 0.0];
        let mut f = Follower::new(Settings::default());
        f.follow(&p).unwrap();
        let mut pose = Pose { x: 1.9, y: 0.0, theta: 0.0 };
        let s = f.step(&pose, 0.05);
        assert!(matches!(s.events[..], [Event::Reached { index: 0, .. }]));
        assert_eq!(f.phase(), Phase::Looking);
        // it turns left to face the checkpoint (within the 6 s it waits)
        for _ in 0..110 {
            let s = f.step(&pose, 0.05);
            pose.theta = wrap_angle(pose.theta + s.omega * 0.05);
            pose.x += s.v * 0.05 * pose.theta.cos();
        }
        let want = 1.6f64.atan2(0.1);
        assert!((pose.theta - want).abs() < 3f64.to_radians(), "facing {}°", pose.theta.to_degrees());
        assert_eq!(f.phase(), Phase::Looking);
        // a correction by another checkpoint does not end the look; by this one it does
        let mut f = Follower::new(Settings::default());
        f.follow(&p).unwrap();
        let pose = Pose { x: 1.9, y: 0.0, theta: PI / 2.0 };
        f.step(&pose, 0.05);
        f.correction_seen(2);
        f.step(&pose, 0.05);
        assert_eq!(f.phase(), Phase::Looking);
        f.correction_seen(1);
        f.step(&pose, 0.05);
        assert_eq!(f.phase(), Phase::Rotating, "on to the next point (behind its right shoulder)");
        assert_eq!(f.index(), 1);
        // a path without landmarks (all zeros, far from the via point): no look
        let mut bare = p.clone();
        for v in &mut bare.points {
            v.landmark = [0.0; 2];
        }
        bare.points[0].point = [5.0, 0.0];
        bare.points[1].point = [8.0, 0.0];
        let mut f = Follower::new(Settings::default());
        f.follow(&bare).unwrap();
        f.step(&Pose { x: 4.9, y: 0.0, theta: 0.0 }, 0.05);
        assert_eq!((f.index(), f.phase()), (1, Phase::Driving));
        // without a correction the look ends after the timeout
        let mut f = Follower::new(Settings { look_timeout_s: 1.0, ..Settings::default() });
        f.follow(&p).unwrap();
        for _ in 0..22 {
            f.step(&pose, 0.05);
        }
        assert_ne!(f.phase(), Phase::Looking);
    }
}
