//! The look-around sweep: a list of pan angles the head visits in turn,
//! dwelling at each once it has got there, so that a camera on a pan head
//! sees beside the robot's path (the checkpoint sensor of the cooperation
//! experiment finds the target in the open space on the robot's right this
//! way; thesis section 4.3.3).
//!
//! The sweep is a pure state machine driven by time and, when the head
//! reports it, the measured pan: a step ends `dwell` after the head has
//! settled within `settle` of the set-point. Without head reports it ends
//! after the travel time at `speed` plus `dwell`. Frames taken while the head
//! moves are not trusted by the checkpoint sensor, so the dwell is what gives
//! it still frames.

pub use shm_schemas::geom::wrap_angle;

/// What the sweep needs to know.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepSettings {
    /// Pan angles visited in turn, radians (positive to the left).
    pub pans_rad: Vec<f64>,
    /// How long the head stays still at each angle, ns.
    pub dwell_ns: u64,
    /// Within this of the set-point, the head counts as there, radians.
    pub settle_rad: f64,
    /// Assumed pan speed when the head does not report, rad/s.
    pub speed_rad_s: f64,
}

impl Default for SweepSettings {
    fn default() -> Self {
        Self {
            pans_rad: [0.0f64, -50.0, 0.0, 50.0].iter().map(|d| d.to_radians()).collect(),
            dwell_ns: 600_000_000,
            settle_rad: 2f64.to_radians(),
            speed_rad_s: 90f64.to_radians(),
        }
    }
}

/// Parses `"0,-60,0,60"` (degrees) into radians; at least one finite angle
/// within ±`limit_deg`.
pub fn parse_pans_deg(text: &str, limit_deg: f64) -> Result<Vec<f64>, String> {
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let d: f64 = part.parse().map_err(|_| format!("`{part}` is not a number of degrees (e.g. \"0,-60,0,60\")"))?;
        if !d.is_finite() || d.abs() > limit_deg {
            return Err(format!("pan {d}° is outside ±{limit_deg}°"));
        }
        out.push(d.to_radians());
    }
    if out.is_empty() {
        return Err("give at least one pan angle in degrees, e.g. \"0,-60,0,60\"".into());
    }
    Ok(out)
}

/// The sweep's state.
#[derive(Debug, Clone)]
pub struct Sweep {
    index: usize,
    /// When the current step began.
    started_ns: u64,
    /// When the head settled at the current set-point.
    settled_ns: Option<u64>,
    /// Where the previous set-point was (for the travel-time estimate).
    from_rad: f64,
    steps: u64,
}

impl Sweep {
    /// A sweep starting at the first angle at `now_ns`.
    pub fn new(now_ns: u64) -> Self {
        Self { index: 0, started_ns: now_ns, settled_ns: None, from_rad: 0.0, steps: 0 }
    }

    /// Steps completed so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The set-point at `now_ns`, given the measured pan if the head reports
    /// it (a fresh report), advancing to the next angle when the dwell is over.
    pub fn update(&mut self, s: &SweepSettings, now_ns: u64, measured_pan: Option<f64>) -> f64 {
        if s.pans_rad.is_empty() {
            return 0.0;
        }
        if self.index >= s.pans_rad.len() {
            self.index = 0;
        }
        let target = s.pans_rad[self.index];
        let settled = match measured_pan {
            Some(p) => (p - target).abs() <= s.settle_rad,
            None => {
                let travel_s = (target - self.from_rad).abs() / s.speed_rad_s.max(1e-3);
                now_ns.saturating_sub(self.started_ns) as f64 >= travel_s * 1e9
            }
        };
        match (settled, self.settled_ns) {
            (true, None) => self.settled_ns = Some(now_ns),
            (false, Some(_)) if measured_pan.is_some() => self.settled_ns = None,
            _ => {}
        }
        if self.settled_ns.is_some_and(|t| now_ns.saturating_sub(t) >= s.dwell_ns) {
            self.from_rad = target;
            self.index = (self.index + 1) % s.pans_rad.len();
            self.started_ns = now_ns;
            self.settled_ns = None;
            self.steps += 1;
        }
        s.pans_rad[self.index]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn settings() -> SweepSettings {
        SweepSettings { pans_rad: vec![0.0, -1.0, 1.0], dwell_ns: 1000 * MS, ..SweepSettings::default() }
    }

    #[test]
    fn it_waits_for_the_head_to_settle_then_dwells() {
        let s = settings();
        let mut w = Sweep::new(0);
        assert_eq!(w.update(&s, 0, Some(0.0)), 0.0);
        assert_eq!(w.update(&s, 999 * MS, Some(0.0)), 0.0);
        assert_eq!(w.update(&s, 1000 * MS, Some(0.0)), -1.0, "dwell over: next angle");
        // the head is on its way: no dwell counted
        assert_eq!(w.update(&s, 5000 * MS, Some(-0.5)), -1.0);
        assert_eq!(w.update(&s, 5100 * MS, Some(-0.99)), -1.0);
        assert_eq!(w.update(&s, 6000 * MS, Some(-1.0)), -1.0, "only 900 ms still");
        assert_eq!(w.update(&s, 6100 * MS, Some(-1.0)), 1.0);
        assert_eq!(w.steps(), 2);
    }

    #[test]
    fn a_head_that_moves_away_restarts_the_dwell() {
        let s = settings();
        let mut w = Sweep::new(0);
        w.update(&s, 0, Some(0.0));
        w.update(&s, 500 * MS, Some(0.3)); // pushed away
        assert_eq!(w.update(&s, 1000 * MS, Some(0.0)), 0.0);
        assert_eq!(w.update(&s, 1999 * MS, Some(0.0)), 0.0);
        assert_eq!(w.update(&s, 2000 * MS, Some(0.0)), -1.0);
    }

    #[test]
    fn without_reports_it_allows_the_travel_time() {
        let s = settings();
        let mut w = Sweep::new(0);
        assert_eq!(w.update(&s, 0, None), 0.0);
        assert_eq!(w.update(&s, 1000 * MS, None), -1.0);
        // 1 rad at 90°/s is 637 ms of travel, then 1 s of dwell
        assert_eq!(w.update(&s, 1600 * MS, None), -1.0);
        assert_eq!(w.update(&s, 1700 * MS, None), -1.0);
        assert_eq!(w.update(&s, 2600 * MS, None), -1.0);
        assert_eq!(w.update(&s, 2700 * MS, None), 1.0);
    }

    #[test]
    fn the_angles_parse_with_reasons() {
        let v = parse_pans_deg("0, -60,0,60", 100.0).expect("valid");
        assert_eq!(v.len(), 4);
        assert!((v[1] + 60f64.to_radians()).abs() < 1e-12);
        assert!(parse_pans_deg("", 100.0).expect_err("refused").contains("at least one"));
        assert!(parse_pans_deg("0,abc", 100.0).expect_err("refused").contains("abc"));
        assert!(parse_pans_deg("120", 100.0).expect_err("refused").contains("outside"));
    }
}
