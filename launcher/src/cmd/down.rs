//! `nerve down`: stop every agent of the robot and its router with a
//! grace → SIGTERM → SIGKILL ladder, then remove what they left: pid files,
//! stale iceoryx2 resources, and this robot's files in `/dev/shm`; and drop
//! its persisted connection list unless `--keep-connections` (the output
//! says which). A router that crashes or is restarted keeps the list: only
//! a deliberate `nerve down` forgets it. The ladder and the cleaning are
//! [`crate::bring::down`] and [`crate::bring::clean`], shared with every
//! command that brings a robot down.

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
    let (stopped, killed) = bring::down(world, grace);
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
    Ok(ExitCode::SUCCESS)
}
