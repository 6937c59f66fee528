//! From a body command (v, ω) to the wheel set-points of a differential
//! drive, and back from wheel speeds.

/// Wheel ground speeds in mm/s for forward speed `v` (m/s) and turn rate
/// `omega` (rad/s, left positive) on a base with wheels `track_m` apart.
/// If a wheel would exceed `wheel_max_mm_s`, both are scaled down together
/// (the curvature is kept).
pub fn wheel_speeds(v: f64, omega: f64, track_m: f64, wheel_max_mm_s: f64) -> (i16, i16) {
    if !(v.is_finite() && omega.is_finite()) {
        return (0, 0);
    }
    let left = (v - omega * track_m / 2.0) * 1000.0;
    let right = (v + omega * track_m / 2.0) * 1000.0;
    let m = left.abs().max(right.abs());
    let k = if m > wheel_max_mm_s && m > 0.0 { wheel_max_mm_s / m } else { 1.0 };
    let q = |x: f64| (x * k).round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
    (q(left), q(right))
}

/// Moves `from` towards `to` by at most `max_step`.
pub fn ramp(from: f64, to: f64, max_step: f64) -> f64 {
    let step = max_step.abs();
    from + (to - from).clamp(-step, step)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wheels() {
        assert_eq!(wheel_speeds(0.2, 0.0, 0.4, 800.0), (200, 200));
        assert_eq!(wheel_speeds(0.0, 1.0, 0.4, 800.0), (-200, 200));
        // 0.8 m/s and a turn: scaled so the faster wheel stays at 800
        let (l, r) = wheel_speeds(0.8, 1.0, 0.4, 800.0);
        assert_eq!(r, 800);
        assert!((f64::from(l) - 800.0 * 0.6 / 1.0).abs() <= 1.0, "{l}");
        assert_eq!(wheel_speeds(f64::NAN, 0.0, 0.4, 800.0), (0, 0));
        assert_eq!(ramp(0.0, 1.0, 0.05), 0.05);
        assert_eq!(ramp(0.5, 0.49, 0.05), 0.49);
    }
}
