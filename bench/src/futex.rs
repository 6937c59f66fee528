//! The wake-up floor: two processes ping-ponging through a futex in shared
//! memory, nothing else. A round trip is two wake-ups of a blocked process
//! and four atomic stores; no payload moves (the sequence number is the
//! message). Whatever a transport adds above this row is its own code; what
//! this row costs is the kernel and the CPU's idle state (issue 17).
//!
//! The pong side (`nerve-bench __futex-pong`) also writes the CPU it ran on
//! into the shared page, so each round trip knows whether the two ends
//! shared a CPU: the *placement* the scheduler chose.
//!
//! The shared page is a file in `/dev/shm` made by the ping side, mapped by
//! both and unlinked as soon as the pong has mapped it: nothing is left
//! behind, even after a crash of either.

use crate::procs::{ChildGuard, exit_status, parse_sub, realtime_like_an_agent, self_command};
use crate::shared_page::{SharedPage, futex_wait, futex_wake};
use agent_sdk::clock::now_ns;
use anyhow::{Context as _, Result, bail};
use clap::Parser;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{ExitCode, Stdio};
use std::sync::atomic::Ordering;
use std::time::Duration;

/// How long either side waits for the other before it gives up.
const PATIENCE: Duration = Duration::from_secs(2);

/// The page's words, each on a cache line of its own (16 words apart).
/// The ping's sequence number:
const PING: usize = 0;
/// The pong's answer (the same number):
const PONG: usize = 16;
/// The CPU the pong ran on when it answered:
const PONG_CPU: usize = 32;
/// 1: the pong stops.
const STOP: usize = 48;
/// The bytes mapped (and the file's length).
const PAGE: usize = 4096;

/// The CPU the calling thread runs on.
fn this_cpu() -> u32 {
    // SAFETY: sched_getcpu takes no arguments.
    let c = unsafe { libc::sched_getcpu() };
    u32::try_from(c).unwrap_or(u32::MAX)
}

/// The ping side: the shared page, and the placement of the last batch.
pub struct FutexPing {
    page: SharedPage,
    seq: u32,
    /// round trips of the last batch whose pong ran on the ping's CPU
    pub same_cpu: usize,
}

impl std::fmt::Debug for FutexPing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FutexPing").field("seq", &self.seq).finish()
    }
}

impl FutexPing {
    /// Makes the shared page at `path` (which must not exist) for a pong to map.
    pub fn create(path: &Path) -> Result<Self> {
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        f.set_len(PAGE as u64).with_context(|| format!("cannot size {}", path.display()))?;
        Ok(FutexPing { page: SharedPage::map(path, PAGE)?, seq: 0, same_cpu: 0 })
    }

    /// Makes a page and starts a pong (`__futex-pong`) on it; `tag` tells
    /// the pages of one run apart. The page's file is gone once this returns.
    /// With `cpu`, the pong is kept on that CPU.
    pub fn with_pong(tag: &str, cpu: Option<usize>, verbose: bool) -> Result<(ChildGuard, Self)> {
        let path = PathBuf::from(format!("/dev/shm/nerve-bench-futex-{}-{tag}", std::process::id()));
        let ping = FutexPing::create(&path)?;
        let mut cmd = self_command("__futex-pong")?;
        cmd.arg("--path").arg(&path).stdout(Stdio::piped());
        if let Some(c) = cpu {
            cmd.args(["--cpu", &c.to_string()]);
        }
        if !verbose {
            cmd.stderr(Stdio::null());
        }
        let spawned = ChildGuard::spawn(&format!("futex pong {tag}"), cmd);
        let ready = spawned.and_then(|mut c| c.await_ready("futex pong").map(|()| c));
        // the pong unlinks it once mapped; this covers a pong that never got there
        let _ = std::fs::remove_file(&path);
        Ok((ready?, ping))
    }

    /// One batch of `count` round trips; returns their times in ns.
    pub fn ping_batch(&mut self, count: usize) -> Result<Vec<u64>> {
        let (ping, pong, pong_cpu) = (self.page.word(PING), self.page.word(PONG), self.page.word(PONG_CPU));
        let mut rtts = Vec::with_capacity(count);
        self.same_cpu = 0;
        for _ in 0..count {
            self.seq = self.seq.wrapping_add(1).max(1);
            let seq = self.seq;
            let t0 = now_ns();
            let cpu = this_cpu();
            ping.store(seq, Ordering::Release);
            futex_wake(ping, 1);
            let deadline = t0 + PATIENCE.as_nanos() as u64;
            loop {
                let v = pong.load(Ordering::Acquire);
                if v == seq {
                    break;
                }
                if now_ns() > deadline {
                    bail!("the futex pong did not answer {seq} within {PATIENCE:?}");
                }
                futex_wait(pong, v, PATIENCE);
            }
            rtts.push(now_ns().saturating_sub(t0));
            if pong_cpu.load(Ordering::Relaxed) == cpu {
                self.same_cpu += 1;
            }
        }
        Ok(rtts)
    }
}

impl Drop for FutexPing {
    fn drop(&mut self) {
        self.page.word(STOP).store(1, Ordering::Release);
        self.page.word(PING).fetch_add(1, Ordering::Release);
        futex_wake(self.page.word(PING), 1);
    }
}

/// Arguments of `nerve-bench __futex-pong`.
#[derive(Debug, Parser)]
#[command(name = "nerve-bench __futex-pong")]
struct PongArgs {
    /// the shared page the ping made
    #[arg(long)]
    path: PathBuf,
    /// keep the pong on this CPU
    #[arg(long)]
    cpu: Option<usize>,
}

/// Entry of `nerve-bench __futex-pong`: maps the page, unlinks it, prints
/// `ready`, answers until told to stop (or the ping is silent for long).
pub fn pong_main(args: Vec<String>) -> ExitCode {
    match parse_sub::<PongArgs>("__futex-pong", args) {
        Ok(a) => exit_status("futex pong", pong(&a)),
        Err(code) => code,
    }
}

fn pong(a: &PongArgs) -> Result<()> {
    if let Some(c) = a.cpu {
        agent_sdk::rt::set_affinity(&agent_sdk::rt::CpuList(vec![c])).map_err(anyhow::Error::msg)?;
    }
    realtime_like_an_agent(20);
    let page = SharedPage::map(&a.path, PAGE)?;
    std::fs::remove_file(&a.path).with_context(|| format!("cannot remove {}", a.path.display()))?;
    println!("ready");
    std::io::stdout().flush().context("stdout")?;
    let (ping, pong, pong_cpu, stop) = (page.word(PING), page.word(PONG), page.word(PONG_CPU), page.word(STOP));
    let mut last = ping.load(Ordering::Acquire);
    // the ping's batches come seconds apart; five silent minutes mean it is gone
    let mut idle = 0u32;
    loop {
        if stop.load(Ordering::Acquire) == 1 {
            return Ok(());
        }
        let v = ping.load(Ordering::Acquire);
        if v != last {
            last = v;
            idle = 0;
            pong_cpu.store(this_cpu(), Ordering::Relaxed);
            pong.store(v, Ordering::Release);
            futex_wake(pong, 1);
            continue;
        }
        idle += 1;
        if idle > 150 {
            bail!("the ping side has been silent for five minutes");
        }
        futex_wait(ping, v, PATIENCE);
    }
}
