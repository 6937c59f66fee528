//! The checkpoint sensor of the thesis (section 4.3.2.1, Appendix A) as a
//! library, so that its parts are tested without a robot:
//!
//! * [`appendix_a`]: the distance model `Z = D·f/d + Σ α_k (d−h)^−(k+1)`
//!   and its least-squares fit from calibration samples;
//! * [`bands`]: the two colour bands of a tube in a camera frame, their
//!   pixel distance `d`, the tube's column, which way up it stands;
//! * [`locate`]: range and bearing of a tube, which checkpoint the IR code
//!   names, and the robot's corrected pose;
//! * [`sensor`]: the work on one frame — sightings and the correction to send;
//! * [`config`]: the calibration file and the sensor configuration (camera,
//!   colours, IR cones, known checkpoints), strict TOML.
//!
//! The agent (`nerve-checkpoint`) wires these to its ports; the fit tool
//! (`nerve-checkpoint-fit`) turns a samples file into a calibration file.

#![cfg_attr(test, allow(clippy::unwrap_used))]

pub mod appendix_a;
pub mod bands;
pub mod config;
pub mod locate;
pub mod sensor;
