//! Robot 2 of the thesis' cooperation experiment (Fig. 4-10), kinematic and
//! in one process: the target achiever follows robot 1's path from (-4, 0),
//! its wheels slant the path to the right (the motor's odometry does not
//! know), and the checkpoint sensor and the odometry agent's logic correct
//! the pose at the three checkpoints. With the corrections robot 2 stops at
//! the target; without them it ends far from it — the thesis' point.
//! `COOP_DEBUG=1 cargo test -p nerve-target --test cooperate -- --nocapture`
//! prints every frame that shows a tube and every correction applied.

#![allow(clippy::unwrap_used)]

use nerve_checkpoint::appendix_a::Model;
use nerve_checkpoint::bands::Tube;
use nerve_checkpoint::config::SensorConfig;
use nerve_checkpoint::locate::{self, Camera};
use nerve_checkpoint::sensor::{FrameInput, Sensor, SensorSettings};
use nerve_odometry::{DeadReckoning, Settings as OdoSettings};
use nerve_target::{Event, Follower, Phase, Settings};
use shm_schemas::geom::wrap_angle;
use shm_schemas::payloads::{IrSighting, Odometry, ViaKind, ViaPathBuf, ViaPoint};
use std::f64::consts::FRAC_PI_2;
use std::path::Path;

const CHECKPOINTS: [(u8, f64, f64); 3] = [(1, 1.2, 1.2), (2, 6.0, 1.2), (3, 10.8, 1.2)];
const TARGET: (f64, f64) = (12.8, -3.0);

fn camera() -> Camera {
    Camera { width_px: 320.0, hfov_rad: 60f64.to_radians() }
}

/// The path robot 1's map builder makes of the corridor (via points 1.6 m in front).
fn path() -> ViaPathBuf {
    let pts = [
        (1.2, -0.4, ViaKind::Checkpoint, 1, (1.2, 1.2)),
        (6.0, -0.4, ViaKind::Checkpoint, 2, (6.0, 1.2)),
        (10.8, -0.4, ViaKind::Checkpoint, 3, (10.8, 1.2)),
        (12.8, -1.4, ViaKind::TargetApproach, 0, TARGET),
        (12.8, -3.0, ViaKind::Target, 0, TARGET),
    ];
    let mut p = ViaPathBuf::new(1, 0);
    p.points = pts.iter().map(|&(x, y, k, id, lm)| ViaPoint::new([x, y], k, id, [lm.0, lm.1])).collect();
    p
}

/// What the fixed camera shows of the checkpoints from the true pose
/// (pinhole; band centres on whole rows, as the simulator renders them).
fn frame(truth: (f64, f64, f64)) -> Vec<Tube> {
    let f = camera().focal_px();
    CHECKPOINTS
        .iter()
        .filter_map(|&(_, x, y)| {
            let (dx, dy) = (x - truth.0, y - truth.1);
            let a = wrap_angle(dy.atan2(dx) - truth.2);
            let depth = (dx.hypot(dy) - 0.05) * a.cos();
            if a.abs() > 29f64.to_radians() || depth < 0.3 {
                return None;
            }
            let upper = (100.0 - 0.5 * 0.2 * f / depth).round() as f32;
            let lower = (100.0 + 0.5 * 0.2 * f / depth).round() as f32;
            Some(Tube {
                col: (160.0 - f * a.tan()) as f32,
                upper_row: upper,
                lower_row: lower,
                d_px: lower - upper,
                upright: true,
                pixels: (100, 100),
                clipped: false,
            })
        })
        .collect()
}

/// What the IR receiver hears: the nearest checkpoint within 2 m, and
/// which of its transmitters (50° cones, transmitter 0 facing -y) reach the robot.
fn ir(truth: (f64, f64, f64), stamp_ns: u64) -> IrSighting {
    let mut best: Option<(f64, u8, u8)> = None;
    for &(id, x, y) in &CHECKPOINTS {
        let d = (truth.0 - x).hypot(truth.1 - y);
        if d > 2.0 {
            continue;
        }
        let phi = (truth.1 - y).atan2(truth.0 - x);
        let mut mask = 0u8;
        for i in 0..4 {
            if wrap_angle(phi - (-FRAC_PI_2 + f64::from(i) * FRAC_PI_2)).abs() <= 50f64.to_radians() {
                mask |= 1 << i;
            }
        }
        if best.is_none_or(|b| d < b.0) {
            best = Some((d, id, mask));
        }
    }
    match best {
        Some((_, id, tx)) => {
            IrSighting { seq: 1, stamp_ns, seen: 1, checkpoint_id: id, transmitters: tx, reserved: [0; 5] }
        }
        None => IrSighting { seq: 1, stamp_ns, ..Default::default() },
    }
}

struct Run {
    final_distance_m: f64,
    arrived: bool,
    corrections: u32,
    reached: Vec<usize>,
}

fn run(correct: bool) -> Run {
    let config = SensorConfig::parse(
        Path::new("corridor.toml"),
        "[[checkpoint]]\nid = 1\nposition = [1.2, 1.2]\nheading_deg = -90\n\
         [[checkpoint]]\nid = 2\nposition = [6.0, 1.2]\nheading_deg = -90\n\
         [[checkpoint]]\nid = 3\nposition = [10.8, 1.2]\nheading_deg = -90\n",
    )
    .unwrap();
    let mut sensor = Sensor::new(config, Model::pinhole(0.2 * camera().focal_px()));
    let sensing = SensorSettings { correct, ..SensorSettings::default() };
    let start = nerve_odometry::Pose { x: -4.0, y: 0.0, theta: 0.0 };
    let mut odo = DeadReckoning::new(start, OdoSettings::default());
    let mut follower = Follower::new(Settings::default());
    follower.follow(&path()).unwrap();

    let dt = 0.05;
    // the truth, and the motor's own odometry (from its origin)
    let (mut tx, mut ty, mut tth) = (-4.0, 0.0, 0.0);
    let (mut rx, mut ry, mut rth) = (0.0, 0.0, 0.0);
    let (mut v, mut omega) = (0.0, 0.0);
    let mut reached = Vec::new();
    let mut arrived = false;
    for step in 0..8000u64 {
        let stamp = step * 50_000_000;
        // move: the wheels slant the path right by 1.15°/m and go 1 % further than counted
        tth = wrap_angle(tth + omega * dt - 0.02 * v * dt);
        tx += 1.01 * v * dt * tth.cos();
        ty += 1.01 * v * dt * tth.sin();
        rth = wrap_angle(rth + omega * dt);
        rx += v * dt * rth.cos();
        ry += v * dt * rth.sin();
        odo.on_odometry(&Odometry { x: rx, y: ry, theta: rth, v, omega, stamp_ns: stamp }, "motor").unwrap();
        // the camera at 10 Hz
        if step % 2 == 0 {
            let tubes = frame((tx, ty, tth));
            let p = odo.pose();
            let input = FrameInput {
                tubes: &tubes,
                width_px: 320,
                stamp_ns: stamp,
                now_ns: stamp,
                pose: Some(locate::Pose { x: p.x, y: p.y, theta: p.theta }),
                ir: Some(ir((tx, ty, tth), stamp)),
                pan_rad: 0.0,
            };
            let out = sensor.frame(&input, &sensing);
            if std::env::var("COOP_DEBUG").is_ok() && (!tubes.is_empty() || follower.phase() == Phase::Looking) {
                eprintln!(
                    "t {:.1} truth ({tx:.2},{ty:.2},{:.1}) est ({:.2},{:.2},{:.1}) tubes {} ranged {} sightings {:?} corr {:?} rej {:?} phase {:?}",
                    stamp as f64 / 1e9,
                    tth.to_degrees(),
                    p.x,
                    p.y,
                    p.theta.to_degrees(),
                    tubes.len(),
                    out.ranged,
                    out.sightings.iter().map(|s| (s.checkpoint_id, s.from_ir)).collect::<Vec<_>>(),
                    out.correction.map(|c| (c.payload.x, c.payload.y)),
                    out.rejected,
                    follower.phase()
                );
            }
            if let Some(c) = out.correction {
                match odo.apply_correction(&c.payload, "checkpoint") {
                    Ok(a) => {
                        if std::env::var("COOP_DEBUG").is_ok() {
                            let q = odo.pose();
                            eprintln!(
                                "applied {a:?}: now ({:.2},{:.2},{:.1}) truth ({tx:.2},{ty:.2},{:.1})",
                                q.x,
                                q.y,
                                q.theta.to_degrees(),
                                tth.to_degrees()
                            );
                        }
                        follower.correction_seen(c.payload.checkpoint_id)
                    }
                    Err(e) => eprintln!("correction refused: {e}"),
                }
            }
        }
        let p = odo.pose();
        let s = follower.step(&nerve_target::Pose { x: p.x, y: p.y, theta: p.theta }, dt);
        for e in &s.events {
            match e {
                Event::Reached { index, .. } => reached.push(*index),
                Event::Arrived { .. } => arrived = true,
            }
        }
        (v, omega) = (s.v, s.omega);
        if follower.phase() == Phase::Arrived && v == 0.0 {
            break;
        }
    }
    Run { final_distance_m: (tx - TARGET.0).hypot(ty - TARGET.1), arrived, corrections: odo.corrections(), reached }
}

#[test]
fn robot_2_reaches_the_target_with_checkpoints_and_misses_it_without() {
    let with = run(true);
    assert!(with.arrived);
    assert_eq!(with.reached, vec![0, 1, 2, 3]);
    assert!(with.corrections >= 3, "{} corrections", with.corrections);
    assert!(
        with.final_distance_m <= 0.5,
        "with checkpoints robot 2 stopped {:.2} m from the target",
        with.final_distance_m
    );
    let without = run(false);
    eprintln!(
        "with checkpoints: {:.2} m from the target, {} corrections; without: {:.2} m",
        with.final_distance_m, with.corrections, without.final_distance_m
    );
    assert_eq!(without.corrections, 0);
    assert!(
        without.final_distance_m > with.final_distance_m + 0.5,
        "without checkpoints {:.2} m, with {:.2} m",
        without.final_distance_m,
        with.final_distance_m
    );
}
