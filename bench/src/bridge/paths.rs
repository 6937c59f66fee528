//! The paths the bridge scenario drives batch by batch: an SDK sender in
//! robot A and its sink in robot B ([`SdkPath`]), and the raw Zenoh
//! publisher and subscriber processes ([`RawPath`], children spoken to by
//! lines, [`LineChild`]); what a batch gives ([`Batch`]) and its rates.

use crate::agents::read_values;
use crate::bridge_agents::{SETTLE, read_rows, take_sink_batch};
use crate::procs::{ChildGuard, Robot, self_command, wait_file_after};
use anyhow::{Context as _, Result, anyhow, bail};
use std::io::{BufRead as _, Write as _};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::mpsc;
use std::time::Duration;

/// A child driven by lines on stdin, answering lines on stdout.
pub(super) struct LineChild {
    what: String,
    guard: ChildGuard,
    stdin: std::process::ChildStdin,
    lines: mpsc::Receiver<String>,
}

impl LineChild {
    pub(super) fn spawn(what: &str, mut cmd: std::process::Command, verbose: bool) -> Result<Self> {
        cmd.stdin(Stdio::piped()).stdout(Stdio::piped());
        if !verbose {
            cmd.stderr(Stdio::null());
        }
        let mut guard = ChildGuard::spawn(what, cmd)?;
        let stdin = guard.stdin().ok_or_else(|| anyhow!("{what}: no stdin"))?;
        let stdout = guard.stdout().ok_or_else(|| anyhow!("{what}: no stdout"))?;
        let (tx, lines) = mpsc::channel();
        std::thread::Builder::new()
            .name("bench-child-out".into())
            .spawn(move || {
                for l in std::io::BufReader::new(stdout).lines() {
                    let Ok(l) = l else { break };
                    if tx.send(l).is_err() {
                        break;
                    }
                }
            })
            .context("cannot start a reader thread")?;
        let mut c = LineChild { what: what.into(), guard, stdin, lines };
        let first = c.read(Duration::from_secs(30))?;
        if first.trim() != "ready" {
            bail!("{what} did not become ready (said {first:?})");
        }
        Ok(c)
    }

    fn read(&mut self, timeout: Duration) -> Result<String> {
        match self.lines.recv_timeout(timeout) {
            Ok(l) => Ok(l),
            Err(mpsc::RecvTimeoutError::Timeout) => bail!("{} gave no answer within {timeout:?}", self.what),
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                self.guard.check_alive()?;
                bail!("{} closed its output; run with --verbose to see its log", self.what)
            }
        }
    }

    pub(super) fn ask(&mut self, line: &str, timeout: Duration) -> Result<String> {
        writeln!(self.stdin, "{line}")
            .and_then(|()| self.stdin.flush())
            .with_context(|| format!("{}: stdin", self.what))?;
        self.read(timeout)
    }
}

/// What one batch across a path gave.
#[derive(Debug, Default)]
pub(super) struct Batch {
    pub(super) sent: u64,
    pub(super) t_start: u64,
    pub(super) t_end: u64,
    /// (sender's stamp, last hop's stamp or 0, arrival), in arrival order
    pub(super) rows: Vec<[u64; 3]>,
}

/// One SDK path across the bridge: a sender in robot A, a sink in robot B.
pub(super) struct SdkPath {
    pub(super) src: String,
    pub(super) sink: String,
    pub(super) src_dir: PathBuf,
    pub(super) sink_dir: PathBuf,
    pub(super) src_next: u64,
    pub(super) sink_next: u64,
}

impl SdkPath {
    pub(super) fn batch(&mut self, a: &Robot, b: &Robot, expected: Duration) -> Result<Batch> {
        self.src_next += 1;
        self.sink_next += 1;
        a.run(&["suspend", &self.src])?;
        a.run(&["resume", &self.src])?;
        let sent_path = self.src_dir.join(format!("sent-{}.txt", self.src_next));
        if !wait_file_after(&sent_path, expected, expected + Duration::from_secs(20), &mut [])? {
            bail!("the sender {} wrote no batch {} ({})", self.src, self.src_next, sent_path.display());
        }
        let v = read_values(&sent_path)?;
        let _ = std::fs::remove_file(&sent_path);
        let [sent, t_start, t_end] = v[..] else { bail!("{}: expected 3 values", sent_path.display()) };
        let path = self.sink_dir.join(format!("batch-{}.txt", self.sink_next));
        let rows = take_sink_batch(b, &self.sink, &path)?;
        Ok(Batch { sent, t_start, t_end, rows })
    }
}

/// The raw Zenoh path: a publisher and a subscriber process.
pub(super) struct RawPath {
    pub(super) publisher: LineChild,
    pub(super) subscriber: LineChild,
    pub(super) dir: PathBuf,
    pub(super) next: u64,
}

impl RawPath {
    pub(super) fn batch(
        &mut self,
        size: usize,
        count: usize,
        interval_us: u64,
        max_ms: u64,
        expected: Duration,
    ) -> Result<Batch> {
        let ans = self
            .publisher
            .ask(&format!("send {size} {count} {interval_us} {max_ms}"), expected + Duration::from_secs(20))?;
        let w: Vec<u64> = ans.split_whitespace().skip(1).filter_map(|x| x.parse().ok()).collect();
        let [sent, t_start, t_end] = w[..] else { bail!("raw zenoh pub said {ans:?}") };
        self.next += 1;
        let path = self.dir.join(format!("raw-{size}-{}.txt", self.next));
        let ans = self
            .subscriber
            .ask(&format!("take {size} {sent} {} {}", SETTLE.as_millis(), path.display()), Duration::from_secs(30))?;
        if !ans.starts_with("ok") {
            bail!("raw zenoh sub said {ans:?}");
        }
        let rows = read_rows(&path)?;
        let _ = std::fs::remove_file(&path);
        Ok(Batch { sent, t_start, t_end, rows })
    }
}

/// Throughput of one batch: (delivered/s, offered/s). Delivered is counted
/// over the whole batch, from its first send to its last send or its last
/// arrival, whichever is later (a path that delivers a few samples early and
/// then nothing does not look fast).
pub(super) fn rates(b: &Batch) -> (f64, f64) {
    let last = b.rows.iter().map(|r| r[2]).max().unwrap_or(b.t_end).max(b.t_end);
    let span = last.saturating_sub(b.t_start).max(1) as f64 / 1e9;
    let sent_span = b.t_end.saturating_sub(b.t_start).max(1) as f64 / 1e9;
    (b.rows.len() as f64 / span, b.sent as f64 / sent_span)
}

/// The one-way latencies (arrival - sender's stamp) of a batch's rows.
pub(super) fn one_way(rows: &[[u64; 3]]) -> Vec<u64> {
    rows.iter().map(|r| r[2].saturating_sub(r[0])).collect()
}

/// Starts the agent `name` of robot `robot`: this executable's hidden
/// subcommand `sub` with the agent's `common` options and the scenario's
/// `args`, writing its batches to `dir`.
pub(super) fn spawn_agent(
    robot: &Robot,
    sub: &str,
    name: &str,
    common: &[&str],
    args: &[String],
    dir: &Path,
) -> Result<ChildGuard> {
    let mut cmd = self_command(sub)?;
    cmd.args(["--robot", &robot.name, "--name", name]).args(common).arg("--").args(args).arg("--out").arg(dir);
    cmd.env("NERVE_HOME", &robot.home);
    robot.quiet(&mut cmd);
    Ok(ChildGuard::spawn(&format!("agent {name}"), cmd)?)
}
