//! `nerve logs NAME [--follow]`: an agent's log, and the tailing used by
//! `nerve launch --foreground` to stream every agent's log.

use crate::cli::LogsArgs;
use agent_sdk::World;
use anyhow::{Result, bail};
use std::io::{Read, Seek, SeekFrom};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Follows a growing file from an offset, line by line.
#[derive(Debug)]
pub struct Tail {
    path: PathBuf,
    offset: u64,
    partial: String,
}

impl Tail {
    /// Starts at `offset` (0: the beginning; `u64::MAX`: the current end).
    pub fn new(path: PathBuf, offset: u64) -> Self {
        let offset = if offset == u64::MAX { std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0) } else { offset };
        Tail { path, offset, partial: String::new() }
    }

    /// The complete lines added since the last call.
    pub fn poll(&mut self) -> Vec<String> {
        let Ok(mut f) = std::fs::File::open(&self.path) else { return vec![] };
        let len = f.metadata().map(|m| m.len()).unwrap_or(0);
        if len < self.offset {
            self.offset = 0; // truncated or replaced: start again
        }
        if len == self.offset || f.seek(SeekFrom::Start(self.offset)).is_err() {
            return vec![];
        }
        let mut buf = String::new();
        let n = f.read_to_string(&mut buf).unwrap_or(0);
        self.offset += n as u64;
        self.partial.push_str(&buf);
        let mut lines: Vec<String> = self.partial.split('\n').map(str::to_owned).collect();
        self.partial = lines.pop().unwrap_or_default();
        lines
    }
}

/// Set by SIGINT/SIGTERM while following.
pub static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Routes SIGINT and SIGTERM to [`INTERRUPTED`].
pub fn catch_interrupts() {
    use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
    let act = SigAction::new(SigHandler::Handler(on_signal), SaFlags::empty(), SigSet::empty());
    for sig in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        let _ = unsafe { sigaction(sig, &act) };
    }
}

pub fn logs(world: &World, a: LogsArgs) -> Result<ExitCode> {
    let path = world.log_file(&a.name);
    if !path.exists() {
        let known: Vec<String> = std::fs::read_dir(world.logs_dir())
            .map(|rd| {
                rd.filter_map(|e| e.ok())
                    .filter_map(|e| e.path().file_stem().map(|s| s.to_string_lossy().into_owned()))
                    .collect()
            })
            .unwrap_or_default();
        bail!(
            "no log for {:?} in {} (logs exist for: {}); agents started with --daemon log there",
            a.name,
            world.logs_dir().display(),
            if known.is_empty() { "none".into() } else { known.join(", ") }
        );
    }
    let text = std::fs::read_to_string(&path)?;
    let lines: Vec<&str> = text.lines().collect();
    let skip = a.lines.map(|n| lines.len().saturating_sub(n)).unwrap_or(0);
    for l in &lines[skip..] {
        println!("{l}");
    }
    if a.follow {
        catch_interrupts();
        let mut tail = Tail::new(path, text.len() as u64);
        while !INTERRUPTED.load(Ordering::SeqCst) {
            for l in tail.poll() {
                println!("{l}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
    Ok(ExitCode::SUCCESS)
}
