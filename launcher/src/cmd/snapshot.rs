//! `nerve snapshot`: the black box's last seconds, to an MCAP file.
//!
//! A `blackbox` agent (`nerve start blackbox -- --config FILE`) keeps the
//! last seconds of its ports in memory; this command asks it for them (it
//! sets the agent's `snapshot` parameter to the file's absolute path), waits
//! until the file is there (the black box writes it aside and renames it
//! into place when whole) and says what it holds. The same black box also
//! writes snapshots by itself when an agent dies or a watched field
//! changes, into the folder its configuration names.

use crate::client::RouterSession;
use crate::cmd::record::dated_file;
use agent_sdk::World;
use anyhow::{Context as _, Result, bail};
use nerve_recording::read::{Event, RecordingReader};
use shm_schemas::control::cli_to_router::{CliRequest, RouterError};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// `nerve snapshot`
#[derive(Debug, clap::Args)]
pub struct SnapshotArgs {
    /// The MCAP file to write (default: `blackbox-ROBOT-YYYYmmdd-HHMMSS.mcap` here).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// The black box agent to ask.
    #[arg(long, default_value = "blackbox")]
    pub agent: String,
    /// Give up after this many seconds without the file.
    #[arg(long, default_value_t = 60.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub timeout: f64,
}

pub fn snapshot(world: &World, a: SnapshotArgs) -> Result<ExitCode> {
    let path = a.output.clone().unwrap_or_else(|| dated_file("blackbox", world));
    let path = absolute(&path)?;
    if path.extension().is_none_or(|e| e != "mcap") {
        bail!("{}: a snapshot is an MCAP file; give a name ending in .mcap", path.display());
    }
    if path.exists() {
        bail!("{} exists; remove it or give another -o", path.display());
    }
    let session = RouterSession::open(world)?;
    let value = path.to_str().context("the file's path is not UTF-8")?.to_string();
    if let Err(e) = session.ok(CliRequest::ParamSet { name: a.agent.clone(), key: "snapshot".into(), value }) {
        if matches!(e.downcast_ref::<RouterError>(), Some(RouterError::UnknownAgent { .. })) {
            bail!(
                "no black box named {:?} runs on robot {}; start one with `nerve start blackbox --name {} -- --config FILE` (or name it with --agent)",
                a.agent,
                world.robot(),
                a.agent
            );
        }
        return Err(e.context(format!("{} did not take the request", a.agent)));
    }
    let until = Instant::now() + Duration::from_secs_f64(a.timeout);
    while !path.exists() {
        if Instant::now() >= until {
            bail!("{} did not write {} within {} s; see `nerve logs {}`", a.agent, path.display(), a.timeout, a.agent);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let (per_topic, span) = contents(&path)?;
    let total: u64 = per_topic.values().sum();
    println!("snapshot of {}: {total} messages over {:.1} s to {}", a.agent, span, path.display());
    for (topic, n) in &per_topic {
        println!("  {topic:<40} {n:>8} messages");
    }
    Ok(ExitCode::SUCCESS)
}

/// `path` made absolute against the current folder, whose folder must exist.
fn absolute(path: &Path) -> Result<PathBuf> {
    let p = if path.is_absolute() { path.to_path_buf() } else { std::env::current_dir()?.join(path) };
    match p.parent() {
        Some(d) if d.is_dir() => Ok(p),
        _ => bail!("{}: its folder does not exist", p.display()),
    }
}

/// Messages per topic, and the seconds between the first and the last
/// (the file streamed, a message at a time; one cut short is read up to its
/// last whole message, with a warning).
fn contents(path: &Path) -> Result<(BTreeMap<String, u64>, f64)> {
    let mut reader = RecordingReader::open(path)?;
    let mut per_topic = BTreeMap::new();
    let (mut first, mut last) = (u64::MAX, 0u64);
    while let Some(event) = reader.next_event()? {
        if let Event::Message(m) = event {
            *per_topic.entry(m.channel.topic.clone()).or_insert(0) += 1;
            first = first.min(m.log_time);
            last = last.max(m.log_time);
        }
    }
    if let Some(cut) = reader.cut() {
        eprintln!("warning: {cut}");
    }
    Ok((per_topic, last.saturating_sub(first) as f64 / 1e9))
}
