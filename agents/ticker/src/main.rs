//! `ticker`: a periodic agent that sends a numbered, stamped tick on its
//! output `tick` every period. The quick start's source, and the simplest
//! example of a periodic agent.
//!
//! Parameters: `step` (u64, default 1) — how much the sequence number grows per tick.

use agent_sdk::{Agent, AgentError, Context, Output, Param, Setup, Task};
use shm_schemas::payloads::Tick;
use std::time::Duration;

struct Ticker {
    out: Output<Tick>,
    step: Param<u64>,
    seq: u64,
}

impl Agent for Ticker {
    const KIND: &'static str = "ticker";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(100))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        Ok(Ticker {
            out: setup.output("tick")?,
            step: setup
                .param_checked("step", 1u64, |v| if *v > 0 { Ok(()) } else { Err("step must be at least 1".into()) }),
            seq: 0,
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        self.seq += self.step.get();
        self.out.send(Tick { seq: self.seq, stamp_ns: ctx.now_ns() })?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Ticker>()
}
