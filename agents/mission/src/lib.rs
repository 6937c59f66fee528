//! The command sender and receiver of the cooperation experiment (thesis
//! section 4.3.2, Fig. 4-8 and 4-9) as a library: one pure state machine
//! per robot, fed with what arrives and a clock, answering with what to
//! send. The agent (`src/main.rs`) only moves samples.
//!
//! Robot 1, the **explorer** ([`Explorer`]): "when the target is found, …
//! the decision maker will launch the command sender and ask the robot 2 to
//! come for the target. It will then wait for the arrival of robot 2. If
//! robot 2 finds the target, the command receiver will get the response
//! from robot 2 and resume exploring the area."
//!
//! ```text
//! exploring ──map builder's path──> found ──decision maker in `wait`: plan──> sent ──"arrived"──> done
//!   (target: none)                 (target: close: stop)   path + "come",     "resume" to robot 2
//!                                                          again every resend  (target: none: explore)
//! ```
//!
//! **Robot 2's path comes from the map builder's `plan` call** (issue 42).
//! The map builder's path says that the target is found and holds its
//! landmarks: the confirmed checkpoints' via points, the target's approach
//! and the target. Once the robot has stopped, the explorer asks `plan` for
//! a path from robot 1 to where robot 2 is ([`Explorer::plan_goal`]): the
//! position robot 2 last reported ("arrived" carries where it believed it
//! was), else the `peer_start` the launch file gives (robot 2 says nothing
//! before its first path). The answer, turned round and ended with the
//! target's approach and the target ([`assemble::from_plan`]), is what goes
//! to robot 2. The call never blocks a step: the agent sends it and takes
//! the answer at a later step ([`Explorer::on_plan`]). A call that fails
//! (no path, no answer in time, no server) is asked again after
//! [`PLAN_RETRY_NS`], at most [`PLAN_ATTEMPTS`] times; then the map
//! builder's own path (its via points and robot 1's way to the target,
//! which robot 2 has followed since before `plan` existed) goes out
//! instead, so that robot 2 still comes, and the agent says so in its log
//! and its `path_from` figure.
//!
//! Robot 2, the **executor** ([`Executor`]): "once the map data and the
//! command from robot 1 are received, the target-achieving agent will be
//! executed … When robot 2 arrives the final target, it will give its
//! control to the external control module to execute a special actuation
//! function, for example, grasping. Meanwhile, robot 2 will inform robot 1
//! to start exploration again."
//!
//! ```text
//! waiting ──path + "come"──> following ──target achiever: "arrived"──> grasping ──arm: holding/missed──> done
//!                            path + "come" to the target achiever      grasp request      "arrived" to robot 1,
//!                            "via-reached" forwarded to robot 1        (a path without    again every resend
//!                                                                       a target: no grasp) until robot 1's "resume"
//! ```
//!
//! **Over a link that fails.** The bridge carries these messages reliably,
//! but a bridge restarted mid-run loses what it held, and either agent may
//! be restarted. So each side repeats its last word every `resend` until
//! the other answers: robot 1 repeats the path and "come" until "arrived";
//! robot 2 repeats "arrived" until "resume". Both key on `path_id`, so a
//! repetition is harmless.

#![cfg_attr(test, allow(clippy::unwrap_used))]

pub mod assemble;

use shm_schemas::payloads::{
    ArmGraspState, GraspAction, GraspPhase, GraspRequest, MissionCode, MissionCommand, TargetState, ViaKind,
    ViaPathBuf, ViaPathHeader,
};

/// Which robot an agent speaks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Robot 1: explores, finds the target, sends the path, waits.
    Explorer,
    /// Robot 2: waits, follows the path, grasps, reports.
    Executor,
}

impl Role {
    /// `explorer` or `executor`.
    pub fn name(self) -> &'static str {
        match self {
            Role::Explorer => "explorer",
            Role::Executor => "executor",
        }
    }

    /// The role named `s`.
    pub fn parse(s: &str) -> Result<Role, MissionError> {
        match s {
            "explorer" => Ok(Role::Explorer),
            "executor" => Ok(Role::Executor),
            other => Err(MissionError::UnknownRole(other.to_owned())),
        }
    }
}

/// What the mission agent refuses.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MissionError {
    /// `--role` names no role.
    #[error(
        "unknown role {0:?}: give `-- --role explorer` (robot 1: sends the path) or `-- --role executor` (robot 2: follows it)"
    )]
    UnknownRole(String),
    /// A path that cannot be followed.
    #[error("path {path_id} has {count} points; a path to follow has at least 1, all finite")]
    BadPath {
        /// the path
        path_id: u32,
        /// its count
        count: u32,
    },
}

/// Whether `path` can be sent or followed: an id and at least one point,
/// every one finite (its length is bounded by the port it came on).
pub fn check_path(path: &ViaPathBuf) -> Result<(), MissionError> {
    let finite = path.entries().all(|(p, _, _)| p[0].is_finite() && p[1].is_finite());
    if path.path_id() == 0 || path.points.is_empty() || !finite {
        let count = u32::try_from(path.points.len()).unwrap_or(u32::MAX);
        return Err(MissionError::BadPath { path_id: path.path_id(), count });
    }
    Ok(())
}

/// A message to the other robot or to a local agent.
#[derive(Debug, Clone, PartialEq)]
pub enum Send {
    /// The path (explorer: to robot 2; executor: to the target achiever).
    Path(ViaPathBuf),
    /// An order (explorer: "come", "resume" to robot 2; executor: "come",
    /// "abort" to the target achiever).
    Order(MissionCommand),
    /// A report to robot 1 (executor only): "via-reached", "arrived".
    Report(MissionCommand),
    /// A request to the arm (executor only).
    Grasp(GraspRequest),
}

/// What the explorer is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ExplorerPhase {
    /// No target yet, or robot 2 came to the last one: explore.
    Exploring,
    /// The map builder has a path; waiting for the decision maker to stop.
    Found {
        /// the path
        path_id: u32,
    },
    /// Path and "come" sent; waiting for "arrived".
    Sent {
        /// the path
        path_id: u32,
    },
    /// Robot 2 reported "arrived" for this path.
    Done {
        /// the path
        path_id: u32,
    },
}

/// A failed `plan` call is asked again after this long, ns.
pub const PLAN_RETRY_NS: u64 = 1_000_000_000;
/// A path's `plan` is asked at most this many times before the map
/// builder's own path goes out instead.
pub const PLAN_ATTEMPTS: u32 = 5;

/// Where robot 2's path came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathFrom {
    /// The map builder's `plan` answer (turned round, ended at the target).
    Plan,
    /// The map builder's own path: `plan` failed [`PLAN_ATTEMPTS`] times,
    /// or robot 2's position is not known.
    MapBuilder,
}

impl PathFrom {
    /// `plan` or `map-builder`.
    pub fn name(self) -> &'static str {
        match self {
            PathFrom::Plan => "plan",
            PathFrom::MapBuilder => "map-builder",
        }
    }
}

/// How a `plan` call ended, as the explorer takes it.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanAnswer {
    /// The way points `plan` found, from robot 1 to the goal.
    Found(Vec<[f64; 2]>),
    /// No path, or no answer: why (a status name, the call's error).
    Failed(String),
}

/// The `plan` call of the path in hand.
#[derive(Debug, Clone, Default)]
struct Planning {
    attempts: u32,
    in_flight: bool,
    last_ask_ns: u64,
    last_error: String,
}

/// Robot 1's side; see the module documentation.
#[derive(Debug, Clone)]
pub struct Explorer {
    /// The decision maker's mode in which the path goes out (`""`: at once).
    pub wait_mode: String,
    /// Repeat the path and "come" this often while waiting, ns.
    pub resend_ns: u64,
    /// Where robot 2 is until it reports (the launch file's `peer_start`).
    pub peer_start: Option<(f64, f64)>,
    phase: ExplorerPhase,
    /// The map builder's path: the target found, and its landmarks.
    path: Option<ViaPathBuf>,
    /// Robot 2's path, once made.
    to_send: Option<(ViaPathBuf, PathFrom)>,
    planning: Planning,
    /// Where robot 2 last said it was.
    peer: Option<(f64, f64)>,
    mode: Option<String>,
    last_sent_ns: u64,
}

impl Explorer {
    /// An explorer that sends in mode `wait_mode` and repeats every `resend_ns`.
    pub fn new(wait_mode: &str, resend_ns: u64) -> Self {
        Explorer {
            wait_mode: wait_mode.to_owned(),
            resend_ns,
            peer_start: None,
            phase: ExplorerPhase::Exploring,
            path: None,
            to_send: None,
            planning: Planning::default(),
            peer: None,
            mode: None,
            last_sent_ns: 0,
        }
    }

    /// Where robot 2's path came from, once made.
    pub fn path_from(&self) -> Option<PathFrom> {
        self.to_send.as_ref().map(|(_, f)| *f)
    }

    /// Where robot 2 is, as far as robot 1 knows: where it last reported
    /// being, else `peer_start`.
    pub fn peer(&self) -> Option<(f64, f64)> {
        self.peer.or(self.peer_start)
    }

    /// How many times the path in hand asked `plan`, and the last failure.
    pub fn plan_attempts(&self) -> (u32, &str) {
        (self.planning.attempts, &self.planning.last_error)
    }

    /// Whether the decision maker has stopped the robot (or none is waited for).
    fn stopped(&self) -> bool {
        self.wait_mode.is_empty() || self.mode.as_deref() == Some(self.wait_mode.as_str())
    }

    /// The goal to ask `plan` for now, if a call is due: the robot has
    /// stopped with a path found, none is made yet, no call is in flight,
    /// and the last failed one is [`PLAN_RETRY_NS`] old. The caller sends
    /// the call and hands its end to [`Explorer::on_plan`] (a call that
    /// could not even be sent too). `None` also when robot 2's position is
    /// not known: then the map builder's path is taken at once.
    pub fn plan_goal(&mut self, now_ns: u64) -> Option<(f64, f64)> {
        if !matches!(self.phase, ExplorerPhase::Found { .. }) || self.to_send.is_some() || !self.stopped() {
            return None;
        }
        let pl = &self.planning;
        if pl.in_flight || (pl.attempts > 0 && now_ns.saturating_sub(pl.last_ask_ns) < PLAN_RETRY_NS) {
            return None;
        }
        let Some(goal) = self.peer() else {
            self.planning.last_error = "where robot 2 is is not known (no report, no peer_start)".into();
            self.fall_back();
            return None;
        };
        self.planning.attempts += 1;
        self.planning.in_flight = true;
        self.planning.last_ask_ns = now_ns;
        Some(goal)
    }

    /// How the `plan` call ended. A path found makes robot 2's path; a
    /// failure is asked again later, and after [`PLAN_ATTEMPTS`] the map
    /// builder's own path is taken. Returns what the path came from once it
    /// is made by this answer.
    pub fn on_plan(&mut self, answer: PlanAnswer) -> Option<PathFrom> {
        self.planning.in_flight = false;
        if self.to_send.is_some() {
            return None;
        }
        let landmarks = self.path.as_ref()?;
        let made = match answer {
            PlanAnswer::Found(way) => assemble::from_plan(landmarks, &way).map_err(|e| e.to_string()),
            PlanAnswer::Failed(why) => Err(why),
        };
        match made {
            Ok(p) => {
                self.to_send = Some((p, PathFrom::Plan));
                Some(PathFrom::Plan)
            }
            Err(why) => {
                self.planning.last_error = why;
                if self.planning.attempts >= PLAN_ATTEMPTS {
                    self.fall_back();
                    return Some(PathFrom::MapBuilder);
                }
                None
            }
        }
    }

    fn fall_back(&mut self) {
        if let Some(p) = &self.path {
            self.to_send = Some((p.clone(), PathFrom::MapBuilder));
        }
    }

    /// The phase.
    pub fn phase(&self) -> ExplorerPhase {
        self.phase
    }

    /// What to tell the decision maker: the target is `close` (stop and
    /// wait) from the path found until robot 2 arrives, `none` otherwise.
    pub fn target_state(&self) -> TargetState {
        match self.phase {
            ExplorerPhase::Found { .. } | ExplorerPhase::Sent { .. } => TargetState::Close,
            ExplorerPhase::Exploring | ExplorerPhase::Done { .. } => TargetState::None,
        }
    }

    /// The map builder's path. A path already taken (same id; the map
    /// builder repeats it) changes nothing; a new one while exploring or
    /// done starts a mission; a bad one is refused.
    pub fn on_path(&mut self, path: &ViaPathBuf) -> Result<bool, MissionError> {
        check_path(path)?;
        let busy = match self.phase {
            ExplorerPhase::Exploring => None,
            ExplorerPhase::Done { path_id } => Some(path_id),
            ExplorerPhase::Found { path_id } | ExplorerPhase::Sent { path_id } => {
                if path_id == path.path_id() {
                    // the same path again, perhaps with more points: keep the newest
                    self.path = Some(path.clone());
                    if let Some((_, PathFrom::MapBuilder)) = self.to_send {
                        self.fall_back();
                    }
                }
                return Ok(false);
            }
        };
        if busy == Some(path.path_id()) {
            return Ok(false);
        }
        self.path = Some(path.clone());
        self.to_send = None;
        self.planning = Planning::default();
        self.phase = ExplorerPhase::Found { path_id: path.path_id() };
        Ok(true)
    }

    /// The decision maker's mode.
    pub fn on_mode(&mut self, name: &str) {
        self.mode = Some(name.to_owned());
    }

    /// A report from robot 2. Returns the messages to send: "resume" for an
    /// "arrived" of the path in progress (or of the one done: the first
    /// "resume" may have been lost).
    pub fn on_report(&mut self, r: &MissionCommand, now_ns: u64) -> Vec<Send> {
        // where robot 2 believed it was ((0, 0) is "not said": the message has no flag)
        if r.x.is_finite() && r.y.is_finite() && (r.x, r.y) != (0.0, 0.0) {
            self.peer = Some((r.x, r.y));
        }
        match (r.code(), self.phase) {
            (Some(MissionCode::Arrived), ExplorerPhase::Sent { path_id } | ExplorerPhase::Found { path_id })
                if r.path_id == path_id =>
            {
                self.phase = ExplorerPhase::Done { path_id };
                vec![Send::Order(MissionCommand::new(MissionCode::Resume, path_id, now_ns))]
            }
            (Some(MissionCode::Arrived), ExplorerPhase::Done { path_id }) if r.path_id == path_id => {
                vec![Send::Order(MissionCommand::new(MissionCode::Resume, path_id, now_ns))]
            }
            _ => Vec::new(),
        }
    }

    /// The clock: sends robot 2's path and "come" once the decision maker
    /// has stopped the robot and the path is made, and again every
    /// `resend_ns` until "arrived".
    pub fn tick(&mut self, now_ns: u64) -> Vec<Send> {
        let Some((path, _)) = &self.to_send else { return Vec::new() };
        let due = match self.phase {
            ExplorerPhase::Found { .. } => self.stopped(),
            ExplorerPhase::Sent { .. } => now_ns.saturating_sub(self.last_sent_ns) >= self.resend_ns,
            ExplorerPhase::Exploring | ExplorerPhase::Done { .. } => false,
        };
        if !due {
            return Vec::new();
        }
        let path_id = path.path_id();
        let mut out = path.clone();
        out.header.stamp_ns = now_ns;
        self.phase = ExplorerPhase::Sent { path_id };
        self.last_sent_ns = now_ns;
        vec![Send::Path(out), Send::Order(MissionCommand::new(MissionCode::Come, path_id, now_ns))]
    }
}

/// What the executor is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ExecutorPhase {
    /// No path to follow.
    Waiting,
    /// The target achiever follows this path.
    Following {
        /// the path
        path_id: u32,
    },
    /// At the last point of a path ending at the target; the arm grasps.
    Grasping {
        /// the path
        path_id: u32,
        /// the grasp request
        request_id: u32,
    },
    /// Arrived (and grasped, or not): "arrived" reported until "resume".
    Done {
        /// the path
        path_id: u32,
        /// whether robot 1 answered "resume"
        acknowledged: bool,
    },
}

/// How the grasp at the end of a path went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GraspOutcome {
    /// The path did not end at a target: nothing to grasp.
    NotAsked,
    /// The arm holds the target.
    Held,
    /// The arm missed (its state says why).
    Missed,
    /// The arm did not answer in time.
    NoAnswer,
}

/// Robot 2's side; see the module documentation.
#[derive(Debug, Clone)]
pub struct Executor {
    /// Repeat the path and "come" to the target achiever, and "arrived" to
    /// robot 1, this often, ns.
    pub resend_ns: u64,
    /// Give up waiting for the arm after this long, ns.
    pub grasp_timeout_ns: u64,
    /// Whether to grasp at a path's target.
    pub grasp: bool,
    phase: ExecutorPhase,
    paths: Vec<ViaPathBuf>,
    come_for: Option<u32>,
    /// Done and acknowledged paths are not followed again.
    finished: Vec<u32>,
    pose: Option<(f64, f64, f64)>,
    last_sent_ns: u64,
    since_ns: u64,
    arrived_index: u32,
    next_request: u32,
    outcome: Option<GraspOutcome>,
}

impl Executor {
    /// An executor that repeats every `resend_ns` and waits `grasp_timeout_ns` for the arm.
    pub fn new(resend_ns: u64, grasp_timeout_ns: u64) -> Self {
        Executor {
            resend_ns,
            grasp_timeout_ns,
            grasp: true,
            phase: ExecutorPhase::Waiting,
            paths: Vec::new(),
            come_for: None,
            finished: Vec::new(),
            pose: None,
            last_sent_ns: 0,
            since_ns: 0,
            arrived_index: 0,
            next_request: 1,
            outcome: None,
        }
    }

    /// The phase.
    pub fn phase(&self) -> ExecutorPhase {
        self.phase
    }

    /// How the last grasp went, once decided.
    pub fn outcome(&self) -> Option<GraspOutcome> {
        self.outcome
    }

    /// What to tell the decision maker: `none` while waiting or done,
    /// `seen` while following (the target achiever drives), `close` while
    /// grasping (stand still).
    pub fn target_state(&self) -> TargetState {
        match self.phase {
            ExecutorPhase::Waiting | ExecutorPhase::Done { .. } => TargetState::None,
            ExecutorPhase::Following { .. } => TargetState::Seen,
            ExecutorPhase::Grasping { .. } => TargetState::Close,
        }
    }

    /// The robot's pose (world frame), for the arm's guess.
    pub fn on_pose(&mut self, x: f64, y: f64, theta: f64) {
        if x.is_finite() && y.is_finite() && theta.is_finite() {
            self.pose = Some((x, y, theta));
        }
    }

    /// A path from robot 1 (kept by id; the last few only).
    pub fn on_path(&mut self, path: &ViaPathBuf, now_ns: u64) -> Result<Vec<Send>, MissionError> {
        check_path(path)?;
        self.paths.retain(|p| p.path_id() != path.path_id());
        self.paths.push(path.clone());
        if self.paths.len() > 4 {
            self.paths.remove(0);
        }
        Ok(self.start_if_ready(now_ns))
    }

    /// An order from robot 1: "come", "resume" (the answer to "arrived"), "abort".
    pub fn on_order(&mut self, o: &MissionCommand, now_ns: u64) -> Vec<Send> {
        match o.code() {
            Some(MissionCode::Come) => {
                self.come_for = Some(o.path_id);
                self.start_if_ready(now_ns)
            }
            Some(MissionCode::Resume) => {
                if let ExecutorPhase::Done { path_id, .. } = self.phase
                    && path_id == o.path_id
                {
                    self.phase = ExecutorPhase::Done { path_id, acknowledged: true };
                }
                Vec::new()
            }
            Some(MissionCode::Abort) => {
                self.come_for = None;
                let path_id = match self.phase {
                    ExecutorPhase::Following { path_id } | ExecutorPhase::Grasping { path_id, .. } => path_id,
                    _ => return Vec::new(),
                };
                self.phase = ExecutorPhase::Waiting;
                vec![Send::Order(MissionCommand::new(MissionCode::Abort, path_id, now_ns))]
            }
            _ => Vec::new(),
        }
    }

    /// The target achiever's report: "via-reached" goes on to robot 1;
    /// "arrived" at the last point starts the grasp (or ends the mission).
    pub fn on_progress(&mut self, r: &MissionCommand, now_ns: u64) -> Vec<Send> {
        let ExecutorPhase::Following { path_id } = self.phase else { return Vec::new() };
        if r.path_id != path_id {
            return Vec::new();
        }
        match r.code() {
            Some(MissionCode::ViaReached) => vec![Send::Report(*r)],
            Some(MissionCode::Arrived) => {
                self.arrived_index = r.index;
                let target = self.path(path_id).and_then(target_of);
                match target {
                    Some(t) if self.grasp => {
                        let request_id = self.next_request;
                        self.next_request = self.next_request.wrapping_add(1).max(1);
                        self.phase = ExecutorPhase::Grasping { path_id, request_id };
                        self.since_ns = now_ns;
                        vec![Send::Grasp(self.grasp_request(request_id, t, now_ns))]
                    }
                    _ => {
                        self.outcome = Some(GraspOutcome::NotAsked);
                        self.finish(path_id, now_ns)
                    }
                }
            }
            _ => Vec::new(),
        }
    }

    /// The arm's state: a final phase of the request under way ends the grasp.
    pub fn on_arm(&mut self, s: &ArmGraspState, now_ns: u64) -> Vec<Send> {
        let ExecutorPhase::Grasping { path_id, request_id } = self.phase else { return Vec::new() };
        if s.request_id != request_id {
            return Vec::new();
        }
        match s.phase() {
            Some(GraspPhase::Holding) => {
                self.outcome = Some(GraspOutcome::Held);
                self.finish(path_id, now_ns)
            }
            Some(GraspPhase::Missed) => {
                self.outcome = Some(GraspOutcome::Missed);
                self.finish(path_id, now_ns)
            }
            _ => Vec::new(),
        }
    }

    /// The clock: repeats the path and "come" to the target achiever, the
    /// grasp request to the arm, "arrived" to robot 1 until "resume"; gives
    /// up on a silent arm.
    pub fn tick(&mut self, now_ns: u64) -> Vec<Send> {
        let due = now_ns.saturating_sub(self.last_sent_ns) >= self.resend_ns;
        match self.phase {
            ExecutorPhase::Waiting | ExecutorPhase::Done { acknowledged: true, .. } => Vec::new(),
            ExecutorPhase::Following { path_id } if due => {
                self.last_sent_ns = now_ns;
                self.follow_orders(path_id, now_ns)
            }
            ExecutorPhase::Grasping { path_id, .. }
                if now_ns.saturating_sub(self.since_ns) >= self.grasp_timeout_ns =>
            {
                self.outcome = Some(GraspOutcome::NoAnswer);
                self.finish(path_id, now_ns)
            }
            ExecutorPhase::Grasping { path_id, request_id } if due => {
                self.last_sent_ns = now_ns;
                match self.path(path_id).and_then(target_of) {
                    Some(t) => vec![Send::Grasp(self.grasp_request(request_id, t, now_ns))],
                    None => Vec::new(),
                }
            }
            ExecutorPhase::Done { path_id, acknowledged: false } if due => {
                self.last_sent_ns = now_ns;
                vec![Send::Report(self.arrived(path_id, now_ns))]
            }
            _ => Vec::new(),
        }
    }

    fn path(&self, path_id: u32) -> Option<&ViaPathBuf> {
        self.paths.iter().find(|p| p.path_id() == path_id)
    }

    fn start_if_ready(&mut self, now_ns: u64) -> Vec<Send> {
        let Some(id) = self.come_for else { return Vec::new() };
        let busy = match self.phase {
            ExecutorPhase::Waiting => false,
            ExecutorPhase::Following { path_id } | ExecutorPhase::Grasping { path_id, .. } => path_id == id,
            ExecutorPhase::Done { path_id, .. } => path_id == id,
        };
        if busy || self.finished.contains(&id) || self.path(id).is_none() {
            return Vec::new();
        }
        self.phase = ExecutorPhase::Following { path_id: id };
        self.outcome = None;
        self.last_sent_ns = now_ns;
        self.follow_orders(id, now_ns)
    }

    fn follow_orders(&self, path_id: u32, now_ns: u64) -> Vec<Send> {
        match self.path(path_id) {
            Some(p) => vec![
                Send::Path(ViaPathBuf {
                    header: ViaPathHeader { stamp_ns: now_ns, ..p.header },
                    points: p.points.clone(),
                }),
                Send::Order(MissionCommand::new(MissionCode::Come, path_id, now_ns)),
            ],
            None => Vec::new(),
        }
    }

    fn finish(&mut self, path_id: u32, now_ns: u64) -> Vec<Send> {
        self.phase = ExecutorPhase::Done { path_id, acknowledged: false };
        if !self.finished.contains(&path_id) {
            self.finished.push(path_id);
            if self.finished.len() > 16 {
                self.finished.remove(0);
            }
        }
        self.last_sent_ns = now_ns;
        vec![Send::Report(self.arrived(path_id, now_ns))]
    }

    fn arrived(&self, path_id: u32, now_ns: u64) -> MissionCommand {
        let mut m = MissionCommand::new(MissionCode::Arrived, path_id, now_ns);
        m.index = self.arrived_index;
        if let Some((x, y, _)) = self.pose {
            (m.x, m.y) = (x, y);
        }
        m
    }

    /// A grasp request with the target's position in the robot's frame
    /// when the pose is known.
    fn grasp_request(&self, request_id: u32, target: [f64; 2], now_ns: u64) -> GraspRequest {
        let mut g =
            GraspRequest { stamp_ns: now_ns, request_id, action: GraspAction::Grasp as u8, ..Default::default() };
        if let Some((x, y, th)) = self.pose {
            let (dx, dy) = (target[0] - x, target[1] - y);
            let (s, c) = th.sin_cos();
            (g.x, g.y, g.has_point) = (c * dx + s * dy, -s * dx + c * dy, 1);
        }
        g
    }
}

/// The target of a path: its last point when that is of kind `target`.
pub fn target_of(path: &ViaPathBuf) -> Option<[f64; 2]> {
    let (p, kind, _) = path.entries().last()?;
    (ViaKind::from_code(kind) == Some(ViaKind::Target)).then_some(p)
}

#[cfg(test)]
mod tests;
