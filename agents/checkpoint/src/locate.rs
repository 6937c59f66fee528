//! From what the camera and the IR receiver see to a checkpoint's range and
//! bearing, its identity, and a correction of the robot's pose (thesis
//! section 4.3.2.1: "since the distance and orientation between the robot
//! and checkpoint can be obtained, and the coordinates of checkpoints are
//! already known in advance, the coordinate of the robot can therefore be
//! estimated").
//!
//! **Range and bearing** ([`observe`]). A tube at column `c` of a frame
//! `w` pixels wide lies at the camera angle `a = atan((w/2 − c)/f)`, with
//! `f = (w/2)/tan(hfov/2)` (positive to the left); the robot's bearing adds
//! the head's pan. Appendix A gives the depth `Z` of the tube's near surface
//! along the optical axis; the range to its centre is `Z/cos(a) + radius`.
//!
//! **Identity** ([`identify`]). The IR receiver names the nearest
//! checkpoint (its code) and which transmitters it receives. A fresh IR
//! code names the upright tube whose position, placed with the current
//! pose, falls nearest the code's known position; the target (upside down)
//! is never a checkpoint.
//!
//! **Correction** ([`correct_pose`]). The robot lies at `range` from the
//! known checkpoint, in the direction `φ` from the checkpoint. With the
//! estimated heading `θ`, `φ = θ + bearing + π`, and the position
//! `checkpoint + range·(cos φ, sin φ)` corrects the accumulated error of the
//! position. A single point landmark does not tell the heading; the IR
//! transmitters received bound `φ` to a cone around the direction they face
//! (one transmitter: ±(90° − half angle); two adjacent ones: ±(half angle −
//! 45°)). When `φ` from the estimated heading falls outside that cone, the
//! heading is wrong: `φ` is moved to the nearest edge of the cone and the
//! heading follows, `θ = φ − bearing − π`. (Two checkpoints seen one after
//! the other tell the heading better; the odometry agent does that with
//! the checkpoint positions this agent sends along.)

use crate::appendix_a::{Model, ModelError};
use crate::bands::Tube;
pub use shm_schemas::geom::{Pose, wrap_angle};
use std::f64::consts::{FRAC_PI_2, PI};

/// The camera's geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Frame width, pixels.
    pub width_px: f64,
    /// Horizontal field of view, radians.
    pub hfov_rad: f64,
}

impl Camera {
    /// Focal length, pixels.
    pub fn focal_px(&self) -> f64 {
        (self.width_px / 2.0) / (self.hfov_rad / 2.0).tan()
    }

    /// The angle of image column `col` (continuous, from the left edge)
    /// from the optical axis, radians, positive to the left.
    pub fn angle_of(&self, col: f64) -> f64 {
        ((self.width_px / 2.0 - col) / self.focal_px()).atan()
    }
}

/// A tube measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Range from the camera to the tube's centre, metres.
    pub range_m: f64,
    /// Bearing from the robot's heading, radians, positive left.
    pub bearing_rad: f64,
    /// Depth of the near surface along the optical axis (Appendix A's `Z`), metres.
    pub depth_m: f64,
    /// A checkpoint (upright) or the target.
    pub upright: bool,
}

/// Measures `tube` seen by `camera` with the head panned by `pan_rad`.
pub fn observe(
    tube: &Tube,
    camera: &Camera,
    model: &Model,
    pan_rad: f64,
    radius_m: f64,
) -> Result<Observation, ModelError> {
    let depth = model.distance(f64::from(tube.d_px))?;
    let a = camera.angle_of(f64::from(tube.col));
    Ok(Observation {
        range_m: depth / a.cos().max(0.1) + radius_m,
        bearing_rad: wrap_angle(a + pan_rad),
        depth_m: depth,
        upright: tube.upright,
    })
}

/// Where an observed tube lies in the world, seen from `pose`.
pub fn place(pose: &Pose, obs: &Observation) -> (f64, f64) {
    let a = pose.theta + obs.bearing_rad;
    (pose.x + obs.range_m * a.cos(), pose.y + obs.range_m * a.sin())
}

/// The cone of directions, seen from a checkpoint, in which the robot can
/// be given the transmitters it receives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IrCone {
    /// The direction the received transmitter(s) face, radians, world frame.
    pub centre: f64,
    /// Half width of the cone, radians.
    pub half_width: f64,
}

/// The cone for transmitter mask `transmitters` of a checkpoint whose
/// transmitter 0 faces `heading`, each transmitter covering ±`half_angle`;
/// `None` for no or an impossible pattern.
pub fn ir_cone(heading: f64, transmitters: u8, half_angle: f64) -> Option<IrCone> {
    let m = transmitters & 0x0F;
    let bits: Vec<u8> = (0..4).filter(|i| m & (1 << i) != 0).collect();
    let (sector, pair) = match bits.as_slice() {
        [a] => (f64::from(*a), false),
        [0, 3] => (3.5, true),
        [a, b] if b - a == 1 => (f64::from(*a) + 0.5, true),
        _ => return None,
    };
    let half_width = if pair { half_angle - FRAC_PI_2 / 2.0 } else { FRAC_PI_2 - half_angle };
    Some(IrCone { centre: wrap_angle(heading + sector * FRAC_PI_2), half_width: half_width.max(0.0) })
}

/// A corrected pose and what was corrected.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correction {
    /// The corrected pose.
    pub pose: Pose,
    /// The heading was corrected too (the estimate fell outside the IR cone).
    pub heading_corrected: bool,
    /// The direction from the checkpoint to the robot used, radians.
    pub phi: f64,
}

/// Corrects `estimate` from `obs` of the known checkpoint at `checkpoint`,
/// bounded by the IR `cone` (widened by `margin`) when one is known.
pub fn correct_pose(
    estimate: &Pose,
    checkpoint: (f64, f64),
    obs: &Observation,
    cone: Option<IrCone>,
    margin: f64,
) -> Correction {
    let phi_est = wrap_angle(estimate.theta + obs.bearing_rad + PI);
    let (phi, heading_corrected) = match cone {
        Some(c) => {
            let off = wrap_angle(phi_est - c.centre);
            let lim = c.half_width + margin.max(0.0);
            if off.abs() <= lim { (phi_est, false) } else { (wrap_angle(c.centre + lim.copysign(off)), true) }
        }
        None => (phi_est, false),
    };
    let theta = if heading_corrected { wrap_angle(phi - obs.bearing_rad - PI) } else { estimate.theta };
    Correction {
        pose: Pose { x: checkpoint.0 + obs.range_m * phi.cos(), y: checkpoint.1 + obs.range_m * phi.sin(), theta },
        heading_corrected,
        phi,
    }
}

/// The index of the tube an IR code names: among the upright
/// observations, the one placed nearest `known` from `pose`, if within `gate_m`.
pub fn identify(pose: &Pose, observations: &[Observation], known: (f64, f64), gate_m: f64) -> Option<usize> {
    observations
        .iter()
        .enumerate()
        .filter(|(_, o)| o.upright)
        .map(|(i, o)| {
            let (x, y) = place(pose, o);
            (i, (x - known.0).hypot(y - known.1))
        })
        .filter(|(_, d)| *d <= gate_m)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    const CAM: Camera = Camera { width_px: 320.0, hfov_rad: std::f64::consts::FRAC_PI_3 };

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    /// The tube the simulator's camera would show of a checkpoint at `cp`
    /// seen from `pose` (pinhole, exact).
    fn tube_of(pose: &Pose, cp: (f64, f64), upright: bool) -> Tube {
        let (dx, dy) = (cp.0 - pose.x, cp.1 - pose.y);
        let a = wrap_angle(dy.atan2(dx) - pose.theta);
        let depth = (dx.hypot(dy) - 0.05) * a.cos();
        let f = CAM.focal_px();
        let d = (0.2 * f / depth) as f32;
        let col = (160.0 - f * a.tan()) as f32;
        let (u, l) = if upright { (100.0, 100.0 + d) } else { (100.0 + d, 100.0) };
        Tube { col, upper_row: u, lower_row: l, d_px: d, upright, pixels: (100, 100), clipped: false }
    }

    #[test]
    fn range_and_bearing_through_the_field_of_view() {
        let m = Model::pinhole(0.2 * CAM.focal_px());
        assert!(close(CAM.angle_of(160.0), 0.0, 1e-12));
        assert!(close(CAM.angle_of(0.0), 30f64.to_radians(), 1e-9), "the left edge is hfov/2 to the left");
        let pose = Pose { x: 0.0, y: 0.0, theta: 0.3 };
        for cp in [(2.0, 0.9), (1.5, -0.2), (2.5, 1.5)] {
            let o = observe(&tube_of(&pose, cp, true), &CAM, &m, 0.0, 0.05).unwrap();
            let want = (cp.0.hypot(cp.1), wrap_angle(cp.1.atan2(cp.0) - 0.3));
            assert!(close(o.range_m, want.0, 1e-4) && close(o.bearing_rad, want.1, 1e-4), "{o:?} vs {want:?}");
            let (x, y) = place(&pose, &o);
            assert!(close(x, cp.0, 1e-4) && close(y, cp.1, 1e-4));
        }
        // the head's pan adds to the bearing
        let t = tube_of(&pose, (2.0, 0.9), true);
        let a = observe(&t, &CAM, &m, 0.0, 0.05).unwrap();
        let b = observe(&t, &CAM, &m, 0.5, 0.05).unwrap();
        assert!(close(b.bearing_rad - a.bearing_rad, 0.5, 1e-12));
        assert!(observe(&Tube { d_px: 0.0, ..t }, &CAM, &m, 0.0, 0.05).is_err());
    }

    #[test]
    fn ir_cones() {
        let h = 50f64.to_radians();
        let c = ir_cone(-FRAC_PI_2, 0b0001, h).unwrap();
        assert!(close(c.centre, -FRAC_PI_2, 1e-12) && close(c.half_width, 40f64.to_radians(), 1e-12));
        let c = ir_cone(0.0, 0b0011, h).unwrap();
        assert!(close(c.centre, 45f64.to_radians(), 1e-12) && close(c.half_width, 5f64.to_radians(), 1e-12));
        let c = ir_cone(0.0, 0b1001, h).unwrap();
        assert!(close(c.centre, -45f64.to_radians(), 1e-12));
        assert_eq!(ir_cone(0.0, 0b0101, h), None);
        assert_eq!(ir_cone(0.0, 0, h), None);
    }

    #[test]
    fn a_drifted_position_is_corrected_onto_the_truth() {
        let m = Model::pinhole(0.2 * CAM.focal_px());
        let cp = (6.0, 1.2);
        let truth = Pose { x: 5.0, y: -0.3, theta: 0.4 };
        let obs = observe(&tube_of(&truth, cp, true), &CAM, &m, 0.0, 0.05).unwrap();
        // odometry believes it is 0.6 m off, heading right
        let est = Pose { x: 4.5, y: 0.0, theta: 0.4 };
        // transmitter 0 faces −90° (down the corridor): the robot is within its cone
        let cone = ir_cone(-FRAC_PI_2, 0b0001, 50f64.to_radians());
        let c = correct_pose(&est, cp, &obs, cone, 0.0);
        assert!(!c.heading_corrected);
        assert!(close(c.pose.x, truth.x, 1e-3) && close(c.pose.y, truth.y, 1e-3), "{c:?}");
        assert_eq!(c.pose.theta, est.theta);
    }

    #[test]
    fn a_heading_outside_the_ir_cone_is_pulled_to_its_edge() {
        let m = Model::pinhole(0.2 * CAM.focal_px());
        let cp = (6.0, 1.2);
        // the robot stands straight below the checkpoint, facing it
        let truth = Pose { x: 6.0, y: -0.3, theta: FRAC_PI_2 };
        let obs = observe(&tube_of(&truth, cp, true), &CAM, &m, 0.0, 0.05).unwrap();
        // odometry's heading is 60° off: φ would be 60° outside the transmitter's axis
        let est = Pose { x: 6.0, y: -0.3, theta: FRAC_PI_2 + 60f64.to_radians() };
        let cone = ir_cone(-FRAC_PI_2, 0b0001, 50f64.to_radians());
        let c = correct_pose(&est, cp, &obs, cone, 0.0);
        assert!(c.heading_corrected);
        // pulled back to the cone's edge (40° off the axis): heading 40° off, not 60°
        assert!(close(wrap_angle(c.pose.theta - truth.theta), 40f64.to_radians(), 1e-3), "{c:?}");
        assert!(close((c.pose.x - cp.0).hypot(c.pose.y - cp.1), obs.range_m, 1e-9));
        // without a cone the heading is kept
        assert!(!correct_pose(&est, cp, &obs, None, 0.0).heading_corrected);
    }

    #[test]
    fn the_ir_code_names_the_nearest_upright_tube() {
        let m = Model::pinhole(0.2 * CAM.focal_px());
        let pose = Pose { x: 0.0, y: 0.0, theta: 0.0 };
        let obs: Vec<Observation> = [((2.0, 0.8), true), ((2.0, -0.8), false), ((2.5, -0.5), true)]
            .iter()
            .map(|(cp, up)| observe(&tube_of(&pose, *cp, *up), &CAM, &m, 0.0, 0.05).unwrap())
            .collect();
        assert_eq!(identify(&pose, &obs, (2.5, -0.4), 1.0), Some(2));
        assert_eq!(identify(&pose, &obs, (2.1, 0.7), 1.0), Some(0));
        // the target is never a checkpoint; nothing within the gate
        assert_eq!(identify(&pose, &obs, (2.0, -0.8), 0.2), None);
        assert_eq!(identify(&pose, &obs, (9.0, 9.0), 1.0), None);
    }

    #[test]
    fn wrap_stays_in_range() {
        for a in [-7.0, -PI, 0.0, PI, 3.5 * PI, 100.0] {
            let w = wrap_angle(a);
            assert!(w > -PI - 1e-12 && w <= PI + 1e-12, "{a} -> {w}");
            assert!(close(w.sin(), f64::sin(a), 1e-9) && close(w.cos(), f64::cos(a), 1e-9));
        }
    }
}
