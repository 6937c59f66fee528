//! The filter of the actuator pattern (thesis Fig. 2-4: "the filter receives
//! and blocks out the improper command"): it refuses a command that is
//!
//! * **not finite** (NaN or infinite speed or turn rate);
//! * **over the limits** of the base (`|v| > v_max`, `|ω| > omega_max`);
//! * an **acceleration over the limit**: compared with the same sender's
//!   previous accepted command, `|Δv| / Δt > accel_refuse` or
//!   `|Δω| / Δt > alpha_refuse` (Δt from the commands' stamps) — a source
//!   that jumps like that is broken or confused. (The controller then ramps
//!   whatever it accepts to the board's own acceleration limit.)
//! * **stale**: made longer than `stale` ago (by its stamp), or **from the
//!   future** (stamped more than `future` ahead of now: a wrong clock);
//! * linguistic: an **unknown term** code, an intensity outside 0 … 1, or a
//!   term meant for another actuator (the head's `look up` sent to the base).
//!
//! Refusals are returned as [`Refusal`], whose message says what to fix.

use shm_schemas::payloads::{LinguisticCommand, LinguisticTerm, VelocityCommand};

/// Limits of a base and of the filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Largest |forward speed|, m/s.
    pub v_max: f64,
    /// Largest |turn rate|, rad/s.
    pub omega_max: f64,
    /// Acceleration the controller ramps with, m/s² (the board's limit).
    pub accel_max: f64,
    /// Angular acceleration the controller ramps with, rad/s².
    pub alpha_max: f64,
    /// A sender's commands implying more than this acceleration are refused, m/s².
    pub accel_refuse: f64,
    /// ... or more than this angular acceleration, rad/s².
    pub alpha_refuse: f64,
    /// Commands older than this are refused (and dropped when they age), ns.
    pub stale_ns: u64,
    /// Commands stamped more than this ahead of now are refused, ns.
    pub future_ns: u64,
}

impl Limits {
    /// H1: 0.8 m/s, 2 rad/s, ramps 1 m/s² and 4 rad/s²; refuses jumps over 5 m/s² or 20 rad/s²; stale after 500 ms.
    pub const H1: Limits = Limits {
        v_max: 0.8,
        omega_max: 2.0,
        accel_max: 1.0,
        alpha_max: 4.0,
        accel_refuse: 5.0,
        alpha_refuse: 20.0,
        stale_ns: 500_000_000,
        future_ns: 100_000_000,
    };
    /// H2: 0.6 m/s, 2 rad/s, ramps 0.8 m/s².
    pub const H2: Limits = Limits { v_max: 0.6, accel_max: 0.8, ..Limits::H1 };
}

/// Why a command was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Refusal {
    /// NaN or infinite.
    #[error("not a finite number ({what} = {value}); send finite values")]
    NotFinite {
        /// which field
        what: &'static str,
        /// its value
        value: f64,
    },
    /// Beyond what the hardware can do.
    #[error(
        "{what} = {value:.3} is over the limit {limit:.3}; send at most the limit (parameters `v_max`, `omega_max`)"
    )]
    OverLimit {
        /// which field
        what: &'static str,
        /// its value
        value: f64,
        /// the limit
        limit: f64,
    },
    /// Jumps too fast from the sender's previous command.
    #[error("{what} implies an acceleration of {value:.2} over the limit {limit:.2}; change commands gradually")]
    Acceleration {
        /// which field
        what: &'static str,
        /// implied acceleration
        value: f64,
        /// the limit
        limit: f64,
    },
    /// Too old.
    #[error(
        "stale: made {age_ms} ms ago, the limit is {limit_ms} ms (parameter `stale_ms`); stamp commands when sending"
    )]
    Stale {
        /// age
        age_ms: u64,
        /// limit
        limit_ms: u64,
    },
    /// Stamped in the future.
    #[error("stamped {ahead_ms} ms in the future; stamp commands with CLOCK_MONOTONIC")]
    FromTheFuture {
        /// how far ahead
        ahead_ms: u64,
    },
    /// An unknown linguistic term code.
    #[error("unknown linguistic term code {0}; known: {known}", known = LinguisticTerm::known_phrases().join(", "))]
    UnknownTerm(u32),
    /// Intensity outside 0 … 1.
    #[error("intensity {0} is outside 0 … 1")]
    BadIntensity(f32),
    /// A term this actuator does not handle.
    #[error("\"{0}\" is not a command for this actuator")]
    NotForThisActuator(LinguisticTerm),
}

/// Refuses a stamp that is stale or from the future.
pub fn check_age(stamp_ns: u64, now_ns: u64, l: &Limits) -> Result<(), Refusal> {
    if stamp_ns > now_ns + l.future_ns {
        return Err(Refusal::FromTheFuture { ahead_ms: (stamp_ns - now_ns) / 1_000_000 });
    }
    let age = now_ns.saturating_sub(stamp_ns);
    if age > l.stale_ns {
        return Err(Refusal::Stale { age_ms: age / 1_000_000, limit_ms: l.stale_ns / 1_000_000 });
    }
    Ok(())
}

/// Checks a numeric command; `previous` is the same sender's last accepted one.
pub fn check_numeric(
    cmd: &VelocityCommand,
    previous: Option<&VelocityCommand>,
    now_ns: u64,
    l: &Limits,
) -> Result<(), Refusal> {
    for (what, value) in [("v", cmd.v), ("omega", cmd.omega)] {
        if !value.is_finite() {
            return Err(Refusal::NotFinite { what, value });
        }
    }
    if cmd.v.abs() > l.v_max + 1e-9 {
        return Err(Refusal::OverLimit { what: "v", value: cmd.v, limit: l.v_max });
    }
    if cmd.omega.abs() > l.omega_max + 1e-9 {
        return Err(Refusal::OverLimit { what: "omega", value: cmd.omega, limit: l.omega_max });
    }
    check_age(cmd.stamp_ns, now_ns, l)?;
    if let Some(p) = previous.filter(|p| cmd.stamp_ns > p.stamp_ns) {
        let dt = ((cmd.stamp_ns - p.stamp_ns) as f64 / 1e9).max(1e-3);
        let a = (cmd.v - p.v).abs() / dt;
        if a > l.accel_refuse {
            return Err(Refusal::Acceleration { what: "v", value: a, limit: l.accel_refuse });
        }
        let alpha = (cmd.omega - p.omega).abs() / dt;
        if alpha > l.alpha_refuse {
            return Err(Refusal::Acceleration { what: "omega", value: alpha, limit: l.alpha_refuse });
        }
    }
    Ok(())
}

/// Checks a linguistic command; `accepts` says which terms this actuator handles.
pub fn check_linguistic(
    cmd: &LinguisticCommand,
    now_ns: u64,
    l: &Limits,
    accepts: impl Fn(LinguisticTerm) -> bool,
) -> Result<LinguisticTerm, Refusal> {
    let term = cmd.term().ok_or(Refusal::UnknownTerm(cmd.term))?;
    if !accepts(term) {
        return Err(Refusal::NotForThisActuator(term));
    }
    if !cmd.intensity.is_finite() || !(0.0..=1.0).contains(&cmd.intensity) {
        return Err(Refusal::BadIntensity(cmd.intensity));
    }
    check_age(cmd.stamp_ns, now_ns, l)?;
    Ok(term)
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOW: u64 = 10_000_000_000;

    fn vc(v: f64, omega: f64, stamp_ns: u64) -> VelocityCommand {
        VelocityCommand { v, omega, stamp_ns }
    }

    #[test]
    fn impractical_numeric_commands_are_refused() {
        let l = Limits::H1;
        assert!(check_numeric(&vc(0.3, 0.1, NOW), None, NOW, &l).is_ok());
        assert!(matches!(check_numeric(&vc(f64::NAN, 0.0, NOW), None, NOW, &l), Err(Refusal::NotFinite { .. })));
        assert!(matches!(check_numeric(&vc(0.0, f64::INFINITY, NOW), None, NOW, &l), Err(Refusal::NotFinite { .. })));
        assert!(matches!(check_numeric(&vc(1.5, 0.0, NOW), None, NOW, &l), Err(Refusal::OverLimit { what: "v", .. })));
        assert!(matches!(
            check_numeric(&vc(0.0, -3.0, NOW), None, NOW, &l),
            Err(Refusal::OverLimit { what: "omega", .. })
        ));
        // 0 → 0.8 m/s in 10 ms is 80 m/s²
        let prev = vc(0.0, 0.0, NOW - 10_000_000);
        assert!(matches!(
            check_numeric(&vc(0.8, 0.0, NOW), Some(&prev), NOW, &l),
            Err(Refusal::Acceleration { what: "v", .. })
        ));
        // the same change over a second is fine
        let prev = vc(0.0, 0.0, NOW - 1_000_000_000);
        assert!(check_numeric(&vc(0.8, 0.0, NOW), Some(&prev), NOW, &l).is_ok());
    }

    #[test]
    fn stale_and_future_commands_are_refused() {
        let l = Limits::H1;
        let e = check_numeric(&vc(0.1, 0.0, NOW - 2_000_000_000), None, NOW, &l).expect_err("stale");
        assert_eq!(e, Refusal::Stale { age_ms: 2000, limit_ms: 500 });
        assert!(e.to_string().contains("stale_ms"));
        assert!(matches!(
            check_numeric(&vc(0.1, 0.0, NOW + 5_000_000_000), None, NOW, &l),
            Err(Refusal::FromTheFuture { ahead_ms: 5000 })
        ));
        assert!(matches!(check_numeric(&vc(0.1, 0.0, 0), None, NOW, &l), Err(Refusal::Stale { .. })));
    }

    #[test]
    fn linguistic_checks() {
        let l = Limits::H1;
        let all = |_| true;
        let c = LinguisticCommand::new(LinguisticTerm::TurnLeftMuch, 1.0, NOW);
        assert_eq!(check_linguistic(&c, NOW, &l, all), Ok(LinguisticTerm::TurnLeftMuch));
        let bad = LinguisticCommand { term: 99, intensity: 1.0, stamp_ns: NOW };
        let e = check_linguistic(&bad, NOW, &l, all).expect_err("unknown");
        assert!(e.to_string().contains("turn right a little"), "{e}");
        let nan = LinguisticCommand { intensity: f32::NAN, ..c };
        assert!(matches!(check_linguistic(&nan, NOW, &l, all), Err(Refusal::BadIntensity(_))));
        let old = LinguisticCommand { stamp_ns: NOW - 600_000_000, ..c };
        assert!(matches!(check_linguistic(&old, NOW, &l, all), Err(Refusal::Stale { .. })));
        let head = LinguisticCommand::new(LinguisticTerm::LookUp, 1.0, NOW);
        assert!(matches!(
            check_linguistic(&head, NOW, &l, |t| t != LinguisticTerm::LookUp),
            Err(Refusal::NotForThisActuator(LinguisticTerm::LookUp))
        ));
    }
}
