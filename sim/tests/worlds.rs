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
