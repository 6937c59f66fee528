//! nerve-sim: a 2-D world that stands in for the robots H1 and H2.
//!
//! It emulates the robots' hardware so that the very same agent code drives
//! the simulator and the real robot:
//!
//! * [`world`]: strict TOML world files (walls with doors, boxes, coloured
//!   and moving objects, checkpoints and the target, one or more robot
//!   starts with an optional fixed odometry drift);
//! * [`robot`]: the H1 and H2 models and the noise model;
//! * [`sim`]: the deterministic fixed-step core — one world, any number of
//!   robots ([`RobotId`], [`RobotRef`], [`RobotMut`]), differential drive
//!   with wheel slip, collisions of disc robots with the world and with each
//!   other, H2's gripper, ground truth;
//! * [`sensors`]: sonar ring and IR receiver; [`camera`]: 320x240 RGB
//!   rendering into a caller's buffer;
//! * [`pty`] and [`hub`]: each device on its own pseudo-terminal, published
//!   as a symlink, speaking the `nerve-devices` protocols; one hub per robot;
//! * [`truth`]: the ground-truth CSV.
//!
//! Tests and other crates drive a [`Simulation`] step by step; the
//! `nerve-sim` binary (`src/main.rs`) is an SDK agent whose periodic step
//! advances the simulation and serves the devices.
#![warn(missing_docs)]

pub mod camera;
pub mod geom;
pub mod hub;
pub mod pty;
pub mod robot;
pub mod sensors;
pub mod sim;
pub mod truth;
pub mod world;

pub use camera::{CAMERA_FRAME_BYTES, CAMERA_HEIGHT, CAMERA_WIDTH, focal_length_px};
pub use geom::{Segment, Vec2};
pub use hub::DeviceHub;
pub use pty::{DeviceKind, PtyDevice, PtyError, PtyStats};
pub use robot::{NoiseModel, RobotKind, RobotModel};
pub use sim::{Graspable, RobotId, RobotMut, RobotRef, SimConfig, SimError, Simulation, Truth};
pub use truth::{TRUTH_HEADER, TruthError, TruthLog, gripper_word};
pub use world::{RobotStart, World, WorldError};
