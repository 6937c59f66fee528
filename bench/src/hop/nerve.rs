//! nerve's rows: SDK agents in the scenario's robot, started as users
//! start agents and wired with `nerve connect`; a batch is a `nerve
//! suspend` and a `nerve resume` of the ping agent, which writes its round
//! trips to a file. Rows `nerve`, `nerve-pinned` (both ends on one CPU),
//! `nerve-poll` (both sides in the SDK's polling mode, `--poll`, on CPUs 0
//! and 1), `nerve-python` (the ping against a
//! Python pong) and, with dora, `nerve-5ms` (dora's pattern, see
//! [`super::dora_rows`]).

use super::pinger::{Pinger, Pingers};
use super::python::spawn_python_pong;
use super::{HopOpts, PERIODIC_PAIRS, PINNED_CPU, count_of};
use crate::agents::read_values;
use crate::bridge_agents::take_sink_batch;
use crate::dora;
use crate::procs::{ChildGuard, Robot, self_command, wait_file_after};
use anyhow::{Context as _, Result, bail};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Which agents beside the plain pairs a run has.
#[derive(Debug)]
pub(super) struct Agents<'a> {
    /// the Python with nerve's package, for the `nerve-python` pairs
    pub(super) python: Option<&'a Path>,
    /// nerve's pairs in dora's pattern (only when dora runs)
    pub(super) periodic: bool,
    /// samples per batch of those pairs
    pub(super) periodic_count: usize,
}

/// Starts every agent of every size, waits until they are registered, and
/// wires each pair; returns the agents' guards.
pub(super) fn start(
    robot: &Robot,
    opts: &HopOpts,
    counts: &[(usize, usize)],
    agents: &Agents<'_>,
) -> Result<Vec<ChildGuard>> {
    let mut children = Vec::new();
    let mut names = Vec::new();
    for &size in &opts.sizes {
        spawn_size(robot, opts, size, count_of(counts, size), agents, &mut children, &mut names)?;
    }
    let name_refs: Vec<&str> = names.iter().map(String::as_str).collect();
    robot.wait_registered(&name_refs, Duration::from_secs(15))?;
    for &size in &opts.sizes {
        connect_size(robot, size, agents)?;
    }
    Ok(children)
}

/// A folder of the run's work directory, made.
fn work_folder(opts: &HopOpts, name: &str) -> Result<PathBuf> {
    let dir = opts.work.join(name);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    Ok(dir)
}

/// Starts the agents of one payload size.
fn spawn_size(
    robot: &Robot,
    opts: &HopOpts,
    size: usize,
    count: usize,
    agents: &Agents<'_>,
    children: &mut Vec<ChildGuard>,
    names: &mut Vec<String>,
) -> Result<()> {
    let dir = work_folder(opts, &agent_name("nerve", size))?;
    let poll_dir = work_folder(opts, &agent_name("nerve-poll", size))?;
    let pin_dir = work_folder(opts, &agent_name("nerve-pinned", size))?;
    for role in ["ping", "pong", "poll-ping", "poll-pong", "pin-ping", "pin-pong"] {
        let name = agent_name(role, size);
        let d = if role.starts_with("poll-") {
            &poll_dir
        } else if role.starts_with("pin-") {
            &pin_dir
        } else {
            &dir
        };
        children.push(spawn_bench_agent(robot, role, &name, size, count, d)?);
        names.push(name);
    }
    if let Some(python) = agents.python {
        let dir = work_folder(opts, &agent_name("nerve-python", size))?;
        let ping = agent_name("pyping", size);
        children.push(spawn_bench_agent(robot, "ping", &ping, size, count, &dir)?);
        let pong = agent_name("pypong", size);
        children.push(spawn_python_pong(robot, python, &pong, size)?);
        names.extend([ping, pong]);
    }
    if agents.periodic {
        let pairs = PERIODIC_PAIRS
            .iter()
            .flat_map(|&(src, sink, _, cpu)| [("__agent-bsend", src, cpu), ("__agent-bsink", sink, cpu)]);
        for (sub, role, cpu) in pairs {
            let name = agent_name(role, size);
            let dir = work_folder(opts, &name)?;
            children.push(spawn_periodic_agent(robot, sub, &name, size, agents.periodic_count, &dir, cpu)?);
            names.push(name);
        }
    }
    Ok(())
}

/// Wires the pairs of one payload size: ping to pong and back (a cycle,
/// allowed: ping and pong answer one sample with one), sender to sink.
fn connect_size(robot: &Robot, size: usize, agents: &Agents<'_>) -> Result<()> {
    let pair = |ping: &str, pong: &str, cycle: bool| -> Result<()> {
        let (ping, pong) = (agent_name(ping, size), agent_name(pong, size));
        robot.run(&["connect", &format!("{ping}/out"), &format!("{pong}/in")])?;
        let back = [format!("{pong}/out"), format!("{ping}/in")];
        if cycle {
            robot.run(&["connect", "--allow-cycle", &back[0], &back[1]])?;
        } else {
            robot.run(&["connect", &back[0], &back[1]])?;
        }
        Ok(())
    };
    pair("ping", "pong", true)?;
    if agents.python.is_some() {
        pair("pyping", "pypong", true)?;
    }
    pair("pin-ping", "pin-pong", true)?;
    pair("poll-ping", "poll-pong", true)?;
    if agents.periodic {
        for (src, sink, _, _) in PERIODIC_PAIRS {
            let (src, sink) = (agent_name(src, size), agent_name(sink, size));
            robot.run(&["connect", &format!("{src}/out"), &format!("{sink}/in")])?;
        }
    }
    Ok(())
}

/// The rows `nerve-pinned`, `nerve`, `nerve-python` (with Python) and
/// `nerve-poll` of `size`.
pub(super) fn push_pingers(pingers: &mut Pingers, size: usize, opts: &HopOpts, python: bool) {
    let ping = |agent: &str, dir: &str| NervePing::new(agent_name(agent, size), opts.work.join(agent_name(dir, size)));
    pingers.push((size, "nerve-pinned", Box::new(ping("pin-ping", "nerve-pinned"))));
    pingers.push((size, "nerve", Box::new(ping("ping", "nerve"))));
    if python {
        pingers.push((size, "nerve-python", Box::new(ping("pyping", "nerve-python"))));
    }
    let poll = NervePollPing { ping: ping("poll-ping", "nerve-poll"), pong: agent_name("poll-pong", size) };
    pingers.push((size, "nerve-poll", Box::new(poll)));
}

/// Starts a benchmark SDK agent (`role` `ping`, suspended until a batch, or
/// `pong`) named `name` in `robot`; a ping writes its batches into `dir`.
pub(crate) fn spawn_bench_agent(
    robot: &Robot,
    role: &str,
    name: &str,
    size: usize,
    count: usize,
    dir: &Path,
) -> Result<ChildGuard> {
    // `ROLE@P`: the task at SCHED_FIFO priority P instead of the SDK's 20
    let (role, priority) = match role.split_once('@') {
        Some((r, p)) => (r, Some(p.parse::<u8>().with_context(|| format!("bad priority in role {role}"))?)),
        None => (role, None),
    };
    // `pin-ping`, `pin-pong`: the same agents kept on CPU 0; `cpuN-ROLE` on CPU N
    let (role, cpu) = match role.strip_prefix("pin-") {
        Some(r) => (r, Some(PINNED_CPU)),
        None => match role.strip_prefix("cpu").and_then(|r| r.split_once('-')) {
            Some((n, r)) => (r, Some(n.parse::<usize>().with_context(|| format!("bad CPU in role {role}"))?)),
            None => (role, None),
        },
    };
    // `poll-ping`, `poll-pong`: the event-driven agents in the SDK's polling
    // mode (`--poll`, issue 42), each on a CPU of its own (0 and 1)
    let (role, cpu, poll) = match role.strip_prefix("poll-") {
        Some(r) => (r, Some(usize::from(r == "pong")), true),
        None => (role, cpu, false),
    };
    let mut cmd = self_command(&format!("__agent-{role}"))?;
    cmd.args(["--robot", &robot.name, "--name", name]);
    if let Some(cpu) = cpu {
        cmd.args(["--cpus", &cpu.to_string()]);
    }
    if let Some(p) = priority {
        cmd.args(["--priority", &p.to_string()]);
    }
    if role.ends_with("ping") || poll {
        cmd.arg("--suspended");
    }
    if poll {
        cmd.arg("--poll");
        // two polling tasks under SCHED_FIFO take both cores of a 2-core
        // machine from the router (SCHED_OTHER), and the `nerve suspend`
        // that ends the batch never gets an answer: here a polling agent is
        // a normal-priority task (on a machine with a core to give, it
        // would be real-time on an isolated core)
        cmd.arg("--no-realtime");
    }
    cmd.args(["--", "--size", &size.to_string(), "--count", &count.to_string()]);
    cmd.arg("--out").arg(dir);
    cmd.env("NERVE_HOME", &robot.home);
    // Output::send_with builds T::default() before writing it into the sample;
    // frames of megabytes need a task stack larger than the default 2 MiB
    // (NERVE_BENCH_DEFAULT_STACK=1 leaves it out, to show the failure)
    if std::env::var_os("NERVE_BENCH_DEFAULT_STACK").is_none() {
        cmd.env("RUST_MIN_STACK", (64usize << 20).to_string());
    }
    robot.quiet(&mut cmd);
    Ok(ChildGuard::spawn(&format!("agent {name}"), cmd)?)
}

/// The polling SDK agents: the pong is resumed for the batch only (it
/// takes its CPU while it runs), then the ping as [`NervePing`] does.
struct NervePollPing {
    ping: NervePing,
    pong: String,
}

impl Pinger for NervePollPing {
    fn batch(&mut self, robot: &Robot, count: usize) -> Result<Vec<u64>> {
        robot.run(&["resume", &self.pong])?;
        let v = self.ping.batch(robot, count);
        let _ = robot.run(&["suspend", &self.ping.name]);
        robot.run(&["suspend", &self.pong])?;
        v
    }
}

/// The SDK ping agent, driven through the `nerve` command: each batch is a
/// `nerve suspend` + `nerve resume`, and the agent writes `batch-<k>.txt`.
pub(crate) struct NervePing {
    pub(crate) name: String,
    pub(crate) dir: PathBuf,
    pub(crate) next: u64,
    /// how long this process sleeps before it looks for the batch's file:
    /// three quarters of the last batch's time, so that its polling runs
    /// beside the batch's end only
    quiet: Duration,
}

impl NervePing {
    pub(crate) fn new(name: String, dir: PathBuf) -> Self {
        NervePing { name, dir, next: 0, quiet: Duration::ZERO }
    }

    /// Runs one batch; returns its round-trip times, ns.
    pub(crate) fn run_batch(&mut self, robot: &Robot) -> Result<Vec<u64>> {
        Pinger::batch(self, robot, 0)
    }
}

impl Pinger for NervePing {
    fn batch(&mut self, robot: &Robot, _count: usize) -> Result<Vec<u64>> {
        self.next += 1;
        let path = self.dir.join(format!("batch-{}.txt", self.next));
        for attempt in 0..3 {
            robot.run(&["suspend", &self.name])?;
            let t0 = Instant::now();
            robot.run(&["resume", &self.name])?;
            if wait_file_after(&path, self.quiet, Duration::from_secs(30), &mut [])? {
                self.quiet = t0.elapsed() * 3 / 4;
                let v = read_values(&path)?;
                let _ = std::fs::remove_file(&path);
                return Ok(v);
            }
            eprintln!("  {}: batch {} did not finish (attempt {}); resuming again", self.name, self.next, attempt + 1);
        }
        bail!("the nerve ping agent {} produced no batch {} in 90 s; see its log with --verbose", self.name, self.next)
    }
}

/// nerve in dora's pattern: the `bridge` scenario's SDK sender and sink
/// wired directly; each batch is a `nerve suspend` + `nerve resume` of the
/// sender, which sends `count` samples 5 ms apart and writes `sent-<k>.txt`;
/// the sink writes `batch-<k>.txt` (stamp, header stamp, arrival per sample).
pub(super) struct NervePeriodic {
    pub(super) src: String,
    pub(super) sink: String,
    pub(super) src_dir: PathBuf,
    pub(super) sink_dir: PathBuf,
    pub(super) count: usize,
    pub(super) next: u64,
}

impl Pinger for NervePeriodic {
    fn batch(&mut self, robot: &Robot, _count: usize) -> Result<Vec<u64>> {
        self.next += 1;
        let k = self.next;
        robot.run(&["suspend", &self.src])?;
        robot.run(&["resume", &self.src])?;
        let sent = self.src_dir.join(format!("sent-{k}.txt"));
        let expected = Duration::from_micros(dora::PERIOD_US * self.count as u64);
        if !wait_file_after(&sent, expected, expected + Duration::from_secs(20), &mut [])? {
            bail!("the sender {} wrote no batch {k} ({})", self.src, sent.display());
        }
        let _ = std::fs::remove_file(&sent);
        let path = self.sink_dir.join(format!("batch-{k}.txt"));
        let rows = take_sink_batch(robot, &self.sink, &path)?;
        Ok(rows.iter().map(|r| r[2].saturating_sub(r[0])).collect())
    }
}

/// Starts a sender or sink of the `bridge` scenario (`sub`: `__agent-bsend`
/// or `__agent-bsink`) in `robot`, writing its batch files into `dir`, kept
/// on CPU `cpu` if given.
fn spawn_periodic_agent(
    robot: &Robot,
    sub: &str,
    name: &str,
    size: usize,
    count: usize,
    dir: &Path,
    cpu: Option<usize>,
) -> Result<ChildGuard> {
    let mut cmd = self_command(sub)?;
    cmd.args(["--robot", &robot.name, "--name", name]);
    if let Some(cpu) = cpu {
        cmd.args(["--cpus", &cpu.to_string()]);
    }
    cmd.arg("--");
    cmd.args(["--size", &size.to_string(), "--count", &count.to_string()]);
    cmd.args(["--interval-us", &dora::PERIOD_US.to_string()]);
    cmd.arg("--out").arg(dir);
    cmd.env("NERVE_HOME", &robot.home);
    robot.quiet(&mut cmd);
    Ok(ChildGuard::spawn(&format!("agent {name}"), cmd)?)
}

/// The short form of a payload size in agent names: `8`, `4k`, `230k`, `6m`.
pub(crate) fn size_tag(size: usize) -> &'static str {
    match size {
        8 => "8",
        4096 => "4k",
        230_400 => "230k",
        _ => "6m",
    }
}

pub(super) fn agent_name(prefix: &str, size: usize) -> String {
    format!("{prefix}-{}", size_tag(size))
}
