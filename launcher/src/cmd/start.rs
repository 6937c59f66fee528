//! `nerve router`, `nerve start` and `nerve exec`: running the router,
//! hot-adding an agent (the router starts it as a daemon, starting a router
//! first if none runs: the router is the only process that starts agents),
//! and running an agent in place of this process (for systemd units: `exec`
//! replaces this process, it starts none).

use crate::client::RouterSession;
use crate::kinds::resolve_kind;
use agent_sdk::World;
use agent_sdk::daemon::{Readiness, daemonize, init_logging, sd_notify};
use anyhow::{Context as _, Result, bail};
use shm_schemas::AgentName;
use shm_schemas::control::cli_to_router::{
    CliRequest, RestartPolicy, RouterReply, StartOutcome, StartResult, StartSpec, Supervision,
};
use std::process::{Command, ExitCode};

/// `nerve router`
#[derive(Debug, clap::Args)]
pub struct RouterArgs {
    /// Detach and run as a daemon (log in the robot's state directory).
    #[arg(long)]
    pub daemon: bool,
    /// Log filter; RUST_LOG is used when absent.
    #[arg(long, value_parser = agent_sdk::daemon::parse_log_level)]
    pub log_level: Option<String>,
}

/// `nerve start`
#[derive(Debug, clap::Args)]
pub struct StartArgs {
    /// Agent kind (ticker, relay, ...) or the path of an agent executable.
    pub kind: String,
    /// Agent name, unique within the robot.
    #[arg(long)]
    pub name: String,
    /// Period of a periodic agent: 10ms, 1s, 100hz...
    #[arg(long)]
    pub period: Option<String>,
    /// Log filter of the agent.
    #[arg(long, value_parser = agent_sdk::daemon::parse_log_level)]
    pub log_level: Option<String>,
    /// Start with the task suspended.
    #[arg(long)]
    pub suspended: bool,
    /// Wake-up latency bound (PM QoS) the agent holds while it runs, in µs,
    /// or `off` (default: the agent's, 0 unless NERVE_CPU_LATENCY says otherwise).
    #[arg(long, value_name = "US|off")]
    pub cpu_latency: Option<agent_sdk::cpu_latency::CpuLatencySetting>,
    /// Keep the agent on these CPUs: 1, 0,1, 0-3.
    #[arg(long, value_name = "LIST")]
    pub cpus: Option<agent_sdk::rt::CpuList>,
    /// Poll instead of sleeping, on the CPUs of --cpus (required): the
    /// fastest hop, at the cost of those CPUs.
    #[arg(long)]
    pub poll: bool,
    /// Set a parameter before the task starts (repeatable): `--param gain=2`.
    /// `nerve param list NAME` shows an agent's parameters.
    #[arg(long = "param", value_name = "KEY=VALUE", value_parser = parse_param)]
    pub params: Vec<String>,
    /// Arguments for the agent itself.
    #[arg(last = true)]
    pub args: Vec<String>,
}

/// A `--param` value: `KEY=VALUE` with a non-empty key (the agent checks the value).
fn parse_param(s: &str) -> Result<String, String> {
    match s.split_once('=') {
        Some((k, _)) if !k.trim().is_empty() => Ok(s.to_owned()),
        _ => Err(format!("{s:?} is not KEY=VALUE (e.g. --param gain=2)")),
    }
}

/// `nerve exec`
#[derive(Debug, clap::Args)]
pub struct ExecArgs {
    /// Agent kind.
    pub kind: String,
    /// Arguments of the agent (common options, then `--` and its own).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<String>,
}

pub fn router(world: &World, a: RouterArgs) -> Result<ExitCode> {
    let mut readiness = Readiness::foreground();
    if a.daemon {
        world.ensure_state_dirs()?;
        readiness = daemonize(&world.log_file("router"), &world.pid_file("router")).context("cannot daemonize")?;
    }
    init_logging("router", a.log_level.as_deref());
    let router = match nerve_router::Router::new(world.clone()) {
        Ok(r) => r,
        Err(e) => {
            readiness.fail(&e.to_string());
            bail!(e);
        }
    };
    // liveness checks and restarts keep their timing under load; agents run above (20+)
    if let Err(e) = agent_sdk::rt::set_thread_fifo(ROUTER_PRIORITY) {
        tracing::info!("real-time scheduling not permitted ({e}); the router runs with normal priority");
    }
    readiness.ready(&format!("router of robot {} started (pid {})", world.robot(), std::process::id()));
    let _ = sd_notify("READY=1");
    router.run().map_err(anyhow::Error::msg)?;
    drop(readiness);
    Ok(ExitCode::SUCCESS)
}

/// SCHED_FIFO priority of the router: below every agent's task (20) and message checker.
const ROUTER_PRIORITY: i32 = 10;

pub fn start(world: &World, a: StartArgs) -> Result<ExitCode> {
    AgentName::new(&a.name)?;
    super::shm_space::ensure_shm_space("start an agent")?;
    let exe = resolve_kind(&a.kind)?;
    let mut argv: Vec<String> = vec![
        exe.display().to_string(),
        "--robot".into(),
        world.robot().to_string(),
        "--name".into(),
        a.name.clone(),
        "--daemon".into(),
    ];
    if let Some(p) = &a.period {
        agent_sdk::clock::parse_duration(p).map_err(anyhow::Error::msg).context("--period")?;
        argv.extend(["--period".into(), p.clone()]);
    }
    if let Some(l) = &a.log_level {
        argv.extend(["--log-level".into(), l.clone()]);
    }
    if a.suspended {
        argv.push("--suspended".into());
    }
    if let Some(c) = a.cpu_latency {
        argv.extend(["--cpu-latency".into(), c.to_string()]);
    }
    if let Some(c) = &a.cpus {
        argv.extend(["--cpus".into(), c.to_string()]);
    }
    if a.poll {
        argv.push("--poll".into());
    }
    for p in &a.params {
        argv.extend(["--param".into(), p.clone()]);
    }
    if !a.args.is_empty() {
        argv.push("--".into());
        argv.extend(a.args.iter().cloned());
    }
    // the router starts it (the only process that starts agents): one if none runs
    crate::bring::ensure_router(world)?;
    let session = RouterSession::open(world)?;
    let spec = StartSpec {
        agent: Supervision {
            name: a.name.clone(),
            argv,
            policy: RestartPolicy::Never,
            max_restarts: 0,
            window_ns: 0,
            backoff_ns: 0,
            importance: 5,
            cwd: std::env::current_dir().ok().map(|d| d.display().to_string()),
        },
        // a hot-added agent is not supervised, and one supervised by a
        // launch keeps its policy
        supervise: false,
        env: Some(crate::bring::environment()),
    };
    let outcome = crate::bring::ask_start(&session, vec![spec])?.into_iter().next();
    let Some(StartOutcome { result, .. }) = outcome else { bail!("the router answered a start without its outcome") };
    match result {
        StartResult::Running { pid } => {
            eprintln!(
                "error: {} is already running as pid {pid}; stop it first (`nerve stop {}`), or choose another --name",
                a.name, a.name
            );
            Ok(ExitCode::from(1))
        }
        StartResult::Failed { status, said } => {
            if said.is_empty() {
                bail!(
                    "{} exited with {status} without a word: is it a nerve agent? (agents are built on agent-sdk; try `{} --describe`)",
                    exe.display(),
                    exe.display()
                );
            }
            eprintln!("{said}");
            Ok(ExitCode::from(1))
        }
        StartResult::Started { said } => {
            // an agent's start-up says "NAME started (pid N, robot R)"
            if !said.lines().any(|l| l.starts_with(&format!("{} started (pid ", a.name))) {
                if !said.is_empty() {
                    println!("{said}");
                }
                bail!(
                    "{} exited without starting an agent: it is not a nerve agent, or it ignored --daemon (agents are built on agent-sdk; try `{} --describe`)",
                    exe.display(),
                    exe.display()
                );
            }
            println!("{said}");
            // it is ready once registered (its start-up said so after the
            // router answered it): the router tells, woken by the registration
            let ask = CliRequest::WaitRegistered {
                names: vec![a.name.clone()],
                timeout_ns: agent_sdk::clock::nanos(REGISTER_WAIT),
            };
            match session.call(ask) {
                Ok(RouterReply::Waited { missing }) if missing.is_empty() => {}
                Ok(_) => eprintln!(
                    "warning: {} runs but has not registered with the router within {REGISTER_WAIT:?}; see `nerve logs {}`",
                    a.name, a.name
                ),
                Err(e) => eprintln!("warning: cannot ask the router whether {} registered: {e:#}", a.name),
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// How long `nerve start` waits for its agent's registration after its
/// start-up said it started.
const REGISTER_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

/// Replaces this process with the agent of kind `a.kind` (same pid, so
/// systemd's `Type=notify` and watchdog see the agent itself).
pub fn exec(world: &World, a: ExecArgs) -> Result<ExitCode> {
    use std::os::unix::process::CommandExt;
    let exe = resolve_kind(&a.kind)?;
    let err = Command::new(&exe).arg("--robot").arg(world.robot().as_str()).args(&a.args).exec();
    bail!("cannot run {}: {err}", exe.display())
}
