//! The shipped world files load, and the robots start free in them.

use std::path::Path;

use nerve_sim::{NoiseModel, RobotModel, SimConfig, Simulation, World, WorldError};

#[test]
fn test_room_loads_for_both_robots() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/test-room.toml");
    let world = World::load(&path).expect("test-room.toml is valid");
    assert_eq!(world.name, "test-room");
    // the east wall is cut by the door into two pieces
    let east: Vec<_> =
        world.walls.iter().filter(|w| (w.seg.a.x - 6.0).abs() < 1e-9 && (w.seg.b.x - 6.0).abs() < 1e-9).collect();
    assert_eq!(east.len(), 2);
    assert!(world.checkpoints.iter().any(|c| c.target));
    for model in [RobotModel::h1(), RobotModel::h2()] {
        let cfg = SimConfig::new(1).with_noise(NoiseModel::none());
        Simulation::new(world.clone(), model, cfg).expect("start pose is free");
    }
}

#[test]
fn missing_world_file_names_the_path() {
    let err = World::load(Path::new("/nonexistent/room.toml")).expect_err("missing");
    assert!(matches!(err, WorldError::Read { .. }));
    assert!(err.to_string().contains("/nonexistent/room.toml"));
}

#[test]
fn start_inside_an_obstacle_is_refused() {
    let text = "[robot]\nx = 1.0\ny = 1.0\n[[box]]\ncenter = [1.0, 1.0]\nsize = [2.0, 2.0]\n";
    let world = World::from_toml_str(text, Path::new("boxed.toml")).expect("parses");
    let err = Simulation::new(world, RobotModel::h1(), SimConfig::new(1)).expect_err("blocked");
    assert!(err.to_string().contains("boxed.toml"), "{err}");
}

#[test]
fn every_shipped_world_loads_and_its_robots_start_free() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).expect("worlds/") {
        let path = entry.expect("entry").path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let world = World::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let cfg = SimConfig::new(1).with_noise(NoiseModel::none());
        let mut sim =
            Simulation::new(world.clone(), RobotModel::h1(), cfg).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        // every further start takes an H2 (the cooperation's robot 2)
        for i in 1..world.robots.len() {
            sim.add_robot(&format!("robot {}", i + 1), RobotModel::h2())
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
        seen += 1;
    }
    assert!(seen >= 5, "{seen} world files");
}

#[test]
fn the_island_world_has_a_free_standing_box_beside_the_start() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/explore-island.toml");
    let world = World::load(&path).expect("valid");
    let sim =
        Simulation::new(world, RobotModel::h1(), SimConfig::new(1).with_noise(NoiseModel::none())).expect("free start");
    // sonar 9 (right) sees the island 0.6 m from the robot's centre
    let right = sim.sonar_true_ranges()[9].expect("echo");
    assert!((right - (0.6 - 0.25)).abs() < 0.02, "island on the right: {right} m");
    // the island touches no wall: at least 1.5 m of floor all round it
    let island = &sim.world().boxes[0];
    for wall in &sim.world().walls {
        for e in &island.edges {
            for p in [e.a, e.b] {
                assert!(wall.seg.distance_to(p) >= 1.5, "island corner {p:?} near wall {wall:?}");
            }
        }
    }
}
