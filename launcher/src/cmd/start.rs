//! `nerve router`, `nerve start` and `nerve exec`: running the router,
//! hot-adding an agent as a daemon, and running an agent in place of this
//! process (for systemd units).

use crate::kinds::resolve_kind;
use agent_sdk::World;
use agent_sdk::daemon::{Readiness, daemonize, init_logging, sd_notify};
use anyhow::{Context as _, Result, bail};
use shm_schemas::AgentName;
use std::process::{Command, ExitCode, Stdio};

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
    let mut cmd = Command::new(&exe);
    cmd.arg("--robot").arg(world.robot().as_str()).arg("--name").arg(&a.name).arg("--daemon");
    if let Some(p) = &a.period {
        agent_sdk::clock::parse_duration(p).map_err(anyhow::Error::msg).context("--period")?;
        cmd.arg("--period").arg(p);
    }
    if let Some(l) = &a.log_level {
        cmd.arg("--log-level").arg(l);
    }
    if a.suspended {
        cmd.arg("--suspended");
    }
    if let Some(c) = a.cpu_latency {
        cmd.arg("--cpu-latency").arg(c.to_string());
    }
    if let Some(c) = &a.cpus {
        cmd.arg("--cpus").arg(c.to_string());
    }
    for p in &a.params {
        cmd.arg("--param").arg(p);
    }
    if !a.args.is_empty() {
        cmd.arg("--").args(&a.args);
    }
    let out = cmd.stdin(Stdio::null()).output().with_context(|| format!("cannot run {}", exe.display()))?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    print!("{stdout}");
    eprint!("{stderr}");
    // an agent's start-up says "NAME started (pid N, robot R)" or why it failed
    let said_started = stdout.lines().any(|l| l.starts_with(&format!("{} started (pid ", a.name)));
    if !out.status.success() {
        if stderr.trim().is_empty() {
            bail!(
                "{} exited with {} without a word: is it a nerve agent? (agents are built on agent-sdk; try `{} --describe`)",
                exe.display(),
                out.status,
                exe.display()
            );
        }
        return Ok(ExitCode::from(1));
    }
    if !said_started {
        bail!(
            "{} exited without starting an agent: it is not a nerve agent, or it ignored --daemon (agents are built on agent-sdk; try `{} --describe`)",
            exe.display(),
            exe.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Replaces this process with the agent of kind `a.kind` (same pid, so
/// systemd's `Type=notify` and watchdog see the agent itself).
pub fn exec(world: &World, a: ExecArgs) -> Result<ExitCode> {
    use std::os::unix::process::CommandExt;
    let exe = resolve_kind(&a.kind)?;
    let err = Command::new(&exe).arg("--robot").arg(world.robot().as_str()).args(&a.args).exec();
    bail!("cannot run {}: {err}", exe.display())
}
