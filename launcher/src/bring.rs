//! Bringing a robot up and down: the code `nerve launch`, `nerve down` and
//! the commands that bring a robot down share, so that none of them calls
//! another command (`nerve demo` and `nerve calibrate`, in `nerve-demo`,
//! run `nerve launch` and `nerve down` themselves).
//!
//! * Up ([`up`]): the router if none answers; one
//!   [`CliRequest::Start`] for every agent, which the router hands to its
//!   supervision and starts in parallel if not yet running (the router is
//!   the only process that starts agents: nothing here spawns one); a
//!   progress line each, with a failed agent's message and last log lines;
//!   one wait until each has registered, then the connections.
//! * Down ([`down`], [`clean`]): ask the router to stop every agent and
//!   itself, then a grace → SIGTERM → SIGKILL ladder for every process of
//!   the robot (those with a pid file too); then remove pid files of dead
//!   processes, stale iceoryx2 resources and, once nothing of the robot
//!   runs, its shared-memory files and its simulated clock's page.

use crate::client::RouterSession;
use crate::launch_file::LaunchFile;
use agent_sdk::World;
use agent_sdk::process::{ProcessError, ProcessHandle};
use agent_sdk::world::pid_alive;
use anyhow::{Context as _, Result, anyhow, bail};
use nix::sys::signal::Signal;
use shm_schemas::control::cli_to_router::{self as proto, CliRequest, RouterReply};
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

/// How many of its last log lines a launch shows of an agent that failed to start.
const FAILED_LOG_LINES: usize = 12;

/// How long a command waits for the router to answer a [`CliRequest::Start`]:
/// the router answers once every start-up process has ended, and an agent's
/// start-up waits up to a minute for its own `start` before it reports
/// ready anyway (`agent_sdk::runtime`).
pub const START_WAIT: Duration = Duration::from_secs(90);

/// This command's environment, for the agents the router starts: they get
/// what they would have inherited from it (`NERVE_SIM_CLOCK`,
/// `PYTHONPATH`, `RUST_LOG`...), not the router's. Variables that are not
/// UTF-8 are left out.
pub fn environment() -> Vec<(String, String)> {
    std::env::vars_os().filter_map(|(k, v)| Some((k.into_string().ok()?, v.into_string().ok()?))).collect()
}

/// Asks the router to start `agents` (it spawns them in parallel; nothing
/// here starts a process) and returns the outcomes in the same order.
pub fn ask_start(session: &RouterSession, agents: Vec<proto::StartSpec>) -> Result<Vec<proto::StartOutcome>> {
    let n = agents.len();
    match session.call_within(CliRequest::Start { agents }, START_WAIT)? {
        RouterReply::Started(v) if v.len() == n => Ok(v),
        other => bail!("unexpected reply from the router to a start of {n} agent(s): {other:?}"),
    }
}

/// Has the router start every agent of `file` not already running, each
/// handed to its supervision first (so that an agent dying right after it
/// starts is restarted), and prints a progress line for each; returns the
/// names of those already running and of those that failed.
fn start_agents(session: &RouterSession, world: &World, file: &LaunchFile) -> Result<(Vec<String>, Vec<String>)> {
    let n = file.agents.len();
    let cwd = std::env::current_dir().ok().map(|d| d.display().to_string());
    let env = environment();
    // from the logs' ends now: a failure shows this start's lines only
    let mut logs: Vec<crate::agent_logs::Tail> =
        file.agents.iter().map(|a| crate::agent_logs::Tail::from_end(world.log_file(&a.name))).collect();
    let specs = file
        .agents
        .iter()
        .map(|spec| proto::StartSpec {
            agent: proto::Supervision {
                name: spec.name.clone(),
                argv: spec.argv(world.robot().as_str()),
                policy: spec.restart,
                max_restarts: spec.max_restarts,
                window_ns: agent_sdk::clock::nanos(spec.restart_window),
                backoff_ns: agent_sdk::clock::nanos(spec.backoff),
                importance: spec.importance,
                cwd: cwd.clone(),
            },
            supervise: true,
            env: Some(env.clone()),
        })
        .collect();
    let outcomes = ask_start(session, specs).context("the router could not start the agents")?;
    let (mut running, mut failed) = (Vec::new(), Vec::new());
    for (i, ((spec, outcome), log)) in file.agents.iter().zip(outcomes).zip(&mut logs).enumerate() {
        match outcome.result {
            proto::StartResult::Running { .. } => {
                eprintln!("  [{}/{n}] {} ({}) already running", i + 1, spec.name, spec.kind);
                running.push(spec.name.clone());
            }
            proto::StartResult::Started { said } => eprintln!(
                "  [{}/{n}] {} ({}) {}",
                i + 1,
                spec.name,
                spec.kind,
                said.trim_start_matches(&format!("{} ", spec.name))
            ),
            proto::StartResult::Failed { status, said } => {
                failed.push(spec.name.clone());
                let log_file = world.log_file(&spec.name).display().to_string();
                let why = said.trim().trim_start_matches("error: ");
                let why = if why.is_empty() {
                    format!("its start-up ended with {status} without a word")
                } else {
                    why.to_owned()
                };
                // the agent's own message may name its log already
                let log_note = if why.contains(&log_file) { String::new() } else { format!(" (log: {log_file})") };
                eprintln!("  [{}/{n}] {} ({}) FAILED: {why}{log_note}", i + 1, spec.name, spec.kind);
                // what the agent wrote before it went: a failure without a
                // message (a panic, a signal) is otherwise read in another window
                let lines = crate::agent_logs::without_backtraces(&log.poll());
                let lines: Vec<&String> = lines.iter().skip_while(|l| l.trim().is_empty()).collect();
                for l in &lines[lines.len().saturating_sub(FAILED_LOG_LINES)..] {
                    eprintln!("        | {l}");
                }
            }
        }
    }
    Ok((running, failed))
}

/// How long one [`CliRequest::WaitRegistered`] may wait: well within the
/// time a command waits for the router ([`crate::client::ROUTER_TIMEOUT`]).
const REGISTER_ASK: Duration = Duration::from_secs(5);

/// Waits until every agent of `file` that was neither `running` before nor
/// reported as `failed` by its start has registered (or is in its
/// supervisor's hands). A failed agent is not waited for: its `start` runs
/// beside its registration, so it may have died before the router could
/// check its pid, and then the router has never heard of it (CI of
/// 2026-11-27 waited 20 s for a SIGSEGV in `start`). The router answers
/// when all have registered ([`CliRequest::WaitRegistered`]), woken by the
/// registrations themselves: nothing is polled, and no agent is asked for
/// its statistics while the others start.
fn wait_registered(session: &RouterSession, file: &LaunchFile, running: &[String], failed: &[String]) -> Result<()> {
    let t0 = Instant::now();
    let mut unheard: Vec<String> =
        file.agents.iter().map(|a| a.name.clone()).filter(|n| !failed.contains(n) && !running.contains(n)).collect();
    while !unheard.is_empty() {
        let left = REGISTER_TIMEOUT.saturating_sub(t0.elapsed());
        if left.is_zero() {
            return Err(anyhow!(
                "not registered after {REGISTER_TIMEOUT:?}: {} (see `nerve logs NAME`)",
                unheard.join(", ")
            ));
        }
        let ask = CliRequest::WaitRegistered {
            names: unheard.clone(),
            timeout_ns: agent_sdk::clock::nanos(left.min(REGISTER_ASK)),
        };
        match session.call(ask)? {
            RouterReply::Waited { missing } => unheard = missing,
            other => bail!("unexpected reply from the router: {other:?}"),
        }
    }
    Ok(())
}

/// What [`up`] achieved.
pub struct BroughtUp {
    /// agents that did not start
    pub failed: usize,
    /// connections that could not be made
    pub wiring_failed: usize,
}

/// Starts the router if needed, has it start the agents not yet running
/// (each handed to its supervision first, so that an agent dying right after
/// it starts is restarted), waits until they have registered, and applies
/// the connections — a progress line for each.
pub fn up(world: &World, file: &LaunchFile) -> Result<BroughtUp> {
    ensure_router(world)?;
    let session = RouterSession::open(world)?;
    let (running, failed) = start_agents(&session, world, file)?;
    wait_registered(&session, file, &running, &failed)?;
    let mut wiring_failed = 0;
    for ((from, to), done) in file.connections.iter().zip(connect_all(world, file)) {
        match done {
            Ok(()) => eprintln!("  connected {from} -> {to}"),
            Err(e) => {
                wiring_failed += 1;
                eprintln!("  could not connect {from} -> {to}: {e:#}");
            }
        }
    }
    Ok(BroughtUp { failed: failed.len(), wiring_failed })
}

/// How many of a launch file's connections are asked for at once.
const CONNECTS_AT_ONCE: usize = 8;

/// Asks the router for every connection of `file`, [`CONNECTS_AT_ONCE`] at a
/// time (as many lanes, each with a session of its own); the outcomes in the
/// file's order.
///
/// Each connect waits for its agent to subscribe (a millisecond or two) and
/// for the connection list to reach the disk, and the router serves many
/// side by side: one after another, the 49 connections of a chain of 50
/// agents took 117 ms of a 524 ms launch (2026-11-27). The router checks for
/// event loops against the connects still in flight too, so that two asked
/// for together cannot close a loop unseen; a fan-in's connects to one agent
/// reach it one at a time, in order (the router's per-agent queue).
fn connect_all(world: &World, file: &LaunchFile) -> Vec<Result<()>> {
    let lanes = CONNECTS_AT_ONCE.min(file.connections.len()).max(1);
    let mut done: Vec<(usize, Result<()>)> = std::thread::scope(|s| {
        // lane k asks for connections k, k + lanes, k + 2 lanes...
        let lanes: Vec<_> = (0..lanes)
            .map(|lane| {
                s.spawn(move || {
                    let session = RouterSession::open(world);
                    let mut done = Vec::new();
                    for (i, (from, to)) in file.connections.iter().enumerate().skip(lane).step_by(lanes) {
                        let allow_cycle = file.allow_cycle.contains(&(from.clone(), to.clone()));
                        let req = CliRequest::Connect { from: from.clone(), to: to.clone(), allow_cycle };
                        let result = match &session {
                            Ok(session) => session.ok(req),
                            Err(e) => Err(anyhow!("{e:#}")),
                        };
                        done.push((i, result));
                    }
                    done
                })
            })
            .collect();
        lanes.into_iter().flat_map(|lane| lane.join().unwrap_or_else(|p| std::panic::resume_unwind(p))).collect()
    });
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, result)| result).collect()
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

/// A handle of process `pid` if it runs a nerve program of this robot. A
/// pid file can outlive its process (a crash), and the pid can be reused
/// meanwhile, by an unrelated program or by another robot's router or agent.
/// So the process must be one of nerve's ([`ProcessHandle::is_nerve`]: its
/// executable is `nerve` or `nerve-*`, or it holds a live iceoryx2 node of
/// this robot; a `tail -f .../logs/t1.log` is neither, whatever its command
/// line says), and work for this robot ([`ProcessHandle::robot`]: its
/// `--robot` argument, else its `NERVE_ROBOT`, else the default robot). The
/// handle is taken first, so every later signal reaches this process only
/// (reliability review R6).
pub(crate) fn belongs_to(pid: u32, world: &World) -> Option<ProcessHandle> {
    let handle = ProcessHandle::take(pid).ok()?;
    let ours = handle.is_nerve(world) && handle.robot().is_some_and(|r| r == world.robot().as_str());
    ours.then_some(handle)
}

/// Waits up to `grace` for `procs` to exit; returns those still running.
/// It sleeps on each process's exit in turn ([`ProcessHandle::wait_exit`],
/// on its pidfd) rather than looking at all of them every few milliseconds:
/// the whole wait is bounded by `grace`, and a robot that stops at once is
/// seen to have stopped at once.
fn wait_gone(procs: &[ProcessHandle], grace: Duration) -> Vec<ProcessHandle> {
    let deadline = Instant::now() + grace;
    for p in procs {
        if !p.wait_exit(deadline.saturating_duration_since(Instant::now())) {
            break;
        }
    }
    procs.iter().filter(|p| p.is_alive()).cloned().collect()
}

fn signal_all(procs: &[ProcessHandle], sig: Signal) {
    for p in procs {
        // Gone: it exited (or its pid was reused) since the last look: nothing to do
        if let Err(e @ ProcessError::Signal { .. }) = p.signal(sig) {
            tracing::warn!(pid = p.pid(), signal = %sig, "{e}");
        }
    }
}

/// What [`down`] did.
#[derive(Debug, Default)]
pub struct Stopped {
    /// the processes it stopped (asked, then signalled if need be)
    pub processes: Vec<ProcessHandle>,
    /// how many of them needed SIGKILL
    pub killed: usize,
}

/// Stops everything of `world`; returns (processes stopped, processes killed).
pub fn down(world: &World, grace: Duration) -> (usize, usize) {
    let s = down_procs(world, grace);
    (s.processes.len(), s.killed)
}

/// Stops everything of `world` as [`down`] does; returns the processes.
pub fn down_procs(world: &World, grace: Duration) -> Stopped {
    let mut procs: Vec<ProcessHandle> = Vec::new();
    // Each handle is taken before the process is asked to stop, while its
    // pid is still its own. 1. every process with a pid file: agents started
    // without a router, and the router
    for (_, pid, _) in pid_files(world) {
        if let Some(h) = belongs_to(pid, world) {
            procs.push(h);
        }
    }
    // 2. ask the router to stop each agent, then itself
    if let Ok(s) = RouterSession::open(world) {
        if let Ok(RouterReply::Agents(agents)) = s.call(CliRequest::Ps) {
            for a in &agents {
                if a.pid > 0
                    && !procs.iter().any(|p| p.pid() == a.pid)
                    && let Some(h) = belongs_to(a.pid, world)
                {
                    procs.push(h);
                }
            }
            for a in &agents {
                let _ = s.call(CliRequest::Stop { name: a.name.clone() });
            }
        }
        let _ = s.call(CliRequest::Shutdown);
    }
    let mut alive = wait_gone(&procs, grace);
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
            eprintln!("warning: process {} survived SIGKILL (uninterruptible sleep?)", p.pid());
        }
    }
    Stopped { processes: procs, killed }
}

/// The robot's nerve processes that [`down`] did not stop and that still
/// run: CLI clients such as `nerve echo` or `nerve hz` in another terminal
/// (the `nerve` executable, working for this robot), never this process.
pub fn other_clients(world: &World, stopped: &[ProcessHandle]) -> Vec<ProcessHandle> {
    let me = std::process::id();
    let Ok(rd) = std::fs::read_dir("/proc") else { return vec![] };
    let mut out: Vec<ProcessHandle> = rd
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| *pid != me && !stopped.iter().any(|p| p.pid() == *pid))
        .filter_map(|pid| ProcessHandle::take(pid).ok())
        .filter(|h| {
            h.exe().is_some_and(|e| {
                e.file_name().and_then(|n| n.to_str()).is_some_and(|n| n == "nerve" || n == "nerve (deleted)")
            }) && h.robot().is_some_and(|r| r == world.robot().as_str())
        })
        .collect();
    out.sort_by_key(ProcessHandle::pid);
    out
}

/// Removes pid files of dead processes, stale iceoryx2 resources and, when
/// no process of the robot is left, its shared-memory files and its
/// simulated clock's page.
pub fn clean(world: &World) -> usize {
    for (_, pid, path) in pid_files(world) {
        // dead, or its pid now names a process that is not nerve's
        if !ProcessHandle::take(pid).is_ok_and(|h| h.is_nerve(world)) {
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
        // the tools' socket of a router that was killed (one that stopped
        // removed its own): nothing listens on it any more
        if std::os::unix::net::UnixStream::connect(world.tool_socket()).is_err() {
            let _ = std::fs::remove_file(world.tool_socket());
        }
        for f in world.shm_files() {
            if std::fs::remove_file(&f).is_ok() {
                removed += 1;
            }
        }
        // the simulated clock's page of a robot on simulated time
        // (`nerve launch --sim-time`): nothing of the robot maps it any more
        let page = world.state_dir().join(agent_sdk::simclock::PAGE_FILE);
        match std::fs::remove_file(&page) {
            Ok(()) => tracing::info!(page = %page.display(), "removed the simulated clock"),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => tracing::warn!(page = %page.display(), "cannot remove the simulated clock: {e}"),
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

#[cfg(test)]
mod tests {
    use super::belongs_to;
    use agent_sdk::World;
    use std::process::{Child, Command};
    use std::time::{Duration, Instant};

    /// Kills and reaps the child when dropped.
    struct Reaped(Child);

    impl Drop for Reaped {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }

    /// Waits until the command line of `pid` contains `needle` (after a shell's exec).
    fn wait_cmdline(pid: u32, needle: &str) {
        let t0 = Instant::now();
        while !std::fs::read(format!("/proc/{pid}/cmdline")).is_ok_and(|c| String::from_utf8_lossy(&c).contains(needle))
        {
            assert!(t0.elapsed() < Duration::from_secs(10), "pid {pid} never showed {needle:?}");
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// `wait_gone` returns as soon as every process has exited, and when
    /// one runs on, it gives up at the grace and names that one only.
    #[test]
    fn wait_gone_returns_at_the_last_exit_or_names_who_runs_on() {
        use agent_sdk::process::ProcessHandle;
        let spawn = |secs: &str| Reaped(Command::new("sleep").arg(secs).spawn().expect("sleep"));
        let handle = |c: &Reaped| ProcessHandle::take(c.0.id()).expect("a handle");

        let quick = [spawn("0.1"), spawn("0.3")];
        let procs: Vec<ProcessHandle> = quick.iter().map(handle).collect();
        let t0 = Instant::now();
        assert!(super::wait_gone(&procs, Duration::from_secs(30)).is_empty(), "both exited");
        assert!(t0.elapsed() < Duration::from_secs(20), "it returned at the exits, not at the grace");

        let (goes, stays) = (spawn("0.1"), spawn("30"));
        let mixed = [handle(&goes), handle(&stays)];
        let t0 = Instant::now();
        let left = super::wait_gone(&mixed, Duration::from_millis(300));
        assert!(t0.elapsed() >= Duration::from_millis(300), "it waited the whole grace");
        assert_eq!(left.iter().map(ProcessHandle::pid).collect::<Vec<_>>(), vec![stays.0.id()]);
    }

    /// A stale pid file whose pid now names a process of the same user
    /// that mentions nerve and the robot (review R6) must not be signalled:
    /// a `tail` of the robot's log, a program that calls itself `nerve-x`.
    #[test]
    fn a_process_that_only_names_nerve_and_the_robot_does_not_belong_to_it() {
        let world = World::new(&format!("own{}", std::process::id())).expect("world");
        let robot = world.robot().to_string();
        let dir = std::env::temp_dir().join(format!("nerve-own-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("logs")).expect("log dir");
        let log = dir.join("logs").join("t1.log");
        std::fs::write(&log, "").expect("log");

        let tail = Reaped(
            Command::new("tail")
                .arg("-f")
                .arg(&log)
                .env(agent_sdk::world::ROBOT_ENV, &robot)
                .spawn()
                .expect("start tail"),
        );
        let named = Reaped(
            std::os::unix::process::CommandExt::arg0(&mut Command::new("sleep"), "nerve-x")
                .arg("30")
                .env(agent_sdk::world::ROBOT_ENV, &robot)
                .spawn()
                .expect("start sleep"),
        );
        wait_cmdline(tail.0.id(), "nerve");
        wait_cmdline(named.0.id(), "nerve-x");
        for p in [&tail, &named] {
            assert!(agent_sdk::process::ProcessHandle::take(p.0.id()).is_ok(), "pid {} runs", p.0.id());
            assert!(belongs_to(p.0.id(), &world).is_none(), "pid {} would be signalled by `nerve down`", p.0.id());
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
