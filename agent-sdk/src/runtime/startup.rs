//! Start-up of an agent: the command line, `--describe` (the agent's ports
//! and parameters as JSON, from a throw-away world), and [`start`]: the node,
//! the control service (beside the task's wake-up event and the router's
//! client), the agent's ports, the task thread, registration, then the
//! message checker until the agent stops.

use super::checker::Checker;
use super::router_link::{RegisterError, RouterLink};
use super::runaway;
use super::task::{Stepper, SuspendGate, Wakes, task_main};
use super::{Shared, TaskFigures};
use crate::agent::{Agent, AgentError, Binding, Setup, Task};
use crate::cli::CommonArgs;
use crate::clock::{now_ns, parse_duration};
use crate::control::{ControlError, ControlServer, ControlSize, agent_router_client};
use crate::daemon::{Readiness, daemonize, init_logging, sd_notify};
use crate::params::ParamTable;
use crate::rt;
use crate::world::{Ipc, World};
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use shm_schemas::AgentName;
use shm_schemas::control::agent_to_router::{Registration, TaskKind};
use shm_schemas::control::cli_to_router::{RouterReply, RouterRequest};
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Exit code when the agent could not start (bad arguments, duplicate name, device).
pub const EXIT_STARTUP: u8 = 1;

/// Why an agent could not start. Each keeps its cause; the message is what
/// `nerve start` prints.
#[derive(Debug, thiserror::Error)]
pub enum StartupError {
    /// The robot's world (its folders, its iceoryx2 node).
    #[error(transparent)]
    World(#[from] crate::world::WorldError),
    /// `--name` is not a valid agent name.
    #[error("invalid --name: {0}")]
    Name(#[source] shm_schemas::NameError),
    /// `--cpus` names CPUs the agent may not run on.
    #[error("--cpus: {0}")]
    Cpus(String),
    /// `--poll` without a placement.
    #[error(transparent)]
    Poll(#[from] super::poll::PollError),
    /// `--period` cannot be read, or is given to an event-driven agent.
    #[error("--period: {0}")]
    Period(String),
    /// Another agent of this name runs.
    #[error(
        "an agent named {name:?} is already running on robot {robot}; choose another --name, or stop it first with `nerve stop {name}`"
    )]
    AlreadyRunning {
        /// the name
        name: String,
        /// the robot
        robot: String,
    },
    /// The agent's control service could not be served.
    #[error(transparent)]
    Control(#[from] ControlError),
    /// The task's wake-up event could not be made.
    #[error("cannot create the task's wake-up event {service}: {source}")]
    WakeEvent {
        /// the event service
        service: String,
        /// what iceoryx2 said
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The agent's own `new` or `start` failed (a port, a device, its configuration).
    #[error("{kind} {name:?} could not start: {source}")]
    Agent {
        /// its kind
        kind: &'static str,
        /// its name
        name: String,
        /// what it said
        #[source]
        source: AgentError,
    },
    /// A `--param KEY=VALUE` setting was refused.
    #[error("--param {setting}: {reason}")]
    Param {
        /// the setting as given
        setting: String,
        /// why
        reason: String,
    },
    /// The router refused the registration.
    #[error(transparent)]
    Refused(shm_schemas::control::cli_to_router::RouterError),
    /// The task thread could not be started.
    #[error("cannot start the task thread: {0}")]
    Thread(#[source] std::io::Error),
    /// The task ended while the agent started (a panic, a stop).
    #[error("{kind} {name:?} stopped while starting")]
    StoppedWhileStarting {
        /// its kind
        kind: &'static str,
        /// its name
        name: String,
    },
    /// It could not become a daemon.
    #[error("cannot daemonize: {0}")]
    Daemon(#[source] std::io::Error),
    /// `--describe` could not write the description.
    #[error("cannot describe the agent: {0}")]
    Describe(#[source] serde_json::Error),
}

fn wake_err<E: std::error::Error + Send + Sync + 'static>(service: &str) -> impl FnOnce(E) -> StartupError {
    move |e| StartupError::WakeEvent { service: service.into(), source: Box::new(e) }
}

/// Runs agent `A` with the common command line; the body of an agent's `main`.
pub fn run<A: Agent>() -> ExitCode {
    let args = <CommonArgs as clap::Parser>::parse();
    run_with_args::<A>(args)
}

/// Makes a panic anywhere in this process end the process, in any build:
/// the panic is reported as usual, then the process aborts. The release
/// profile says `panic = "abort"`; the dev profile unwinds (tests need
/// unwinding, and a profile that aborts made cargo build every dependency
/// twice, once per strategy). Unwinding would lose only the thread that
/// panicked: an agent whose task died alone answers the router but never
/// steps again, and a router whose serving thread died supervises no one,
/// and neither is visible to whoever watches the process. Every nerve
/// daemon calls this first ([`run`] does for agents; `nerve` for the router
/// and its other commands).
pub fn abort_on_panic() {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        report(info);
        std::process::abort();
    }));
}

/// Runs agent `A` with already parsed arguments.
pub fn run_with_args<A: Agent>(args: CommonArgs) -> ExitCode {
    ExitCode::from(run_status::<A>(args))
}

/// [`run_with_args`], returning the process's exit status as a number (0,
/// or [`EXIT_STARTUP`] when the agent could not start), for a host that
/// ends the process itself (the Python package's `nerve.run`).
pub fn run_status<A: Agent>(args: CommonArgs) -> u8 {
    let mut make = |setup: &mut Setup| A::new(setup).map(|a| Box::new(a) as Box<dyn Stepper>);
    run_status_erased(args, AgentKind { kind: A::kind(), task: A::task(), make: &mut make })
}

/// Makes the agent on its setup: [`Agent::new`], its result behind a pointer.
type MakeAgent<'a> = &'a mut dyn FnMut(&mut Setup) -> Result<Box<dyn Stepper>, AgentError>;

/// What the start-up needs of an agent type, without being generic over it
/// (see [`Stepper`]): its kind, its task, and how to make one.
struct AgentKind<'a> {
    kind: &'static str,
    task: Task,
    make: MakeAgent<'a>,
}

/// [`run_status`], compiled once here rather than in every agent program.
fn run_status_erased(args: CommonArgs, mut agent: AgentKind<'_>) -> u8 {
    // the start-up's debug lines count from here, through the daemon's forks
    let began = Instant::now();
    abort_on_panic();
    let name = args.name.clone().unwrap_or_else(|| agent.kind.to_owned());
    let mut readiness = Readiness::foreground();
    let world = match World::new(&args.robot) {
        Ok(w) => w,
        Err(e) => return startup_error(&mut readiness, &e.into()),
    };
    if let Err(e) = AgentName::new(&name) {
        return startup_error(&mut readiness, &StartupError::Name(e));
    }
    if args.describe {
        return match describe(&args, &mut agent) {
            Ok(json) => {
                println!("{json}");
                0
            }
            Err(e) => startup_error(&mut readiness, &e),
        };
    }
    if args.daemon {
        if let Err(e) = world.ensure_state_dirs() {
            return startup_error(&mut readiness, &e.into());
        }
        match daemonize(&world.log_file(&name), &world.pid_file(&name)) {
            Ok(r) => readiness = r,
            Err(e) => return startup_error(&mut readiness, &StartupError::Daemon(e)),
        }
    }
    init_logging(&name, args.log_level.as_deref());
    // in the daemon, not the parent waiting for its readiness
    if let Err(e) = crate::termination::install() {
        tracing::warn!("{e}; a SIGTERM may go unseen when another signal follows it");
    }
    match start(&args, &name, world, &mut readiness, began, agent) {
        Ok(()) => 0,
        Err(e) => startup_error(&mut readiness, &e),
    }
}

fn startup_error(readiness: &mut Readiness, e: &StartupError) -> u8 {
    let msg = e.to_string();
    let msg = msg.as_str();
    tracing::error!("{msg}");
    if readiness.pid_file().is_none() {
        eprintln!("error: {msg}");
    }
    readiness.fail(msg);
    EXIT_STARTUP
}

/// The agent's description, made by running [`Agent::new`] with its ports
/// bound to nothing: no iceoryx2 node, no shared memory, no device (authors
/// open devices in [`Agent::start`], which describing never runs). The
/// world the agent sees is a private robot's (`describe-PID`), so that a
/// check of what else runs (a ring's writer) never refuses a description.
fn describe(args: &CommonArgs, kind: &mut AgentKind<'_>) -> Result<String, StartupError> {
    use shm_schemas::control::describe::Description;
    let world = World::new(&format!("describe-{}", std::process::id()))?;
    let mut setup =
        Setup::new(world, AgentName::new(kind.kind).map_err(StartupError::Name)?, Binding::Nothing, args.args.clone());
    let agent = (kind.make)(&mut setup).map_err(|source| StartupError::Agent {
        kind: kind.kind,
        name: kind.kind.into(),
        source,
    })?;
    apply_params(&setup.params, &args.params)?;
    let (task, default_period_ns) = match kind.task {
        Task::Periodic(p) => (TaskKind::Periodic, Some(crate::clock::nanos(p))),
        Task::EventDriven => (TaskKind::EventDriven, None),
    };
    let d = Description {
        protocol: shm_schemas::PROTOCOL_VERSION,
        kind: kind.kind.into(),
        task,
        default_period_ns,
        inputs: setup.inputs.iter().filter(|i| !setup.calls.is_call(i.name())).map(|i| i.spec()).collect(),
        outputs: setup.outputs.clone(),
        params: setup.params.snapshot(),
        schemas: setup.schemas.clone(),
        services: setup.calls.services.clone(),
        clients: setup.calls.clients.clone(),
    };
    drop(agent);
    drop(setup);
    serde_json::to_string(&d).map_err(StartupError::Describe)
}

/// Applies `--param KEY=VALUE` settings.
fn apply_params(table: &ParamTable, settings: &[String]) -> Result<(), StartupError> {
    for s in settings {
        let (k, v) = s
            .split_once('=')
            .ok_or_else(|| StartupError::Param { setting: format!("{s:?}"), reason: "write KEY=VALUE".into() })?;
        table.set(k.trim(), v).map_err(|reason| StartupError::Param { setting: s.clone(), reason })?;
    }
    Ok(())
}

/// The whole start-up of an agent of kind `agent.kind`, made by
/// `agent.make`: not generic over the agent, so compiled once here rather
/// than in every agent program (see [`Stepper`]).
fn start(
    args: &CommonArgs,
    name: &str,
    world: World,
    readiness: &mut Readiness,
    began: Instant,
    agent: AgentKind<'_>,
) -> Result<(), StartupError> {
    let AgentKind { kind, task: task_kind, make } = agent;
    let agent_name = AgentName::new(name).map_err(StartupError::Name)?;
    let period = match (task_kind, &args.period) {
        (Task::Periodic(default), None) => Some(default),
        (Task::Periodic(_), Some(p)) => Some(parse_duration(p).map_err(|e| StartupError::Period(e.to_string()))?),
        (Task::EventDriven, Some(_)) => {
            return Err(StartupError::Period(format!("agent kind {} is event-driven; it takes no --period", kind)));
        }
        (Task::EventDriven, None) => None,
    };

    let polling = super::poll::from_args(args)?;
    // before any thread starts: they all inherit it
    if let Some(cpus) = &args.cpus {
        rt::set_affinity(cpus).map_err(StartupError::Cpus)?;
    }
    // every line of the start-up says so, with the agent's name and kind
    let startup = tracing::info_span!("start-up", agent = name, kind = kind).entered();
    // held until this function returns, or the kernel drops it when the process ends
    let (_cpu_latency_hold, cpu_latency) = if args.no_realtime {
        (None, shm_schemas::stats::CpuLatency::Off)
    } else {
        crate::cpu_latency::apply(args.cpu_latency)
    };
    // µs since the process began (its `main`), through the daemon's forks
    let stage = |what: &str| tracing::debug!(us = began.elapsed().as_micros() as u64, "{what}");
    stage("daemon, logging and PM QoS set up");
    let node = Arc::new(world.node(name)?);
    stage("node created");
    let ctl_service = world.robot().ctl_service(&agent_name);
    let wake_service = format!("nerve/{}/{}/_wake", world.robot(), name);
    // Side by side on two threads, none of it visible to other processes
    // until the registration: the control service here, the task's wake-up
    // event and the client of the router's service on a helper (1.3 to 2 ms
    // each way, on the path of a hot-add; a third thread was slower on two
    // cores).
    let (server, early_wake, router_client) = std::thread::scope(|s| {
        let helper = std::thread::Builder::new().name("start-up".into()).spawn_scoped(s, || {
            (wake_event(&node, &wake_service), agent_router_client::<RouterRequest, RouterReply>(&world, &node).ok())
        });
        let server = control_server(&world, &node, &ctl_service, &agent_name);
        // no helper to be had: its part is made in turn below
        let (wake, client) = helper.map_or_else(|e| (Err(StartupError::Thread(e)), None), joined);
        (server, wake, client)
    });
    let server = server?;
    stage("control service, wake-up event and router client created");
    // A crashed run of this agent may have left the wake-up event full of
    // its listeners until the control service's clean-up above removed
    // them: made again once, after it.
    let (wake_listener, checker_wake, wake) = match early_wake {
        Ok(w) => w,
        Err(e) => {
            tracing::debug!("wake-up event made again after the clean-up ({e})");
            wake_event(&node, &wake_service)?
        }
    };
    let mut link = RouterLink::new();
    if let Some(c) = router_client {
        link.adopt_client(c);
    }

    let mut setup = Setup::new(world.clone(), agent_name.clone(), Binding::Shm(node.clone()), args.args.clone());
    let agent = make(&mut setup).map_err(|source| StartupError::Agent { kind, name: name.into(), source })?;
    stage("agent and its ports created");
    let Setup { inputs, outputs, schemas, params, calls, waker, .. } = setup;
    apply_params(&params, &args.params)?;
    crate::port::depth::apply_settings(&inputs, &args.inputs).map_err(|source| StartupError::Agent {
        kind,
        name: name.into(),
        source,
    })?;

    let shared = Arc::new(Shared {
        period_ns: AtomicU64::new(period.map(crate::clock::nanos).unwrap_or(0)),
        suspended: AtomicBool::new(args.suspended),
        stop: AtomicBool::new(false),
        generation: AtomicU64::new(0),
        realtime: AtomicBool::new(false),
        cpu_latency,
        figures: Mutex::new(TaskFigures { last_cycle_ns: now_ns(), ..TaskFigures::default() }),
        in_step_since_ns: AtomicU64::new(0),
        gate: SuspendGate::default(),
        wake,
        polling,
    });

    // the task thread, before the registration: the agent's own `start`
    // (a device opened, a session up) runs on it while the router answers,
    // and the connections that come with the answer are made at most that
    // `start` later (issue 18)
    let task_shared = shared.clone();
    let task_inputs = inputs.clone();
    let name_owned = name.to_owned();
    let want_rt = !args.no_realtime;
    let prio = args.priority;
    let (started_tx, started_rx) = std::sync::mpsc::channel::<Result<(), AgentError>>();
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
            let wakes = Wakes { listener: wake_listener, waker };
            task_main(agent, &name_owned, &task_shared, &task_inputs, wakes, task_kind, started_tx)
        })
        .map_err(StartupError::Thread)?;
    if want_rt {
        let _ = rt::set_thread_fifo((prio + 1).min(99));
    }
    let registration = Registration {
        name: name.to_owned(),
        pid: std::process::id(),
        kind: kind.to_owned(),
        executable: std::env::current_exe().map(|p| p.display().to_string()).unwrap_or_default(),
        task: match task_kind {
            Task::Periodic(_) => TaskKind::Periodic,
            Task::EventDriven => TaskKind::EventDriven,
        },
        period_ns: period.map(crate::clock::nanos),
        inputs: inputs.iter().filter(|i| !calls.is_call(i.name())).map(|i| i.spec()).collect(),
        outputs,
        log_file: readiness.pid_file().map(|_| world.log_file(name).display().to_string()),
        suspended: args.suspended,
        schemas,
        services: calls.services,
        clients: calls.clients,
    };
    let registered = link.register(&node, &world, &registration, &shared);
    stage("registration answered");
    match registered {
        Ok(()) => {}
        Err(RegisterError::Refused(e)) => {
            stop_task(&shared, handle);
            return Err(StartupError::Refused(e));
        }
        Err(RegisterError::NoRouter) => tracing::warn!(
            "no router runs for robot {}; running unregistered, and registering as soon as one starts (`nerve router --robot {}`)",
            world.robot(),
            world.robot()
        ),
        Err(RegisterError::Other(e)) => tracing::warn!("could not register with the router: {e}; will retry"),
    }

    // ready only once the agent's own `start` worked (devices opened, a
    // network session up): a failed start is a failed `nerve start`, and an
    // exit without leaving the router, so supervision counts it as a failure
    match started_rx.recv_timeout(START_TIMEOUT) {
        Ok(Ok(())) => stage("agent started"),
        Ok(Err(source)) => {
            let _ = handle.join();
            return Err(StartupError::Agent { kind, name: name.into(), source });
        }
        Err(_) if handle.is_finished() => {
            return Err(StartupError::StoppedWhileStarting { kind, name: name.into() });
        }
        Err(_) => tracing::warn!(
            "the agent's start has not finished after {} s; reporting ready anyway",
            START_TIMEOUT.as_secs()
        ),
    }

    let startup_msg = format!("{name} started (pid {}, robot {})", std::process::id(), world.robot());
    tracing::info!(
        "started: kind {}, {}{}",
        kind,
        match period {
            Some(p) => format!("periodic every {}", crate::clock::format_duration(p)),
            None => "event-driven".into(),
        },
        if link.is_registered() { ", registered with the router" } else { "" }
    );
    readiness.ready(&startup_msg);
    let _ = sd_notify("READY=1");
    drop(startup);

    // a poller keeps its CPU by design: the runaway guard would demote it (see `poll`)
    let guard = if shared.realtime.load(Ordering::Relaxed) && shared.polling.is_none() {
        use std::os::unix::thread::JoinHandleExt;
        runaway::TaskThread::new(handle.as_pthread_t()).map(|t| (t, runaway::Guard::new(args.rt_cpu_limit), prio))
    } else {
        None
    };
    let checker = Checker {
        world: &world,
        node: &node,
        shared: &shared,
        inputs: &inputs,
        params: &params,
        task_kind,
        guard: std::cell::RefCell::new(guard),
        lateness_scratch: std::cell::RefCell::default(),
    };
    checker.run(&server, &checker_wake, &mut link, &registration, !args.no_realtime);

    stop_task(&shared, handle);
    link.unregister(name);
    let _ = sd_notify("STOPPING=1");
    tracing::info!("stopped");
    Ok(())
}

/// What a start-up helper thread made (its panic goes on in this thread).
fn joined<T>(helper: std::thread::ScopedJoinHandle<'_, T>) -> T {
    helper.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
}

/// Serves the agent's control service. A crashed run of this agent leaves
/// its control server behind (and its other ports) until the router cleans
/// up after it: found here as a served service, cleaned, and tried again
/// (after waiting, while a run killed a moment ago is still exiting); a
/// live one stays served, and is the agent of this name running.
fn control_server(
    world: &World,
    node: &Node<Ipc>,
    ctl_service: &str,
    name: &AgentName,
) -> Result<ControlServer<AgentCommand, AgentReply>, StartupError> {
    let blockable = |e: &ControlError| matches!(e, ControlError::AlreadyServed { .. } | ControlError::Ipc { .. });
    // a run of this agent killed a moment ago may not be gone yet
    ControlServer::create_clearing(node, ctl_service, ControlSize::AGENT, "control service", blockable).map_err(|e| {
        match e {
            ControlError::AlreadyServed { .. } => {
                StartupError::AlreadyRunning { name: name.to_string(), robot: world.robot().to_string() }
            }
            e => e.into(),
        }
    })
}

/// The task's wake-up event: the task's listener, the message checker's
/// (the task wakes it when it stops) and the notifier that wakes the task.
type WakeEvent = (Listener<Ipc>, Listener<Ipc>, Notifier<Ipc>);

/// Makes the task's [`WakeEvent`].
fn wake_event(node: &Node<Ipc>, service: &str) -> Result<WakeEvent, StartupError> {
    let factory = node
        .service_builder(&service.try_into().map_err(wake_err(service))?)
        .event()
        .max_listeners(2)
        .max_notifiers(2)
        .open_or_create()
        .map_err(wake_err(service))?;
    let task = factory.listener_builder().create().map_err(wake_err(service))?;
    let checker = factory.listener_builder().create().map_err(wake_err(service))?;
    let notifier = factory.notifier_builder().create().map_err(wake_err(service))?;
    Ok((task, checker, notifier))
}

/// Stops the task: wakes it, waits for it a bounded time.
fn stop_task(shared: &Shared, handle: std::thread::JoinHandle<()>) {
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
}

/// How long the start-up waits for the agent's own `start` before it
/// reports ready anyway.
const START_TIMEOUT: Duration = Duration::from_secs(60);
