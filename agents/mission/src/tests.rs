//! The mission's unit tests: both roles' steps on the library's logic (the
//! explorer's plan call and its fallback, the executor's grasps and reports).

use super::*;
use shm_schemas::payloads::GraspMiss;

const S: u64 = 1_000_000_000;

fn path(id: u32, pts: &[([f64; 2], ViaKind)]) -> ViaPathBuf {
    let mut p = ViaPathBuf::new(id, 0);
    p.points = pts.iter().map(|&(xy, k)| shm_schemas::payloads::ViaPoint::new(xy, k, 0, xy)).collect();
    p
}

fn corridor() -> ViaPathBuf {
    path(
        1,
        &[([1.2, -0.4], ViaKind::Checkpoint), ([12.8, -1.4], ViaKind::TargetApproach), ([12.8, -3.0], ViaKind::Target)],
    )
}

fn codes(sends: &[Send]) -> Vec<String> {
    sends
        .iter()
        .map(|s| match s {
            Send::Path(p) => format!("path {}", p.path_id()),
            Send::Order(o) => format!("order {} {}", o.code().map_or("?", |c| c.name()), o.path_id),
            Send::Report(r) => format!("report {} {}", r.code().map_or("?", |c| c.name()), r.path_id),
            Send::Grasp(g) => format!("grasp {}", g.request_id),
        })
        .collect()
}

#[test]
fn roles_parse_and_bad_ones_say_what_to_give() {
    assert_eq!(Role::parse("explorer"), Ok(Role::Explorer));
    assert_eq!(Role::parse(Role::Executor.name()), Ok(Role::Executor));
    let e = Role::parse("robot1").unwrap_err().to_string();
    assert!(e.contains("--role explorer") && e.contains("executor"), "{e}");
}

#[test]
fn explorer_waits_for_the_decision_maker_then_sends_until_arrived() {
    let mut ex = Explorer::new("wait", 2 * S);
    assert!(ex.tick(0).is_empty());
    assert_eq!(ex.target_state(), TargetState::None);
    assert!(ex.on_path(&corridor()).unwrap());
    assert_eq!(ex.target_state(), TargetState::Close, "stop: the target is found");
    ex.on_mode("explore");
    assert!(ex.tick(S).is_empty(), "the robot has not stopped yet");
    ex.on_mode("wait");
    assert!(ex.tick(S).is_empty(), "no path for robot 2 yet");
    assert_eq!(ex.plan_goal(S), None, "robot 2's position is not known: the map builder's path at once");
    assert_eq!(ex.path_from(), Some(PathFrom::MapBuilder));
    assert_eq!(codes(&ex.tick(S)), ["path 1", "order come 1"]);
    assert!(ex.tick(2 * S).is_empty());
    assert!(!ex.on_path(&corridor()).unwrap(), "the map builder repeats its path: nothing new");
    assert_eq!(codes(&ex.tick(3 * S)), ["path 1", "order come 1"], "repeated while robot 2 is silent");
    // a via point reached changes nothing; "arrived" of another path neither
    let mut via = MissionCommand::new(MissionCode::ViaReached, 1, 0);
    via.index = 0;
    assert!(ex.on_report(&via, 4 * S).is_empty());
    assert!(ex.on_report(&MissionCommand::new(MissionCode::Arrived, 7, 0), 4 * S).is_empty());
    assert_eq!(codes(&ex.on_report(&MissionCommand::new(MissionCode::Arrived, 1, 0), 5 * S)), ["order resume 1"]);
    assert_eq!(ex.phase(), ExplorerPhase::Done { path_id: 1 });
    assert_eq!(ex.target_state(), TargetState::None, "explore again");
    assert!(ex.tick(9 * S).is_empty(), "nothing more is sent");
    // "arrived" again (our "resume" was lost): answered again
    assert_eq!(codes(&ex.on_report(&MissionCommand::new(MissionCode::Arrived, 1, 0), 9 * S)), ["order resume 1"]);
    // the map builder's old path again: no new mission; a new one: yes
    assert!(!ex.on_path(&corridor()).unwrap());
    let mut p2 = corridor();
    p2.header.path_id = 2;
    assert!(ex.on_path(&p2).unwrap());
    assert_eq!(ex.path_from(), None, "a new mission makes a new path");
}

/// Robot 1 waits at (13.8, -4), past the target; `plan` answers the
/// way back along the corridor to robot 2's cell.
fn plan_to_robot_2() -> PlanAnswer {
    PlanAnswer::Found(vec![[13.8, -4.0], [12.2, -1.2], [11.2, -0.3], [-3.75, 0.25]])
}

#[test]
fn explorer_asks_plan_once_stopped_and_sends_its_answer_turned_round() {
    let mut ex = Explorer::new("wait", 2 * S);
    ex.peer_start = Some((-4.0, 0.0));
    ex.on_path(&corridor()).unwrap();
    assert_eq!(ex.plan_goal(0), None, "not before the robot stopped: robot 1's pose is the plan's start");
    ex.on_mode("wait");
    assert_eq!(ex.plan_goal(S), Some((-4.0, 0.0)), "robot 2's start, from the launch file");
    assert_eq!(ex.plan_goal(S), None, "one call in flight");
    assert!(ex.tick(S).is_empty(), "waiting for the answer");
    assert_eq!(ex.on_plan(plan_to_robot_2()), Some(PathFrom::Plan));
    let sent = ex.tick(S);
    assert_eq!(codes(&sent), ["path 1", "order come 1"]);
    let Send::Path(p) = &sent[0] else { unreachable!() };
    let pts: Vec<_> = p.entries().map(|(xy, k, id)| (xy, ViaKind::from_code(k).unwrap(), id)).collect();
    assert_eq!(pts[0], ([-3.75, 0.25], ViaKind::Waypoint, 0), "from robot 2's end: {pts:?}");
    assert_eq!(pts[1].1, ViaKind::Checkpoint, "the checkpoint on the way is kept: {pts:?}");
    assert_eq!(
        &pts[pts.len() - 2..],
        &[([12.8, -1.4], ViaKind::TargetApproach, 0), ([12.8, -3.0], ViaKind::Target, 0)]
    );
    assert!(pts.iter().all(|p| p.0 != [13.8, -4.0]), "robot 1's own place is cut off: {pts:?}");
    // "arrived" says where robot 2 is: the next mission plans to there
    let mut arrived = MissionCommand::new(MissionCode::Arrived, 1, 0);
    (arrived.x, arrived.y) = (12.8, -2.6);
    ex.on_report(&arrived, 3 * S);
    assert_eq!(ex.peer(), Some((12.8, -2.6)));
    let mut p2 = corridor();
    p2.header.path_id = 2;
    ex.on_path(&p2).unwrap();
    assert_eq!(ex.plan_goal(4 * S), Some((12.8, -2.6)));
}

#[test]
fn a_failing_plan_is_asked_again_then_the_map_builders_path_goes_out() {
    let mut ex = Explorer::new("", S);
    ex.peer_start = Some((-4.0, 0.0));
    ex.on_path(&corridor()).unwrap();
    let mut now = 0;
    for attempt in 1..PLAN_ATTEMPTS {
        assert!(ex.plan_goal(now).is_some(), "attempt {attempt}");
        assert_eq!(ex.on_plan(PlanAnswer::Failed("goal-unseen".into())), None);
        assert_eq!(ex.plan_attempts(), (attempt, "goal-unseen"));
        assert_eq!(ex.plan_goal(now + PLAN_RETRY_NS / 2), None, "not again before the retry time");
        assert!(ex.tick(now).is_empty());
        now += PLAN_RETRY_NS;
    }
    assert!(ex.plan_goal(now).is_some());
    // a broken answer counts as a failure too
    assert_eq!(ex.on_plan(PlanAnswer::Found(vec![])), Some(PathFrom::MapBuilder));
    assert!(ex.plan_attempts().1.contains("no way point"), "{:?}", ex.plan_attempts());
    let sent = ex.tick(now);
    let Send::Path(p) = &sent[0] else { panic!("{sent:?}") };
    assert_eq!(p.points, corridor().points, "the map builder's own path");
    assert_eq!(ex.plan_goal(now + 10 * PLAN_RETRY_NS), None, "no more calls");
    // a late answer changes nothing
    assert_eq!(ex.on_plan(plan_to_robot_2()), None);
    assert_eq!(ex.path_from(), Some(PathFrom::MapBuilder));
}

#[test]
fn explorer_without_a_decision_maker_sends_at_once_and_refuses_bad_paths() {
    let mut ex = Explorer::new("", S);
    assert!(ex.on_path(&ViaPathBuf::new(3, 0)).is_err(), "no point");
    let mut nan = corridor();
    nan.points[0].point[0] = f64::NAN;
    assert!(ex.on_path(&nan).is_err());
    assert!(ex.on_path(&path(0, &[([1.0, 1.0], ViaKind::Waypoint)])).is_err(), "path id 0 is none");
    assert_eq!(ex.phase(), ExplorerPhase::Exploring);
    ex.on_path(&corridor()).unwrap();
    ex.peer_start = Some((-4.0, 0.0));
    assert!(ex.plan_goal(0).is_some(), "asked at once");
    ex.on_plan(plan_to_robot_2());
    assert_eq!(codes(&ex.tick(0)), ["path 1", "order come 1"]);
}

fn arm_state(request_id: u32, phase: GraspPhase) -> ArmGraspState {
    ArmGraspState { request_id, phase: phase as u8, reason: GraspMiss::None as u8, ..Default::default() }
}

#[test]
fn executor_follows_grasps_and_reports_until_resumed() {
    let mut x = Executor::new(2 * S, 20 * S);
    assert_eq!(x.target_state(), TargetState::None);
    // "come" may overtake the path: it waits for it
    assert!(x.on_order(&MissionCommand::new(MissionCode::Come, 1, 0), 0).is_empty());
    assert_eq!(codes(&x.on_path(&corridor(), 0).unwrap()), ["path 1", "order come 1"]);
    assert_eq!(x.phase(), ExecutorPhase::Following { path_id: 1 });
    assert_eq!(x.target_state(), TargetState::Seen);
    // repeated by robot 1: nothing new
    assert!(x.on_path(&corridor(), S).unwrap().is_empty());
    assert!(x.on_order(&MissionCommand::new(MissionCode::Come, 1, 0), S).is_empty());
    assert_eq!(codes(&x.tick(2 * S)), ["path 1", "order come 1"], "repeated to the target achiever");
    let mut via = MissionCommand::new(MissionCode::ViaReached, 1, 0);
    via.index = 1;
    assert_eq!(codes(&x.on_progress(&via, 3 * S)), ["report via-reached 1"]);
    // at the last point, facing the target 0.4 m ahead and a little left
    x.on_pose(12.8, -2.6, -std::f64::consts::FRAC_PI_2);
    let mut arrived = MissionCommand::new(MissionCode::Arrived, 1, 0);
    arrived.index = 2;
    let s = x.on_progress(&arrived, 4 * S);
    assert_eq!(codes(&s), ["grasp 1"]);
    let Send::Grasp(g) = s[0].clone() else { unreachable!() };
    assert_eq!((g.action(), g.has_point), (Some(GraspAction::Grasp), 1));
    assert!((g.x - 0.4).abs() < 1e-9 && g.y.abs() < 1e-9, "robot frame: ({}, {})", g.x, g.y);
    assert_eq!(x.target_state(), TargetState::Close);
    assert!(x.on_arm(&arm_state(1, GraspPhase::Moving), 5 * S).is_empty());
    assert!(x.on_arm(&arm_state(9, GraspPhase::Holding), 5 * S).is_empty(), "another request");
    assert_eq!(codes(&x.tick(6 * S)), ["grasp 1"], "the request is repeated (the arm may have restarted)");
    let s = x.on_arm(&arm_state(1, GraspPhase::Holding), 7 * S);
    assert_eq!(codes(&s), ["report arrived 1"]);
    let Send::Report(r) = s[0].clone() else { unreachable!() };
    assert_eq!((r.index, r.x, r.y), (2, 12.8, -2.6));
    assert_eq!(x.outcome(), Some(GraspOutcome::Held));
    assert_eq!(codes(&x.tick(9 * S)), ["report arrived 1"], "until robot 1 answers");
    x.on_order(&MissionCommand::new(MissionCode::Resume, 1, 0), 10 * S);
    assert_eq!(x.phase(), ExecutorPhase::Done { path_id: 1, acknowledged: true });
    assert!(x.tick(20 * S).is_empty());
    // the same path again is not followed again
    assert!(x.on_path(&corridor(), 21 * S).unwrap().is_empty());
}

#[test]
fn executor_without_a_target_or_an_arm_still_reports() {
    let mut x = Executor::new(2 * S, 20 * S);
    x.on_path(&path(5, &[([1.0, 0.0], ViaKind::Waypoint)]), 0).unwrap();
    assert_eq!(codes(&x.on_order(&MissionCommand::new(MissionCode::Come, 5, 0), 0)), ["path 5", "order come 5"]);
    let s = x.on_progress(&MissionCommand::new(MissionCode::Arrived, 5, 0), S);
    assert_eq!(codes(&s), ["report arrived 5"], "no target at the end: nothing to grasp");
    assert_eq!(x.outcome(), Some(GraspOutcome::NotAsked));

    // a silent arm: arrived after the timeout
    let mut x = Executor::new(2 * S, 10 * S);
    x.on_path(&corridor(), 0).unwrap();
    x.on_order(&MissionCommand::new(MissionCode::Come, 1, 0), 0);
    assert_eq!(codes(&x.on_progress(&MissionCommand::new(MissionCode::Arrived, 1, 0), S)), ["grasp 1"]);
    assert_eq!(codes(&x.tick(3 * S)), ["grasp 1"]);
    assert_eq!(codes(&x.tick(11 * S)), ["report arrived 1"]);
    assert_eq!(x.outcome(), Some(GraspOutcome::NoAnswer));
}

#[test]
fn executor_abort_stops_the_target_achiever_and_a_miss_is_reported_too() {
    let mut x = Executor::new(2 * S, 20 * S);
    x.on_path(&corridor(), 0).unwrap();
    x.on_order(&MissionCommand::new(MissionCode::Come, 1, 0), 0);
    assert_eq!(codes(&x.on_order(&MissionCommand::new(MissionCode::Abort, 1, 0), S)), ["order abort 1"]);
    assert_eq!(x.phase(), ExecutorPhase::Waiting);
    assert!(x.tick(5 * S).is_empty());
    // "come" again: follows again; the arm misses: still "arrived"
    x.on_order(&MissionCommand::new(MissionCode::Come, 1, 0), 6 * S);
    assert_eq!(x.phase(), ExecutorPhase::Following { path_id: 1 });
    x.on_progress(&MissionCommand::new(MissionCode::Arrived, 1, 0), 7 * S);
    let miss = ArmGraspState { reason: GraspMiss::OutOfReach as u8, ..arm_state(1, GraspPhase::Missed) };
    assert_eq!(codes(&x.on_arm(&miss, 8 * S)), ["report arrived 1"]);
    assert_eq!(x.outcome(), Some(GraspOutcome::Missed));
}

#[test]
fn target_of_is_the_last_point_of_kind_target() {
    assert_eq!(target_of(&corridor()), Some([12.8, -3.0]));
    assert_eq!(target_of(&path(2, &[([1.0, 2.0], ViaKind::TargetApproach)])), None);
    assert_eq!(target_of(&ViaPathBuf::default()), None);
}
