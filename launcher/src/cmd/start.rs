//! `nerve router` and `nerve start`: running the router, and hot-adding an
//! agent as a daemon.

use crate::cli::{ExecArgs, RouterArgs, StartArgs};
use agent_sdk::World;
use agent_sdk::daemon::{Readiness, daemonize, init_logging, sd_notify};
use anyhow::{Context as _, Result, bail};
use shm_schemas::AgentName;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};

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

/// Prefix of agent executables: kind `ticker` is the program `nerve-ticker`.
pub const AGENT_PREFIX: &str = "nerve-";

/// Finds the executable of an agent kind: a path, else `nerve-<kind>` next to
/// this program, else on `PATH`.
pub fn resolve_kind(kind: &str) -> Result<PathBuf> {
    if kind.contains('/') {
        let p = PathBuf::from(kind);
        if !is_executable(&p) {
            bail!("{kind} is not an executable file; give the path of a built agent, or a kind such as `ticker`");
        }
        return Ok(p);
    }
    let file = format!("{AGENT_PREFIX}{kind}");
    let mut dirs: Vec<PathBuf> = Vec::new();
    if let Some(dir) = std::env::current_exe().ok().and_then(|p| p.parent().map(Path::to_path_buf)) {
        dirs.push(dir);
    }
    if let Some(path) = std::env::var_os("PATH") {
        dirs.extend(std::env::split_paths(&path));
    }
    for d in &dirs {
        let p = d.join(&file);
        if is_executable(&p) {
            return Ok(p);
        }
    }
    let known = known_kinds();
    bail!(
        "unknown agent kind {kind:?}: no executable {file} next to nerve or on PATH; known kinds: {} (build agents with `cargo build --workspace`)",
        if known.is_empty() { "none found".to_string() } else { known.join(", ") }
    )
}

/// Agent kinds installed next to this program.
pub fn known_kinds() -> Vec<String> {
    let Some(dir) = std::env::current_exe().ok().and_then(|p| p.parent().map(Path::to_path_buf)) else { return vec![] };
    let mut kinds: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter_map(|e| e.file_name().to_str().and_then(|n| n.strip_prefix(AGENT_PREFIX)).map(str::to_owned))
                .filter(|k| k.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-'))
                .collect()
        })
        .unwrap_or_default();
    kinds.sort();
    kinds.dedup();
    kinds
}

fn is_executable(p: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    p.metadata().map(|m| m.is_file() && m.permissions().mode() & 0o111 != 0).unwrap_or(false)
}

pub fn start(world: &World, a: StartArgs) -> Result<ExitCode> {
    AgentName::new(&a.name)?;
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
    if !a.args.is_empty() {
        cmd.arg("--").args(&a.args);
    }
    let status = cmd.stdin(Stdio::null()).status().with_context(|| format!("cannot run {}", exe.display()))?;
    if !status.success() {
        // the agent printed why on stderr
        return Ok(ExitCode::from(1));
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
