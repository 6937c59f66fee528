//! What an agent executable says about itself with `--describe`: its kind,
//! task, ports and parameters, printed as JSON without joining any robot.
//! `nerve launch` uses it to check a launch file (unknown ports, mismatched
//! types) before anything starts.

use super::agent_to_router::{PortSpec, TaskKind};
use serde::{Deserialize, Serialize};

/// An agent's static description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Description {
    /// [`super::PROTOCOL_VERSION`] of the agent's build
    pub protocol: u16,
    /// kind of agent
    pub kind: String,
    /// periodic or event-driven
    pub task: TaskKind,
    /// default period of a periodic agent, ns
    pub default_period_ns: Option<u64>,
    /// input ports
    pub inputs: Vec<PortSpec>,
    /// output ports
    pub outputs: Vec<PortSpec>,
    /// parameters with their default values
    pub params: Vec<(String, String)>,
    /// the layout of each payload type of its ports, so that a launch file's
    /// connections are checked field by field before anything starts
    #[serde(default)]
    pub schemas: Vec<crate::Schema>,
    /// services it answers (see [`super::call`])
    #[serde(default)]
    pub services: Vec<PortSpec>,
    /// clients it calls services through
    #[serde(default)]
    pub clients: Vec<PortSpec>,
}
