//! `idle`: an agent with nothing to do, for measuring what an idle agent
//! costs (`tests/idle_wakeups.rs`).
//!
//! By default it is event-driven with one input, `in`, that nobody
//! connects: its task sleeps on a WaitSet for ever and only the message
//! checker's housekeeping can wake the process. With `NERVE_IDLE_PERIODIC=1`
//! it is a periodic agent instead (every 100 ms, sending nothing), to be
//! started `--suspended`: then the suspend gate is what is measured.
//!
//! ```text
//! cargo run -p agent-sdk --example idle -- --robot r1 --no-realtime
//! ```

use agent_sdk::{Agent, AgentError, Context, Input, Setup, Task};
use shm_schemas::payloads::Tick;
use std::time::Duration;

/// Event-driven, one input never connected.
struct Idle {
    input: Input<Tick>,
}

impl Agent for Idle {
    const KIND: &'static str = "idle";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        Ok(Idle { input: setup.input("in")? })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        self.input.drain(|_, _| {});
        Ok(())
    }
}

/// Periodic, doing nothing; meant to run `--suspended`.
struct IdlePeriodic;

impl Agent for IdlePeriodic {
    const KIND: &'static str = "idle-periodic";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(100))
    }

    fn new(_setup: &mut Setup) -> Result<Self, AgentError> {
        Ok(IdlePeriodic)
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    if std::env::var_os("NERVE_IDLE_PERIODIC").is_some_and(|v| v == "1") {
        agent_sdk::run::<IdlePeriodic>()
    } else {
        agent_sdk::run::<Idle>()
    }
}
