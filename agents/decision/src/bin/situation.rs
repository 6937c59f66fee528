//! `situation`: a hand-driven source of `nerve::Situation` reports, for
//! trying and testing a knowledge base without a robot ("what does the
//! decision maker do when a target is seen while danger is high?").
//!
//! Periodic (default every 100 ms): sends on output `situation` one report
//! made of its parameters, changeable at run time:
//!
//! * `danger` — `none`, `low`, `high`, `stop`, or `off` (default): the
//!   report does not speak about danger;
//! * `target` — `none`, `seen`, `close`, or `off` (default);
//! * `size` — target area as a fraction of the image (default 0.05).
//!
//! ```text
//! nerve start situation --name fake
//! nerve connect fake/situation decision/situation
//! nerve param set fake danger high
//! ```

use agent_sdk::{Agent, AgentError, Context, Output, Param, Setup, Task};
use shm_schemas::payloads::situation::{REPORTS_DANGER, REPORTS_TARGET};
use shm_schemas::payloads::{DangerLevel, Situation, TargetState};
use std::time::Duration;

struct Source {
    out: Output<Situation>,
    danger: Param<String>,
    target: Param<String>,
    size: Param<f64>,
}

fn danger_of(s: &str) -> Option<DangerLevel> {
    DangerLevel::ALL.into_iter().find(|l| l.name() == s)
}

fn target_of(s: &str) -> Option<TargetState> {
    TargetState::ALL.into_iter().find(|l| l.name() == s)
}

impl Agent for Source {
    const KIND: &'static str = "situation";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(100))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        Ok(Source {
            out: setup.output("situation")?,
            danger: setup.param_checked("danger", "off".to_owned(), |v| {
                if v == "off" || danger_of(v).is_some() {
                    Ok(())
                } else {
                    Err("danger is one of none, low, high, stop, off".into())
                }
            }),
            target: setup.param_checked("target", "off".to_owned(), |v| {
                if v == "off" || target_of(v).is_some() {
                    Ok(())
                } else {
                    Err("target is one of none, seen, close, off".into())
                }
            }),
            size: setup.param_checked("size", 0.05, |v| {
                if (0.0..=1.0).contains(v) { Ok(()) } else { Err("size is a fraction 0 … 1".into()) }
            }),
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let mut s = Situation { stamp_ns: ctx.now_ns(), ..Default::default() };
        if let Some(d) = danger_of(&self.danger.get()) {
            s.reports |= REPORTS_DANGER;
            s.danger_level = d as u8;
            s.danger = d as u8 as f32 / 3.0;
        }
        if let Some(t) = target_of(&self.target.get()) {
            s.reports |= REPORTS_TARGET;
            s.target = t as u8;
            s.target_size = self.size.get() as f32;
        }
        if s.reports != 0 {
            self.out.send(s)?;
        }
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Source>()
}
