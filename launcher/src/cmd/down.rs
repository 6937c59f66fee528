//! `nerve down`: stop every agent of the robot and its router with a
//! grace → SIGTERM → SIGKILL ladder, then remove what they left: pid files,
//! stale iceoryx2 resources, and this robot's files in `/dev/shm`; and drop
//! its persisted connection list unless `--keep-connections` (the output
//! says which). A router that crashes or is restarted keeps the list: only
//! a deliberate `nerve down` forgets it. The ladder and the cleaning are
//! [`crate::bring::down`] and [`crate::bring::clean`], shared with every
//! command that brings a robot down.
//!
//! CLI clients of the robot (`nerve echo`, `nerve hz`... in other
//! terminals) are not stopped: as `ros2 topic echo` outlives the nodes it
//! listens to, they are the user's tools, and may wait for the robot to come
//! back. But they hold shared memory, so `nerve down` names them, with
//! their pids and what they keep (reliability review F1d: three `nerve
//! echo` kept 43 files, silently).

use crate::bring;
use agent_sdk::World;
use anyhow::Result;
use std::process::ExitCode;
use std::time::Duration;

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

/// The number of connections in a persisted connection list (0 when there
/// is none): its journal's last record, which a router killed before it
/// rewrote the file leaves newer than the file, else the file.
fn count_connections(path: &std::path::Path) -> usize {
    let journal = nerve_router::journal::read(&nerve_router::journal::path_for(path)).ok().and_then(|c| c.last);
    journal
        .or_else(|| std::fs::read(path).ok())
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
    for f in [list.clone(), list.with_extension("json.bak"), nerve_router::journal::path_for(&list)] {
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
    let bring::Stopped { processes, killed } = bring::down_procs(world, grace);
    let stopped = processes.len();
    let removed = bring::clean(world);
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
    let logs = world.logs_dir();
    if std::fs::read_dir(&logs).is_ok_and(|mut d| d.next().is_some()) {
        // "leave nothing behind" is about processes and shared memory: the
        // logs stay for `nerve logs` after the fact, and say so
        println!("  its logs stay in {} (`nerve logs NAME`); remove the folder to drop them", logs.display());
    }
    if let Some(note) = clients_note(world, &processes) {
        eprintln!("{note}");
    }
    Ok(ExitCode::SUCCESS)
}

/// The line naming the robot's CLI clients that still run, if any.
fn clients_note(world: &World, stopped: &[agent_sdk::process::ProcessHandle]) -> Option<String> {
    let clients = bring::other_clients(world, stopped);
    if clients.is_empty() {
        return None;
    }
    let pids: Vec<String> = clients.iter().map(|c| c.pid().to_string()).collect();
    let files = world.shm_files().len() + world.iox2_files().len();
    Some(format!(
        "note: {} nerve client(s) of robot {} still run (pids {}): they keep {files} shared-memory and iceoryx2 file(s) until they exit; stop them (Ctrl-C, or `kill {}`), then `nerve down` again removes the files",
        clients.len(),
        world.robot(),
        pids.join(", "),
        pids.join(" ")
    ))
}
