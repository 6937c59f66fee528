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
//!
//! Optional input `revisit` (`nerve::Scalar`, the map builder's `revisit`:
//! 1 while the robot is back at a place it passed long ago). On its rising
//! edge, with `side` = `auto`, the follower switches to the other side for
//! `revisit_hold_s` seconds, at most once every `revisit_holdoff_s`
//! (library: `SideSwitch`); the read-only figure `revisit_switches` counts
//! the switches. Not connected, or silent for 3 s, it changes nothing.

use agent_sdk::params::{Declare, in_range, in_range_above_zero};
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use nerve_wall_follow::{RevisitEvent, RevisitSettings, Settings, SideSwitch, WallSide, follow, revisit_settings};
use shm_schemas::payloads::{Scalar, SonarScan, VelocityCommand};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
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
/// The longest hold and hold-off of a revisit switch, s.
const REVISIT_S_MAX: f32 = 600.0;
/// A `revisit` reading older than this is no reading, ns (the map builder
/// sends one every 200 ms, every 1.6 s when the resource manager has
/// slowed it down the most).
const REVISIT_FRESH_NS: u64 = 3_000_000_000;

/// The follower's parameters, each number bounded above and below.
struct Params {
    target: Param<f32>,
    v_max: Param<f32>,
    accel: Param<f32>,
    side: Param<String>,
    timeout_ms: Param<u64>,
    revisit_hold_s: Param<f32>,
    revisit_holdoff_s: Param<f32>,
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
            revisit_hold_s: d.checked("revisit_hold_s", RevisitSettings::default().hold_s, |v| {
                in_range_above_zero("revisit_hold_s", *v, REVISIT_S_MAX, "s")
            }),
            revisit_holdoff_s: d.checked("revisit_holdoff_s", RevisitSettings::default().holdoff_s, |v| {
                in_range_above_zero("revisit_holdoff_s", *v, REVISIT_S_MAX, "s")
            }),
        }
    }
}

struct WallFollow {
    scan: Input<SonarScan>,
    revisit: Input<Scalar>,
    cmd: Output<VelocityCommand>,
    target: Param<f32>,
    v_max: Param<f32>,
    accel: Param<f32>,
    side: Param<String>,
    timeout_ms: Param<u64>,
    revisit_hold_s: Param<f32>,
    revisit_holdoff_s: Param<f32>,
    last_revisit: Option<(u64, bool)>,
    switch: SideSwitch,
    switches: Arc<AtomicU64>,
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
        let revisit = setup.input("revisit")?;
        let cmd = setup.output("cmd")?;
        let Params { target, v_max, accel, side, timeout_ms, revisit_hold_s, revisit_holdoff_s } =
            Params::declare(setup);
        let switches = Arc::new(AtomicU64::new(0));
        let figure = switches.clone();
        setup.figures(move || vec![("revisit_switches".into(), figure.load(Ordering::Relaxed).to_string())]);
        Ok(WallFollow {
            scan,
            revisit,
            cmd,
            target,
            v_max,
            accel,
            side,
            timeout_ms,
            revisit_hold_s,
            revisit_holdoff_s,
            last_revisit: None,
            switch: SideSwitch::default(),
            switches,
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
        let fixed = match self.side.get().as_str() {
            "left" => Some(WallSide::Left),
            "right" => Some(WallSide::Right),
            _ => None,
        };
        let r = self.on_revisit(now, fixed);
        let base = Settings {
            target: self.target.get(),
            v_max: self.v_max.get(),
            accel: self.accel.get(),
            side: fixed,
            ..Settings::default()
        };
        let s = revisit_settings(&base, if fixed.is_none() { self.switch.forced(now) } else { None }, &r);
        let c = follow(&scan, &s, self.wall, self.rising, dt);
        if c.side != self.wall {
            tracing::info!(
                "following {}",
                c.side.map_or("no wall", |w| if w == WallSide::Left { "the left wall" } else { "the right wall" })
            );
        }
        self.wall = c.side;
        self.switch.followed(c.side);
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

impl WallFollow {
    /// Reads `revisit` and switches sides on its rising edge (side `auto`
    /// only: a side set by the operator is kept).
    fn on_revisit(&mut self, now: u64, fixed: Option<WallSide>) -> RevisitSettings {
        if let Some((_, r)) = self.revisit.latest() {
            if r.value.is_finite() {
                self.last_revisit = Some((now, r.value >= 0.5));
            } else {
                tracing::debug!(value = r.value, "revisit reading not a number: ignored");
            }
        }
        let back = self.last_revisit.filter(|(t, _)| now.saturating_sub(*t) <= REVISIT_FRESH_NS).map(|(_, b)| b);
        let s = RevisitSettings {
            hold_s: self.revisit_hold_s.get(),
            holdoff_s: self.revisit_holdoff_s.get(),
            ..RevisitSettings::default()
        };
        match self.switch.revisit(back, now, &s) {
            RevisitEvent::Nothing => {}
            RevisitEvent::Switched { from, to } if fixed.is_none() => {
                self.switches.store(self.switch.switches(), Ordering::Relaxed);
                tracing::info!(
                    from = from.name(),
                    to = to.name(),
                    hold_s = s.hold_s,
                    switches = self.switch.switches(),
                    "back at a place passed before: switching to the {} wall",
                    to.name()
                );
            }
            RevisitEvent::Switched { .. } => {
                tracing::info!(side = self.side.get(), "back at a place passed before; side fixed by parameter, kept")
            }
            RevisitEvent::TooSoon { since_s } => tracing::info!(
                since_s,
                holdoff_s = s.holdoff_s,
                "back at a place passed before, but switched sides only {since_s:.0} s ago: keeping the side"
            ),
            RevisitEvent::NoWall => {
                tracing::info!("back at a place passed before, but no wall followed yet: nothing to switch")
            }
        }
        s
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
        assert_eq!(keys.len(), 6, "{keys:?}");
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
        for (key, ok) in [
            ("scan_timeout_ms", "100"),
            ("scan_timeout_ms", "10000"),
            ("v_max", "0.8"),
            ("target", "2"),
            ("revisit_hold_s", "600"),
            ("revisit_holdoff_s", "0.5"),
        ] {
            t.set(key, ok).unwrap_or_else(|e| panic!("{key} = {ok}: {e}"));
        }
    }
}
