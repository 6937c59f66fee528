//! Bringing a robot up and down: the code `nerve launch`, `nerve down`,
//! `nerve demo` and `nerve calibrate` share, so that none of them calls
//! another command.
//!
//! * Up ([`up`], [`launch_robot`]): the router if none answers, every agent
//!   handed to its supervision, the agents not yet running started as
//!   daemons in parallel (a progress line each), a wait until each has
//!   registered, then the connections.
//! * Down ([`down`], [`clean`]): ask the router to stop every agent and
//!   itself, then a grace → SIGTERM → SIGKILL ladder for every process of
//!   the robot (those with a pid file too); then remove pid files of dead
//!   processes, stale iceoryx2 resources and, once nothing of the robot
//!   runs, its shared-memory files.

use crate::client::RouterSession;
use crate::launch_file::{self, LaunchFile, RestartPolicy};
use agent_sdk::World;
use agent_sdk::world::pid_alive;
use anyhow::{Context as _, Result, anyhow, bail};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use shm_schemas::control::cli_to_router::{self as proto, CliRequest, RouterReply};
use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How long [`up`] waits for every agent to register.
const REGISTER_TIMEOUT: Duration = Duration::from_secs(20);

fn router_up(world: &World) -> bool {
    RouterSession::open(world).and_then(|s| s.call(CliRequest::Ps)).is_ok()
}

/// Starts the router of `world` as a daemon unless one answers.
pub fn ensure_router(world: &World) -> Result<()> {
    if router_up(world) {
        return Ok(());
    }
    let exe = std::env::current_exe().context("cannot find the nerve executable")?;
    let out = Command::new(exe)
        .args(["--robot", world.robot().as_str(), "router", "--daemon"])
        .stdin(Stdio::null())
        .output()
        .context("cannot start the router")?;
    if !out.status.success() {
        bail!("the router did not start: {}", String::from_utf8_lossy(&out.stderr).trim());
    }
    eprintln!("{}", String::from_utf8_lossy(&out.stdout).trim());
    Ok(())
}

fn policy(p: RestartPolicy) -> proto::RestartPolicy {
    match p {
        RestartPolicy::Never => proto::RestartPolicy::Never,
        RestartPolicy::OnFailure => proto::RestartPolicy::OnFailure,
        RestartPolicy::Always => proto::RestartPolicy::Always,
    }
}

/// Starts every agent not already running, in parallel; returns how many failed.
fn start_agents(world: &World, file: &LaunchFile, running: &[String]) -> Result<usize> {
    let n = file.agents.len();
    let mut children = Vec::new();
    for spec in &file.agents {
        if running.contains(&spec.name) {
            children.push((spec, None));
            continue;
        }
        let argv = spec.argv(world.robot().as_str());
        let child = Command::new(&argv[0])
            .args(&argv[1..])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("cannot start {}", argv[0]))?;
        children.push((spec, Some(child)));
    }
    let mut failed = 0;
    for (i, (spec, child)) in children.into_iter().enumerate() {
        let Some(mut child) = child else {
            eprintln!("  [{}/{n}] {} ({}) already running", i + 1, spec.name, spec.kind);
            continue;
        };
        let status = child.wait()?;
        let mut out = String::new();
        let mut err = String::new();
        if let Some(mut o) = child.stdout.take() {
            let _ = o.read_to_string(&mut out);
        }
        if let Some(mut e) = child.stderr.take() {
            let _ = e.read_to_string(&mut err);
        }
        if status.success() {
            eprintln!(
                "  [{}/{n}] {} ({}) {}",
                i + 1,
                spec.name,
                spec.kind,
                out.trim().trim_start_matches(&format!("{} ", spec.name))
            );
        } else {
            failed += 1;
            eprintln!(
                "  [{}/{n}] {} ({}) FAILED: {} (log: {})",
                i + 1,
                spec.name,
                spec.kind,
                err.trim().trim_start_matches("error: "),
                world.log_file(&spec.name).display()
            );
        }
    }
    Ok(failed)
}

fn wait_registered(session: &RouterSession, file: &LaunchFile) -> Result<()> {
    let t0 = Instant::now();
    loop {
        // registered, or already in the supervisor's hands (restarting, failed)
        let live: Vec<String> = match session.call(CliRequest::Ps)? {
            RouterReply::Agents(v) => v.into_iter().map(|a| a.name).collect(),
            _ => vec![],
        };
        let missing: Vec<&str> =
            file.agents.iter().map(|a| a.name.as_str()).filter(|n| !live.iter().any(|l| l == n)).collect();
        if missing.is_empty() {
            return Ok(());
        }
        if t0.elapsed() > REGISTER_TIMEOUT {
            return Err(anyhow!(
                "not registered after {REGISTER_TIMEOUT:?}: {} (see `nerve logs NAME`)",
                missing.join(", ")
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Launches `path` as `nerve launch` does (without `--foreground`) on robot
/// `robot` unless the file names its own, and returns the robot's world.
/// Unlike `nerve launch`, any failure — an invalid file, an agent that did not
/// start or register, a connection refused — is an error. Used by `nerve demo`.
pub fn launch_robot(robot: &str, path: &std::path::Path) -> Result<World> {
    let (file, world) = launch_file::load(path, robot, false).map_err(|e| anyhow!("{e}"))?;
    crate::cmd::shm_space::ensure_shm_space("launch")?;
    world.ensure_state_dirs()?;
    let up = up(&world, &file)?;
    if up.failed > 0 {
        bail!("{} agent(s) of {} did not start (see the lines above)", up.failed, path.display());
    }
    if up.wiring_failed > 0 {
        bail!("{} connection(s) of {} could not be made (see the lines above)", up.wiring_failed, path.display());
    }
    Ok(world)
}

/// What [`up`] achieved.
pub struct BroughtUp {
    /// agents that did not start
    pub failed: usize,
    /// connections that could not be made
    pub wiring_failed: usize,
}

/// Starts the router if needed, hands every agent to its supervision (first,
/// so that an agent dying right after it starts is restarted), starts the
/// agents not yet running, waits until they have registered, and applies the
/// connections — a progress line for each.
pub fn up(world: &World, file: &LaunchFile) -> Result<BroughtUp> {
    ensure_router(world)?;
    let session = RouterSession::open(world)?;
    let running: Vec<String> = match session.call(CliRequest::Ps)? {
        RouterReply::Agents(v) => v.into_iter().filter(|a| a.pid > 0).map(|a| a.name).collect(),
        _ => vec![],
    };
    for spec in &file.agents {
        session
            .ok(CliRequest::Supervise(proto::Supervision {
                name: spec.name.clone(),
                argv: spec.argv(world.robot().as_str()),
                policy: policy(spec.restart),
                max_restarts: spec.max_restarts,
                window_ns: agent_sdk::clock::nanos(spec.restart_window),
                backoff_ns: agent_sdk::clock::nanos(spec.backoff),
                importance: spec.importance,
            }))
            .with_context(|| format!("the router refused to supervise {}", spec.name))?;
    }
    let failed = start_agents(world, file, &running)?;
    wait_registered(&session, file)?;
    let mut wiring_failed = 0;
    for (from, to) in &file.connections {
        let allow_cycle = file.allow_cycle.contains(&(from.clone(), to.clone()));
        match session.ok(CliRequest::Connect { from: from.clone(), to: to.clone(), allow_cycle }) {
            Ok(()) => eprintln!("  connected {from} -> {to}"),
            Err(e) => {
                wiring_failed += 1;
                eprintln!("  could not connect {from} -> {to}: {e:#}");
            }
        }
    }
    Ok(BroughtUp { failed, wiring_failed })
}

/// (name, pid) of every process that has a pid file in the robot's state directory.
fn pid_files(world: &World) -> Vec<(String, u32, std::path::PathBuf)> {
    let Ok(rd) = std::fs::read_dir(world.pids_dir()) else { return vec![] };
    rd.filter_map(|e| e.ok())
        .filter_map(|e| {
            let path = e.path();
            let name = path.file_stem()?.to_str()?.to_owned();
            let pid: u32 = std::fs::read_to_string(&path).ok()?.trim().parse().ok()?;
            Some((name, pid, path))
        })
        .collect()
}

/// Whether `pid` runs a nerve program of this robot. A pid file can outlive
/// its process (a crash), and the pid can be reused meanwhile — possibly by
/// another robot's router or agent: the robot is read from the process's own
/// `--robot` argument, else its `NERVE_ROBOT`, else the default robot.
fn belongs_to(pid: u32, world: &World) -> bool {
    let Ok(cmdline) = std::fs::read(format!("/proc/{pid}/cmdline")) else { return false };
    let args: Vec<String> = cmdline.split(|b| *b == 0).map(|a| String::from_utf8_lossy(a).into_owned()).collect();
    if !args.iter().any(|a| a.contains("nerve")) {
        return false;
    }
    let robot = args
        .windows(2)
        .find(|w| w[0] == "--robot")
        .map(|w| w[1].clone())
        .or_else(|| args.iter().find_map(|a| a.strip_prefix("--robot=").map(str::to_owned)))
        .or_else(|| {
            let env = std::fs::read(format!("/proc/{pid}/environ")).ok()?;
            env.split(|b| *b == 0).find_map(|v| {
                String::from_utf8_lossy(v).strip_prefix(&format!("{}=", agent_sdk::world::ROBOT_ENV)).map(str::to_owned)
            })
        })
        .unwrap_or_else(|| agent_sdk::world::DEFAULT_ROBOT.to_owned());
    robot == world.robot().as_str()
}

fn wait_gone(pids: &[u32], grace: Duration) -> Vec<u32> {
    let t0 = Instant::now();
    loop {
        let alive: Vec<u32> = pids.iter().copied().filter(|p| pid_alive(*p)).collect();
        if alive.is_empty() || t0.elapsed() >= grace {
            return alive;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn signal_all(pids: &[u32], sig: Signal) {
    for p in pids {
        let _ = kill(Pid::from_raw(*p as i32), sig);
    }
}

/// Stops everything of `world`; returns (processes stopped, processes killed).
pub fn down(world: &World, grace: Duration) -> (usize, usize) {
    let mut pids: Vec<u32> = Vec::new();
    // 1. ask the router to stop each agent, then itself
    if let Ok(s) = RouterSession::open(world) {
        if let Ok(RouterReply::Agents(agents)) = s.call(CliRequest::Ps) {
            for a in &agents {
                if a.pid > 0 {
                    pids.push(a.pid);
                }
                let _ = s.call(CliRequest::Stop { name: a.name.clone() });
            }
        }
        let _ = s.call(CliRequest::Shutdown);
    }
    // 2. every process with a pid file (agents started without a router, the router)
    for (_, pid, _) in pid_files(world) {
        if pid > 0 && !pids.contains(&pid) && pid_alive(pid) && belongs_to(pid, world) {
            pids.push(pid);
        }
    }
    let mut alive = wait_gone(&pids, grace);
    let mut killed = 0;
    if !alive.is_empty() {
        signal_all(&alive, Signal::SIGTERM);
        alive = wait_gone(&alive, grace);
    }
    if !alive.is_empty() {
        killed = alive.len();
        signal_all(&alive, Signal::SIGKILL);
        let left = wait_gone(&alive, Duration::from_secs(2));
        for p in left {
            eprintln!("warning: process {p} survived SIGKILL (uninterruptible sleep?)");
        }
    }
    (pids.len(), killed)
}

/// Removes pid files of dead processes, stale iceoryx2 resources and, when
/// no process of the robot is left, its shared-memory files.
pub fn clean(world: &World) -> usize {
    for (_, pid, path) in pid_files(world) {
        if !pid_alive(pid) {
            let _ = std::fs::remove_file(path);
        }
    }
    let me = std::process::id();
    // a killed process keeps its node "alive" (its lock held) until its last
    // thread has exited, shortly after it shows as a zombie: wait for those
    let t0 = std::time::Instant::now();
    while world.live_node_pids().into_iter().any(|p| p != me && !pid_alive(p)) && t0.elapsed() < Duration::from_secs(3)
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    world.cleanup_dead_nodes();
    let others_alive = world.live_node_pids().into_iter().any(|p| p != me);
    let mut removed = 0;
    if !others_alive {
        for f in world.shm_files() {
            if std::fs::remove_file(&f).is_ok() {
                removed += 1;
            }
        }
        // node records live in a folder per node (`nodes/<id>/`): drop it once
        // empty. Never the shared folders themselves (the root, `nodes/`,
        // `services/`): other robots create files in them at any moment.
        let nodes_dir = world.iox2_root().join("nodes");
        for f in world.iox2_files() {
            if std::fs::remove_file(&f).is_ok() {
                removed += 1;
            }
            if let Some(dir) = f.parent()
                && dir.parent() == Some(nodes_dir.as_path())
            {
                let _ = std::fs::remove_dir(dir);
            }
        }
    }
    removed
}

/// Names of the agents running on `world` (none when no router answers).
pub fn running_agents(world: &World) -> Vec<String> {
    let Ok(s) = RouterSession::open(world) else { return vec![] };
    match s.call(CliRequest::Ps) {
        Ok(RouterReply::Agents(v)) => v.into_iter().filter(|a| a.pid > 0).map(|a| a.name).collect(),
        _ => vec![],
    }
}

/// Stops everything of `world` with 3 s of grace per step and cleans up
/// after it; returns (processes stopped, processes killed).
pub fn down_and_clean(world: &World) -> (usize, usize) {
    let n = down(world, Duration::from_secs(3));
    clean(world);
    n
}

/// "stopped N process(es)", and how many needed SIGKILL.
pub fn stopped_line(stopped: usize, killed: usize) -> String {
    format!(
        "stopped {stopped} process(es){}",
        if killed > 0 { format!(", {killed} with SIGKILL") } else { String::new() }
    )
}
