//! What the command line (and the agents, through [`RouterRequest::Agent`])
//! ask of the router, its answers, and the errors it reports.

use super::agent_to_router::{AgentToRouter, PortSpec, TaskKind};
use super::router_to_agent::AgentCommand;
use crate::names::PortRef;
use crate::stats::AgentStats;
use serde::{Deserialize, Serialize};

/// Any request on the router's service `nerve/<robot>/router`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum RouterRequest {
    /// From an agent.
    Agent(AgentToRouter),
    /// From the command line.
    Cli(CliRequest),
}

/// A request from the command line.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum CliRequest {
    /// The live agents, with their statistics.
    Ps,
    /// The connection list, with live figures per connection.
    Graph,
    /// What happened in the graph since event `after` (0: all the router
    /// still holds): agents registered, left, died; edges made and removed.
    Events {
        /// the sequence number of the last event the caller has seen
        after: u64,
    },
    /// Connect an output port to an input port.
    Connect {
        /// output port
        from: PortRef,
        /// input port
        to: PortRef,
        /// connect even if it closes a cycle of event-driven agents
        /// ([`crate::cycles`]): an agent on it breaks the loop itself
        allow_cycle: bool,
    },
    /// Remove a connection.
    Disconnect {
        /// output port
        from: PortRef,
        /// input port
        to: PortRef,
    },
    /// Change the period of a periodic agent.
    Rate {
        /// agent
        name: String,
        /// new period
        period_ns: u64,
    },
    /// Suspend an agent's task.
    Suspend {
        /// agent
        name: String,
    },
    /// Resume an agent's task.
    Resume {
        /// agent
        name: String,
    },
    /// Read a parameter of an agent.
    ParamGet {
        /// agent
        name: String,
        /// parameter
        key: String,
    },
    /// List an agent's parameters and figures.
    ParamList {
        /// agent
        name: String,
    },
    /// Change a parameter of an agent.
    ParamSet {
        /// agent
        name: String,
        /// parameter
        key: String,
        /// value as text
        value: String,
    },
    /// Stop an agent cleanly.
    Stop {
        /// agent
        name: String,
    },
    /// Kill an agent with SIGKILL.
    Kill {
        /// agent
        name: String,
    },
    /// Supervise an agent: restart it by `argv` when it dies, per `policy`.
    Supervise(Supervision),
    /// Start agents: the router spawns each one not already running (in
    /// parallel) and answers with [`RouterReply::Started`] once every
    /// start-up process has said whether its agent started (protocol 9:
    /// the router is the only process that starts agents).
    Start {
        /// the agents, answered in this order
        agents: Vec<StartSpec>,
    },
    /// Stop the router itself.
    Shutdown,
    /// Feed input `to` from port `from` of a tool that is not an agent
    /// (`nerve cmd` publishes on `cli-<pid>/<input>`): the router checks the
    /// input and the type as for [`CliRequest::Connect`] and has the agent
    /// subscribe. The edge is not saved and not made again after a restart;
    /// it goes with `Detach`, when process `pid` is gone, or when the
    /// input's agent leaves.
    Attach {
        /// the tool's output port (its agent part names no running agent)
        from: PortRef,
        /// the tool's process
        pid: u32,
        /// the payload type the tool sends
        type_name: String,
        /// [`crate::Schema::fingerprint`] of that type as the tool was built
        fingerprint: u64,
        /// input port
        to: PortRef,
    },
    /// Remove an edge made by [`CliRequest::Attach`].
    Detach {
        /// the tool's output port
        from: PortRef,
        /// input port
        to: PortRef,
    },
    /// One agent with fresh statistics (answered with [`RouterReply::Agents`]
    /// of one view): what `Ps` gives for that agent, without asking the others.
    Agent {
        /// agent
        name: String,
    },
    /// Wait until every agent named has registered, or is in its
    /// supervisor's hands (restarting, failed), or `timeout_ns` has passed
    /// (the router caps it at a minute); answered with
    /// [`RouterReply::Waited`] naming those still missing. `nerve launch`
    /// asks it instead of polling the events and `ps`.
    WaitRegistered {
        /// agents
        names: Vec<String>,
        /// the longest wait
        timeout_ns: u64,
    },
}

/// When a supervised agent is restarted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartPolicy {
    /// Never.
    Never,
    /// When it dies without leaving cleanly (crash, kill).
    OnFailure,
    /// Whenever it exits, unless stopped by `nerve stop` or `nerve down`.
    Always,
}

/// How the router restarts an agent.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Supervision {
    /// agent name
    pub name: String,
    /// the command line that starts it as a daemon
    pub argv: Vec<String>,
    /// when to restart
    pub policy: RestartPolicy,
    /// restarts allowed within `window_ns`; past it the agent is marked failed
    pub max_restarts: u32,
    /// the window, ns
    pub window_ns: u64,
    /// first back-off delay, ns; it doubles with each restart in the window
    pub backoff_ns: u64,
    /// 1..10, for the resource manager
    pub importance: u8,
    /// the folder the agent was started in, where relative paths in `argv`
    /// (a world file, a knowledge base) are found; a restart starts there
    /// too, wherever the router runs
    #[serde(default)]
    pub cwd: Option<String>,
}

/// One agent for [`CliRequest::Start`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StartSpec {
    /// its name, the command line that starts it as a daemon (`--daemon`:
    /// the start-up process exits once the agent is ready, or says why
    /// not), the folder it starts in and, with `supervise`, how it is restarted
    pub agent: Supervision,
    /// hand it to supervision first (replacing an earlier spec of the
    /// name), as `nerve launch` does; `nerve start` does not
    pub supervise: bool,
    /// its whole environment (the caller's, so that a launch's
    /// `NERVE_SIM_CLOCK`, `PYTHONPATH`... reach the agent); `None`: the router's
    pub env: Option<Vec<(String, String)>>,
}

/// How the start of one agent went ([`RouterReply::Started`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StartOutcome {
    /// the agent
    pub name: String,
    /// what happened
    pub result: StartResult,
}

/// What became of one agent of a [`CliRequest::Start`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum StartResult {
    /// Its start-up process reported it ready.
    Started {
        /// what the start-up process printed: `NAME started (pid N, robot R)`
        said: String,
    },
    /// An agent of this name was registered already: nothing was started.
    Running {
        /// the live agent's pid
        pid: u32,
    },
    /// It did not start: the program could not be run, or its start-up
    /// process exited with an error (the agent's own message, and how it
    /// ended), or another request is starting the name.
    Failed {
        /// how the start-up process ended: `exit status 1`, `killed by
        /// SIGSEGV`, `not run`
        status: String,
        /// what it wrote on its standard error (the agent's message)
        said: String,
    },
}

/// Whether an agent's task runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AgentState {
    /// The task runs.
    Running,
    /// The task is suspended.
    Suspended,
    /// The agent does not answer its control service.
    Unresponsive,
    /// The agent died and its supervisor will restart it after a back-off.
    Restarting,
    /// The agent died too often; its supervisor gave up.
    Failed,
}

impl std::fmt::Display for AgentState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            AgentState::Running => "running",
            AgentState::Suspended => "suspended",
            AgentState::Unresponsive => "unresponsive",
            AgentState::Restarting => "restarting",
            AgentState::Failed => "failed",
        })
    }
}

/// How many events the router keeps; a caller that fell further behind
/// sees a gap in the sequence numbers.
pub const EVENTS_KEPT: usize = 1024;

/// Something that happened in the graph, as the router saw it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RouterEvent {
    /// from 1, one more per event
    pub seq: u64,
    /// CLOCK_REALTIME nanoseconds when the router saw it
    pub unix_ns: u64,
    /// what happened
    pub what: EventKind,
}

/// What a [`RouterEvent`] reports.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum EventKind {
    /// An agent registered.
    Registered {
        /// its name
        agent: String,
        /// its process
        pid: u32,
    },
    /// An agent unregistered and left cleanly.
    Left {
        /// its name
        agent: String,
        /// its process
        pid: u32,
    },
    /// An agent's process ended without unregistering: killed, crashed, aborted.
    Died {
        /// its name
        agent: String,
        /// its process
        pid: u32,
    },
    /// An edge was made.
    Connected {
        /// output port
        from: String,
        /// input port
        to: String,
    },
    /// An edge was removed.
    Disconnected {
        /// output port
        from: String,
        /// input port
        to: String,
    },
}

impl std::fmt::Display for EventKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EventKind::Registered { agent, pid } => write!(f, "{agent} (pid {pid}) registered"),
            EventKind::Left { agent, pid } => write!(f, "{agent} (pid {pid}) left"),
            EventKind::Died { agent, pid } => write!(f, "{agent} (pid {pid}) died"),
            EventKind::Connected { from, to } => write!(f, "connected {from} -> {to}"),
            EventKind::Disconnected { from, to } => write!(f, "disconnected {from} -> {to}"),
        }
    }
}

/// One live agent as `nerve ps` shows it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AgentView {
    /// name
    pub name: String,
    /// process id
    pub pid: u32,
    /// kind
    pub kind: String,
    /// state
    pub state: AgentState,
    /// periodic or event-driven
    pub task: TaskKind,
    /// period in nanoseconds (periodic agents)
    pub period_ns: Option<u64>,
    /// input ports with their types
    pub inputs: Vec<PortSpec>,
    /// output ports with their types
    pub outputs: Vec<PortSpec>,
    /// log file of a daemon
    pub log_file: Option<String>,
    /// statistics, when the agent answered in time
    pub stats: Option<AgentStats>,
    /// restarts by the supervisor since it was first supervised
    #[serde(default)]
    pub restarts: u32,
    /// importance (1..10) when supervised
    #[serde(default)]
    pub importance: Option<u8>,
    /// the schema of each type its ports carry (by fingerprint)
    #[serde(default)]
    pub schemas: Vec<crate::Schema>,
    /// the services it answers (`setup.serve`), typed as calls (protocol 12)
    #[serde(default)]
    pub services: Vec<PortSpec>,
    /// the clients it calls services through (`setup.client`, protocol 12)
    #[serde(default)]
    pub clients: Vec<PortSpec>,
}

impl AgentView {
    /// The schema of layout `fingerprint` on one of its ports: the one it
    /// registered, else a built-in type's.
    pub fn schema_for(&self, fingerprint: u64) -> Option<crate::Schema> {
        self.schemas
            .iter()
            .find(|s| s.fingerprint() == fingerprint)
            .cloned()
            .or_else(|| crate::schema::built_in(fingerprint))
    }
}

/// One connection as `nerve graph` shows it, with live figures measured at
/// the receiving input.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ConnectionView {
    /// output port
    pub from: String,
    /// input port
    pub to: String,
    /// payload type
    pub type_name: String,
    /// both ends are alive and the receiver holds the subscription
    pub active: bool,
    /// samples per second over the last seconds
    pub rate_hz: f64,
    /// age of the last sample received, in milliseconds
    pub last_age_ms: Option<f64>,
    /// samples received since the subscription was made
    pub received: u64,
    /// samples lost (sequence gaps) since the subscription was made
    pub dropped: u64,
    /// made by a tool with [`CliRequest::Attach`]: not saved, gone with the tool
    #[serde(default)]
    pub transient: bool,
    /// the input's depth, samples per source (issue 46; 16 by default)
    #[serde(default)]
    pub depth: u32,
    /// the input's policy past its depth: `latest` (overwrite the oldest,
    /// the default) or `all` (lose nothing)
    #[serde(default)]
    pub keep: String,
    /// a keep-all input the source publishes to losslessly (its sends wait)
    #[serde(default)]
    pub lossless: bool,
    /// samples overwritten in the input's own queue (a deep `latest` input)
    #[serde(default)]
    pub overwritten: u64,
    /// waits for this input: the source's sends that waited for its keep-all
    /// readers (all of them, when it has several), and times the input's own
    /// queue was full with samples waiting
    #[serde(default)]
    pub back_pressure: u64,
    /// samples the source gave up for its keep-all readers after the bounded wait
    #[serde(default)]
    pub lost: u64,
}

/// The whole graph.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GraphView {
    /// live agents with their ports
    pub agents: Vec<AgentView>,
    /// the connection list
    pub connections: Vec<ConnectionView>,
}

/// The router's answer.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum RouterReply {
    /// Done.
    Ok,
    /// A registration was accepted.
    Registered {
        /// the router's epoch, to notice a restarted router
        epoch: u64,
        /// what the agent carries out at once, in this order, before it
        /// serves any request: the kept connections of its inputs (each a
        /// [`AgentCommand::Connect`]), so that a restarted or hot-added
        /// agent reads its sources without waiting for the router to open
        /// a client to it and send them (protocol 7)
        first: Vec<AgentCommand>,
    },
    /// The live agents.
    Agents(Vec<AgentView>),
    /// The graph.
    Graph(GraphView),
    /// The value of a parameter.
    Param(String),
    /// An agent's parameters and figures.
    Params(Vec<super::router_to_agent::ParamInfo>),
    /// Events since the asked one, oldest first.
    Events {
        /// the router's epoch: a new router numbers its events from 1 again
        epoch: u64,
        /// the sequence number the next event will get
        next: u64,
        /// the events, at most [`EVENTS_KEPT`]
        events: Vec<RouterEvent>,
    },
    /// Refused.
    Error(RouterError),
    /// The answer to [`CliRequest::Start`]: one outcome per agent, in the
    /// request's order.
    Started(Vec<StartOutcome>),
    /// The answer to [`CliRequest::WaitRegistered`]: the agents named that
    /// have neither registered nor are in their supervisor's hands (none:
    /// all are there).
    Waited {
        /// still missing, by name
        missing: Vec<String>,
    },
}

fn list(v: &[String]) -> String {
    if v.is_empty() { "none".into() } else { v.join(", ") }
}

/// Why the router refused a request. The text says what to do.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, thiserror::Error)]
pub enum RouterError {
    /// The name is taken by a live agent.
    #[error(
        "an agent named {name:?} is already running (pid {pid}); choose another --name, or stop it first with `nerve stop {name}`"
    )]
    DuplicateName {
        /// name
        name: String,
        /// the live agent's pid
        pid: u32,
    },
    /// No live agent has that name.
    #[error("no agent named {name:?} is running (running: {}); see `nerve ps`", list(.running))]
    UnknownAgent {
        /// name
        name: String,
        /// the live agents
        running: Vec<String>,
    },
    /// The agent has no such port.
    #[error("agent {agent:?} has no {direction} port {port:?} (its {direction} ports: {}); see `nerve ps`", list(.available))]
    UnknownPort {
        /// agent
        agent: String,
        /// port
        port: String,
        /// "input" or "output"
        direction: String,
        /// the ports of that direction
        available: Vec<String>,
    },
    /// The two ports carry one type name built from different definitions
    /// (a stale build on one side): connecting them would misread every
    /// sample.
    #[error(
        "cannot connect {from} to {to}: both carry {type_name}, but built from different definitions of it \
         ({from} has layout {from_fingerprint:#018x}, {to} has {to_fingerprint:#018x}); {rebuild}"
    )]
    LayoutMismatch {
        /// output port
        from: String,
        /// input port
        to: String,
        /// the type name both carry
        type_name: String,
        /// the output's layout fingerprint
        from_fingerprint: u64,
        /// the input's layout fingerprint
        to_fingerprint: u64,
        /// what to rebuild: the agent with the older executable, when the
        /// router can tell
        rebuild: String,
    },
    /// The two ports carry different types.
    #[error("cannot connect {from} to {to}: {from} sends {from_type} but {to} takes {to_type}")]
    TypeMismatch {
        /// output port
        from: String,
        /// its type
        from_type: String,
        /// input port
        to: String,
        /// its type
        to_type: String,
    },
    /// The connection does not exist.
    #[error("{from} is not connected to {to}; see `nerve graph`")]
    NotConnected {
        /// output port
        from: String,
        /// input port
        to: String,
    },
    /// The agent refused the command.
    #[error("agent {name:?} refused: {message}")]
    AgentRefused {
        /// agent
        name: String,
        /// its reason
        message: String,
    },
    /// The agent did not answer.
    #[error("agent {name:?} did not answer: {detail}; check its log (`nerve ps` shows the log file)")]
    AgentUnreachable {
        /// agent
        name: String,
        /// what happened
        detail: String,
    },
    /// The connection would close a cycle of event-driven agents.
    #[error(
        "connecting {from} to {to} closes a loop of event-driven agents ({}): each sample would wake the next agent at once, forever; if an agent on it breaks the loop, connect with `nerve connect --allow-cycle` (or `allow_cycle = true` in the launch file's [[connect]])",
        .cycle.join(" -> ")
    )]
    Cycle {
        /// output port
        from: String,
        /// input port
        to: String,
        /// the agents on the loop, first and last the same
        cycle: Vec<String>,
    },
    /// The command does not apply to this agent.
    #[error("{0}")]
    NotApplicable(String),
    /// A name in the request is invalid.
    #[error("{0}")]
    InvalidName(String),
    /// The router could not do what was asked for another reason.
    #[error("router error: {0}")]
    Internal(String),
    /// The change is in effect but the connection list could not be saved.
    #[error(
        "{what}, but the connection list {file} could not be saved ({detail}): the change holds until the router restarts; free space or repair the file system, then run the command again"
    )]
    NotSaved {
        /// what was done
        what: String,
        /// the connection list's file
        file: String,
        /// why it could not be saved
        detail: String,
    },
    /// A registration whose pid the router cannot believe (reliability
    /// review R10): no such process, another user's, or not a nerve agent.
    #[error(
        "registration of agent {name:?} refused: pid {pid}: {reason}; an agent registers itself with its own pid (agent_sdk::run does this)"
    )]
    RegistrationRefused {
        /// the name it asked for
        name: String,
        /// the pid it gave
        pid: u32,
        /// which check failed
        reason: String,
    },
}
