//! What the router asks of an agent's message checker, and its answers.
//!
//! Each request is answered at once by the message checker; the task applies
//! the change at its next cycle and is never blocked by it.

use crate::stats::AgentStats;
use serde::{Deserialize, Serialize};

/// A command to an agent, sent on its control service `nerve/<robot>/<agent>/ctl`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum AgentCommand {
    /// Subscribe input `input` to the output port `from_agent/from_port`.
    Connect {
        /// the agent's input port
        input: String,
        /// the source agent
        from_agent: String,
        /// the source agent's output port
        from_port: String,
        /// the payload type name the router checked
        type_name: String,
    },
    /// Drop the subscription of `input` to `from_agent/from_port`.
    Disconnect {
        /// the agent's input port
        input: String,
        /// the source agent
        from_agent: String,
        /// the source agent's output port
        from_port: String,
    },
    /// Change the period of a periodic task.
    SetPeriod {
        /// new period in nanoseconds
        period_ns: u64,
    },
    /// Stop running the task until resumed (the message checker keeps answering).
    Suspend,
    /// Run the task again.
    Resume,
    /// Read a parameter.
    ParamGet {
        /// parameter name
        key: String,
    },
    /// Change a parameter.
    ParamSet {
        /// parameter name
        key: String,
        /// new value, as text; the agent parses it with the parameter's type
        value: String,
    },
    /// Stop the agent cleanly.
    Stop,
    /// Report statistics.
    Stats,
}

/// The message checker's answer.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum AgentReply {
    /// Done.
    Ok,
    /// Refused, with a message for the user.
    Error(String),
    /// The value of a parameter.
    Param(String),
    /// Statistics.
    Stats(AgentStats),
}
