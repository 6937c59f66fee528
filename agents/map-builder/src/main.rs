//! `map-builder`: robot 1's map builder (thesis section 4.3.2.2, Fig. 4-8).
//! Periodic (default 200 ms).
//!
//! Inputs:
//! * `pose` (`nerve::PoseEstimate`): the odometry agent's `pose`;
//! * `sighting` (`nerve::CheckpointSighting`): the checkpoint agent's `sighting`;
//! * `mission_in` (`nerve::MissionCommand`): robot 2's reports ("via-reached",
//!   "arrived"), through the bridge.
//!
//! Outputs:
//! * `path` (`nerve::ViaPath` = `Seq<ViaPoint, ViaPathHeader>`, any length up to
//!   `VIA_PATH_MAX_LEN`): once the target is confirmed, the via points
//!   ([`MapBuilder::path`]); repeated every `republish_ms` until robot 2
//!   arrives (the receiver keys on `path_id`). Robot 1's mission agent takes
//!   it as "target found" and makes robot 2's path from `plan` with its
//!   checkpoints and ending (`nerve_mission::assemble`); this path goes to
//!   robot 2 itself only when `plan` fails or no mission agent runs;
//! * `mission` (`nerve::MissionCommand`): "come" with the path, repeated
//!   with it; "resume" once robot 2 reports "arrived" (for robot 1's decision
//!   maker: explore again);
//! * `revisit` (`nerve::Scalar`): every cycle, 1 when the robot is at a
//!   place it passed before (it is going round in circles), else 0;
//! * `map` (`nerve::MapCells`, a sequence of at most [`MAX_CELLS`] cells):
//!   every cell of the visited grid, with its bounds; sent every `map_every`
//!   cycles when the grid changed since the last one sent, and every
//!   [`MAP_RESEND`] × `map_every` cycles regardless (for a viewer that
//!   starts later).
//!
//! Service:
//! * `plan` (`nerve::PlanRequest` → `nerve::PlannedPath`, a sequence of at
//!   most [`MAX_PATH_POINTS`] way points): a path from the robot's position
//!   (its last pose, if at most 1 s old) to the goal over the cells it has
//!   seen (`nerve_map_builder::plan`), or no way points and the reason in
//!   the header's `status`. `nerve call map-builder/plan '{"x": 1.0, "y": 2.6}'`.
//!   Answered at the agent's next step. The SDK's test harness has no calls
//!   yet: there the agent runs without the service.
//!
//! The algorithm is the library `nerve_map_builder`. Parameters:
//! `via_distance_m` (1.6), `merge_m` (1.0), `min_sightings` (3),
//! `detour_factor` (2.0), `target_range_m` (0: a target counts at any
//! range), `clear_m` (0: robot 1 drives this far on after finding the target
//! before the path is sent and it stops, to be out of robot 2's way), `republish_ms` (1000), `cell_m`
//! (0.5; read at start), `revisit_after_s` (30; read at start), `revisit_radius_m` (0.5),
//! `map_every` (5 cycles: 1 s; 0: no map), `goal_tolerance_m` (1.0: a goal,
//! or the robot, this near a seen cell's centre is snapped to it);
//! read-only figures `landmarks`, `confirmed`, `cells`, `paths_sent`,
//! `maps_sent`, `plans`.

use agent_sdk::port::{SeqOutput, SeqServer};
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use nerve_map_builder::{
    MapBuilder, Pose, Settings, SightingEvent, VisitedGrid,
    plan::{islands, plan},
};
use shm_schemas::payloads::{
    CheckpointSighting, MapCell, MapHeader, MissionCode, MissionCommand, PathHeader, PathPoint, PlanRequest,
    PlanStatus, PoseEstimate, Scalar, VIA_PATH_MAX_LEN, ViaKind, ViaPathBuf, ViaPathHeader, ViaPoint,
};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// A pose older than this is not used, ns.
const POSE_FRESH_NS: u64 = 1_000_000_000;
/// Most cells the visited grid keeps (0.5 m cells: a 100 m × 100 m area).
const MAX_CELLS: usize = 40_000;
/// An `unreachable` answer's log counts each end's island up to this many cells.
const ISLAND_LIMIT: usize = 100_000;
/// Most way points a `plan` answer holds.
const MAX_PATH_POINTS: usize = 4096;
/// An unchanged map is sent again every this many times `map_every` cycles.
const MAP_RESEND: u64 = 10;

#[derive(Debug, Default)]
struct Figures {
    landmarks: AtomicU64,
    confirmed: AtomicU64,
    cells: AtomicU64,
    paths_sent: AtomicU64,
    maps_sent: AtomicU64,
    plans: AtomicU64,
}

#[derive(Debug, Clone, PartialEq)]
enum Mission {
    /// No target yet (or robot 2 has arrived at the last one).
    Exploring,
    /// The path was sent; waiting for "arrived".
    Sent { path: ViaPathBuf, last_sent_ns: u64 },
    /// Robot 2 arrived at the target of `path_id`.
    Done { path_id: u32 },
}

struct MapBuilderAgent {
    pose: Input<PoseEstimate>,
    sighting: Input<CheckpointSighting>,
    mission_in: Input<MissionCommand>,
    path_out: SeqOutput<ViaPoint, ViaPathHeader>,
    mission_out: Output<MissionCommand>,
    revisit_out: Output<Scalar>,
    map_out: SeqOutput<MapCell, MapHeader>,
    plan: SeqServer<PlanRequest, PathPoint, PathHeader>,
    via_distance_m: Param<f64>,
    merge_m: Param<f64>,
    min_sightings: Param<u32>,
    detour_factor: Param<f64>,
    target_range_m: Param<f64>,
    clear_m: Param<f64>,
    republish_ms: Param<u64>,
    revisit_radius_m: Param<f64>,
    map_every: Param<u32>,
    goal_tolerance_m: Param<f64>,
    map: MapBuilder,
    grid: VisitedGrid,
    figures: Arc<Figures>,
    last_pose: Option<PoseEstimate>,
    mission: Mission,
    next_path_id: u32,
    was_revisiting: bool,
    /// Steps so far.
    cycle: u64,
    /// The grid's revision and the cycle of the last map sent.
    map_sent: Option<(u32, u64)>,
}

fn in_range(lo: f64, hi: f64) -> impl Fn(&f64) -> Result<(), String> + Send + Sync + 'static {
    move |v| if (lo..=hi).contains(v) { Ok(()) } else { Err(format!("{v} is outside {lo} … {hi}")) }
}

impl MapBuilderAgent {
    fn settings(&self) -> Settings {
        Settings {
            via_distance_m: self.via_distance_m.get(),
            merge_m: self.merge_m.get(),
            min_sightings: self.min_sightings.get(),
            detour_factor: self.detour_factor.get(),
            target_range_m: self.target_range_m.get(),
            clear_m: self.clear_m.get(),
        }
    }

    fn send_path(&mut self, path: &ViaPathBuf, now: u64) -> Result<(), AgentError> {
        self.path_out.send(&ViaPathHeader { stamp_ns: now, ..path.header }, &path.points)?;
        let mut come = MissionCommand::new(MissionCode::Come, path.path_id(), now);
        if let Some(p) = self.last_pose {
            (come.x, come.y) = (p.x, p.y);
        }
        self.mission_out.send(come)?;
        self.figures.paths_sent.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }
}

impl MapBuilderAgent {
    /// Sends the map every `map_every` cycles when the grid changed since
    /// the last one sent, and every [`MAP_RESEND`] times as long regardless.
    fn send_map(&mut self, now: u64) -> Result<(), AgentError> {
        let every = u64::from(self.map_every.get());
        if every == 0 || !self.cycle.is_multiple_of(every) {
            return Ok(());
        }
        let revision = self.grid.revision();
        let due = match self.map_sent {
            None => true,
            Some((sent, at)) => sent != revision || self.cycle.saturating_sub(at) >= every.saturating_mul(MAP_RESEND),
        };
        if !due {
            return Ok(());
        }
        let grid = &self.grid;
        self.map_out.send_with(grid.len().min(MAX_CELLS), |header, cells| grid.write_map(now, header, cells))?;
        self.map_sent = Some((revision, self.cycle));
        self.figures.maps_sent.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }

    /// Answers the `plan` calls waiting: paths from `pose` over the grid.
    fn serve_plans(&self, pose: Option<Pose>, now: u64) {
        let server = &self.plan;
        let (grid, tolerance) = (&self.grid, self.goal_tolerance_m.get());
        let start = pose.map(|p| (p.x, p.y));
        let served = server.serve(|goal| {
            let p = plan(grid, start, (goal.x, goal.y), tolerance, MAX_PATH_POINTS, now);
            let status = p.status().map_or("?", |s| s.name());
            tracing::info!(
                goal_x = goal.x,
                goal_y = goal.y,
                status,
                points = p.points.len(),
                length_m = p.header.length_m,
                "plan asked"
            );
            if p.status() == Some(PlanStatus::Unreachable) {
                // which islands of cells the two ends are in (issue 42: why no way)
                if let Some(i) = start.and_then(|s| islands(grid, s, (goal.x, goal.y), tolerance, ISLAND_LIMIT)) {
                    tracing::warn!(
                        start_cell = ?i.start_cell,
                        start_island_cells = i.start_cells,
                        goal_cell = ?i.goal_cell,
                        goal_island_cells = i.goal_cells,
                        grid_cells = grid.len(),
                        "plan: no chain of cells driven between the robot and the goal"
                    );
                }
            }
            (p.header, p.points)
        });
        match served {
            Ok(n) => {
                self.figures.plans.fetch_add(n as u64, Ordering::Relaxed);
            }
            // a call gone wrong is the caller's loss; the map builder steps on
            Err(e) => tracing::warn!(error = %e, "plan: a call could not be answered"),
        }
    }
}

impl Agent for MapBuilderAgent {
    const KIND: &'static str = "map-builder";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(200))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let d = Settings::default();
        let cell_m = setup.param_checked("cell_m", 0.5, in_range(0.1, 5.0));
        let revisit_after_s = setup.param_checked("revisit_after_s", 30.0, in_range(0.0, 3600.0));
        let figures = Arc::new(Figures::default());
        let f2 = figures.clone();
        setup.figures(move || {
            let g = |a: &AtomicU64| a.load(Ordering::Relaxed).to_string();
            vec![
                ("landmarks".into(), g(&f2.landmarks)),
                ("confirmed".into(), g(&f2.confirmed)),
                ("cells".into(), g(&f2.cells)),
                ("paths_sent".into(), g(&f2.paths_sent)),
                ("maps_sent".into(), g(&f2.maps_sent)),
                ("plans".into(), g(&f2.plans)),
            ]
        });
        let plan = setup.serve_seq("plan", MAX_PATH_POINTS)?;
        Ok(MapBuilderAgent {
            pose: setup.input("pose")?,
            sighting: setup.input("sighting")?,
            mission_in: setup.input("mission_in")?,
            path_out: setup.output_seq("path", VIA_PATH_MAX_LEN)?,
            mission_out: setup.output("mission")?,
            revisit_out: setup.output("revisit")?,
            map_out: setup.output_seq("map", MAX_CELLS)?,
            plan,
            via_distance_m: setup.param_checked("via_distance_m", d.via_distance_m, in_range(0.0, 10.0)),
            merge_m: setup.param_checked("merge_m", d.merge_m, in_range(0.01, 10.0)),
            min_sightings: setup.param_checked("min_sightings", d.min_sightings, |v| {
                if *v >= 1 { Ok(()) } else { Err("min_sightings is at least 1".into()) }
            }),
            detour_factor: setup.param_checked("detour_factor", d.detour_factor, |v| {
                if *v == 0.0 || (1.0..=100.0).contains(v) { Ok(()) } else { Err("0 (off) or 1 … 100".into()) }
            }),
            target_range_m: setup.param_checked("target_range_m", d.target_range_m, in_range(0.0, 20.0)),
            clear_m: setup.param_checked("clear_m", d.clear_m, in_range(0.0, 20.0)),
            republish_ms: setup.param_checked("republish_ms", 1000u64, |v| {
                if *v >= 50 { Ok(()) } else { Err("republish_ms is at least 50".into()) }
            }),
            revisit_radius_m: setup.param_checked("revisit_radius_m", 0.5, in_range(0.0, 10.0)),
            map_every: setup.param_checked("map_every", 5u32, |v| {
                if *v <= 10_000 { Ok(()) } else { Err("map_every is 0 (no map) … 10000 cycles".into()) }
            }),
            goal_tolerance_m: setup.param_checked("goal_tolerance_m", 1.0, in_range(0.0, 10.0)),
            map: MapBuilder::new(d),
            grid: VisitedGrid::new(cell_m.get(), (revisit_after_s.get() * 1e9) as u64, MAX_CELLS),
            figures,
            last_pose: None,
            mission: Mission::Exploring,
            next_path_id: 1,
            was_revisiting: false,
            cycle: 0,
            map_sent: None,
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let s = self.settings();
        self.map.set_settings(s);
        // where the robot is and has been
        let mut poses = Vec::new();
        self.pose.drain(|_, p| poses.push(*p));
        for p in poses.iter().filter(|p| p.x.is_finite() && p.y.is_finite() && p.theta.is_finite()) {
            self.grid.visit_along(p.x, p.y, p.stamp_ns);
            self.map.on_pose(p.x, p.y);
            if self.last_pose.is_none_or(|l| p.stamp_ns >= l.stamp_ns) {
                self.last_pose = Some(*p);
            }
        }
        let pose = self.last_pose.filter(|p| now.saturating_sub(p.stamp_ns) <= POSE_FRESH_NS).map(|p| Pose {
            x: p.x,
            y: p.y,
            theta: p.theta,
        });
        self.cycle = self.cycle.saturating_add(1);
        self.send_map(now)?;
        self.serve_plans(pose, now);
        // landmarks
        let mut sightings = Vec::new();
        self.sighting.drain(|_, s| sightings.push(*s));
        for sg in &sightings {
            match self.map.on_sighting(sg, pose) {
                SightingEvent::Confirmed { id, is_target } => {
                    let l = self.map.landmarks().iter().find(|l| l.id == id && l.is_target == is_target);
                    let (x, y, via) = l.map_or((0.0, 0.0, (0.0, 0.0)), |l| (l.x, l.y, l.via_point(s.via_distance_m)));
                    tracing::info!(
                        id,
                        is_target,
                        x,
                        y,
                        via_x = via.0,
                        via_y = via.1,
                        "{} recorded",
                        if is_target { "target" } else { "checkpoint" }
                    );
                }
                SightingEvent::Ignored | SightingEvent::New | SightingEvent::Again => {}
            }
        }
        self.figures.landmarks.store(self.map.landmarks().len() as u64, Ordering::Relaxed);
        self.figures.confirmed.store(self.map.confirmed().count() as u64, Ordering::Relaxed);
        self.figures.cells.store(self.grid.len() as u64, Ordering::Relaxed);
        // robot 2's reports
        let mut reports = Vec::new();
        self.mission_in.drain(|m, c| reports.push((m.sender.to_string(), *c)));
        for (sender, r) in &reports {
            match (r.code(), &self.mission) {
                (Some(MissionCode::ViaReached), _) => {
                    tracing::info!(path = r.path_id, index = r.index, x = r.x, y = r.y, %sender, "robot 2 reached a via point");
                }
                (Some(MissionCode::Arrived), Mission::Sent { path, .. }) if r.path_id == path.path_id() => {
                    tracing::info!(path = r.path_id, x = r.x, y = r.y, %sender, "robot 2 arrived: resume exploring");
                    self.mission_out.send(MissionCommand::new(MissionCode::Resume, r.path_id, now))?;
                    self.mission = Mission::Done { path_id: r.path_id };
                }
                (Some(MissionCode::Arrived), _) => {
                    tracing::debug!(path = r.path_id, "arrived for a path not in progress; ignored");
                }
                (Some(code), _) => {
                    tracing::debug!(code = code.name(), %sender, "mission message not for the map builder")
                }
                (None, _) => tracing::warn!(code = r.code, %sender, "mission message of unknown code; ignored"),
            }
        }
        // the path, once a target is confirmed
        match &self.mission {
            Mission::Exploring => {
                if let Some(path) = self.map.path(self.next_path_id, now) {
                    self.next_path_id = self.next_path_id.saturating_add(1);
                    let pts: Vec<String> = path
                        .entries()
                        .map(|(p, k, id)| {
                            let kind = ViaKind::from_code(k).map_or("?", |k| k.name());
                            format!("({:.2}, {:.2}) {kind} {id}", p[0], p[1])
                        })
                        .collect();
                    tracing::info!(
                        path = path.path_id(),
                        points = path.points.len(),
                        "target found: path sent: {}",
                        pts.join(" -> ")
                    );
                    self.send_path(&path, now)?;
                    self.mission = Mission::Sent { path, last_sent_ns: now };
                }
            }
            Mission::Sent { path, last_sent_ns } => {
                if now.saturating_sub(*last_sent_ns) >= self.republish_ms.get().saturating_mul(1_000_000) {
                    let path = path.clone();
                    self.send_path(&path, now)?;
                    self.mission = Mission::Sent { path, last_sent_ns: now };
                }
            }
            Mission::Done { .. } => {}
        }
        // going round in circles?
        if let Some(p) = pose {
            let at = self.last_pose.map_or(now, |l| l.stamp_ns);
            let again = self.grid.visited_before(p.x, p.y, self.revisit_radius_m.get(), at);
            if again != self.was_revisiting {
                tracing::info!(
                    x = p.x,
                    y = p.y,
                    "{}",
                    if again { "back at a place passed before" } else { "in new space" }
                );
                self.was_revisiting = again;
            }
            self.revisit_out.send(Scalar { value: if again { 1.0 } else { 0.0 }, stamp_ns: now })?;
        }
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<MapBuilderAgent>()
}

#[cfg(test)]
mod tests {
    //! The agent's glue, through the SDK's harness: sightings to `path` and
    //! `mission` ("come") through `step`, the path sent again until robot 2
    //! arrives, "resume" then, the figures and a refused parameter. The map
    //! itself is tested in the library.

    use super::*;
    use agent_sdk::testing::Harness;
    use shm_schemas::payloads::PlanStatus;

    fn pose(x: f64, stamp_ns: u64) -> PoseEstimate {
        PoseEstimate { x, stamp_ns, ..Default::default() }
    }

    fn target_at(x: f64, y: f64, stamp_ns: u64) -> CheckpointSighting {
        CheckpointSighting { stamp_ns, x, y, range_m: 2.0, is_target: 1, from_camera: 1, ..Default::default() }
    }

    /// The paths sent on `path` since the last look.
    fn paths(h: &mut Harness<MapBuilderAgent>) -> Vec<ViaPathBuf> {
        let sent = h.output_bytes("path").expect("path");
        sent.iter().map(|(_, b)| ViaPathBuf::from_bytes(b).expect("a whole path")).collect()
    }

    fn codes(h: &mut Harness<MapBuilderAgent>) -> Vec<(MissionCode, u32)> {
        h.output::<MissionCommand>("mission")
            .expect("mission")
            .iter()
            .filter_map(|m| Some((m.code()?, m.path_id)))
            .collect()
    }

    #[test]
    fn a_confirmed_target_sends_a_path_until_robot_2_arrives() {
        let mut h = Harness::<MapBuilderAgent>::new().expect("the map builder starts");
        h.send("pose", pose(0.0, h.now_ns())).expect("pose");
        h.send("sighting", target_at(3.0, 0.0, h.now_ns())).expect("sighting");
        h.step().expect("step");
        assert!(paths(&mut h).is_empty(), "one sighting does not confirm");
        assert_eq!(h.param("landmarks").as_deref(), Ok("1"));
        assert_eq!(h.param("confirmed").as_deref(), Ok("0"));

        for _ in 0..2 {
            h.send("pose", pose(0.0, h.now_ns())).expect("pose");
            h.send("sighting", target_at(3.0, 0.0, h.now_ns())).expect("sighting");
            h.step().expect("step");
        }
        let sent = paths(&mut h);
        let p = sent.last().expect("the third sighting confirms: a path");
        let (last, kind, _) = p.entries().last().expect("points");
        assert_eq!((last, ViaKind::from_code(kind)), ([3.0, 0.0], Some(ViaKind::Target)), "{p:?}");
        assert_eq!(codes(&mut h), [(MissionCode::Come, p.path_id())]);
        assert_eq!(h.param("paths_sent").as_deref(), Ok("1"));

        // sent again every republish_ms until robot 2 arrives
        h.advance(Duration::from_millis(1200)).expect("steps");
        assert!(paths(&mut h).iter().any(|q| q.path_id() == p.path_id()));
        assert!(codes(&mut h).contains(&(MissionCode::Come, p.path_id())));

        let mut arrived = MissionCommand::new(MissionCode::Arrived, p.path_id(), h.now_ns());
        arrived.index = p.points.len() as u32 - 1;
        h.send_from("mission_in", "bridge", arrived).expect("arrived");
        h.step().expect("step");
        assert_eq!(codes(&mut h), [(MissionCode::Resume, p.path_id())]);
        h.advance(Duration::from_millis(1200)).expect("steps");
        assert!(paths(&mut h).is_empty(), "done: no more paths");
    }

    /// The `map` output as (header.count, revision, elements) of each sample sent since the last look.
    fn maps(h: &mut Harness<MapBuilderAgent>) -> Vec<(u64, u64, usize)> {
        use shm_schemas::Described as _;
        use shm_schemas::schema::Value;
        let schema = shm_schemas::payloads::MapCells::schema();
        let shape = schema.sequence_shape().expect("a sequence");
        let n = |bytes: &[u8], path: &str| match schema.decode_path(path, bytes) {
            Some(Value::Unsigned(v)) => v,
            other => panic!("{path}: {other:?}"),
        };
        h.output_bytes("map")
            .expect("map")
            .iter()
            .map(|(_, b)| {
                (n(b, "header.count"), n(b, "header.revision"), shape.count_of(b.len()).expect("whole cells"))
            })
            .collect()
    }

    #[test]
    fn the_map_is_sent_when_the_grid_changed_and_again_now_and_then() {
        let mut h = Harness::<MapBuilderAgent>::new().expect("the map builder starts");
        h.set_param("map_every", "2").expect("map_every");
        assert!(h.set_param("map_every", "20000").is_err(), "bounded");
        // into three cells, a pose a step: a map every second step, when changed
        for x in [0.1, 0.6, 1.1, 1.2] {
            h.send("pose", pose(x, h.now_ns())).expect("pose");
            h.step().expect("step");
        }
        assert_eq!(maps(&mut h), [(2, 2, 2), (3, 3, 3)], "at steps 2 and 4, with the cells so far");
        // unchanged: nothing until 10 × 2 cycles after the last one sent (step 4)
        h.run_cycles(18).expect("steps");
        assert!(maps(&mut h).is_empty());
        h.run_cycles(2).expect("steps");
        assert_eq!(maps(&mut h), [(3, 3, 3)], "sent again, unchanged");
        assert_eq!(h.param("maps_sent").as_deref(), Ok("3"));
        h.set_param("map_every", "0").expect("off");
        h.send("pose", pose(5.0, h.now_ns())).expect("pose");
        h.run_cycles(30).expect("steps");
        assert!(maps(&mut h).is_empty(), "map_every 0: no map");
    }

    /// `plan` answered at the agent's step, as `nerve call` gets it: along
    /// the cells driven, and a goal far from them refused with no points.
    #[test]
    fn plan_is_answered_over_the_cells_driven() {
        let mut h = Harness::<MapBuilderAgent>::new().expect("the map builder starts");
        for x in [0.1, 0.6, 1.1, 1.6] {
            h.send("pose", pose(x, h.now_ns())).expect("pose");
            h.step().expect("step");
        }
        let ask = |h: &mut Harness<MapBuilderAgent>, x: f64| {
            h.ask::<PlanRequest, (PathHeader, Vec<PathPoint>)>("plan", PlanRequest { x, y: 0.0, stamp_ns: 0 })
                .expect("answered")
        };
        let (header, points) = ask(&mut h, 0.1);
        assert_eq!(header.status(), Some(PlanStatus::Found), "{header:?}");
        assert!((header.start_x - 1.6).abs() < 0.5 && header.length_m > 1.0, "{header:?}");
        let end = points.last().expect("way points");
        assert!(end.x < 0.5 && end.y.abs() < 0.5, "{points:?}");
        let (header, points) = ask(&mut h, 9.0);
        assert_eq!((header.status(), points.len()), (Some(PlanStatus::GoalUnseen), 0));
        assert_eq!(h.param("plans").as_deref(), Ok("2"));
    }

    #[test]
    fn min_sightings_is_checked_and_read_at_the_next_step() {
        let mut h = Harness::<MapBuilderAgent>::new().expect("the map builder starts");
        let e = h.set_param("min_sightings", "0").expect_err("at least one");
        assert!(e.contains("at least 1"), "{e}");
        h.set_param("min_sightings", "1").expect("one sighting is enough");
        h.send("pose", pose(0.0, h.now_ns())).expect("pose");
        h.send("sighting", target_at(2.5, 1.0, h.now_ns())).expect("sighting");
        h.step().expect("step");
        assert_eq!(paths(&mut h).len(), 1, "confirmed by one sighting");
        assert!(h.set_param("confirmed", "0").expect_err("a figure").contains("read-only"));
    }
}
