//! Risk estimation of the sonar agent (thesis section 4.2.2.1: "the agent
//! measures the probability of risks at each direction by estimating the
//! difference of the distance between two sample times").
//!
//! For each of the 12 directions, between two scans `dt` apart:
//!
//! * **closing speed** `c = (r_prev - r_now) / dt` (m/s, positive when the
//!   obstacle approaches), smoothed by an exponential filter
//!   `c ← (1-s)·c + s·c_new` (`smoothing` = s). A jump faster than
//!   `max_closing` (3 m/s by default: faster than robot and obstacle can
//!   move together) is a sonar artefact (specular reflection, crosstalk) and
//!   is ignored; the smoothed speed only decays for that sample.
//! * **approach risk** from the time to contact `ttc = r / c`:
//!   `p_approach = clamp(1 - ttc / ttc_horizon, 0, 1)` when `c > 0`, else 0.
//! * **proximity risk** `p_near = clamp((near - r) / (near - min_range), 0, 1)`
//!   — something already close is a risk even when it does not move.
//! * **risk** = `1 - (1 - p_approach)(1 - p_near)` (either may cause a
//!   collision), in 0 … 1.
//!
//! A direction without echo has risk 0 and forgets its history (there is
//! nothing whose distance could change).

/// Number of directions.
pub const DIRECTIONS: usize = nerve_devices::SONAR_COUNT;
/// The sonar's shortest reading, m.
pub const MIN_RANGE_M: f64 = 0.15;

/// Tunable constants of the estimator (parameters of the agent).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RiskParams {
    /// Time to contact at which the approach risk becomes 0, s.
    pub ttc_horizon: f64,
    /// Distance below which proximity alone is a risk, m.
    pub near: f64,
    /// Smoothing factor of the closing speed, 0 < s ≤ 1 (1 = no smoothing).
    pub smoothing: f64,
    /// Closing speeds above this are artefacts, m/s.
    pub max_closing: f64,
}

impl Default for RiskParams {
    fn default() -> Self {
        RiskParams { ttc_horizon: 3.0, near: 0.5, smoothing: 0.5, max_closing: 3.0 }
    }
}

/// Per-direction state of the estimator.
#[derive(Debug, Clone, Default)]
pub struct RiskEstimator {
    last: [Option<f64>; DIRECTIONS],
    closing: [f64; DIRECTIONS],
    last_t: Option<f64>,
    /// samples ignored as artefacts
    pub artefacts: u64,
}

impl RiskEstimator {
    /// A fresh estimator.
    pub fn new() -> Self {
        Self::default()
    }

    /// The smoothed closing speed of each direction, m/s.
    pub fn closing_speeds(&self) -> [f64; DIRECTIONS] {
        self.closing
    }

    /// Feeds one scan taken at `t` seconds (ranges in m, `None` = no echo)
    /// and returns the risk per direction.
    pub fn update(&mut self, t: f64, ranges: &[Option<f64>; DIRECTIONS], p: &RiskParams) -> [f64; DIRECTIONS] {
        let dt = self.last_t.map(|t0| t - t0).filter(|dt| *dt > 1e-3);
        let s = p.smoothing.clamp(0.01, 1.0);
        let mut risk = [0.0; DIRECTIONS];
        for i in 0..DIRECTIONS {
            let Some(r) = ranges[i] else {
                self.last[i] = None;
                self.closing[i] = 0.0;
                continue;
            };
            if let (Some(r0), Some(dt)) = (self.last[i], dt) {
                let c = (r0 - r) / dt;
                if c.abs() > p.max_closing {
                    self.artefacts += 1;
                    self.closing[i] *= 1.0 - s;
                } else {
                    self.closing[i] = (1.0 - s) * self.closing[i] + s * c;
                }
            }
            self.last[i] = Some(r);
            let c = self.closing[i];
            let p_approach = if c > 1e-6 { (1.0 - (r / c) / p.ttc_horizon).clamp(0.0, 1.0) } else { 0.0 };
            let p_near =
                if p.near > MIN_RANGE_M { ((p.near - r) / (p.near - MIN_RANGE_M)).clamp(0.0, 1.0) } else { 0.0 };
            risk[i] = 1.0 - (1.0 - p_approach) * (1.0 - p_near);
        }
        self.last_t = Some(t);
        risk
    }
}

/// Unwraps the module's 16-bit scan counter into a 64-bit sequence number.
#[derive(Debug, Clone, Default)]
pub struct SeqUnwrapper {
    last: Option<u16>,
    value: u64,
    /// scans missing between consecutive received ones
    pub missed: u64,
}

impl SeqUnwrapper {
    /// The 64-bit number of a received 16-bit `seq`.
    pub fn unwrap(&mut self, seq: u16) -> u64 {
        match self.last {
            None => self.value = u64::from(seq),
            Some(l) => {
                let d = seq.wrapping_sub(l);
                if d > 1 && d < 0x8000 {
                    self.missed += u64::from(d) - 1;
                }
                self.value += u64::from(d.max(1));
            }
        }
        self.last = Some(seq);
        self.value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(r: f64) -> [Option<f64>; DIRECTIONS] {
        let mut a = [Some(4.0); DIRECTIONS];
        a[0] = Some(r);
        a[6] = None;
        a
    }

    #[test]
    fn approaching_obstacle_raises_risk_static_does_not() {
        let p = RiskParams { smoothing: 1.0, ..RiskParams::default() };
        let mut e = RiskEstimator::new();
        e.update(0.0, &scan(2.0), &p);
        // ahead: 2.0 → 1.75 m in 0.25 s = 1 m/s closing, ttc 1.75 s
        let r = e.update(0.25, &scan(1.75), &p);
        assert!((r[0] - (1.0 - 1.75 / 3.0)).abs() < 1e-9, "{r:?}");
        assert_eq!(r[3], 0.0, "a static far wall is no risk");
        assert_eq!(r[6], 0.0, "no echo, no risk");
        // receding: no approach risk
        let r = e.update(0.5, &scan(2.0), &p);
        assert_eq!(r[0], 0.0);
    }

    #[test]
    fn near_is_risky_and_artefacts_are_ignored() {
        let p = RiskParams::default();
        let mut e = RiskEstimator::new();
        let r = e.update(0.0, &scan(0.2), &p);
        assert!(r[0] > 0.8, "{r:?}");
        e.update(0.25, &scan(3.0), &p);
        // 3.0 → 0.4 in 0.25 s is 10 m/s: an artefact, not an approach
        e.update(0.5, &scan(0.4), &p);
        assert_eq!(e.artefacts, 2);
        assert!(e.closing_speeds()[0].abs() < 0.5);
    }

    #[test]
    fn seq_unwraps_and_counts_gaps() {
        let mut u = SeqUnwrapper::default();
        assert_eq!(u.unwrap(65534), 65534);
        assert_eq!(u.unwrap(65535), 65535);
        assert_eq!(u.unwrap(1), 65537);
        assert_eq!(u.missed, 1);
    }
}
