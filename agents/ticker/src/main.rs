//! `ticker`: a periodic agent that sends a numbered, stamped tick on its
//! output `tick` every period. The quick start's source, and the simplest
//! example of a periodic agent.
//!
//! Parameters: `step` (u64, 1 to 1 000 000, default 1) — how much the
//! sequence number grows per tick.

use agent_sdk::{Agent, AgentError, Context, Output, Param, Setup, Task};
use shm_schemas::payloads::Tick;
use std::time::Duration;

/// The largest `step`: at 100 000 ticks a second the sequence number would
/// still take 5 800 years to reach `u64::MAX` (where it then stays).
const STEP_MAX: u64 = 1_000_000;

/// The check of `step`: 1 to [`STEP_MAX`].
fn check_step(v: &u64) -> Result<(), String> {
    if (1..=STEP_MAX).contains(v) { Ok(()) } else { Err(format!("step is in [1, {STEP_MAX}]")) }
}

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
        Ok(Ticker { out: setup.output("tick")?, step: setup.param_checked("step", 1u64, check_step), seq: 0 })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        // never wraps: a sequence number that went backwards would read as a restart
        self.seq = self.seq.saturating_add(self.step.get());
        self.out.send(Tick { seq: self.seq, stamp_ns: ctx.now_ns() })?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Ticker>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::params::ParamTable;

    #[test]
    fn step_is_bounded_above_and_says_its_range() {
        let mut t = ParamTable::default();
        t.declare("step", 1u64, Some(Box::new(check_step)));
        for absurd in ["18446744073709551615", "1000001", "0"] {
            let e = t.set("step", absurd).expect_err(&format!("step = {absurd} must be refused"));
            assert!(e.contains("step is in [1, 1000000]"), "step = {absurd}: {e}");
        }
        for absurd in ["-1", "1e6", "NaN", ""] {
            assert!(t.set("step", absurd).is_err(), "step = {absurd} must be refused");
        }
        for ok in ["1", "1000000"] {
            t.set("step", ok).unwrap_or_else(|e| panic!("step = {ok}: {e}"));
        }
    }
}
