//! Scenario `hop`: one-hop round-trip latency between two processes,
//! event-driven (both sides blocked until woken), for each payload size and
//! four transports measured side by side, interleaved batch by batch:
//!
//! * `nerve`: two SDK agents (`bench-ping`, `bench-pong`) in a robot of their
//!   own, with a router, wired with `nerve connect` as users do; a batch is
//!   started with `nerve suspend` + `nerve resume` of the ping agent;
//! * `iox2-waitset`: raw iceoryx2, reader blocked on a WaitSet;
//! * `iox2-listener`: raw iceoryx2, reader blocked on the listener itself;
//! * `iox2-waitset-fill`: as `iox2-waitset`, but every send first writes
//!   `P::default()` into the sample, as `Output::send_with` does: it shows how
//!   much of nerve's gap is that fill;
//! * `uds`: a blocking Unix stream socket, copying: the floor of a copying
//!   transport at every size;
//! * `futex`: two processes ping-ponging a sequence number through a futex
//!   in shared memory ([`crate::futex`]): the floor of any wake-up, with the
//!   share of round trips whose two ends ran on one CPU (placement);
//! * `ddsperf`: Cyclone DDS's own ping-pong, when installed ([`crate::dds`]);
//! * `dora`: two dora-rs nodes on dora's Rust node API, one `dora run` per
//!   batch, when `scripts/setup.sh --bench` has built them ([`crate::dora`]);
//! * `nerve-python`: the SDK ping against a Python pong (`bench/py/pong.py`,
//!   the `nerve` package: read in place, the number written in place in a
//!   loaned sample), when the package is installed (`NERVE_PYTHON`, else
//!   `target/nerve-py`); its ratio to `nerve` is issue 15's target.
//!
//! With dora come two more rows, in dora's own pattern (its
//! `examples/benchmark`: one sample every 5 ms, latency taken at the
//! receiver), one way instead of round trips, reported apart:
//!
//! * `nerve-5ms`: an SDK sender (`__agent-bsend`, event-driven, a batch per
//!   `nerve resume`) stamps CLOCK_MONOTONIC into the first 8 bytes of a
//!   sample every 5 ms on absolute deadlines (`Output::send_uninit`, nothing
//!   else written); an SDK sink (`__agent-bsink`) wired to it with `nerve
//!   connect` records `arrival - stamp`: the agents of the `bridge`
//!   scenario, here in one robot without a bridge;
//! * `dora-5ms`: the same with the dora nodes (see [`crate::dora`]).
//!
//! dora's two rows and `nerve-5ms` are measured under PM QoS as well
//! (`dora-pmqos`, `dora-5ms-pmqos`, `nerve-5ms-pmqos`, below), so that dora
//! and nerve are compared under the same settings both ways.
//!
//! `nerve-5ms-pinned` and `dora-5ms-pinned` (and their `-pmqos` rows) are
//! dora's pattern with both ends kept on one CPU ([`PINNED_CPU`]): nerve's
//! sender and sink with `--cpus`, dora's two nodes started by `taskset`;
//! the router and dora's daemon stay free. A sample every 5 ms wakes a sink
//! whose CPU has been idle for 5 ms; on one CPU the sink is woken by the
//! sender's own, still warm, CPU instead. What that buys each system is the
//! placement question of a sparse stream.
//!
//! `nerve-pinned` and `futex-pinned` are the pairs with both ends kept on
//! one CPU (`--cpus 0` for the agents; the futex ping thread for its batch):
//! what placement buys, without PM QoS.
//!
//! Every agent of the run holds no PM QoS bound (`NERVE_CPU_LATENCY=off`),
//! so that the rows above measure the machine as it idles by default. The
//! rows `nerve-pmqos`, `iox2-waitset-pmqos`, `uds-pmqos` and `futex-pmqos`
//! are the same pairs with this process holding `/dev/cpu_dma_latency` at 0
//! for the batch only ([`agent_sdk::cpu_latency`]); the kernel honours one
//! bound for the whole machine, whoever holds it, so `nerve-pmqos` is what
//! nerve's agents get by default (each real-time agent holds 0 while it
//! runs). Batches of all rows interleave, so both states are measured in
//! one run. Before the batches, [`crate::idle`] measures where the CPUs of
//! the idle robot spend their time with and without the bound.
//!
//! The ratios dora/nerve (p50, per size, both patterns) go with the others;
//! the target is dora ≥ [`DORA_TARGET`] times nerve's latency (issue 18).
//!
//! The benchmark's own ping side runs at the agents' SCHED_FIFO priority (20)
//! with locked memory, like the SDK's task thread, so that only the code
//! paths differ. The first samples of every batch are dropped (warm-up), and
//! so is a whole first round. The SDK ping, started by a `nerve resume`,
//! ping-pongs 100 ms before it records, while that command is answered and
//! exits: a raw pair's batch starts from this process and has no such
//! neighbour, and a short batch (250 frames of 1080p: 5 ms) ran entirely
//! beside it.

use crate::agents::read_values;
use crate::bridge_agents::take_sink_batch;
use crate::dds::{self, DdsPeer};
use crate::dora::{self, DoraPeer, Pattern};
use crate::futex::FutexPing;
use crate::idle::IdleShare;
use crate::machine::{Machine, command_line, steal_ms};
use crate::payloads::{BenchPayload, SIZES, label};
use crate::procs::{ChildGuard, Robot, normal_priority, realtime_like_an_agent, self_command, wait_file_after};
use crate::raw::{Mode, Side};
use crate::stats::{Rounds, Summary, median_f64, ratio, ratio_cell, verdict};
use crate::uds::UdsPing;
use crate::with_payload;
use anyhow::{Context as _, Result, bail};
use serde::Serialize;
use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::rc::Rc;
use std::time::{Duration, Instant};

/// Samples dropped at the start of every batch.
const DISCARD: usize = 5;
/// The transports, in the order of the tables.
pub const TRANSPORTS: [&str; 19] = [
    "nerve",
    "nerve-python",
    "nerve-python-pmqos",
    "nerve-pmqos",
    "iox2-waitset",
    "iox2-waitset-pmqos",
    "iox2-listener",
    "iox2-waitset-fill",
    "uds",
    "uds-pmqos",
    "futex",
    "futex-pmqos",
    "nerve-pinned",
    "futex-pinned",
    "ddsperf",
    "dora",
    "dora-pmqos",
    "nerve-poll",
    "iox2-poll",
];
/// The CPU the `-pinned` rows keep both ends on.
pub(crate) const PINNED_CPU: usize = 0;
/// The transports measured again under a PM QoS bound of 0 µs (row `T-pmqos`).
const UNDER_PM_QOS: [&str; 10] = [
    "nerve",
    "nerve-python",
    "iox2-waitset",
    "uds",
    "futex",
    "dora",
    "nerve-5ms",
    "dora-5ms",
    "nerve-5ms-pinned",
    "dora-5ms-pinned",
];
/// nerve's round trip (with its default PM QoS bound) may be this many times the futex floor's (issue 17).
pub const FUTEX_TARGET: f64 = 1.5;
/// nerve's pairs in dora's pattern: (sender's role, sink's role, row, the
/// CPU both are kept on); the agents are `ROLE-SIZE`.
const PERIODIC_PAIRS: [(&str, &str, &str, Option<usize>); 2] =
    [("psend", "psink", "nerve-5ms", None), ("pin-psend", "pin-psink", "nerve-5ms-pinned", Some(PINNED_CPU))];
/// The rows in dora's pattern (one way, a sample every 5 ms), in table order.
pub const PERIODIC: [&str; 8] = [
    "nerve-5ms",
    "dora-5ms",
    "nerve-5ms-pmqos",
    "dora-5ms-pmqos",
    "nerve-5ms-pinned",
    "dora-5ms-pinned",
    "nerve-5ms-pinned-pmqos",
    "dora-5ms-pinned-pmqos",
];
/// nerve may be this much slower than raw iceoryx2 (the target).
pub const TARGET_RATIO: f64 = 1.1;
/// A Python agent's round trip may be this many times a Rust agent's (issue 15).
pub const PYTHON_TARGET: f64 = 1.5;
/// dora should take at least this many times nerve's latency (issue 18).
pub const DORA_TARGET: f64 = 10.0;
/// Samples per batch in the 5 ms pattern (a second; a fifth with --quick).
const PERIODIC_COUNT: (usize, usize) = (200, 40);

/// Options of the hop scenario.
#[derive(Debug, Clone)]
pub struct HopOpts {
    /// smoke run
    pub quick: bool,
    /// payload sizes (bytes)
    pub sizes: Vec<usize>,
    /// measured rounds (a warm-up round comes first)
    pub rounds: usize,
    /// round trips per batch, by size; None for the defaults
    pub count: Option<usize>,
    /// show children's output
    pub verbose: bool,
    /// where batch files go
    pub work: PathBuf,
}

/// Results of one transport at one payload size.
#[derive(Debug, Clone, Serialize)]
pub struct HopResult {
    /// transport
    pub transport: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// all measured round trips pooled
    pub rtt: Summary,
    /// median round trip of each round, ns
    pub round_p50_ns: Vec<u64>,
    /// share of round trips whose two ends ran on the same CPU (the futex rows)
    pub same_cpu_share: Option<f64>,
}

/// Results of one system at one payload size in dora's pattern (a sample every 5 ms).
#[derive(Debug, Clone, Serialize)]
pub struct OneWayResult {
    /// `nerve-5ms` or `dora-5ms`
    pub transport: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// all measured one-way latencies pooled (sender's stamp to the receiver's code)
    pub one_way: Summary,
    /// median one-way latency of each round, ns
    pub round_p50_ns: Vec<u64>,
}

/// nerve against the others at one payload size.
#[derive(Debug, Clone, Serialize)]
pub struct HopRatio {
    /// payload bytes
    pub size: usize,
    /// nerve p50 / iox2-waitset p50 (pooled)
    pub nerve_vs_waitset_p50: f64,
    /// nerve p99 / iox2-waitset p99
    pub nerve_vs_waitset_p99: f64,
    /// median over rounds of the per-round p50 ratio
    pub nerve_vs_waitset_p50_round_median: f64,
    /// nerve p50 / iox2-listener p50
    pub nerve_vs_listener_p50: f64,
    /// nerve p99 / iox2-listener p99
    pub nerve_vs_listener_p99: f64,
    /// nerve p50 / iox2-waitset-fill p50: the SDK's cost apart from the fill
    pub nerve_vs_waitset_fill_p50: f64,
    /// nerve p99 / iox2-waitset-fill p99
    pub nerve_vs_waitset_fill_p99: f64,
    /// uds p50 / nerve p50
    pub uds_vs_nerve_p50: f64,
    /// ddsperf p50 / nerve p50 (None without ddsperf)
    pub dds_vs_nerve_p50: Option<f64>,
    /// nerve-poll p50 / iox2-poll p50
    pub nerve_poll_vs_iox2_poll_p50: Option<f64>,
    /// dora p50 / nerve p50, ping-pong round trips (None without dora)
    pub dora_vs_nerve_p50: Option<f64>,
    /// dora p99 / nerve p99, ping-pong round trips
    pub dora_vs_nerve_p99: Option<f64>,
    /// dora-5ms p50 / nerve-5ms p50: one way, a sample every 5 ms (None without dora)
    pub dora_5ms_vs_nerve_5ms_p50: Option<f64>,
    /// dora-5ms p99 / nerve-5ms p99
    pub dora_5ms_vs_nerve_5ms_p99: Option<f64>,
    /// whether both dora p50 ratios are at least [`DORA_TARGET`] (None without dora)
    pub dora_target_met: Option<bool>,
    /// dora-pmqos p50 / nerve-pmqos p50: round trips, both under a PM QoS
    /// bound of 0 µs (nerve's default; dora holds none of its own)
    pub dora_pmqos_vs_nerve_pmqos_p50: Option<f64>,
    /// dora-5ms-pmqos p50 / nerve-5ms-pmqos p50: one way every 5 ms, both under the bound
    pub dora_5ms_pmqos_vs_nerve_5ms_pmqos_p50: Option<f64>,
    /// whether both ratios under the bound are at least [`DORA_TARGET`]
    pub dora_target_met_pmqos: Option<bool>,
    /// dora-5ms-pinned p50 / nerve-5ms-pinned p50: one way every 5 ms, each
    /// system's two ends on one CPU, no bound (None without the rows)
    pub dora_5ms_pinned_vs_nerve_5ms_pinned_p50: Option<f64>,
    /// dora-5ms-pinned-pmqos p50 / nerve-5ms-pinned-pmqos p50: the same under the bound
    pub dora_5ms_pinned_pmqos_vs_nerve_5ms_pinned_pmqos_p50: Option<f64>,
    /// nerve-5ms-pmqos p50 / nerve-5ms-pinned-pmqos p50: what one CPU for both ends buys nerve in dora's pattern
    pub pinned_gain_nerve_5ms_pmqos: Option<f64>,
    /// dora p50 / nerve-pmqos p50: each as it runs by default (dora holds no
    /// bound, nerve's agents hold 0 µs); not the same settings
    pub dora_vs_nerve_pmqos_p50: Option<f64>,
    /// whether nerve p50 is within the target of iox2-waitset p50
    pub target_met: bool,
    /// nerve p50 / futex p50, neither holding PM QoS
    pub nerve_vs_futex_p50: Option<f64>,
    /// nerve-pmqos p50 / futex-pmqos p50: both under a bound of 0 µs
    pub nerve_pmqos_vs_futex_pmqos_p50: Option<f64>,
    /// nerve-pmqos p50 / futex p50: nerve as it runs by default against the
    /// floor of a machine left as it idles by default
    pub nerve_pmqos_vs_futex_p50: Option<f64>,
    /// whether nerve-pmqos p50 ≤ [`FUTEX_TARGET`] × futex-pmqos p50 (same settings)
    pub futex_target_met: Option<bool>,
    /// nerve-pmqos p50 / iox2-waitset-pmqos p50
    pub nerve_pmqos_vs_waitset_pmqos_p50: Option<f64>,
    /// nerve p50 / nerve-pmqos p50: what the bound buys nerve
    pub pmqos_gain_nerve: Option<f64>,
    /// nerve p50 / nerve-pinned p50: what one CPU for both ends buys nerve
    pub pinned_gain_nerve: Option<f64>,
    /// nerve-pinned p50 / futex-pinned p50
    pub nerve_pinned_vs_futex_pinned_p50: Option<f64>,
    /// nerve-python p50 / nerve p50: a Python pong against a Rust one (None without the package)
    pub python_vs_nerve_p50: Option<f64>,
    /// nerve-python p99 / nerve p99
    pub python_vs_nerve_p99: Option<f64>,
    /// whether nerve-python p50 ≤ [`PYTHON_TARGET`] × nerve p50
    pub python_target_met: Option<bool>,
    /// nerve-python-pmqos p50 / nerve-pmqos p50: both holding PM QoS, as agents run by default
    pub python_pmqos_vs_nerve_pmqos_p50: Option<f64>,
}

/// Time to write a whole payload once (what `Output::send_with` adds per send).
#[derive(Debug, Clone, Serialize)]
pub struct FillCost {
    /// payload bytes
    pub size: usize,
    /// median time to zero the payload in warm memory (the same buffer again), ns
    pub memset_warm_p50_ns: u64,
    /// median time to zero it in memory not touched recently (64 MiB of buffers in turn), ns
    pub memset_cold_p50_ns: u64,
}

/// The hop report.
#[derive(Debug, Clone, Serialize)]
pub struct HopReport {
    /// "hop"
    pub scenario: &'static str,
    /// the command that produced it
    pub command: String,
    /// the machine
    pub machine: Machine,
    /// measured rounds
    pub rounds: usize,
    /// round trips per batch, by size
    pub batch: Vec<(usize, usize)>,
    /// per transport and size: round trips
    pub results: Vec<HopResult>,
    /// `nerve-5ms` and `dora-5ms` per size: one way, a sample every 5 ms
    pub periodic: Vec<OneWayResult>,
    /// samples per batch of the 5 ms rows
    pub periodic_batch: usize,
    /// what `dora --version` said (None: no dora rows)
    pub dora_version: Option<String>,
    /// per size
    pub ratios: Vec<HopRatio>,
    /// target ratio (nerve / iox2-waitset, p50)
    pub target_ratio: f64,
    /// target ratio dora / nerve (p50, both patterns): at least this
    pub dora_target_ratio: f64,
    /// cost of filling a payload once, by size
    pub fill_cost: Vec<FillCost>,
    /// where the idle robot's CPUs spent their time, without and with PM QoS
    pub idle: Vec<IdleShare>,
    /// nerve-pmqos / futex-pmqos p50 target
    pub futex_target_ratio: f64,
    /// per measured round: the time the hypervisor ran something else while
    /// this guest's CPUs had work, ms, all CPUs (`steal` of /proc/stat, in
    /// steps of USER_HZ ticks, 10 ms here: too coarse for one batch, whose
    /// slow rounds add about 10 ms in all; empty where the kernel does not say)
    pub round_steal_ms: Vec<f64>,
    /// wall time of the run, s
    pub seconds: f64,
}

pub(crate) fn default_count(size: usize, quick: bool) -> usize {
    match (size, quick) {
        (8, false) => 3000,
        (8, true) => 300,
        (230_400, false) => 1500,
        (230_400, true) => 100,
        (_, false) => 250,
        (_, true) => 30,
    }
}

/// Something that runs a batch of round trips.
pub(crate) trait Pinger {
    fn batch(&mut self, robot: &Robot, count: usize) -> Result<Vec<u64>>;
    /// round trips of the last batch whose two ends shared a CPU, where known
    fn same_cpu(&self) -> Option<usize> {
        None
    }
}

/// A pinger measured in two rows: as it is, and under PM QoS.
pub(crate) type SharedPinger = Rc<RefCell<Box<dyn Pinger>>>;

/// The row of a [`SharedPinger`]: its batches run with or without this
/// process holding a PM QoS bound of 0 µs for the batch.
pub(crate) struct Row {
    pub(crate) pinger: SharedPinger,
    pub(crate) pm_qos: bool,
}

impl Row {
    /// The two rows of one pinger: as it is, and under PM QoS.
    pub(crate) fn both(p: Box<dyn Pinger>) -> (Row, Row) {
        let shared: SharedPinger = Rc::new(RefCell::new(p));
        (Row { pinger: Rc::clone(&shared), pm_qos: false }, Row { pinger: shared, pm_qos: true })
    }
}

impl Pinger for Row {
    fn batch(&mut self, robot: &Robot, count: usize) -> Result<Vec<u64>> {
        let _hold = if self.pm_qos {
            let h =
                agent_sdk::cpu_latency::hold(0).context("the -pmqos rows need /dev/cpu_dma_latency (run as root)")?;
            // idle CPUs re-pick their state when the bound changes
            std::thread::sleep(Duration::from_millis(2));
            Some(h)
        } else {
            None
        };
        self.pinger.borrow_mut().batch(robot, count)
    }

    fn same_cpu(&self) -> Option<usize> {
        self.pinger.borrow().same_cpu()
    }
}

/// Whether this process may hold a PM QoS bound; says so when not (the
/// `-pmqos` rows are left out, as a missing peer's are).
pub(crate) fn pm_qos_permitted(scenario: &str) -> bool {
    match agent_sdk::cpu_latency::hold(0) {
        Ok(_) => true,
        Err(e) => {
            eprintln!("{scenario}: warning: no -pmqos rows: {e}");
            false
        }
    }
}

/// A pinger whose batches run with this thread kept on [`PINNED_CPU`]
/// (the pong was started there): placement without PM QoS.
pub(crate) struct Pinned(pub(crate) Box<dyn Pinger>);

impl Pinger for Pinned {
    fn batch(&mut self, robot: &Robot, count: usize) -> Result<Vec<u64>> {
        let all =
            agent_sdk::rt::CpuList((0..std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)).collect());
        agent_sdk::rt::set_affinity(&agent_sdk::rt::CpuList(vec![PINNED_CPU])).map_err(anyhow::Error::msg)?;
        let r = self.0.batch(robot, count);
        agent_sdk::rt::set_affinity(&all).map_err(anyhow::Error::msg)?;
        r
    }

    fn same_cpu(&self) -> Option<usize> {
        self.0.same_cpu()
    }
}

impl Pinger for FutexPing {
    fn batch(&mut self, _robot: &Robot, count: usize) -> Result<Vec<u64>> {
        self.ping_batch(count)
    }

    fn same_cpu(&self) -> Option<usize> {
        Some(self.same_cpu)
    }
}

impl<P: BenchPayload> Pinger for Side<P> {
    fn batch(&mut self, _robot: &Robot, count: usize) -> Result<Vec<u64>> {
        self.ping_batch(count)
    }
}

impl Pinger for UdsPing {
    fn batch(&mut self, _robot: &Robot, count: usize) -> Result<Vec<u64>> {
        self.ping_batch(count)
    }
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
    let mut cmd = self_command(&format!("__agent-{role}"))?;
    cmd.args(["--robot", &robot.name, "--name", name]);
    if let Some(cpu) = cpu {
        cmd.args(["--cpus", &cpu.to_string()]);
    }
    if let Some(p) = priority {
        cmd.args(["--priority", &p.to_string()]);
    }
    if role == "ping" || role.starts_with("poll-") {
        cmd.arg("--suspended");
    }
    if role.starts_with("poll-") {
        // two tasks waking at 100 kHz under SCHED_FIFO take both cores of a
        // 2-core machine from the router (SCHED_OTHER), and the `nerve
        // suspend` that ends the batch never gets an answer: a polling agent
        // is a normal-priority task, as anyone polling would run it
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
    ChildGuard::spawn(&format!("agent {name}"), cmd)
}

/// The Python that has nerve's package: `NERVE_PYTHON`, else the
/// workspace's `target/nerve-py` (where `.ci/run` installs it).
fn python_with_nerve() -> Result<PathBuf> {
    let python = match std::env::var_os("NERVE_PYTHON") {
        Some(p) => PathBuf::from(p),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/nerve-py/bin/python"),
    };
    let ok = Command::new(&python)
        .args(["-c", "import nerve._native, numpy"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        bail!(
            "{} cannot import the nerve package; install it (docs/python.md) or name a Python that has it with NERVE_PYTHON",
            python.display()
        );
    }
    Ok(python)
}

/// Starts `bench/py/pong.py` as agent `name` with `python`.
fn spawn_python_pong(robot: &Robot, python: &Path, name: &str, size: usize) -> Result<ChildGuard> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("py").join("pong.py");
    let mut cmd = Command::new(python);
    cmd.arg(&script).args(["--robot", &robot.name, "--name", name, "--", "--size", &size.to_string()]);
    cmd.env("NERVE_HOME", &robot.home).stdin(Stdio::null());
    robot.quiet(&mut cmd);
    ChildGuard::spawn(&format!("agent {name}"), cmd)
}

/// The polling SDK agents: the pong is resumed for the batch only (it polls
/// at 100 kHz while it runs), then the ping as [`NervePing`] does.
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
struct NervePeriodic {
    src: String,
    sink: String,
    src_dir: PathBuf,
    sink_dir: PathBuf,
    count: usize,
    next: u64,
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

/// A dora batch: one `dora run` (see [`crate::dora`]).
struct DoraPinger {
    peer: Rc<DoraPeer>,
    size: usize,
    pattern: Pattern,
    count: Option<usize>,
    /// both nodes kept on this CPU
    cpu: Option<usize>,
}

impl Pinger for DoraPinger {
    fn batch(&mut self, _robot: &Robot, count: usize) -> Result<Vec<u64>> {
        self.peer.batch(self.size, self.pattern, self.count.unwrap_or(count), self.cpu)
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
    ChildGuard::spawn(&format!("agent {name}"), cmd)
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

fn agent_name(prefix: &str, size: usize) -> String {
    format!("{prefix}-{}", size_tag(size))
}

fn measure_fill(size: usize) -> FillCost {
    let time = |buf: &mut [u8]| {
        let t0 = agent_sdk::clock::now_ns();
        // SAFETY: `buf` is valid for `buf.len()` bytes.
        unsafe { std::ptr::write_bytes(std::hint::black_box(buf.as_mut_ptr()), 0, buf.len()) };
        std::hint::black_box(&buf);
        agent_sdk::clock::now_ns() - t0
    };
    let mut one = vec![1u8; size];
    let warm: Vec<u64> = (0..21).map(|_| time(&mut one)).collect();
    let n = ((64usize << 20) / size.max(1)).clamp(2, 4096);
    let mut many: Vec<Vec<u8>> = (0..n).map(|_| vec![1u8; size]).collect();
    let cold: Vec<u64> = (0..(3 * n).min(300)).map(|i| time(&mut many[i % n])).collect();
    FillCost { size, memset_warm_p50_ns: Summary::of(&warm).p50_ns, memset_cold_p50_ns: Summary::of(&cold).p50_ns }
}

/// Runs the hop scenario.
pub fn run(opts: &HopOpts) -> Result<HopReport> {
    let started = Instant::now();
    let machine = Machine::probe();
    for s in &opts.sizes {
        if !SIZES.contains(s) {
            bail!("no payload of {s} bytes; use 8, 230400 or 6220800");
        }
    }
    let counts: Vec<(usize, usize)> =
        opts.sizes.iter().map(|&s| (s, opts.count.unwrap_or_else(|| default_count(s, opts.quick)))).collect();
    let count_of = |s: usize| counts.iter().find(|(x, _)| *x == s).map(|(_, c)| *c).unwrap_or(100);

    // the robot first: dropped last, so `nerve down` runs after every child stopped
    // no agent holds PM QoS: the -pmqos rows hold it for their batches only
    let robot = Robot::new("h", opts.verbose)?.with_cpu_latency("off");
    eprintln!("hop: {}", machine.idle_line());
    eprintln!(
        "hop: robot {} (sizes {:?}, {} rounds{})",
        robot.name,
        opts.sizes,
        opts.rounds,
        if opts.quick { "" } else { " + warm-up" }
    );
    let _router = robot.start_router()?;
    let mut children: Vec<ChildGuard> = Vec::new();

    // dora, when built; with it, nerve in dora's pattern
    let dora_peer = match DoraPeer::find(&opts.work, opts.verbose) {
        Ok(p) => {
            eprintln!("hop: {} with its nodes from {}", p.version, p.cache.display());
            Some(Rc::new(p))
        }
        Err(e) => {
            eprintln!("hop: warning: no dora rows ({e:#}); `scripts/setup.sh --bench` builds dora");
            None
        }
    };
    let periodic_count = if opts.quick { PERIODIC_COUNT.1 } else { PERIODIC_COUNT.0 };
    // a Python pong beside the Rust one, when the package is installed
    let python = match python_with_nerve() {
        Ok(p) => {
            eprintln!("hop: Python agents with {}", p.display());
            Some(p)
        }
        Err(e) => {
            eprintln!("hop: warning: no nerve-python row ({e:#})");
            None
        }
    };

    // nerve agents, wired through the router
    let mut names = Vec::new();
    for &size in &opts.sizes {
        let dir = opts.work.join(agent_name("nerve", size));
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let poll_dir = opts.work.join(agent_name("nerve-poll", size));
        std::fs::create_dir_all(&poll_dir).with_context(|| format!("cannot create {}", poll_dir.display()))?;
        let pin_dir = opts.work.join(agent_name("nerve-pinned", size));
        std::fs::create_dir_all(&pin_dir).with_context(|| format!("cannot create {}", pin_dir.display()))?;
        for role in ["ping", "pong", "poll-ping", "poll-pong", "pin-ping", "pin-pong"] {
            let name = agent_name(role, size);
            let d = if role.starts_with("poll-") {
                &poll_dir
            } else if role.starts_with("pin-") {
                &pin_dir
            } else {
                &dir
            };
            children.push(spawn_bench_agent(&robot, role, &name, size, count_of(size), d)?);
            names.push(name);
        }
        if let Some(python) = &python {
            let dir = opts.work.join(agent_name("nerve-python", size));
            std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
            let ping = agent_name("pyping", size);
            children.push(spawn_bench_agent(&robot, "ping", &ping, size, count_of(size), &dir)?);
            let pong = agent_name("pypong", size);
            children.push(spawn_python_pong(&robot, python, &pong, size)?);
            names.extend([ping, pong]);
        }
        if dora_peer.is_some() {
            let agents = PERIODIC_PAIRS
                .iter()
                .flat_map(|&(src, sink, _, cpu)| [("__agent-bsend", src, cpu), ("__agent-bsink", sink, cpu)]);
            for (sub, role, cpu) in agents {
                let name = agent_name(role, size);
                let dir = opts.work.join(&name);
                std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
                children.push(spawn_periodic_agent(&robot, sub, &name, size, periodic_count, &dir, cpu)?);
                names.push(name);
            }
        }
    }
    let name_refs: Vec<&str> = names.iter().map(String::as_str).collect();
    robot.wait_registered(&name_refs, Duration::from_secs(15))?;
    for &size in &opts.sizes {
        let (ping, pong) = (agent_name("ping", size), agent_name("pong", size));
        robot.run(&["connect", &format!("{ping}/out"), &format!("{pong}/in")])?;
        // ping and pong answer one sample with one: the loop is the benchmark
        robot.run(&["connect", "--allow-cycle", &format!("{pong}/out"), &format!("{ping}/in")])?;
        if python.is_some() {
            let (ping, pong) = (agent_name("pyping", size), agent_name("pypong", size));
            robot.run(&["connect", &format!("{ping}/out"), &format!("{pong}/in")])?;
            robot.run(&["connect", "--allow-cycle", &format!("{pong}/out"), &format!("{ping}/in")])?;
        }
        let (ping, pong) = (agent_name("pin-ping", size), agent_name("pin-pong", size));
        robot.run(&["connect", &format!("{ping}/out"), &format!("{pong}/in")])?;
        robot.run(&["connect", "--allow-cycle", &format!("{pong}/out"), &format!("{ping}/in")])?;
        let (ping, pong) = (agent_name("poll-ping", size), agent_name("poll-pong", size));
        robot.run(&["connect", &format!("{ping}/out"), &format!("{pong}/in")])?;
        robot.run(&["connect", &format!("{pong}/out"), &format!("{ping}/in")])?;
        if dora_peer.is_some() {
            for (src, sink, _, _) in PERIODIC_PAIRS {
                let (src, sink) = (agent_name(src, size), agent_name(sink, size));
                robot.run(&["connect", &format!("{src}/out"), &format!("{sink}/in")])?;
            }
        }
    }
    eprintln!("hop: nerve agents running and connected");

    // raw iceoryx2, socket and futex pongs
    let (mut uds_pings, mut futex_pings) = (Vec::new(), Vec::new());
    for &size in &opts.sizes {
        for mode in ["waitset", "listener", "waitset-fill", "poll"] {
            let mut cmd = self_command("__raw-pong")?;
            cmd.args(["--robot", &robot.name, "--mode", mode, "--size", &size.to_string()]);
            cmd.env("NERVE_HOME", &robot.home).stdout(Stdio::piped());
            if !opts.verbose {
                cmd.stderr(Stdio::null());
            }
            let mut c = ChildGuard::spawn(&format!("raw pong {mode} {size}"), cmd)?;
            c.await_ready("raw iceoryx2 pong")?;
            children.push(c);
        }
        let (c, ping) = UdsPing::with_pong(&robot.home, size, opts.verbose)?;
        children.push(c);
        uds_pings.push(ping);
        let (c, ping) = FutexPing::with_pong(&format!("{size}"), None, opts.verbose)?;
        children.push(c);
        let (c2, pinned) = FutexPing::with_pong(&format!("{size}-pinned"), Some(PINNED_CPU), opts.verbose)?;
        children.push(c2);
        futex_pings.push((ping, pinned));
    }

    // the ping sides; from here on this thread runs like an agent's task
    let mut pingers: Vec<(usize, &'static str, Box<dyn Pinger>)> = Vec::new();
    let (mut uds_pings, mut futex_pings) = (uds_pings.into_iter(), futex_pings.into_iter());
    for &size in &opts.sizes {
        if let (Some(u), Some((f, fp))) = (uds_pings.next(), futex_pings.next()) {
            pingers.push((size, "uds", Box::new(u)));
            pingers.push((size, "futex", Box::new(f)));
            pingers.push((size, "futex-pinned", Box::new(Pinned(Box::new(fp)))));
        }
        pingers.push((
            size,
            "nerve-pinned",
            Box::new(NervePing::new(agent_name("pin-ping", size), opts.work.join(agent_name("nerve-pinned", size)))),
        ));
        pingers.push((
            size,
            "nerve",
            Box::new(NervePing::new(agent_name("ping", size), opts.work.join(agent_name("nerve", size)))),
        ));
        if python.is_some() {
            pingers.push((
                size,
                "nerve-python",
                Box::new(NervePing::new(agent_name("pyping", size), opts.work.join(agent_name("nerve-python", size)))),
            ));
        }
        pingers.push((
            size,
            "nerve-poll",
            Box::new(NervePollPing {
                ping: NervePing::new(agent_name("poll-ping", size), opts.work.join(agent_name("nerve-poll", size))),
                pong: agent_name("poll-pong", size),
            }),
        ));
        for (mode, t) in [
            (Mode::Waitset, "iox2-waitset"),
            (Mode::Listener, "iox2-listener"),
            (Mode::WaitsetFill, "iox2-waitset-fill"),
            (Mode::Poll, "iox2-poll"),
        ] {
            let p: Box<dyn Pinger> = with_payload!(size, P => Box::new(Side::<P>::open(&robot.name, mode, "ping", "pong", "raw-ping")?), _ => bail!("size"));
            pingers.push((size, t, p));
        }
        if let Some(peer) = &dora_peer {
            for (src, sink, row, _) in PERIODIC_PAIRS {
                let (src, sink) = (agent_name(src, size), agent_name(sink, size));
                let (src_dir, sink_dir) = (opts.work.join(&src), opts.work.join(&sink));
                let p = NervePeriodic { src, sink, src_dir, sink_dir, count: periodic_count, next: 0 };
                pingers.push((size, row, Box::new(p)));
            }
            for (pattern, count) in [(Pattern::PingPong, None), (Pattern::Periodic, Some(periodic_count))] {
                let p = DoraPinger { peer: Rc::clone(peer), size, pattern, count, cpu: None };
                pingers.push((size, pattern.transport(), Box::new(p)));
            }
            if peer.can_pin() {
                let cpu = Some(PINNED_CPU);
                let p = DoraPinger {
                    peer: Rc::clone(peer),
                    size,
                    pattern: Pattern::Periodic,
                    count: Some(periodic_count),
                    cpu,
                };
                pingers.push((size, "dora-5ms-pinned", Box::new(p)));
            } else if size == opts.sizes[0] {
                eprintln!("hop: warning: no dora-5ms-pinned rows: `taskset` (util-linux) is not on PATH");
            }
        }
    }
    // the rows measured again under PM QoS share their pinger with the plain row
    let pm_qos = pm_qos_permitted("hop");
    let mut pingers: Vec<(usize, &'static str, Box<dyn Pinger>)> = pingers
        .into_iter()
        .flat_map(|(size, t, p)| {
            let Some(&pmqos) = UNDER_PM_QOS.iter().find(|x| **x == t && pm_qos) else {
                return vec![(size, t, p)];
            };
            let pmqos_name = TRANSPORTS
                .iter()
                .chain(PERIODIC.iter())
                .copied()
                .find(|x| x.strip_suffix("-pmqos") == Some(pmqos))
                .unwrap_or(t);
            let (plain, held) = Row::both(p);
            vec![(size, t, Box::new(plain) as Box<dyn Pinger>), (size, pmqos_name, Box::new(held))]
        })
        .collect();
    // where an idle robot's CPUs spend their time, without and with the bound
    let idle_span = Duration::from_secs(if opts.quick { 1 } else { 3 });
    let idle = vec![crate::idle::measure(false, idle_span), crate::idle::measure(true, idle_span)];
    // Cyclone DDS, when installed
    let dds_peer = if dds::available() {
        Some(DdsPeer::start(opts.verbose)?)
    } else {
        eprintln!("hop: warning: `ddsperf` not found (apt-get install cyclonedds-tools); no Cyclone DDS row");
        None
    };
    let mut dds_intervals: Vec<(usize, Vec<dds::Interval>, Vec<u64>)> =
        opts.sizes.iter().map(|&s| (s, Vec::new(), Vec::new())).collect();
    realtime_like_an_agent(20);

    let mut rounds = Rounds::new(pingers.len(), DISCARD);
    // (round trips on one CPU, round trips) per pinger, measured rounds
    let mut placement = vec![(0usize, 0usize); pingers.len()];
    let mut round_steal_ms = Vec::new();
    let result = (|| -> Result<()> {
        // a quick run has no warm-up round (the first samples of each batch are still dropped)
        for round in usize::from(opts.quick)..=opts.rounds {
            let t_round = Instant::now();
            let steal0 = steal_ms();
            for &size in &opts.sizes {
                let idx: Vec<usize> = (0..pingers.len()).filter(|&i| pingers[i].0 == size).collect();
                for i in Rounds::order(&idx, round) {
                    let v = pingers[i]
                        .2
                        .batch(&robot, count_of(size))
                        .with_context(|| format!("{} at {} B, round {round}", pingers[i].1, size))?;
                    rounds.keep(i, round, &v);
                    if round > 0
                        && let Some(same) = pingers[i].2.same_cpu()
                    {
                        placement[i].0 += same;
                        placement[i].1 += v.len();
                    }
                }
                if let Some(peer) = &dds_peer {
                    let secs = if opts.quick {
                        1
                    } else if size > 1_000_000 {
                        4
                    } else {
                        2
                    };
                    let v = peer.batch(size, secs).with_context(|| format!("ddsperf at {size} B, round {round}"))?;
                    if round > 0
                        && let Some(d) = dds_intervals.iter_mut().find(|d| d.0 == size)
                    {
                        d.2.push(dds::summarise(&v).p50_ns);
                        d.1.extend(v);
                    }
                }
            }
            let what = if round == 0 { "warm-up".to_owned() } else { format!("round {round}/{}", opts.rounds) };
            let stolen = steal0.zip(steal_ms()).map(|(a, b)| b - a);
            let stolen_note = stolen.map(|s| format!(" (time stolen by the host: {s:.0} ms)")).unwrap_or_default();
            eprintln!("hop: {what} done in {:.1} s{stolen_note}", t_round.elapsed().as_secs_f64());
            if let (Some(s), true) = (stolen, round > 0) {
                round_steal_ms.push(s);
            }
            for &size in &opts.sizes {
                if round == 0 {
                    break;
                }
                let line: Vec<String> = pingers
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| p.0 == size)
                    .map(|(i, p)| {
                        format!("{} {:.1}us", p.1, rounds.round_p50[i].last().copied().unwrap_or(0) as f64 / 1e3)
                    })
                    .collect();
                eprintln!("  {:>7}: {}", label(size), line.join(", "));
            }
        }
        Ok(())
    })();
    normal_priority();
    let keys: Vec<(usize, &'static str)> = pingers.iter().map(|p| (p.0, p.1)).collect();
    drop(pingers);
    drop(dds_peer);
    let dora_version = dora_peer.as_ref().map(|p| p.version.clone());
    drop(dora_peer);
    for mut c in children.drain(..) {
        c.stop(Duration::from_secs(2));
    }
    result?;

    let mut results = Vec::new();
    for &size in &opts.sizes {
        for t in TRANSPORTS {
            if t == "ddsperf" {
                if let Some((_, iv, dds_round_p50)) = dds_intervals.iter().find(|d| d.0 == size && !d.1.is_empty()) {
                    results.push(HopResult {
                        transport: t.into(),
                        size,
                        label: label(size).into(),
                        rtt: dds::summarise(iv),
                        round_p50_ns: dds_round_p50.clone(),
                        same_cpu_share: None,
                    });
                }
                continue;
            }
            let Some(i) = keys.iter().position(|k| *k == (size, t)) else {
                if t.starts_with("dora") || t.starts_with("nerve-python") {
                    continue;
                }
                bail!("internal: no samples for {t} {size}");
            };
            results.push(HopResult {
                transport: t.into(),
                size,
                label: label(size).into(),
                rtt: Summary::of(&rounds.samples[i]),
                round_p50_ns: rounds.round_p50[i].clone(),
                same_cpu_share: (placement[i].1 > 0).then(|| placement[i].0 as f64 / placement[i].1 as f64),
            });
        }
    }
    let mut periodic = Vec::new();
    for &size in &opts.sizes {
        for t in PERIODIC {
            if let Some(i) = keys.iter().position(|k| *k == (size, t)) {
                periodic.push(OneWayResult {
                    transport: t.into(),
                    size,
                    label: label(size).into(),
                    one_way: Summary::of(&rounds.samples[i]),
                    round_p50_ns: rounds.round_p50[i].clone(),
                });
            }
        }
    }
    let find = |t: &str, s: usize| results.iter().find(|r| r.transport == t && r.size == s);
    let find_periodic = |t: &str, s: usize| periodic.iter().find(|r| r.transport == t && r.size == s);
    let mut ratios = Vec::new();
    for &size in &opts.sizes {
        let (Some(n), Some(w), Some(l), Some(f), Some(u)) = (
            find("nerve", size),
            find("iox2-waitset", size),
            find("iox2-listener", size),
            find("iox2-waitset-fill", size),
            find("uds", size),
        ) else {
            continue;
        };
        let per_round: Vec<f64> = n.round_p50_ns.iter().zip(&w.round_p50_ns).map(|(a, b)| ratio(*a, *b)).collect();
        let r = ratio(n.rtt.p50_ns, w.rtt.p50_ns);
        let dora = find("dora", size);
        let dora_5ms = match (find_periodic("dora-5ms", size), find_periodic("nerve-5ms", size)) {
            (Some(d), Some(n5)) => {
                Some((ratio(d.one_way.p50_ns, n5.one_way.p50_ns), ratio(d.one_way.p99_ns, n5.one_way.p99_ns)))
            }
            _ => None,
        };
        let dora_p50 = dora.map(|d| ratio(d.rtt.p50_ns, n.rtt.p50_ns));
        let p50 = |t: &str| find(t, size).map(|x| x.rtt.p50_ns);
        let both = |a: Option<u64>, b: Option<u64>| a.zip(b).map(|(a, b)| ratio(a, b));
        let one_way_p50 = |t: &str| find_periodic(t, size).map(|x| x.one_way.p50_ns);
        let dora_pmqos = both(p50("dora-pmqos"), p50("nerve-pmqos"));
        let dora_5ms_pmqos = both(one_way_p50("dora-5ms-pmqos"), one_way_p50("nerve-5ms-pmqos"));
        let nerve_pmqos_vs_futex_pmqos = both(p50("nerve-pmqos"), p50("futex-pmqos"));
        ratios.push(HopRatio {
            size,
            nerve_vs_waitset_p50: r,
            nerve_vs_waitset_p99: ratio(n.rtt.p99_ns, w.rtt.p99_ns),
            nerve_vs_waitset_p50_round_median: median_f64(&per_round),
            nerve_vs_listener_p50: ratio(n.rtt.p50_ns, l.rtt.p50_ns),
            nerve_vs_listener_p99: ratio(n.rtt.p99_ns, l.rtt.p99_ns),
            nerve_vs_waitset_fill_p50: ratio(n.rtt.p50_ns, f.rtt.p50_ns),
            nerve_vs_waitset_fill_p99: ratio(n.rtt.p99_ns, f.rtt.p99_ns),
            uds_vs_nerve_p50: ratio(u.rtt.p50_ns, n.rtt.p50_ns),
            dds_vs_nerve_p50: find("ddsperf", size).map(|d| ratio(d.rtt.p50_ns, n.rtt.p50_ns)),
            nerve_poll_vs_iox2_poll_p50: match (find("nerve-poll", size), find("iox2-poll", size)) {
                (Some(a), Some(b)) => Some(ratio(a.rtt.p50_ns, b.rtt.p50_ns)),
                _ => None,
            },
            dora_vs_nerve_p50: dora_p50,
            dora_vs_nerve_p99: dora.map(|d| ratio(d.rtt.p99_ns, n.rtt.p99_ns)),
            dora_5ms_vs_nerve_5ms_p50: dora_5ms.map(|x| x.0),
            dora_5ms_vs_nerve_5ms_p99: dora_5ms.map(|x| x.1),
            dora_target_met: match (dora_p50, dora_5ms) {
                (Some(a), Some((b, _))) => Some(a >= DORA_TARGET && b >= DORA_TARGET),
                _ => None,
            },
            dora_pmqos_vs_nerve_pmqos_p50: dora_pmqos,
            dora_5ms_pmqos_vs_nerve_5ms_pmqos_p50: dora_5ms_pmqos,
            dora_target_met_pmqos: dora_pmqos.zip(dora_5ms_pmqos).map(|(a, b)| a >= DORA_TARGET && b >= DORA_TARGET),
            dora_5ms_pinned_vs_nerve_5ms_pinned_p50: both(
                one_way_p50("dora-5ms-pinned"),
                one_way_p50("nerve-5ms-pinned"),
            ),
            dora_5ms_pinned_pmqos_vs_nerve_5ms_pinned_pmqos_p50: both(
                one_way_p50("dora-5ms-pinned-pmqos"),
                one_way_p50("nerve-5ms-pinned-pmqos"),
            ),
            pinned_gain_nerve_5ms_pmqos: both(one_way_p50("nerve-5ms-pmqos"), one_way_p50("nerve-5ms-pinned-pmqos")),
            dora_vs_nerve_pmqos_p50: both(p50("dora"), p50("nerve-pmqos")),
            target_met: r <= TARGET_RATIO,
            nerve_vs_futex_p50: both(p50("nerve"), p50("futex")),
            nerve_pmqos_vs_futex_pmqos_p50: nerve_pmqos_vs_futex_pmqos,
            nerve_pmqos_vs_futex_p50: both(p50("nerve-pmqos"), p50("futex")),
            futex_target_met: nerve_pmqos_vs_futex_pmqos.map(|x| x <= FUTEX_TARGET),
            nerve_pmqos_vs_waitset_pmqos_p50: both(p50("nerve-pmqos"), p50("iox2-waitset-pmqos")),
            pmqos_gain_nerve: both(p50("nerve"), p50("nerve-pmqos")),
            pinned_gain_nerve: both(p50("nerve"), p50("nerve-pinned")),
            nerve_pinned_vs_futex_pinned_p50: both(p50("nerve-pinned"), p50("futex-pinned")),
            python_vs_nerve_p50: both(p50("nerve-python"), p50("nerve")),
            python_vs_nerve_p99: find("nerve-python", size).map(|x| ratio(x.rtt.p99_ns, n.rtt.p99_ns)),
            python_target_met: both(p50("nerve-python"), p50("nerve")).map(|x| x <= PYTHON_TARGET),
            python_pmqos_vs_nerve_pmqos_p50: both(p50("nerve-python-pmqos"), p50("nerve-pmqos")),
        });
    }
    drop(_router);
    drop(robot);
    Ok(HopReport {
        scenario: "hop",
        command: command_line(),
        machine,
        rounds: opts.rounds,
        batch: counts,
        results,
        periodic,
        periodic_batch: periodic_count,
        dora_version,
        ratios,
        target_ratio: TARGET_RATIO,
        dora_target_ratio: DORA_TARGET,
        fill_cost: opts.sizes.iter().map(|&s| measure_fill(s)).collect(),
        idle,
        futex_target_ratio: FUTEX_TARGET,
        round_steal_ms,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// A markdown table of latencies: payload, `who` (transport or system), n, median, p99, max.
fn latency_table<'a>(who: &str, rows: impl Iterator<Item = (&'a str, &'a str, &'a Summary)>) {
    println!("| payload | {who} | n | median µs | p99 µs | max µs |");
    println!("|---|---|---:|---:|---:|---:|");
    for (label, transport, x) in rows {
        println!(
            "| {label} | {transport} | {} | {} | {} | {} |",
            x.n,
            crate::stats::us(x.p50_ns),
            crate::stats::us(x.p99_ns),
            crate::stats::us(x.max_ns)
        );
    }
}

/// Prints the tables of a hop report (markdown).
pub fn print_tables(r: &HopReport) {
    latency_table("transport", r.results.iter().map(|x| (x.label.as_str(), x.transport.as_str(), &x.rtt)));
    println!();
    println!(
        "| payload | nerve/iox2-waitset p50 | (median of rounds) | p99 | nerve/iox2-listener p50 | p99 | nerve/iox2-waitset-fill p50 | p99 | uds/nerve p50 | ddsperf/nerve p50 | nerve-poll/iox2-poll p50 | target ≤{TARGET_RATIO} |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for x in &r.ratios {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} |",
            label(x.size),
            x.nerve_vs_waitset_p50,
            x.nerve_vs_waitset_p50_round_median,
            x.nerve_vs_waitset_p99,
            x.nerve_vs_listener_p50,
            x.nerve_vs_listener_p99,
            x.nerve_vs_waitset_fill_p50,
            x.nerve_vs_waitset_fill_p99,
            x.uds_vs_nerve_p50,
            ratio_cell(x.dds_vs_nerve_p50),
            ratio_cell(x.nerve_poll_vs_iox2_poll_p50),
            if x.target_met { "met" } else { "missed" }
        );
    }
    println!();
    println!("The wake-up floor and PM QoS, same run (nerve-pmqos is nerve as its agents run by default):");
    println!();
    println!(
        "| payload | nerve/futex p50 (no PM QoS) | nerve-pmqos/futex-pmqos | nerve-pmqos/futex | nerve-pmqos/iox2-waitset-pmqos | nerve/nerve-pmqos | nerve/nerve-pinned | nerve-pinned/futex-pinned | target ≤{FUTEX_TARGET} |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---|");
    for x in &r.ratios {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            label(x.size),
            ratio_cell(x.nerve_vs_futex_p50),
            ratio_cell(x.nerve_pmqos_vs_futex_pmqos_p50),
            ratio_cell(x.nerve_pmqos_vs_futex_p50),
            ratio_cell(x.nerve_pmqos_vs_waitset_pmqos_p50),
            ratio_cell(x.pmqos_gain_nerve),
            ratio_cell(x.pinned_gain_nerve),
            ratio_cell(x.nerve_pinned_vs_futex_pinned_p50),
            verdict(x.futex_target_met)
        );
    }
    let placed: Vec<String> = r
        .results
        .iter()
        .filter_map(|x| x.same_cpu_share.map(|s| format!("{} {}: {:.0}%", x.transport, x.label, s * 100.0)))
        .collect();
    if !placed.is_empty() {
        println!();
        println!("round trips whose two ends ran on one CPU: {}", placed.join(", "));
    }
    for i in &r.idle {
        let states: Vec<String> = i.states.iter().map(|(n, v)| format!("{n} {:.1}%", v * 100.0)).collect();
        println!(
            "idle robot, {:.0} s {}: CPUs busy {:.1}%, idle in {}",
            i.seconds,
            if i.pm_qos { "holding PM QoS at 0" } else { "without PM QoS" },
            i.busy * 100.0,
            states.join(", ")
        );
    }
    if !r.periodic.is_empty() {
        println!();
        println!(
            "One way, one sample every {} ms (dora's own pattern), {} samples per batch:",
            dora::PERIOD_US / 1000,
            r.periodic_batch
        );
        println!();
        latency_table("system", r.periodic.iter().map(|x| (x.label.as_str(), x.transport.as_str(), &x.one_way)));
    }
    if r.ratios.iter().any(|x| x.python_vs_nerve_p50.is_some()) {
        println!();
        println!("A Python pong (bench/py/pong.py, the nerve package) against a Rust one, same run:");
        println!();
        println!(
            "| payload | nerve-python/nerve p50 | p99 | target ≤{PYTHON_TARGET} | nerve-python-pmqos/nerve-pmqos p50 |"
        );
        println!("|---|---:|---:|---|---:|");
        for x in &r.ratios {
            println!(
                "| {} | {} | {} | {} | {} |",
                label(x.size),
                ratio_cell(x.python_vs_nerve_p50),
                ratio_cell(x.python_vs_nerve_p99),
                verdict(x.python_target_met),
                ratio_cell(x.python_pmqos_vs_nerve_pmqos_p50)
            );
        }
    }
    if let Some(v) = &r.dora_version {
        println!();
        println!("dora ({v}) against nerve, same run:");
        println!();
        println!(
            "| payload | dora/nerve p50 (round trip) | p99 | dora-5ms/nerve-5ms p50 (one way, 5 ms) | p99 | target ≥{DORA_TARGET} | both under PM QoS 0: round trip | one way, 5 ms | target ≥{DORA_TARGET} | dora/nerve-pmqos (each by default) |"
        );
        println!("|---|---:|---:|---:|---:|---|---:|---:|---|---:|");
        for x in &r.ratios {
            println!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                label(x.size),
                ratio_cell(x.dora_vs_nerve_p50),
                ratio_cell(x.dora_vs_nerve_p99),
                ratio_cell(x.dora_5ms_vs_nerve_5ms_p50),
                ratio_cell(x.dora_5ms_vs_nerve_5ms_p99),
                verdict(x.dora_target_met),
                ratio_cell(x.dora_pmqos_vs_nerve_pmqos_p50),
                ratio_cell(x.dora_5ms_pmqos_vs_nerve_5ms_pmqos_p50),
                verdict(x.dora_target_met_pmqos),
                ratio_cell(x.dora_vs_nerve_pmqos_p50)
            );
        }
        if r.ratios.iter().any(|x| x.dora_5ms_pinned_vs_nerve_5ms_pinned_p50.is_some()) {
            println!();
            println!(
                "dora's pattern with each system's two ends on CPU {PINNED_CPU} (router and dora's daemon free), same run:"
            );
            println!();
            println!(
                "| payload | dora-5ms-pinned/nerve-5ms-pinned p50 | both under PM QoS 0 | target ≥{DORA_TARGET} | nerve-5ms-pmqos/nerve-5ms-pinned-pmqos (what one CPU buys nerve) |"
            );
            println!("|---|---:|---:|---|---:|");
            for x in &r.ratios {
                let met = x.dora_5ms_pinned_pmqos_vs_nerve_5ms_pinned_pmqos_p50.map(|v| v >= DORA_TARGET);
                println!(
                    "| {} | {} | {} | {} | {} |",
                    label(x.size),
                    ratio_cell(x.dora_5ms_pinned_vs_nerve_5ms_pinned_p50),
                    ratio_cell(x.dora_5ms_pinned_pmqos_vs_nerve_5ms_pinned_pmqos_p50),
                    verdict(met),
                    ratio_cell(x.pinned_gain_nerve_5ms_pmqos)
                );
            }
        }
    }
    println!();
    for f in &r.fill_cost {
        println!(
            "fill cost {}: memset of the whole payload {} µs warm, {} µs cold",
            label(f.size),
            crate::stats::us(f.memset_warm_p50_ns),
            crate::stats::us(f.memset_cold_p50_ns)
        );
    }
}

/// Where batch files of a run go.
pub fn work_dir(out: &Path) -> PathBuf {
    out.join(format!("hop-work-{}", std::process::id()))
}
