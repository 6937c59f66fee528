//! The cooperation experiment's simulator side (thesis section 4.3): the
//! corridor world with two robots, each an obstacle to the other; the IR
//! codes of the checkpoints by range and direction; the two colour bands
//! of a tube as a pinhole camera sees them; H2's grasp; the odometry drift
//! that makes a straight drive slant.

mod common;

use std::path::Path;
use std::time::Duration;

use common::{room, run_for};
use nerve_devices::{
    EncoderReport, GraspAction, GraspCommand, GripperPhase, IrSighting, Message, Odometry, Pose2, SerialLink,
    WheelCommand,
};
use nerve_sim::{
    CAMERA_FRAME_BYTES, CAMERA_HEIGHT, CAMERA_WIDTH, DeviceHub, NoiseModel, RobotId, RobotModel, SimConfig, SimError,
    Simulation, World, focal_length_px,
};

fn cooperate() -> World {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/cooperate.toml");
    World::load(&path).expect("cooperate.toml is valid")
}

/// Robot 1 (H1) and robot 2 (H2) in `world`.
fn pair(world: World, seed: u64, noise: NoiseModel) -> (Simulation, RobotId) {
    let cfg = SimConfig::new(seed).with_noise(noise);
    let mut sim = Simulation::new(world, RobotModel::h1(), cfg).expect("robot 1 starts free");
    let r2 = sim.add_robot("robot 2", RobotModel::h2()).expect("robot 2 starts free");
    (sim, r2)
}

fn cmd(l: i16, r: i16) -> WheelCommand {
    WheelCommand { left_mm_s: l, right_mm_s: r }
}

fn pose(x: f64, y: f64, deg: f64) -> Pose2 {
    Pose2 { x, y, theta: deg.to_radians() }
}

#[test]
fn the_corridor_of_section_4_3_3() {
    let w = cooperate();
    let starts: Vec<_> = w.robots.iter().map(|r| (r.pose.x, r.pose.y)).collect();
    assert_eq!(starts, vec![(0.0, 0.0), (-4.0, 0.0)]);
    let cps: Vec<_> = w.checkpoints.iter().filter(|c| !c.target).map(|c| (c.id, c.position.x, c.position.y)).collect();
    assert_eq!(cps, vec![(1, 1.2, 1.2), (2, 6.0, 1.2), (3, 10.8, 1.2), (4, 15.6, 1.2)]);
    let target: Vec<_> = w.checkpoints.iter().filter(|c| c.target).map(|c| (c.position.x, c.position.y)).collect();
    assert_eq!(target, vec![(12.8, -3.0)]);
    // both robots drift to the right (right wheel short)
    assert!(w.robots.iter().all(|r| r.wheel_bias.is_some_and(|b| b[1] < b[0])));

    let (mut sim, r2) = pair(w, 1, NoiseModel::default());
    assert_eq!(sim.robot_count(), 2);
    assert_eq!(sim.robot(r2).model().kind, nerve_sim::RobotKind::H2);
    // a third robot has no start in this world
    match sim.add_robot("robot 3", RobotModel::h1()) {
        Err(e @ SimError::NoStart { .. }) => {
            assert!(e.to_string().contains("cooperate.toml") && e.to_string().contains("[[robot]]"), "{e}");
        }
        other => panic!("expected NoStart, got {other:?}"),
    }
    // robot 1 hears robot 2 behind it: sonar 6, 4 m centre to centre
    let behind = sim.robot(RobotId::FIRST).sonar_true_ranges()[6].expect("echo from robot 2");
    assert!((behind - (4.0 - 0.25 - 0.22)).abs() < 0.01, "{behind}");
    // the free space on the right after the third checkpoint: sonar 9
    // (right) of a robot at x = 14 sees into the open space; at x = 13.2
    // its beam holds the target's tube, 2.73 m away
    sim.robot_mut(RobotId::FIRST).set_pose(pose(14.0, 0.0, 0.0));
    let right = sim.robot(RobotId::FIRST).sonar_true_ranges()[9].expect("echo");
    assert!(right > 3.0, "open space on the right: {right} m");
    sim.robot_mut(RobotId::FIRST).set_pose(pose(13.2, 0.0, 0.0));
    let right = sim.robot(RobotId::FIRST).sonar_true_ranges()[9].expect("echo");
    assert!((right - 2.73).abs() < 0.01, "the target's tube: {right} m");
    sim.robot_mut(RobotId::FIRST).set_pose(pose(9.0, 0.0, 0.0));
    let right = sim.robot(RobotId::FIRST).sonar_true_ranges()[9].expect("echo");
    assert!((right - 1.35).abs() < 0.02, "corridor wall on the right before it: {right} m");
}

#[test]
fn robots_move_independently_and_bump_into_each_other() {
    let text = "[[robot]]\nx = 2.0\ny = 5.0\n[[robot]]\nx = 6.0\ny = 5.0\nheading_deg = 180.0\n\
                [[wall]]\nfrom = [0.0, 0.0]\nto = [10.0, 0.0]\n[[wall]]\nfrom = [10.0, 0.0]\nto = [10.0, 10.0]\n\
                [[wall]]\nfrom = [10.0, 10.0]\nto = [0.0, 10.0]\n[[wall]]\nfrom = [0.0, 10.0]\nto = [0.0, 0.0]\n";
    let world = World::from_toml_str(text, Path::new("two.toml")).expect("valid");
    let (mut sim, r2) = pair(world, 1, NoiseModel::none());
    let r1 = RobotId::FIRST;

    // each sees the other: robot 1's camera has robot 2's light body
    // straight ahead, robot 2's camera robot 1's dark one
    let mut frame = vec![0u8; CAMERA_FRAME_BYTES];
    let centre = |frame: &[u8]| {
        let i = ((CAMERA_HEIGHT / 2 + 40) * CAMERA_WIDTH + CAMERA_WIDTH / 2) * 3;
        [frame[i], frame[i + 1], frame[i + 2]]
    };
    sim.robot(r1).render_camera(&mut frame).expect("render");
    let p = centre(&frame);
    assert!(p.iter().all(|c| *c > 150), "robot 2 (light) ahead of robot 1: {p:?}");
    sim.robot(r2).render_camera(&mut frame).expect("render");
    let p = centre(&frame);
    assert!(p.iter().all(|c| *c < 70), "robot 1 (dark) ahead of robot 2: {p:?}");
    let ahead = sim.robot(r1).sonar_true_ranges()[0].expect("echo");
    assert!((ahead - (4.0 - 0.25 - 0.22)).abs() < 0.01, "{ahead}");

    // only robot 1 is commanded: only robot 1 moves, until it meets robot 2
    sim.robot_mut(r1).command_wheels(&cmd(400, 400));
    run_for(&mut sim, 15.0);
    let (a, b) = (sim.robot(r1).pose(), sim.robot(r2).pose());
    assert_eq!((b.x, b.y), (6.0, 5.0), "robot 2 did not move");
    let gap = (b.x - a.x).hypot(b.y - a.y);
    let touching = RobotModel::h1().radius + RobotModel::h2().radius;
    assert!(gap >= touching - 1e-9 && gap < touching + 0.01, "stopped at contact: gap {gap}");
    assert_eq!(sim.robot(r1).collisions(), 1, "robot 1 bumped into robot 2 once");
    assert!(sim.robot(r1).in_contact() && sim.robot(r2).in_contact());
    assert_eq!(sim.robot(r2).collisions(), 1, "a contact between robots counts for both");

    // robot 2 backs away on its own; robot 1 stays pushed against nothing
    sim.robot_mut(r1).command_wheels(&cmd(0, 0));
    sim.robot_mut(r2).command_wheels(&cmd(-300, -300));
    run_for(&mut sim, 3.0);
    let (a2, b2) = (sim.robot(r1).pose(), sim.robot(r2).pose());
    assert!(b2.x > b.x + 0.5, "robot 2 backed away east: {b2:?}");
    assert!((a2.x - a.x).abs() < 0.05, "robot 1 stayed: {a2:?}");
    assert!(!sim.robot(r1).in_contact() && !sim.robot(r2).in_contact());
    // and robot 2 cannot drive through robot 1 either
    sim.robot_mut(r2).command_wheels(&cmd(300, 300));
    run_for(&mut sim, 10.0);
    let b3 = sim.robot(r2).pose();
    assert!(b3.x > a2.x + touching - 1e-9, "robot 2 stopped at robot 1: {b3:?} vs {a2:?}");
    assert_eq!(sim.robot(r2).collisions(), 2);
}

#[test]
fn a_robot_may_not_start_on_another() {
    let text = "[[robot]]\nx = 2.0\ny = 5.0\n[[robot]]\nx = 2.3\ny = 5.0\n";
    let world = World::from_toml_str(text, Path::new("overlap.toml")).expect("valid");
    let mut sim = Simulation::new(world, RobotModel::h1(), SimConfig::new(1)).expect("first is free");
    let err = sim.add_robot("robot 2", RobotModel::h2()).expect_err("overlaps robot 1");
    assert!(matches!(err, SimError::StartBlocked { .. }), "{err}");
}

fn ir_of(sim: &mut Simulation, id: RobotId, at: Pose2) -> Option<IrSighting> {
    sim.robot_mut(id).set_pose(at);
    sim.robot(id).ir_true_sighting()
}

#[test]
fn ir_codes_name_the_checkpoint_and_the_transmitter_facing_the_robot() {
    let (mut sim, r2) = pair(cooperate(), 1, NoiseModel::none());
    // park robot 2 out of the way
    sim.robot_mut(r2).set_pose(pose(-4.0, 0.0, 0.0));
    let r1 = RobotId::FIRST;
    let code = |checkpoint_id, transmitters| Some(IrSighting { checkpoint_id, transmitters });
    // checkpoint 2 at (6, 1.2) faces south: straight in front of it, 1.6 m
    // (the via point), transmitter 0 (south)
    assert_eq!(ir_of(&mut sim, r1, pose(6.0, -0.4, 0.0)), code(2, 0b0001));
    // coming from the west, transmitter 3 (heading + 270° = west)
    assert_eq!(ir_of(&mut sim, r1, pose(4.6, 0.2, 0.0)), code(2, 0b1000));
    // leaving to the east, transmitter 1
    assert_eq!(ir_of(&mut sim, r1, pose(7.4, 0.2, 180.0)), code(2, 0b0010));
    // the robot's heading does not matter, only where it is
    assert_eq!(ir_of(&mut sim, r1, pose(6.0, -0.4, 123.0)), code(2, 0b0001));
    // the other checkpoints and the target, each with its own id
    assert_eq!(ir_of(&mut sim, r1, pose(1.2, -0.4, 0.0)), code(1, 0b0001));
    assert_eq!(ir_of(&mut sim, r1, pose(10.8, -0.4, 0.0)), code(3, 0b0001));
    assert_eq!(ir_of(&mut sim, r1, pose(15.6, -0.4, 0.0)), code(4, 0b0001));
    assert_eq!(ir_of(&mut sim, r1, pose(12.8, -1.4, 0.0)), code(9, 0b0001));
    // out of range (2 m): just beyond, and half-way between two checkpoints
    assert_eq!(ir_of(&mut sim, r1, pose(7.9, 0.55, 0.0)), None);
    assert_eq!(ir_of(&mut sim, r1, pose(3.6, 0.0, 0.0)), None);
    assert_eq!(ir_of(&mut sim, r1, pose(6.0 + 1.95, 1.2 - 0.3, 0.0)), code(2, 0b0010));
    // another robot in the line of sight blocks the light
    sim.robot_mut(r2).set_pose(pose(6.0, 0.45, 0.0));
    assert_eq!(ir_of(&mut sim, r1, pose(6.0, -0.4, 0.0)), None);
}

/// Rows of the tube's upper (yellow) and lower (blue) band in the centre
/// column: their centres, in pixels.
fn band_centres(frame: &[u8]) -> (f64, f64) {
    let col = CAMERA_WIDTH / 2;
    let (mut yellow, mut blue) = (Vec::new(), Vec::new());
    for row in 0..CAMERA_HEIGHT {
        let p = &frame[(row * CAMERA_WIDTH + col) * 3..][..3];
        if p[0] > 100 && p[1] > 80 && p[2] < 50 {
            yellow.push(row as f64 + 0.5);
        }
        if p[2] > 100 && p[0] < 50 && p[1] < 100 {
            blue.push(row as f64 + 0.5);
        }
    }
    assert!(!yellow.is_empty() && !blue.is_empty(), "both bands visible");
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    // rows are pixel centres; a band covering rows a..=b has centre (a+b)/2
    (mean(&yellow), mean(&blue))
}

#[test]
fn the_camera_sees_two_bands_whose_spacing_falls_with_range_as_a_pinhole() {
    // H2's camera is 0.8 m high, the middle of the tube: the whole tube is
    // in view from 0.8 m on (H1's, 1.0 m high, tilts down below ~0.95 m)
    let cp = "[[checkpoint]]\nid = 1\nposition = [8.0, 5.0]\n";
    let model = RobotModel::h2();
    let f = focal_length_px(model.camera_hfov);
    let mut last = f64::INFINITY;
    for z in [0.8, 1.0, 1.4, 1.8, 2.2, 2.6, 3.0] {
        let world = room(12.0, 8.0 - z, 5.0, 0.0, cp);
        let (d_band, radius) = (world.checkpoints[0].band_spacing(), world.checkpoints[0].radius);
        let sim = Simulation::new(world, model.clone(), SimConfig::new(1).with_noise(NoiseModel::none()))
            .expect("free start");
        let mut frame = vec![0u8; CAMERA_FRAME_BYTES];
        sim.render_camera(&mut frame).expect("render");
        let (upper, lower) = band_centres(&frame);
        assert!(upper < lower, "yellow above blue at {z} m");
        let d = lower - upper;
        // the front of the tube is `radius` nearer than its axis
        let pinhole = f * d_band / (z - radius);
        assert!((d - pinhole).abs() <= 1.0, "at {z} m: {d:.1} px between band centres, pinhole {pinhole:.1}");
        assert!(d < last, "spacing falls with range: {d} after {last}");
        last = d;
    }
}

/// Steps `sim` until robot `id`'s gripper is in `phase`.
fn step_until(sim: &mut Simulation, id: RobotId, phase: GripperPhase) {
    for _ in 0..500 {
        sim.step();
        if sim.robot(id).gripper().0 == phase {
            return;
        }
    }
    panic!("gripper never reached {phase:?}: {:?}", sim.robot(id).gripper());
}

#[test]
fn a_grasp_holds_the_target_only_within_reach() {
    let (mut sim, r2) = pair(cooperate(), 1, NoiseModel::none());
    // robot 1 stays in the corridor; robot 2 faces the target from 0.5 m
    // (the gripper's tip, 0.5 m ahead with the arm stretched, on the tube)
    sim.robot_mut(r2).set_pose(pose(12.8, -2.5, -90.0));
    let g = sim.robot(r2).graspable().expect("the world has a target");
    assert!(g.within_reach && g.distance < 0.01 && g.id == 9, "{g:?}");
    sim.robot_mut(r2).command_grasp(GraspAction::Release);
    step_until(&mut sim, r2, GripperPhase::Open);
    run_for(&mut sim, 1.5);
    assert!(sim.robot(r2).arm_position()[2] > 1.0, "gripper opened");
    sim.robot_mut(r2).command_grasp(GraspAction::Grasp);
    assert_eq!(sim.robot(r2).gripper().0, GripperPhase::Closing);
    step_until(&mut sim, r2, GripperPhase::Holding);
    assert_eq!(sim.robot(r2).gripper(), (GripperPhase::Holding, Some(9)));
    let t = sim.robot(r2).truth();
    assert_eq!((t.gripper, t.held), (GripperPhase::Holding, Some(9)));
    assert_eq!(sim.robot(r2).grasp_state(3).held_id, 9);
    // releasing opens the fingers and lets go
    sim.robot_mut(r2).command_grasp(GraspAction::Release);
    assert_eq!(sim.robot(r2).gripper(), (GripperPhase::Open, None));

    // 1.6 m away (at the via point) the fingers close on nothing
    sim.robot_mut(r2).set_pose(pose(12.8, -1.4, -90.0));
    sim.robot_mut(r2).command_grasp(GraspAction::Grasp);
    step_until(&mut sim, r2, GripperPhase::Missed);
    assert_eq!(sim.robot(r2).gripper(), (GripperPhase::Missed, None));
    let g = sim.robot(r2).graspable().expect("target");
    assert!(!g.within_reach && (g.distance - 1.1).abs() < 0.01, "{g:?}");
    // just outside the tolerance (0.1 m), still a miss; the arm swung
    // sideways does not reach a tube straight ahead either
    sim.robot_mut(r2).command_grasp(GraspAction::Release);
    run_for(&mut sim, 1.5);
    sim.robot_mut(r2).set_pose(pose(12.8, -2.38, -90.0));
    sim.robot_mut(r2).command_grasp(GraspAction::Grasp);
    step_until(&mut sim, r2, GripperPhase::Missed);
    // H1 has no arm: a grasp does nothing
    sim.robot_mut(RobotId::FIRST).command_grasp(GraspAction::Grasp);
    assert_eq!(sim.robot(RobotId::FIRST).gripper(), (GripperPhase::Open, None));
    assert!(sim.robot(RobotId::FIRST).graspable().is_none());
}

#[test]
fn grasp_over_the_arm_pty() {
    let dir = std::env::temp_dir().join(format!("nerve-sim-grasp-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (mut sim, r2) = pair(cooperate(), 1, NoiseModel::none());
    sim.robot_mut(r2).set_pose(pose(12.8, -2.5, -90.0));
    let mut hub = DeviceHub::open_robot(&dir, &sim, r2).expect("publish robot 2");
    for name in ["motor", "ir", "arm"] {
        assert!(std::fs::symlink_metadata(dir.join(name)).is_ok(), "{name} published");
    }
    assert!(!dir.join("sonar").exists(), "H2 has no sonar");
    let mut arm = SerialLink::open(&dir.join("arm")).expect("open arm");
    let step = |sim: &mut Simulation, hub: &mut DeviceHub| {
        hub.apply_commands(sim);
        sim.step();
        hub.send_reports(sim);
    };
    step(&mut sim, &mut hub);
    arm.send(&GraspCommand { action: GraspAction::Grasp }.into()).expect("send");
    let mut held = None;
    for _ in 0..3000 {
        step(&mut sim, &mut hub);
        while let Some(m) = arm.recv(Duration::from_millis(1)).expect("read") {
            if let Message::GraspState(g) = m
                && g.phase == GripperPhase::Holding
            {
                held = Some(g);
            }
        }
        if held.is_some() {
            break;
        }
    }
    let g = held.expect("a GraspState reporting the grasp");
    assert_eq!(g.held_id, 9);
    assert!(g.nearest_mm < 20, "{g:?}");
    drop(arm);
    drop(hub);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Drives robot `id` straight with `c` for `secs`, integrating odometry
/// from its encoder counts every 50 ms as a motor agent would.
fn drive(sim: &mut Simulation, id: RobotId, c: WheelCommand, secs: f64) -> Pose2 {
    let geometry = sim.robot(id).model().geometry;
    let mut odo = Odometry::new(geometry, sim.robot(id).pose());
    let report = |s: &Simulation| {
        let (left, right) = s.robot(id).encoder_counts();
        EncoderReport { seq: 0, time_ms: 0, left, right }
    };
    odo.update(&report(sim));
    sim.robot_mut(id).command_wheels(&c);
    let steps = (secs / sim.dt()).round() as u64;
    for i in 1..=steps {
        sim.step();
        if i % 5 == 0 {
            odo.update(&report(sim));
        }
    }
    odo.pose()
}

#[test]
fn drift_makes_a_straight_drive_slant_to_the_right() {
    // an open room, a fixed bias of 1 % on the right wheel
    let text = "[robot]\nx = 2.0\ny = 20.0\nwheel_bias = [0.0, -0.01]\n";
    for seed in [1, 2, 3] {
        let world = World::from_toml_str(text, Path::new("open.toml")).expect("valid");
        let mut sim = Simulation::new(world, RobotModel::h1(), SimConfig::new(seed)).expect("free");
        let odo = drive(&mut sim, RobotId::FIRST, cmd(400, 400), 20.0);
        let truth = sim.pose();
        // odometry believes in a straight line (both wheels counted alike)
        assert!((odo.y - 20.0).abs() < 1e-3 && odo.theta.abs() < 1e-3, "seed {seed}: odometry {odo:?}");
        // the robot went right: ~0.5 * (0.01 / 0.4 m) * (7.7 m)^2
        assert!(truth.y < 20.0 - 0.4 && truth.theta < -0.1, "seed {seed}: truth {truth:?}");
        assert!((sim.robot(RobotId::FIRST).wheel_bias().1 + 0.01).abs() < 1e-12);
    }
    // without noise the world's bias is off too: exact geometry
    let world = World::from_toml_str(text, Path::new("open.toml")).expect("valid");
    let mut sim =
        Simulation::new(world, RobotModel::h1(), SimConfig::new(1).with_noise(NoiseModel::none())).expect("free");
    drive(&mut sim, RobotId::FIRST, cmd(400, 400), 10.0);
    assert!((sim.pose().y - 20.0).abs() < 1e-9);

    // in the corridor, robot 2 (H2) drives 10 m east from its start: its
    // odometry says straight, the truth slants right (south)
    for seed in [1, 2, 3] {
        let (mut sim, r2) = pair(cooperate(), seed, NoiseModel::default());
        sim.robot_mut(RobotId::FIRST).set_pose(pose(12.0, 0.5, 0.0));
        let odo = drive(&mut sim, r2, cmd(350, 350), 30.0);
        let truth = sim.robot(r2).pose();
        assert!(truth.x > 5.0, "seed {seed}: moved on: {truth:?}");
        assert!(odo.y.abs() < 1e-3, "seed {seed}: odometry {odo:?}");
        assert!(truth.y < -0.2, "seed {seed}: slanted right: {truth:?}");
        assert_eq!(sim.robot(r2).collisions(), 0);
        assert_eq!(sim.robot(RobotId::FIRST).collisions(), 0);
    }
}

#[test]
fn a_single_robot_run_is_unchanged_by_the_second_robot_stream() {
    // robot 1 draws from the seed's first stream whatever else is in the
    // world: its sonar readings are the same with or without robot 2 when
    // robot 2 is out of its sight
    let scans = |with_r2: bool| {
        let text = "[[robot]]\nx = 2.0\ny = 2.0\n[[robot]]\nx = 30.0\ny = 30.0\n\
                    [[wall]]\nfrom = [0.0, 0.0]\nto = [4.0, 0.0]\n[[wall]]\nfrom = [4.0, 0.0]\nto = [4.0, 4.0]\n\
                    [[wall]]\nfrom = [4.0, 4.0]\nto = [0.0, 4.0]\n[[wall]]\nfrom = [0.0, 4.0]\nto = [0.0, 0.0]\n";
        let world = World::from_toml_str(text, Path::new("s.toml")).expect("valid");
        let mut sim = Simulation::new(world, RobotModel::h1(), SimConfig::new(9)).expect("free");
        if with_r2 {
            let r2 = sim.add_robot("r2", RobotModel::h2()).expect("free");
            sim.robot_mut(r2).command_wheels(&cmd(100, 100));
        }
        sim.command_wheels(&cmd(100, 120));
        run_for(&mut sim, 2.0);
        (sim.pose(), sim.sonar_scan(), sim.ir_sighting())
    };
    assert_eq!(scans(false), scans(true));
}
