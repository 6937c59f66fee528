//! `gripper`: an agent with a payload type of its own, `acme::Gripper`,
//! that nerve was not built with: one `#[derive(Payload)]` and nothing else,
//! as a team's agent crate outside the workspace would define it. The tests
//! echo, watch and connect it by its schema alone.
//!
//! Periodic (20 ms): output `state` counts up; input `cmd` takes the same
//! type; parameter `tool` (text) is the tool it reports holding.
//! `-- --layout old` runs the same agent with the type as an older build
//! defined it (same name and size, the fields in another order), the stale
//! build that must be refused. `-- --layout wide` runs it with `acme::Wide`,
//! a type too large to register with its schema.

use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use shm_schemas::schema::Bool;
use shm_schemas::{FixedName, Payload};
use std::time::Duration;

/// A fingertip's reading, nested in [`Gripper`].
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, Payload)]
#[payload(name = "acme::Finger")]
#[repr(C)]
pub struct Finger {
    /// contact force, N
    pub force_n: f32,
    /// whether it touches something (a `Bool`: a payload holds no `bool`)
    pub contact: Bool,
    /// explicit padding (a payload has no implicit padding)
    #[serde(skip)]
    pub _pad: [u8; 3],
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
    /// explicit padding
    #[serde(skip)]
    pub _pad: [u8; 2],
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
        /// explicit padding
        #[serde(skip)]
        pub _pad: [u8; 2],
    }
}

/// `acme::Wide`: a type whose schema (900 fields, nested) makes the
/// agent's registration too large for the router's service with its
/// schemas, so that it registers without them (`-- --layout wide`).
pub mod wide {
    use shm_schemas::Payload;

    /// Thirty readings.
    #[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, Payload)]
    #[payload(name = "acme::Row")]
    #[repr(C)]
    pub struct Row {
        /// reading 0
        pub r00: u32,
        /// reading 1
        pub r01: u32,
        /// reading 2
        pub r02: u32,
        /// reading 3
        pub r03: u32,
        /// reading 4
        pub r04: u32,
        /// reading 5
        pub r05: u32,
        /// reading 6
        pub r06: u32,
        /// reading 7
        pub r07: u32,
        /// reading 8
        pub r08: u32,
        /// reading 9
        pub r09: u32,
        /// reading 10
        pub r10: u32,
        /// reading 11
        pub r11: u32,
        /// reading 12
        pub r12: u32,
        /// reading 13
        pub r13: u32,
        /// reading 14
        pub r14: u32,
        /// reading 15
        pub r15: u32,
        /// reading 16
        pub r16: u32,
        /// reading 17
        pub r17: u32,
        /// reading 18
        pub r18: u32,
        /// reading 19
        pub r19: u32,
        /// reading 20
        pub r20: u32,
        /// reading 21
        pub r21: u32,
        /// reading 22
        pub r22: u32,
        /// reading 23
        pub r23: u32,
        /// reading 24
        pub r24: u32,
        /// reading 25
        pub r25: u32,
        /// reading 26
        pub r26: u32,
        /// reading 27
        pub r27: u32,
        /// reading 28
        pub r28: u32,
        /// reading 29
        pub r29: u32,
    }

    /// Thirty rows.
    #[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, Payload)]
    #[payload(name = "acme::Wide")]
    #[repr(C)]
    pub struct Wide {
        /// row 0
        pub w00: Row,
        /// row 1
        pub w01: Row,
        /// row 2
        pub w02: Row,
        /// row 3
        pub w03: Row,
        /// row 4
        pub w04: Row,
        /// row 5
        pub w05: Row,
        /// row 6
        pub w06: Row,
        /// row 7
        pub w07: Row,
        /// row 8
        pub w08: Row,
        /// row 9
        pub w09: Row,
        /// row 10
        pub w10: Row,
        /// row 11
        pub w11: Row,
        /// row 12
        pub w12: Row,
        /// row 13
        pub w13: Row,
        /// row 14
        pub w14: Row,
        /// row 15
        pub w15: Row,
        /// row 16
        pub w16: Row,
        /// row 17
        pub w17: Row,
        /// row 18
        pub w18: Row,
        /// row 19
        pub w19: Row,
        /// row 20
        pub w20: Row,
        /// row 21
        pub w21: Row,
        /// row 22
        pub w22: Row,
        /// row 23
        pub w23: Row,
        /// row 24
        pub w24: Row,
        /// row 25
        pub w25: Row,
        /// row 26
        pub w26: Row,
        /// row 27
        pub w27: Row,
        /// row 28
        pub w28: Row,
        /// row 29
        pub w29: Row,
    }
}

/// What the agent needs of each layout.
trait Sample: Payload + Default {
    fn make(n: u64, tool: &str) -> Self;
}

fn fingers(n: u64) -> [Finger; 3] {
    [0.5f32, 1.0, 1.5].map(|f| Finger {
        force_n: f * (n % 10) as f32,
        contact: n.is_multiple_of(2).into(),
        _pad: [0; 3],
    })
}

impl Sample for Gripper {
    fn make(n: u64, tool: &str) -> Self {
        Gripper {
            count: n,
            opening_m: n as f64 * 0.001,
            fingers: fingers(n),
            tool: FixedName::new(tool),
            temp_cdeg: -250,
            _pad: [0; 2],
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
            _pad: [0; 2],
        }
    }
}

impl Sample for wide::Wide {
    fn make(n: u64, _tool: &str) -> Self {
        let mut w = wide::Wide::default();
        w.w00.r00 = n as u32;
        w
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
    let after: Vec<String> = std::env::args().skip_while(|a| a != "--").collect();
    if after.iter().any(|a| a == "old") {
        agent_sdk::run::<GripperAgent<old::Gripper>>()
    } else if after.iter().any(|a| a == "wide") {
        agent_sdk::run::<GripperAgent<wide::Wide>>()
    } else {
        agent_sdk::run::<GripperAgent<Gripper>>()
    }
}
