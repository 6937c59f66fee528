//! The base's decision each control cycle: the latest command of every
//! sender, filtered, fuzzified, weighted and fused; a safety stop wins.
//!
//! **Store.** Each sender (named in the sample header) has at most one
//! numeric command, one linguistic command and one stop; a newer one
//! replaces the older. Commands are used while fresh (age ≤ `stale`) and
//! then dropped. Refused commands never enter the store.
//!
//! **Fuzzy rule base** (linguistic commands; ω universe `[-ω_max, ω_max]`,
//! acceleration universe `[-a_max, a_max]`, triangles written
//! `tri(centre, half-width)`; `v` is the current speed, `τ` = 0.5 s):
//!
//! | rule | if the command is | then ω is | and the acceleration is |
//! |---|---|---|---|
//! | R1 | turn left a little | `tri(+0.2 ω_max, 0.2 ω_max)` | — |
//! | R2 | turn left much | `tri(+0.6 ω_max, 0.3 ω_max)` | — |
//! | R3 | turn right a little | `tri(-0.2 ω_max, 0.2 ω_max)` | — |
//! | R4 | turn right much | `tri(-0.6 ω_max, 0.3 ω_max)` | — |
//! | R5 | go forward | `tri(0, 0.1 ω_max)` | `tri((cruise - v)/τ, 0.1 a_max)` |
//! | R6 | stop | `tri(0, 0.1 ω_max)` | `tri(-v/τ, 0.1 a_max)` |
//! | R7 | increase speed | — | `tri(+0.3 a_max, 0.3 a_max)` |
//! | R8 | decrease speed | — | `tri(-0.3 a_max, 0.3 a_max)` |
//!
//! A rule fires with the command's intensity, its consequent is clipped
//! there and scaled by the sender's weight; the consequents are summed and
//! defuzzified by centroid ([`crate::fuzzy`]). The linguistic speed is
//! `v + a·dt`: a held "increase speed" keeps accelerating, like a foot on
//! the pedal, whatever the senders' or the agent's rates.
//!
//! **Fusion.** Per dimension (v and ω), the target is the weighted mean of
//! every fresh numeric command (weight of its sender) and of the linguistic
//! result (weight Σ sender weight × intensity of the rules that fired on that
//! dimension). A dimension nobody speaks about keeps its current value; when
//! no fresh command carries a positive weight — none at all (dead man), or
//! every fresh sender weighted 0 (e.g. the decision maker gave the foot to
//! a source that died) — the target is zero on both dimensions: the base
//! stops and does not turn.
//!
//! **Safety.** Any active stop (input `stop`) wins over everything: the
//! speed is set to 0 at once (not ramped; the board decelerates at its own
//! limit), and the turn rate too unless every active stop allows turning.
//! A stop holds until its sender releases it (`active = 0`) or, if it gives
//! `hold_ms`, until that long after it was received.
//!
//! **Control.** The applied (v, ω) moves towards the target by at most
//! `accel_max·dt` and `alpha_max·dt` per cycle and never exceeds the limits.

use crate::drive::ramp;
use crate::filter::{Limits, Refusal, check_linguistic, check_numeric};
use crate::fuzzy::{Fired, Triangle, centroid};
use crate::weights::Weights;
use shm_schemas::payloads::{LinguisticCommand, LinguisticTerm, SafetyStop, VelocityCommand};
use std::collections::BTreeMap;

/// Time constant of the "go forward" and "stop" rules, s.
pub const TAU: f64 = 0.5;

/// Whether the base handles `term` (the head's terms are refused).
pub fn base_term(term: LinguisticTerm) -> bool {
    !matches!(term, LinguisticTerm::LookUp | LinguisticTerm::LookDown | LinguisticTerm::LookAhead)
}

#[derive(Debug, Clone, Copy)]
struct Said {
    term: LinguisticTerm,
    intensity: f64,
    stamp_ns: u64,
}

#[derive(Debug, Clone, Copy)]
struct Stop {
    allow_turn: bool,
    until_ns: Option<u64>,
}

/// A fused value on one dimension and the weight it carries: `(value, weight)`.
pub type Vote = (f64, f64);

/// What the fusion decided for one cycle.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    /// Forward speed to apply now, m/s.
    pub v: f64,
    /// Turn rate to apply now, rad/s.
    pub omega: f64,
    /// The fused target speed before ramping, m/s.
    pub target_v: f64,
    /// The fused target turn rate before ramping, rad/s.
    pub target_omega: f64,
    /// The sender whose stop is in force, if any.
    pub stopped_by: Option<String>,
    /// Senders with a fresh command.
    pub sources: usize,
    /// Senders with a fresh command that counts: a positive weight (and,
    /// for a linguistic command, a positive intensity). With none the base
    /// stops.
    pub weighted: usize,
}

/// The fusion state of one base; see the module documentation.
#[derive(Debug, Clone, Default)]
pub struct Fusion {
    numeric: BTreeMap<String, VelocityCommand>,
    said: BTreeMap<String, Said>,
    stops: BTreeMap<String, Stop>,
    v: f64,
    omega: f64,
    /// Speed the "go forward" rule aims at, m/s.
    pub cruise: f64,
}

impl Fusion {
    /// An idle base; "go forward" aims at `cruise` m/s.
    pub fn new(cruise: f64) -> Self {
        Fusion { cruise, ..Default::default() }
    }

    /// The applied (v, ω).
    pub fn applied(&self) -> (f64, f64) {
        (self.v, self.omega)
    }

    /// Offers a numeric command from `sender`; refused ones are not stored.
    pub fn offer_numeric(
        &mut self,
        sender: &str,
        cmd: &VelocityCommand,
        now_ns: u64,
        l: &Limits,
    ) -> Result<(), Refusal> {
        check_numeric(cmd, self.numeric.get(sender), now_ns, l)?;
        // a linguistic command of the same sender is superseded
        self.said.remove(sender);
        self.numeric.insert(sender.to_owned(), *cmd);
        Ok(())
    }

    /// Offers a linguistic command from `sender`.
    pub fn offer_linguistic(
        &mut self,
        sender: &str,
        cmd: &LinguisticCommand,
        now_ns: u64,
        l: &Limits,
    ) -> Result<LinguisticTerm, Refusal> {
        let term = check_linguistic(cmd, now_ns, l, base_term)?;
        self.numeric.remove(sender);
        self.said.insert(sender.to_owned(), Said { term, intensity: f64::from(cmd.intensity), stamp_ns: cmd.stamp_ns });
        Ok(term)
    }

    /// Offers a stop (or its release, `active == 0`) from a safety source.
    /// Stops are never refused: when in doubt, stop.
    pub fn offer_stop(&mut self, sender: &str, stop: &SafetyStop, now_ns: u64) {
        if stop.active == 0 {
            self.stops.remove(sender);
        } else {
            let until_ns = (stop.hold_ms > 0).then(|| now_ns + u64::from(stop.hold_ms) * 1_000_000);
            self.stops.insert(sender.to_owned(), Stop { allow_turn: stop.allow_turn != 0, until_ns });
        }
    }

    fn expire(&mut self, now_ns: u64, l: &Limits) {
        let fresh = |stamp: u64| now_ns.saturating_sub(stamp) <= l.stale_ns;
        self.numeric.retain(|_, c| fresh(c.stamp_ns));
        self.said.retain(|_, s| fresh(s.stamp_ns));
        self.stops.retain(|_, s| s.until_ns.is_none_or(|u| now_ns < u));
    }

    /// The fuzzy rule base's output: `(ω, weight)` and `(acceleration, weight)`,
    /// each `None` when no rule fired on that dimension.
    pub fn linguistic(&self, l: &Limits, weights: &Weights, default_w: f64) -> (Option<Vote>, Option<Vote>) {
        let (wm, am) = (l.omega_max, l.accel_max);
        let (mut turn, mut speed) = (Vec::new(), Vec::new());
        for (sender, s) in &self.said {
            let weight = weights.of(sender, default_w);
            let f = |set| Fired { set, strength: s.intensity, weight };
            let to = |target: f64| Triangle::new(target.clamp(-0.9 * am, 0.9 * am), 0.1 * am);
            match s.term {
                LinguisticTerm::TurnLeftALittle => turn.push(f(Triangle::new(0.2 * wm, 0.2 * wm))),
                LinguisticTerm::TurnLeftMuch => turn.push(f(Triangle::new(0.6 * wm, 0.3 * wm))),
                LinguisticTerm::TurnRightALittle => turn.push(f(Triangle::new(-0.2 * wm, 0.2 * wm))),
                LinguisticTerm::TurnRightMuch => turn.push(f(Triangle::new(-0.6 * wm, 0.3 * wm))),
                LinguisticTerm::GoForward => {
                    turn.push(f(Triangle::new(0.0, 0.1 * wm)));
                    speed.push(f(to((self.cruise - self.v) / TAU)));
                }
                LinguisticTerm::Stop => {
                    turn.push(f(Triangle::new(0.0, 0.1 * wm)));
                    speed.push(f(to(-self.v / TAU)));
                }
                LinguisticTerm::IncreaseSpeed => speed.push(f(Triangle::new(0.3 * am, 0.3 * am))),
                LinguisticTerm::DecreaseSpeed => speed.push(f(Triangle::new(-0.3 * am, 0.3 * am))),
                LinguisticTerm::LookUp | LinguisticTerm::LookDown | LinguisticTerm::LookAhead => {}
            }
        }
        let mass = |v: &[Fired]| v.iter().map(|f| f.weight * f.strength).sum::<f64>();
        let t = centroid(-wm, wm, &turn).map(|x| (x, mass(&turn)));
        let a = centroid(-am, am, &speed).map(|x| (x, mass(&speed)));
        (t, a)
    }

    /// Decides the (v, ω) to apply for a cycle of `dt` seconds.
    pub fn decide(&mut self, now_ns: u64, dt: f64, l: &Limits, weights: &Weights, default_w: f64) -> Decision {
        self.expire(now_ns, l);
        let dt = dt.clamp(1e-3, 1.0);
        let (turn, accel) = self.linguistic(l, weights, default_w);
        let (mut v_num, mut v_den, mut w_num, mut w_den) = (0.0, 0.0, 0.0, 0.0);
        let mut weighted = 0;
        for (sender, c) in &self.numeric {
            let w = weights.of(sender, default_w);
            weighted += usize::from(w > 0.0);
            v_num += w * c.v;
            v_den += w;
            w_num += w * c.omega;
            w_den += w;
        }
        if let Some((a, w)) = accel {
            v_num += w * (self.v + a * dt);
            v_den += w;
        }
        if let Some((omega, w)) = turn {
            w_num += w * omega;
            w_den += w;
        }
        weighted += self.said.iter().filter(|(sender, s)| weights.of(sender, default_w) * s.intensity > 0.0).count();
        let sources = self.numeric.len() + self.said.len();
        // nobody fresh with a positive weight: stop, do not keep the last speed and turn
        let idle = weighted == 0;
        let pick = |num: f64, den: f64, current: f64| {
            if den > 1e-12 {
                num / den
            } else if idle {
                0.0
            } else {
                current
            }
        };
        let mut target_v = pick(v_num, v_den, self.v).clamp(-l.v_max, l.v_max);
        let mut target_omega = pick(w_num, w_den, self.omega).clamp(-l.omega_max, l.omega_max);
        let mut v = ramp(self.v, target_v, l.accel_max * dt);
        let mut omega = ramp(self.omega, target_omega, l.alpha_max * dt);
        let stopped_by = self.stops.keys().next().cloned();
        if stopped_by.is_some() {
            target_v = 0.0;
            v = 0.0;
            if self.stops.values().any(|s| !s.allow_turn) {
                target_omega = 0.0;
                omega = 0.0;
            }
        }
        self.v = v;
        self.omega = omega;
        Decision { v, omega, target_v, target_omega, stopped_by, sources, weighted }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOW: u64 = 100_000_000_000;

    fn say(term: LinguisticTerm) -> LinguisticCommand {
        LinguisticCommand::new(term, 1.0, NOW)
    }

    #[test]
    fn conflicting_linguistic_commands_fuse_by_weight() {
        let l = Limits::H1;
        let mut f = Fusion::new(0.3);
        f.offer_linguistic("wall-follow", &say(LinguisticTerm::TurnLeftMuch), NOW, &l).expect("ok");
        f.offer_linguistic("tracker", &say(LinguisticTerm::TurnRightALittle), NOW, &l).expect("ok");
        let weights = Weights::parse("wall-follow:1,tracker:2").expect("weights");
        let d = f.decide(NOW, 0.05, &l, &weights, 1.0);
        // centre of sums: left-much area 1 × 0.3 ω_max at +0.6 ω_max,
        // right-a-little area 2 × 0.2 ω_max at -0.2 ω_max
        let expect = (0.3 * 0.6 - 0.4 * 0.2) / 0.7 * l.omega_max;
        assert!((d.target_omega - expect).abs() < 2e-3, "{} vs {expect}", d.target_omega);
        assert!((d.target_omega - 0.2857).abs() < 2e-3);
        // nobody spoke about speed: it stays 0; ω is ramped at alpha_max
        assert_eq!(d.target_v, 0.0);
        assert!((d.omega - l.alpha_max * 0.05).abs() < 1e-9);

        // weights change at run time: the tracker now counts 4×
        let weights = Weights::parse("wall-follow:1,tracker:8").expect("weights");
        let d = f.decide(NOW, 0.05, &l, &weights, 1.0);
        let expect = (0.3 * 0.6 - 1.6 * 0.2) / 1.9 * l.omega_max;
        assert!((d.target_omega - expect).abs() < 2e-3, "{} vs {expect}", d.target_omega);
        assert!(d.target_omega < 0.0, "the heavier sender now wins: turn right");
    }

    #[test]
    fn numeric_and_linguistic_sources_are_weighted() {
        let l = Limits::H1;
        let mut f = Fusion::new(0.3);
        f.offer_numeric("planner", &VelocityCommand { v: 0.4, omega: 0.0, stamp_ns: NOW }, NOW, &l).expect("ok");
        f.offer_numeric("joystick", &VelocityCommand { v: 0.1, omega: 1.0, stamp_ns: NOW }, NOW, &l).expect("ok");
        let w = Weights::parse("planner:3").expect("w");
        let d = f.decide(NOW, 0.05, &l, &w, 1.0);
        assert!((d.target_v - (3.0 * 0.4 + 0.1) / 4.0).abs() < 1e-9);
        assert!((d.target_omega - 0.25).abs() < 1e-9);
        assert_eq!(d.sources, 2);
    }

    #[test]
    fn increase_speed_accelerates_and_stop_brakes() {
        let l = Limits::H1;
        let mut f = Fusion::new(0.3);
        let w = Weights::default();
        let mut t = NOW;
        for _ in 0..20 {
            t += 50_000_000;
            f.offer_linguistic("a", &LinguisticCommand::new(LinguisticTerm::IncreaseSpeed, 1.0, t), t, &l).expect("ok");
            f.decide(t, 0.05, &l, &w, 1.0);
        }
        // about 0.3 m/s² for 1 s
        let (v, _) = f.applied();
        assert!((v - 0.3).abs() < 0.02, "{v}");
        for _ in 0..40 {
            t += 50_000_000;
            f.offer_linguistic("a", &LinguisticCommand::new(LinguisticTerm::Stop, 1.0, t), t, &l).expect("ok");
            f.decide(t, 0.05, &l, &w, 1.0);
        }
        assert!(f.applied().0 < 0.05, "{:?}", f.applied());
    }

    #[test]
    fn safety_stop_overrides_every_source() {
        let l = Limits::H1;
        let mut f = Fusion::new(0.3);
        let w = Weights::parse("planner:100").expect("w");
        let mut t = NOW;
        for _ in 0..20 {
            t += 50_000_000;
            f.offer_numeric("planner", &VelocityCommand { v: 0.5, omega: 0.5, stamp_ns: t }, t, &l).expect("ok");
            f.offer_linguistic("wf", &LinguisticCommand::new(LinguisticTerm::IncreaseSpeed, 1.0, t), t, &l)
                .expect("ok");
            f.decide(t, 0.05, &l, &w, 1.0);
        }
        assert!(f.applied().0 > 0.4);
        // stop, but turning allowed (the thesis' safety monitor)
        f.offer_stop("safety", &SafetyStop { active: 1, allow_turn: 1, ..Default::default() }, t);
        t += 50_000_000;
        f.offer_numeric("planner", &VelocityCommand { v: 0.5, omega: 0.5, stamp_ns: t }, t, &l).expect("ok");
        let d = f.decide(t, 0.05, &l, &w, 1.0);
        assert_eq!((d.v, d.target_v), (0.0, 0.0));
        assert!(d.omega > 0.4);
        assert_eq!(d.stopped_by.as_deref(), Some("safety"));
        // a full stop from a second source: nothing moves
        f.offer_stop("bumper", &SafetyStop { active: 1, allow_turn: 0, hold_ms: 200, ..Default::default() }, t);
        let d = f.decide(t, 0.05, &l, &w, 1.0);
        assert_eq!((d.v, d.omega), (0.0, 0.0));
        // releases: the bumper's by time, the safety's by message
        f.offer_stop("safety", &SafetyStop::default(), t);
        t += 300_000_000;
        f.offer_numeric("planner", &VelocityCommand { v: 0.5, omega: 0.5, stamp_ns: t }, t, &l).expect("ok");
        let d = f.decide(t, 0.05, &l, &w, 1.0);
        assert_eq!(d.stopped_by, None);
        assert!(d.v > 0.0);
    }

    #[test]
    fn stale_commands_are_dropped_and_the_base_stops() {
        let l = Limits::H1;
        let mut f = Fusion::new(0.3);
        let w = Weights::default();
        f.offer_numeric("a", &VelocityCommand { v: 0.3, omega: 0.0, stamp_ns: NOW }, NOW, &l).expect("ok");
        let d = f.decide(NOW, 0.05, &l, &w, 1.0);
        assert_eq!(d.target_v, 0.3);
        // 600 ms later the command is stale: dead man, target 0
        let d = f.decide(NOW + 600_000_000, 0.05, &l, &w, 1.0);
        assert_eq!((d.target_v, d.sources), (0.0, 0));
        // a stale command is refused outright
        let old = VelocityCommand { v: 0.3, omega: 0.0, stamp_ns: NOW };
        assert!(matches!(f.offer_numeric("a", &old, NOW + 600_000_000, &l), Err(Refusal::Stale { .. })));
        // an impractical one too, and it leaves no trace
        let fast = VelocityCommand { v: 3.0, omega: 0.0, stamp_ns: NOW + 600_000_000 };
        assert!(f.offer_numeric("b", &fast, NOW + 600_000_000, &l).is_err());
        assert_eq!(f.decide(NOW + 600_000_000, 0.05, &l, &w, 1.0).sources, 0);
    }

    #[test]
    fn fresh_sources_all_weighted_zero_stop_the_base() {
        let l = Limits::H1;
        let mut f = Fusion::new(0.3);
        // the tracker drives alone (the decision maker's `hold`), the others silenced
        let w = Weights::parse("tracker:1,safety:0,wall-follow:0").expect("w");
        let mut t = NOW;
        let cmd = |v, omega, stamp_ns| VelocityCommand { v, omega, stamp_ns };
        for _ in 0..40 {
            t += 50_000_000;
            f.offer_numeric("tracker", &cmd(0.3, 0.5, t), t, &l).expect("ok");
            f.offer_numeric("safety", &cmd(0.2, 0.0, t), t, &l).expect("ok");
            f.decide(t, 0.05, &l, &w, 1.0);
        }
        let (v, omega) = f.applied();
        assert!(v > 0.25 && omega > 0.45, "driving: {v} {omega}");
        // the tracker dies: only the safety monitor (weight 0) and a
        // linguistic source (weight 0) stay fresh; its last command goes stale
        t += l.stale_ns + 1;
        for _ in 0..40 {
            t += 50_000_000;
            f.offer_numeric("safety", &cmd(0.2, 0.0, t), t, &l).expect("ok");
            f.offer_linguistic("wall-follow", &LinguisticCommand::new(LinguisticTerm::TurnLeftMuch, 1.0, t), t, &l)
                .expect("ok");
            let d = f.decide(t, 0.05, &l, &w, 1.0);
            assert_eq!((d.target_v, d.target_omega), (0.0, 0.0), "a weight-0 source keeps it going: {d:?}");
            assert_eq!((d.sources, d.weighted), (2, 0));
        }
        assert_eq!(f.applied(), (0.0, 0.0), "ramped down to a standstill");
        // a linguistic command of intensity 0 does not count either
        f.offer_linguistic("joystick", &LinguisticCommand::new(LinguisticTerm::TurnLeftMuch, 0.0, t), t, &l)
            .expect("ok");
        assert_eq!(f.decide(t, 0.05, &l, &w, 1.0).weighted, 0);
        // a source with a positive weight drives again
        f.offer_numeric("tracker", &cmd(0.1, 0.0, t), t, &l).expect("ok");
        let d = f.decide(t, 0.05, &l, &w, 1.0);
        assert_eq!((d.target_v, d.weighted), (0.1, 1));
    }
}
