//! `nerve down`: stop every agent of the robot and its router with a
//! grace → SIGTERM → SIGKILL ladder, then remove what they left: pid files,
//! stale iceoryx2 resources, and this robot's files in `/dev/shm`; and drop
//! its persisted connection list unless `--keep-connections` (the output
//! says which). A router that crashes or is restarted keeps the list: only
//! a deliberate `nerve down` forgets it.

use crate::client::RouterSession;
use agent_sdk::World;
use agent_sdk::world::pid_alive;
use anyhow::Result;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// `nerve down`
#[derive(Debug, clap::Args)]
pub struct DownArgs {
    /// Seconds to wait for a clean stop before SIGTERM, and again before SIGKILL.
    #[arg(long, default_value_t = 3.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub grace: f64,
    /// Keep the robot's connection list for its next start (by default a
    /// robot brought down starts unwired next time: its launch file or
    /// `nerve connect` wires it again).
    #[arg(long)]
    pub keep_connections: bool,
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
pub fn bring_down(world: &World, grace: Duration) -> (usize, usize) {
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

/// The number of connections in a persisted connection list (0 when there is none).
fn count_connections(path: &std::path::Path) -> usize {
    std::fs::read(path)
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| v.get("connections").and_then(|c| c.as_array()).map(Vec::len))
        .unwrap_or(0)
}

/// Drops the robot's persisted connection list (and its backup), or keeps
/// it; says which (reliability review F3d': connections used to survive
/// `nerve down` silently and wire the next, unrelated launch).
fn connections_after_down(world: &World, keep: bool) -> String {
    let list = world.state_dir().join("connections.json");
    let n = count_connections(&list);
    if keep {
        return format!("; kept its {n} connection(s) for the next start");
    }
    let mut dropped = false;
    for f in [list.clone(), list.with_extension("json.bak")] {
        dropped |= std::fs::remove_file(&f).is_ok();
    }
    if dropped && n > 0 {
        format!("; dropped its {n} connection(s): the next start begins unwired (--keep-connections keeps them)")
    } else {
        String::new()
    }
}

pub fn down(world: &World, a: DownArgs) -> Result<ExitCode> {
    let grace = Duration::from_secs_f64(a.grace.max(0.0));
    let (stopped, killed) = bring_down(world, grace);
    let removed = clean(world);
    let connections = connections_after_down(world, a.keep_connections);
    println!(
        "robot {}: stopped {stopped} process(es){}{}{connections}",
        world.robot(),
        if killed > 0 { format!(", {killed} of them with SIGKILL") } else { String::new() },
        if removed > 0 {
            format!("; removed {removed} stale shared-memory and iceoryx2 file(s)")
        } else {
            String::new()
        }
    );
    Ok(ExitCode::SUCCESS)
}
