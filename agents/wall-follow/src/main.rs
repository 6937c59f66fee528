//! `wall-follow`: the wall follower (thesis section 4.2.2.3). Periodic
//! (default every 100 ms): on the newest scan of input `scan`
//! (`nerve::SonarScan`) it sends on output `cmd` (`nerve::VelocityCommand`)
//! a command that keeps `target` metres from the wall and raises the speed
//! (algorithm in the library, `nerve_wall_follow`).
//!
//! When the scans stop for `scan_timeout_ms` it sends nothing (the motor's
//! dead man stops the robot if no other source speaks) and starts again
//! from `v_min` when they come back. After being suspended (a gap of more
//! than three periods) it also starts again from `v_min`.

use agent_sdk::params::{Declare, in_range, in_range_above_zero};
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use nerve_wall_follow::{Settings, WallSide, follow};
use shm_schemas::payloads::{SonarScan, VelocityCommand};
use std::time::Duration;

/// The farthest wall to keep to, m: beyond it the sonar sees no wall.
const TARGET_MAX: f32 = 2.0;
/// The fastest speed, m/s: the board's limit.
const V_MAX: f32 = 0.8;
/// The largest speed-up rate, m/s²: the motor refuses jumps over 5.
const ACCEL_MAX: f32 = 5.0;
/// Scan timeout bounds, ms: under 100 ms a scan period would count as
/// silence; over 10 s the robot would follow a wall it no longer sees.
const TIMEOUT_MS: std::ops::RangeInclusive<u64> = 100..=10_000;

/// The follower's parameters, each number bounded above and below.
struct Params {
    target: Param<f32>,
    v_max: Param<f32>,
    accel: Param<f32>,
    side: Param<String>,
    timeout_ms: Param<u64>,
}

impl Params {
    fn declare(d: &mut impl Declare) -> Self {
        let s = Settings::default();
        Params {
            target: d.checked("target", s.target, |v| in_range_above_zero("target", *v, TARGET_MAX, "m")),
            v_max: d.checked("v_max", s.v_max, |v| in_range_above_zero("v_max", *v, V_MAX, "m/s")),
            accel: d.checked("accel", s.accel, |v| in_range_above_zero("accel", *v, ACCEL_MAX, "m/s²")),
            side: d.checked("side", "auto".to_owned(), |v| match v.as_str() {
                "auto" | "left" | "right" => Ok(()),
                _ => Err("side is auto, left or right".into()),
            }),
            timeout_ms: d.checked("scan_timeout_ms", 1000u64, |v| in_range("scan_timeout_ms", *v, &TIMEOUT_MS, "ms")),
        }
    }
}

struct WallFollow {
    scan: Input<SonarScan>,
    cmd: Output<VelocityCommand>,
    target: Param<f32>,
    v_max: Param<f32>,
    accel: Param<f32>,
    side: Param<String>,
    timeout_ms: Param<u64>,
    last_scan: Option<(u64, SonarScan)>,
    last_step_ns: Option<u64>,
    rising: f32,
    wall: Option<WallSide>,
    silent: bool,
    sent: Option<(f32, f32, u64)>,
}

/// Speed changes sent are limited to this, m/s² (the motor refuses jumps over 5).
const ACCEL: f32 = 3.0;
/// Turn-rate changes are limited to this, rad/s² (the motor refuses jumps over 20).
const ALPHA: f32 = 12.0;

fn slew(from: f32, to: f32, rate: f32, dt: f32) -> f32 {
    let d = rate * dt.max(0.0);
    to.clamp(from - d, from + d)
}

impl Agent for WallFollow {
    const KIND: &'static str = "wall-follow";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(100))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let scan = setup.input("scan")?;
        let cmd = setup.output("cmd")?;
        let Params { target, v_max, accel, side, timeout_ms } = Params::declare(setup);
        Ok(WallFollow {
            scan,
            cmd,
            target,
            v_max,
            accel,
            side,
            timeout_ms,
            last_scan: None,
            last_step_ns: None,
            rising: 0.0,
            wall: None,
            silent: false,
            sent: None,
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let period = ctx.period().unwrap_or(Duration::from_millis(100));
        let dt = self.last_step_ns.map_or(0.0, |t| now.saturating_sub(t) as f32 / 1e9);
        if dt > 3.0 * period.as_secs_f32() {
            self.rising = 0.0; // resumed after a suspension: start gently
        }
        self.last_step_ns = Some(now);
        if let Some((_, scan)) = self.scan.latest() {
            self.last_scan = Some((now, scan));
        }
        let fresh =
            self.last_scan.filter(|(t, _)| now.saturating_sub(*t) <= self.timeout_ms.get().saturating_mul(1_000_000));
        let Some((_, scan)) = fresh else {
            if !self.silent && self.last_scan.is_some() {
                tracing::warn!("no sonar scan for {} ms: sending no command", self.timeout_ms.get());
            }
            self.silent = true;
            self.rising = 0.0;
            self.sent = None;
            return Ok(());
        };
        self.silent = false;
        let s = Settings {
            target: self.target.get(),
            v_max: self.v_max.get(),
            accel: self.accel.get(),
            side: match self.side.get().as_str() {
                "left" => Some(WallSide::Left),
                "right" => Some(WallSide::Right),
                _ => None,
            },
            ..Settings::default()
        };
        let c = follow(&scan, &s, self.wall, self.rising, dt);
        if c.side != self.wall {
            tracing::info!(
                "following {}",
                c.side.map_or("no wall", |w| if w == WallSide::Left { "the left wall" } else { "the right wall" })
            );
        }
        self.wall = c.side;
        self.rising = c.rising;
        let (v0, w0, t0) =
            self.sent.unwrap_or((0.0, 0.0, now.saturating_sub(u64::try_from(period.as_nanos()).unwrap_or(u64::MAX))));
        let since = now.saturating_sub(t0) as f32 / 1e9;
        let (v, omega) = (slew(v0, c.v, ACCEL, since), slew(w0, c.omega, ALPHA, since));
        self.sent = Some((v, omega, now));
        self.cmd.send(VelocityCommand { v: f64::from(v), omega: f64::from(omega), stamp_ns: now })?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<WallFollow>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::params::ParamTable;

    #[test]
    fn every_numeric_parameter_is_bounded_above_and_says_its_range() {
        let mut t = ParamTable::default();
        let _p = Params::declare(&mut t);
        let keys: Vec<String> = t.snapshot().into_iter().map(|(k, _)| k).filter(|k| k != "side").collect();
        assert_eq!(keys.len(), 4, "{keys:?}");
        for key in &keys {
            // values of the parameter's type, refused by its range
            for absurd in ["18446744073709551615", "0"] {
                let e = t.set(key, absurd).expect_err(&format!("{key} = {absurd} must be refused"));
                assert!(e.contains(key.as_str()) && e.contains(" is in ") && e.contains(']'), "{key} = {absurd}: {e}");
            }
            // refused by the range or by the type
            for absurd in ["1e30", "-1", "NaN", "inf"] {
                assert!(t.set(key, absurd).is_err(), "{key} = {absurd} must be refused");
            }
        }
        assert!(t.set("side", "up").is_err());
        for (key, ok) in [("scan_timeout_ms", "100"), ("scan_timeout_ms", "10000"), ("v_max", "0.8"), ("target", "2")] {
            t.set(key, ok).unwrap_or_else(|e| panic!("{key} = {ok}: {e}"));
        }
    }
}
