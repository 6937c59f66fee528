//! What an agent tells the router: who it is when it starts, that it leaves
//! when it stops.

use crate::{Payload, Schema};
use serde::{Deserialize, Serialize};

/// How an agent's task is driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TaskKind {
    /// Runs every period, to absolute deadlines.
    Periodic,
    /// Runs when an input arrives.
    EventDriven,
}

impl std::fmt::Display for TaskKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            TaskKind::Periodic => "periodic",
            TaskKind::EventDriven => "event-driven",
        })
    }
}

/// A port, the type name of what it carries and the fingerprint of the
/// layout this build gave that type.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PortSpec {
    /// Port name, unique among the agent's inputs (or outputs).
    pub name: String,
    /// Stable payload type name, e.g. `nerve::Tick`.
    pub type_name: String,
    /// [`crate::Schema::fingerprint`] of the type as this agent was built:
    /// two ports of one type name with different fingerprints come from
    /// different definitions of it (a stale build), and are never connected.
    #[serde(default)]
    pub fingerprint: u64,
}

impl PortSpec {
    /// The spec of port `name` carrying `T`.
    pub fn of<T: Payload>(name: &str) -> Self {
        PortSpec { name: name.into(), type_name: T::stable_type_name().into(), fingerprint: T::layout_fingerprint() }
    }
}

/// Adds `schema` to `schemas` unless a schema of the same layout is there.
pub fn add_schema(schemas: &mut Vec<Schema>, schema: Schema) {
    let fp = schema.fingerprint();
    if !schemas.iter().any(|s| s.fingerprint() == fp) {
        schemas.push(schema);
    }
}

/// Everything the router needs to know about an agent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Registration {
    /// Agent name, unique within the robot.
    pub name: String,
    /// Process id.
    pub pid: u32,
    /// Kind of agent (`ticker`, `relay`, `sonar`, ...).
    pub kind: String,
    /// Path of the executable.
    pub executable: String,
    /// Periodic or event-driven.
    pub task: TaskKind,
    /// Current period in nanoseconds (periodic agents).
    pub period_ns: Option<u64>,
    /// Input ports.
    pub inputs: Vec<PortSpec>,
    /// Output ports.
    pub outputs: Vec<PortSpec>,
    /// Log file, when the agent runs as a daemon.
    pub log_file: Option<String>,
    /// Whether the task is suspended at the time of registration.
    pub suspended: bool,
    /// The schema of each type the ports carry, once per layout: what
    /// tools need to read a port whose type they were not built with.
    #[serde(default)]
    pub schemas: Vec<Schema>,
    /// Services the agent answers (`setup.serve`), each typed by
    /// [`super::call::call_spec`]: the router wires clients to them.
    #[serde(default)]
    pub services: Vec<PortSpec>,
    /// Clients the agent calls services through (`setup.client`), typed
    /// as the services they may be wired to.
    #[serde(default)]
    pub clients: Vec<PortSpec>,
}

/// A message from an agent to the router.
// sent once per registration and decoded at once: its size on the stack does not matter
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum AgentToRouter {
    /// The agent starts (or re-registers with a restarted router).
    Register(Registration),
    /// The agent stops cleanly.
    Unregister {
        /// agent name
        name: String,
        /// its pid, so that a stale message cannot remove a newer agent
        pid: u32,
    },
}
