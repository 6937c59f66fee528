//! dora-rs as a peer of the hop benchmark: two Rust nodes on dora's node
//! API (`dora-node-api` 1.1.0, crate `bench/dora`), run by dora's own CLI
//! (`dora-cli` 1.1.0) with `dora run`, dora's way to run a dataflow on one
//! machine (its daemon in the CLI's process, no coordinator).
//!
//! Both are built once by `scripts/setup.sh --bench` into a cache outside
//! the repository, [`cache_dir`]:
//! `${NERVE_BENCH_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/nerve-bench}/dora`,
//! holding `bin/dora` and `target/release/nerve-dora-{ping,pong}`. Without
//! them the hop scenario says so in one line and runs without dora's rows.
//!
//! Each batch is one `dora run` of a dataflow written here (no `build:` key,
//! which would make dora rebuild the nodes; `path:` names the cached
//! binaries): `nerve-dora-ping` sends a payload of the batch's size on `out`,
//! `nerve-dora-pong` answers on its `out`, wired `ping/out -> pong/in` and
//! `pong/out -> ping/echo`. Two patterns ([`Pattern`]):
//!
//! * `dora`: ping-pong, the next sample as soon as the echo is back; ping
//!   writes round trips, like every other row of the hop table;
//! * `dora-5ms`: dora's own pattern (its `examples/benchmark`: one sample
//!   every 5 ms, latency taken at the receiver): ping stamps each sample
//!   with CLOCK_MONOTONIC, pong takes the one-way latency when the input
//!   reaches its event loop and sends it back in a 16-byte reply; ping writes
//!   the one-way latencies.
//!
//! A batch may keep both nodes on one CPU (`taskset -c CPU` starts each
//! node, so that `dora run` and its daemon stay free, as nerve's router does
//! beside its pinned agents): the rows `dora-5ms-pinned`, beside nerve's
//! `nerve-5ms-pinned`.
//!
//! The ping drops its first samples (a fresh dataflow: dora's shared-memory
//! pool, the Arrow schema, the first wake-ups) before the hop scenario drops
//! its own first few of every batch. Both nodes run under SCHED_FIFO priority
//! 20 from their first instruction (every thread dora and zenoh start
//! inherits it), as ddsperf does. Every `dora run` is bounded twice:
//! `--stop-after` (dora stops the dataflow itself), and a wall-clock limit
//! after which the CLI gets SIGINT, then SIGKILL; the nodes write their pids
//! and any still alive after the run is killed (dora's nodes lead process
//! groups of their own, so they are not reached through the CLI's). zenoh's
//! 12 KB shared-memory file that each run leaves in /dev/shm is removed once
//! no process uses it.

use crate::agents::read_values;
use crate::procs::spawn_dying_with_us;
use agent_sdk::process::ProcessHandle;
use anyhow::{Context as _, Result, bail};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The version of dora the benchmark is built against (CLI and node API).
pub const VERSION: &str = "1.1.0";
/// SCHED_FIFO priority of the nodes (the other peers' too).
const FIFO_PRIORITY: u32 = 20;
/// Period of dora's own pattern, µs.
pub const PERIOD_US: u64 = 5000;
/// Samples the ping sends first and drops, by pattern.
const WARMUP_PINGPONG: usize = 20;
const WARMUP_PERIODIC: usize = 10;

/// How the ping paces its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pattern {
    /// nerve's hop: the next sample when the echo is back; round trips.
    PingPong,
    /// dora's benchmark: one sample every [`PERIOD_US`]; one-way latencies.
    Periodic,
}

impl Pattern {
    fn env(self) -> &'static str {
        match self {
            Pattern::PingPong => "pingpong",
            Pattern::Periodic => "periodic",
        }
    }

    /// The row's name in the report.
    pub fn transport(self) -> &'static str {
        match self {
            Pattern::PingPong => "dora",
            Pattern::Periodic => "dora-5ms",
        }
    }
}

/// Where `scripts/setup.sh --bench` builds dora:
/// `${NERVE_BENCH_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/nerve-bench}/dora`
/// (an empty variable counts as unset, as in the shell).
pub fn cache_dir() -> Option<PathBuf> {
    let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
    let base = var("NERVE_BENCH_CACHE")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("nerve-bench")))
        .or_else(|| var("HOME").map(|h| h.join(".cache").join("nerve-bench")))?;
    Some(base.join("dora"))
}

/// The cached dora CLI and nodes, running one dataflow per batch.
#[derive(Debug)]
pub struct DoraPeer {
    dora: PathBuf,
    ping: PathBuf,
    pong: PathBuf,
    /// what `dora --version` says
    pub version: String,
    /// the cache it came from
    pub cache: PathBuf,
    /// `taskset` (util-linux), which keeps a node on one CPU; None: not found
    taskset: Option<PathBuf>,
    work: PathBuf,
    verbose: bool,
    next: Cell<u64>,
}

impl DoraPeer {
    /// Finds the cached CLI and nodes; `Err` says what is missing (the
    /// caller prints it as a warning and goes on without dora).
    pub fn find(work: &Path, verbose: bool) -> Result<Self> {
        let dir = cache_dir().context("neither NERVE_BENCH_CACHE, XDG_CACHE_HOME nor HOME is set")?;
        let dora = dir.join("bin/dora");
        let ping = dir.join("target/release/nerve-dora-ping");
        let pong = dir.join("target/release/nerve-dora-pong");
        for p in [&dora, &ping, &pong] {
            if !p.is_file() {
                bail!("no {}", p.display());
            }
        }
        let out = run_bounded(Command::new(&dora).arg("--version"), Duration::from_secs(10))
            .with_context(|| format!("cannot run {} --version", dora.display()))?;
        let version = out.trim().to_owned();
        if !version.contains(VERSION) {
            bail!("{} is {version:?}, not {VERSION}", dora.display());
        }
        // absolute: `dora run` runs in each batch's folder, and reads the
        // dataflow's paths (and the nodes their output files) from there; a
        // relative `--out` (the default, bench-results) named files it could not find
        let work = std::path::absolute(work.join("dora")).context("cannot make the work folder's path absolute")?;
        std::fs::create_dir_all(&work).with_context(|| format!("cannot create {}", work.display()))?;
        let taskset = on_path("taskset");
        Ok(DoraPeer { dora, ping, pong, version, cache: dir, taskset, work, verbose, next: Cell::new(0) })
    }

    /// Whether batches can keep both nodes on one CPU (`taskset` was found).
    pub fn can_pin(&self) -> bool {
        self.taskset.is_some()
    }

    /// One `dora run` of `count` kept samples of `size` bytes in `pattern`,
    /// both nodes kept on CPU `cpu` if given; returns them, ns (round trips
    /// or one-way latencies, see [`Pattern`]).
    pub fn batch(&self, size: usize, pattern: Pattern, count: usize, cpu: Option<usize>) -> Result<Vec<u64>> {
        self.next.set(self.next.get() + 1);
        let dir = self.work.join(format!("run-{}", self.next.get()));
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let r = self.run_in(&dir, size, pattern, count, cpu);
        if r.is_ok() || !self.verbose {
            let _ = std::fs::remove_dir_all(&dir);
        }
        r
    }

    fn run_in(&self, dir: &Path, size: usize, pattern: Pattern, count: usize, cpu: Option<usize>) -> Result<Vec<u64>> {
        let warmup = match pattern {
            Pattern::PingPong => WARMUP_PINGPONG,
            Pattern::Periodic => WARMUP_PERIODIC,
        };
        let out = dir.join("samples.txt");
        let yml = dir.join("dataflow.yml");
        let pin = match cpu {
            Some(c) => Some((self.taskset.as_deref().context("no `taskset` to keep the dora nodes on one CPU")?, c)),
            None => None,
        };
        let text = dataflow(&self.ping, &self.pong, pin, dir, &out, size, pattern, count, warmup)?;
        std::fs::write(&yml, text).with_context(|| format!("cannot write {}", yml.display()))?;

        // generous bounds: dora's slowest round trip here is milliseconds
        let per_sample_ms = match pattern {
            Pattern::PingPong if size > 1_000_000 => 50,
            Pattern::PingPong => 5,
            Pattern::Periodic => 3 * PERIOD_US / 1000,
        };
        let stop_after = 15 + (count + warmup) as u64 * per_sample_ms / 1000;
        let log = dir.join("dora.log");
        let log_file = std::fs::File::create(&log).with_context(|| format!("cannot create {}", log.display()))?;
        let mut cmd = Command::new(&self.dora);
        cmd.arg("run").arg(&yml).args(["--stop-after", &format!("{stop_after}s")]);
        cmd.current_dir(dir).stdin(Stdio::null());
        cmd.stdout(log_file.try_clone().context("cannot share the log file")?).stderr(log_file);
        let mut run = DoraRun::spawn(cmd, dir)?;
        run.zenoh_before = zenoh_segments();
        let status = run.wait(Duration::from_secs(stop_after + 20))?;
        let tail = || log_tail(&log, 15);
        let Some(status) = status else {
            bail!("`dora run` did not end within {} s; its log ends with:\n{}", stop_after + 20, tail());
        };
        if !out.is_file() {
            bail!("`dora run` ended ({status}) without the ping's samples; its log ends with:\n{}", tail());
        }
        if !status.success() && self.verbose {
            eprintln!("  dora: `dora run` exited with {status} after the ping wrote its samples");
        }
        let v = read_values(&out)?;
        if v.len() != count {
            bail!("the dora ping wrote {} samples, not {count}", v.len());
        }
        Ok(v)
    }
}

/// A running `dora run`: stopped when dropped (SIGINT, as Ctrl-C, then
/// SIGKILL), and so are the nodes it leaves behind.
struct DoraRun {
    child: Child,
    pid_dir: PathBuf,
    reaped: bool,
    /// zenoh's shared-memory files before the run
    zenoh_before: Vec<PathBuf>,
}

impl DoraRun {
    fn spawn(mut cmd: Command, pid_dir: &Path) -> Result<Self> {
        let child = spawn_dying_with_us(&mut cmd).with_context(|| format!("cannot start {cmd:?}"))?;
        Ok(DoraRun { child, pid_dir: pid_dir.to_owned(), reaped: false, zenoh_before: Vec::new() })
    }

    /// Waits up to `timeout` for the exit; `None` when it did not come.
    fn wait(&mut self, timeout: Duration) -> Result<Option<std::process::ExitStatus>> {
        // asleep until it ends: a poll every few ms would run beside the
        // batch, at this process's real-time priority (not taken: it has
        // exited already)
        if let Ok(run) = ProcessHandle::take(self.child.id()) {
            run.wait_exit(timeout);
        }
        let status = self.child.try_wait().context("cannot wait for `dora run`")?;
        self.reaped = status.is_some();
        Ok(status)
    }
}

impl Drop for DoraRun {
    fn drop(&mut self) {
        if !self.reaped {
            let _ = kill(Pid::from_raw(self.child.id() as i32), Signal::SIGINT);
            if !matches!(self.wait(Duration::from_secs(5)), Ok(Some(_))) {
                let _ = self.child.kill();
                let _ = self.child.wait();
            }
        }
        // nodes that outlived their `dora run` (they lead process groups of their own)
        for node in ["ping", "pong"] {
            let Ok(s) = std::fs::read_to_string(self.pid_dir.join(format!("{node}.pid"))) else { continue };
            let Ok(pid) = s.trim().parse::<i32>() else { continue };
            let exe = std::fs::read_link(format!("/proc/{pid}/exe")).unwrap_or_default();
            // (a binary rebuilt while the node ran reads `... (deleted)`)
            let name = exe.file_name().map(|n| n.to_string_lossy().trim_end_matches(" (deleted)").to_owned());
            if name.is_some_and(|n| n == format!("nerve-dora-{node}")) {
                eprintln!("  dora: the {node} node (pid {pid}) outlived `dora run`; killing it");
                let _ = kill(Pid::from_raw(pid), Signal::SIGKILL);
            }
        }
        // zenoh (dora's data plane) leaves a 12 KB `/dev/shm/<n>.zenoh` behind per
        // run, which the next zenoh process would collect: remove the run's own,
        // those that appeared during it and that no process maps or holds open
        let new: Vec<PathBuf> = zenoh_segments().into_iter().filter(|p| !self.zenoh_before.contains(p)).collect();
        if !new.is_empty() {
            let used = files_in_use();
            for p in new {
                if !used.contains(&p) {
                    let _ = std::fs::remove_file(&p);
                }
            }
        }
    }
}

/// zenoh's shared-memory files (`/dev/shm/<n>.zenoh`).
fn zenoh_segments() -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir("/dev/shm") else { return Vec::new() };
    rd.filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "zenoh") && p.is_file())
        .collect()
}

/// Files of /dev/shm that some process maps or holds open (what this user may see of /proc).
fn files_in_use() -> std::collections::HashSet<PathBuf> {
    let mut used = std::collections::HashSet::new();
    let Ok(procs) = std::fs::read_dir("/proc") else { return used };
    for p in procs.filter_map(|e| e.ok()) {
        if !p.file_name().to_string_lossy().bytes().all(|b| b.is_ascii_digit()) {
            continue;
        }
        if let Ok(maps) = std::fs::read_to_string(p.path().join("maps")) {
            for l in maps.lines().filter(|l| l.contains("/dev/shm/")) {
                if let Some(i) = l.find("/dev/shm/") {
                    used.insert(PathBuf::from(l[i..].trim_end_matches(" (deleted)")));
                }
            }
        }
        if let Ok(fds) = std::fs::read_dir(p.path().join("fd")) {
            for fd in fds.filter_map(|e| e.ok()) {
                if let Ok(t) = std::fs::read_link(fd.path())
                    && t.starts_with("/dev/shm/")
                {
                    used.insert(t);
                }
            }
        }
    }
    used
}

/// Runs `cmd` to its end within `timeout`; returns its stdout.
fn run_bounded(cmd: &mut Command, timeout: Duration) -> Result<String> {
    cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::null());
    let mut child = cmd.spawn().context("cannot start it")?;
    let t0 = Instant::now();
    loop {
        if child.try_wait().context("cannot wait for it")?.is_some() {
            let out = child.wait_with_output().context("cannot read its output")?;
            return Ok(String::from_utf8_lossy(&out.stdout).into_owned());
        }
        if t0.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            bail!("no answer within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The last `n` lines of a log, indented.
fn log_tail(path: &Path, n: usize) -> String {
    let s = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = s.lines().collect();
    lines[lines.len().saturating_sub(n)..].iter().map(|l| format!("    {l}")).collect::<Vec<_>>().join("\n")
}

/// A YAML double-quoted scalar (a JSON string is one).
fn quoted(s: &str) -> String {
    serde_json::Value::String(s.to_owned()).to_string()
}

/// `name` in a folder of `PATH`, if there.
fn on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).map(|d| d.join(name)).find(|p| p.is_file())
}

/// The dataflow of one batch; with `pin` (`taskset`, CPU), each node is
/// started by `taskset -c CPU`, which keeps it on that CPU and execs it.
#[allow(clippy::too_many_arguments)]
fn dataflow(
    ping: &Path,
    pong: &Path,
    pin: Option<(&Path, usize)>,
    pid_dir: &Path,
    out: &Path,
    size: usize,
    pattern: Pattern,
    count: usize,
    warmup: usize,
) -> Result<String> {
    let s = |p: &Path| -> Result<String> {
        p.to_str().map(quoted).with_context(|| format!("{} is not UTF-8", p.display()))
    };
    // `path:` and, when pinned, `args:` (dora splits them at white space)
    let start = |exe: &Path| -> Result<String> {
        let Some((taskset, cpu)) = pin else { return s(exe) };
        let e = exe.to_str().with_context(|| format!("{} is not UTF-8", exe.display()))?;
        if e.contains(char::is_whitespace) {
            bail!("cannot pin the dora node {e}: dora splits a node's arguments at white space");
        }
        Ok(format!("{}\n    args: {}", s(taskset)?, quoted(&format!("-c {cpu} {e}"))))
    };
    let common = format!(
        "      NERVE_DORA_MODE: {}\n      NERVE_DORA_FIFO: \"{FIFO_PRIORITY}\"\n      NERVE_DORA_PID_DIR: {}\n",
        quoted(pattern.env()),
        s(pid_dir)?
    );
    Ok(format!(
        "# written by nerve-bench hop for one batch (see bench/src/dora.rs)\n\
         nodes:\n  \
           - id: ping\n    \
             path: {ping}\n    \
             inputs:\n      \
               echo: pong/out\n    \
             outputs:\n      \
               - out\n    \
             env:\n{common}      \
               NERVE_DORA_SIZE: \"{size}\"\n      \
               NERVE_DORA_COUNT: \"{count}\"\n      \
               NERVE_DORA_WARMUP: \"{warmup}\"\n      \
               NERVE_DORA_PERIOD_US: \"{PERIOD_US}\"\n      \
               NERVE_DORA_OUT: {out}\n  \
           - id: pong\n    \
             path: {pong}\n    \
             inputs:\n      \
               in: ping/out\n    \
             outputs:\n      \
               - out\n    \
             env:\n{common}",
        ping = start(ping)?,
        pong = start(pong)?,
        out = s(out)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dataflow_names_the_binaries_and_settings_and_builds_nothing() {
        let d = dataflow(
            Path::new("/c/ping"),
            Path::new("/c/pong"),
            None,
            Path::new("/w/run-1"),
            Path::new("/w/run-1/samples.txt"),
            230_400,
            Pattern::Periodic,
            200,
            10,
        )
        .expect("a dataflow");
        assert!(d.contains("path: \"/c/ping\""), "{d}");
        assert!(d.contains("path: \"/c/pong\""), "{d}");
        assert!(d.contains("echo: pong/out") && d.contains("in: ping/out"), "{d}");
        assert!(d.contains("NERVE_DORA_SIZE: \"230400\"") && d.contains("NERVE_DORA_COUNT: \"200\""), "{d}");
        assert_eq!(d.matches("NERVE_DORA_MODE: \"periodic\"").count(), 2, "{d}");
        assert!(!d.contains("build:") && !d.contains("args:"), "{d}");
    }

    #[test]
    fn a_pinned_dataflow_starts_each_node_through_taskset_on_the_cpu() {
        let taskset = Path::new("/usr/bin/taskset");
        let (ping, pong) = (Path::new("/c/ping"), Path::new("/c/pong"));
        let (dir, out) = (Path::new("/w/run-1"), Path::new("/w/run-1/samples.txt"));
        let d = dataflow(ping, pong, Some((taskset, 1)), dir, out, 8, Pattern::Periodic, 200, 10).expect("a dataflow");
        assert_eq!(d.matches("path: \"/usr/bin/taskset\"").count(), 2, "{d}");
        assert!(d.contains("args: \"-c 1 /c/ping\"") && d.contains("args: \"-c 1 /c/pong\""), "{d}");
        let spaced = Path::new("/c/my ping");
        let e = dataflow(spaced, pong, Some((taskset, 1)), dir, out, 8, Pattern::Periodic, 200, 10);
        assert!(e.is_err_and(|e| e.to_string().contains("white space")));
    }

    #[test]
    fn the_cache_follows_the_setup_script() {
        // only the shape: the variables belong to the environment of the test run
        if let Some(d) = cache_dir() {
            assert!(d.ends_with("dora"), "{}", d.display());
        }
    }
}
