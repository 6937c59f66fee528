//! `mission`: the command sender and receiver of the cooperation experiment
//! (thesis section 4.3.2, Fig. 4-8 and 4-9), one agent kind for both
//! robots, `-- --role explorer` on robot 1 and `-- --role executor` on
//! robot 2. The two meet only through their bridges; the logic is the
//! library `nerve_mission`. Periodic (default 100 ms).
//!
//! Explorer (robot 1). Inputs: `path_in` (`nerve::ViaPath`, the map builder's
//! `path`: the target found, with its landmarks), `mode` (`nerve::Mode`, the
//! decision maker's `mode`), `report` (`nerve::MissionCommand`, robot 2's
//! `report` through the bridge). Client: `planner` (`nerve::PlanRequest` →
//! `nerve::PlannedPath`, wired to the map builder's `plan`): robot 2's path
//! is `plan`'s answer from robot 1 to robot 2, turned round and ended at the
//! target (`nerve_mission::assemble`). Outputs: `path` and `order` ("come",
//! "resume"; to robot 2 through the bridge), `situation` (`nerve::Situation`:
//! target `close` from the path found until robot 2 arrives, else `none`; to
//! the decision maker).
//!
//! Executor (robot 2). Inputs: `path_in` and `order_in` (robot 1's, through the
//! bridge), `progress` (`nerve::MissionCommand`, the target achiever's
//! `mission`), `arm` (`nerve::ArmGraspState`, the arm's `state`), `pose`
//! (`nerve::PoseEstimate`, the odometry's `pose`: the arm's guess). Outputs:
//! `path` and `order` (to the target achiever's `path` and `mission_in`),
//! `grasp` (`nerve::GraspRequest`, to the arm's `cmd`), `report`
//! ("via-reached", "arrived"; to robot 1 through the bridge), `situation`
//! (target `seen` while following, `close` while grasping, else `none`).
//!
//! Parameters: `resend_ms` (2000: repeat the last word until answered);
//! explorer `wait_mode` (`wait`: the decision maker's mode in which the path
//! goes out; empty: at once), `peer_start` (`X,Y`: where robot 2 is, world
//! frame, until it reports a position; empty: not known, and the map
//! builder's own path goes out); executor `grasp` (true), `grasp_timeout_ms`
//! (30000). Read-only figures: `phase`, `path_id`, `sent`, `received`,
//! `refused`; the explorer's `path_from` (`plan`, or `map-builder` when
//! `plan` failed `nerve_mission::PLAN_ATTEMPTS` times), `plans` (calls
//! answered with a path), `plan_failures` and `plan_error` (the last); the
//! executor's `grasp`.

use agent_sdk::port::SeqClient;
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, SeqInput, SeqOutput, Setup, Task};
use nerve_mission::{Executor, ExecutorPhase, Explorer, ExplorerPhase, PathFrom, PlanAnswer, Role, Send};
use shm_schemas::payloads::{
    ArmGraspState, GraspRequest, MissionCommand, Mode, PathHeader, PathPoint, PlanRequest, PlanStatus, PoseEstimate,
    Situation, VIA_PATH_MAX_LEN, ViaKind, ViaPathBuf, ViaPathHeader, ViaPoint,
};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Arguments after `--`.
#[derive(Debug, clap::Parser)]
struct Args {
    /// `explorer` (robot 1: sends the path, waits) or `executor` (robot 2: follows, grasps, reports).
    #[arg(long)]
    role: String,
}

/// What `nerve ps` shows.
#[derive(Debug, Default, Clone)]
struct Figures {
    phase: String,
    path_id: u32,
    sent: u64,
    received: u64,
    refused: u64,
    grasp: String,
    path_from: String,
    plans: u64,
    plan_failures: u64,
    plan_error: String,
}

/// Ports and state of one role (one value per agent: the size difference does not matter).
#[allow(clippy::large_enum_variant)]
enum Side {
    Explorer {
        path_in: SeqInput<ViaPoint, ViaPathHeader>,
        mode: Input<Mode>,
        report: Input<MissionCommand>,
        planner: SeqClient<PlanRequest, PathPoint, PathHeader>,
        wait_mode: Param<String>,
        peer_start: Param<String>,
        /// the `peer_start` text last parsed into `logic` (parsed again only
        /// when it changes, not at every step)
        peer_start_seen: String,
        logic: Explorer,
    },
    Executor {
        path_in: SeqInput<ViaPoint, ViaPathHeader>,
        order_in: Input<MissionCommand>,
        progress: Input<MissionCommand>,
        arm: Input<ArmGraspState>,
        pose: Input<PoseEstimate>,
        grasp_out: Output<GraspRequest>,
        report_out: Output<MissionCommand>,
        grasp: Param<bool>,
        grasp_timeout_ms: Param<u64>,
        logic: Executor,
    },
}

struct Mission {
    role: Role,
    side: Side,
    path_out: SeqOutput<ViaPoint, ViaPathHeader>,
    order_out: Output<MissionCommand>,
    situation: Output<Situation>,
    resend_ms: Param<u64>,
    figures: Arc<Mutex<Figures>>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn describe_path(p: &ViaPathBuf) -> String {
    p.entries()
        .map(|(xy, k, _)| format!("({:.2}, {:.2}) {}", xy[0], xy[1], ViaKind::from_code(k).map_or("?", |k| k.name())))
        .collect::<Vec<_>>()
        .join(" -> ")
}

/// `X,Y` (metres), or empty for none.
fn parse_xy(s: &str) -> Result<Option<(f64, f64)>, String> {
    let s = s.trim();
    if s.is_empty() {
        return Ok(None);
    }
    let bad = || format!("{s:?} is not X,Y in metres (e.g. `-4,0`), nor empty");
    let (x, y) = s.split_once(',').ok_or_else(bad)?;
    let (x, y) = (x.trim().parse::<f64>().map_err(|_| bad())?, y.trim().parse::<f64>().map_err(|_| bad())?);
    if x.is_finite() && y.is_finite() { Ok(Some((x, y))) } else { Err(bad()) }
}

/// Robot 2's path from the map builder's `plan`: takes the calls that
/// ended (answered, timed out, the server gone) and sends one when the
/// logic asks for it. Never waits for an answer.
fn plan_path(
    planner: &SeqClient<PlanRequest, PathPoint, PathHeader>,
    logic: &mut Explorer,
    figures: &Mutex<Figures>,
    now: u64,
) {
    while let Some((_, done)) = planner.take() {
        let answer = match done {
            Ok((h, pts)) if h.status() == Some(PlanStatus::Found) => {
                tracing::info!(
                    points = pts.len(),
                    length_m = h.length_m,
                    from_x = h.start_x,
                    from_y = h.start_y,
                    goal_x = h.goal_x,
                    goal_y = h.goal_y,
                    "plan: the map builder found a way from robot 1 to robot 2"
                );
                lock(figures).plans += 1;
                PlanAnswer::Found(pts.iter().map(|p| [p.x, p.y]).collect())
            }
            Ok((h, _)) => PlanAnswer::Failed(format!("plan answered {}", h.status().map_or("?", |s| s.name()))),
            Err(e) => PlanAnswer::Failed(e.to_string()),
        };
        report_plan(logic, figures, answer);
    }
    let before = logic.path_from();
    let goal = logic.plan_goal(now);
    if before.is_none() && logic.path_from() == Some(PathFrom::MapBuilder) {
        tracing::warn!(
            "plan: where robot 2 is is not known (no report from it, no `peer_start`); sending the map builder's own path"
        );
    }
    if let Some((x, y)) = goal {
        tracing::info!(goal_x = x, goal_y = y, attempt = logic.plan_attempts().0, "plan: asking the way to robot 2");
        if let Err(e) = planner.call(&PlanRequest { x, y, stamp_ns: now }) {
            report_plan(logic, figures, PlanAnswer::Failed(e.to_string()));
        }
    }
}

/// Hands a call's end to the logic; logs and counts a call that made no path.
fn report_plan(logic: &mut Explorer, figures: &Mutex<Figures>, answer: PlanAnswer) {
    if logic.path_from().is_some() {
        return; // a late answer: the path is made already
    }
    let made = logic.on_plan(answer);
    if made == Some(PathFrom::Plan) {
        return;
    }
    let (attempts, error) = logic.plan_attempts();
    {
        let mut f = lock(figures);
        f.plan_failures += 1;
        f.plan_error = error.to_owned();
    }
    if made == Some(PathFrom::MapBuilder) {
        tracing::warn!(
            attempts,
            error,
            "plan: no way to robot 2 after {attempts} calls; sending the map builder's own path instead"
        );
    } else {
        let retry_ms = nerve_mission::PLAN_RETRY_NS / 1_000_000;
        tracing::warn!(attempts, error, retry_ms, "plan: no way to robot 2 yet; asking again");
    }
}

impl Mission {
    /// Sends what the logic asked for on the ports of this role.
    fn send(&mut self, sends: Vec<Send>) -> Result<(), AgentError> {
        for s in sends {
            match (&self.side, s) {
                (_, Send::Path(p)) => self.path_out.send(&p.header, &p.points)?,
                (_, Send::Order(o)) => self.order_out.send(o)?,
                (Side::Executor { report_out, .. }, Send::Report(r)) => report_out.send(r)?,
                (Side::Executor { grasp_out, .. }, Send::Grasp(g)) => grasp_out.send(g)?,
                (Side::Explorer { .. }, s) => {
                    tracing::error!(send = ?s, "the explorer has no port for this; a bug in nerve_mission");
                    continue;
                }
            }
            lock(&self.figures).sent += 1;
        }
        Ok(())
    }

    fn step_explorer(&mut self, now: u64) -> Result<(), AgentError> {
        let Side::Explorer { path_in, mode, report, planner, wait_mode, peer_start, peer_start_seen, logic } =
            &mut self.side
        else {
            return Ok(());
        };
        logic.wait_mode = wait_mode.get();
        if peer_start.with(|text| text != peer_start_seen) {
            *peer_start_seen = peer_start.get();
            logic.peer_start = parse_xy(peer_start_seen).ok().flatten();
        }
        logic.resend_ns = self.resend_ms.get().saturating_mul(1_000_000);
        if let Some((_, m)) = mode.latest() {
            logic.on_mode(m.name.as_str());
        }
        let mut paths = Vec::new();
        path_in.drain(|_, h, pts| paths.push(ViaPathBuf::of(h, pts)));
        let mut sends = Vec::new();
        let mut figs = Figures::default();
        for p in &paths {
            match logic.on_path(p) {
                Ok(true) => tracing::info!(
                    path = p.path_id(),
                    points = p.points.len(),
                    wait_mode = %logic.wait_mode,
                    "target found: path {} to send once the decision maker stops the robot: {}",
                    p.path_id(),
                    describe_path(p)
                ),
                Ok(false) => {}
                Err(e) => {
                    figs.refused += 1;
                    tracing::warn!(path = p.path_id(), "path refused: {e}");
                }
            }
        }
        let mut reports = Vec::new();
        report.drain(|m, r| reports.push((m.sender.to_string(), *r)));
        figs.received += reports.len() as u64;
        for (sender, r) in &reports {
            let before = logic.phase();
            let out = logic.on_report(r, now);
            match (r.code(), before, logic.phase()) {
                (Some(code), ExplorerPhase::Sent { .. }, ExplorerPhase::Done { path_id }) => tracing::info!(
                    path = path_id,
                    code = code.name(),
                    x = r.x,
                    y = r.y,
                    %sender,
                    "robot 2 arrived: resume exploring"
                ),
                (Some(code), ..) => {
                    tracing::debug!(path = r.path_id, index = r.index, code = code.name(), %sender, "robot 2 reports")
                }
                (None, ..) => tracing::warn!(code = r.code, %sender, "report of unknown code; ignored"),
            }
            sends.extend(out);
        }
        plan_path(planner, logic, &self.figures, now);
        let before = logic.phase();
        let out = logic.tick(now);
        if let (ExplorerPhase::Found { path_id }, ExplorerPhase::Sent { .. }) = (before, logic.phase()) {
            let from = logic.path_from().map_or("?", |f| f.name());
            tracing::info!(path = path_id, from, "path and \"come\" sent to robot 2; waiting for it to arrive");
        }
        sends.extend(out);
        let target = logic.target_state();
        let (phase, path_id) = match logic.phase() {
            ExplorerPhase::Exploring => ("exploring", 0),
            ExplorerPhase::Found { path_id } => ("found", path_id),
            ExplorerPhase::Sent { path_id } => ("sent", path_id),
            ExplorerPhase::Done { path_id } => ("done", path_id),
        };
        {
            let mut f = lock(&self.figures);
            f.phase = phase.into();
            f.path_id = path_id;
            f.received += figs.received;
            f.refused += figs.refused;
            f.path_from = logic.path_from().map_or_else(String::new, |p| p.name().to_owned());
        }
        self.situation.send(Situation::target(target, 0.0, 0.0, now))?;
        self.send(sends)
    }

    fn step_executor(&mut self, now: u64) -> Result<(), AgentError> {
        let Side::Executor { path_in, order_in, progress, arm, pose, grasp, grasp_timeout_ms, logic, .. } =
            &mut self.side
        else {
            return Ok(());
        };
        logic.resend_ns = self.resend_ms.get().saturating_mul(1_000_000);
        logic.grasp = grasp.get();
        logic.grasp_timeout_ns = grasp_timeout_ms.get().saturating_mul(1_000_000);
        if let Some((_, p)) = pose.latest() {
            logic.on_pose(p.x, p.y, p.theta);
        }
        let mut sends = Vec::new();
        let mut figs = Figures::default();
        let before = logic.phase();
        let mut paths = Vec::new();
        path_in.drain(|_, h, pts| paths.push(ViaPathBuf::of(h, pts)));
        figs.received += paths.len() as u64;
        for p in &paths {
            match logic.on_path(p, now) {
                Ok(s) => sends.extend(s),
                Err(e) => {
                    figs.refused += 1;
                    tracing::warn!(path = p.path_id(), "path from robot 1 refused: {e}");
                }
            }
        }
        let mut orders = Vec::new();
        order_in.drain(|m, o| orders.push((m.sender.to_string(), *o)));
        figs.received += orders.len() as u64;
        for (sender, o) in &orders {
            match o.code() {
                Some(_) => sends.extend(logic.on_order(o, now)),
                None => tracing::warn!(code = o.code, %sender, "order of unknown code; ignored"),
            }
        }
        let mut reports = Vec::new();
        progress.drain(|_, r| reports.push(*r));
        for r in &reports {
            sends.extend(logic.on_progress(r, now));
        }
        let mut states = Vec::new();
        arm.drain(|_, s| states.push(*s));
        for s in &states {
            sends.extend(logic.on_arm(s, now));
        }
        sends.extend(logic.tick(now));
        let after = logic.phase();
        if after != before {
            match after {
                ExecutorPhase::Following { path_id } => {
                    let desc =
                        paths.iter().rev().find(|p| p.path_id() == path_id).map(describe_path).unwrap_or_default();
                    tracing::info!(path = path_id, "come: following path {path_id}: {desc}");
                }
                ExecutorPhase::Grasping { path_id, request_id } => {
                    tracing::info!(path = path_id, request = request_id, "at the target: grasping")
                }
                ExecutorPhase::Done { path_id, acknowledged: false } => tracing::info!(
                    path = path_id,
                    grasp = ?logic.outcome(),
                    "arrived: reporting to robot 1 until it answers"
                ),
                ExecutorPhase::Done { path_id, acknowledged: true } => {
                    tracing::info!(path = path_id, "robot 1 resumed exploring")
                }
                ExecutorPhase::Waiting => tracing::info!("aborted: waiting"),
            }
        }
        let target = logic.target_state();
        let (phase, path_id) = match after {
            ExecutorPhase::Waiting => ("waiting", 0),
            ExecutorPhase::Following { path_id } => ("following", path_id),
            ExecutorPhase::Grasping { path_id, .. } => ("grasping", path_id),
            ExecutorPhase::Done { path_id, acknowledged: false } => ("arrived", path_id),
            ExecutorPhase::Done { path_id, acknowledged: true } => ("done", path_id),
        };
        {
            let mut f = lock(&self.figures);
            f.phase = phase.into();
            f.path_id = path_id;
            f.received += figs.received;
            f.refused += figs.refused;
            f.grasp = logic.outcome().map_or_else(String::new, |o| format!("{o:?}").to_lowercase());
        }
        self.situation.send(Situation::target(target, 0.0, 0.0, now))?;
        self.send(sends)
    }
}

impl Agent for Mission {
    const KIND: &'static str = "mission";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(100))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let role = Role::parse(&args.role).map_err(|e| AgentError::Config(e.to_string()))?;
        let resend_ms = setup.param_checked("resend_ms", 2000u64, |v| {
            if (100..=60_000).contains(v) { Ok(()) } else { Err("resend_ms is 100 … 60000".into()) }
        });
        let side = match role {
            Role::Explorer => {
                let wait_mode = setup.param("wait_mode", "wait".to_owned());
                let peer_start = setup.param_checked("peer_start", String::new(), |v| parse_xy(v).map(|_| ()));
                Side::Explorer {
                    path_in: setup.input_seq("path_in")?,
                    mode: setup.input("mode")?,
                    report: setup.input("report")?,
                    planner: setup.client_seq("planner")?,
                    logic: Explorer::new(&wait_mode.get(), 2_000_000_000),
                    wait_mode,
                    peer_start,
                    peer_start_seen: String::new(),
                }
            }
            Role::Executor => Side::Executor {
                path_in: setup.input_seq("path_in")?,
                order_in: setup.input("order_in")?,
                progress: setup.input("progress")?,
                arm: setup.input("arm")?,
                pose: setup.input("pose")?,
                grasp_out: setup.output("grasp")?,
                report_out: setup.output("report")?,
                grasp: setup.param("grasp", true),
                grasp_timeout_ms: setup.param_checked("grasp_timeout_ms", 30_000u64, |v| {
                    if (1000..=600_000).contains(v) {
                        Ok(())
                    } else {
                        Err("grasp_timeout_ms is 1000 … 600000".into())
                    }
                }),
                logic: Executor::new(2_000_000_000, 30_000_000_000),
            },
        };
        let figures = Arc::new(Mutex::new(Figures::default()));
        let f2 = figures.clone();
        setup.figures(move || {
            let f = lock(&f2).clone();
            let mut v = vec![
                ("role".into(), role.name().to_owned()),
                ("phase".into(), f.phase),
                ("path_id".into(), f.path_id.to_string()),
                ("sent".into(), f.sent.to_string()),
                ("received".into(), f.received.to_string()),
                ("refused".into(), f.refused.to_string()),
            ];
            match role {
                Role::Executor => v.push(("grasp".into(), f.grasp)),
                Role::Explorer => v.extend([
                    ("path_from".into(), f.path_from),
                    ("plans".into(), f.plans.to_string()),
                    ("plan_failures".into(), f.plan_failures.to_string()),
                    ("plan_error".into(), f.plan_error),
                ]),
            }
            v
        });
        Ok(Mission {
            role,
            side,
            path_out: setup.output_seq("path", VIA_PATH_MAX_LEN)?,
            order_out: setup.output("order")?,
            situation: setup.output("situation")?,
            resend_ms,
            figures,
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        match self.role {
            Role::Explorer => self.step_explorer(now),
            Role::Executor => self.step_executor(now),
        }
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Mission>()
}

#[cfg(test)]
mod tests {
    //! The agent's glue, through the SDK's harness: `--role` and its
    //! refusals, the explorer's path going out only in the decision maker's
    //! `wait_mode` (a parameter), sent again until robot 2 arrives, and
    //! "resume" then; a path refused and counted. The mission logic itself
    //! is tested in the library.

    use super::*;
    use agent_sdk::testing::Harness;
    use shm_schemas::FixedName;
    use shm_schemas::payloads::MissionCode;

    fn path(id: u32) -> ViaPathBuf {
        let mut p = ViaPathBuf::new(id, 0);
        p.points.push(ViaPoint::new([1.0, 0.0], ViaKind::TargetApproach, 0, [2.0, 0.0]));
        p.points.push(ViaPoint::new([2.0, 0.0], ViaKind::Target, 0, [2.0, 0.0]));
        p
    }

    /// The paths sent on `path` since the last look.
    fn paths(h: &mut Harness<Mission>) -> Vec<ViaPathBuf> {
        let sent = h.output_bytes("path").expect("path");
        sent.iter().map(|(_, b)| ViaPathBuf::from_bytes(b).expect("a whole path")).collect()
    }

    fn orders(h: &mut Harness<Mission>) -> Vec<(MissionCode, u32)> {
        h.output::<MissionCommand>("order")
            .expect("order")
            .iter()
            .filter_map(|m| Some((m.code()?, m.path_id)))
            .collect()
    }

    #[test]
    fn the_role_is_required_and_checked() {
        let e = Harness::<Mission>::new().expect_err("no role").to_string();
        assert!(e.contains("--role") && e.contains("nerve-mission -- --help"), "{e}");
        let e = Harness::<Mission>::builder().args(["--role", "pilot"]).start().expect_err("no such role").to_string();
        assert!(e.contains("pilot"), "{e}");
    }

    #[test]
    fn the_explorer_sends_the_path_when_stopped_and_resumes_when_robot_2_arrives() {
        let mut h = Harness::<Mission>::builder()
            .args(["--role", "explorer"])
            .param("resend_ms", "500")
            .param("peer_start", "-4,0.5")
            .start()
            .expect("the explorer starts");
        assert_eq!(h.param("role").as_deref(), Ok("explorer"));
        h.send_bytes_from("path_in", "test", &path(4).to_bytes()).expect("path");
        h.step().expect("step");
        assert!(paths(&mut h).is_empty(), "not before the robot waits");
        assert_eq!(h.param("phase").as_deref(), Ok("found"));

        h.send("mode", Mode { name: FixedName::new("wait"), ..Default::default() }).expect("mode");
        h.step().expect("step");
        // stopped: robot 2's path is asked of the map builder's `plan`, to robot 2's start
        let asked = h.requests::<PlanRequest>("planner").expect("planner");
        assert_eq!(asked.iter().map(|(_, r)| (r.x, r.y)).collect::<Vec<_>>(), [(-4.0, 0.5)]);
        assert!(paths(&mut h).is_empty(), "not before the answer");
        // the way from robot 1 (at 2.5, past the target) back to robot 2
        let header = PathHeader { status: PlanStatus::Found as u8, ..Default::default() };
        let way = vec![PathPoint { x: 2.5, y: 0.0 }, PathPoint { x: -3.8, y: 0.3 }];
        h.answer("planner", asked[0].0, Ok((header, way))).expect("answered");
        h.step().expect("step");
        let sent: Vec<_> = paths(&mut h)
            .into_iter()
            .map(|p| (p.path_id(), p.entries().map(|(xy, k, _)| (xy, k)).collect::<Vec<_>>()))
            .collect();
        let (approach, target) = (ViaKind::TargetApproach as u8, ViaKind::Target as u8);
        let want = vec![([-3.8, 0.3], ViaKind::Waypoint as u8), ([1.0, 0.0], approach), ([2.0, 0.0], target)];
        assert_eq!(sent, [(4, want)], "plan's way turned round, cut at the approach, ended at the target");
        assert_eq!(h.param("path_from").as_deref(), Ok("plan"));
        assert_eq!(h.param("plans").as_deref(), Ok("1"));
        assert_eq!(orders(&mut h), [(MissionCode::Come, 4)]);
        assert_eq!(h.param("phase").as_deref(), Ok("sent"));

        // no answer: sent again every resend_ms
        h.advance(Duration::from_millis(600)).expect("steps");
        assert_eq!(orders(&mut h), [(MissionCode::Come, 4)]);

        h.send_from("report", "bridge", MissionCommand::new(MissionCode::Arrived, 4, h.now_ns())).expect("arrived");
        h.step().expect("step");
        assert_eq!(orders(&mut h), [(MissionCode::Resume, 4)]);
        assert_eq!(h.param("phase").as_deref(), Ok("done"));

        // a path without points is refused and counted
        h.send_bytes_from("path_in", "test", &ViaPathBuf::new(5, 0).to_bytes()).expect("empty path");
        h.step().expect("step");
        assert_eq!(h.param("refused").as_deref(), Ok("1"));
        let e = h.set_param("resend_ms", "10").expect_err("too often");
        assert!(e.contains("100"), "{e}");
        let e = h.set_param("peer_start", "-4").expect_err("not X,Y");
        assert!(e.contains("X,Y"), "{e}");
    }

    /// A `plan` that finds no way is asked again, a bounded number of
    /// times, one call at a time; then the map builder's path goes out.
    #[test]
    fn a_plan_that_fails_is_asked_again_then_the_map_builders_path_goes_out() {
        let mut h = Harness::<Mission>::builder()
            .args(["--role", "explorer"])
            .param("wait_mode", "")
            .param("peer_start", "-4,0")
            .start()
            .expect("the explorer starts");
        h.send_bytes_from("path_in", "test", &path(4).to_bytes()).expect("path");
        let unseen = PathHeader { status: PlanStatus::GoalUnseen as u8, ..Default::default() };
        let mut asked = 0;
        for _ in 0..(nerve_mission::PLAN_ATTEMPTS * 12) {
            h.step().expect("step");
            for (id, _) in h.requests::<PlanRequest>("planner").expect("planner") {
                asked += 1;
                h.answer("planner", id, Ok((unseen, Vec::<PathPoint>::new()))).expect("answered");
            }
            if !paths(&mut h).is_empty() {
                break;
            }
            h.advance(Duration::from_millis(100)).expect("time");
        }
        assert_eq!(asked, nerve_mission::PLAN_ATTEMPTS);
        assert_eq!(h.param("path_from").as_deref(), Ok("map-builder"));
        assert_eq!(h.param("plan_failures").as_deref(), Ok("5"));
        assert!(h.param("plan_error").expect("figure").contains("goal-unseen"), "{:?}", h.param("plan_error"));
    }
}
