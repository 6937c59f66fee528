//! Differential drive, wheel slip and odometry drift, collisions.

mod common;

use common::{h1, room, run_for};
use nerve_devices::{DiffDriveGeometry, EncoderReport, Odometry, Pose2, WheelCommand};
use nerve_sim::{NoiseModel, Simulation};

fn cmd(l: i16, r: i16) -> WheelCommand {
    WheelCommand { left_mm_s: l, right_mm_s: r }
}

/// Drives with `c` for `secs`, integrating odometry from the encoder counts
/// every 50 ms as a motor agent would.
fn drive_with_odometry(sim: &mut Simulation, c: WheelCommand, secs: f64) -> Pose2 {
    let mut odo = Odometry::new(DiffDriveGeometry::H1, sim.pose());
    let report = |s: &Simulation| {
        let (left, right) = s.encoder_counts();
        EncoderReport { seq: 0, time_ms: 0, left, right }
    };
    odo.update(&report(sim));
    sim.command_wheels(&c);
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
fn straight_command_moves_forward() {
    let mut sim = h1(room(20.0, 2.0, 10.0, 0.0, ""), 1, NoiseModel::none());
    let odo = drive_with_odometry(&mut sim, cmd(300, 300), 2.0);
    let p = sim.pose();
    // 0.3 m/s for 2 s, minus the 0.3 s ramp at 1 m/s²
    assert!((p.x - 2.0 - 0.555).abs() < 0.01, "x = {}", p.x);
    assert!((p.y - 10.0).abs() < 1e-9 && p.theta.abs() < 1e-9);
    // without noise, odometry is the truth
    assert!((odo.x - p.x).abs() < 2e-3 && (odo.y - p.y).abs() < 2e-3, "{odo:?} vs {p:?}");
    assert_eq!(sim.collisions(), 0);
}

#[test]
fn opposite_wheels_turn_in_place() {
    let mut sim = h1(room(20.0, 10.0, 10.0, 0.0, ""), 1, NoiseModel::none());
    sim.command_wheels(&cmd(-200, 200));
    run_for(&mut sim, 1.0);
    let p = sim.pose();
    assert!(p.theta > 0.5, "turned left: theta = {}", p.theta);
    assert!((p.x - 10.0).abs() < 1e-9 && (p.y - 10.0).abs() < 1e-9);
    sim.command_wheels(&cmd(200, -200));
    run_for(&mut sim, 2.0);
    assert!(sim.pose().theta < 0.0, "turned right: theta = {}", sim.pose().theta);
}

#[test]
fn slip_makes_odometry_drift_from_truth() {
    let mut sim = h1(room(30.0, 2.0, 15.0, 0.0, ""), 7, NoiseModel::default());
    let odo = drive_with_odometry(&mut sim, cmd(400, 400), 20.0);
    let p = sim.pose();
    assert!(p.x > 8.0, "still moved forward: {p:?}");
    let err = (odo.x - p.x).hypot(odo.y - p.y);
    assert!(err > 0.01, "odometry should drift with slip, error {err} m");
    assert!(err < 2.0, "but not absurdly: {err} m");
}

#[test]
fn same_seed_same_run() {
    let run = |seed| {
        let mut sim = h1(room(30.0, 2.0, 15.0, 0.0, ""), seed, NoiseModel::default());
        sim.command_wheels(&cmd(400, 380));
        run_for(&mut sim, 3.0);
        (sim.pose(), sim.sonar_scan())
    };
    assert_eq!(run(3), run(3));
    assert_ne!(run(3).0, run(4).0);
}

#[test]
fn walls_stop_the_robot_and_collisions_are_counted() {
    // wall at x = 4; robot (radius 0.25) starts 1 m away, facing it
    let mut sim = h1(room(4.0, 2.75, 2.0, 0.0, ""), 1, NoiseModel::default());
    sim.command_wheels(&cmd(500, 500));
    let limit = 4.0 - sim.model().radius;
    for _ in 0..500 {
        sim.step();
        assert!(sim.pose().x <= limit + 1e-9, "passed into the wall: {:?}", sim.pose());
    }
    assert!(sim.pose().x > limit - 0.01, "reached the wall: {:?}", sim.pose());
    assert_eq!(sim.collisions(), 1, "one contact, counted once");
    assert!(sim.in_contact());
    // encoders still count while the wheels spin against the wall
    let before = sim.encoder_counts();
    run_for(&mut sim, 0.5);
    assert!(sim.encoder_counts().0 > before.0);

    // back off, hit again: a second collision
    sim.command_wheels(&cmd(-300, -300));
    run_for(&mut sim, 1.0);
    assert!(!sim.in_contact());
    sim.command_wheels(&cmd(300, 300));
    run_for(&mut sim, 3.0);
    assert_eq!(sim.collisions(), 2);
}

#[test]
fn door_lets_the_robot_through_and_boxes_block() {
    // a wall across the room at x = 3 with a 0.9 m door centred at y = 2
    let extra = "[[wall]]\nfrom = [3.0, 0.0]\nto = [3.0, 4.0]\ndoors = [{ at = 2.0, width = 0.9 }]\n\
                 [[box]]\ncenter = [2.0, 0.8]\nsize = [0.4, 0.4]\n";
    let mut sim = h1(room(6.0, 1.0, 2.0, 0.0, extra), 1, NoiseModel::none());
    sim.command_wheels(&cmd(400, 400));
    run_for(&mut sim, 8.0);
    assert!(sim.pose().x > 4.0, "went through the door: {:?}", sim.pose());
    assert_eq!(sim.collisions(), 0);

    // the same run one metre lower meets the box and stops short of it
    let mut sim = h1(room(6.0, 1.0, 0.8, 0.0, extra), 1, NoiseModel::none());
    sim.command_wheels(&cmd(400, 400));
    run_for(&mut sim, 5.0);
    assert!(sim.pose().x <= 1.8 - 0.25 + 1e-9 && sim.pose().x > 1.5, "{:?}", sim.pose());
    assert_eq!(sim.collisions(), 1);
}
