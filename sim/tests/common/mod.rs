//! Helpers shared by the simulator's integration tests.
#![allow(dead_code)]

use std::path::Path;

use nerve_sim::{NoiseModel, RobotModel, SimConfig, Simulation, World};

/// A square room `size` m wide with its corner at the origin, robot at
/// `(x, y, heading_deg)`, plus `extra` TOML.
pub fn room(size: f64, x: f64, y: f64, heading_deg: f64, extra: &str) -> World {
    let s = size;
    let text = format!(
        "[robot]\nx = {x}\ny = {y}\nheading_deg = {heading_deg}\n\
         [[wall]]\nfrom = [0.0, 0.0]\nto = [{s}, 0.0]\n\
         [[wall]]\nfrom = [{s}, 0.0]\nto = [{s}, {s}]\n\
         [[wall]]\nfrom = [{s}, {s}]\nto = [0.0, {s}]\n\
         [[wall]]\nfrom = [0.0, {s}]\nto = [0.0, 0.0]\n{extra}"
    );
    World::from_toml_str(&text, Path::new("test-world.toml")).expect("test world is valid")
}

/// An H1 simulation of `world`.
pub fn h1(world: World, seed: u64, noise: NoiseModel) -> Simulation {
    Simulation::new(world, RobotModel::h1(), SimConfig::new(seed).with_noise(noise)).expect("start pose is free")
}

/// Steps `sim` for `secs` simulated seconds.
pub fn run_for(sim: &mut Simulation, secs: f64) {
    let n = (secs / sim.dt()).round() as u64;
    for _ in 0..n {
        sim.step();
    }
}
