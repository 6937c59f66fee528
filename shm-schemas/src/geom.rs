//! Planar geometry shared by the agents, the simulator and the device
//! protocols: a pose, and angles wrapped into (−π, π]. One definition, so
//! that a heading means the same to the odometry, the map, the checkpoint
//! locator, the target follower, the simulator and the motor board's dead
//! reckoning.
//!
//! Not a payload: the payloads keep their own `#[repr(C)]` fields
//! (`Odometry`, `PoseEstimate`, ...) and are converted at the edges.

use std::f64::consts::{PI, TAU};

/// A planar pose: metres and radians, heading counter-clockwise from +x.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
    /// Heading, radians (kept in (−π, π] by whoever turns it: [`wrap_angle`]).
    pub theta: f64,
}

impl Pose {
    /// The pose at (`x`, `y`) heading `theta`.
    pub const fn new(x: f64, y: f64, theta: f64) -> Self {
        Pose { x, y, theta }
    }

    /// Whether all three are finite numbers (not NaN, not infinite).
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }

    /// The distance between the two positions, metres.
    pub fn distance_to(&self, other: &Pose) -> f64 {
        (other.x - self.x).hypot(other.y - self.y)
    }
}

/// Wraps an angle into (−π, π] (NaN stays NaN). The remainder is exact
/// (`%` on floats is), so an angle already in range comes back unchanged.
pub fn wrap_angle(a: f64) -> f64 {
    let a = a % TAU;
    if a <= -PI {
        a + TAU
    } else if a > PI {
        a - TAU
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_wrap_into_the_half_open_turn() {
        assert_eq!(wrap_angle(PI), PI, "π is in range");
        assert_eq!(wrap_angle(-PI), PI, "−π is not: it is π");
        assert_eq!(wrap_angle(0.0), 0.0);
        assert_eq!(wrap_angle(1.0), 1.0, "in range: unchanged, to the bit");
        assert_eq!(wrap_angle(-3.0), -3.0);
        assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(7.0 * TAU + 0.25) - 0.25).abs() < 1e-12);
        assert!((wrap_angle(-7.0 * TAU - 0.25) + 0.25).abs() < 1e-12);
        assert!(wrap_angle(f64::NAN).is_nan());
        assert!(wrap_angle(f64::INFINITY).is_nan(), "no turn is infinite");
    }

    #[test]
    fn every_wrapped_angle_is_in_range_and_the_same_direction() {
        // a sweep over ±20 turns, the steps not a divisor of a turn
        for i in -4000..=4000 {
            let a = f64::from(i) * 0.0317;
            let w = wrap_angle(a);
            assert!(w > -PI && w <= PI, "{a} -> {w}");
            assert!((w.sin() - a.sin()).abs() < 1e-9 && (w.cos() - a.cos()).abs() < 1e-9, "{a} -> {w}");
            assert_eq!(wrap_angle(w), w, "wrapping twice changes nothing: {a}");
        }
    }

    #[test]
    fn a_pose_knows_whether_it_is_finite_and_how_far_another_is() {
        let p = Pose::new(1.0, 2.0, 0.5);
        assert!(p.is_finite());
        assert!(!Pose { x: f64::NAN, ..p }.is_finite());
        assert!(!Pose { theta: f64::INFINITY, ..p }.is_finite());
        assert_eq!(p.distance_to(&Pose::new(4.0, 6.0, -1.0)), 5.0);
        assert_eq!(Pose::default(), Pose::new(0.0, 0.0, 0.0));
    }
}
