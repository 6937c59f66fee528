//! H2's arm at the target (thesis section 4.3.2.3: "when robot 2 arrives
//! the final target, it will give its control to the external control
//! module to execute a special actuation function, for example, grasping")
//! as a library: the arm's kinematics, locating the target with the arm's
//! proximity sensor, and the grasp as a pure state machine.
//!
//! **Why probe.** The target achiever stops a stand-off short of where it
//! *believes* the target is; its pose has the odometry's error, and the
//! gripper's tip with the arm stretched lies 0.5 m ahead, past the tube. A
//! grasp holds a tube only within 0.1 m of the tip (docs/devices.md). So the
//! arm does not trust the guess: the board reports the distance from the
//! tip to the nearest target's axis (`GraspState.nearest_mm`); the arm moves
//! its tip to three points around the guess, reads the distance at each,
//! and [`locate`]s the axis where the three circles meet. Then it
//! [`reach`]es there (inverse kinematics), closes, and reports holding or
//! missed.
//!
//! [`Grasper`], the state machine: `open` → (request) → **opening** (the
//! gripper opens fully) → **probing** ×3 (move the tip, wait until the
//! joints settle, take the next distance) → **reaching** → **closing** →
//! `holding` | `missed` (with a [`GraspMiss`] reason). Every phase has a
//! deadline; a board that vanishes ends a grasp as missed. It takes the
//! board's reports and a clock, and answers with [`Command`]s for the board:
//! no I/O, so every path is unit-tested below.

#![cfg_attr(test, allow(clippy::unwrap_used))]

use shm_schemas::payloads::{GraspMiss, GraspPhase};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_3};

/// The arm's geometry as seen from above (docs/devices.md, "Arm"): the
/// shoulder `base` metres ahead of the robot's centre, the upper arm
/// turning by the shoulder angle from the forward axis, the forearm by the
/// elbow angle from the upper arm, the tip at the forearm's end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// Shoulder ahead of the robot's centre, metres.
    pub base: f64,
    /// Upper arm and forearm, metres.
    pub links: [f64; 2],
    /// Joint limits (min, max) of shoulder, elbow, gripper, radians.
    pub limits: [(f64, f64); 3],
    /// A tube within this of the tip is held when the gripper closes, metres.
    pub grasp_tolerance: f64,
}

impl Geometry {
    /// H2's arm (docs/devices.md): shoulder 0.15 m ahead, links 0.20 and
    /// 0.15 m, shoulder ±90°, elbow ±120°, gripper 0 … 60°, 0.1 m tolerance.
    pub const H2: Geometry = Geometry {
        base: 0.15,
        links: [0.20, 0.15],
        limits: [(-FRAC_PI_2, FRAC_PI_2), (-2.0 * FRAC_PI_3, 2.0 * FRAC_PI_3), (0.0, FRAC_PI_3)],
        grasp_tolerance: 0.1,
    };

    /// The gripper fully open, radians.
    pub fn gripper_open(&self) -> f64 {
        self.limits[2].1
    }

    /// Where the tip is, robot frame (x forward, y left), for shoulder and
    /// elbow angles.
    pub fn tip(&self, shoulder: f64, elbow: f64) -> (f64, f64) {
        let (a, b) = (shoulder, shoulder + elbow);
        (
            self.base + self.links[0] * a.cos() + self.links[1] * b.cos(),
            self.links[0] * a.sin() + self.links[1] * b.sin(),
        )
    }
}

/// The shoulder and elbow angles that put the tip at `(x, y)` (robot
/// frame), within the joint limits; of the two solutions the one with the
/// smaller shoulder angle. `None` when the point is out of reach.
pub fn reach(g: &Geometry, x: f64, y: f64) -> Option<(f64, f64)> {
    if !(x.is_finite() && y.is_finite()) {
        return None;
    }
    let (l1, l2) = (g.links[0], g.links[1]);
    let (dx, dy) = (x - g.base, y);
    let r2 = dx * dx + dy * dy;
    let c = (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
    if !(-1.0 - 1e-9..=1.0 + 1e-9).contains(&c) {
        return None;
    }
    let b0 = c.clamp(-1.0, 1.0).acos();
    let within = |v: f64, (lo, hi): (f64, f64)| v >= lo - 1e-9 && v <= hi + 1e-9;
    [b0, -b0]
        .into_iter()
        .map(|b| (dy.atan2(dx) - (l2 * b.sin()).atan2(l1 + l2 * b.cos()), b))
        .filter(|&(a, b)| within(a, g.limits[0]) && within(b, g.limits[1]))
        .min_by(|p, q| p.0.abs().total_cmp(&q.0.abs()))
}

/// Where a point lies whose distances from three or more points are known
/// (`(x, y, distance)`): the least-squares solution of the linear equations
/// left by subtracting the first circle from the others. `None` for fewer
/// than three points, points (nearly) on a line, or non-finite values.
pub fn locate(probes: &[(f64, f64, f64)]) -> Option<(f64, f64)> {
    if probes.len() < 3 || probes.iter().any(|p| !(p.0.is_finite() && p.1.is_finite() && p.2.is_finite())) {
        return None;
    }
    let (x0, y0, d0) = probes[0];
    // rows: 2(xi − x0)·cx + 2(yi − y0)·cy = (xi² + yi² − di²) − (x0² + y0² − d0²)
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(x, y, d) in &probes[1..] {
        let (u, v) = (2.0 * (x - x0), 2.0 * (y - y0));
        let w = (x * x + y * y - d * d) - (x0 * x0 + y0 * y0 - d0 * d0);
        a11 += u * u;
        a12 += u * v;
        a22 += v * v;
        b1 += u * w;
        b2 += v * w;
    }
    let det = a11 * a22 - a12 * a12;
    // the normal equations of points spread by a few cm have det ~1e-4;
    // collinear points give ~0
    if det.abs() < 1e-10 * (a11 + a22).max(1e-12).powi(2) || det.abs() < 1e-14 {
        return None;
    }
    Some(((a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det))
}

/// Settings of a [`Grasper`] (the agent's parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// The arm.
    pub geometry: Geometry,
    /// Where the target is assumed to be when a request gives no guess,
    /// robot frame, metres (the target achiever's stand-off straight ahead).
    pub default_guess: (f64, f64),
    /// How far around the guess the tip probes, metres.
    pub probe_m: f64,
    /// Joints within this of their set-point count as settled, radians.
    pub settle_rad: f64,
    /// Each phase must end within this, ns.
    pub phase_timeout_ns: u64,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            geometry: Geometry::H2,
            default_guess: (0.35, 0.0),
            probe_m: 0.06,
            settle_rad: 1.5f64.to_radians(),
            phase_timeout_ns: 4_000_000_000,
        }
    }
}

/// What the board's gripper says (its `GraspState.phase`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Gripper {
    /// Open, holding nothing.
    Open,
    /// Closing.
    Closing,
    /// Closed on the tube with this id.
    Holding(u8),
    /// Closed on nothing.
    Missed,
}

/// What the grasper asks of the board.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Joint set-points: shoulder, elbow, gripper, radians (`ArmCommand`).
    Joints([f64; 3]),
    /// Close the gripper on what is within reach (`GraspCommand` grasp).
    Close,
    /// Open the gripper fully and let go (`GraspCommand` release).
    Open,
}

/// The grasper's phase, with what it needs.
#[derive(Debug, Clone, PartialEq)]
enum Step {
    /// No grasp under way; the last outcome.
    Idle(Outcome),
    /// Waiting for the gripper to be open.
    Opening,
    /// Moving the tip to probe point `k`; `settled` once the joints are there.
    Probing { k: usize, points: [(f64, f64); 3], settled: bool },
    /// Moving the tip to the located target.
    Reaching { goal: (f64, f64) },
    /// The gripper closes.
    Closing,
    /// Release: the gripper opens and the arm folds back.
    Releasing,
}

/// How the last grasp ended (or the state before any).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Open, nothing held.
    Open,
    /// Holding the tube with this id.
    Holding(u8),
    /// Missed, and why.
    Missed(GraspMiss),
}

/// The grasp as a state machine; see the module documentation.
#[derive(Debug, Clone)]
pub struct Grasper {
    settings: Settings,
    step: Step,
    request_id: u32,
    guess: (f64, f64),
    deadline_ns: u64,
    joints: Option<[f64; 3]>,
    gripper: Option<Gripper>,
    /// Tip positions and the distances read there.
    readings: Vec<(f64, f64, f64)>,
    /// The located target, robot frame.
    located: Option<(f64, f64)>,
}

impl Grasper {
    /// An idle grasper.
    pub fn new(settings: Settings) -> Self {
        Grasper {
            settings,
            step: Step::Idle(Outcome::Open),
            request_id: 0,
            guess: settings.default_guess,
            deadline_ns: 0,
            joints: None,
            gripper: None,
            readings: Vec::new(),
            located: None,
        }
    }

    /// Changes the settings (a parameter changed); a grasp under way goes on.
    pub fn set_settings(&mut self, settings: Settings) {
        self.settings = settings;
    }

    /// The phase to report.
    pub fn phase(&self) -> GraspPhase {
        match self.step {
            Step::Idle(Outcome::Open) => GraspPhase::Open,
            Step::Idle(Outcome::Holding(_)) => GraspPhase::Holding,
            Step::Idle(Outcome::Missed(_)) => GraspPhase::Missed,
            Step::Opening | Step::Probing { .. } | Step::Reaching { .. } | Step::Releasing => GraspPhase::Moving,
            Step::Closing => GraspPhase::Closing,
        }
    }

    /// The outcome while idle, `None` while a grasp or release is under way.
    pub fn outcome(&self) -> Option<Outcome> {
        match self.step {
            Step::Idle(o) => Some(o),
            _ => None,
        }
    }

    /// The request the state belongs to (0: none yet).
    pub fn request_id(&self) -> u32 {
        self.request_id
    }

    /// Where the probes put the target (robot frame), once located.
    pub fn located(&self) -> Option<(f64, f64)> {
        self.located
    }

    /// A grasp request `id` with an optional guess of the target's position
    /// (robot frame). A request already taken (same id) is ignored, so a
    /// sender may repeat it; a new one cancels what is under way.
    pub fn grasp(&mut self, id: u32, guess: Option<(f64, f64)>, now_ns: u64) -> Vec<Command> {
        if id == self.request_id && id != 0 {
            return Vec::new();
        }
        self.request_id = id;
        self.guess = guess.filter(|g| g.0.is_finite() && g.1.is_finite()).unwrap_or(self.settings.default_guess);
        self.readings.clear();
        self.located = None;
        self.enter(Step::Opening, now_ns);
        vec![Command::Open]
    }

    /// A release request `id`: open, let go, fold the arm back.
    pub fn release(&mut self, id: u32, now_ns: u64) -> Vec<Command> {
        if id == self.request_id && id != 0 && matches!(self.step, Step::Releasing | Step::Idle(Outcome::Open)) {
            return Vec::new();
        }
        self.request_id = id;
        self.enter(Step::Releasing, now_ns);
        vec![Command::Open, Command::Joints([0.0, 0.0, self.settings.geometry.gripper_open()])]
    }

    /// The board's joint report (radians).
    pub fn on_joints(&mut self, joints: [f64; 3], now_ns: u64) -> Vec<Command> {
        self.joints = Some(joints);
        let open = self.settings.geometry.gripper_open();
        match self.step.clone() {
            Step::Probing { k, points, settled: false } if self.at(points[k]) => {
                self.step = Step::Probing { k, points, settled: true };
                Vec::new()
            }
            Step::Reaching { goal } if self.at(goal) => {
                self.enter(Step::Closing, now_ns);
                vec![Command::Close]
            }
            Step::Releasing if joints[2] >= open - self.settings.settle_rad && self.gripper == Some(Gripper::Open) => {
                self.enter(Step::Idle(Outcome::Open), now_ns);
                Vec::new()
            }
            _ => Vec::new(),
        }
    }

    /// The board's gripper report and proximity reading (metres; `None`
    /// when the board sees no target).
    pub fn on_gripper(&mut self, gripper: Gripper, nearest_m: Option<f64>, now_ns: u64) -> Vec<Command> {
        self.gripper = Some(gripper);
        let open = self.settings.geometry.gripper_open();
        match self.step.clone() {
            Step::Idle(Outcome::Open) => {
                // the board knows better (a grasp by hand, a restarted agent)
                if let Gripper::Holding(id) = gripper {
                    self.step = Step::Idle(Outcome::Holding(id));
                }
                Vec::new()
            }
            Step::Idle(Outcome::Holding(_)) if gripper == Gripper::Open => {
                self.step = Step::Idle(Outcome::Open);
                Vec::new()
            }
            Step::Opening => {
                let opened = self.joints.is_some_and(|j| j[2] >= open - self.settings.settle_rad);
                if gripper != Gripper::Open || !opened {
                    return Vec::new();
                }
                match self.probe_points() {
                    Some(points) => self.move_to_probe(0, points, now_ns),
                    None => self.miss(GraspMiss::OutOfReach, now_ns),
                }
            }
            Step::Probing { k, points, settled: true } => {
                let Some(d) = nearest_m else { return self.miss(GraspMiss::NoTarget, now_ns) };
                let Some(j) = self.joints else { return Vec::new() };
                let (tx, ty) = self.settings.geometry.tip(j[0], j[1]);
                self.readings.push((tx, ty, d));
                if k + 1 < points.len() {
                    return self.move_to_probe(k + 1, points, now_ns);
                }
                let Some(target) = locate(&self.readings) else {
                    return self.miss(GraspMiss::OutOfReach, now_ns);
                };
                self.located = Some(target);
                match reach(&self.settings.geometry, target.0, target.1) {
                    Some((a, b)) => {
                        self.enter(Step::Reaching { goal: target }, now_ns);
                        vec![Command::Joints([a, b, open])]
                    }
                    None => self.miss(GraspMiss::OutOfReach, now_ns),
                }
            }
            Step::Closing => match gripper {
                Gripper::Holding(id) => {
                    self.enter(Step::Idle(Outcome::Holding(id)), now_ns);
                    Vec::new()
                }
                Gripper::Missed => self.miss(GraspMiss::ClosedEmpty, now_ns),
                Gripper::Open | Gripper::Closing => Vec::new(),
            },
            _ => Vec::new(),
        }
    }

    /// The board vanished: a grasp under way is missed.
    pub fn on_device_lost(&mut self, now_ns: u64) -> Vec<Command> {
        self.joints = None;
        self.gripper = None;
        match self.step {
            Step::Idle(_) => Vec::new(),
            Step::Releasing => {
                self.enter(Step::Idle(Outcome::Open), now_ns);
                Vec::new()
            }
            _ => self.miss(GraspMiss::DeviceLost, now_ns),
        }
    }

    /// The clock: a phase past its deadline ends the grasp as missed.
    pub fn tick(&mut self, now_ns: u64) -> Vec<Command> {
        if matches!(self.step, Step::Idle(_)) || now_ns < self.deadline_ns {
            return Vec::new();
        }
        if self.step == Step::Releasing {
            self.enter(Step::Idle(Outcome::Open), now_ns);
            return Vec::new();
        }
        self.miss(GraspMiss::Timeout, now_ns)
    }

    fn enter(&mut self, step: Step, now_ns: u64) {
        self.step = step;
        self.deadline_ns = now_ns.saturating_add(self.settings.phase_timeout_ns);
    }

    fn miss(&mut self, why: GraspMiss, now_ns: u64) -> Vec<Command> {
        self.enter(Step::Idle(Outcome::Missed(why)), now_ns);
        Vec::new()
    }

    /// Whether the measured joints put the tip at `p` (within the settle angle).
    fn at(&self, p: (f64, f64)) -> bool {
        let (Some(j), Some((a, b))) = (self.joints, reach(&self.settings.geometry, p.0, p.1)) else { return false };
        (j[0] - a).abs() <= self.settings.settle_rad && (j[1] - b).abs() <= self.settings.settle_rad
    }

    /// Three reachable points around the guess, not on a line: ahead of
    /// it, left and right of it (moved toward the middle of the arm's
    /// reach, a ring around the shoulder, when one of them is not reachable).
    fn probe_points(&self) -> Option<[(f64, f64); 3]> {
        let g = &self.settings.geometry;
        let p = self.settings.probe_m;
        let around = |c: (f64, f64)| [(c.0 + p, c.1), (c.0, c.1 + p), (c.0, c.1 - p)];
        let ok = |pts: &[(f64, f64); 3]| pts.iter().all(|q| reach(g, q.0, q.1).is_some());
        let (l1, l2) = (g.links[0], g.links[1]);
        let r_min = (l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * g.limits[1].1.cos()).max(0.0).sqrt();
        let mid = (g.base + (r_min + l1 + l2) / 2.0, 0.0);
        let mut c = self.guess;
        for _ in 0..8 {
            let pts = around(c);
            if ok(&pts) {
                return Some(pts);
            }
            c = ((c.0 + mid.0) / 2.0, (c.1 + mid.1) / 2.0);
        }
        ok(&around(mid)).then(|| around(mid))
    }

    fn move_to_probe(&mut self, k: usize, points: [(f64, f64); 3], now_ns: u64) -> Vec<Command> {
        let open = self.settings.geometry.gripper_open();
        let Some((a, b)) = reach(&self.settings.geometry, points[k].0, points[k].1) else {
            return self.miss(GraspMiss::OutOfReach, now_ns);
        };
        self.enter(Step::Probing { k, points, settled: false }, now_ns);
        vec![Command::Joints([a, b, open])]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: Geometry = Geometry::H2;

    #[test]
    fn the_stretched_arm_reaches_half_a_metre() {
        let (x, y) = G.tip(0.0, 0.0);
        assert!((x - 0.5).abs() < 1e-12 && y.abs() < 1e-12);
        let (x, y) = G.tip(std::f64::consts::FRAC_PI_2, 0.0);
        assert!((x - 0.15).abs() < 1e-12 && (y - 0.35).abs() < 1e-12);
    }

    #[test]
    fn reach_inverts_tip_within_the_limits() {
        for &(x, y) in &[(0.35, 0.0), (0.45, 0.1), (0.3, -0.15), (0.25, 0.2), (0.5, 0.0), (0.41, 0.06)] {
            let (a, b) = reach(&G, x, y).unwrap_or_else(|| panic!("({x}, {y}) should be reachable"));
            let (tx, ty) = G.tip(a, b);
            assert!((tx - x).abs() < 1e-9 && (ty - y).abs() < 1e-9, "({x}, {y}) -> ({tx}, {ty})");
            assert!(a.abs() <= G.limits[0].1 + 1e-9 && b.abs() <= G.limits[1].1 + 1e-9);
        }
        assert_eq!(reach(&G, 0.7, 0.0), None, "beyond the stretched arm");
        assert_eq!(reach(&G, 0.15, 0.0), None, "at the shoulder: the elbow cannot fold that far");
        assert_eq!(reach(&G, 0.32, 0.0), None, "0.17 m from the shoulder: neither");
        assert_eq!(reach(&G, f64::NAN, 0.0), None);
    }

    #[test]
    fn locate_finds_the_point_three_distances_agree_on() {
        let c = (0.41, -0.07);
        let d = |x: f64, y: f64| ((x - c.0).powi(2) + (y - c.1).powi(2)).sqrt();
        let probes: Vec<_> = [(0.41, 0.0), (0.29, 0.06), (0.29, -0.06)].iter().map(|&(x, y)| (x, y, d(x, y))).collect();
        let (x, y) = locate(&probes).unwrap();
        assert!((x - c.0).abs() < 1e-9 && (y - c.1).abs() < 1e-9);
        // millimetre readings (the board's resolution) still land within a few mm
        let rounded: Vec<_> = probes.iter().map(|&(x, y, d)| (x, y, (d * 1000.0).round() / 1000.0)).collect();
        let (x, y) = locate(&rounded).unwrap();
        assert!((x - c.0).hypot(y - c.1) < 0.01);
        assert_eq!(locate(&probes[..2]), None, "two circles meet twice");
        assert_eq!(locate(&[(0.1, 0.0, 0.2), (0.2, 0.0, 0.1), (0.3, 0.0, 0.05)]), None, "collinear");
    }

    /// A simulated board: joints move instantly; the target is at `target`.
    struct Board {
        target: Option<(f64, f64)>,
        joints: [f64; 3],
        gripper: Gripper,
    }

    impl Board {
        fn nearest(&self) -> Option<f64> {
            let (x, y) = G.tip(self.joints[0], self.joints[1]);
            self.target.map(|t| (t.0 - x).hypot(t.1 - y))
        }
        fn apply(&mut self, cmds: &[Command]) {
            for c in cmds {
                match *c {
                    Command::Joints(j) => {
                        self.joints = j;
                        if j[2] > 0.0 && self.gripper != Gripper::Closing {
                            self.gripper = Gripper::Open;
                        }
                    }
                    Command::Open => {
                        self.joints[2] = G.gripper_open();
                        self.gripper = Gripper::Open;
                    }
                    Command::Close => {
                        self.joints[2] = 0.0;
                        self.gripper = match self.nearest() {
                            Some(d) if d <= G.grasp_tolerance => Gripper::Holding(9),
                            _ => Gripper::Missed,
                        };
                    }
                }
            }
        }
    }

    /// Runs the grasper against the board for `reports` 100 ms report cycles.
    fn run(g: &mut Grasper, b: &mut Board, mut t: u64, reports: usize) -> u64 {
        for _ in 0..reports {
            t += 100_000_000;
            let c = g.on_joints(b.joints, t);
            b.apply(&c);
            let n = b.nearest();
            let c = g.on_gripper(b.gripper, n, t);
            b.apply(&c);
            let c = g.tick(t);
            b.apply(&c);
        }
        t
    }

    #[test]
    fn a_target_off_the_guess_is_located_and_held() {
        let mut g = Grasper::new(Settings::default());
        // the robot stopped 0.35 m from where it believed the target was;
        // really it is 0.43 m ahead and 0.06 m to the right
        let mut b = Board { target: Some((0.43, -0.06)), joints: [0.0; 3], gripper: Gripper::Open };
        let c = g.grasp(1, Some((0.35, 0.0)), 0);
        assert_eq!(c, vec![Command::Open]);
        assert_eq!(g.phase(), GraspPhase::Moving);
        b.apply(&c);
        run(&mut g, &mut b, 0, 20);
        assert_eq!(g.outcome(), Some(Outcome::Holding(9)), "{g:?}");
        assert_eq!(g.phase(), GraspPhase::Holding);
        let (x, y) = g.located().unwrap();
        assert!((x - 0.43).abs() < 1e-6 && (y + 0.06).abs() < 1e-6);
        // the same request again changes nothing
        assert!(g.grasp(1, None, 3_000_000_000).is_empty());
        assert_eq!(g.phase(), GraspPhase::Holding);
    }

    #[test]
    fn without_probing_the_stretched_arm_would_miss() {
        // the premise of probing: the tip at rest is 0.15 m past a tube 0.35 m ahead
        let (x, _) = G.tip(0.0, 0.0);
        assert!((x - 0.35).abs() > G.grasp_tolerance);
    }

    #[test]
    fn a_target_out_of_reach_or_absent_is_missed_with_the_reason() {
        let mut g = Grasper::new(Settings::default());
        let mut b = Board { target: Some((1.2, 0.0)), joints: [0.0; 3], gripper: Gripper::Open };
        b.apply(&g.grasp(1, None, 0));
        run(&mut g, &mut b, 0, 20);
        assert_eq!(g.outcome(), Some(Outcome::Missed(GraspMiss::OutOfReach)));

        let mut b = Board { target: None, joints: [0.0; 3], gripper: Gripper::Open };
        b.apply(&g.grasp(2, None, 0));
        assert_eq!(g.request_id(), 2);
        run(&mut g, &mut b, 0, 20);
        assert_eq!(g.outcome(), Some(Outcome::Missed(GraspMiss::NoTarget)));
    }

    #[test]
    fn a_silent_board_times_out_and_a_lost_one_ends_the_grasp() {
        let mut g = Grasper::new(Settings::default());
        g.grasp(1, None, 0);
        assert!(g.tick(3_999_999_999).is_empty());
        assert_eq!(g.phase(), GraspPhase::Moving);
        g.tick(4_000_000_000);
        assert_eq!(g.outcome(), Some(Outcome::Missed(GraspMiss::Timeout)));

        g.grasp(2, None, 5_000_000_000);
        g.on_device_lost(5_100_000_000);
        assert_eq!(g.outcome(), Some(Outcome::Missed(GraspMiss::DeviceLost)));
    }

    #[test]
    fn closing_on_nothing_is_missed_and_release_opens_and_folds() {
        let mut g = Grasper::new(Settings::default());
        let mut b = Board { target: Some((0.40, 0.0)), joints: [0.0; 3], gripper: Gripper::Open };
        b.apply(&g.grasp(1, None, 0));
        // the tube is taken away while the arm reaches
        for _ in 0..4 {
            let t = 100_000_000;
            b.apply(&g.on_joints(b.joints, t));
            let n = b.nearest();
            b.apply(&g.on_gripper(b.gripper, n, t));
        }
        b.target = Some((5.0, 5.0));
        run(&mut g, &mut b, 0, 20);
        assert_eq!(g.outcome(), Some(Outcome::Missed(GraspMiss::ClosedEmpty)), "{g:?}");

        let c = g.release(2, 10_000_000_000);
        assert_eq!(c, vec![Command::Open, Command::Joints([0.0, 0.0, G.gripper_open()])]);
        b.apply(&c);
        run(&mut g, &mut b, 10_000_000_000, 2);
        assert_eq!(g.outcome(), Some(Outcome::Open));
    }

    #[test]
    fn an_idle_grasper_follows_what_the_board_holds() {
        let mut g = Grasper::new(Settings::default());
        g.on_gripper(Gripper::Holding(4), Some(0.02), 0);
        assert_eq!(g.outcome(), Some(Outcome::Holding(4)));
        g.on_gripper(Gripper::Open, Some(0.3), 0);
        assert_eq!(g.outcome(), Some(Outcome::Open));
    }

    #[test]
    fn probe_points_stay_reachable_for_a_far_guess() {
        let mut g = Grasper::new(Settings::default());
        g.grasp(1, Some((0.9, 0.4)), 0);
        let pts = g.probe_points().unwrap();
        assert!(pts.iter().all(|p| reach(&G, p.0, p.1).is_some()));
    }
}
