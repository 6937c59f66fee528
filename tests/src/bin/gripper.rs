//! `gripper`: an agent with a payload type of its own, `acme::Gripper`,
//! that nerve was not built with: one `#[derive(Payload)]` and nothing else,
//! as a team's agent crate outside the workspace would define it. The tests
//! echo, watch and connect it by its schema alone.
//!
//! Periodic (20 ms): output `state` counts up; input `cmd` takes the same
//! type; parameter `tool` (text) is the tool it reports holding.
//! `-- --layout old` runs the same agent with the type as an older build
//! defined it (same name and size, the fields in another order), the stale
//! build that must be refused.

use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use shm_schemas::{FixedName, Payload};
use std::time::Duration;

/// A fingertip's reading, nested in [`Gripper`].
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, Payload)]
#[payload(name = "acme::Finger")]
#[repr(C)]
pub struct Finger {
    /// contact force, N
    pub force_n: f32,
    /// whether it touches something
    pub contact: bool,
}

/// The gripper's state as this build defines it.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, Payload)]
#[payload(name = "acme::Gripper")]
#[repr(C)]
pub struct Gripper {
    /// samples sent so far
    pub count: u64,
    /// jaw opening, m
    pub opening_m: f64,
    /// the three fingers
    pub fingers: [Finger; 3],
    /// the tool held
    pub tool: FixedName,
    /// a signed reading (temperature, centi-degrees)
    pub temp_cdeg: i16,
}

/// `acme::Gripper` as an older build defined it: `count` and `opening_m`
/// in the other order.
pub mod old {
    use super::Finger;
    use shm_schemas::{FixedName, Payload};

    /// The old layout.
    #[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, Payload)]
    #[payload(name = "acme::Gripper")]
    #[repr(C)]
    pub struct Gripper {
        /// jaw opening, m
        pub opening_m: f64,
        /// samples sent so far
        pub count: u64,
        /// the three fingers
        pub fingers: [Finger; 3],
        /// the tool held
        pub tool: FixedName,
        /// temperature, centi-degrees
        pub temp_cdeg: i16,
    }
}

/// What the agent needs of either layout.
trait Sample: Payload + Default {
    fn make(n: u64, tool: &str) -> Self;
}

fn fingers(n: u64) -> [Finger; 3] {
    [0.5f32, 1.0, 1.5].map(|f| Finger { force_n: f * (n % 10) as f32, contact: n.is_multiple_of(2) })
}

impl Sample for Gripper {
    fn make(n: u64, tool: &str) -> Self {
        Gripper {
            count: n,
            opening_m: n as f64 * 0.001,
            fingers: fingers(n),
            tool: FixedName::new(tool),
            temp_cdeg: -250,
        }
    }
}

impl Sample for old::Gripper {
    fn make(n: u64, tool: &str) -> Self {
        old::Gripper {
            opening_m: n as f64 * 0.001,
            count: n,
            fingers: fingers(n),
            tool: FixedName::new(tool),
            temp_cdeg: -250,
        }
    }
}

struct GripperAgent<T: Sample> {
    cmd: Input<T>,
    state: Output<T>,
    tool: Param<String>,
    n: u64,
}

impl<T: Sample> Agent for GripperAgent<T> {
    const KIND: &'static str = "gripper";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(20))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        Ok(GripperAgent {
            cmd: setup.input("cmd")?,
            state: setup.output("state")?,
            tool: setup.param("tool", "screwdriver".to_string()),
            n: 0,
        })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        while self.cmd.recv().is_some() {}
        self.n += 1;
        self.state.send(T::make(self.n, &self.tool.get()))?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    let old = std::env::args().skip_while(|a| a != "--").any(|a| a == "old");
    if old { agent_sdk::run::<GripperAgent<old::Gripper>>() } else { agent_sdk::run::<GripperAgent<Gripper>>() }
}
