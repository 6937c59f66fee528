//! Dead reckoning with checkpoint corrections (thesis section 4.3.2.1:
//! "the dead reckoning can be used for a short distance, but suffers from
//! the accumulated error; … this mechanism is useful for correction of
//! accumulated error of odometer").
//!
//! **Dead reckoning** ([`DeadReckoning::on_odometry`]). The motor agent
//! integrates its encoders into a pose in its own frame (`nerve::Odometry`).
//! This estimator takes the *increments* between successive reports — the
//! motion in the robot's frame, `R(−θ_prev)·Δp` and `Δθ` — and adds them to
//! its own world-frame estimate, which starts at the configured start pose.
//! So a correction simply moves the estimate, and a motor agent restarted
//! from its origin is only a reset of the increments (detected as an
//! impossible step, logged and counted), not a jump of the estimate.
//!
//! **Corrections** ([`DeadReckoning::apply_correction`]). A correction gives
//! the pose at the instant of an observation, a little in the past. The
//! estimator keeps a few seconds of its history, finds its estimate at that
//! instant, and moves the whole estimate by the rigid transform that takes
//! that estimate onto the correction — so the motion since the observation
//! is carried over. A correction that would move the pose farther than
//! `max_jump_m`, or that is older than the history, is refused.
//!
//! **Heading from two checkpoints** ([`heading_from_two`]). One checkpoint
//! fixes the position, not the heading: a rotation about the checkpoint
//! leaves its range and bearing unchanged, so a heading error `δ` at the
//! first checkpoint `C1` leaves the corrected position turned by `δ` about
//! `C1`, and dead reckoning carries the same turn along the leg that
//! follows. At a second, different checkpoint `C2`, seen with only dead
//! reckoning since `C1`, the estimate `E` is therefore the truth turned by
//! `δ` about `C1`; `δ` is the angle that makes `C1 + R(−δ)·(E − C1)` agree
//! with the range and bearing measured to `C2` (with the heading turned
//! back by the same angle). It is found by a bounded 1-D search, used only
//! when the leg is long enough (`min_baseline_m`) and the fit is good
//! (`max_residual_m`). The heading error is assumed constant along the leg;
//! a drift that grows along it is reduced, not removed.

#![cfg_attr(test, allow(clippy::unwrap_used))]

pub use shm_schemas::geom::{Pose, wrap_angle};
use shm_schemas::payloads::navigation::{CORRECTS_HEADING, CORRECTS_POSITION};
use shm_schemas::payloads::{Odometry, PoseCorrection, PoseEstimate, PoseSource};
use std::collections::VecDeque;

/// The rigid transform taking pose `from` onto pose `to`, applied to `p`.
fn carry(from: &Pose, to: &Pose, p: &Pose) -> Pose {
    let dth = wrap_angle(to.theta - from.theta);
    let (s, c) = dth.sin_cos();
    let (dx, dy) = (p.x - from.x, p.y - from.y);
    Pose { x: to.x + c * dx - s * dy, y: to.y + s * dx + c * dy, theta: wrap_angle(p.theta + dth) }
}

/// Settings of the estimator (the agent's parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// A step of the motor's odometry longer than this is a reset, metres.
    pub max_step_m: f64,
    /// A step turning more than this is a reset, radians.
    pub max_step_rad: f64,
    /// History kept for late corrections, ns.
    pub history_ns: u64,
    /// A correction moving the pose farther is refused, metres.
    pub max_jump_m: f64,
    /// Refine the heading from two different checkpoints.
    pub two_checkpoints: bool,
    /// Shortest leg between the two checkpoints' corrections, metres.
    pub min_baseline_m: f64,
    /// Largest heading error the two-checkpoint fix may find, radians.
    pub max_heading_fix_rad: f64,
    /// Largest residual of the two-checkpoint fix, metres.
    pub max_residual_m: f64,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            max_step_m: 0.5,
            max_step_rad: 1.0,
            history_ns: 3_000_000_000,
            max_jump_m: 3.0,
            two_checkpoints: true,
            min_baseline_m: 2.0,
            max_heading_fix_rad: 35f64.to_radians(),
            max_residual_m: 0.3,
        }
    }
}

/// What one odometry report did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Step {
    /// The first report: the increments start from it.
    First,
    /// The estimate moved.
    Moved,
    /// The report jumped (the motor agent restarted): the increments start again from it.
    Reset {
        /// How far the report jumped, metres.
        jump_m: f64,
    },
    /// The report is older than the previous one: ignored.
    Stale,
}

/// Why a report or a correction was not used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OdomError {
    /// A value that is not a number.
    #[error("{what} with a non-finite value from {sender}; is the sender misbehaving?")]
    NonFinite {
        /// Which message.
        what: &'static str,
        /// Who sent it.
        sender: String,
    },
    /// Older than the history.
    #[error(
        "correction from {age_ms} ms ago is older than the {history_ms} ms of history kept; is the checkpoint sensor lagging?"
    )]
    TooOld {
        /// Its age.
        age_ms: u64,
        /// The history kept.
        history_ms: u64,
    },
    /// It would move the pose too far.
    #[error("correction by checkpoint {checkpoint} would move the pose {jump_m:.2} m (max_jump_m {max_m}); refused")]
    TooFar {
        /// The checkpoint.
        checkpoint: u8,
        /// The jump.
        jump_m: f64,
        /// The limit.
        max_m: f64,
    },
    /// No odometry yet: nothing to correct.
    #[error("correction before the first odometry report; connect motor/odom to odometry/odom")]
    NoOdometry,
}

/// What a correction did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Applied {
    /// How far the position jumped, metres (at the observation's instant).
    pub jump_m: f64,
    /// How much the heading turned, radians.
    pub dtheta: f64,
    /// The heading came from two checkpoints.
    pub heading_from_two: bool,
}

#[derive(Debug, Clone, Copy)]
struct Anchor {
    checkpoint: u8,
    checkpoint_pos: (f64, f64),
    stamp_ns: u64,
    pose: Pose,
}

/// The estimator.
#[derive(Debug, Clone)]
pub struct DeadReckoning {
    settings: Settings,
    pose: Pose,
    v: f64,
    omega: f64,
    stamp_ns: u64,
    last_raw: Option<(Pose, u64)>,
    history: VecDeque<(u64, Pose)>,
    anchor: Option<Anchor>,
    corrections: u32,
    resets: u64,
    source: PoseSource,
    last_checkpoint: u8,
}

impl DeadReckoning {
    /// Starts at `start` (world frame).
    pub fn new(start: Pose, settings: Settings) -> Self {
        DeadReckoning {
            settings,
            pose: start,
            v: 0.0,
            omega: 0.0,
            stamp_ns: 0,
            last_raw: None,
            history: VecDeque::new(),
            anchor: None,
            corrections: 0,
            resets: 0,
            source: PoseSource::DeadReckoning,
            last_checkpoint: 0,
        }
    }

    /// Changes the settings.
    pub fn set_settings(&mut self, s: Settings) {
        self.settings = s;
    }

    /// The current estimate.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// Corrections applied so far.
    pub fn corrections(&self) -> u32 {
        self.corrections
    }

    /// Resets of the motor's odometry seen so far.
    pub fn resets(&self) -> u64 {
        self.resets
    }

    /// The estimate as a payload.
    pub fn estimate(&self) -> PoseEstimate {
        PoseEstimate {
            x: self.pose.x,
            y: self.pose.y,
            theta: self.pose.theta,
            v: self.v,
            omega: self.omega,
            stamp_ns: self.stamp_ns,
            corrections: self.corrections,
            source: self.source as u8,
            last_checkpoint: self.last_checkpoint,
            reserved: [0; 2],
        }
    }

    /// Adds the motion of one report of the motor's odometry.
    pub fn on_odometry(&mut self, o: &Odometry, sender: &str) -> Result<Step, OdomError> {
        let raw = Pose { x: o.x, y: o.y, theta: o.theta };
        if !raw.is_finite() {
            return Err(OdomError::NonFinite { what: "odometry", sender: sender.to_owned() });
        }
        let step = match self.last_raw {
            None => Step::First,
            Some((_, t)) if o.stamp_ns < t => return Ok(Step::Stale),
            Some((prev, _)) => {
                let (dx, dy) = (raw.x - prev.x, raw.y - prev.y);
                let (s, c) = prev.theta.sin_cos();
                // the motion in the robot's frame at the previous report
                let (fx, fy) = (c * dx + s * dy, -s * dx + c * dy);
                let dth = wrap_angle(raw.theta - prev.theta);
                let len = dx.hypot(dy);
                if len > self.settings.max_step_m || dth.abs() > self.settings.max_step_rad {
                    self.resets += 1;
                    Step::Reset { jump_m: len }
                } else {
                    let (s, c) = self.pose.theta.sin_cos();
                    self.pose.x += c * fx - s * fy;
                    self.pose.y += s * fx + c * fy;
                    self.pose.theta = wrap_angle(self.pose.theta + dth);
                    Step::Moved
                }
            }
        };
        self.last_raw = Some((raw, o.stamp_ns));
        if o.v.is_finite() && o.omega.is_finite() {
            (self.v, self.omega) = (o.v, o.omega);
        }
        self.stamp_ns = o.stamp_ns;
        self.history.push_back((o.stamp_ns, self.pose));
        let keep_from = o.stamp_ns.saturating_sub(self.settings.history_ns);
        while self.history.len() > 2 && self.history.front().is_some_and(|(t, _)| *t < keep_from) {
            self.history.pop_front();
        }
        Ok(step)
    }

    /// The estimate at `stamp_ns`: the last one not after it (the current
    /// one when no history is kept yet); `None` when it is older than the history.
    pub fn pose_at(&self, stamp_ns: u64) -> Option<Pose> {
        if self.history.is_empty() {
            return Some(self.pose);
        }
        if self.history.front().is_some_and(|(t, _)| stamp_ns < *t) {
            return None;
        }
        self.history.iter().rev().find(|(t, _)| *t <= stamp_ns).map(|(_, p)| *p)
    }

    /// Applies a checkpoint's correction (see the module's documentation).
    pub fn apply_correction(&mut self, c: &PoseCorrection, sender: &str) -> Result<Applied, OdomError> {
        let corr = Pose { x: c.x, y: c.y, theta: c.theta };
        if !corr.is_finite() || !c.checkpoint_x.is_finite() || !c.checkpoint_y.is_finite() {
            return Err(OdomError::NonFinite { what: "correction", sender: sender.to_owned() });
        }
        if self.last_raw.is_none() {
            return Err(OdomError::NoOdometry);
        }
        let est = self.pose_at(c.stamp_ns).ok_or(OdomError::TooOld {
            age_ms: self.stamp_ns.saturating_sub(c.stamp_ns) / 1_000_000,
            history_ms: self.settings.history_ns / 1_000_000,
        })?;
        let mut target = Pose {
            x: if c.fields & CORRECTS_POSITION != 0 { corr.x } else { est.x },
            y: if c.fields & CORRECTS_POSITION != 0 { corr.y } else { est.y },
            theta: if c.fields & CORRECTS_HEADING != 0 { corr.theta } else { est.theta },
        };
        let mut from_two = false;
        let range = f64::from(c.range_m);
        let bearing = f64::from(c.bearing_rad);
        if let Some(a) = self.anchor.filter(|a| self.settings.two_checkpoints && a.checkpoint != c.checkpoint_id) {
            let leg = (est.x - a.pose.x, est.y - a.pose.y);
            if leg.0.hypot(leg.1) >= self.settings.min_baseline_m
                && range.is_finite()
                && bearing.is_finite()
                && let Some((delta, resid)) = heading_from_two(
                    a.checkpoint_pos,
                    (est.x - a.checkpoint_pos.0, est.y - a.checkpoint_pos.1),
                    est.theta,
                    (c.checkpoint_x, c.checkpoint_y),
                    range,
                    bearing,
                    self.settings.max_heading_fix_rad,
                )
                && resid <= self.settings.max_residual_m
            {
                let theta = wrap_angle(est.theta + delta);
                let phi = theta + bearing;
                target = Pose { x: c.checkpoint_x - range * phi.cos(), y: c.checkpoint_y - range * phi.sin(), theta };
                from_two = true;
            }
        }
        let jump_m = (target.x - est.x).hypot(target.y - est.y);
        if jump_m > self.settings.max_jump_m {
            return Err(OdomError::TooFar { checkpoint: c.checkpoint_id, jump_m, max_m: self.settings.max_jump_m });
        }
        let dtheta = wrap_angle(target.theta - est.theta);
        self.pose = carry(&est, &target, &self.pose);
        for (_, p) in self.history.iter_mut() {
            *p = carry(&est, &target, p);
        }
        self.anchor = Some(Anchor {
            checkpoint: c.checkpoint_id,
            checkpoint_pos: (c.checkpoint_x, c.checkpoint_y),
            stamp_ns: c.stamp_ns,
            pose: target,
        });
        self.corrections = self.corrections.saturating_add(1);
        self.source = PoseSource::Checkpoint;
        self.last_checkpoint = c.checkpoint_id;
        Ok(Applied { jump_m, dtheta, heading_from_two: from_two })
    }

    /// The instant of the last correction, if any.
    pub fn last_correction_ns(&self) -> Option<u64> {
        self.anchor.map(|a| a.stamp_ns)
    }
}

/// The correction `δ` of the heading, turning the estimate about `pivot`
/// (the previous checkpoint; `offset` is the estimated position minus
/// `pivot`), such that with the heading `theta + δ` the checkpoint at
/// `checkpoint` is seen at `range` and `bearing` from the turned position.
/// Searches `|δ| ≤ max`; returns `δ` and the residual (metres) of the best fit.
pub fn heading_from_two(
    pivot: (f64, f64),
    offset: (f64, f64),
    theta: f64,
    checkpoint: (f64, f64),
    range: f64,
    bearing: f64,
    max: f64,
) -> Option<(f64, f64)> {
    let resid = |d: f64| {
        let (s, c) = d.sin_cos();
        let px = pivot.0 + c * offset.0 - s * offset.1;
        let py = pivot.1 + s * offset.0 + c * offset.1;
        let a = theta + d + bearing;
        (px + range * a.cos() - checkpoint.0).hypot(py + range * a.sin() - checkpoint.1)
    };
    if !(max.is_finite() && max > 0.0) {
        return None;
    }
    let n: usize = 181;
    let step = 2.0 * max / (n - 1) as f64;
    let (bi, _) = (0..n).map(|i| (i, resid(-max + step * i as f64))).min_by(|a, b| a.1.total_cmp(&b.1))?;
    let (mut a, mut b) = (-max + step * bi.saturating_sub(1) as f64, (-max + step * (bi + 1) as f64).min(max));
    let g = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..80 {
        let c = b - g * (b - a);
        let d = a + g * (b - a);
        if resid(c) < resid(d) { b = d } else { a = c }
    }
    let d = 0.5 * (a + b);
    Some((d, resid(d)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn odo(x: f64, y: f64, theta: f64, t_ms: u64) -> Odometry {
        Odometry { x, y, theta, v: 0.0, omega: 0.0, stamp_ns: t_ms * 1_000_000 }
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn dead_reckoning_from_increments_in_the_world_frame() {
        // the motor starts at its origin; the robot at (-4, 0) facing +y
        let mut dr = DeadReckoning::new(Pose { x: -4.0, y: 0.0, theta: PI / 2.0 }, Settings::default());
        assert_eq!(dr.on_odometry(&odo(0.0, 0.0, 0.0, 0), "motor"), Ok(Step::First));
        for i in 1..=10 {
            assert_eq!(dr.on_odometry(&odo(0.1 * i as f64, 0.0, 0.0, i * 100), "motor"), Ok(Step::Moved));
        }
        // turn left 90° on the spot, then 1 m
        for i in 1..=9 {
            dr.on_odometry(&odo(1.0, 0.0, 0.1745329 * i as f64, 1000 + i * 100), "motor").unwrap();
        }
        dr.on_odometry(&odo(1.0, 0.0, PI / 2.0, 2000), "motor").unwrap();
        for i in 1..=10 {
            dr.on_odometry(&odo(1.0, 0.1 * i as f64, PI / 2.0, 2000 + i * 100), "motor").unwrap();
        }
        let p = dr.pose();
        assert!(close(p.x, -5.0, 1e-9) && close(p.y, 1.0, 1e-9) && close(p.theta, PI, 1e-6), "{p:?}");
        let e = dr.estimate();
        assert_eq!((e.corrections, e.source()), (0, Some(PoseSource::DeadReckoning)));
    }

    #[test]
    fn a_restarted_motor_is_a_reset_not_a_jump_and_stale_reports_are_ignored() {
        let mut dr = DeadReckoning::new(Pose::default(), Settings::default());
        dr.on_odometry(&odo(5.0, 5.0, 1.0, 0), "motor").unwrap();
        dr.on_odometry(&odo(5.1, 5.0, 1.0, 100), "motor").unwrap();
        let before = dr.pose();
        // the motor agent restarted: its odometry is back at its origin
        assert!(matches!(dr.on_odometry(&odo(0.0, 0.0, 0.0, 200), "motor"), Ok(Step::Reset { .. })));
        assert_eq!(dr.pose(), before);
        assert_eq!(dr.resets(), 1);
        dr.on_odometry(&odo(0.1, 0.0, 0.0, 300), "motor").unwrap();
        assert!(close((dr.pose().x - before.x).hypot(dr.pose().y - before.y), 0.1, 1e-9));
        assert_eq!(dr.on_odometry(&odo(9.0, 9.0, 0.0, 250), "motor"), Ok(Step::Stale));
        assert!(dr.on_odometry(&odo(f64::NAN, 0.0, 0.0, 400), "motor").is_err());
    }

    #[test]
    fn a_late_correction_carries_the_motion_since_over() {
        let mut dr = DeadReckoning::new(Pose::default(), Settings::default());
        for i in 0..=20 {
            dr.on_odometry(&odo(0.1 * i as f64, 0.0, 0.0, i * 100), "motor").unwrap();
        }
        // at t = 1 s the estimate said (1, 0); the checkpoint says it was at (1.2, 0.3)
        let c = PoseCorrection {
            x: 1.2,
            y: 0.3,
            theta: 0.0,
            stamp_ns: 1_000_000_000,
            fields: CORRECTS_POSITION,
            checkpoint_id: 1,
            ..Default::default()
        };
        let a = dr.apply_correction(&c, "checkpoint").unwrap();
        assert!(close(a.jump_m, 0.2f64.hypot(0.3), 1e-9) && !a.heading_from_two);
        // the 1 m travelled since is kept
        let p = dr.pose();
        assert!(close(p.x, 2.2, 1e-9) && close(p.y, 0.3, 1e-9), "{p:?}");
        let e = dr.estimate();
        assert_eq!((e.corrections, e.last_checkpoint, e.source()), (1, 1, Some(PoseSource::Checkpoint)));
        // too far, too old, nonsense
        let far = PoseCorrection { x: 50.0, stamp_ns: 2_000_000_000, ..c };
        assert!(matches!(dr.apply_correction(&far, "checkpoint"), Err(OdomError::TooFar { .. })));
        let old = PoseCorrection { stamp_ns: 1, ..c };
        for i in 21..=60 {
            dr.on_odometry(&odo(0.1 * i as f64, 0.0, 0.0, i * 100), "motor").unwrap();
        }
        assert!(matches!(dr.apply_correction(&old, "checkpoint"), Err(OdomError::TooOld { .. })));
        assert!(dr.apply_correction(&PoseCorrection { x: f64::NAN, ..c }, "x").is_err());
        assert_eq!(dr.corrections(), 1);
        let fresh = DeadReckoning::new(Pose::default(), Settings::default()).apply_correction(&c, "c");
        assert_eq!(fresh, Err(OdomError::NoOdometry));
    }

    /// A robot drives straight along y = 0 past checkpoints at (1.2, 1.2)
    /// and (6, 1.2); its odometry turns its heading by a bias. The
    /// checkpoint sensor corrects the position only (as `nerve-checkpoint`
    /// does when the heading is inside the IR cone); the second checkpoint
    /// gives the heading back.
    #[test]
    fn two_checkpoints_give_the_heading_back() {
        let bias = 6f64.to_radians(); // the odometry believes it heads 6° left of the truth
        let mut dr = DeadReckoning::new(Pose { x: 0.0, y: 0.0, theta: bias }, Settings::default());
        let cps = [(1, (1.2, 1.2)), (2, (6.0, 1.2))];
        let mut t = 0u64;
        // raw odometry: straight along its own x (the motor's frame)
        let mut corrected_at = Vec::new();
        for i in 0..=80 {
            let x = 0.1 * i as f64; // true position (x, 0), heading 0
            t = i * 100;
            dr.on_odometry(&odo(x, 0.0, 0.0, t), "motor").unwrap();
            for (id, cp) in cps {
                if (x - (cp.0 - 1.0)).abs() < 0.05 {
                    // the robot sees the checkpoint 1 m ahead of it: truth range and bearing
                    let (dx, dy) = (cp.0 - x, cp.1);
                    let (range, bearing) = (dx.hypot(dy), dy.atan2(dx));
                    let est = dr.pose();
                    let phi = est.theta + bearing + PI;
                    let c = PoseCorrection {
                        x: cp.0 + range * phi.cos(),
                        y: cp.1 + range * phi.sin(),
                        theta: est.theta,
                        checkpoint_x: cp.0,
                        checkpoint_y: cp.1,
                        stamp_ns: t * 1_000_000,
                        range_m: range as f32,
                        bearing_rad: bearing as f32,
                        fields: CORRECTS_POSITION,
                        source: PoseSource::Checkpoint as u8,
                        checkpoint_id: id,
                        reserved: [0; 5],
                    };
                    corrected_at.push((id, dr.apply_correction(&c, "checkpoint").unwrap(), x));
                }
            }
        }
        assert_eq!(corrected_at.len(), 2, "{corrected_at:?}");
        assert!(!corrected_at[0].1.heading_from_two);
        assert!(corrected_at[1].1.heading_from_two, "{corrected_at:?}");
        let p = dr.pose();
        // heading back to the truth (within the f32 of the payload), position on the line
        assert!(close(p.theta, 0.0, 0.5f64.to_radians()), "heading {}°", p.theta.to_degrees());
        assert!(close(p.x, 8.0, 0.05) && close(p.y, 0.0, 0.05), "{p:?}");
        assert!(t > 0);
    }

    #[test]
    fn heading_from_two_finds_a_known_error() {
        // the leg was really along x for 4 m; the estimate believed 10° to the left
        let delta = -10f64.to_radians();
        let leg = (4.0 * (-delta).cos(), 4.0 * (-delta).sin());
        let (d, r) = heading_from_two((0.0, 0.0), leg, -delta, (5.0, 1.0), 2f64.sqrt(), PI / 4.0, 0.6).unwrap();
        assert!(close(d, delta, 1e-6) && r < 1e-6, "{d} {r}");
        assert_eq!(heading_from_two((0.0, 0.0), leg, 0.0, (5.0, 1.0), 1.0, 0.0, f64::NAN), None);
    }
}
