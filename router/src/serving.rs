//! The router's core: what the router knows and its answer to every input,
//! as a state machine without I/O.
//!
//! [`State::handle`] takes one [`Input`] (a request of an agent or a tool,
//! an agent's reply, a save on disk, a death, the liveness tick) with the
//! time it came, changes the state, and returns the [`Effect`]s to carry
//! out: a command to an agent, a save, a spawn, a kill, a reply. It holds no
//! iceoryx2 node, no thread and no process, and reads no clock of its own:
//! `crate::driver` looks at processes and carries the effects out, and the
//! unit tests (`serving/tests.rs`) drive it directly, every request and
//! every fault the end-to-end tests inject, in milliseconds. A tool's
//! request is handled in `serving/cli.rs`, a job's end in
//! `serving/outcomes.rs`, `ps`'s view of the agents in `serving/views.rs`.
//!
//! A request the router can answer from what it knows (register, `Supervise`,
//! a refused `connect`) is answered at once. One that needs agents becomes a
//! [`Job`]: its commands go out as [`Effect::Send`], the job keeps the
//! caller's [`RequestId`], and it is answered when the last outcome is in.
//! A `Start` is a job too: its agents go out as [`Effect::Start`], and it is
//! answered when the last start-up process has ended ([`Input::StartEnded`]).
//! Nothing here waits, so a hung agent delays its own commands only
//! (reliability review R5, F2c).
//!
//! What the router records follows what the agents did, not what was asked
//! (F2d, F2e): an edge leaves the list when its input agent has let go of
//! it (or is not running), a `Suspend` marks the agent suspended when it
//! obeyed, and a `Stop` cancels the agent's restarts only when it obeyed.
//! The connection list is saved once per change, after the agent answered,
//! and the change is answered once that save is on disk (review R11a).

use crate::calls::{AGENT_TIMEOUT, Outcome, STATS_TIMEOUT, Ticket};
use crate::events::EventLog;
use crate::registry::{Entry, Registry};
use crate::remembered::{self, FORGET_AFTER, Remembered};
use crate::spawner::StartEnd;
use crate::store::{Connection, Store};
use crate::supervision::{Exit, Supervisor};
use crate::transient::{Attached, Transient};
use crate::wiring::{self, Wiring};
use agent_sdk::process::ProcessHandle;
use shm_schemas::control::ProtocolError;
use shm_schemas::control::agent_to_router::{PortSpec, Registration, TaskKind};
use shm_schemas::control::cli_to_router::{
    AgentState, AgentView, CliRequest, EventKind, GraphView, RouterError, RouterReply, StartOutcome, StartResult,
    StartSpec,
};
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use shm_schemas::cycles::event_cycle;
use shm_schemas::stats::AgentStats;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

mod cli;
mod outcomes;
#[cfg(test)]
mod tests;
mod views;

/// How often names gone for long are looked for.
const GC_PERIOD: Duration = Duration::from_secs(60);
/// The longest a [`CliRequest::WaitRegistered`] waits.
pub const MAX_WAIT_REGISTERED: Duration = Duration::from_secs(60);
/// How long `nerve kill` waits for the process to be gone.
pub const KILL_WAIT: Duration = Duration::from_millis(500);

/// Names a request whose reply is owed ([`Effect::Reply`]); given by the driver.
pub type RequestId = u64;
/// Names a save of the connection list ([`Effect::SaveList`], [`Input::Saved`]).
pub type SaveId = u64;

/// What the router's core is told.
#[derive(Debug)]
pub enum Input {
    /// An agent registers. `process`: its pid as the driver found it
    /// ([`crate::registry::check_process`]); `holder_alive`: the instance
    /// registered under this name with another pid still runs.
    Register {
        /// the request
        id: RequestId,
        /// what the agent sent
        reg: Registration,
        /// its process, or why it is not believed
        process: Result<ProcessHandle, RouterError>,
        /// the name's registered holder (another pid) is alive
        holder_alive: bool,
    },
    /// An agent leaves cleanly.
    Unregister {
        /// the request
        id: RequestId,
        /// agent
        name: String,
        /// its pid
        pid: u32,
    },
    /// A request of the command line or a tool. `tool`: for `Attach`, the
    /// tool's process as the driver found it.
    Cli {
        /// the request
        id: RequestId,
        /// what was asked
        req: CliRequest,
        /// the attaching tool's process, or why there is none
        tool: Option<Result<ProcessHandle, String>>,
    },
    /// An agent answered a command (or did not in time, or is gone).
    Outcome(Outcome),
    /// A save of the connection list is done (or failed, saying why).
    Saved {
        /// which save
        save: SaveId,
        /// done, or why not
        result: Result<(), String>,
    },
    /// A kill asked for by [`Effect::Kill`] is over: whether the process is
    /// still there after [`KILL_WAIT`], or why it could not be signalled.
    Killed {
        /// the kill's ticket
        ticket: Ticket,
        /// still alive, or the error
        result: Result<bool, RouterError>,
    },
    /// The liveness check: agents whose process is gone (name, pid) and
    /// tools (pids) that fed an input and are gone.
    Liveness {
        /// dead agents
        dead: Vec<(String, u32)>,
        /// pids of tools gone
        gone_tools: Vec<u32>,
    },
    /// An asked start ([`Effect::Start`]) is over: the start-up process
    /// said its agent is ready, or why not, or could not be run.
    StartEnded(StartEnd),
    /// The start-up process of a restarted agent failed before it registered.
    StartFailed {
        /// agent
        name: String,
    },
    /// The liveness tick: restarts due, agents missing after a router
    /// restart, names gone for long.
    Tick,
}

/// What the router's core asks to be done, in order.
#[derive(Debug, Clone)]
pub enum Effect {
    /// Answer request `id`.
    Reply {
        /// the request
        id: RequestId,
        /// the answer
        reply: RouterReply,
    },
    /// Queue a command to an agent; its outcome comes back as [`Input::Outcome`].
    Send {
        /// names the outcome
        ticket: Ticket,
        /// agent
        agent: String,
        /// command
        cmd: AgentCommand,
        /// how long to wait for the reply once sent
        timeout: Duration,
    },
    /// An agent of this name registered: reach it through a fresh client.
    Reach {
        /// agent
        agent: String,
    },
    /// An agent left or died: drop its client once nothing is pending.
    Release {
        /// agent
        agent: String,
    },
    /// Save the connection list (through its journal); done is told by [`Input::Saved`].
    SaveList {
        /// names the save
        save: SaveId,
        /// the file's bytes ([`Store::encode`])
        body: Vec<u8>,
    },
    /// Write a file atomically (the supervision list), nobody waiting.
    Write {
        /// file
        path: PathBuf,
        /// bytes
        body: Vec<u8>,
    },
    /// Remove a file (the supervision list at `nerve down`).
    Remove {
        /// file
        path: PathBuf,
    },
    /// Start an agent again (supervision); a failed start comes back as
    /// [`Input::StartFailed`].
    Spawn {
        /// agent
        name: String,
        /// command line
        argv: Vec<String>,
        /// where it was launched
        cwd: Option<String>,
        /// the environment it was launched with (`None`: the router's)
        env: Option<Vec<(String, String)>>,
        /// its restart count
        restart: u32,
    },
    /// Start an agent as a request asked ([`CliRequest::Start`]); the end
    /// of its start-up process comes back as [`Input::StartEnded`].
    Start {
        /// names the end
        ticket: Ticket,
        /// agent
        name: String,
        /// command line (it starts the agent as a daemon)
        argv: Vec<String>,
        /// the folder to start it in
        cwd: Option<String>,
        /// its environment (`None`: the router's)
        env: Option<Vec<(String, String)>>,
    },
    /// SIGKILL this process and wait up to [`KILL_WAIT`] for it to go;
    /// [`Input::Killed`] tells the end.
    Kill {
        /// names the end
        ticket: Ticket,
        /// agent
        name: String,
        /// its process as registered
        process: ProcessHandle,
    },
    /// Clean up the shared-memory resources of dead nodes.
    Sweep,
}

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
    /// `kill`: the process is gone (or the wait is over, or it could not be
    /// signalled)
    Kill { name: String, pid: u32, over: Option<Result<bool, RouterError>> },
    /// re-applying remembered state or a connection to a re-registered
    /// agent: logged, nobody waits
    Background { name: String, what: String, effect: Asked },
    /// `connect`/`disconnect` done: answered once the connection list is
    /// on disk (review R11a)
    Saved { save: SaveId, what: String, done: Option<Result<(), String>> },
    /// `CliRequest::WaitRegistered`: until all are there or `until`
    WaitRegistered { names: Vec<String>, until: Instant },
    /// `CliRequest::Start`: the agents in the request's order, and how
    /// each start went (the running ones and refusals at once, the others
    /// as their start-up processes end)
    Start { order: Vec<String>, results: BTreeMap<String, StartResult> },
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
            Work::WaitRegistered { .. } => "wait-registered",
            Work::Start { .. } => "start",
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
    reply: Option<RequestId>,
    waiting: Vec<Ticket>,
    outcomes: Vec<Outcome>,
    work: Work,
    /// when the request came (kept across the wait for the disk), for the
    /// debug log's timings
    since: Instant,
}

impl Job {
    /// A job waiting for `waiting`, answered to nobody yet (the caller's
    /// request is set when a request made it), timed from `now`.
    fn new(waiting: Vec<Ticket>, work: Work, now: Instant) -> Job {
        Job { reply: None, waiting, outcomes: Vec::new(), work, since: now }
    }

    /// Whether it has all it waits for.
    fn ready(&self) -> bool {
        match &self.work {
            Work::Kill { over, .. } => over.is_some(),
            Work::Saved { done, .. } => done.is_some(),
            _ => self.waiting.is_empty(),
        }
    }
}

/// Everything the router knows.
#[derive(Debug)]
pub struct State {
    pub(crate) epoch: u64,
    pub(crate) registry: Registry,
    pub(crate) wiring: Wiring,
    /// the edges of tools (`nerve cmd`), never saved
    pub(crate) transient: Transient,
    /// the connection list's file, named in a failed save's message
    list_file: PathBuf,
    /// the robot's log folder (`<name>.log`)
    logs_dir: PathBuf,
    pub(crate) supervisor: Supervisor,
    pub(crate) remembered: Remembered,
    pub(crate) jobs: Vec<Job>,
    /// what happened in the graph, for `CliRequest::Events`
    pub(crate) events: EventLog,
    pub(crate) shutdown: bool,
    last_gc: Option<Instant>,
    /// the last ticket given to a command or a kill
    ticket: Ticket,
    /// the last save of the connection list asked for
    save: SaveId,
    /// agents whose asked start is under way, with its ticket
    starting: BTreeMap<String, Ticket>,
    /// the effects of the input being handled
    out: Vec<Effect>,
    /// the time of the input being handled
    now: Instant,
}

/// The answer to a request the router cannot decode.
pub fn protocol_error(e: ProtocolError) -> RouterReply {
    RouterReply::Error(RouterError::Internal(e.to_string()))
}

/// How a command-line request starts.
enum Started {
    /// answered at once
    Answer(RouterReply),
    /// waits for agents
    Job(Box<Job>),
}

impl State {
    /// The router's state at start: `connections` and `supervisor` as the
    /// last router saved them; the connection list's file and the log
    /// folder are named in messages and views.
    pub fn new(
        epoch: u64,
        connections: Vec<Connection>,
        supervisor: Supervisor,
        list_file: PathBuf,
        logs_dir: PathBuf,
        now: Instant,
    ) -> State {
        State {
            epoch,
            registry: Registry::default(),
            wiring: Wiring::new(connections),
            transient: Transient::default(),
            list_file,
            logs_dir,
            supervisor,
            remembered: Remembered::default(),
            jobs: Vec::new(),
            events: EventLog::default(),
            shutdown: false,
            last_gc: Some(now),
            ticket: 0,
            save: 0,
            starting: BTreeMap::new(),
            out: Vec::new(),
            now,
        }
    }

    /// Takes `input`, which came at `now`; returns what to do, in order.
    pub fn handle(&mut self, now: Instant, input: Input) -> Vec<Effect> {
        self.now = now;
        match input {
            Input::Register { id, reg, process, holder_alive } => {
                let reply = self.register(reg, process, holder_alive);
                self.reply(id, reply);
            }
            Input::Unregister { id, name, pid } => {
                if self.registry.unregister(&name, pid) {
                    tracing::info!(agent = %name, pid, "agent {name} (pid {pid}) left");
                    self.events.push(EventKind::Left { agent: name.clone(), pid });
                    self.out.push(Effect::Release { agent: name.clone() });
                    self.exited(&name, false);
                }
                self.reply(id, RouterReply::Ok);
            }
            Input::Cli { id, req, tool } => match self.cli(req, tool) {
                Ok(Started::Answer(reply)) => self.reply(id, reply),
                Ok(Started::Job(mut job)) => {
                    job.reply = Some(id);
                    self.jobs.push(*job);
                }
                Err(e) => self.reply(id, RouterReply::Error(e)),
            },
            Input::Outcome(o) => {
                if let Some(job) = self.jobs.iter_mut().find(|j| j.waiting.contains(&o.ticket)) {
                    job.waiting.retain(|t| *t != o.ticket);
                    job.outcomes.push(o);
                }
            }
            Input::Saved { save, result } => {
                for job in &mut self.jobs {
                    if let Work::Saved { save: s, done, .. } = &mut job.work
                        && *s == save
                    {
                        *done = Some(result.clone());
                    }
                }
            }
            Input::Killed { ticket, result } => {
                if let Some(job) = self.jobs.iter_mut().find(|j| j.waiting.contains(&ticket)) {
                    job.waiting.clear();
                    if let Work::Kill { over, .. } = &mut job.work {
                        *over = Some(result);
                    }
                }
            }
            Input::Liveness { dead, gone_tools } => self.liveness(&dead, &gone_tools),
            Input::StartEnded(end) => self.start_ended(end),
            Input::StartFailed { name } => {
                if !self.registry.contains(&name) {
                    tracing::warn!(agent = %name, "the restarted {name} could not start (see its log)");
                    self.exited(&name, true);
                }
            }
            Input::Tick => self.tick(),
        }
        self.settle();
        std::mem::take(&mut self.out)
    }

    /// Whether requests wait for agents, a kill or the disk (a wait for
    /// registrations is not: registrations wake the router, and the
    /// liveness tick ends the wait).
    pub fn busy(&self) -> bool {
        self.jobs.iter().any(|j| !matches!(j.work, Work::WaitRegistered { .. } | Work::Start { .. }))
    }

    /// Whether `name` has registered or is in its supervisor's hands
    /// (restarting, failed): what a launch waits for.
    fn there(&self, name: &str) -> bool {
        self.registry.contains(name) || self.supervisor.get(name).is_some_and(|s| s.is_pending())
    }

    /// Whether the router is stopping and owes no answer any more.
    pub fn stopped(&self) -> bool {
        self.shutdown && self.jobs.is_empty()
    }

    fn reply(&mut self, id: RequestId, reply: RouterReply) {
        self.out.push(Effect::Reply { id, reply });
    }

    /// Asks for `cmd` to be sent to `agent`; its ticket.
    fn send(&mut self, agent: &str, cmd: AgentCommand, timeout: Duration) -> Ticket {
        self.ticket = self.ticket.wrapping_add(1);
        let ticket = self.ticket;
        self.out.push(Effect::Send { ticket, agent: agent.to_owned(), cmd, timeout });
        ticket
    }

    /// Asks for `cmd` to be sent to the live agent `name`, or says it is not live.
    fn submit(&mut self, name: &str, cmd: AgentCommand, timeout: Duration) -> Result<Ticket, RouterError> {
        self.registry.live(name)?;
        Ok(self.send(name, cmd, timeout))
    }

    /// A job of nobody's waiting for `tickets`, from now.
    fn job(&self, tickets: Vec<Ticket>, work: Work) -> Job {
        Job::new(tickets, work, self.now)
    }

    /// Asks for the supervision list to be saved.
    fn persist_supervision(&mut self) {
        self.out.push(Effect::Write { path: self.supervisor.path().to_owned(), body: self.supervisor.encode() });
    }

    /// Asks for the connection list to be saved; the save to wait for.
    fn persist_wiring(&mut self) -> SaveId {
        self.save = self.save.wrapping_add(1);
        self.out.push(Effect::SaveList { save: self.save, body: Store::encode(self.wiring.list()) });
        self.save
    }

    /// The job that answers `what` (done) once save `save` is on disk.
    fn when_saved(&self, save: SaveId, what: String) -> Job {
        self.job(Vec::new(), Work::Saved { save, what, done: None })
    }

    /// Answers the jobs that have all they wait for.
    fn settle(&mut self) {
        let mut i = 0;
        while i < self.jobs.len() {
            let ready = match &self.jobs[i].work {
                Work::WaitRegistered { names, until } => {
                    self.shutdown || self.now >= *until || names.iter().all(|n| self.there(n))
                }
                _ => self.jobs[i].ready(),
            };
            if ready {
                let job = self.jobs.swap_remove(i);
                self.finish(job);
            } else {
                i += 1;
            }
        }
    }

    /// `CliRequest::Start`: checks every spec first (nothing is started or
    /// supervised when one is invalid), supervises those asked to be, and
    /// starts each agent neither registered nor being started already.
    fn start(&mut self, agents: Vec<StartSpec>) -> Result<Started, RouterError> {
        if self.shutdown {
            return Err(RouterError::NotApplicable(
                "the router is stopping (`nerve down`): start the agents again once it is down".into(),
            ));
        }
        let mut order: Vec<String> = Vec::with_capacity(agents.len());
        for spec in &agents {
            crate::supervision::check(&spec.agent)?;
            if order.contains(&spec.agent.name) {
                return Err(RouterError::InvalidName(format!(
                    "{:?} is named twice in one start; give each agent a name of its own",
                    spec.agent.name
                )));
            }
            order.push(spec.agent.name.clone());
        }
        let mut supervised = false;
        for spec in agents.iter().filter(|s| s.supervise) {
            let registry = &self.registry;
            self.supervisor.supervise(spec.agent.clone(), self.now, |n| registry.contains(n))?;
            self.supervisor.set_env(&spec.agent.name, spec.env.clone());
            supervised = true;
        }
        if supervised {
            self.persist_supervision();
        }
        let mut results = BTreeMap::new();
        let mut tickets = Vec::new();
        for spec in agents {
            let StartSpec { agent, env, .. } = spec;
            let name = agent.name;
            if let Some(e) = self.registry.get(&name) {
                results.insert(name, StartResult::Running { pid: e.reg.pid });
                continue;
            }
            if self.starting.contains_key(&name) {
                let said = format!("{name} is being started by another request; see `nerve ps` in a moment");
                results.insert(name, StartResult::Failed { status: "not run".into(), said });
                continue;
            }
            self.ticket = self.ticket.wrapping_add(1);
            let ticket = self.ticket;
            self.starting.insert(name.clone(), ticket);
            tickets.push(ticket);
            self.out.push(Effect::Start { ticket, name, argv: agent.argv, cwd: agent.cwd, env });
        }
        Ok(self.waiting(tickets, Work::Start { order, results }))
    }

    /// An asked start is over: its job learns how it went. A start-up that
    /// failed is no death for supervision (the agent never ran: restarting
    /// it would fail the same way); its caller shows why.
    fn start_ended(&mut self, end: StartEnd) {
        let StartEnd { ticket, name, result } = end;
        if self.starting.get(&name) == Some(&ticket) {
            self.starting.remove(&name);
        }
        match &result {
            StartResult::Started { said } => tracing::info!(agent = %name, "{said}"),
            StartResult::Failed { status, said } => {
                tracing::warn!(agent = %name, status = %status, "{name} did not start ({status}): {said}")
            }
            StartResult::Running { .. } => {}
        }
        if let Some(job) = self.jobs.iter_mut().find(|j| j.waiting.contains(&ticket)) {
            job.waiting.retain(|t| *t != ticket);
            if let Work::Start { results, .. } = &mut job.work {
                results.insert(name, result);
            }
        }
    }

    fn register(
        &mut self,
        reg: Registration,
        process: Result<ProcessHandle, RouterError>,
        holder_alive: bool,
    ) -> RouterReply {
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
        let process = match process {
            Ok(p) => p,
            Err(e) => {
                tracing::warn!(agent = %name, pid, "{e}");
                return RouterReply::Error(e);
            }
        };
        if let Err(e) = self.registry.register(reg, process, holder_alive) {
            return RouterReply::Error(e);
        }
        tracing::info!(agent = %name, pid, "agent {name} registered: {summary}");
        self.events.push(EventKind::Registered { agent: name.clone(), pid });
        self.supervisor.registered(&name);
        self.out.push(Effect::Reach { agent: name.clone() });
        // Sent after this reply, by the driver's next pump: the agent goes
        // on starting its threads meanwhile. Its own inputs' connections
        // travel in the reply unless something re-applied must come first
        // (a suspend).
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
            let ticket = self.send(name, cmd, AGENT_TIMEOUT);
            let work = Work::Background { name: name.into(), what: format!("re-applied to {name}: {what}"), effect };
            let job = self.job(vec![ticket], work);
            self.jobs.push(job);
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
            let ticket = self.send(&agent, cmd, AGENT_TIMEOUT);
            let work = Work::Background {
                name: agent,
                what: format!("rewired {} -> {}", c.from, c.to),
                effect: Asked::Nothing,
            };
            let job = self.job(vec![ticket], work);
            self.jobs.push(job);
        }
        first
    }

    /// A supervised agent exited (`failure`: died without leaving cleanly).
    fn exited(&mut self, name: &str, failure: bool) {
        // its subscriptions to tools went with it, and a tool attaches anew
        for a in self.transient.into_agent(name) {
            self.events.push(EventKind::Disconnected { from: a.conn.from.to_string(), to: a.conn.to.to_string() });
        }
        let exit = if self.shutdown { Exit::Left } else { self.supervisor.exited(name, failure, self.now) };
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
                self.persist_supervision();
            }
        }
    }

    /// Takes the dead out of the registry and has agents let go of the
    /// ports of tools that are gone (a `nerve cmd` killed before it
    /// detached); the dead agents' connections are kept for their restart.
    fn liveness(&mut self, dead: &[(String, u32)], gone_tools: &[u32]) {
        for a in self.transient.orphaned(|p| gone_tools.contains(&p.pid())) {
            let (from, to) = (a.conn.from.to_string(), a.conn.to.to_string());
            self.events.push(EventKind::Disconnected { from: from.clone(), to: to.clone() });
            let (agent, cmd) = Wiring::disconnect_command(&a.conn);
            let what = format!("{to} let go of {from}, whose tool (pid {}) is gone", a.process.pid());
            let ticket = self.send(&agent, cmd, AGENT_TIMEOUT);
            let job = self.job(vec![ticket], Work::Background { name: agent, what, effect: Asked::Nothing });
            self.jobs.push(job);
        }
        let mut died = false;
        for (name, pid) in dead {
            if !self.registry.remove_dead(name, *pid) {
                continue;
            }
            died = true;
            tracing::warn!(agent = %name, pid, "agent {name} (pid {pid}) died; its connections are kept for its restart");
            self.events.push(EventKind::Died { agent: name.clone(), pid: *pid });
            self.out.push(Effect::Release { agent: name.clone() });
            self.exited(name, true);
        }
        if died {
            self.out.push(Effect::Sweep);
        }
    }

    /// The liveness tick: counts as dead the agents an earlier router
    /// expected and that never came back, starts the supervised agents
    /// whose back-off has passed, and forgets names gone for long.
    fn tick(&mut self) {
        let now = self.now;
        let registry = &self.registry;
        for name in self.supervisor.missing(now, |n| registry.contains(n)) {
            tracing::warn!(agent = %name, "{name} was running under the previous router and has not come back");
            self.exited(&name, true);
        }
        let registry = &self.registry;
        for (name, argv, restart) in self.supervisor.due(now, |n| registry.contains(n)) {
            let sup = self.supervisor.get(&name);
            let cwd = sup.and_then(|s| s.spec.cwd.clone());
            let env = sup.and_then(|s| s.env.clone());
            self.out.push(Effect::Spawn { name, argv, cwd, env, restart });
        }
        self.forget_gone();
    }

    /// Drops the remembered state and the supervision of names gone for
    /// [`FORGET_AFTER`]; keeps the time live names were last seen.
    fn forget_gone(&mut self) {
        let now = self.now;
        for (name, _) in self.registry.iter() {
            self.remembered.seen(name, now);
            self.supervisor.seen(name, now);
        }
        if self.last_gc.is_some_and(|t| now.saturating_duration_since(t) < GC_PERIOD) {
            return;
        }
        self.last_gc = Some(now);
        let registry = &self.registry;
        for name in self.remembered.forget_gone(now, |n| registry.contains(n)) {
            tracing::info!(agent = %name, "forgot the run-time state of {name}: gone for more than {FORGET_AFTER:?}");
        }
        let gone = self.supervisor.forget_gone(now, FORGET_AFTER, |n| registry.contains(n));
        for name in &gone {
            tracing::info!(agent = %name, "stopped supervising {name}: gone for more than {FORGET_AFTER:?}");
        }
        if !gone.is_empty() {
            self.persist_supervision();
        }
    }

    /// (from agent, to agent) of every connect still waiting for its agent
    /// and not allowed to close a loop.
    fn pending_loop_edges(&self) -> impl Iterator<Item = (&str, &str)> {
        self.jobs.iter().filter_map(|j| match &j.work {
            Work::Connect { conn } => wiring::loop_edge(conn),
            _ => None,
        })
    }

    /// A job of the request being handled, waiting for `tickets`.
    fn waiting(&self, tickets: Vec<Ticket>, work: Work) -> Started {
        Started::Job(Box::new(self.job(tickets, work)))
    }
}
