//! `safety`: the safety monitor (thesis section 4.2.2.3). Periodic (default
//! every 100 ms), on the newest sonar scan of input `scan`
//! (`nerve::SonarScan`):
//!
//! * output `cmd` (`nerve::VelocityCommand`): slower near obstacles, turning
//!   toward the safer, wider side;
//! * output `stop` (`nerve::SafetyStop`): stop moving — not turning — when
//!   something is too close or approaching fast; repeated every cycle while
//!   it holds (each holds `hold_ms`), released once clear in
//!   `release_scans` scans in a row (default 1; see the library for when
//!   more);
//! * output `situation` (`nerve::Situation`): the danger level for the
//!   decision maker.
//!
//! The algorithm is in the library (`nerve_safety`). When the scans stop
//! for `scan_timeout_ms` the monitor is blind: it stops the robot moving
//! (turning allowed), sends no motion command, and reports danger `stop`.

use agent_sdk::params::{Declare, in_range, in_range_above_zero};
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use nerve_safety::{Judgement, Settings, judge, slew};
use shm_schemas::payloads::{DangerLevel, SafetyStop, Situation, SonarScan, VelocityCommand};
use std::time::Duration;

/// The largest distance thresholds, m: beyond the sonar's range.
const DIST_MAX: f32 = 10.0;
/// The largest speed, m/s: the board's limit.
const CRUISE_MAX: f32 = 0.8;
/// The largest turn rate, rad/s: the motor's limit.
const OMEGA_MAX: f32 = 2.0;
/// Scan timeout bounds, ms: under 100 ms a scan period would count as
/// silence; over 10 s a dead sonar would count as alive for too long.
const TIMEOUT_MS: std::ops::RangeInclusive<u64> = 100..=10_000;
/// Clear scans in a row that release a stop: at least one; over 50 (5 s at
/// 100 ms) a stopped robot would turn on the spot for too long.
const RELEASE_SCANS: std::ops::RangeInclusive<u64> = 1..=50;

/// The monitor's parameters, each bounded above and below.
struct Params {
    slow_dist: Param<f32>,
    stop_dist: Param<f32>,
    cruise: Param<f32>,
    omega_max: Param<f32>,
    risk_stop: Param<f32>,
    timeout_ms: Param<u64>,
    release_scans: Param<u64>,
}

impl Params {
    fn declare(d: &mut impl Declare) -> Self {
        let s = Settings::default();
        Params {
            slow_dist: d.checked("slow_dist", s.slow_dist, |v| in_range_above_zero("slow_dist", *v, DIST_MAX, "m")),
            stop_dist: d.checked("stop_dist", s.stop_dist, |v| in_range_above_zero("stop_dist", *v, DIST_MAX, "m")),
            cruise: d.checked("cruise", s.cruise, |v| in_range_above_zero("cruise", *v, CRUISE_MAX, "m/s")),
            omega_max: d
                .checked("omega_max", s.omega_max, |v| in_range_above_zero("omega_max", *v, OMEGA_MAX, "rad/s")),
            risk_stop: d.checked("risk_stop", s.risk_stop, |v| in_range_above_zero("risk_stop", *v, 1.0, "")),
            timeout_ms: d.checked("scan_timeout_ms", 1000u64, |v| in_range("scan_timeout_ms", *v, &TIMEOUT_MS, "ms")),
            release_scans: d.checked("release_scans", u64::from(s.release_scans), |v| {
                in_range("release_scans", *v, &RELEASE_SCANS, "scans")
            }),
        }
    }
}

/// Speed changes the monitor asks for are limited to this, m/s² (the motor refuses jumps over 5).
const ACCEL: f32 = 3.0;
/// Turn-rate changes are limited to this, rad/s² (the motor refuses jumps over 20).
const ALPHA: f32 = 12.0;

struct Safety {
    scan: Input<SonarScan>,
    cmd: Output<VelocityCommand>,
    stop: Output<SafetyStop>,
    situation: Output<Situation>,
    slow_dist: Param<f32>,
    stop_dist: Param<f32>,
    cruise: Param<f32>,
    omega_max: Param<f32>,
    risk_stop: Param<f32>,
    timeout_ms: Param<u64>,
    release_scans: Param<u64>,
    last: Option<Judgement>,
    last_scan_ns: Option<u64>,
    sent: Option<(f32, f32, u64)>,
    stopping: bool,
    blind: bool,
}

impl Safety {
    fn settings(&self) -> Settings {
        Settings {
            slow_dist: self.slow_dist.get(),
            stop_dist: self.stop_dist.get(),
            cruise: self.cruise.get(),
            omega_max: self.omega_max.get(),
            risk_stop: self.risk_stop.get(),
            release_scans: u32::try_from(self.release_scans.get()).unwrap_or(u32::MAX),
            ..Settings::default()
        }
    }

    fn send_stop(&mut self, active: bool, why: &str, now: u64, period: Duration) -> Result<(), AgentError> {
        let hold_ms = u32::try_from(period.as_millis()).unwrap_or(u32::MAX).saturating_mul(4).max(500);
        if active || self.stopping {
            self.stop.send(SafetyStop {
                active: u8::from(active),
                allow_turn: 1,
                reserved: [0; 2],
                hold_ms: if active { hold_ms } else { 0 },
                stamp_ns: now,
            })?;
        }
        if active != self.stopping {
            if active {
                tracing::info!("stop: {why}");
            } else {
                tracing::info!("stop released");
            }
        }
        self.stopping = active;
        Ok(())
    }
}

impl Agent for Safety {
    const KIND: &'static str = "safety";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(100))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let scan = setup.input("scan")?;
        let cmd = setup.output("cmd")?;
        let stop = setup.output("stop")?;
        let situation = setup.output("situation")?;
        let Params { slow_dist, stop_dist, cruise, omega_max, risk_stop, timeout_ms, release_scans } =
            Params::declare(setup);
        Ok(Safety {
            scan,
            cmd,
            stop,
            situation,
            slow_dist,
            stop_dist,
            cruise,
            omega_max,
            risk_stop,
            timeout_ms,
            release_scans,
            last: None,
            last_scan_ns: None,
            sent: None,
            stopping: false,
            blind: false,
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let period = ctx.period().unwrap_or(Duration::from_millis(100));
        let s = self.settings();
        if s.stop_dist >= s.slow_dist {
            return Err(AgentError::Config(format!(
                "stop_dist ({}) must be less than slow_dist ({}); fix with `nerve param set`",
                s.stop_dist, s.slow_dist
            )));
        }
        if let Some((_, scan)) = self.scan.latest() {
            self.last = Some(judge(&scan, &s, self.last.as_ref()));
            self.last_scan_ns = Some(now);
        }
        let fresh =
            self.last_scan_ns.is_some_and(|t| now.saturating_sub(t) <= self.timeout_ms.get().saturating_mul(1_000_000));
        let Some(j) = self.last.filter(|_| fresh) else {
            // blind: no scan yet, or the sonar went silent
            if !self.blind {
                match self.last_scan_ns {
                    None => tracing::info!("no sonar scan yet: blind, the robot stays stopped (turning allowed)"),
                    Some(_) => tracing::warn!(
                        "no sonar scan for {} ms: blind, stopping the robot (turning allowed)",
                        self.timeout_ms.get()
                    ),
                }
                self.blind = true;
            }
            self.sent = None;
            self.send_stop(true, "blind (no sonar scan)", now, period)?;
            self.situation.send(Situation::danger(DangerLevel::Stop, 1.0, now))?;
            return Ok(());
        };
        if self.blind {
            tracing::info!("sonar scans again");
            self.blind = false;
        }
        let (v, omega) = match self.sent {
            Some((v0, w0, t0)) => {
                let dt = now.saturating_sub(t0) as f32 / 1e9;
                (slew(v0, j.v, ACCEL, dt), slew(w0, j.omega, ALPHA, dt))
            }
            None => (slew(0.0, j.v, ACCEL, period.as_secs_f32()), slew(0.0, j.omega, ALPHA, period.as_secs_f32())),
        };
        self.send_stop(j.stop, "something is too close", now, period)?;
        self.cmd.send(VelocityCommand { v: f64::from(v), omega: f64::from(omega), stamp_ns: now })?;
        self.sent = Some((v, omega, now));
        self.situation.send(Situation::danger(j.level, j.danger, now))?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Safety>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::params::ParamTable;
    use agent_sdk::testing::Harness;
    use shm_schemas::payloads::SONAR_DIRECTIONS;

    /// A scan with every direction at `far` metres and no risk.
    fn scan(far: f32) -> SonarScan {
        SonarScan { ranges_m: [far; SONAR_DIRECTIONS], valid: [1; SONAR_DIRECTIONS], ..Default::default() }
    }

    /// The monitor as it runs, driven step by step: blind until the first
    /// scan, speeding up smoothly in open space, stopping (turning allowed)
    /// when something comes too close, releasing, then blind again when the
    /// sonar falls silent past its timeout.
    #[test]
    fn the_monitor_stops_when_blind_or_close_and_ramps_up_in_open_space() {
        let mut h = Harness::<Safety>::new().expect("safety starts");
        assert_eq!(h.period(), Some(Duration::from_millis(100)));
        // no scan yet: blind, so stopped
        h.step().expect("step");
        let stops = h.output::<SafetyStop>("stop").expect("stop");
        assert_eq!(stops.len(), 1);
        assert!(stops[0].active == 1 && stops[0].allow_turn == 1, "{stops:?}");
        assert!(h.output::<VelocityCommand>("cmd").expect("cmd").is_empty(), "no command while blind");
        let sit = h.output::<Situation>("situation").expect("situation");
        assert_eq!(sit[0].danger_level(), Some(DangerLevel::Stop));

        // open space: the stop is released once, the speed ramps up by at most ACCEL
        let mut speeds = Vec::new();
        for _ in 0..10 {
            h.send("scan", scan(3.0)).expect("scan");
            h.step().expect("step");
            speeds.extend(h.output::<VelocityCommand>("cmd").expect("cmd").iter().map(|c| c.v));
        }
        let releases = h.output::<SafetyStop>("stop").expect("stop");
        assert_eq!(releases.iter().map(|s| s.active).collect::<Vec<_>>(), [0], "released once: {releases:?}");
        let cruise = f64::from(Settings::default().cruise);
        assert!((speeds[speeds.len() - 1] - cruise).abs() < 1e-6, "reaches cruise: {speeds:?}");
        for w in speeds.windows(2) {
            assert!(w[1] >= w[0] && w[1] - w[0] <= f64::from(ACCEL) * 0.1 + 1e-6, "a smooth ramp: {speeds:?}");
        }
        assert_eq!(
            h.output::<Situation>("situation").expect("s").last().map(|s| s.danger_level()),
            Some(Some(DangerLevel::None))
        );

        // a lower cruise set at run time is obeyed at the next steps
        h.set_param("cruise", "0.2").expect("cruise");
        assert!(h.set_param("cruise", "5").expect_err("over the board's limit").contains("cruise is in (0, 0.8]"));
        h.send("scan", scan(3.0)).expect("scan");
        h.advance(Duration::from_secs(1)).expect("steps");
        let v = h.output::<VelocityCommand>("cmd").expect("cmd").last().map(|c| c.v);
        assert!(v.is_some_and(|v| (v - 0.2).abs() < 1e-6), "{v:?}");

        // something too close: stopped, not moving
        let mut close = scan(3.0);
        close.ranges_m[0] = 0.2;
        h.send("scan", close).expect("scan");
        h.step().expect("step");
        assert_eq!(h.output::<SafetyStop>("stop").expect("stop").last().map(|s| s.active), Some(1));
        assert_eq!(h.output::<VelocityCommand>("cmd").expect("cmd").last().map(|c| c.v), Some(0.0));

        // the sonar falls silent: the last scan counts for its timeout (1 s), then blind
        h.output::<Situation>("situation").expect("s");
        let before = h.cycles();
        assert_eq!(h.advance(Duration::from_millis(2000)).expect("steps"), 20);
        assert_eq!(h.cycles() - before, 20);
        let levels: Vec<_> = h.output::<Situation>("situation").expect("s").iter().map(|s| s.danger_level()).collect();
        assert_eq!(levels.len(), 20);
        assert!(levels.iter().all(|l| *l == Some(DangerLevel::Stop)), "{levels:?}");
        assert!(h.output::<VelocityCommand>("cmd").expect("cmd").len() < 20, "commands stop once blind");
    }

    /// A bad pair of distances set at run time fails the step, saying how to
    /// fix it, and sends nothing; fixing it resumes the monitor.
    #[test]
    fn a_stop_distance_beyond_the_slow_distance_fails_the_step_until_fixed() {
        let mut h =
            Harness::<Safety>::builder().param("stop_dist", "2").param("slow_dist", "1").start().expect("start");
        h.send("scan", scan(3.0)).expect("scan");
        let e = h.step().expect_err("stop_dist >= slow_dist");
        assert!(e.to_string().contains("nerve param set"), "{e}");
        assert_eq!(h.errors(), 1);
        assert!(h.output::<VelocityCommand>("cmd").expect("cmd").is_empty());
        h.set_param("stop_dist", "0.35").expect("fix");
        h.set_param("slow_dist", "1.2").expect("fix");
        h.step().expect("fixed");
        assert_eq!(h.output::<VelocityCommand>("cmd").expect("cmd").len(), 1);
    }

    /// A suspended monitor sends nothing; resumed, it steps on the scan it
    /// missed (the newest of those that waited).
    #[test]
    fn a_suspended_monitor_sends_nothing() {
        let mut h = Harness::<Safety>::new().expect("start");
        h.suspend();
        h.send("scan", scan(3.0)).expect("scan");
        assert_eq!(h.advance(Duration::from_secs(1)).expect("advance"), 0);
        assert!(h.output::<SafetyStop>("stop").expect("stop").is_empty());
        h.resume().expect("resume");
        h.step().expect("step");
        assert_eq!(h.output::<VelocityCommand>("cmd").expect("cmd").len(), 1, "the waiting scan is judged");
    }

    #[test]
    fn every_numeric_parameter_is_bounded_above_and_says_its_range() {
        let mut t = ParamTable::default();
        let _p = Params::declare(&mut t);
        let keys: Vec<String> = t.snapshot().into_iter().map(|(k, _)| k).collect();
        assert_eq!(keys.len(), 7, "{keys:?}");
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
        // the defaults and the edges are accepted
        let d = Settings::default();
        assert_eq!(t.get("slow_dist").as_deref(), Ok(d.slow_dist.to_string().as_str()));
        for (key, ok) in [
            ("scan_timeout_ms", "100"),
            ("scan_timeout_ms", "10000"),
            ("cruise", "0.8"),
            ("risk_stop", "1"),
            ("release_scans", "1"),
            ("release_scans", "50"),
        ] {
            t.set(key, ok).unwrap_or_else(|e| panic!("{key} = {ok}: {e}"));
        }
    }

    /// A sonar that reports every direction at `far` metres, every 100 ms.
    struct FakeSonar {
        out: agent_sdk::Output<SonarScan>,
        far: f32,
    }

    impl Agent for FakeSonar {
        const KIND: &'static str = "fake-sonar";
        fn task() -> Task {
            Task::Periodic(Duration::from_millis(100))
        }
        fn new(setup: &mut Setup) -> Result<Self, AgentError> {
            Ok(FakeSonar { out: setup.output("scan")?, far: 3.0 })
        }
        fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
            self.out.send(scan(self.far))?;
            Ok(())
        }
    }

    /// Records the stops it is sent, when it is sent them.
    struct Brake {
        stop: agent_sdk::Input<SafetyStop>,
        got: Vec<(u8, u64)>,
    }

    impl Agent for Brake {
        const KIND: &'static str = "brake";
        fn task() -> Task {
            Task::EventDriven
        }
        fn new(setup: &mut Setup) -> Result<Self, AgentError> {
            Ok(Brake { stop: setup.input("stop")?, got: Vec::new() })
        }
        fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
            let (got, now) = (&mut self.got, ctx.now_ns());
            self.stop.try_drain(|_, s| {
                got.push((s.active, now));
                Ok::<(), AgentError>(())
            })?;
            Ok(())
        }
    }

    /// The real monitor wired between a sonar and a brake in one process
    /// (`agent_sdk::testing::Wiring`): stopped while the sonar is silent,
    /// released once by open space, stopped again in the same cycle as the
    /// scan that shows an obstacle (the sonar, added first, steps first at
    /// a shared deadline).
    #[test]
    fn wired_between_a_sonar_and_a_brake_the_monitor_stops_at_the_scan_that_shows_an_obstacle() {
        use agent_sdk::testing::Wiring;
        const MS: u64 = 1_000_000;
        let mut w = Wiring::new();
        w.add_built(Harness::<FakeSonar>::builder().name("sonar").suspended()).expect("sonar");
        w.add::<Safety>("safety").expect("safety");
        w.add::<Brake>("brake").expect("brake");
        w.connect("sonar/scan", "safety/scan").expect("scan");
        w.connect("safety/stop", "brake/stop").expect("stop");
        let e = w.connect("safety/cmd", "brake/stop").expect_err("a command is not a stop").to_string();
        assert!(e.starts_with("cannot connect safety/cmd to brake/stop: safety/cmd sends"), "{e}");
        let start = w.now_ns();

        w.advance(Duration::from_millis(100)).expect("no scan yet");
        assert_eq!(w.agent::<Brake>("brake").expect("brake").got, [(1, start + 100 * MS)], "blind: stopped");

        w.resume("sonar").expect("the sonar speaks");
        w.advance(Duration::from_secs(1)).expect("open space");
        let got = &w.agent::<Brake>("brake").expect("brake").got;
        let released: Vec<_> = got.iter().filter(|(active, _)| *active == 0).collect();
        assert_eq!(released.len(), 1, "released once: {got:?}");
        assert_eq!(got.last().map(|(active, _)| *active), Some(0), "and stays released: {got:?}");
        assert!(!w.output::<VelocityCommand>("safety/cmd").expect("cmd").is_empty(), "moving");

        w.harness_mut::<FakeSonar>("sonar").expect("sonar").agent_mut().far = 0.2;
        w.advance(Duration::from_millis(100)).expect("an obstacle");
        let got = &w.agent::<Brake>("brake").expect("brake").got;
        assert_eq!(got.last(), Some(&(1, start + 1200 * MS)), "stopped in the cycle of that scan: {got:?}");
    }
}
