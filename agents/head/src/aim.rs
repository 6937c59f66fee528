//! The head's filter, fuzzy rule base and fusion (the actuator pattern of
//! Fig. 2-4, as in `nerve_motor`, for a pan-tilt head).
//!
//! **Filter.** A numeric set-point (`nerve::HeadCommand`) is refused when not
//! finite, outside the head's range (pan ±100°, tilt ±30°) or stale; a
//! linguistic one when its term is unknown or not for the head (speed
//! terms), its intensity is outside 0 … 1, or it is stale.
//!
//! **Rule base** (pan-rate universe `[-r, r]`, tilt-rate universe `[-r, r]`,
//! r = 90°/s the head's slew rate, `τ` = 0.5 s):
//!
//! | command | pan rate is | tilt rate is |
//! |---|---|---|
//! | turn left a little / much | `tri(+0.2r, 0.2r)` / `tri(+0.6r, 0.3r)` | — |
//! | turn right a little / much | `tri(-0.2r, 0.2r)` / `tri(-0.6r, 0.3r)` | — |
//! | look up / look down | — | `tri(±0.3r, 0.3r)` |
//! | look ahead | `tri(-pan/τ, 0.1r)` | `tri(-tilt/τ, 0.1r)` |
//! | stop | `tri(0, 0.1r)` | `tri(0, 0.1r)` |
//!
//! Rules fire with the command's intensity, weighted by the sender's weight,
//! summed and defuzzified by centroid; the linguistic target is the current
//! set-point plus rate × dt. **Fusion** per axis: the weighted mean of the
//! numeric set-points and the linguistic target; an axis nobody speaks about
//! keeps its set-point (the head holds its position when commands stop).

use nerve_motor::filter::{Limits, Refusal, check_age};
use nerve_motor::fuzzy::{Fired, Triangle, centroid};
use nerve_motor::weights::Weights;
use shm_schemas::payloads::{HeadCommand, LinguisticCommand, LinguisticTerm};
use std::collections::BTreeMap;

/// Pan range, rad (±100°).
pub const PAN_MAX: f64 = 100.0 * std::f64::consts::PI / 180.0;
/// Tilt range, rad (±30°).
pub const TILT_MAX: f64 = 30.0 * std::f64::consts::PI / 180.0;
/// Slew rate, rad/s (90°/s).
pub const RATE: f64 = std::f64::consts::FRAC_PI_2;
const TAU: f64 = 0.5;

/// Whether the head handles `term`.
pub fn head_term(t: LinguisticTerm) -> bool {
    !matches!(t, LinguisticTerm::IncreaseSpeed | LinguisticTerm::DecreaseSpeed | LinguisticTerm::GoForward)
}

/// Checks a numeric set-point.
pub fn check_command(c: &HeadCommand, now_ns: u64, l: &Limits) -> Result<(), Refusal> {
    for (what, value, limit) in [("pan", c.pan_rad, PAN_MAX), ("tilt", c.tilt_rad, TILT_MAX)] {
        if !value.is_finite() {
            return Err(Refusal::NotFinite { what, value });
        }
        if value.abs() > limit + 1e-9 {
            return Err(Refusal::OverLimit { what, value, limit });
        }
    }
    check_age(c.stamp_ns, now_ns, l)
}

/// The head's fusion state.
#[derive(Debug, Clone, Default)]
pub struct Aim {
    numeric: BTreeMap<String, HeadCommand>,
    said: BTreeMap<String, (LinguisticTerm, f64, u64)>,
    /// The current set-point (pan, tilt), rad.
    pub target: (f64, f64),
}

impl Aim {
    /// Offers a numeric set-point.
    pub fn offer_command(&mut self, sender: &str, c: &HeadCommand, now_ns: u64, l: &Limits) -> Result<(), Refusal> {
        check_command(c, now_ns, l)?;
        self.said.remove(sender);
        self.numeric.insert(sender.to_owned(), *c);
        Ok(())
    }

    /// Offers a linguistic command.
    pub fn offer_said(&mut self, sender: &str, c: &LinguisticCommand, now_ns: u64, l: &Limits) -> Result<(), Refusal> {
        let term = nerve_motor::filter::check_linguistic(c, now_ns, l, head_term)?;
        self.numeric.remove(sender);
        self.said.insert(sender.to_owned(), (term, f64::from(c.intensity), c.stamp_ns));
        Ok(())
    }

    /// Fuses the fresh commands into a new set-point for a cycle of `dt` s.
    pub fn decide(&mut self, now_ns: u64, dt: f64, l: &Limits, weights: &Weights, default_w: f64) -> (f64, f64) {
        self.numeric.retain(|_, c| now_ns.saturating_sub(c.stamp_ns) <= l.stale_ns);
        self.said.retain(|_, s| now_ns.saturating_sub(s.2) <= l.stale_ns);
        let (pan, tilt) = self.target;
        let (mut pf, mut tf) = (Vec::new(), Vec::new());
        for (sender, (term, intensity, _)) in &self.said {
            let f = |set| Fired { set, strength: *intensity, weight: weights.of(sender, default_w) };
            let toward = |x: f64| Triangle::new((-x / TAU).clamp(-0.9 * RATE, 0.9 * RATE), 0.1 * RATE);
            match term {
                LinguisticTerm::TurnLeftALittle => pf.push(f(Triangle::new(0.2 * RATE, 0.2 * RATE))),
                LinguisticTerm::TurnLeftMuch => pf.push(f(Triangle::new(0.6 * RATE, 0.3 * RATE))),
                LinguisticTerm::TurnRightALittle => pf.push(f(Triangle::new(-0.2 * RATE, 0.2 * RATE))),
                LinguisticTerm::TurnRightMuch => pf.push(f(Triangle::new(-0.6 * RATE, 0.3 * RATE))),
                LinguisticTerm::LookUp => tf.push(f(Triangle::new(0.3 * RATE, 0.3 * RATE))),
                LinguisticTerm::LookDown => tf.push(f(Triangle::new(-0.3 * RATE, 0.3 * RATE))),
                LinguisticTerm::LookAhead => {
                    pf.push(f(toward(pan)));
                    tf.push(f(toward(tilt)));
                }
                LinguisticTerm::Stop => {
                    pf.push(f(Triangle::new(0.0, 0.1 * RATE)));
                    tf.push(f(Triangle::new(0.0, 0.1 * RATE)));
                }
                _ => {}
            }
        }
        let mass = |v: &[Fired]| v.iter().map(|f| f.weight * f.strength).sum::<f64>();
        let axis = |current: f64, fired: &[Fired], pick: fn(&HeadCommand) -> f64, limit: f64| {
            let (mut num, mut den) = (0.0, 0.0);
            for (sender, c) in &self.numeric {
                let w = weights.of(sender, default_w);
                num += w * pick(c);
                den += w;
            }
            if let Some(rate) = centroid(-RATE, RATE, fired) {
                let w = mass(fired);
                num += w * (current + rate * dt);
                den += w;
            }
            let t = if den > 1e-12 { num / den } else { current };
            t.clamp(-limit, limit)
        };
        let new_pan = axis(pan, &pf, |c| c.pan_rad, PAN_MAX);
        let new_tilt = axis(tilt, &tf, |c| c.tilt_rad, TILT_MAX);
        self.target = (new_pan, new_tilt);
        self.target
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOW: u64 = 50_000_000_000;

    #[test]
    fn refuses_out_of_range_and_stale() {
        let l = Limits::H1;
        let mut a = Aim::default();
        let ok = HeadCommand { pan_rad: 0.5, tilt_rad: 0.1, stamp_ns: NOW };
        assert!(a.offer_command("t", &ok, NOW, &l).is_ok());
        assert!(a.offer_command("t", &HeadCommand { pan_rad: 2.0, ..ok }, NOW, &l).is_err());
        assert!(a.offer_command("t", &HeadCommand { tilt_rad: f64::NAN, ..ok }, NOW, &l).is_err());
        assert!(a.offer_command("t", &HeadCommand { stamp_ns: NOW - 1_000_000_000, ..ok }, NOW, &l).is_err());
        let speed = LinguisticCommand::new(LinguisticTerm::IncreaseSpeed, 1.0, NOW);
        assert!(matches!(a.offer_said("t", &speed, NOW, &l), Err(Refusal::NotForThisActuator(_))));
    }

    #[test]
    fn linguistic_pan_and_weighted_targets() {
        let l = Limits::H1;
        let mut a = Aim::default();
        a.offer_said("tracker", &LinguisticCommand::new(LinguisticTerm::TurnLeftMuch, 1.0, NOW), NOW, &l).expect("ok");
        let (pan, tilt) = a.decide(NOW, 0.1, &l, &Weights::default(), 1.0);
        assert!((pan - 0.6 * RATE * 0.1).abs() < 1e-3, "{pan}");
        assert_eq!(tilt, 0.0);
        let mut a = Aim::default();
        a.offer_command("x", &HeadCommand { pan_rad: 1.0, tilt_rad: 0.0, stamp_ns: NOW }, NOW, &l).expect("ok");
        a.offer_command("y", &HeadCommand { pan_rad: -1.0, tilt_rad: 0.3, stamp_ns: NOW }, NOW, &l).expect("ok");
        let (pan, tilt) = a.decide(NOW, 0.1, &l, &Weights::parse("x:3").expect("w"), 1.0);
        assert!((pan - 0.5).abs() < 1e-9 && (tilt - 0.075).abs() < 1e-9);
    }
}
