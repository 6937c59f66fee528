//! What each request does. The router's state ([`State`]) and its answer to
//! every request, agent or command line.
//!
//! A request the router can answer from what it knows (register, `Supervise`,
//! a refused `connect`) is answered at once. One that needs agents becomes a
//! [`Job`]: its commands go out through [`Calls`], the job keeps the
//! caller's [`Responder`], and it is answered when the last outcome is in.
//! Nothing here waits, so a hung agent delays its own commands only
//! (reliability review R5, F2c).
//!
//! What the router records follows what the agents did, not what was asked
//! (F2d, F2e): an edge leaves the list when its input agent has let go of
//! it (or is not running), a `Suspend` marks the agent suspended when it
//! obeyed, and a `Stop` cancels the agent's restarts only when it obeyed.

use crate::calls::{AGENT_TIMEOUT, Calls, Looks, Outcome, STATS_TIMEOUT, Ticket};
use crate::events::EventLog;
use crate::registry::{Entry, Registry};
use crate::remembered::{self, FORGET_AFTER, Remembered};
use crate::store::{Connection, ListSaves, Saved, Store, Writer};
use crate::supervision::{Exit, Supervisor};
use crate::transient::{Attached, Transient};
use crate::wiring::{self, Wiring};
use agent_sdk::control::Responder;
use agent_sdk::process::{ProcessError, ProcessHandle};
use agent_sdk::world::{Ipc, World};
use iceoryx2::prelude::Node;
use shm_schemas::control::ProtocolError;
use shm_schemas::control::agent_to_router::{AgentToRouter, PortSpec, Registration, TaskKind};
use shm_schemas::control::cli_to_router::{
    AgentState, AgentView, CliRequest, EventKind, GraphView, RouterError, RouterReply, RouterRequest,
};
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use shm_schemas::cycles::event_cycle;
use shm_schemas::stats::AgentStats;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// How often names gone for long are looked for.
const GC_PERIOD: Duration = Duration::from_secs(60);
/// How long `nerve kill` waits for the process to be gone.
const KILL_WAIT: Duration = Duration::from_millis(500);

/// What a job does when its outcomes are in.
#[derive(Debug)]
enum Work {
    /// `ps` or `graph`: statistics of every live agent
    Views { graph: bool, asked: BTreeMap<Ticket, String> },
    /// `CliRequest::Agent`: statistics of one agent
    AgentView { name: String },
    /// `connect`: the input agent subscribed
    Connect { conn: Connection },
    /// `disconnect`: the input agent let go
    Disconnect { conn: Connection },
    /// a tool's edge (`CliRequest::Attach`): the input agent subscribed
    Attach { attached: Attached },
    /// a tool's edge removed (`CliRequest::Detach`): the input agent let go
    Detach { conn: Connection },
    /// `rate`, `suspend`, `resume`, `param get/set`, `stop`
    Command { name: String, what: Asked },
    /// `kill`: the process is gone
    Kill { name: String, process: ProcessHandle, until: Instant },
    /// re-applying remembered state or a connection to a re-registered
    /// agent: logged, nobody waits
    Background { name: String, what: String, effect: Asked },
    /// `connect`/`disconnect` done (or refused: `refused`): answered once
    /// the connection list is on disk (review R11a)
    Saved { saved: Saved, what: String, refused: Option<RouterError> },
}

impl Work {
    /// A short name for the debug log.
    fn label(&self) -> &'static str {
        match self {
            Work::Views { .. } => "views",
            Work::Connect { .. } => "connect",
            Work::Disconnect { .. } => "disconnect",
            Work::Attach { .. } => "attach",
            Work::Detach { .. } => "detach",
            Work::AgentView { .. } => "agent",
            Work::Command { .. } => "command",
            Work::Kill { .. } => "kill",
            Work::Background { .. } => "background",
            Work::Saved { .. } => "saved",
        }
    }
}

/// A command whose success changes what the router records.
#[derive(Debug, Clone)]
enum Asked {
    Rate(u64),
    Suspend,
    Resume,
    ParamGet,
    ParamList,
    ParamSet {
        key: String,
        value: String,
    },
    Stop,
    /// nothing to record
    Nothing,
}

/// A request waiting for agents.
#[derive(Debug)]
pub struct Job {
    reply: Option<Responder<RouterReply>>,
    waiting: Vec<Ticket>,
    outcomes: Vec<Outcome>,
    work: Work,
    /// when the request came (kept across the wait for the disk), for the
    /// debug log's timings
    since: Instant,
}

impl Job {
    /// A job waiting for `waiting`, answered to nobody yet (the caller's
    /// responder is set when a request made it), timed from now.
    fn new(waiting: Vec<Ticket>, work: Work) -> Job {
        Job { reply: None, waiting, outcomes: Vec::new(), work, since: Instant::now() }
    }
}

/// Everything the router knows.
pub struct State {
    pub(crate) world: World,
    pub(crate) node: Node<Ipc>,
    pub(crate) epoch: u64,
    pub(crate) registry: Registry,
    pub(crate) wiring: Wiring,
    /// the edges of tools (`nerve cmd`), never saved
    pub(crate) transient: Transient,
    pub(crate) store: Store,
    pub(crate) writer: Writer,
    /// the connection list's saves
    pub(crate) saves: ListSaves,
    pub(crate) supervisor: Supervisor,
    pub(crate) remembered: Remembered,
    pub(crate) calls: Calls,
    pub(crate) jobs: Vec<Job>,
    /// what happened in the graph, for `CliRequest::Events`
    pub(crate) events: EventLog,
    pub(crate) shutdown: bool,
    pub(crate) last_gc: Instant,
}

/// The answer to a request the router cannot decode.
pub fn protocol_error(e: ProtocolError) -> RouterReply {
    RouterReply::Error(RouterError::Internal(e.to_string()))
}

fn answer(reply: Option<Responder<RouterReply>>, r: Result<RouterReply, RouterError>) {
    if let Some(responder) = reply {
        let r = r.unwrap_or_else(RouterReply::Error);
        responder.respond_or(&r, protocol_error);
    }
}

impl State {
    /// Takes a request: answers it, or makes it a job.
    pub fn accept(&mut self, req: Result<RouterRequest, ProtocolError>, responder: Responder<RouterReply>) {
        let req = match req {
            Ok(r) => r,
            Err(e) => return responder.respond_or(&protocol_error(e), protocol_error),
        };
        match req {
            RouterRequest::Agent(AgentToRouter::Register(reg)) => {
                let reply = self.register(reg);
                responder.respond_or(&reply, protocol_error);
            }
            RouterRequest::Agent(AgentToRouter::Unregister { name, pid }) => {
                if self.registry.unregister(&name, pid) {
                    tracing::info!(agent = %name, pid, "agent {name} (pid {pid}) left");
                    self.events.push(EventKind::Left { agent: name.clone(), pid });
                    self.calls.left(&name);
                    self.exited(&name, false);
                }
                responder.respond_or(&RouterReply::Ok, protocol_error);
            }
            RouterRequest::Cli(cli) => match self.cli(cli) {
                Ok(Started::Answer(reply)) => responder.respond_or(&reply, protocol_error),
                Ok(Started::Job(mut job)) => {
                    job.reply = Some(responder);
                    self.jobs.push(*job);
                }
                Err(e) => responder.respond_or(&RouterReply::Error(e), protocol_error),
            },
        }
    }

    fn register(&mut self, reg: Registration) -> RouterReply {
        let name = reg.name.clone();
        let summary = format!(
            "kind {}, pid {}, {}, inputs [{}], outputs [{}]",
            reg.kind,
            reg.pid,
            reg.task,
            reg.inputs.iter().map(|p| format!("{}: {}", p.name, p.type_name)).collect::<Vec<_>>().join(", "),
            reg.outputs.iter().map(|p| format!("{}: {}", p.name, p.type_name)).collect::<Vec<_>>().join(", ")
        );
        let pid = reg.pid;
        let process = match crate::registry::check_process(&reg, &self.world) {
            Ok(p) => p,
            Err(e) => {
                tracing::warn!(agent = %name, pid, "{e}");
                return RouterReply::Error(e);
            }
        };
        if let Err(e) = self.registry.register(reg, process) {
            return RouterReply::Error(e);
        }
        tracing::info!(agent = %name, pid, "agent {name} registered: {summary}");
        self.events.push(EventKind::Registered { agent: name.clone(), pid });
        self.supervisor.registered(&name);
        self.calls.registered(&name);
        // Sent after this reply, by the next pump: the agent goes on starting
        // its threads meanwhile. Its own inputs' connections travel in the
        // reply unless something re-applied must come first (a suspend).
        let reapplied = self.reapply(&name);
        let first = self.rewire(&name, !reapplied);
        RouterReply::Registered { epoch: self.epoch, first }
    }

    /// Queues what was set at run time for an earlier agent of this name:
    /// a suspend first (so that it does not run meanwhile), then parameters
    /// and period, a resume last. Whether anything was queued.
    fn reapply(&mut self, name: &str) -> bool {
        let Some(mem) = self.remembered.get(name).cloned() else { return false };
        let Some(entry) = self.registry.get(name) else { return false };
        let registered_suspended = entry.state == AgentState::Suspended;
        let registered_period = entry.reg.period_ns;
        let mut todo = Vec::new();
        if mem.suspended == Some(true) && !registered_suspended {
            todo.push((AgentCommand::Suspend, "suspend".to_owned(), Asked::Suspend));
        }
        for (key, value) in &mem.params {
            todo.push((
                AgentCommand::ParamSet { key: key.clone(), value: value.clone() },
                format!("{key} = {value}"),
                Asked::Nothing,
            ));
        }
        if let Some(period_ns) = mem.period_ns.filter(|p| Some(*p) != registered_period) {
            let what = format!("period {}", agent_sdk::clock::format_duration(Duration::from_nanos(period_ns)));
            todo.push((AgentCommand::SetPeriod { period_ns }, what, Asked::Rate(period_ns)));
        }
        if mem.suspended == Some(false) && registered_suspended {
            todo.push((AgentCommand::Resume, "resume".to_owned(), Asked::Resume));
        }
        let queued = !todo.is_empty();
        for (cmd, what, effect) in todo {
            let ticket = self.calls.submit(name, cmd, AGENT_TIMEOUT);
            let work = Work::Background { name: name.into(), what: format!("re-applied to {name}: {what}"), effect };
            self.jobs.push(Job::new(vec![ticket], work));
        }
        queued
    }

    /// Queues every stored connection that involves `name` and whose other
    /// end is live. With `in_reply`, those into `name`'s own inputs are
    /// returned instead, for the registration's reply: the agent makes them
    /// at once, about a millisecond before the router could have opened a
    /// client to it and sent them (a hot-add, a restart; issue 18).
    fn rewire(&mut self, name: &str, in_reply: bool) -> Vec<AgentCommand> {
        let registry = &self.registry;
        let mut first = Vec::new();
        for c in self.wiring.involving(name, |a| registry.contains(a)) {
            let (agent, cmd) = Wiring::connect_command(&c);
            if in_reply && agent == name {
                tracing::info!(agent = name, "rewiring {} -> {}: handed to {name} with its registration", c.from, c.to);
                first.push(cmd);
                continue;
            }
            let ticket = self.calls.submit(&agent, cmd, AGENT_TIMEOUT);
            let work = Work::Background {
                name: agent,
                what: format!("rewired {} -> {}", c.from, c.to),
                effect: Asked::Nothing,
            };
            self.jobs.push(Job::new(vec![ticket], work));
        }
        first
    }

    /// A supervised agent exited (`failure`: died without leaving cleanly).
    fn exited(&mut self, name: &str, failure: bool) {
        // its subscriptions to tools went with it, and a tool attaches anew
        for a in self.transient.into_agent(name) {
            self.events.push(EventKind::Disconnected { from: a.conn.from, to: a.conn.to });
        }
        let exit = if self.shutdown { Exit::Left } else { self.supervisor.exited(name, failure, Instant::now()) };
        match exit {
            Exit::Left => {}
            Exit::Restart(delay) => {
                let s = self.supervisor.get(name);
                tracing::warn!(
                    agent = name,
                    ?delay,
                    "restarting {name} in {delay:?} (at most {} restarts within {:?})",
                    s.map_or(0, |s| s.spec.max_restarts),
                    s.map_or(Duration::ZERO, |s| Duration::from_nanos(s.spec.window_ns))
                );
            }
            Exit::Failed { restarts, window } => {
                tracing::error!(
                    agent = name,
                    restarts,
                    "agent {name} failed: {restarts} restarts within {window:?}; not restarting it (see its log, fix it, then `nerve start` it or launch again)"
                );
                self.supervisor.persist(&self.writer);
            }
        }
    }

    /// Removes dead agents from the registry and cleans their resources.
    pub fn check_liveness(&mut self) {
        if !self.transient.is_empty() {
            self.detach_orphans();
        }
        let dead = self.registry.dead();
        if dead.is_empty() {
            return;
        }
        for (name, pid) in &dead {
            tracing::warn!(agent = %name, pid, "agent {name} (pid {pid}) died; its connections are kept for its restart");
            self.events.push(EventKind::Died { agent: name.clone(), pid: *pid });
            self.calls.left(name);
            self.exited(name, true);
        }
        self.sweep();
    }

    /// Has agents let go of the ports of tools that are gone (a `nerve cmd`
    /// killed before it detached).
    fn detach_orphans(&mut self) {
        for a in self.transient.orphaned() {
            let (from, to) = (a.conn.from.clone(), a.conn.to.clone());
            self.events.push(EventKind::Disconnected { from: from.clone(), to: to.clone() });
            let (agent, cmd) = Wiring::disconnect_command(&a.conn);
            let what = format!("{to} let go of {from}, whose tool (pid {}) is gone", a.process.pid());
            let ticket = self.calls.submit(&agent, cmd, AGENT_TIMEOUT);
            self.jobs.push(Job::new(vec![ticket], Work::Background { name: agent, what, effect: Asked::Nothing }));
        }
    }

    /// Cleans up after dead processes that were not agents (tools, programs).
    pub fn sweep(&mut self) {
        let cleaned = self.world.cleanup_dead_nodes();
        if cleaned > 0 {
            tracing::info!(cleaned, "cleaned the shared-memory resources of {cleaned} dead node(s)");
        }
    }

    /// Starts the supervised agents whose back-off has passed, and counts
    /// as dead those an earlier router expected and that never came back.
    pub fn run_restarts(&mut self) {
        for name in self.supervisor.reap() {
            if !self.registry.contains(&name) {
                tracing::warn!(agent = %name, "the restarted {name} could not start (see its log)");
                self.exited(&name, true);
            }
        }
        let now = Instant::now();
        let registry = &self.registry;
        for name in self.supervisor.missing(now, |n| registry.contains(n)) {
            tracing::warn!(agent = %name, "{name} was running under the previous router and has not come back");
            self.exited(&name, true);
        }
        let registry = &self.registry;
        for (name, argv, restart) in self.supervisor.due(now, |n| registry.contains(n)) {
            let log = self.world.log_file(&name);
            self.supervisor.spawn(&name, &argv, &log, restart);
        }
    }

    /// Drops the remembered state and the supervision of names gone for
    /// [`FORGET_AFTER`]; keeps the time live names were last seen.
    pub fn forget_gone(&mut self) {
        let now = Instant::now();
        for (name, _) in self.registry.iter() {
            self.remembered.seen(name, now);
            self.supervisor.seen(name, now);
        }
        if now.duration_since(self.last_gc) < GC_PERIOD {
            return;
        }
        self.last_gc = now;
        let registry = &self.registry;
        for name in self.remembered.forget_gone(now, |n| registry.contains(n)) {
            tracing::info!(agent = %name, "forgot the run-time state of {name}: gone for more than {FORGET_AFTER:?}");
        }
        let gone = self.supervisor.forget_gone(now, FORGET_AFTER, |n| registry.contains(n));
        for name in &gone {
            tracing::info!(agent = %name, "stopped supervising {name}: gone for more than {FORGET_AFTER:?}");
        }
        if !gone.is_empty() {
            self.supervisor.persist(&self.writer);
        }
    }

    /// Hands the connection list to the writer thread, which saves it off
    /// the request path (its fsyncs take 10-60 ms on a busy disk).
    fn persist_wiring(&mut self) -> Saved {
        self.saves.save(&self.writer, &self.store, self.wiring.list())
    }

    /// Queues `list` for the disk (see [`ListSaves`]: a rewire queues the
    /// list it expects while the agent works).
    fn persist_list(&mut self, list: &[Connection]) -> Saved {
        self.saves.save(&self.writer, &self.store, list)
    }

    /// Answers a rewire the agent refused once the list is back on disk as
    /// it is: the list it was expected to become may have been written
    /// meanwhile ([`State::persist_list`]).
    fn answer_when_written_back(&mut self, reply: Option<Responder<RouterReply>>, since: Instant, e: RouterError) {
        let saved = self.persist_wiring();
        let work = Work::Saved { saved, what: String::new(), refused: Some(e) };
        self.jobs.push(Job { reply, since, ..Job::new(Vec::new(), work) });
    }

    /// The job that answers `what` (done) once save `saved` is on disk.
    fn when_saved(saved: Saved, what: String) -> Job {
        Job::new(Vec::new(), Work::Saved { saved, what, refused: None })
    }

    /// Whether jobs wait for something the loop must look at soon.
    pub fn busy(&self) -> bool {
        // a job waits for agents, a death or a save: each is looked at soon
        self.calls.busy() || !self.jobs.is_empty()
    }

    /// Whether a job waits for something no event announces (a process to
    /// die, the disk writer), so that the serving loop must look again soon
    /// by itself; replies of agents wake it (see [`crate::calls`]).
    pub fn needs_polling(&self) -> bool {
        self.jobs.iter().any(|j| matches!(j.work, Work::Kill { .. } | Work::Saved { .. }))
            || (self.calls.busy() && !self.calls.in_flight())
    }

    /// (from agent, to agent) of every connect still waiting for its agent
    /// and not allowed to close a loop.
    fn pending_loop_edges(&self) -> impl Iterator<Item = (&str, &str)> {
        self.jobs.iter().filter_map(|j| match &j.work {
            Work::Connect { conn } => wiring::loop_edge(conn),
            _ => None,
        })
    }

    fn submit(&mut self, name: &str, cmd: AgentCommand, timeout: Duration) -> Result<Ticket, RouterError> {
        self.registry.live(name)?;
        Ok(self.calls.submit(name, cmd, timeout))
    }

    fn cli(&mut self, req: CliRequest) -> Result<Started, RouterError> {
        // answer from a registry without dead agents (a few /proc reads)
        self.check_liveness();
        let command = |s: &mut Self, name: String, cmd: AgentCommand, what: Asked| -> Result<Started, RouterError> {
            let ticket = s.submit(&name, cmd, AGENT_TIMEOUT)?;
            Ok(Started::waiting(vec![ticket], Work::Command { name, what }))
        };
        match req {
            CliRequest::Ps | CliRequest::Graph => {
                let graph = matches!(req, CliRequest::Graph);
                let names: Vec<String> = self.registry.iter().map(|(n, _)| n.clone()).collect();
                let mut asked = BTreeMap::new();
                for name in names {
                    let ticket = self.calls.submit(&name, AgentCommand::Stats, STATS_TIMEOUT);
                    asked.insert(ticket, name);
                }
                Ok(Started::waiting(asked.keys().copied().collect(), Work::Views { graph, asked }))
            }
            CliRequest::Agent { name } => {
                self.registry.live(&name)?;
                let ticket = self.calls.submit(&name, AgentCommand::Stats, STATS_TIMEOUT);
                Ok(Started::waiting(vec![ticket], Work::AgentView { name }))
            }
            CliRequest::Attach { from, pid, type_name, fingerprint, to } => {
                if self.registry.contains(from.agent.as_str()) {
                    return Err(RouterError::NotApplicable(format!(
                        "{from} is an agent's port: connect it with `nerve connect {from} {to}`"
                    )));
                }
                let process = ProcessHandle::take(pid).map_err(|e| {
                    RouterError::NotApplicable(format!("cannot attach {from}: its process {pid} is not there ({e})"))
                })?;
                let spec = PortSpec { name: from.port.clone(), type_name, fingerprint };
                self.registry.check_input(&from, &spec, &to)?;
                let conn = Connection {
                    from: from.to_string(),
                    to: to.to_string(),
                    type_name: spec.type_name,
                    allow_cycle: false,
                };
                let (agent, cmd) = Wiring::connect_command(&conn);
                let ticket = self.submit(&agent, cmd, AGENT_TIMEOUT)?;
                Ok(Started::waiting(vec![ticket], Work::Attach { attached: Attached { conn, process } }))
            }
            CliRequest::Detach { from, to } => {
                let (f, t) = (from.to_string(), to.to_string());
                if self.registry.contains(from.agent.as_str()) {
                    return Err(RouterError::NotConnected { from: f, to: t });
                }
                let conn = match self.transient.remove(&f, &t) {
                    Some(a) => {
                        self.events.push(EventKind::Disconnected { from: f, to: t });
                        a.conn
                    }
                    // attached under an earlier router: the agent may still hold it
                    None => Connection { from: f, to: t, type_name: String::new(), allow_cycle: false },
                };
                let (agent, cmd) = Wiring::disconnect_command(&conn);
                let ticket = self.submit(&agent, cmd, AGENT_TIMEOUT)?;
                Ok(Started::waiting(vec![ticket], Work::Detach { conn }))
            }
            CliRequest::Events { after } => Ok(Started::Answer(RouterReply::Events {
                epoch: self.epoch,
                next: self.events.next(),
                events: self.events.after(after),
            })),
            CliRequest::Connect { from, to, allow_cycle } => {
                let from_type = self.registry.check_compatible(&from, &to)?;
                if !allow_cycle {
                    let registry = &self.registry;
                    let event_driven = |n: &str| registry.get(n).is_some_and(|e| e.reg.task == TaskKind::EventDriven);
                    // a loop through an edge allowed to close one is allowed;
                    // connects still waiting for their agent count too, so
                    // that requests sent side by side (`nerve launch`) cannot
                    // close a loop between them unseen
                    let edges = self.wiring.loop_edges().chain(self.pending_loop_edges());
                    if let Some(cycle) = event_cycle(edges, from.agent.as_str(), to.agent.as_str(), event_driven) {
                        return Err(RouterError::Cycle { from: from.to_string(), to: to.to_string(), cycle });
                    }
                }
                let conn = Connection { from: from.to_string(), to: to.to_string(), type_name: from_type, allow_cycle };
                let (agent, cmd) = Wiring::connect_command(&conn);
                let ticket = self.submit(&agent, cmd, AGENT_TIMEOUT)?;
                let mut expected = Wiring::new(self.wiring.list().to_vec());
                if expected.add(conn.clone()) {
                    self.persist_list(expected.list());
                }
                Ok(Started::waiting(vec![ticket], Work::Connect { conn }))
            }
            CliRequest::Disconnect { from, to } => {
                let (f, t) = (from.to_string(), to.to_string());
                let Some(conn) = self.wiring.find(&f, &t).cloned() else {
                    return Err(RouterError::NotConnected { from: f, to: t });
                };
                if !self.registry.contains(to.agent.as_str()) {
                    // nobody reads it: the list is the whole truth
                    self.wiring.remove(&f, &t);
                    self.events.push(EventKind::Disconnected { from: f.clone(), to: t.clone() });
                    let saved = self.persist_wiring();
                    tracing::info!(from = %f, to = %t, "disconnected {f} -> {t}");
                    return Ok(Started::Job(Box::new(Self::when_saved(saved, format!("disconnected {f} -> {t}")))));
                }
                let (agent, cmd) = Wiring::disconnect_command(&conn);
                let ticket = self.submit(&agent, cmd, AGENT_TIMEOUT)?;
                let mut expected = Wiring::new(self.wiring.list().to_vec());
                expected.remove(&f, &t);
                self.persist_list(expected.list());
                Ok(Started::waiting(vec![ticket], Work::Disconnect { conn }))
            }
            CliRequest::Rate { name, period_ns } => {
                command(self, name, AgentCommand::SetPeriod { period_ns }, Asked::Rate(period_ns))
            }
            CliRequest::Suspend { name } => command(self, name, AgentCommand::Suspend, Asked::Suspend),
            CliRequest::Resume { name } => command(self, name, AgentCommand::Resume, Asked::Resume),
            CliRequest::ParamGet { name, key } => command(self, name, AgentCommand::ParamGet { key }, Asked::ParamGet),
            CliRequest::ParamList { name } => command(self, name, AgentCommand::ParamList, Asked::ParamList),
            CliRequest::ParamSet { name, key, value } => {
                let cmd = AgentCommand::ParamSet { key: key.clone(), value: value.clone() };
                command(self, name, cmd, Asked::ParamSet { key, value })
            }
            CliRequest::Stop { name } => {
                if !self.registry.contains(&name) {
                    // a supervised agent waiting for its restart: stopping it
                    // cancels the restart (there is no process to disagree)
                    if self.supervisor.stopped_by_user(&name) {
                        self.supervisor.persist(&self.writer);
                    }
                    return Err(self.registry.unknown(&name));
                }
                command(self, name, AgentCommand::Stop, Asked::Stop)
            }
            CliRequest::Supervise(spec) => {
                tracing::info!(
                    agent = %spec.name,
                    "supervising {}: restart {:?}, at most {} restarts in {:?}",
                    spec.name,
                    spec.policy,
                    spec.max_restarts,
                    Duration::from_nanos(spec.window_ns)
                );
                let registry = &self.registry;
                self.supervisor.supervise(spec, Instant::now(), |n| registry.contains(n))?;
                self.supervisor.persist(&self.writer);
                Ok(Started::Answer(RouterReply::Ok))
            }
            CliRequest::Kill { name } => {
                // through the handle taken at registration: a pid reused since
                // the agent died (and before the liveness check saw it) is not signalled
                let process = self.registry.live(&name)?.process.clone();
                let pid = process.pid();
                match process.signal(nix::sys::signal::Signal::SIGKILL) {
                    Ok(()) => tracing::info!(agent = %name, pid, "killed agent {name} (pid {pid}) on request"),
                    Err(ProcessError::Gone { .. }) => {
                        tracing::info!(agent = %name, pid, "{name} (pid {pid}) had exited already")
                    }
                    Err(e) => return Err(RouterError::Internal(e.to_string())),
                }
                Ok(Started::waiting(vec![], Work::Kill { name, process, until: Instant::now() + KILL_WAIT }))
            }
            CliRequest::Shutdown => {
                self.shutdown = true;
                self.supervisor.forget_all(&self.writer);
                Ok(Started::Answer(RouterReply::Ok))
            }
        }
    }

    /// Hands the outcomes of agent commands to their jobs, and answers the
    /// jobs that are complete.
    pub fn pump(&mut self, looks: &Looks) {
        let outcomes = self.calls.pump(&self.world, &self.node, Instant::now(), looks);
        for o in outcomes {
            if let Some(job) = self.jobs.iter_mut().find(|j| j.waiting.contains(&o.ticket)) {
                job.waiting.retain(|t| *t != o.ticket);
                job.outcomes.push(o);
            }
        }
        let mut i = 0;
        while i < self.jobs.len() {
            let ready = match &self.jobs[i].work {
                Work::Kill { process, until, .. } => !process.is_alive() || Instant::now() >= *until,
                Work::Saved { saved, .. } => self.writer.outcome(*saved).is_some(),
                _ => self.jobs[i].waiting.is_empty(),
            };
            if ready {
                let job = self.jobs.swap_remove(i);
                self.finish(job);
            } else {
                i += 1;
            }
        }
    }

    fn finish(&mut self, job: Job) {
        let Job { reply, mut outcomes, work, since, .. } = job;
        let label = work.label();
        tracing::debug!(job = label, us = since.elapsed().as_micros() as u64, "job ready");
        let mut single = || {
            outcomes
                .pop()
                .map_or_else(|| Err(RouterError::Internal("a command without an outcome".into())), |o| o.result)
        };
        let result = match work {
            Work::Views { graph, asked } => {
                let mut stats: BTreeMap<String, AgentStats> = BTreeMap::new();
                for o in outcomes {
                    let name = asked.get(&o.ticket).cloned().unwrap_or(o.agent);
                    if let Ok(AgentReply::Stats(s)) = o.result {
                        stats.insert(name, s);
                    }
                }
                let agents = self.views(&stats);
                Ok(if graph {
                    let mut connections = self.wiring.views(&agents);
                    connections.extend(self.transient.connections().map(|c| wiring::view(c, &agents, true)));
                    RouterReply::Graph(GraphView { agents, connections })
                } else {
                    RouterReply::Agents(agents)
                })
            }
            Work::Connect { conn } => match single() {
                Ok(_) => {
                    tracing::info!(from = %conn.from, to = %conn.to, "connected {} -> {}", conn.from, conn.to);
                    let what = format!("connected {} -> {}", conn.from, conn.to);
                    let event = EventKind::Connected { from: conn.from.clone(), to: conn.to.clone() };
                    if self.wiring.add(conn) {
                        self.events.push(event);
                        let saved = self.persist_wiring();
                        return self.jobs.push(Job { reply, since, ..Self::when_saved(saved, what) });
                    }
                    Ok(RouterReply::Ok)
                }
                Err(e) => return self.answer_when_written_back(reply, since, e),
            },
            Work::AgentView { name } => match single() {
                // one view, not every agent's (`nerve cmd` asks every 20 ms); none if it left meanwhile
                Ok(AgentReply::Stats(s)) => Ok(RouterReply::Agents(
                    self.registry.get(&name).map(|e| self.live_view(&name, e, Some(s))).into_iter().collect(),
                )),
                Ok(other) => Err(RouterError::Internal(format!("unexpected reply {other:?}"))),
                Err(e) => Err(e),
            },
            Work::Attach { attached } => single().map(|_| {
                let (from, to) = (attached.conn.from.clone(), attached.conn.to.clone());
                let pid = attached.process.pid();
                tracing::info!(from = %from, to = %to, pid, "attached {from} -> {to} (a tool, pid {pid})");
                if self.transient.add(attached) {
                    self.events.push(EventKind::Connected { from, to });
                }
                RouterReply::Ok
            }),
            Work::Detach { conn } => {
                // it let go, or it did not have it: either way nothing flows
                match single() {
                    Ok(_) | Err(RouterError::AgentRefused { .. }) => {
                        tracing::info!(from = %conn.from, to = %conn.to, "detached {} -> {}", conn.from, conn.to);
                        Ok(RouterReply::Ok)
                    }
                    Err(e) => Err(e),
                }
            }
            Work::Disconnect { conn } => match single() {
                // it let go, or it did not have it: either way nothing flows
                Ok(_) | Err(RouterError::AgentRefused { .. }) => {
                    self.wiring.remove(&conn.from, &conn.to);
                    self.events.push(EventKind::Disconnected { from: conn.from.clone(), to: conn.to.clone() });
                    let saved = self.persist_wiring();
                    tracing::info!(from = %conn.from, to = %conn.to, "disconnected {} -> {}", conn.from, conn.to);
                    let what = format!("disconnected {} -> {}", conn.from, conn.to);
                    return self.jobs.push(Job { reply, since, ..Self::when_saved(saved, what) });
                }
                Err(RouterError::AgentUnreachable { name, detail }) => {
                    let e = RouterError::AgentUnreachable {
                        detail: format!(
                            "{detail}; {} -> {} stays in the connection list since {name} may still read it: try again, or `nerve kill {name}` and disconnect then",
                            conn.from, conn.to
                        ),
                        name,
                    };
                    return self.answer_when_written_back(reply, since, e);
                }
                Err(e) => return self.answer_when_written_back(reply, since, e),
            },
            Work::Command { name, what } => single().map(|reply| self.obeyed(&name, &what, reply)),
            Work::Kill { name, process, .. } => {
                self.check_liveness();
                let pid = process.pid();
                if process.is_alive() {
                    tracing::warn!(agent = %name, pid, "{name} (pid {pid}) is still there {KILL_WAIT:?} after SIGKILL");
                }
                Ok(RouterReply::Ok)
            }
            Work::Saved { refused: Some(e), .. } => Err(e),
            Work::Saved { saved, what, refused: None } => match self.writer.outcome(saved) {
                Some(Err(detail)) => {
                    Err(RouterError::NotSaved { what, file: self.store.path().display().to_string(), detail })
                }
                _ => Ok(RouterReply::Ok),
            },
            Work::Background { name, what, effect } => {
                match single() {
                    Ok(reply) => {
                        tracing::info!(agent = %name, "{what}");
                        self.obeyed(&name, &effect, reply);
                    }
                    Err(e) => tracing::warn!(agent = %name, "not done: {what}: {e}"),
                }
                return;
            }
        };
        if reply.is_some() {
            tracing::debug!(job = label, us = since.elapsed().as_micros() as u64, "answered");
        }
        answer(reply, result);
    }

    /// Records what an agent obeyed; the reply to give.
    fn obeyed(&mut self, name: &str, what: &Asked, reply: AgentReply) -> RouterReply {
        let now = Instant::now();
        match what {
            Asked::Rate(period_ns) => {
                if let Some(e) = self.registry.get_mut(name) {
                    e.reg.period_ns = Some(*period_ns);
                }
                self.remembered.set_period(name, *period_ns, now);
            }
            Asked::Suspend | Asked::Resume => {
                let suspended = matches!(what, Asked::Suspend);
                if let Some(e) = self.registry.get_mut(name) {
                    e.state = if suspended { AgentState::Suspended } else { AgentState::Running };
                }
                self.remembered.set_suspended(name, suspended, now);
            }
            Asked::ParamGet => {
                return match reply {
                    AgentReply::Param(v) => RouterReply::Param(v),
                    other => RouterReply::Error(RouterError::Internal(format!("unexpected reply {other:?}"))),
                };
            }
            Asked::ParamList => {
                return match reply {
                    AgentReply::Params(v) => RouterReply::Params(v),
                    other => RouterReply::Error(RouterError::Internal(format!("unexpected reply {other:?}"))),
                };
            }
            Asked::ParamSet { key, value } => {
                if !self.remembered.set_param(name, key, value, now) {
                    tracing::warn!(
                        agent = name,
                        "{name}: {key} = {value} is set but not remembered for a restart: {} other parameters of it are",
                        remembered::MAX_PARAMS
                    );
                }
            }
            Asked::Stop => {
                if self.supervisor.stopped_by_user(name) {
                    self.supervisor.persist(&self.writer);
                }
            }
            Asked::Nothing => {}
        }
        RouterReply::Ok
    }

    /// The agents as `ps` shows them: the live ones with the statistics
    /// they answered (`unresponsive` when they did not), then the supervised
    /// ones that are restarting or failed.
    fn views(&self, stats: &BTreeMap<String, AgentStats>) -> Vec<AgentView> {
        let mut out = Vec::new();
        for (name, e) in self.registry.iter() {
            out.push(self.live_view(name, e, stats.get(name).cloned()));
        }
        for (name, sup) in self.supervisor.iter() {
            if self.registry.contains(name) || !sup.is_pending() {
                continue;
            }
            out.push(AgentView {
                name: name.clone(),
                pid: 0,
                kind: sup.spec.argv[0].rsplit('/').next().unwrap_or("").trim_start_matches("nerve-").to_owned(),
                state: if sup.failed { AgentState::Failed } else { AgentState::Restarting },
                task: TaskKind::Periodic,
                period_ns: None,
                inputs: vec![],
                outputs: vec![],
                log_file: Some(self.world.log_file(name).display().to_string()),
                stats: None,
                restarts: sup.total,
                importance: Some(sup.spec.importance),
                schemas: vec![],
            });
        }
        out.sort_by(|a, b| a.name.cmp(&b.name));
        out
    }

    /// Live agent `name` as `ps` shows it, with the statistics it answered
    /// (`None`: it did not, and shows as unresponsive).
    fn live_view(&self, name: &str, e: &Entry, stats: Option<AgentStats>) -> AgentView {
        let sup = self.supervisor.get(name);
        AgentView {
            name: name.to_owned(),
            pid: e.reg.pid,
            kind: e.reg.kind.clone(),
            state: if stats.is_some() { e.state } else { AgentState::Unresponsive },
            task: e.reg.task,
            period_ns: if e.reg.task == TaskKind::Periodic { e.reg.period_ns } else { None },
            inputs: e.reg.inputs.clone(),
            outputs: e.reg.outputs.clone(),
            log_file: e.reg.log_file.clone(),
            stats,
            restarts: sup.map(|s| s.total).unwrap_or(0),
            importance: sup.map(|s| s.spec.importance),
            schemas: e.reg.schemas.clone(),
        }
    }
}

/// How a command-line request starts.
enum Started {
    /// answered at once
    Answer(RouterReply),
    /// waits for agents
    Job(Box<Job>),
}

impl Started {
    fn waiting(tickets: Vec<Ticket>, work: Work) -> Started {
        Started::Job(Box::new(Job::new(tickets, work)))
    }
}
