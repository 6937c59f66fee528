//! `target`: robot 2's target-achieving agent (thesis section 4.3.2.3,
//! Fig. 4-9). Periodic (default 50 ms).
//!
//! Inputs:
//! * `pose` (`nerve::PoseEstimate`): the odometry agent's `pose`;
//! * `path` (`nerve::ViaPath`, a sequence of via points of any length): robot
//!   1's map builder's `path`, through the bridge;
//! * `mission_in` (`nerve::MissionCommand`): `come` (follow path N; needs
//!   that path), `abort` (stop), through the bridge;
//! * `sighting` (`nerve::CheckpointSighting`, optional): robot 2's own
//!   checkpoint sensor; on the last two legs a sighting of the target within
//!   `target_shift_m` (1.0) of the path's target moves the target there —
//!   robot 2 then drives to the target it sees, not to where robot 1's
//!   odometry placed it.
//!
//! Outputs:
//! * `cmd` (`nerve::VelocityCommand`): to the motor's `cmd` while following
//!   and for a second after arriving (zero), nothing otherwise;
//! * `mission` (`nerve::MissionCommand`): `via-reached` for each via point,
//!   `arrived` at the last one (repeated every `report_ms` until a new path
//!   comes) — to robot 1 through the bridge, and to robot 2's decision maker
//!   (grasp).
//!
//! The algorithm is the library `nerve_target`. Parameters: `v_cruise`
//! (0.3 m/s), `rotate_above_deg` (10), `deadband_deg` (1), `reach_m` (0.25),
//! `standoff_m` (0.35), `auto_start` (false: wait for `come`), `report_ms`
//! (2000), `look_at_checkpoints` (true: at a checkpoint's via point, face
//! the checkpoint until the odometry reports its correction), `look_timeout_s`
//! (6).

use agent_sdk::params::positive;
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, SeqInput, Setup, Task};
use nerve_target::{Event, Follower, Phase, Pose, Settings};
use shm_schemas::payloads::{
    CheckpointSighting, MissionCode, MissionCommand, PoseEstimate, VelocityCommand, ViaPathBuf, ViaPathHeader, ViaPoint,
};
use std::time::Duration;

/// A pose older than this is not followed: the robot stops, ns.
const POSE_FRESH_NS: u64 = 500_000_000;
/// Zero commands are sent this long after arriving, ns.
const HOLD_AFTER_ARRIVAL_NS: u64 = 1_000_000_000;

struct Target {
    pose: Input<PoseEstimate>,
    path: SeqInput<ViaPoint, ViaPathHeader>,
    mission_in: Input<MissionCommand>,
    sighting: Input<CheckpointSighting>,
    target_shift_m: Param<f64>,
    cmd: Output<VelocityCommand>,
    mission: Output<MissionCommand>,
    v_cruise: Param<f64>,
    rotate_above_deg: Param<f64>,
    deadband_deg: Param<f64>,
    reach_m: Param<f64>,
    standoff_m: Param<f64>,
    auto_start: Param<bool>,
    report_ms: Param<u64>,
    look: Param<bool>,
    look_timeout_s: Param<f64>,
    follower: Follower,
    corrections_seen: Option<u32>,
    latest_path: Option<ViaPathBuf>,
    come_for: Option<u32>,
    finished: Option<u32>,
    last_pose: Option<PoseEstimate>,
    arrived_at: Option<(u64, u64, usize)>,
    last_step_ns: Option<u64>,
    blind: bool,
}

fn in_range(lo: f64, hi: f64) -> impl Fn(&f64) -> Result<(), String> + Send + Sync + 'static {
    move |v| if (lo..=hi).contains(v) { Ok(()) } else { Err(format!("{v} is outside {lo} … {hi}")) }
}

impl Target {
    fn settings(&self) -> Settings {
        Settings {
            v_cruise: self.v_cruise.get(),
            rotate_above: self.rotate_above_deg.get().to_radians(),
            deadband: self.deadband_deg.get().to_radians(),
            reach_m: self.reach_m.get(),
            standoff_m: self.standoff_m.get(),
            look_at_checkpoints: self.look.get(),
            look_timeout_s: self.look_timeout_s.get(),
            ..Settings::default()
        }
    }

    fn report(&self, code: MissionCode, index: usize, now: u64) -> Result<(), AgentError> {
        let mut m = MissionCommand::new(code, self.follower.path_id(), now);
        m.index = index as u32;
        if let Some(p) = self.last_pose {
            (m.x, m.y) = (p.x, p.y);
        }
        self.mission.send(m)?;
        Ok(())
    }

    fn start_if_asked(&mut self) {
        let Some(path) = self.latest_path.clone() else { return };
        let id = path.path_id();
        let asked = self.auto_start.get() || self.come_for == Some(id);
        let new = self.follower.path_id() != id && self.finished != Some(id);
        if !(asked && new) {
            return;
        }
        match self.follower.follow(&path) {
            Ok(()) => {
                let pts: Vec<String> = self
                    .follower
                    .points()
                    .iter()
                    .map(|p| format!("({:.2}, {:.2}) {}", p.x, p.y, p.kind.name()))
                    .collect();
                tracing::info!(path = id, points = pts.len(), "following: {}", pts.join(" -> "));
                self.arrived_at = None;
            }
            Err(e) => tracing::warn!(path = id, "refused: {e}"),
        }
    }
}

impl Agent for Target {
    const KIND: &'static str = "target";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(50))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let d = Settings::default();
        Ok(Target {
            pose: setup.input("pose")?,
            path: setup.input_seq("path")?,
            mission_in: setup.input("mission_in")?,
            sighting: setup.input("sighting")?,
            target_shift_m: setup.param_checked("target_shift_m", 1.0, in_range(0.0, 5.0)),
            cmd: setup.output("cmd")?,
            mission: setup.output("mission")?,
            v_cruise: setup.param_checked("v_cruise", d.v_cruise, in_range(0.01, 0.6)),
            rotate_above_deg: setup.param_checked("rotate_above_deg", 10.0, in_range(1.0, 90.0)),
            deadband_deg: setup.param_checked("deadband_deg", 1.0, in_range(0.0, 10.0)),
            reach_m: setup.param_checked("reach_m", d.reach_m, positive),
            standoff_m: setup.param_checked("standoff_m", d.standoff_m, in_range(0.0, 2.0)),
            auto_start: setup.param("auto_start", false),
            report_ms: setup.param_checked("report_ms", 2000u64, |v| {
                if *v >= 100 { Ok(()) } else { Err("report_ms is at least 100".into()) }
            }),
            look: setup.param("look_at_checkpoints", d.look_at_checkpoints),
            look_timeout_s: setup.param_checked("look_timeout_s", d.look_timeout_s, in_range(0.0, 60.0)),
            follower: Follower::new(d),
            corrections_seen: None,
            latest_path: None,
            come_for: None,
            finished: None,
            last_pose: None,
            arrived_at: None,
            last_step_ns: None,
            blind: false,
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let dt = self.last_step_ns.map_or(0.05, |t| (now.saturating_sub(t) as f64 / 1e9).clamp(0.0, 0.2));
        self.last_step_ns = Some(now);
        self.follower.set_settings(self.settings());
        if let Some((_, p)) = self.pose.latest() {
            // a new correction by a checkpoint ends a look at it
            if self.corrections_seen.is_some_and(|n| p.corrections > n) {
                self.follower.correction_seen(p.last_checkpoint);
            }
            self.corrections_seen = Some(p.corrections);
            self.last_pose = Some(p);
        }
        let mut paths = Vec::new();
        self.path.drain(|_, h, pts| paths.push(ViaPathBuf::of(h, pts)));
        for p in paths {
            if self.latest_path.as_ref().is_none_or(|l| l.path_id() != p.path_id()) {
                tracing::info!(path = p.path_id(), points = p.points.len(), "path received");
            }
            self.latest_path = Some(p);
        }
        let mut orders = Vec::new();
        self.mission_in.drain(|m, c| orders.push((m.sender.to_string(), *c)));
        for (sender, o) in orders {
            match o.code() {
                Some(MissionCode::Come) => {
                    if self.come_for != Some(o.path_id) {
                        tracing::info!(path = o.path_id, %sender, "come");
                    }
                    self.come_for = Some(o.path_id);
                }
                Some(MissionCode::Abort) => {
                    tracing::info!(%sender, "abort: stop following");
                    self.follower.abort();
                    self.come_for = None;
                    self.cmd.send(VelocityCommand { v: 0.0, omega: 0.0, stamp_ns: now })?;
                }
                Some(c) => tracing::debug!(code = c.name(), %sender, "mission message not for the target achiever"),
                None => tracing::warn!(code = o.code, %sender, "mission message of unknown code; ignored"),
            }
        }
        self.start_if_asked();
        let mut seen = Vec::new();
        self.sighting.drain(|_, s| {
            if s.is_target == 1 && s.from_camera == 1 {
                seen.push((s.x, s.y));
            }
        });
        for (x, y) in seen {
            if self.follower.target_seen(x, y, self.target_shift_m.get()) {
                tracing::debug!(x, y, "the target as robot 2 sees it");
            }
        }

        match self.follower.phase() {
            Phase::Idle => Ok(()),
            Phase::Arrived => {
                if let Some((at, last_report, index)) = self.arrived_at {
                    if now.saturating_sub(at) <= HOLD_AFTER_ARRIVAL_NS {
                        self.cmd.send(VelocityCommand { v: 0.0, omega: 0.0, stamp_ns: now })?;
                    }
                    if now.saturating_sub(last_report) >= self.report_ms.get().saturating_mul(1_000_000) {
                        self.report(MissionCode::Arrived, index, now)?;
                        self.arrived_at = Some((at, now, index));
                    }
                }
                Ok(())
            }
            Phase::Rotating | Phase::Driving | Phase::Looking => {
                let fresh = self.last_pose.filter(|p| {
                    now.saturating_sub(p.stamp_ns) <= POSE_FRESH_NS && p.x.is_finite() && p.theta.is_finite()
                });
                let Some(p) = fresh else {
                    if !self.blind {
                        tracing::warn!("no fresh pose: stopped; connect odometry/pose target/pose");
                        self.blind = true;
                    }
                    self.cmd.send(VelocityCommand { v: 0.0, omega: 0.0, stamp_ns: now })?;
                    return Ok(());
                };
                if self.blind {
                    tracing::info!("pose back: following again");
                    self.blind = false;
                }
                let s = self.follower.step(&Pose { x: p.x, y: p.y, theta: p.theta }, dt);
                for e in &s.events {
                    match *e {
                        Event::Reached { index, distance_m } => {
                            tracing::info!(
                                path = self.follower.path_id(),
                                index,
                                distance_m,
                                x = p.x,
                                y = p.y,
                                "via point reached"
                            );
                            self.report(MissionCode::ViaReached, index, now)?;
                        }
                        Event::Arrived { index, distance_m } => {
                            tracing::info!(
                                path = self.follower.path_id(),
                                index,
                                distance_m,
                                x = p.x,
                                y = p.y,
                                "arrived"
                            );
                            self.report(MissionCode::Arrived, index, now)?;
                            self.arrived_at = Some((now, now, index));
                            self.finished = Some(self.follower.path_id());
                        }
                    }
                }
                self.cmd.send(VelocityCommand { v: s.v, omega: s.omega, stamp_ns: now })?;
                Ok(())
            }
        }
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Target>()
}

#[cfg(test)]
mod tests {
    //! The agent's glue, through the SDK's harness: inputs to `cmd` and
    //! `mission` through `step`, `come` and `abort`, a stale pose, a
    //! parameter and a refusal. The follower itself is tested in the library.

    use super::*;
    use agent_sdk::testing::Harness;
    use shm_schemas::payloads::ViaKind;

    /// One waypoint at (1, 0), then the target at (3, 0).
    fn path(id: u32) -> Vec<u8> {
        let mut p = ViaPathBuf::new(id, 0);
        p.points.push(ViaPoint::new([1.0, 0.0], ViaKind::Waypoint, 0, [1.0, 0.0]));
        p.points.push(ViaPoint::new([3.0, 0.0], ViaKind::Target, 0, [3.0, 0.0]));
        p.to_bytes()
    }

    fn pose(x: f64, stamp_ns: u64) -> PoseEstimate {
        PoseEstimate { x, stamp_ns, ..Default::default() }
    }

    fn last_cmd(h: &mut Harness<Target>) -> Option<VelocityCommand> {
        h.output::<VelocityCommand>("cmd").expect("cmd").last().copied()
    }

    #[test]
    fn a_path_is_followed_only_when_asked_and_stopped_on_abort() {
        let mut h = Harness::<Target>::new().expect("the target agent starts");
        h.send_bytes_from("path", "test", &path(7)).expect("path");
        h.send("pose", pose(0.0, h.now_ns())).expect("pose");
        h.step().expect("step");
        assert_eq!(last_cmd(&mut h), None, "a path alone is not followed (auto_start is off)");

        // `come` for another path: still nothing
        h.send("mission_in", MissionCommand::new(MissionCode::Come, 8, 0)).expect("come");
        h.step().expect("step");
        assert_eq!(last_cmd(&mut h), None);

        h.send("mission_in", MissionCommand::new(MissionCode::Come, 7, 0)).expect("come");
        h.send("pose", pose(0.0, h.now_ns())).expect("pose");
        h.step().expect("step");
        let c = last_cmd(&mut h).expect("following: a command each step");
        assert!(c.v > 0.0 && c.v <= 0.3 + 1e-9, "drives ahead at most v_cruise: {c:?}");

        // the via point is reached: reported on `mission` with its index
        h.send("pose", pose(0.95, h.now_ns())).expect("pose");
        h.step().expect("step");
        let m = h.output::<MissionCommand>("mission").expect("mission");
        assert!(m.iter().any(|m| m.code() == Some(MissionCode::ViaReached) && m.path_id == 7 && m.index == 0), "{m:?}");

        h.send("mission_in", MissionCommand::new(MissionCode::Abort, 7, 0)).expect("abort");
        h.step().expect("step");
        let c = last_cmd(&mut h).expect("a stop on abort");
        assert_eq!((c.v, c.omega), (0.0, 0.0));
        h.step().expect("step");
        assert_eq!(last_cmd(&mut h), None, "idle after the abort: nothing more is sent");
    }

    #[test]
    fn a_stale_pose_stops_the_robot_and_v_cruise_is_a_checked_parameter() {
        let mut h = Harness::<Target>::builder()
            .param("auto_start", "true")
            .param("v_cruise", "0.2")
            .start()
            .expect("the target agent starts");
        h.send_bytes_from("path", "test", &path(1)).expect("path");
        h.send("pose", pose(0.0, h.now_ns())).expect("pose");
        h.step().expect("step");
        let c = last_cmd(&mut h).expect("auto_start follows at once");
        assert!(c.v > 0.0 && c.v <= 0.2 + 1e-9, "at most the v_cruise set: {c:?}");

        // no pose for longer than 500 ms: stopped
        h.advance(Duration::from_millis(600)).expect("steps without a pose");
        let c = last_cmd(&mut h).expect("a stop");
        assert_eq!((c.v, c.omega), (0.0, 0.0), "no fresh pose: stopped");

        let e = h.set_param("v_cruise", "5").expect_err("too fast");
        assert!(e.contains("outside"), "{e}");
        assert_eq!(h.param("v_cruise").as_deref(), Ok("0.2"), "the refused value is not taken");
    }
}
