//! `safety`: the safety monitor (thesis section 4.2.2.3). Periodic (default
//! every 100 ms), on the newest sonar scan of input `scan`
//! (`nerve::SonarScan`):
//!
//! * output `cmd` (`nerve::VelocityCommand`): slower near obstacles, turning
//!   toward the safer, wider side;
//! * output `stop` (`nerve::SafetyStop`): stop moving — not turning — when
//!   something is too close or approaching fast; repeated every cycle while
//!   it holds (each holds `hold_ms`), released once clear;
//! * output `situation` (`nerve::Situation`): the danger level for the
//!   decision maker.
//!
//! The algorithm is in the library (`nerve_safety`). When the scans stop
//! for `scan_timeout_ms` the monitor is blind: it stops the robot moving
//! (turning allowed), sends no motion command, and reports danger `stop`.

use agent_sdk::params::positive;
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use nerve_safety::{Judgement, Settings, judge, slew};
use shm_schemas::payloads::{DangerLevel, SafetyStop, Situation, SonarScan, VelocityCommand};
use std::time::Duration;

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
            ..Settings::default()
        }
    }

    fn send_stop(&mut self, active: bool, why: &str, now: u64, period: Duration) -> Result<(), AgentError> {
        let hold_ms = (period.as_millis() as u32).saturating_mul(4).max(500);
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
        let d = Settings::default();
        Ok(Safety {
            scan: setup.input("scan")?,
            cmd: setup.output("cmd")?,
            stop: setup.output("stop")?,
            situation: setup.output("situation")?,
            slow_dist: setup.param_checked("slow_dist", d.slow_dist, positive),
            stop_dist: setup.param_checked("stop_dist", d.stop_dist, positive),
            cruise: setup.param_checked("cruise", d.cruise, positive),
            omega_max: setup.param_checked("omega_max", d.omega_max, positive),
            risk_stop: setup.param_checked("risk_stop", d.risk_stop, |v| {
                if (0.0..=1.0).contains(v) && *v > 0.0 { Ok(()) } else { Err("risk_stop is in (0, 1]".into()) }
            }),
            timeout_ms: setup.param_checked("scan_timeout_ms", 1000u64, |v| {
                if *v >= 100 { Ok(()) } else { Err("scan_timeout_ms is at least 100".into()) }
            }),
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
        let fresh = self.last_scan_ns.is_some_and(|t| now.saturating_sub(t) <= self.timeout_ms.get() * 1_000_000);
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
