//! Wheel geometry of H1 and H2 and dead reckoning from encoder counts.
//!
//! The motor DSP board reports cumulative counts per wheel
//! ([`crate::EncoderReport`]); [`Odometry`] turns successive reports into a
//! pose with the usual differential-drive update. The simulator uses the
//! same [`DiffDriveGeometry`] to produce the counts, so host and device agree
//! on units.

use crate::messages::EncoderReport;

/// Planar pose: metres and radians, heading counter-clockwise from +x,
/// normalised to (-π, π]; the pose every agent uses ([`shm_schemas::geom`]).
pub type Pose2 = shm_schemas::geom::Pose;

pub use shm_schemas::geom::wrap_angle;

/// Wheel and encoder geometry of a differential-drive base.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiffDriveGeometry {
    /// Nominal wheel diameter, mm.
    pub wheel_diameter_mm: f64,
    /// Distance between the two wheel contact points, mm.
    pub wheel_base_mm: f64,
    /// Encoder counts per wheel revolution (after quadrature).
    pub counts_per_rev: f64,
}

impl DiffDriveGeometry {
    /// H1: 150 mm wheels, 400 mm apart, 2000 counts per revolution.
    pub const H1: Self = Self { wheel_diameter_mm: 150.0, wheel_base_mm: 400.0, counts_per_rev: 2000.0 };
    /// H2: 125 mm wheels, 350 mm apart, 2000 counts per revolution.
    pub const H2: Self = Self { wheel_diameter_mm: 125.0, wheel_base_mm: 350.0, counts_per_rev: 2000.0 };

    /// Wheel travel per encoder count, mm.
    pub fn mm_per_count(&self) -> f64 {
        std::f64::consts::PI * self.wheel_diameter_mm / self.counts_per_rev
    }
}

/// Dead reckoning from cumulative encoder counts.
#[derive(Debug, Clone)]
pub struct Odometry {
    geometry: DiffDriveGeometry,
    last: Option<(i32, i32)>,
    pose: Pose2,
}

impl Odometry {
    /// Starts at `start`; the first report only sets the reference counts.
    pub fn new(geometry: DiffDriveGeometry, start: Pose2) -> Self {
        Self { geometry, last: None, pose: start }
    }

    /// Integrates one report and returns the new pose estimate. Counter
    /// wrap-around is handled (differences are taken modulo 2³²).
    pub fn update(&mut self, report: &EncoderReport) -> Pose2 {
        if let Some((l0, r0)) = self.last {
            let k = self.geometry.mm_per_count() / 1000.0;
            let dl = f64::from(report.left.wrapping_sub(l0)) * k;
            let dr = f64::from(report.right.wrapping_sub(r0)) * k;
            let ds = 0.5 * (dl + dr);
            let dth = (dr - dl) / (self.geometry.wheel_base_mm / 1000.0);
            let mid = self.pose.theta + 0.5 * dth;
            self.pose.x += ds * mid.cos();
            self.pose.y += ds * mid.sin();
            self.pose.theta = wrap_angle(self.pose.theta + dth);
        }
        self.last = Some((report.left, report.right));
        self.pose
    }

    /// The current estimate.
    pub fn pose(&self) -> Pose2 {
        self.pose
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_and_turn() {
        let g = DiffDriveGeometry::H1;
        let mut o = Odometry::new(g, Pose2::default());
        let rep = |l, r| EncoderReport { seq: 0, time_ms: 0, left: l, right: r };
        o.update(&rep(0, 0));
        let per_m = (1000.0 / g.mm_per_count()).round() as i32;
        let p = o.update(&rep(per_m, per_m));
        assert!((p.x - 1.0).abs() < 1e-3 && p.y.abs() < 1e-9);
        // spin in place a quarter turn: each wheel travels base * π/4
        let quarter = (g.wheel_base_mm * std::f64::consts::FRAC_PI_4 / g.mm_per_count()) as i32;
        let p = o.update(&rep(per_m - quarter, per_m + quarter));
        assert!((p.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-2);
    }

    #[test]
    fn wraps() {
        assert!((wrap_angle(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-12);
    }
}
