//! `head`: the head (pan-tilt) motor agent of H1 — the actuator pattern of
//! Fig. 2-4 in front of the head board.
//!
//! Inputs (fan-in; the latest command per sender is kept): `cmd`
//! (`nerve::HeadCommand`, pan and tilt set-points in rad) and `say`
//! (`nerve::LinguisticCommand`: "turn left a little", "look up", "look
//! ahead", ...). Each cycle (periodic, default 50 ms) the commands are
//! filtered, fuzzified and fused by weight (see the `aim` module) into a
//! set-point, sent to the board over `-- --device PATH` when it changes (and
//! once a second). Output `state` (`nerve::HeadState`): the board's measured
//! position (10 Hz) with the set-point.
//!
//! Parameters: `weights` (`sender:weight,...`), `default_weight`,
//! `stale_ms`; figures (read-only counters) `accepted`, `refused` and the
//! device link's counters. When the board vanishes the agent logs it and reopens
//! it with exponential backoff; after recovery it sends the set-point again.

mod aim;

use agent_sdk::device::{Count, CounterFigures, DeviceEvent, DeviceLink};
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use aim::Aim;
use nerve_devices::Message;
use nerve_motor::{Limits, Weights};
use shm_schemas::payloads::{HeadCommand, HeadState, LinguisticCommand};
use std::path::PathBuf;
use std::time::Duration;

/// What `start` says when no `--device` was given.
const NO_DEVICE: &str =
    "no device: give the head board's serial port after `--`, e.g. `nerve start head -- --device /dev/ttyUSB3`";

/// Arguments after `--`.
#[derive(Debug, clap::Parser)]
struct Args {
    /// Serial device of the head board.
    #[arg(long)]
    device: Option<PathBuf>,
}

struct Head {
    device: Option<PathBuf>,
    link: Option<DeviceLink>,
    cmd: Input<HeadCommand>,
    say: Input<LinguisticCommand>,
    out: Output<HeadState>,
    weights: Param<String>,
    default_weight: Param<f64>,
    stale_ms: Param<u64>,
    accepted: Count,
    refused: Count,
    counters: CounterFigures,
    aim: Aim,
    sent: Option<(i16, i16)>,
    sent_at: u64,
    last_step_ns: u64,
}

fn cdeg(rad: f64) -> i16 {
    (rad.to_degrees() * 100.0).round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

impl Agent for Head {
    const KIND: &'static str = "head";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(50))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        // read-only counters: figures, after the device link's
        let (accepted, refused) = (Count::default(), Count::default());
        let (a, r) = (accepted.clone(), refused.clone());
        let counters =
            agent_sdk::device::counter_figures(setup, move || vec![a.figure("accepted"), r.figure("refused")]);
        Ok(Head {
            device: args.device,
            link: None,
            cmd: setup.input("cmd")?,
            say: setup.input("say")?,
            out: setup.output("state")?,
            weights: setup.param_checked("weights", String::new(), |s: &String| Weights::parse(s).map(|_| ())),
            default_weight: setup.param_checked("default_weight", 1.0, |v: &f64| {
                if v.is_finite() && *v >= 0.0 { Ok(()) } else { Err("must be a finite number >= 0".into()) }
            }),
            stale_ms: setup.param_checked("stale_ms", 500u64, |v: &u64| {
                if (10..=60_000).contains(v) { Ok(()) } else { Err("must be between 10 and 60000 ms".into()) }
            }),
            accepted,
            refused,
            counters,
            aim: Aim::default(),
            sent: None,
            sent_at: 0,
            last_step_ns: 0,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        self.link = Some(agent_sdk::device::open_link(&self.device, "head", NO_DEVICE)?);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let limits = Limits { stale_ns: self.stale_ms.get() * 1_000_000, ..Limits::H1 };
        let mut offered = Vec::new();
        self.cmd.drain(|m, c| offered.push((m.sender.as_str().to_owned(), Ok(*c))));
        self.say.drain(|m, c| offered.push((m.sender.as_str().to_owned(), Err(*c))));
        for (sender, c) in offered {
            let r = match c {
                Ok(c) => self.aim.offer_command(&sender, &c, now, &limits),
                Err(c) => self.aim.offer_said(&sender, &c, now, &limits),
            };
            match r {
                Ok(()) => self.accepted.add(1),
                Err(e) => {
                    self.refused.add(1);
                    if self.refused.get().is_power_of_two() {
                        tracing::warn!(
                            "refused a head command from {sender} ({} refused so far): {e}",
                            self.refused.get()
                        );
                    }
                }
            }
        }
        let dt = if self.last_step_ns == 0 { 0.05 } else { now.saturating_sub(self.last_step_ns) as f64 / 1e9 };
        self.last_step_ns = now;
        let weights = Weights::parse(&self.weights.get()).unwrap_or_default();
        let (pan, tilt) = self.aim.decide(now, dt, &limits, &weights, self.default_weight.get());
        let Some(link) = &self.link else { return Ok(()) };
        let mut result = Ok(());
        while let Some(ev) = link.try_recv() {
            match ev {
                DeviceEvent::Message(Message::HeadState(s), at) => {
                    let state = HeadState {
                        pan_rad: f64::from(s.pan_cdeg).to_radians() / 100.0,
                        tilt_rad: f64::from(s.tilt_cdeg).to_radians() / 100.0,
                        target_pan_rad: pan,
                        target_tilt_rad: tilt,
                        stamp_ns: now.saturating_sub(agent_sdk::clock::elapsed_ns(at)),
                    };
                    if let Err(e) = self.out.send(state) {
                        result = Err(e.into());
                    }
                }
                DeviceEvent::Connected => self.sent = None,
                _ => {}
            }
        }
        let want = (cdeg(pan), cdeg(tilt));
        let due = self.sent != Some(want) || now.saturating_sub(self.sent_at) > 1_000_000_000;
        if due && link.send(nerve_devices::HeadCommand { pan_cdeg: want.0, tilt_cdeg: want.1 }.into()) {
            self.sent = Some(want);
            self.sent_at = now;
        }
        self.counters.update(&link.stats(), "head");
        result
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Head>()
}
