//! `relay`: an event-driven agent that forwards every tick arriving on its
//! input `in` to its output `out`, unchanged. Woken by input arrival, never
//! re-entered; the simplest example of an event-driven agent.

use agent_sdk::{Agent, AgentError, Context, Input, Output, Setup, Task};
use shm_schemas::payloads::Tick;

struct Relay {
    input: Input<Tick>,
    out: Output<Tick>,
}

impl Agent for Relay {
    const KIND: &'static str = "relay";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        Ok(Relay { input: setup.input("in")?, out: setup.output("out")? })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        // a failed send ends the step with its error; the samples after it
        // wait for the next step
        self.input.try_drain(|_, tick| self.out.send(*tick))?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Relay>()
}
