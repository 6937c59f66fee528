//! The nerve router: the registry of live agents and the connection list.
//!
//! It is control plane only. Agents register with it at start
//! ([`AgentToRouter::Register`]) and leave on stop; the command line asks it
//! to connect, disconnect, change rates, suspend, resume, set parameters and
//! stop agents, and it carries these out by commanding the agents' message
//! checkers. Data never passes through it: killing the router stops no data
//! flow.
//!
//! * **Liveness**: every 250 ms it checks each agent's pid (and notices
//!   zombies); a dead agent is removed from the live registry and the stale
//!   iceoryx2 resources of dead nodes are cleaned. Its connections are kept,
//!   so that the agent restarted under the same name is rewired.
//! * **Persistence**: the connection list is saved atomically in the robot's
//!   state directory and reloaded at start.
//! * **Restart**: at start the router publishes a new epoch on
//!   `nerve/<robot>/router/epoch`; running agents see it and re-register.
//! * **Run-time state**: what `nerve suspend`, `resume`, `rate` and
//!   `param set` changed is remembered per agent name and re-applied when an
//!   agent of that name registers again ([`remembered`]).
//! * **Bounds**: the registry holds live agents only; the remembered state
//!   and the supervision entries are bounded in number, and those of names
//!   gone for [`remembered::FORGET_AFTER`] are dropped (a supervised agent
//!   still waiting for its restart is kept). The connection list is the
//!   user's wiring, persisted, and is never dropped behind their back.

pub mod remembered;
pub mod store;

use agent_sdk::clock::now_ns;
use agent_sdk::control::{ControlClient, ControlError, ControlServer, ControlSize};
use agent_sdk::runtime::epoch_service;
use agent_sdk::world::{Ipc, World, pid_alive};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use remembered::{FORGET_AFTER, Remembered};
use shm_schemas::control::agent_to_router::{AgentToRouter, Registration, TaskKind};
use shm_schemas::control::cli_to_router::{
    AgentState, AgentView, CliRequest, ConnectionView, GraphView, RestartPolicy, RouterError, RouterReply,
    RouterRequest, Supervision,
};
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use shm_schemas::payloads::RouterEpoch;
use shm_schemas::stats::AgentStats;
use shm_schemas::{AgentName, PortRef};
use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};
use store::{Connection, Store, Writer};

/// How long the router waits for an agent's message checker to answer.
pub const AGENT_TIMEOUT: Duration = Duration::from_millis(1000);
/// How long it waits for statistics (per agent, for `ps` and `graph`).
pub const STATS_TIMEOUT: Duration = Duration::from_millis(300);
/// How often liveness is checked.
pub const LIVENESS_PERIOD: Duration = Duration::from_millis(250);

struct Entry {
    reg: Registration,
    client: Option<ControlClient<AgentCommand, AgentReply>>,
    state: AgentState,
}

enum Action {
    /// Re-apply every connection that involves this agent.
    Rewire(String),
}

/// The longest back-off between two restarts.
pub const MAX_BACKOFF: Duration = Duration::from_secs(10);

/// Supervision state of one agent.
struct Supervised {
    spec: Supervision,
    /// restart times within the window
    recent: VecDeque<Instant>,
    total: u32,
    failed: bool,
    next_start: Option<Instant>,
    /// `nerve stop` asked it to leave: do not restart
    stopped_by_user: bool,
    /// when its agent was last live (or supervision was asked for)
    last_seen: Instant,
}

impl Supervised {
    fn new(spec: Supervision, now: Instant) -> Self {
        Supervised {
            spec,
            recent: VecDeque::new(),
            total: 0,
            failed: false,
            next_start: None,
            stopped_by_user: false,
            last_seen: now,
        }
    }
}

/// The most agents the router supervises at once.
pub const MAX_SUPERVISED: usize = 1024;
/// How often names gone for long are looked for.
const GC_PERIOD: Duration = Duration::from_secs(60);

/// A supervision spec the router can act on: a valid agent name (it names
/// the log file the router opens, so `../x` would write outside the robot's
/// logs: reliability review R10) and a command line.
fn check_supervision(spec: &shm_schemas::control::cli_to_router::Supervision) -> Result<(), RouterError> {
    AgentName::new(&spec.name).map_err(|e| RouterError::InvalidName(format!("{:?}: {e}", spec.name)))?;
    if spec.argv.is_empty() {
        return Err(RouterError::NotApplicable("supervision needs a command line".into()));
    }
    Ok(())
}

/// Drops the supervision of names that are not live, not waiting for a
/// restart, and gone for more than `forget_after` before `now`; returns them.
fn forget_gone_supervision(
    supervised: &mut BTreeMap<String, Supervised>,
    now: Instant,
    forget_after: Duration,
    live: impl Fn(&str) -> bool,
) -> Vec<String> {
    let gone: Vec<String> = supervised
        .iter()
        .filter(|(n, s)| {
            !live(n) && s.next_start.is_none() && now.saturating_duration_since(s.last_seen) > forget_after
        })
        .map(|(n, _)| n.clone())
        .collect();
    for n in &gone {
        supervised.remove(n);
    }
    gone
}

/// Why the router could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// Another router serves this robot.
    #[error("a router already runs for robot {robot}; use it, or stop it first with `nerve --robot {robot} down`")]
    AlreadyRunning {
        /// robot
        robot: String,
    },
    /// Anything else, with its message.
    #[error("{0}")]
    Other(String),
}

/// The router of one robot.
pub struct Router {
    /// agents register here (many clients, small messages)
    server: ControlServer<RouterRequest, RouterReply>,
    /// tools and programs call here (few clients, replies of any size)
    cli_server: ControlServer<RouterRequest, RouterReply>,
    epoch_pub: Publisher<Ipc, RouterEpoch, ()>,
    state: State,
}

/// Everything but the server, so that request handlers can borrow it mutably.
struct State {
    world: World,
    node: Node<Ipc>,
    epoch: u64,
    agents: BTreeMap<String, Entry>,
    connections: Vec<Connection>,
    writer: Writer,
    pending: VecDeque<Action>,
    shutdown: bool,
    supervised: BTreeMap<String, Supervised>,
    /// start-up processes of restarted agents, reaped as they exit
    children: Vec<std::process::Child>,
    /// run-time state re-applied to a re-registering agent
    remembered: Remembered,
    last_gc: Instant,
}

impl std::fmt::Debug for Router {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Router")
            .field("robot", self.state.world.robot())
            .field("agents", &self.state.agents.len())
            .finish()
    }
}

impl Router {
    /// Creates the router of `world`, loading the persisted connection list.
    pub fn new(world: World) -> Result<Self, StartError> {
        world.ensure_state_dirs().map_err(|e| StartError::Other(e.to_string()))?;
        let node = world.node("router").map_err(|e| StartError::Other(e.to_string()))?;
        world.cleanup_dead_nodes();
        let serve = |service: String, size: ControlSize| {
            ControlServer::create(&node, &service, size).map_err(|e| match e {
                ControlError::AlreadyServed { .. } => StartError::AlreadyRunning { robot: world.robot().to_string() },
                e => StartError::Other(e.to_string()),
            })
        };
        let server = serve(world.robot().router_service(), ControlSize::ROUTER)?;
        let cli_server = serve(world.robot().router_cli_service(), ControlSize::ROUTER_CLI)?;
        let store = Store::new(world.state_dir());
        let connections = store.load().map_err(StartError::Other)?;
        let epoch = now_ns() ^ ((std::process::id() as u64) << 32);
        let epoch_pub = epoch_service(&node, &world)
            .map_err(StartError::Other)?
            .publisher_builder()
            .create()
            .map_err(|e| StartError::Other(format!("cannot publish the router epoch: {e:?}")))?;
        epoch_pub
            .send_copy(RouterEpoch { epoch, pid: std::process::id(), reserved: 0 })
            .map_err(|e| StartError::Other(format!("cannot publish the router epoch: {e:?}")))?;
        tracing::info!(
            "router of robot {} started (pid {}), {} connection(s) loaded from {}",
            world.robot(),
            std::process::id(),
            connections.len(),
            store.path().display()
        );
        Ok(Router {
            server,
            cli_server,
            epoch_pub,
            state: State {
                world,
                node,
                epoch,
                agents: BTreeMap::new(),
                connections,
                writer: Writer::start(store.clone())
                    .map_err(|e| StartError::Other(format!("cannot start the persisting thread: {e}")))?,
                pending: VecDeque::new(),
                shutdown: false,
                supervised: BTreeMap::new(),
                children: Vec::new(),
                remembered: Remembered::default(),
                last_gc: Instant::now(),
            },
        })
    }

    /// Serves until SIGTERM, SIGINT or a `Shutdown` request.
    ///
    /// Call it from the thread that set the router's scheduling policy:
    /// that thread's real-time policy is marked not to pass to the agents
    /// the supervisor restarts from it (see [`reset_realtime_on_fork`]).
    pub fn run(mut self) -> Result<(), String> {
        reset_realtime_on_fork();
        let ws = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Ipc>()
            .map_err(|e| format!("cannot create the router's WaitSet: {e:?}"))?;
        let _req = ws.attach_notification(self.server.listener()).map_err(|e| format!("{e:?}"))?;
        let _cli = ws.attach_notification(self.cli_server.listener()).map_err(|e| format!("{e:?}"))?;
        let _tick = ws.attach_interval(LIVENESS_PERIOD).map_err(|e| format!("{e:?}"))?;
        let mut last_liveness = Instant::now();
        let watchdog = agent_sdk::daemon::watchdog_interval();
        let mut last_ping = Instant::now();
        while !self.state.shutdown {
            match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
                Ok(WaitSetRunResult::TerminationRequest) => break,
                Ok(_) => {}
                Err(e) => {
                    tracing::warn!("router wait failed: {e:?}");
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
            for server in [&self.server, &self.cli_server] {
                let state = &mut self.state;
                if let Err(e) = server.serve(|req| match req {
                    Ok(req) => state.handle(req),
                    Err(e) => RouterReply::Error(RouterError::Internal(e.to_string())),
                }) {
                    tracing::warn!("router service failed: {e}");
                }
            }
            while let Some(action) = self.state.pending.pop_front() {
                match action {
                    Action::Rewire(name) => {
                        self.state.reapply(&name);
                        self.state.rewire(&name);
                    }
                }
            }
            if last_liveness.elapsed() >= LIVENESS_PERIOD {
                last_liveness = Instant::now();
                self.state.check_liveness();
                self.state.run_restarts();
                self.state.forget_gone();
                self.server.tidy();
                self.cli_server.tidy();
                let _ = self.epoch_pub.update_connections();
            }
            if let Some(wd) = watchdog
                && last_ping.elapsed() >= wd / 2
            {
                let _ = agent_sdk::daemon::sd_notify("WATCHDOG=1");
                last_ping = Instant::now();
            }
        }
        self.state.writer.flush();
        tracing::info!("router stopped");
        Ok(())
    }
}

/// Marks the calling thread's real-time policy (SCHED_FIFO or SCHED_RR, set
/// by `nerve router` before it serves) with `SCHED_RESET_ON_FORK`, so that
/// every process and thread it creates starts under SCHED_OTHER.
///
/// Without it an agent restarted by the supervisor inherited the router's
/// SCHED_FIFO 10 through fork and exec: every thread of it, the task of a
/// `--no-realtime` agent, helper threads and a CPU-bound step included, ran
/// real-time and could starve normal work, where the same agent started by
/// `nerve launch` ran them SCHED_OTHER. A normal-priority router has
/// nothing to pass on and is left alone.
pub fn reset_realtime_on_fork() {
    // SAFETY: sched_getscheduler and sched_getparam on the calling thread (0)
    // with a valid sched_param; no other memory is touched.
    let (policy, mut param) = unsafe {
        let mut param = std::mem::zeroed::<libc::sched_param>();
        (libc::sched_getscheduler(0), if libc::sched_getparam(0, &mut param) == 0 { Some(param) } else { None })
    };
    let policy = policy & !libc::SCHED_RESET_ON_FORK;
    if !(policy == libc::SCHED_FIFO || policy == libc::SCHED_RR) {
        return;
    }
    let Some(param) = param.as_mut() else { return };
    // SAFETY: sets the calling thread's own policy to the one it has, plus the flag.
    let rc = unsafe { libc::sched_setscheduler(0, policy | libc::SCHED_RESET_ON_FORK, param) };
    if rc != 0 {
        tracing::warn!(
            "cannot mark the router's real-time policy reset-on-fork ({}); agents the supervisor restarts may run real-time",
            std::io::Error::last_os_error()
        );
    }
}

fn unknown_agent(name: &str, agents: &BTreeMap<String, Entry>) -> RouterError {
    RouterError::UnknownAgent { name: name.into(), running: agents.keys().cloned().collect() }
}

impl State {
    fn handle(&mut self, req: RouterRequest) -> RouterReply {
        match req {
            RouterRequest::Agent(AgentToRouter::Register(reg)) => self.register(reg),
            RouterRequest::Agent(AgentToRouter::Unregister { name, pid }) => {
                if self.agents.get(&name).is_some_and(|e| e.reg.pid == pid) {
                    self.agents.remove(&name);
                    tracing::info!("agent {name} (pid {pid}) left");
                    self.exited(&name, false);
                }
                RouterReply::Ok
            }
            RouterRequest::Cli(cli) => match self.handle_cli(cli) {
                Ok(reply) => reply,
                Err(e) => RouterReply::Error(e),
            },
        }
    }

    fn register(&mut self, reg: Registration) -> RouterReply {
        if let Err(e) = AgentName::new(&reg.name) {
            return RouterReply::Error(RouterError::InvalidName(e.to_string()));
        }
        if let Some(existing) = self.agents.get(&reg.name)
            && existing.reg.pid != reg.pid
            && pid_alive(existing.reg.pid)
        {
            return RouterReply::Error(RouterError::DuplicateName { name: reg.name, pid: existing.reg.pid });
        }
        let name = reg.name.clone();
        // The agent's control client is opened when first needed (by the
        // rewiring queued below, right after this reply), not before the
        // reply: the agent goes on starting its threads meanwhile.
        let client = None;
        tracing::info!(
            "agent {name} registered: kind {}, pid {}, {}, inputs [{}], outputs [{}]",
            reg.kind,
            reg.pid,
            reg.task,
            reg.inputs.iter().map(|p| format!("{}: {}", p.name, p.type_name)).collect::<Vec<_>>().join(", "),
            reg.outputs.iter().map(|p| format!("{}: {}", p.name, p.type_name)).collect::<Vec<_>>().join(", ")
        );
        let state = if reg.suspended { AgentState::Suspended } else { AgentState::Running };
        if let Some(sup) = self.supervised.get_mut(&name) {
            sup.stopped_by_user = false;
            sup.next_start = None;
        }
        self.agents.insert(name.clone(), Entry { reg, client, state });
        self.pending.push_back(Action::Rewire(name));
        RouterReply::Registered { epoch: self.epoch }
    }

    fn open_agent(&self, name: &str) -> Option<ControlClient<AgentCommand, AgentReply>> {
        let agent = AgentName::new(name).ok()?;
        let service = self.world.robot().ctl_service(&agent);
        let mut opened = ControlClient::open_reserved(&self.node, &service, ControlSize::AGENT);
        if matches!(opened, Err(ControlError::Ipc { .. } | ControlError::Full { .. })) {
            // Every client slot may be taken, some by tools that were
            // killed: clean the ports of dead processes and try once more.
            let cleaned = self.world.cleanup_dead_nodes();
            if cleaned > 0 {
                tracing::info!("cleaned the shared-memory resources of {cleaned} dead node(s) to reach {name}");
            }
            opened = ControlClient::open_reserved(&self.node, &service, ControlSize::AGENT);
        }
        match opened {
            Ok(c) => Some(c),
            Err(e) => {
                tracing::warn!("cannot open the control service of {name}: {e}");
                None
            }
        }
    }

    /// Sends a command to a live agent.
    fn command(&mut self, name: &str, cmd: &AgentCommand, timeout: Duration) -> Result<AgentReply, RouterError> {
        if !self.agents.contains_key(name) {
            return Err(unknown_agent(name, &self.agents));
        }
        let mut result = self.call_agent(name, cmd, timeout, false);
        if matches!(result, Some(Err(ControlError::NoServer { .. }))) {
            // The client was opened while the agent's previous instance (same
            // name) was still leaving, and may be bound to the service it
            // tore down: open it afresh and try once more (seen about once in
            // 40 hot-add/stop cycles).
            if let Some(again) = self.call_agent(name, cmd, timeout, true) {
                result = Some(again);
            }
        }
        match result {
            None => Err(RouterError::AgentUnreachable {
                name: name.into(),
                detail: "its control service is missing".into(),
            }),
            Some(Ok(AgentReply::Error(message))) => Err(RouterError::AgentRefused { name: name.into(), message }),
            Some(Ok(reply)) => Ok(reply),
            Some(Err(e)) => Err(RouterError::AgentUnreachable { name: name.into(), detail: e.to_string() }),
        }
    }

    /// Calls `name` through its control client, opening the client first
    /// when it has none or when `reopen`; `None` when it cannot be opened.
    fn call_agent(
        &mut self,
        name: &str,
        cmd: &AgentCommand,
        timeout: Duration,
        reopen: bool,
    ) -> Option<Result<AgentReply, ControlError>> {
        if reopen || self.agents.get(name).is_some_and(|e| e.client.is_none()) {
            let client = self.open_agent(name);
            if let Some(e) = self.agents.get_mut(name) {
                e.client = client;
            }
        }
        let client = self.agents.get(name).and_then(|e| e.client.as_ref())?;
        Some(client.call(cmd, timeout))
    }

    /// Re-applies to a newly registered `name` what was set at run time for
    /// an earlier agent of that name: a suspend first (so that it does not
    /// run meanwhile), then parameters and period, a resume last. An agent
    /// that does not answer is not tried further (the router would wait for
    /// each command).
    fn reapply(&mut self, name: &str) {
        let Some(mem) = self.remembered.get(name).cloned() else { return };
        let Some(entry) = self.agents.get(name) else { return };
        let registered_suspended = entry.state == AgentState::Suspended;
        let registered_period = entry.reg.period_ns;
        let mut todo = Vec::new();
        if mem.suspended == Some(true) && !registered_suspended {
            todo.push(AgentCommand::Suspend);
        }
        for (key, value) in &mem.params {
            todo.push(AgentCommand::ParamSet { key: key.clone(), value: value.clone() });
        }
        if let Some(period_ns) = mem.period_ns.filter(|p| Some(*p) != registered_period) {
            todo.push(AgentCommand::SetPeriod { period_ns });
        }
        if mem.suspended == Some(false) && registered_suspended {
            todo.push(AgentCommand::Resume);
        }
        for cmd in todo {
            let what = match &cmd {
                AgentCommand::Suspend => "suspend".to_owned(),
                AgentCommand::Resume => "resume".to_owned(),
                AgentCommand::SetPeriod { period_ns } => {
                    format!("period {}", agent_sdk::clock::format_duration(Duration::from_nanos(*period_ns)))
                }
                AgentCommand::ParamSet { key, value } => format!("{key} = {value}"),
                other => format!("{other:?}"),
            };
            match self.command(name, &cmd, AGENT_TIMEOUT) {
                Ok(_) => {
                    tracing::info!("re-applied to {name}: {what}");
                    if let Some(e) = self.agents.get_mut(name) {
                        match cmd {
                            AgentCommand::Suspend => e.state = AgentState::Suspended,
                            AgentCommand::Resume => e.state = AgentState::Running,
                            AgentCommand::SetPeriod { period_ns } => e.reg.period_ns = Some(period_ns),
                            _ => {}
                        }
                    }
                }
                Err(e @ RouterError::AgentRefused { .. }) => {
                    tracing::warn!("could not re-apply {what} to {name}: {e}");
                }
                Err(e) => {
                    tracing::warn!("could not re-apply {what} (and what follows) to {name}: {e}; set it again by hand");
                    break;
                }
            }
        }
    }

    /// Drops the remembered state and the supervision of names gone for
    /// [`FORGET_AFTER`]; keeps the time live names were last seen.
    fn forget_gone(&mut self) {
        let now = Instant::now();
        for name in self.agents.keys() {
            self.remembered.seen(name, now);
            if let Some(s) = self.supervised.get_mut(name) {
                s.last_seen = now;
            }
        }
        if now.duration_since(self.last_gc) < GC_PERIOD {
            return;
        }
        self.last_gc = now;
        let agents = &self.agents;
        for name in self.remembered.forget_gone(now, |n| agents.contains_key(n)) {
            tracing::info!("forgot the run-time state of {name}: gone for more than {FORGET_AFTER:?}");
        }
        for name in forget_gone_supervision(&mut self.supervised, now, FORGET_AFTER, |n| agents.contains_key(n)) {
            tracing::info!("stopped supervising {name}: gone for more than {FORGET_AFTER:?}");
        }
    }

    /// Applies every stored connection that involves `name` and whose other end is live.
    fn rewire(&mut self, name: &str) {
        let todo: Vec<Connection> = self
            .connections
            .iter()
            .filter(|c| port_agent(&c.from) == name || port_agent(&c.to) == name)
            .filter(|c| self.agents.contains_key(port_agent(&c.from)) && self.agents.contains_key(port_agent(&c.to)))
            .cloned()
            .collect();
        for c in todo {
            match self.send_connect(&c) {
                Ok(()) => tracing::info!("rewired {} -> {}", c.from, c.to),
                Err(e) => tracing::warn!("could not rewire {} -> {}: {e}", c.from, c.to),
            }
        }
    }

    fn send_connect(&mut self, c: &Connection) -> Result<(), RouterError> {
        let (from_agent, from_port) = split_port(&c.from);
        let (to_agent, to_port) = split_port(&c.to);
        let cmd = AgentCommand::Connect {
            input: to_port.into(),
            from_agent: from_agent.into(),
            from_port: from_port.into(),
            type_name: c.type_name.clone(),
        };
        self.command(to_agent, &cmd, AGENT_TIMEOUT).map(|_| ())
    }

    /// Hands the connection list to the writer thread, which saves it off
    /// the request path (its fsyncs take 10-60 ms on a busy disk).
    fn persist(&self) {
        self.writer.save(self.connections.clone());
    }

    fn check_liveness(&mut self) {
        let dead: Vec<(String, u32)> =
            self.agents.iter().filter(|(_, e)| !pid_alive(e.reg.pid)).map(|(n, e)| (n.clone(), e.reg.pid)).collect();
        if dead.is_empty() {
            return;
        }
        for (name, pid) in &dead {
            self.agents.remove(name);
            tracing::warn!("agent {name} (pid {pid}) died; its connections are kept for its restart");
            self.exited(name, true);
        }
        let cleaned = self.world.cleanup_dead_nodes();
        if cleaned > 0 {
            tracing::info!("cleaned the shared-memory resources of {cleaned} dead node(s)");
        }
    }

    fn port_spec<'a>(&'a self, p: &PortRef, output: bool) -> Result<&'a str, RouterError> {
        let entry = self.agents.get(p.agent.as_str()).ok_or_else(|| unknown_agent(p.agent.as_str(), &self.agents))?;
        let ports = if output { &entry.reg.outputs } else { &entry.reg.inputs };
        ports.iter().find(|s| s.name == p.port).map(|s| s.type_name.as_str()).ok_or_else(|| RouterError::UnknownPort {
            agent: p.agent.to_string(),
            port: p.port.clone(),
            direction: if output { "output" } else { "input" }.into(),
            available: ports.iter().map(|s| s.name.clone()).collect(),
        })
    }

    fn handle_cli(&mut self, req: CliRequest) -> Result<RouterReply, RouterError> {
        // answer from a registry without dead agents (a few /proc reads)
        self.check_liveness();
        match req {
            CliRequest::Ps => Ok(RouterReply::Agents(self.views())),
            CliRequest::Graph => {
                let agents = self.views();
                let connections = self.connection_views(&agents);
                Ok(RouterReply::Graph(GraphView { agents, connections }))
            }
            CliRequest::Connect { from, to } => {
                let from_type = self.port_spec(&from, true)?.to_owned();
                let to_type = self.port_spec(&to, false)?.to_owned();
                if from_type != to_type {
                    return Err(RouterError::TypeMismatch {
                        from: from.to_string(),
                        from_type,
                        to: to.to_string(),
                        to_type,
                    });
                }
                let c = Connection { from: from.to_string(), to: to.to_string(), type_name: from_type };
                let t0 = std::time::Instant::now();
                self.send_connect(&c)?;
                tracing::debug!("{from} -> {to}: the agent subscribed and answered in {} us", t0.elapsed().as_micros());
                if !self.connections.contains(&c) {
                    self.connections.push(c);
                    self.persist();
                }
                tracing::info!("connected {from} -> {to}");
                Ok(RouterReply::Ok)
            }
            CliRequest::Disconnect { from, to } => {
                let (f, t) = (from.to_string(), to.to_string());
                let Some(pos) = self.connections.iter().position(|c| c.from == f && c.to == t) else {
                    return Err(RouterError::NotConnected { from: f, to: t });
                };
                self.connections.remove(pos);
                self.persist();
                if self.agents.contains_key(to.agent.as_str()) {
                    let cmd = AgentCommand::Disconnect {
                        input: to.port.clone(),
                        from_agent: from.agent.to_string(),
                        from_port: from.port.clone(),
                    };
                    if let Err(e) = self.command(to.agent.as_str(), &cmd, AGENT_TIMEOUT) {
                        tracing::warn!("{e}");
                    }
                }
                tracing::info!("disconnected {f} -> {t}");
                Ok(RouterReply::Ok)
            }
            CliRequest::Rate { name, period_ns } => {
                self.command(&name, &AgentCommand::SetPeriod { period_ns }, AGENT_TIMEOUT)?;
                if let Some(e) = self.agents.get_mut(&name) {
                    e.reg.period_ns = Some(period_ns);
                }
                self.remembered.set_period(&name, period_ns, Instant::now());
                Ok(RouterReply::Ok)
            }
            CliRequest::Suspend { name } => {
                self.command(&name, &AgentCommand::Suspend, AGENT_TIMEOUT)?;
                if let Some(e) = self.agents.get_mut(&name) {
                    e.state = AgentState::Suspended;
                }
                self.remembered.set_suspended(&name, true, Instant::now());
                Ok(RouterReply::Ok)
            }
            CliRequest::Resume { name } => {
                self.command(&name, &AgentCommand::Resume, AGENT_TIMEOUT)?;
                if let Some(e) = self.agents.get_mut(&name) {
                    e.state = AgentState::Running;
                }
                self.remembered.set_suspended(&name, false, Instant::now());
                Ok(RouterReply::Ok)
            }
            CliRequest::ParamGet { name, key } => {
                match self.command(&name, &AgentCommand::ParamGet { key }, AGENT_TIMEOUT)? {
                    AgentReply::Param(v) => Ok(RouterReply::Param(v)),
                    other => Err(RouterError::Internal(format!("unexpected reply {other:?}"))),
                }
            }
            CliRequest::ParamSet { name, key, value } => {
                let cmd = AgentCommand::ParamSet { key: key.clone(), value: value.clone() };
                self.command(&name, &cmd, AGENT_TIMEOUT)?;
                if !self.remembered.set_param(&name, &key, &value, Instant::now()) {
                    tracing::warn!(
                        "{name}: {key} = {value} is set but not remembered for a restart: {} other parameters of it are",
                        remembered::MAX_PARAMS
                    );
                }
                Ok(RouterReply::Ok)
            }
            CliRequest::Stop { name } => {
                if let Some(sup) = self.supervised.get_mut(&name) {
                    sup.stopped_by_user = true;
                    sup.next_start = None;
                }
                self.command(&name, &AgentCommand::Stop, AGENT_TIMEOUT)?;
                Ok(RouterReply::Ok)
            }
            CliRequest::Supervise(spec) => {
                check_supervision(&spec)?;
                tracing::info!(
                    "supervising {}: restart {:?}, at most {} restarts in {:?}",
                    spec.name,
                    spec.policy,
                    spec.max_restarts,
                    Duration::from_nanos(spec.window_ns)
                );
                let name = spec.name.clone();
                let now = Instant::now();
                let full = self.supervised.len() >= MAX_SUPERVISED;
                match self.supervised.get_mut(&name) {
                    Some(s) => {
                        s.spec = spec;
                        s.failed = false;
                        s.last_seen = now;
                    }
                    None if full => {
                        let agents = &self.agents;
                        let gone = forget_gone_supervision(&mut self.supervised, now, Duration::ZERO, |n| {
                            agents.contains_key(n) || n == name
                        });
                        if !gone.is_empty() {
                            tracing::info!("stopped supervising {} agent(s) no longer running", gone.len());
                        }
                        if self.supervised.len() >= MAX_SUPERVISED {
                            return Err(RouterError::NotApplicable(format!(
                                "the router supervises {MAX_SUPERVISED} agents at most and all are running or restarting; stop some with `nerve stop NAME`, or restart the router with `nerve down`"
                            )));
                        }
                        self.supervised.insert(name, Supervised::new(spec, now));
                    }
                    None => {
                        self.supervised.insert(name, Supervised::new(spec, now));
                    }
                }
                Ok(RouterReply::Ok)
            }
            CliRequest::Kill { name } => {
                let pid =
                    self.agents.get(&name).map(|e| e.reg.pid).ok_or_else(|| unknown_agent(&name, &self.agents))?;
                nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), nix::sys::signal::Signal::SIGKILL)
                    .map_err(|e| RouterError::Internal(format!("cannot kill pid {pid}: {e}")))?;
                tracing::info!("killed agent {name} (pid {pid}) on request");
                let t0 = Instant::now();
                while pid_alive(pid) && t0.elapsed() < Duration::from_millis(500) {
                    std::thread::sleep(Duration::from_millis(2));
                }
                self.check_liveness();
                Ok(RouterReply::Ok)
            }
            CliRequest::Shutdown => {
                self.shutdown = true;
                Ok(RouterReply::Ok)
            }
        }
    }

    /// A supervised agent exited (`failure`: died without leaving cleanly).
    fn exited(&mut self, name: &str, failure: bool) {
        let Some(sup) = self.supervised.get_mut(name) else { return };
        let wanted = match sup.spec.policy {
            RestartPolicy::Never => false,
            RestartPolicy::OnFailure => failure,
            RestartPolicy::Always => true,
        };
        if !wanted || sup.stopped_by_user || sup.failed || self.shutdown {
            return;
        }
        let now = Instant::now();
        let window = Duration::from_nanos(sup.spec.window_ns);
        while sup.recent.front().is_some_and(|t| now.duration_since(*t) > window) {
            sup.recent.pop_front();
        }
        if sup.recent.len() as u32 >= sup.spec.max_restarts {
            sup.failed = true;
            tracing::error!(
                "agent {name} failed: {} restarts within {window:?}; not restarting it (see its log, fix it, then `nerve start` it or launch again)",
                sup.recent.len()
            );
            return;
        }
        let exp = sup.recent.len().min(16) as u32;
        let delay = Duration::from_nanos(sup.spec.backoff_ns).saturating_mul(1 << exp).min(MAX_BACKOFF);
        sup.next_start = Some(now + delay);
        tracing::warn!(
            "restarting {name} in {delay:?} (restart {} of at most {} within {window:?})",
            sup.recent.len() + 1,
            sup.spec.max_restarts
        );
    }

    /// Starts the supervised agents whose back-off has passed; reaps start-up processes.
    fn run_restarts(&mut self) {
        self.children.retain_mut(|c| !matches!(c.try_wait(), Ok(Some(_))));
        let now = Instant::now();
        let due: Vec<String> = self
            .supervised
            .iter()
            .filter(|(n, s)| s.next_start.is_some_and(|t| t <= now) && !self.agents.contains_key(*n))
            .map(|(n, _)| n.clone())
            .collect();
        for name in due {
            let log = self.world.log_file(&name);
            let Some(sup) = self.supervised.get_mut(&name) else { continue };
            sup.next_start = None;
            sup.recent.push_back(now);
            sup.total += 1;
            // rotated by size, 0600, never through a symlink (see agent_sdk::daemon)
            let stderr = agent_sdk::daemon::open_log(&log);
            let mut cmd = std::process::Command::new(&sup.spec.argv[0]);
            cmd.args(&sup.spec.argv[1..]).stdin(std::process::Stdio::null()).stdout(std::process::Stdio::null());
            // whatever policy the router runs under (SCHED_RESET_ON_FORK covers
            // a real-time one; SCHED_BATCH or IDLE would pass on), the agent
            // starts under the normal one and asks for its own (R13)
            // SAFETY: the closure runs in the child between fork and exec and
            // only makes one system call, which is async-signal-safe.
            unsafe {
                std::os::unix::process::CommandExt::pre_exec(&mut cmd, || {
                    let normal = libc::sched_param { sched_priority: 0 };
                    libc::sched_setscheduler(0, libc::SCHED_OTHER, &normal);
                    Ok(())
                });
            }
            match stderr {
                Ok(f) => {
                    cmd.stderr(f);
                }
                Err(e) => tracing::warn!("{e}; {name}'s start-up errors go to the router's log"),
            }
            match cmd.spawn() {
                Ok(child) => {
                    tracing::info!("restarted {name} (restart {})", sup.total);
                    self.children.push(child);
                }
                Err(e) => tracing::error!("cannot restart {name}: {e} ({})", sup.spec.argv[0]),
            }
        }
    }

    fn stats_of(&mut self, name: &str) -> (Option<AgentStats>, bool) {
        match self.command(name, &AgentCommand::Stats, STATS_TIMEOUT) {
            Ok(AgentReply::Stats(s)) => (Some(s), true),
            _ => (None, false),
        }
    }

    fn views(&mut self) -> Vec<AgentView> {
        let names: Vec<String> = self.agents.keys().cloned().collect();
        let mut out = Vec::with_capacity(names.len());
        for name in names {
            let (stats, answered) = self.stats_of(&name);
            let Some(e) = self.agents.get(&name) else { continue };
            out.push(AgentView {
                name: name.clone(),
                pid: e.reg.pid,
                kind: e.reg.kind.clone(),
                state: if answered { e.state } else { AgentState::Unresponsive },
                task: e.reg.task,
                period_ns: if e.reg.task == TaskKind::Periodic { e.reg.period_ns } else { None },
                inputs: e.reg.inputs.clone(),
                outputs: e.reg.outputs.clone(),
                log_file: e.reg.log_file.clone(),
                stats,
                restarts: self.supervised.get(&name).map(|s| s.total).unwrap_or(0),
                importance: self.supervised.get(&name).map(|s| s.spec.importance),
            });
        }
        // supervised agents that are not running: restarting or failed
        for (name, sup) in &self.supervised {
            if self.agents.contains_key(name) || !(sup.failed || sup.next_start.is_some()) {
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
            });
        }
        out.sort_by(|a, b| a.name.cmp(&b.name));
        out
    }

    fn connection_views(&self, agents: &[AgentView]) -> Vec<ConnectionView> {
        self.connections
            .iter()
            .map(|c| {
                let (fa, fp) = split_port(&c.from);
                let (ta, tp) = split_port(&c.to);
                let input =
                    agents.iter().find(|a| a.name == ta).and_then(|a| a.stats.as_ref()).and_then(|s| {
                        s.inputs.iter().find(|i| i.input == tp && i.from_agent == fa && i.from_port == fp)
                    });
                let from_live = agents.iter().any(|a| a.name == fa);
                ConnectionView {
                    from: c.from.clone(),
                    to: c.to.clone(),
                    type_name: c.type_name.clone(),
                    active: from_live && input.is_some(),
                    rate_hz: input.map(|i| i.rate_hz).unwrap_or(0.0),
                    last_age_ms: input.and_then(|i| i.last_age_ns).map(|ns| ns as f64 / 1e6),
                    received: input.map(|i| i.received).unwrap_or(0),
                    dropped: input.map(|i| i.dropped).unwrap_or(0),
                }
            })
            .collect()
    }
}

fn split_port(p: &str) -> (&str, &str) {
    p.split_once('/').unwrap_or((p, ""))
}

fn port_agent(p: &str) -> &str {
    split_port(p).0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(name: &str) -> Supervision {
        Supervision {
            name: name.into(),
            argv: vec!["nerve-ticker".into()],
            policy: RestartPolicy::OnFailure,
            max_restarts: 3,
            window_ns: 1_000_000_000,
            backoff_ns: 1_000_000,
            importance: 5,
        }
    }

    #[test]
    fn a_supervision_name_that_is_not_an_agent_name_is_refused() {
        assert!(check_supervision(&spec("t1")).is_ok());
        for bad in ["../../x", "a/b", "", ".hidden"] {
            match check_supervision(&spec(bad)) {
                Err(RouterError::InvalidName(m)) => assert!(m.contains(&format!("{bad:?}")), "{m}"),
                other => panic!("{bad:?} accepted: {other:?}"),
            }
        }
        let mut no_argv = spec("t1");
        no_argv.argv.clear();
        assert!(matches!(check_supervision(&no_argv), Err(RouterError::NotApplicable(_))));
    }

    #[test]
    fn supervision_of_names_gone_for_long_is_dropped_unless_live_or_restarting() {
        let t0 = Instant::now();
        let mut sup = BTreeMap::new();
        for n in ["gone", "live", "restarting"] {
            sup.insert(n.to_owned(), Supervised::new(spec(n), t0));
        }
        if let Some(s) = sup.get_mut("restarting") {
            s.next_start = Some(t0);
        }
        // not yet gone long enough
        assert!(
            forget_gone_supervision(&mut sup, t0 + Duration::from_secs(60), FORGET_AFTER, |n| n == "live").is_empty()
        );
        let later = t0 + FORGET_AFTER + Duration::from_secs(1);
        assert_eq!(forget_gone_supervision(&mut sup, later, FORGET_AFTER, |n| n == "live"), vec!["gone".to_owned()]);
        assert_eq!(sup.keys().cloned().collect::<Vec<_>>(), vec!["live".to_owned(), "restarting".to_owned()]);
    }

    #[test]
    fn a_real_time_router_starts_its_children_under_the_normal_policy() {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let param = libc::sched_param { sched_priority: 1 };
            // SAFETY: the calling thread's own policy, a valid sched_param.
            if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
                let _ = tx.send(None);
                return;
            }
            reset_realtime_on_fork();
            let child = std::process::Command::new("sleep").arg("5").spawn();
            // SAFETY: as above; back to normal before the thread ends
            let normal = libc::sched_param { sched_priority: 0 };
            unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &normal) };
            let _ = tx.send(Some(child));
        });
        let Some(child) = rx.recv().expect("the spawning thread answers") else {
            eprintln!(
                "SCHED_FIFO is not permitted here: nothing to reset (tests/tests/restart_state.rs checks the router)"
            );
            return;
        };
        let mut child = child.expect("spawn sleep");
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", child.id())).expect("child stat");
        let _ = child.kill();
        let _ = child.wait();
        let policy = stat.rsplit_once(')').and_then(|(_, r)| r.split_whitespace().nth(38)).unwrap_or("?").to_owned();
        assert_eq!(policy, libc::SCHED_OTHER.to_string(), "the child's policy (field 41 of {stat})");
    }
}
