//! The runtime behind [`crate::run`]: builds the agent, registers it with the
//! router, runs the task thread and, in the main thread, the message checker.
//!
//! Threads:
//! * **message checker** (main thread, SCHED_FIFO one above the task): waits
//!   on the control service and a 100 ms housekeeping tick; applies commands
//!   to shared state and answers at once; notices a (re)started router and
//!   re-registers; stops on SIGTERM/SIGINT or a `Stop` command.
//! * **task**: periodic (absolute deadlines, run-time period, lateness and
//!   overruns measured) or event-driven (blocked on a WaitSet of its inputs'
//!   listeners plus a private wake-up event; never re-entered).

use crate::agent::{Agent, AgentError, Context, Setup, Task};
use crate::cli::CommonArgs;
use crate::clock::{now_ns, parse_duration, sleep_until_ns};
use crate::control::{ControlClient, ControlError, ControlServer, ControlSize, agent_router_client};
use crate::daemon::{Readiness, daemonize, init_logging, sd_notify, watchdog_interval};
use crate::meters::{CpuMeter, LatenessRecorder, RateMeter, rss_bytes};
use crate::params::ParamTable;
use crate::ports::DynInput;
use crate::rt;
use crate::world::{Ipc, World};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use shm_schemas::control::agent_to_router::{AgentToRouter, PortSpec, Registration, TaskKind};
use shm_schemas::control::cli_to_router::{RouterError, RouterReply, RouterRequest};
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use shm_schemas::payloads::RouterEpoch;
use shm_schemas::stats::AgentStats;
use shm_schemas::{AgentName, ProtocolError};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

/// Exit code when the agent could not start (bad arguments, duplicate name, device).
pub const EXIT_STARTUP: u8 = 1;

/// Figures the task thread keeps about itself.
#[derive(Debug, Default)]
struct TaskFigures {
    cycles: u64,
    overruns: u64,
    rate: RateMeter,
    lateness: LatenessRecorder,
    errors: u64,
    last_cycle_ns: u64,
    /// when the running step started; 0 between steps
    in_step_since_ns: u64,
}

/// State shared by the message checker and the task.
struct Shared {
    period_ns: AtomicU64,
    suspended: AtomicBool,
    stop: AtomicBool,
    generation: AtomicU64,
    realtime: AtomicBool,
    figures: Mutex<TaskFigures>,
    gate: (Mutex<()>, Condvar),
    wake: Notifier<Ipc>,
}

impl Shared {
    fn poke(&self) {
        self.gate.1.notify_all();
        let _ = self.wake.notify();
    }

    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    fn figures(&self) -> std::sync::MutexGuard<'_, TaskFigures> {
        self.figures.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Runs agent `A` with the common command line; the body of an agent's `main`.
pub fn run<A: Agent>() -> ExitCode {
    let args = <CommonArgs as clap::Parser>::parse();
    run_with_args::<A>(args)
}

/// Runs agent `A` with already parsed arguments.
pub fn run_with_args<A: Agent>(args: CommonArgs) -> ExitCode {
    let name = args.name.clone().unwrap_or_else(|| A::KIND.to_owned());
    let mut readiness = Readiness::foreground();
    let world = match World::new(&args.robot) {
        Ok(w) => w,
        Err(e) => return startup_error(&mut readiness, &e.to_string()),
    };
    if let Err(e) = AgentName::new(&name) {
        return startup_error(&mut readiness, &format!("invalid --name: {e}"));
    }
    if args.describe {
        return match describe::<A>(&args) {
            Ok(json) => {
                println!("{json}");
                ExitCode::SUCCESS
            }
            Err(e) => startup_error(&mut readiness, &e),
        };
    }
    if args.daemon {
        if let Err(e) = world.ensure_state_dirs() {
            return startup_error(&mut readiness, &e.to_string());
        }
        match daemonize(&world.log_file(&name), &world.pid_file(&name)) {
            Ok(r) => readiness = r,
            Err(e) => return startup_error(&mut readiness, &format!("cannot daemonize: {e}")),
        }
    }
    init_logging(&name, args.log_level.as_deref());
    match start::<A>(&args, &name, world, &mut readiness) {
        Ok(()) => ExitCode::SUCCESS,
        Err(msg) => startup_error(&mut readiness, &msg),
    }
}

fn startup_error(readiness: &mut Readiness, msg: &str) -> ExitCode {
    tracing::error!("{msg}");
    if readiness.pid_file().is_none() {
        eprintln!("error: {msg}");
    }
    readiness.fail(msg);
    ExitCode::from(EXIT_STARTUP)
}

/// The agent's description, made by running [`Agent::new`] in a private,
/// throw-away world (so authors must open devices in [`Agent::start`], not in `new`).
fn describe<A: Agent>(args: &CommonArgs) -> Result<String, String> {
    let world = World::new(&format!("describe-{}", std::process::id())).map_err(|e| e.to_string())?;
    let result = describe_in::<A>(args, &world);
    // iceoryx2 keeps a management file per prefix; this world is private and
    // gone, whether the agent could be described or not
    for f in world.shm_files() {
        let _ = std::fs::remove_file(f);
    }
    result
}

fn describe_in<A: Agent>(args: &CommonArgs, world: &World) -> Result<String, String> {
    use shm_schemas::control::describe::Description;
    let node = Arc::new(world.node("describe").map_err(|e| e.to_string())?);
    let mut setup = Setup {
        world: world.clone(),
        name: AgentName::new(A::KIND).map_err(|e| e.to_string())?,
        node,
        args: args.args.clone(),
        inputs: Vec::new(),
        outputs: Vec::new(),
        params: ParamTable::default(),
    };
    let agent = A::new(&mut setup).map_err(|e| format!("{} could not be set up: {e}", A::KIND))?;
    apply_params(&setup.params, &args.params)?;
    let (task, default_period_ns) = match A::task() {
        Task::Periodic(p) => (TaskKind::Periodic, Some(crate::clock::nanos(p))),
        Task::EventDriven => (TaskKind::EventDriven, None),
    };
    let d = Description {
        protocol: shm_schemas::PROTOCOL_VERSION,
        kind: A::KIND.into(),
        task,
        default_period_ns,
        inputs: setup
            .inputs
            .iter()
            .map(|i| PortSpec { name: i.name().into(), type_name: i.type_name().into() })
            .collect(),
        outputs: setup.outputs.clone(),
        params: setup.params.snapshot(),
    };
    drop(agent);
    drop(setup);
    serde_json::to_string(&d).map_err(|e| e.to_string())
}

/// Applies `--param KEY=VALUE` settings.
fn apply_params(table: &ParamTable, settings: &[String]) -> Result<(), String> {
    for s in settings {
        let (k, v) = s.split_once('=').ok_or_else(|| format!("--param {s:?}: write KEY=VALUE"))?;
        table.set(k.trim(), v).map_err(|e| format!("--param {s}: {e}"))?;
    }
    Ok(())
}

fn start<A: Agent>(args: &CommonArgs, name: &str, world: World, readiness: &mut Readiness) -> Result<(), String> {
    let agent_name = AgentName::new(name).map_err(|e| e.to_string())?;
    let task_kind = A::task();
    let period = match (task_kind, &args.period) {
        (Task::Periodic(default), None) => Some(default),
        (Task::Periodic(_), Some(p)) => Some(parse_duration(p).map_err(|e| format!("--period: {e}"))?),
        (Task::EventDriven, Some(_)) => {
            return Err(format!("agent kind {} is event-driven; it takes no --period", A::KIND));
        }
        (Task::EventDriven, None) => None,
    };

    if !args.no_realtime {
        match rt::lock_memory() {
            Ok(()) => tracing::debug!("memory locked (mlockall, on fault)"),
            Err(e) => tracing::info!("memory not locked: mlockall refused ({e}); page faults may add latency"),
        }
    }

    let t_start = Instant::now();
    let stage = |what: &str| tracing::debug!("start-up: {what} at {} us", t_start.elapsed().as_micros());
    let node = Arc::new(world.node(name).map_err(|e| e.to_string())?);
    stage("node created");
    let ctl_service = world.robot().ctl_service(&agent_name);
    let server: ControlServer<AgentCommand, AgentReply> = ControlServer::create(&node, &ctl_service, ControlSize::AGENT)
        .map_err(|e| match e {
            ControlError::AlreadyServed { .. } => format!(
                "an agent named {name:?} is already running on robot {}; choose another --name, or stop it first with `nerve stop {name}`",
                world.robot()
            ),
            e => e.to_string(),
        })?;

    stage("control service created");
    let wake_service = format!("nerve/{}/{}/_wake", world.robot(), name);
    let wake_factory = node
        .service_builder(&wake_service.as_str().try_into().map_err(|e| format!("{e:?}"))?)
        .event()
        .max_listeners(2)
        .max_notifiers(2)
        .open_or_create()
        .map_err(|e| format!("cannot create {wake_service}: {e:?}"))?;
    let wake_listener = wake_factory.listener_builder().create().map_err(|e| format!("{e:?}"))?;
    let wake = wake_factory.notifier_builder().create().map_err(|e| format!("{e:?}"))?;

    let mut setup = Setup {
        world: world.clone(),
        name: agent_name.clone(),
        node: node.clone(),
        args: args.args.clone(),
        inputs: Vec::new(),
        outputs: Vec::new(),
        params: ParamTable::default(),
    };
    stage("wake-up event created");
    let agent = A::new(&mut setup).map_err(|e| format!("{} {name:?} could not start: {e}", A::KIND))?;
    stage("agent and its ports created");
    let Setup { inputs, outputs, params, .. } = setup;
    apply_params(&params, &args.params)?;

    let shared = Arc::new(Shared {
        period_ns: AtomicU64::new(period.map(crate::clock::nanos).unwrap_or(0)),
        suspended: AtomicBool::new(args.suspended),
        stop: AtomicBool::new(false),
        generation: AtomicU64::new(0),
        realtime: AtomicBool::new(false),
        figures: Mutex::new(TaskFigures { last_cycle_ns: now_ns(), ..TaskFigures::default() }),
        gate: (Mutex::new(()), Condvar::new()),
        wake,
    });

    let registration = Registration {
        name: name.to_owned(),
        pid: std::process::id(),
        kind: A::KIND.to_owned(),
        executable: std::env::current_exe().map(|p| p.display().to_string()).unwrap_or_default(),
        task: match task_kind {
            Task::Periodic(_) => TaskKind::Periodic,
            Task::EventDriven => TaskKind::EventDriven,
        },
        period_ns: period.map(crate::clock::nanos),
        inputs: inputs.iter().map(|i| PortSpec { name: i.name().into(), type_name: i.type_name().into() }).collect(),
        outputs,
        log_file: readiness.pid_file().map(|_| world.log_file(name).display().to_string()),
        suspended: args.suspended,
    };
    let mut link = RouterLink::new();
    let registered = link.register(&node, &world, &registration, &shared);
    stage("registration answered");
    link.watch_epoch(&world, &node);
    stage("router epoch subscribed");
    match registered {
        Ok(()) => {}
        Err(RegisterError::Refused(e)) => return Err(e.to_string()),
        Err(RegisterError::NoRouter) => tracing::warn!(
            "no router runs for robot {}; running unregistered, and registering as soon as one starts (`nerve router --robot {}`)",
            world.robot(),
            world.robot()
        ),
        Err(RegisterError::Other(e)) => tracing::warn!("could not register with the router: {e}; will retry"),
    }

    // the task thread
    let task_shared = shared.clone();
    let task_inputs = inputs.clone();
    let name_owned = name.to_owned();
    let want_rt = !args.no_realtime;
    let prio = args.priority;
    let (started_tx, started_rx) = std::sync::mpsc::channel::<Result<(), String>>();
    let handle = std::thread::Builder::new()
        .name("task".into())
        .spawn(move || {
            rt::block_termination_signals();
            rt::tight_timer_slack();
            if want_rt {
                match rt::set_thread_fifo(prio) {
                    Ok(()) => task_shared.realtime.store(true, Ordering::Relaxed),
                    Err(e) => tracing::info!(
                        "real-time scheduling not permitted ({e}); the task runs with normal priority (grant CAP_SYS_NICE or LimitRTPRIO, or pass --no-realtime to silence this)"
                    ),
                }
            }
            task_main(agent, &name_owned, &task_shared, &task_inputs, wake_listener, task_kind, started_tx)
        })
        .map_err(|e| format!("cannot start the task thread: {e}"))?;
    if want_rt {
        let _ = rt::set_thread_fifo((prio + 1).min(99));
    }
    // ready only once the agent's own `start` worked (devices opened, a
    // network session up): a failed start is a failed `nerve start`, and an
    // exit without leaving the router, so supervision counts it as a failure
    match started_rx.recv_timeout(START_TIMEOUT) {
        Ok(Ok(())) => stage("agent started"),
        Ok(Err(e)) => {
            let _ = handle.join();
            return Err(format!("{} {name:?} could not start: {e}", A::KIND));
        }
        Err(_) if handle.is_finished() => return Err(format!("{} {name:?} stopped while starting", A::KIND)),
        Err(_) => tracing::warn!(
            "the agent's start has not finished after {} s; reporting ready anyway",
            START_TIMEOUT.as_secs()
        ),
    }

    let startup_msg = format!("{name} started (pid {}, robot {})", std::process::id(), world.robot());
    tracing::info!(
        "started: kind {}, {}{}",
        A::KIND,
        match period {
            Some(p) => format!("periodic every {}", crate::clock::format_duration(p)),
            None => "event-driven".into(),
        },
        if link.registered.is_some() { ", registered with the router" } else { "" }
    );
    readiness.ready(&startup_msg);
    let _ = sd_notify("READY=1");

    let checker = Checker { world: &world, node: &node, shared: &shared, inputs: &inputs, params: &params, task_kind };
    checker.run(&server, &mut link, &registration);

    // stop: wake the task, wait for it a bounded time, leave the router
    shared.stop.store(true, Ordering::Release);
    shared.poke();
    let deadline = Instant::now() + Duration::from_secs(5);
    while !handle.is_finished() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(5));
    }
    if handle.is_finished() {
        let _ = handle.join();
    } else {
        tracing::warn!("the task did not finish within 5 s of the stop request; exiting anyway");
    }
    link.unregister(name);
    let _ = sd_notify("STOPPING=1");
    tracing::info!("stopped");
    Ok(())
}

/// How long the start-up waits for the agent's own `start` before it
/// reports ready anyway.
const START_TIMEOUT: Duration = Duration::from_secs(60);

fn task_main<A: Agent>(
    mut agent: A,
    name: &str,
    sh: &Shared,
    inputs: &[Arc<dyn DynInput>],
    wake: Listener<Ipc>,
    kind: Task,
    started: std::sync::mpsc::Sender<Result<(), String>>,
) {
    let mut ctx = Context { name: name.to_owned(), cycle: 0, now_ns: now_ns(), period: None, stop: false };
    if let Err(e) = agent.start(&mut ctx) {
        tracing::error!("start failed: {e}; stopping");
        sh.stop.store(true, Ordering::Release);
        let _ = started.send(Err(e.to_string()));
        return;
    }
    let _ = started.send(Ok(()));
    match kind {
        Task::Periodic(_) => periodic_loop(&mut agent, sh, &mut ctx),
        Task::EventDriven => event_loop(&mut agent, sh, inputs, &wake, &mut ctx),
    }
    agent.stop(&mut ctx);
}

fn run_step<A: Agent>(agent: &mut A, sh: &Shared, ctx: &mut Context) {
    sh.figures().in_step_since_ns = ctx.now_ns.max(1);
    let result = agent.step(ctx);
    sh.figures().in_step_since_ns = 0;
    if let Err(e) = result {
        let mut f = sh.figures();
        f.errors += 1;
        if f.errors.is_power_of_two() {
            tracing::warn!("step failed ({} failures so far): {e}", f.errors);
        }
    }
    ctx.cycle += 1;
    if ctx.stop {
        sh.stop.store(true, Ordering::Release);
    }
}

fn wait_while_suspended(sh: &Shared) {
    let mut g = sh.gate.0.lock().unwrap_or_else(|p| p.into_inner());
    while sh.suspended.load(Ordering::Acquire) && !sh.stopping() {
        g = match sh.gate.1.wait_timeout(g, Duration::from_millis(100)) {
            Ok((g, _)) => g,
            Err(p) => p.into_inner().0,
        };
    }
}

/// Longest single sleep, so that stop and suspend are seen promptly even with long periods.
const SLEEP_CHUNK_NS: u64 = 50_000_000;

fn periodic_loop<A: Agent>(agent: &mut A, sh: &Shared, ctx: &mut Context) {
    let mut period = sh.period_ns.load(Ordering::Acquire).max(1);
    let mut last = now_ns();
    let mut next = last.saturating_add(period);
    loop {
        // sleep to the absolute deadline, in chunks, watching stop, suspend
        // and a new period (which counts from the last cycle, at once: a
        // long period in force does not delay a shorter one)
        loop {
            if sh.stopping() {
                return;
            }
            if sh.suspended.load(Ordering::Acquire) {
                break;
            }
            let new_period = sh.period_ns.load(Ordering::Acquire).max(1);
            if new_period != period {
                period = new_period;
                next = last.saturating_add(period);
                sh.figures().lateness.reset();
            }
            let now = now_ns();
            if now >= next {
                break;
            }
            sleep_until_ns(next.min(now.saturating_add(SLEEP_CHUNK_NS)));
        }
        if sh.suspended.load(Ordering::Acquire) {
            wait_while_suspended(sh);
            if sh.stopping() {
                return;
            }
            period = sh.period_ns.load(Ordering::Acquire).max(1);
            last = now_ns();
            next = last.saturating_add(period);
            continue;
        }
        let woke = now_ns();
        last = woke;
        ctx.now_ns = woke;
        ctx.period = Some(Duration::from_nanos(period));
        run_step(agent, sh, ctx);
        let done = now_ns();
        {
            let mut f = sh.figures();
            f.cycles += 1;
            f.rate.record(woke);
            f.lateness.record(woke.saturating_sub(next));
            f.last_cycle_ns = woke;
        }
        let new_period = sh.period_ns.load(Ordering::Acquire).max(1);
        if new_period != period {
            period = new_period;
            next = woke.saturating_add(period);
            sh.figures().lateness.reset();
            continue;
        }
        next = next.saturating_add(period);
        if done > next {
            // the work ran past the next deadline: count it and skip the missed deadlines
            sh.figures().overruns += 1;
            let missed = (done - next) / period + 1;
            next = next.saturating_add(missed.saturating_mul(period));
        }
    }
}

fn drain_listener(l: &Listener<Ipc>) {
    let _ = l.try_wait(|_| {});
}

fn event_loop<A: Agent>(
    agent: &mut A,
    sh: &Shared,
    inputs: &[Arc<dyn DynInput>],
    wake: &Listener<Ipc>,
    ctx: &mut Context,
) {
    loop {
        if sh.stopping() {
            return;
        }
        let generation = sh.generation.load(Ordering::Acquire);
        let listeners: Vec<Arc<Listener<Ipc>>> = inputs.iter().flat_map(|i| i.listeners()).collect();
        let ws = match WaitSetBuilder::new().signal_handling_mode(SignalHandlingMode::Disabled).create::<Ipc>() {
            Ok(ws) => ws,
            Err(e) => {
                tracing::error!("cannot create the task's WaitSet: {e:?}; stopping");
                sh.stop.store(true, Ordering::Release);
                return;
            }
        };
        let Ok(wake_guard) = ws.attach_notification(wake) else {
            tracing::error!("cannot attach the wake-up event; stopping");
            sh.stop.store(true, Ordering::Release);
            return;
        };
        let guards: Vec<_> = listeners.iter().filter_map(|l| ws.attach_notification(l.as_ref()).ok()).collect();
        let mut was_suspended = sh.suspended.load(Ordering::Acquire);
        loop {
            let mut got_input = false;
            let result = ws.wait_and_process_once(|id| {
                if id.has_event_from(&wake_guard) {
                    drain_listener(wake);
                }
                for (g, l) in guards.iter().zip(&listeners) {
                    if id.has_event_from(g) {
                        drain_listener(l);
                        got_input = true;
                    }
                }
                CallbackProgression::Continue
            });
            if let Err(e) = result {
                tracing::warn!("task wait failed: {e:?}");
                std::thread::sleep(Duration::from_millis(10));
            }
            if sh.stopping() {
                return;
            }
            let suspended = sh.suspended.load(Ordering::Acquire);
            let resumed = was_suspended && !suspended;
            was_suspended = suspended;
            if !suspended && (got_input || resumed) {
                let t = now_ns();
                ctx.now_ns = t;
                run_step(agent, sh, ctx);
                let mut f = sh.figures();
                f.cycles += 1;
                f.rate.record(t);
                f.last_cycle_ns = t;
            }
            if sh.generation.load(Ordering::Acquire) != generation {
                tracing::debug!("inputs changed: rebuilding the task's WaitSet");
                break; // inputs changed: rebuild the WaitSet
            }
        }
    }
}

enum RegisterError {
    NoRouter,
    Refused(RouterError),
    Other(String),
}

/// The agent's side of the router: registration, and noticing a restarted router.
struct RouterLink {
    client: Option<ControlClient<RouterRequest, RouterReply>>,
    epoch: Option<Subscriber<Ipc, RouterEpoch, ()>>,
    registered: Option<u64>,
}

/// Opens the router's epoch service (publish-subscribe, history 1).
pub fn epoch_service(
    node: &Node<Ipc>,
    world: &World,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, RouterEpoch, ()>, String> {
    let name = world.robot().router_epoch_service();
    node.service_builder(&name.as_str().try_into().map_err(|e| format!("{e:?}"))?)
        .publish_subscribe::<RouterEpoch>()
        .max_publishers(2)
        .max_subscribers(ControlSize::ROUTER.max_clients)
        .max_nodes(ControlSize::ROUTER.max_nodes)
        .history_size(1)
        .subscriber_max_buffer_size(1)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| format!("cannot open {name}: {e:?}"))
}

impl RouterLink {
    fn new() -> Self {
        RouterLink { client: None, epoch: None, registered: None }
    }

    /// Subscribes to the router's epoch. Done after the first registration,
    /// which is on the path of a hot-add: the subscription keeps the latest
    /// epoch (history 1), so a router that restarted in between is still
    /// noticed by the next [`RouterLink::poll`].
    fn watch_epoch(&mut self, world: &World, node: &Node<Ipc>) {
        self.epoch = match epoch_service(node, world) {
            Ok(f) => f.subscriber_builder().buffer_size(1).history_request(1).create().ok(),
            Err(e) => {
                tracing::warn!("{e}; a restarted router will not be noticed");
                None
            }
        };
    }

    fn register(
        &mut self,
        node: &Node<Ipc>,
        world: &World,
        reg: &Registration,
        sh: &Shared,
    ) -> Result<(), RegisterError> {
        if self.client.is_none() {
            match agent_router_client(world, node) {
                Ok(c) => self.client = Some(c),
                Err(ControlError::NoServer { .. }) => return Err(RegisterError::NoRouter),
                Err(e) => return Err(RegisterError::Other(e.to_string())),
            }
        }
        let Some(client) = &self.client else { return Err(RegisterError::NoRouter) };
        let mut reg = reg.clone();
        reg.suspended = sh.suspended.load(Ordering::Acquire);
        let p = sh.period_ns.load(Ordering::Acquire);
        reg.period_ns = (p > 0).then_some(p);
        match client.call(&RouterRequest::Agent(AgentToRouter::Register(reg)), Duration::from_secs(3)) {
            Ok(RouterReply::Registered { epoch }) => {
                self.registered = Some(epoch);
                Ok(())
            }
            Ok(RouterReply::Error(e)) => Err(RegisterError::Refused(e)),
            Ok(other) => Err(RegisterError::Other(format!("unexpected reply {other:?}"))),
            Err(ControlError::NoServer { .. }) => Err(RegisterError::NoRouter),
            Err(ControlError::Protocol(e @ ProtocolError::VersionMismatch { .. })) => {
                Err(RegisterError::Other(e.to_string()))
            }
            Err(e) => Err(RegisterError::Other(e.to_string())),
        }
    }

    /// Re-registers when a router with a new epoch has started. Returns false
    /// when the router refuses this agent for good (its name was taken meanwhile).
    fn poll(&mut self, node: &Node<Ipc>, world: &World, reg: &Registration, sh: &Shared) -> bool {
        let Some(sub) = &self.epoch else { return true };
        let mut newest = None;
        while let Ok(Some(s)) = sub.receive() {
            newest = Some(*s.payload());
        }
        let Some(e) = newest else { return true };
        if Some(e.epoch) == self.registered {
            return true;
        }
        match self.register(node, world, reg, sh) {
            Ok(()) => {
                tracing::info!("registered with the router (pid {})", e.pid);
                true
            }
            Err(RegisterError::Refused(err)) => {
                tracing::error!("the router refused this agent: {err}");
                false
            }
            Err(RegisterError::NoRouter) => true,
            Err(RegisterError::Other(err)) => {
                tracing::warn!("could not register with the router: {err}");
                true
            }
        }
    }

    fn unregister(&mut self, name: &str) {
        if let (Some(client), Some(_)) = (&self.client, self.registered) {
            let msg = RouterRequest::Agent(AgentToRouter::Unregister { name: name.into(), pid: std::process::id() });
            if let Err(e) = client.call(&msg, Duration::from_millis(500)) {
                tracing::debug!("could not unregister: {e}");
            }
        }
    }
}

struct Checker<'a> {
    world: &'a World,
    node: &'a Node<Ipc>,
    shared: &'a Arc<Shared>,
    inputs: &'a [Arc<dyn DynInput>],
    params: &'a ParamTable,
    task_kind: Task,
}

impl Checker<'_> {
    fn run(&self, server: &ControlServer<AgentCommand, AgentReply>, link: &mut RouterLink, reg: &Registration) {
        let ws = match WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Ipc>()
        {
            Ok(ws) => ws,
            Err(e) => {
                tracing::error!("cannot create the message checker's WaitSet: {e:?}");
                return;
            }
        };
        let (Ok(_ctl), Ok(_tick)) =
            (ws.attach_notification(server.listener()), ws.attach_interval(Duration::from_millis(100)))
        else {
            tracing::error!("cannot attach the control service to the WaitSet");
            return;
        };
        let mut cpu = CpuMeter::default();
        let mut last_cpu = 0u64;
        let watchdog = watchdog_interval();
        let mut last_ping = Instant::now();
        loop {
            match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
                Ok(WaitSetRunResult::TerminationRequest) => {
                    tracing::info!("termination requested by signal");
                    return;
                }
                Ok(_) => {}
                Err(e) => {
                    tracing::warn!("message checker wait failed: {e:?}");
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
            let mut stop_now = false;
            if let Err(e) = server.serve(|req| match req {
                Ok(AgentCommand::Stop) => {
                    stop_now = true;
                    AgentReply::Ok
                }
                Ok(cmd) => self.handle(cmd, &cpu),
                Err(e) => AgentReply::Error(e.to_string()),
            }) {
                tracing::warn!("control service failed: {e}");
            }
            if stop_now {
                tracing::info!("stop requested");
                return;
            }
            if self.shared.stopping() {
                return;
            }
            let now = now_ns();
            if now.saturating_sub(last_cpu) >= 1_000_000_000 {
                cpu.sample(now);
                last_cpu = now;
            }
            if !link.poll(self.node, self.world, reg, self.shared) {
                return;
            }
            if let Some(wd) = watchdog {
                // ping at half the interval, and only while the task makes progress
                if last_ping.elapsed() >= wd / 2 && self.task_alive(now, wd) {
                    let _ = sd_notify("WATCHDOG=1");
                    last_ping = Instant::now();
                }
            }
        }
    }

    /// Whether the task thread has made progress recently enough to keep the
    /// watchdog happy: no step runs for longer than the watchdog interval, and
    /// a periodic task has completed a cycle recently.
    fn task_alive(&self, now: u64, wd: Duration) -> bool {
        let wd_ns = wd.as_nanos() as u64;
        let (last, in_step) = {
            let f = self.shared.figures();
            (f.last_cycle_ns, f.in_step_since_ns)
        };
        if in_step != 0 && now.saturating_sub(in_step) > wd_ns {
            return false;
        }
        if self.shared.suspended.load(Ordering::Acquire) || matches!(self.task_kind, Task::EventDriven) {
            return true;
        }
        let period = self.shared.period_ns.load(Ordering::Acquire);
        now.saturating_sub(last) < wd_ns.max(period * 2)
    }

    fn find_input(&self, name: &str) -> Result<&Arc<dyn DynInput>, String> {
        self.inputs.iter().find(|i| i.name() == name).ok_or_else(|| {
            let names: Vec<&str> = self.inputs.iter().map(|i| i.name()).collect();
            format!(
                "no input port {name:?} (inputs: {})",
                if names.is_empty() { "none".into() } else { names.join(", ") }
            )
        })
    }

    fn changed_inputs(&self) {
        self.shared.generation.fetch_add(1, Ordering::AcqRel);
        self.shared.poke();
    }

    fn handle(&self, cmd: AgentCommand, cpu: &CpuMeter) -> AgentReply {
        match cmd {
            AgentCommand::Connect { input, from_agent, from_port, type_name } => {
                let inp = match self.find_input(&input) {
                    Ok(i) => i,
                    Err(e) => return AgentReply::Error(e),
                };
                if inp.type_name() != type_name {
                    return AgentReply::Error(format!(
                        "input {input:?} takes {} but {from_agent}/{from_port} sends {type_name}",
                        inp.type_name()
                    ));
                }
                let t0 = now_ns();
                match inp.connect(self.node, self.world.robot(), &from_agent, &from_port) {
                    Ok(changed) => {
                        tracing::debug!(
                            "subscribed {input} to {from_agent}/{from_port} in {} us",
                            (now_ns() - t0) / 1000
                        );
                        if changed {
                            tracing::info!("input {input} now reads {from_agent}/{from_port}");
                            self.changed_inputs();
                        }
                        AgentReply::Ok
                    }
                    Err(e) => AgentReply::Error(e.to_string()),
                }
            }
            AgentCommand::Disconnect { input, from_agent, from_port } => {
                let inp = match self.find_input(&input) {
                    Ok(i) => i,
                    Err(e) => return AgentReply::Error(e),
                };
                if inp.disconnect(&from_agent, &from_port) {
                    tracing::info!("input {input} no longer reads {from_agent}/{from_port}");
                    self.changed_inputs();
                    AgentReply::Ok
                } else {
                    AgentReply::Error(format!("input {input:?} does not read {from_agent}/{from_port}"))
                }
            }
            AgentCommand::SetPeriod { period_ns } => match self.task_kind {
                Task::EventDriven => AgentReply::Error("this agent is event-driven; it has no period".into()),
                Task::Periodic(_) if period_ns < 10_000 => AgentReply::Error("a period must be at least 10us".into()),
                Task::Periodic(_) if period_ns > crate::clock::nanos(crate::clock::MAX_DURATION) => {
                    AgentReply::Error("a period must be at most 1 day".into())
                }
                Task::Periodic(_) => {
                    self.shared.period_ns.store(period_ns, Ordering::Release);
                    self.shared.poke();
                    tracing::info!("period set to {}", crate::clock::format_duration(Duration::from_nanos(period_ns)));
                    AgentReply::Ok
                }
            },
            AgentCommand::Suspend => {
                self.shared.suspended.store(true, Ordering::Release);
                self.shared.poke();
                tracing::info!("suspended");
                AgentReply::Ok
            }
            AgentCommand::Resume => {
                self.shared.suspended.store(false, Ordering::Release);
                self.shared.poke();
                tracing::info!("resumed");
                AgentReply::Ok
            }
            AgentCommand::ParamGet { key } => match self.params.get(&key) {
                Ok(v) => AgentReply::Param(v),
                Err(e) => AgentReply::Error(e),
            },
            AgentCommand::ParamSet { key, value } => match self.params.set(&key, &value) {
                Ok(()) => {
                    tracing::info!("parameter {key} = {value}");
                    AgentReply::Ok
                }
                Err(e) => AgentReply::Error(e),
            },
            AgentCommand::Stats => AgentReply::Stats(self.stats(cpu)),
            AgentCommand::Stop => AgentReply::Ok,
        }
    }

    fn stats(&self, cpu: &CpuMeter) -> AgentStats {
        let now = now_ns();
        let f = self.shared.figures();
        let (p50, p99, max) = f.lateness.summary();
        AgentStats {
            cycles: f.cycles,
            rate_hz: f.rate.rate(now),
            jitter_p50_ns: p50,
            jitter_p99_ns: p99,
            jitter_max_ns: max,
            overruns: f.overruns,
            cpu_percent: cpu.percent(),
            rss_bytes: rss_bytes(),
            realtime: self.shared.realtime.load(Ordering::Relaxed),
            inputs: self.inputs.iter().flat_map(|i| i.stats(now)).collect(),
            figures: self.params.figures(),
        }
    }
}

/// Keeps `AgentError` in the public path of this module for agent authors.
pub type StepResult = Result<(), AgentError>;
