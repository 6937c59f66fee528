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
    /// List the parameters and figures, with types, defaults and bounds.
    ParamList,
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
    /// The parameters and figures, sorted by key (parameters first).
    Params(Vec<ParamInfo>),
    /// Statistics.
    Stats(AgentStats),
}

/// One parameter (or read-only figure) of an agent, for `nerve param list`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ParamInfo {
    /// the key `nerve param get/set` takes
    pub key: String,
    /// the value's type as the agent parses it (`f64`, `u32`, `bool`,
    /// `String`...); `figure` for a read-only figure
    pub type_name: String,
    /// the current value, as text
    pub value: String,
    /// the value declared in the agent's code (before `--param` and
    /// `nerve param set`); empty for a figure
    pub default: String,
    /// what the agent's check says values must be (`gain is in (0, 5]`),
    /// when it checks them and refuses an out-of-range value
    pub bounds: Option<String>,
    /// a figure the agent computes: read with `get`, refused by `set`
    pub read_only: bool,
}
