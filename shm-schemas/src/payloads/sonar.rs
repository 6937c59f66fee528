//! `nerve::SonarScan`: one reading of H1's ring of 12 sonars, with the
//! per-direction risk the sonar agent estimates from the change of range
//! between two samples (thesis section 4.2.2.1).

use super::Payload;
use serde::Serialize;

/// Number of sonar directions in a [`SonarScan`] (H1's ring).
pub const SONAR_DIRECTIONS: usize = 12;

/// A scan of the sonar ring. Direction `i` points `i * 30°` counter-clockwise
/// from the robot's forward axis (0 ahead, 3 left, 6 behind, 9 right).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::SonarScan")]
pub struct SonarScan {
    /// Scan number from the sonar module (its wrapping counter, unwrapped by the agent).
    pub seq: u64,
    /// CLOCK_MONOTONIC nanoseconds when the scan was received.
    pub stamp_ns: u64,
    /// Range per direction, metres; meaningful only where `valid[i] == 1`.
    pub ranges_m: [f32; SONAR_DIRECTIONS],
    /// Risk per direction, 0 (none) … 1 (collision imminent).
    pub risk: [f32; SONAR_DIRECTIONS],
    /// 1 when direction `i` heard an echo, 0 when it did not (nothing in range).
    pub valid: [u8; SONAR_DIRECTIONS],
    /// Padding, zero.
    pub reserved: [u8; 4],
}

impl SonarScan {
    /// The nearest valid range and its direction, if any echo was heard.
    pub fn nearest(&self) -> Option<(usize, f32)> {
        (0..SONAR_DIRECTIONS)
            .filter(|&i| self.valid[i] == 1 && self.ranges_m[i].is_finite())
            .map(|i| (i, self.ranges_m[i]))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<SonarScan>(), 128);
        assert_eq!(std::mem::align_of::<SonarScan>(), 8);
        assert_eq!(std::mem::offset_of!(SonarScan, ranges_m), 16);
        assert_eq!(std::mem::offset_of!(SonarScan, risk), 64);
        assert_eq!(std::mem::offset_of!(SonarScan, valid), 112);
        assert_eq!(<SonarScan as Payload>::stable_type_name(), "nerve::SonarScan");
    }

    #[test]
    fn nearest_ignores_invalid() {
        let mut s = SonarScan { ranges_m: [5.0; SONAR_DIRECTIONS], ..Default::default() };
        s.ranges_m[2] = 0.1;
        s.ranges_m[4] = 0.7;
        s.valid[4] = 1;
        s.valid[5] = 1;
        assert_eq!(s.nearest(), Some((4, 0.7)));
    }
}
