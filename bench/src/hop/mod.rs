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
//! * `nerve-poll` and `iox2-poll`: both sides busy-polling instead of
//!   sleeping (the SDK's polling mode, `--poll`, issue 42; raw iceoryx2
//!   spinning on `Subscriber::receive`), both at SCHED_OTHER with the ping
//!   on CPU 0 and the pong on CPU 1 (nerve's pollers cannot be real-time
//!   on two CPUs, see [`nerve`]; until 2026-11-29 the raw pair ran at
//!   SCHED_FIFO and only nerve's was preempted on a loaded machine);
//!   `iox2-poll-ts`: the raw polling pair on `ipc_threadsafe::Service`,
//!   the service type of nerve's ports (see [`crate::raw`]);
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
//!
//! `--rows` measures only the rows it names, e.g. `--rows
//! nerve-poll,iox2-poll,iox2-poll-ts` (the polling pairs, a 16 s run at
//! 8 B): the nerve agents of every row still start and idle, and dora,
//! Python and Cyclone DDS start only when one of their rows is named.
//!
//! The scenario's files, by transport: [`nerve`] (the SDK agents, wired
//! through the router), [`python`] (the Python pong), [`floors`] (raw
//! iceoryx2, the Unix socket and the futex), [`dora_rows`] (dora-rs and
//! nerve in dora's pattern); [`pinger`] (a batch of round trips, and the
//! PM QoS and pinned rows), [`rounds`] (the interleaved batches), [`report`]
//! (results and ratios) and [`tables`].

mod dora_rows;
mod floors;
mod nerve;
mod pinger;
mod python;
mod report;
mod rounds;
mod tables;

pub(crate) use nerve::{NervePing, size_tag, spawn_bench_agent};
pub(crate) use pinger::{Pinger, Row, pm_qos_permitted};
pub use report::{HopReport, HopResults};
pub use tables::print_tables;

use crate::dds::{self, DdsPeer};
use crate::dora::DoraPeer;
use crate::machine::Machine;
use crate::payloads::SIZES;
use crate::procs::{ChildGuard, Robot, normal_priority, realtime_like_an_agent};
use crate::report::Report;
use anyhow::{Result, bail};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Samples dropped at the start of every batch.
const DISCARD: usize = 5;
/// The transports, in the order of the tables.
pub const TRANSPORTS: [&str; 20] = [
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
    "iox2-poll-ts",
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
/// nerve's polling round trip may be this many times raw iceoryx2 polling's (issue 42).
pub const POLL_TARGET: f64 = 1.5;
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
    /// only these rows (`--rows`); None for all
    pub rows: Option<Vec<String>>,
    /// show children's output
    pub verbose: bool,
    /// where batch files go
    pub work: PathBuf,
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

impl HopOpts {
    /// Whether row `row` is measured (`--rows`, or all).
    pub(crate) fn wants(&self, row: &str) -> bool {
        self.rows.as_ref().is_none_or(|rows| rows.iter().any(|r| r == row))
    }

    /// Whether any row starting with `prefix` is measured.
    fn wants_any(&self, prefix: &str) -> bool {
        self.rows.as_ref().is_none_or(|rows| rows.iter().any(|r| r.starts_with(prefix)))
    }
}

/// Refuses a `--rows` name that is no row of the scenario.
fn check_rows(opts: &HopOpts) -> Result<()> {
    for r in opts.rows.iter().flatten() {
        if !TRANSPORTS.contains(&r.as_str()) && !PERIODIC.contains(&r.as_str()) {
            bail!("--rows: no row {r:?}; the rows are {} and {}", TRANSPORTS.join(","), PERIODIC.join(","));
        }
    }
    Ok(())
}

/// Round trips per batch at `size` ([`HopOpts::count`] or the default).
fn count_of(counts: &[(usize, usize)], size: usize) -> usize {
    counts.iter().find(|(x, _)| *x == size).map(|(_, c)| *c).unwrap_or(100)
}

/// Runs the hop scenario: a robot with its router, the nerve agents wired
/// and the other transports' pongs started, one batch per row and size in
/// every round, then the report.
pub fn run(opts: &HopOpts) -> Result<HopReport> {
    let started = Instant::now();
    let machine = Machine::probe();
    for s in &opts.sizes {
        if !SIZES.contains(s) {
            bail!("no payload of {s} bytes; use 8, 230400 or 6220800");
        }
    }
    check_rows(opts)?;
    let counts: Vec<(usize, usize)> =
        opts.sizes.iter().map(|&s| (s, opts.count.unwrap_or_else(|| default_count(s, opts.quick)))).collect();

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
    let router = robot.start_router()?;
    let dora = if opts.wants_any("dora") || opts.wants_any("nerve-5ms") { dora_rows::find_peer(opts) } else { None };
    let periodic_count = if opts.quick { PERIODIC_COUNT.1 } else { PERIODIC_COUNT.0 };
    let python = if opts.wants_any("nerve-python") { python::find() } else { None };
    let agents = nerve::Agents { python: python.as_deref(), periodic: dora.is_some(), periodic_count };
    let mut children = nerve::start(&robot, opts, &counts, &agents)?;
    eprintln!("hop: nerve agents running and connected");
    let (pongs, mut floor_pings) = floors::start_pongs(&robot, opts)?;
    children.extend(pongs);

    let pingers = pingers(&robot, opts, &mut floor_pings, python.is_some(), dora.as_ref(), periodic_count)?;
    let mut pingers = pinger::with_pm_qos_rows(pingers, pm_qos_permitted("hop"));
    pingers.retain(|p| opts.wants(p.1));
    // where an idle robot's CPUs spend their time, without and with the bound
    let idle_span = Duration::from_secs(if opts.quick { 1 } else { 3 });
    let idle = vec![crate::idle::measure(false, idle_span), crate::idle::measure(true, idle_span)];
    let dds_peer = if opts.wants("ddsperf") { start_dds(opts)? } else { None };
    // from here on this thread runs like an agent's task
    realtime_like_an_agent(20);
    let mut measured = rounds::Measured::new(pingers.len(), &opts.sizes);
    let result = rounds::measure(&robot, opts, &counts, &mut pingers, dds_peer.as_ref(), &mut measured);
    normal_priority();
    let keys: Vec<(usize, &'static str)> = pingers.iter().map(|p| (p.0, p.1)).collect();
    drop(pingers);
    drop(dds_peer);
    let dora_version = dora.as_ref().map(|p| p.version.clone());
    drop(dora);
    stop_all(children);
    result?;

    let results = report::round_trips(&opts.sizes, &keys, &measured, |t| opts.wants(t))?;
    let periodic = report::one_way(&opts.sizes, &keys, &measured.rounds);
    let ratios = report::ratios(&opts.sizes, &results, &periodic);
    drop(router);
    drop(robot);
    Ok(Report::new(
        "hop",
        machine,
        HopResults {
            rounds: opts.rounds,
            batch: counts,
            results,
            periodic,
            periodic_batch: periodic_count,
            dora_version,
            ratios,
            target_ratio: TARGET_RATIO,
            dora_target_ratio: DORA_TARGET,
            fill_cost: opts.sizes.iter().map(|&s| report::measure_fill(s)).collect(),
            idle,
            futex_target_ratio: FUTEX_TARGET,
            round_steal_ms: measured.round_steal_ms,
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
}

/// The ping side of every row, in table order within each size (the order
/// [`crate::stats::Rounds::order`] interleaves).
fn pingers(
    robot: &Robot,
    opts: &HopOpts,
    floor_pings: &mut floors::Pings,
    python: bool,
    dora: Option<&std::rc::Rc<DoraPeer>>,
    periodic_count: usize,
) -> Result<pinger::Pingers> {
    let mut pingers = Vec::new();
    for &size in &opts.sizes {
        floors::push_socket_and_futex(&mut pingers, size, floor_pings);
        nerve::push_pingers(&mut pingers, size, opts, python);
        floors::push_iox2(&mut pingers, size, robot)?;
        if let Some(peer) = dora {
            dora_rows::push_pingers(&mut pingers, size, opts, peer, periodic_count);
        }
    }
    Ok(pingers)
}

/// Cyclone DDS's ping-pong, when installed.
fn start_dds(opts: &HopOpts) -> Result<Option<DdsPeer>> {
    if dds::available() {
        Ok(Some(DdsPeer::start(opts.verbose)?))
    } else {
        eprintln!("hop: warning: `ddsperf` not found (apt-get install cyclonedds-tools); no Cyclone DDS row");
        Ok(None)
    }
}

/// Stops every child (SIGTERM, 2 s, SIGKILL), in the order they started.
fn stop_all(mut children: Vec<ChildGuard>) {
    for mut c in children.drain(..) {
        c.stop(Duration::from_secs(2));
    }
}

/// Where batch files of a run go.
pub fn work_dir(out: &Path) -> PathBuf {
    out.join(format!("hop-work-{}", std::process::id()))
}
