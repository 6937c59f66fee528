//! Scenario `bridge`: what the Zenoh bridge agent costs, measured side by
//! side, batch by batch interleaved (the order rotates every round), in one
//! run over loopback.
//!
//! 1. **Across the bridge**, one way, for 8 B, 4 KB and 230 KB:
//!    * `bridge`: a sender SDK agent in robot A (`b<pid>a`) publishes samples
//!      stamped with CLOCK_MONOTONIC; bridge A exports the port; bridge B
//!      (robot `b<pid>b`) imports it; a sink SDK agent in robot B, wired to
//!      the import with `nerve connect`, records `arrival - stamp` (same
//!      host, one clock: one way is valid). The sink also reads the header
//!      stamp of the last hop (when bridge B published the sample), which
//!      splits the path into "A to bridge B" and "bridge B to the sink";
//!    * `bridge-tls`: the same across a second pair of bridges (`tbridge` in
//!      both robots, its own sender `ksrc-<size>` and sink `ksink-<size>`)
//!      linked by mutual TLS (`tls/127.0.0.1`, a fleet CA and one
//!      certificate per robot made with `nerve bridge keys init/add` in the
//!      run's work dir, `[tls]` in both configs): what TLS costs against the
//!      plain pair, measured in the same rounds (latency only, not
//!      throughput);
//!    * `zenoh`: raw Zenoh publish-subscribe between two plain processes
//!      ([`crate::zenoh_raw`]) with the bridge's settings (peer mode,
//!      explicit tcp/127.0.0.1 endpoints, no multicast scouting, express,
//!      `CongestionControl::Drop`): the floor.
//!
//!    Latency: one sample every `--interval-us` (5 ms), `--count` per batch.
//!    Throughput: samples sent back to back for at most `--tput-ms`; what is
//!    delivered per second at the far end (both paths drop under overload:
//!    the bridge's best-effort topics keep the newest, Zenoh drops on
//!    congestion).
//! 2. **A bridge on the local data path**: the one-hop round trip of `hop`
//!    (its ping and pong SDK agents) in robot A, three pairs per size:
//!    `alone` (no bridge reads the ping's port), `bridged` (bridge A exports
//!    the ping's port and bridge B imports it: every sample also crosses to
//!    robot B) and `bridged-100hz` (the same export limited to 100 Hz, as a
//!    sensor stream on a radio link would be).
//!
//! Both robots, their routers, the bridges (run through `__bridge`, which
//! carries the benchmark's payload types), the agents and the raw Zenoh
//! processes are stopped at the end, and each robot is taken down with
//! `nerve down`. Zenoh listens on free ports of 127.0.0.1 (bound to port 0
//! to find them).

use crate::agents::read_values;
use crate::bridge_agents::{SETTLE, read_rows, take_sink_batch};
use crate::hop::{NervePing, size_tag, spawn_bench_agent};
use crate::machine::Machine;
use crate::payloads::label;
use crate::procs::{ChildGuard, Robot, self_command, wait_file_after};
use crate::report::Report;
use crate::stats::{Rounds, Summary, median_f64, ratio, us};
use crate::with_payload;
use anyhow::{Context as _, Result, anyhow, bail};
use serde::Serialize;
use shm_schemas::Payload as _;
use std::io::{BufRead as _, Write as _};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// The payload sizes of the scenario.
pub const SIZES: [usize; 3] = [8, 4096, 230_400];
/// Across the bridge, one way, the bridge may be this much slower than raw Zenoh (median).
pub const ONEWAY_TARGET: f64 = 1.2;
/// A bridge on the port may slow the local round trip by this much (median).
pub const LOCAL_TARGET: f64 = 1.05;
/// Across the bridge, one way, the TLS pair may be this much slower than the plain pair (median).
pub const TLS_TARGET: f64 = 1.15;
/// Samples dropped at the start of every batch.
const DISCARD: usize = 5;
/// The one-way systems, in the order of the tables.
pub const ONEWAY: [&str; 3] = ["bridge", "zenoh", "bridge-tls"];
/// The throughput systems (the first two one-way systems).
pub const TPUT: [&str; 2] = ["bridge", "zenoh"];
/// The local round-trip systems, in the order of the tables.
pub const LOCAL: [&str; 3] = ["alone", "bridged", "bridged-100hz"];
/// Samples per throughput batch at most: a cap no sender reaches in
/// `tput_ms`, so that every throughput batch is bounded by time (the SDK
/// sender, zero copy, puts out over a million samples a second).
const TPUT_CAP: usize = 20_000_000;

/// Options of the bridge scenario.
#[derive(Debug, Clone)]
pub struct BridgeOpts {
    /// smoke run
    pub quick: bool,
    /// payload sizes (bytes)
    pub sizes: Vec<usize>,
    /// measured rounds (a warm-up round comes first unless quick)
    pub rounds: usize,
    /// one-way samples per latency batch
    pub count: usize,
    /// µs between two samples of a latency batch
    pub interval_us: u64,
    /// longest throughput batch, ms
    pub tput_ms: u64,
    /// round trips per local batch
    pub hop_count: usize,
    /// show children's output
    pub verbose: bool,
    /// where batch and config files go
    pub work: PathBuf,
}

/// One-way latency of one system at one size.
#[derive(Debug, Clone, Serialize)]
pub struct OneWayResult {
    /// `bridge`, `zenoh` or `bridge-tls`
    pub system: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// all measured samples pooled (sender's stamp to arrival)
    pub latency: Summary,
    /// median of each round, ns
    pub round_p50_ns: Vec<u64>,
    /// samples sent in measured batches
    pub sent: u64,
    /// samples that never arrived
    pub lost: u64,
    /// bridges: sender's stamp to bridge B's publication (robot A's hop, bridge A, Zenoh, bridge B)
    pub to_bridge_b: Option<Summary>,
    /// bridges: bridge B's publication to the sink (robot B's hop)
    pub bridge_b_to_sink: Option<Summary>,
    /// bridges: from bridge A taking the sample off its input to bridge B
    /// receiving it, µs: the bridge's own `latency_us` figure at the end of
    /// the run (median of the topic's last 256 samples, so of the last batch
    /// only, CLOCK_REALTIME stamps); not comparable with the pooled medians
    pub bridge_a_to_b_us: Option<u64>,
}

/// Throughput of one system at one size.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputResult {
    /// `bridge` or `zenoh`
    pub system: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// samples delivered per second at the far end, median of the rounds
    pub delivered_per_s: f64,
    /// samples the sender put out per second, median of the rounds
    pub offered_per_s: f64,
    /// delivered / sent, over all measured batches
    pub delivered_fraction: f64,
    /// payload MB/s delivered (10^6 B), median of the rounds
    pub delivered_mb_per_s: f64,
    /// one-way latency of the delivered samples under that load, pooled
    pub latency_loaded: Summary,
    /// delivered per second of each round
    pub round_delivered_per_s: Vec<f64>,
}

/// The bridge against raw Zenoh at one size.
#[derive(Debug, Clone, Serialize)]
pub struct OneWayRatio {
    /// payload bytes
    pub size: usize,
    /// bridge p50 / zenoh p50 (pooled)
    pub bridge_vs_zenoh_p50: f64,
    /// bridge p99 / zenoh p99
    pub bridge_vs_zenoh_p99: f64,
    /// median over rounds of the per-round p50 ratio
    pub bridge_vs_zenoh_p50_round_median: f64,
    /// bridge delivered/s / zenoh delivered/s at full speed
    pub throughput_bridge_vs_zenoh: f64,
    /// what the bridge adds to raw Zenoh at the median, ns
    pub extra_p50_ns: i64,
    /// one local hop (half the `alone` round trip's median), ns; 0 when not measured
    pub local_hop_p50_ns: u64,
    /// whether bridge p50 ≤ target × zenoh p50
    pub target_met: bool,
    /// bridge-tls p50 / bridge p50 (pooled); 0 when not measured
    pub tls_vs_plain_p50: f64,
    /// bridge-tls p99 / bridge p99
    pub tls_vs_plain_p99: f64,
    /// median over rounds of the per-round p50 ratio bridge-tls / bridge
    pub tls_vs_plain_p50_round_median: f64,
    /// what TLS adds to the plain bridge at the median, ns
    pub tls_extra_p50_ns: i64,
    /// whether bridge-tls p50 ≤ TLS target × bridge p50
    pub tls_target_met: bool,
}

/// A local round trip at one size.
#[derive(Debug, Clone, Serialize)]
pub struct LocalResult {
    /// `alone`, `bridged`, `bridged-100hz`
    pub system: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// all measured round trips pooled
    pub rtt: Summary,
    /// median of each round, ns
    pub round_p50_ns: Vec<u64>,
}

/// The local round trip with a bridge against without, at one size.
#[derive(Debug, Clone, Serialize)]
pub struct LocalRatio {
    /// payload bytes
    pub size: usize,
    /// bridged p50 / alone p50 (pooled)
    pub bridged_vs_alone_p50: f64,
    /// bridged p99 / alone p99
    pub bridged_vs_alone_p99: f64,
    /// median over rounds of the per-round p50 ratio
    pub bridged_vs_alone_p50_round_median: f64,
    /// bridged-100hz p50 / alone p50
    pub limited_vs_alone_p50: f64,
    /// bridged-100hz p99 / alone p99
    pub limited_vs_alone_p99: f64,
    /// whether bridged p50 ≤ target × alone p50
    pub target_met: bool,
}

/// The bridge report: the [`Head`](crate::report::Head) and [`BridgeResults`].
pub type BridgeReport = Report<BridgeResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Clone, Serialize)]
pub struct BridgeResults {
    /// measured rounds
    pub rounds: usize,
    /// one-way samples per latency batch
    pub count: usize,
    /// µs between two samples of a latency batch
    pub interval_us: u64,
    /// longest throughput batch, ms
    pub tput_ms: u64,
    /// round trips per local batch
    pub hop_count: usize,
    /// one-way latency, per system and size
    pub oneway: Vec<OneWayResult>,
    /// throughput, per system and size
    pub throughput: Vec<ThroughputResult>,
    /// bridge against raw Zenoh, per size
    pub oneway_ratios: Vec<OneWayRatio>,
    /// local round trips, per system and size
    pub local: Vec<LocalResult>,
    /// bridged against alone, per size
    pub local_ratios: Vec<LocalRatio>,
    /// one-way target (bridge / zenoh, p50)
    pub oneway_target: f64,
    /// local target (bridged / alone, p50)
    pub local_target: f64,
    /// TLS target (bridge-tls / bridge, p50)
    pub tls_target: f64,
    /// bridge-tls p50 / bridge p50 per size, pooled, as top-level fields
    /// `tls_vs_plain_p50_8B`, `tls_vs_plain_p50_4KB`, `tls_vs_plain_p50_230KB`
    #[serde(flatten)]
    pub tls_vs_plain: std::collections::BTreeMap<String, f64>,
    /// `nerve bridge status --json` of robots A and B at the end (figures: messages, drops...)
    pub bridge_status: Vec<serde_json::Value>,
    /// wall time of the run, s
    pub seconds: f64,
}

/// `s` as a TOML basic string (quotes and backslashes escaped).
fn toml_str(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

/// A free TCP port on 127.0.0.1 (bound to port 0, then released).
fn free_port() -> Result<u16> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").context("cannot bind 127.0.0.1:0 to find a free port")?;
    Ok(l.local_addr().context("local address")?.port())
}

/// `8B`, `4KB`, `230KB`: a size in a JSON field name (its label without spaces).
fn size_key(size: usize) -> String {
    label(size).replace(' ', "")
}

fn type_name(size: usize) -> Result<&'static str> {
    with_payload!(size, P => Ok(P::stable_type_name()), _ => bail!("no payload of {size} bytes; use 8, 4096 or 230400"))
}

/// A child driven by lines on stdin, answering lines on stdout.
struct LineChild {
    what: String,
    guard: ChildGuard,
    stdin: std::process::ChildStdin,
    lines: mpsc::Receiver<String>,
}

impl LineChild {
    fn spawn(what: &str, mut cmd: std::process::Command, verbose: bool) -> Result<Self> {
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

    fn ask(&mut self, line: &str, timeout: Duration) -> Result<String> {
        writeln!(self.stdin, "{line}")
            .and_then(|()| self.stdin.flush())
            .with_context(|| format!("{}: stdin", self.what))?;
        self.read(timeout)
    }
}

/// What one batch across a path gave.
#[derive(Debug, Default)]
struct Batch {
    sent: u64,
    t_start: u64,
    t_end: u64,
    /// (sender's stamp, last hop's stamp or 0, arrival), in arrival order
    rows: Vec<[u64; 3]>,
}

/// One SDK path across the bridge: a sender in robot A, a sink in robot B.
struct SdkPath {
    src: String,
    sink: String,
    src_dir: PathBuf,
    sink_dir: PathBuf,
    src_next: u64,
    sink_next: u64,
}

impl SdkPath {
    fn batch(&mut self, a: &Robot, b: &Robot, expected: Duration) -> Result<Batch> {
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
struct RawPath {
    publisher: LineChild,
    subscriber: LineChild,
    dir: PathBuf,
    next: u64,
}

impl RawPath {
    fn batch(&mut self, size: usize, count: usize, interval_us: u64, max_ms: u64, expected: Duration) -> Result<Batch> {
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
fn rates(b: &Batch) -> (f64, f64) {
    let last = b.rows.iter().map(|r| r[2]).max().unwrap_or(b.t_end).max(b.t_end);
    let span = last.saturating_sub(b.t_start).max(1) as f64 / 1e9;
    let sent_span = b.t_end.saturating_sub(b.t_start).max(1) as f64 / 1e9;
    (b.rows.len() as f64 / span, b.sent as f64 / sent_span)
}

fn one_way(rows: &[[u64; 3]]) -> Vec<u64> {
    rows.iter().map(|r| r[2].saturating_sub(r[0])).collect()
}

fn spawn_agent(
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

fn bridge_status(robot: &Robot) -> Result<serde_json::Value> {
    let out = robot.run(&["bridge", "status", "--json"])?;
    serde_json::from_str(&out).context("cannot parse `nerve bridge status --json`")
}

/// Waits until the bridge `name` of robot A has wired every export and sees
/// an importer for each.
fn wait_bridge_ready(a: &Robot, name: &str, exports: usize, timeout: Duration) -> Result<()> {
    let t0 = Instant::now();
    loop {
        let st = bridge_status(a)?;
        let ready = st
            .as_array()
            .and_then(|b| b.iter().find(|b| b["name"] == name))
            .and_then(|b| b["exports"].as_array())
            .map(|ex| {
                ex.len() == exports
                    && ex.iter().all(|e| {
                        e["figures"]["wired"] == "true"
                            && e["figures"]["importers"].as_str().and_then(|s| s.parse::<u32>().ok()).unwrap_or(0) > 0
                    })
            })
            .unwrap_or(false);
        if ready {
            return Ok(());
        }
        if t0.elapsed() > timeout {
            bail!(
                "bridge {name} of robot {} did not wire its exports and see their importer within {timeout:?}: {st}",
                a.name
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Runs the bridge scenario.
pub fn run(opts: &BridgeOpts) -> Result<BridgeReport> {
    let started = Instant::now();
    let machine = Machine::probe();
    for s in &opts.sizes {
        if !SIZES.contains(s) {
            bail!("no payload of {s} bytes in this scenario; use 8, 4096 or 230400");
        }
    }
    std::fs::create_dir_all(&opts.work).with_context(|| format!("cannot create {}", opts.work.display()))?;

    // the robots first: dropped last, so `nerve down` runs after every child stopped
    let ra = Robot::new("a", opts.verbose)?;
    let rb = Robot::new("b", opts.verbose)?;
    eprintln!(
        "bridge: robot {} and robot {} (sizes {:?}, {} rounds{})",
        ra.name,
        rb.name,
        opts.sizes,
        opts.rounds,
        if opts.quick { "" } else { " + warm-up" }
    );
    let router_a = ra.start_router()?;
    let router_b = rb.start_router()?;
    let mut children: Vec<ChildGuard> = Vec::new();
    let result = measure(opts, &ra, &rb, &mut children);
    let status: Vec<serde_json::Value> = [&ra, &rb].iter().filter_map(|r| bridge_status(r).ok()).collect();
    for mut c in children.drain(..) {
        c.stop(Duration::from_secs(2));
    }
    drop(router_a);
    drop(router_b);
    drop(ra);
    drop(rb);
    let m = result?;
    Ok(report(opts, machine, m, status, started))
}

/// The throughput batches of one system at one size.
#[derive(Debug, Default)]
struct Tput {
    /// (delivered/s, offered/s) per round
    per_round: Vec<(f64, f64)>,
    /// samples sent in all
    sent: u64,
    /// samples received in all
    received: u64,
    /// one-way latencies of what was delivered
    loaded: Vec<u64>,
}

/// The raw measurements of a run.
struct Measured {
    /// per size: [bridge, zenoh, bridge-tls] one-way
    oneway: Rounds,
    /// per size: [a-side, b-hop] of the bridge, then of the TLS bridge
    parts: Rounds,
    /// per size: [bridge, zenoh, bridge-tls] (sent, lost) of latency batches
    loss: Vec<[(u64, u64); 3]>,
    /// per size: [bridge, zenoh] throughput
    tput: Vec<[Tput; 2]>,
    /// per size: [alone, bridged, bridged-100hz] round trips
    local: Rounds,
}

fn measure(opts: &BridgeOpts, ra: &Robot, rb: &Robot, children: &mut Vec<ChildGuard>) -> Result<Measured> {
    // the configs of the bridges
    let port_a = free_port()?;
    let port_raw = free_port()?;
    let port_tls = free_port()?;
    let ep_a = format!("tcp/127.0.0.1:{port_a}");
    let mut cfg_a = format!("listen = [\"{ep_a}\"]\nconnect = []\n");
    let mut cfg_b = format!("listen = []\nconnect = [\"{ep_a}\"]\n");
    // the TLS pair: the fleet's keys in the work dir, robot B a peer of A
    // (A imports nothing from B, and access control lets only peers subscribe)
    let keys = opts.work.join("keys");
    let keys_s = keys.to_str().ok_or_else(|| anyhow!("the work dir {} is not UTF-8", opts.work.display()))?;
    for args in [vec!["init"], vec!["add", ra.name.as_str()], vec!["add", rb.name.as_str()]] {
        let mut full = vec!["bridge", "keys"];
        full.extend(args);
        full.extend(["--dir", keys_s]);
        ra.run(&full)?;
    }
    let ep_tls = format!("tls/127.0.0.1:{port_tls}");
    let tls_section = format!("\n[tls]\nkeys = {}\n", toml_str(keys_s));
    let mut cfg_ta = format!("listen = [\"{ep_tls}\"]\nconnect = []\npeers = [\"{}\"]\n", rb.name);
    let mut cfg_tb = format!("listen = []\nconnect = [\"{ep_tls}\"]\n");
    let mut exports = 0;
    for &size in &opts.sizes {
        let t = size_tag(size);
        let tn = type_name(size)?;
        for (agent, max_hz) in [
            (format!("lsrc-{t}"), None),
            (format!("tsrc-{t}"), None),
            (format!("bping-{t}"), None),
            (format!("cping-{t}"), Some(100.0)),
        ] {
            cfg_a.push_str(&format!("\n[[export]]\nport = \"{agent}/out\"\ntype = \"{tn}\"\n"));
            if let Some(hz) = max_hz {
                cfg_a.push_str(&format!("max_hz = {hz:.1}\n"));
            }
            cfg_b.push_str(&format!(
                "\n[[import]]\nport = \"{}/{agent}/out\"\ntype = \"{tn}\"\nas = \"{agent}\"\n",
                ra.name
            ));
            exports += 1;
        }
        let agent = format!("ksrc-{t}");
        cfg_ta.push_str(&format!("\n[[export]]\nport = \"{agent}/out\"\ntype = \"{tn}\"\n"));
        cfg_tb.push_str(&format!(
            "\n[[import]]\nport = \"{}/{agent}/out\"\ntype = \"{tn}\"\nas = \"{agent}\"\n",
            ra.name
        ));
    }
    cfg_ta.push_str(&tls_section);
    cfg_tb.push_str(&tls_section);
    let (path_a, path_b) = (opts.work.join("bridge-a.zenoh.toml"), opts.work.join("bridge-b.zenoh.toml"));
    let (path_ta, path_tb) = (opts.work.join("tbridge-a.zenoh.toml"), opts.work.join("tbridge-b.zenoh.toml"));
    for (path, cfg) in [(&path_a, cfg_a), (&path_b, cfg_b), (&path_ta, cfg_ta), (&path_tb, cfg_tb)] {
        std::fs::write(path, cfg).with_context(|| format!("cannot write {}", path.display()))?;
    }

    // the agents of both robots
    let mut names_a = vec!["bridge".to_owned(), "tbridge".to_owned()];
    let mut names_b = vec!["bridge".to_owned(), "tbridge".to_owned()];
    let mut sdk_paths: Vec<(usize, SdkPath, SdkPath, SdkPath)> = Vec::new();
    let mut pings: Vec<(usize, [NervePing; 3])> = Vec::new();
    for &size in &opts.sizes {
        let t = size_tag(size);
        let s = size.to_string();
        let mut paths = Vec::new();
        for (kind, count, interval, max_ms, rt) in [
            ("l", opts.count, opts.interval_us, 0, true),
            ("t", TPUT_CAP, 0, opts.tput_ms, false),
            ("k", opts.count, opts.interval_us, 0, true),
        ] {
            let (src, sink) = (format!("{kind}src-{t}"), format!("{kind}sink-{t}"));
            let (src_dir, sink_dir) = (opts.work.join(&src), opts.work.join(&sink));
            for d in [&src_dir, &sink_dir] {
                std::fs::create_dir_all(d).with_context(|| format!("cannot create {}", d.display()))?;
            }
            let args: Vec<String> = vec![
                "--size".into(),
                s.clone(),
                "--count".into(),
                count.to_string(),
                "--interval-us".into(),
                interval.to_string(),
                "--max-ms".into(),
                max_ms.to_string(),
            ];
            // a back-to-back sender runs like any busy program, not under SCHED_FIFO
            let common: &[&str] = if rt { &[] } else { &["--no-realtime"] };
            children.push(spawn_agent(ra, "__agent-bsend", &src, common, &args, &src_dir)?);
            children.push(spawn_agent(rb, "__agent-bsink", &sink, &[], &args, &sink_dir)?);
            names_a.push(src.clone());
            names_b.push(sink.clone());
            paths.push(SdkPath { src, sink, src_dir, sink_dir, src_next: 0, sink_next: 0 });
        }
        let mut it = paths.into_iter();
        let (Some(lat), Some(tp), Some(tls)) = (it.next(), it.next(), it.next()) else {
            bail!("internal: three paths per size")
        };
        sdk_paths.push((size, lat, tp, tls));
        let mut trio = Vec::new();
        for prefix in ["", "b", "c"] {
            let (ping, pong) = (format!("{prefix}ping-{t}"), format!("{prefix}pong-{t}"));
            let dir = opts.work.join(&ping);
            std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
            children.push(spawn_bench_agent(ra, "ping", &ping, size, opts.hop_count, &dir)?);
            children.push(spawn_bench_agent(ra, "pong", &pong, size, opts.hop_count, &dir)?);
            names_a.push(ping.clone());
            names_a.push(pong);
            trio.push(NervePing::new(ping, dir));
        }
        let trio: [NervePing; 3] = trio.try_into().map_err(|_| anyhow!("internal: three pairs per size"))?;
        pings.push((size, trio));
    }
    for (robot, name, path) in
        [(ra, "bridge", &path_a), (rb, "bridge", &path_b), (ra, "tbridge", &path_ta), (rb, "tbridge", &path_tb)]
    {
        let mut cmd = self_command("__bridge")?;
        cmd.args(["--robot", &robot.name, "--name", name, "--", "--config"]).arg(path);
        cmd.env("NERVE_HOME", &robot.home);
        robot.quiet(&mut cmd);
        children.push(ChildGuard::spawn(&format!("{name} of {}", robot.name), cmd)?);
    }
    let refs: Vec<&str> = names_a.iter().map(String::as_str).collect();
    ra.wait_registered(&refs, Duration::from_secs(30))?;
    let refs: Vec<&str> = names_b.iter().map(String::as_str).collect();
    rb.wait_registered(&refs, Duration::from_secs(30))?;
    for &size in &opts.sizes {
        let t = size_tag(size);
        for prefix in ["", "b", "c"] {
            let (ping, pong) = (format!("{prefix}ping-{t}"), format!("{prefix}pong-{t}"));
            ra.run(&["connect", &format!("{ping}/out"), &format!("{pong}/in")])?;
            ra.run(&["connect", "--allow-cycle", &format!("{pong}/out"), &format!("{ping}/in")])?;
        }
        for kind in ["l", "t"] {
            rb.run(&["connect", &format!("bridge/{kind}src-{t}"), &format!("{kind}sink-{t}/in")])?;
        }
        rb.run(&["connect", &format!("tbridge/ksrc-{t}"), &format!("ksink-{t}/in")])?;
    }
    wait_bridge_ready(ra, "bridge", exports, Duration::from_secs(30))?;
    wait_bridge_ready(ra, "tbridge", opts.sizes.len(), Duration::from_secs(30))?;
    eprintln!("bridge: agents running, bridges linked ({exports} topics, {} over TLS)", opts.sizes.len());

    // raw zenoh: the publisher listens, the subscriber dials (as bridge A and B)
    let ep_raw = format!("tcp/127.0.0.1:{port_raw}");
    let sizes_arg = opts.sizes.iter().map(usize::to_string).collect::<Vec<_>>().join(",");
    let mut cmd = self_command("__zenoh-pub")?;
    cmd.args(["--listen", &ep_raw, "--sizes", &sizes_arg]);
    let publisher = LineChild::spawn("raw zenoh pub", cmd, opts.verbose)?;
    let mut cmd = self_command("__zenoh-sub")?;
    cmd.args(["--connect", &ep_raw, "--sizes", &sizes_arg]);
    let subscriber = LineChild::spawn("raw zenoh sub", cmd, opts.verbose)?;
    let mut raw = RawPath { publisher, subscriber, dir: opts.work.clone(), next: 0 };
    for &size in &opts.sizes {
        let t0 = Instant::now();
        while raw.batch(size, 1, 0, 100, Duration::ZERO)?.rows.is_empty() {
            if t0.elapsed() > Duration::from_secs(20) {
                bail!("raw zenoh: nothing of {size} B arrived within 20 s");
            }
        }
    }
    eprintln!("bridge: raw zenoh pair linked");

    let n = opts.sizes.len();
    let mut m = Measured {
        oneway: Rounds::new(3 * n, DISCARD),
        parts: Rounds::new(4 * n, DISCARD),
        loss: vec![[(0, 0); 3]; n],
        tput: (0..n).map(|_| [Tput::default(), Tput::default()]).collect(),
        local: Rounds::new(3 * n, DISCARD),
    };
    let lat_expected = Duration::from_micros(opts.interval_us * opts.count as u64);
    let tput_expected = Duration::from_millis(opts.tput_ms);
    for round in usize::from(opts.quick)..=opts.rounds {
        let t_round = Instant::now();
        for (k, &size) in opts.sizes.iter().enumerate() {
            let (_, lat, tp, tls) = &mut sdk_paths[k];
            // one way, paced
            for sys in Rounds::order(&[0, 1, 2], round) {
                let b = match sys {
                    0 => lat.batch(ra, rb, lat_expected),
                    2 => tls.batch(ra, rb, lat_expected),
                    _ => raw.batch(size, opts.count, opts.interval_us, 0, lat_expected),
                }
                .with_context(|| format!("{} one way at {size} B, round {round}", ONEWAY[sys]))?;
                m.oneway.keep(3 * k + sys, round, &one_way(&b.rows));
                if sys != 1 {
                    let a_side: Vec<u64> = b.rows.iter().map(|r| r[1].saturating_sub(r[0])).collect();
                    let b_hop: Vec<u64> = b.rows.iter().map(|r| r[2].saturating_sub(r[1])).collect();
                    let at = 4 * k + if sys == 0 { 0 } else { 2 };
                    m.parts.keep(at, round, &a_side);
                    m.parts.keep(at + 1, round, &b_hop);
                }
                if round > 0 {
                    let l = &mut m.loss[k][sys];
                    l.0 += b.sent;
                    l.1 += b.sent.saturating_sub(b.rows.len() as u64);
                }
            }
            // throughput, back to back
            for sys in Rounds::order(&[0, 1], round) {
                let b = if sys == 0 {
                    tp.batch(ra, rb, tput_expected)
                } else {
                    raw.batch(size, TPUT_CAP, 0, opts.tput_ms, tput_expected)
                }
                .with_context(|| format!("{} throughput at {size} B, round {round}", TPUT[sys]))?;
                if round > 0 {
                    let t = &mut m.tput[k][sys];
                    t.per_round.push(rates(&b));
                    t.sent += b.sent;
                    t.received += b.rows.len() as u64;
                    t.loaded.extend(one_way(&b.rows));
                }
            }
            // the local round trip, with and without a bridge on the port
            let (_, trio) = &mut pings[k];
            for sys in Rounds::order(&[0, 1, 2], round) {
                let v = trio[sys]
                    .run_batch(ra)
                    .with_context(|| format!("{} round trip at {size} B, round {round}", LOCAL[sys]))?;
                m.local.keep(3 * k + sys, round, &v);
            }
        }
        let what = if round == 0 { "warm-up".to_owned() } else { format!("round {round}/{}", opts.rounds) };
        eprintln!("bridge: {what} done in {:.1} s", t_round.elapsed().as_secs_f64());
        if round == 0 {
            continue;
        }
        for (k, &size) in opts.sizes.iter().enumerate() {
            let last = |r: &Rounds, i: usize| us(r.round_p50[i].last().copied().unwrap_or(0));
            let tput = |sys: usize| m.tput[k][sys].per_round.last().map_or(0.0, |x| x.0);
            eprintln!(
                "  {:>7}: one way bridge {}us zenoh {}us bridge-tls {}us; delivered/s bridge {:.0} zenoh {:.0}; round trip alone {}us bridged {}us bridged-100hz {}us",
                label(size),
                last(&m.oneway, 3 * k),
                last(&m.oneway, 3 * k + 1),
                last(&m.oneway, 3 * k + 2),
                tput(0),
                tput(1),
                last(&m.local, 3 * k),
                last(&m.local, 3 * k + 1),
                last(&m.local, 3 * k + 2),
            );
        }
    }
    drop(raw);
    Ok(m)
}

/// The `latency_us` figure of the import of `<kind>src-<size>` in the bridges' status.
fn link_latency_us(status: &[serde_json::Value], kind: &str, size: usize) -> Option<u64> {
    let suffix = format!("/{kind}src-{}/out", size_tag(size));
    status
        .iter()
        .filter_map(|s| s.as_array())
        .flatten()
        .filter_map(|b| b["imports"].as_array())
        .flatten()
        .find(|t| t["topic"].as_str().is_some_and(|t| t.ends_with(&suffix)))
        .and_then(|t| t["figures"]["latency_us"].as_str())
        .and_then(|v| v.parse().ok())
}

fn report(
    opts: &BridgeOpts,
    machine: Machine,
    m: Measured,
    bridge_status: Vec<serde_json::Value>,
    started: Instant,
) -> BridgeReport {
    let mut oneway = Vec::new();
    let mut throughput = Vec::new();
    let mut local = Vec::new();
    let mut oneway_ratios = Vec::new();
    let mut local_ratios = Vec::new();
    let mut tls_vs_plain = std::collections::BTreeMap::new();
    for (k, &size) in opts.sizes.iter().enumerate() {
        for (sys, name) in ONEWAY.iter().enumerate() {
            let i = 3 * k + sys;
            let (sent, lost) = m.loss[k][sys];
            let parts = match sys {
                0 => Some(4 * k),
                2 => Some(4 * k + 2),
                _ => None,
            };
            oneway.push(OneWayResult {
                system: (*name).into(),
                size,
                label: label(size).into(),
                latency: Summary::of(&m.oneway.samples[i]),
                round_p50_ns: m.oneway.round_p50[i].clone(),
                sent,
                lost,
                to_bridge_b: parts.map(|p| Summary::of(&m.parts.samples[p])),
                bridge_b_to_sink: parts.map(|p| Summary::of(&m.parts.samples[p + 1])),
                bridge_a_to_b_us: match sys {
                    0 => link_latency_us(&bridge_status, "l", size),
                    2 => link_latency_us(&bridge_status, "k", size),
                    _ => None,
                },
            });
        }
        for (sys, name) in TPUT.iter().enumerate() {
            let t = &m.tput[k][sys];
            let delivered: Vec<f64> = t.per_round.iter().map(|x| x.0).collect();
            let offered: Vec<f64> = t.per_round.iter().map(|x| x.1).collect();
            let d = median_f64(&delivered);
            throughput.push(ThroughputResult {
                system: (*name).into(),
                size,
                label: label(size).into(),
                delivered_per_s: d,
                offered_per_s: median_f64(&offered),
                delivered_fraction: if t.sent == 0 { 0.0 } else { t.received as f64 / t.sent as f64 },
                delivered_mb_per_s: d * size as f64 / 1e6,
                latency_loaded: Summary::of(&t.loaded),
                round_delivered_per_s: delivered,
            });
        }
        for (sys, name) in LOCAL.iter().enumerate() {
            let i = 3 * k + sys;
            local.push(LocalResult {
                system: (*name).into(),
                size,
                label: label(size).into(),
                rtt: Summary::of(&m.local.samples[i]),
                round_p50_ns: m.local.round_p50[i].clone(),
            });
        }
        let ow = |sys: &str| oneway.iter().find(|r| r.system == sys && r.size == size);
        let tp = |sys: &str| throughput.iter().find(|r| r.system == sys && r.size == size);
        let lo = |sys: &str| local.iter().find(|r| r.system == sys && r.size == size);
        if let (Some(b), Some(z), Some(tb), Some(tz), Some(alone)) =
            (ow("bridge"), ow("zenoh"), tp("bridge"), tp("zenoh"), lo("alone"))
        {
            let per_round: Vec<f64> = b.round_p50_ns.iter().zip(&z.round_p50_ns).map(|(x, y)| ratio(*x, *y)).collect();
            let r = ratio(b.latency.p50_ns, z.latency.p50_ns);
            let tls = ow("bridge-tls").filter(|t| t.latency.n > 0);
            let tls_p50 = tls.map_or(0.0, |t| ratio(t.latency.p50_ns, b.latency.p50_ns));
            let tls_rounds: Vec<f64> = tls.map_or_else(Vec::new, |t| {
                t.round_p50_ns.iter().zip(&b.round_p50_ns).map(|(x, y)| ratio(*x, *y)).collect()
            });
            tls_vs_plain.insert(format!("tls_vs_plain_p50_{}", size_key(size)), tls_p50);
            oneway_ratios.push(OneWayRatio {
                size,
                bridge_vs_zenoh_p50: r,
                bridge_vs_zenoh_p99: ratio(b.latency.p99_ns, z.latency.p99_ns),
                bridge_vs_zenoh_p50_round_median: median_f64(&per_round),
                throughput_bridge_vs_zenoh: if tz.delivered_per_s > 0.0 {
                    tb.delivered_per_s / tz.delivered_per_s
                } else {
                    0.0
                },
                extra_p50_ns: b.latency.p50_ns as i64 - z.latency.p50_ns as i64,
                local_hop_p50_ns: alone.rtt.p50_ns / 2,
                target_met: r <= ONEWAY_TARGET,
                tls_vs_plain_p50: tls_p50,
                tls_vs_plain_p99: tls.map_or(0.0, |t| ratio(t.latency.p99_ns, b.latency.p99_ns)),
                tls_vs_plain_p50_round_median: if tls_rounds.is_empty() { 0.0 } else { median_f64(&tls_rounds) },
                tls_extra_p50_ns: tls.map_or(0, |t| t.latency.p50_ns as i64 - b.latency.p50_ns as i64),
                tls_target_met: tls.is_some() && tls_p50 <= TLS_TARGET,
            });
        }
        if let (Some(alone), Some(bridged), Some(limited)) = (lo("alone"), lo("bridged"), lo("bridged-100hz")) {
            let per_round: Vec<f64> =
                bridged.round_p50_ns.iter().zip(&alone.round_p50_ns).map(|(x, y)| ratio(*x, *y)).collect();
            let r = ratio(bridged.rtt.p50_ns, alone.rtt.p50_ns);
            local_ratios.push(LocalRatio {
                size,
                bridged_vs_alone_p50: r,
                bridged_vs_alone_p99: ratio(bridged.rtt.p99_ns, alone.rtt.p99_ns),
                bridged_vs_alone_p50_round_median: median_f64(&per_round),
                limited_vs_alone_p50: ratio(limited.rtt.p50_ns, alone.rtt.p50_ns),
                limited_vs_alone_p99: ratio(limited.rtt.p99_ns, alone.rtt.p99_ns),
                target_met: r <= LOCAL_TARGET,
            });
        }
    }
    Report::new(
        "bridge",
        machine,
        BridgeResults {
            rounds: opts.rounds,
            count: opts.count,
            interval_us: opts.interval_us,
            tput_ms: opts.tput_ms,
            hop_count: opts.hop_count,
            oneway,
            throughput,
            oneway_ratios,
            local,
            local_ratios,
            oneway_target: ONEWAY_TARGET,
            local_target: LOCAL_TARGET,
            tls_target: TLS_TARGET,
            tls_vs_plain,
            bridge_status,
            seconds: started.elapsed().as_secs_f64(),
        },
    )
}

/// Prints the tables of a bridge report (markdown).
pub fn print_tables(r: &BridgeReport) {
    println!("One way across the bridge vs raw Zenoh, one sample every {} µs:", r.interval_us);
    println!();
    println!(
        "| payload | system | n | lost | median µs | p99 µs | max µs | sender to bridge B, median µs | bridge B to sink, median µs |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|");
    let opt = |s: &Option<Summary>| s.as_ref().map_or_else(|| "-".to_owned(), |s| us(s.p50_ns));
    for x in &r.oneway {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            x.label,
            x.system,
            x.latency.n,
            x.lost,
            us(x.latency.p50_ns),
            us(x.latency.p99_ns),
            us(x.latency.max_ns),
            opt(&x.to_bridge_b),
            opt(&x.bridge_b_to_sink)
        );
    }
    println!();
    println!("Throughput, sent back to back for at most {} ms:", r.tput_ms);
    println!();
    println!(
        "| payload | system | offered /s | delivered /s | delivered MB/s | delivered of sent | one way under load, median µs | p99 µs |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|");
    for x in &r.throughput {
        println!(
            "| {} | {} | {:.0} | {:.0} | {:.1} | {:.1}% | {} | {} |",
            x.label,
            x.system,
            x.offered_per_s,
            x.delivered_per_s,
            x.delivered_mb_per_s,
            100.0 * x.delivered_fraction,
            us(x.latency_loaded.p50_ns),
            us(x.latency_loaded.p99_ns)
        );
    }
    println!();
    println!(
        "| payload | bridge/zenoh p50 | (median of rounds) | p99 | bridge adds, µs | one local hop, µs | delivered/s bridge/zenoh | target ≤{ONEWAY_TARGET} |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---|");
    for x in &r.oneway_ratios {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.1} | {} | {:.2} | {} |",
            label(x.size),
            x.bridge_vs_zenoh_p50,
            x.bridge_vs_zenoh_p50_round_median,
            x.bridge_vs_zenoh_p99,
            x.extra_p50_ns as f64 / 1e3,
            us(x.local_hop_p50_ns),
            x.throughput_bridge_vs_zenoh,
            if x.target_met { "met" } else { "missed" }
        );
    }
    println!();
    println!("The bridge with mutual TLS against without (bridge-tls / bridge, one way):");
    println!();
    println!("| payload | tls/plain p50 | (median of rounds) | p99 | TLS adds, µs | target ≤{TLS_TARGET} |");
    println!("|---|---:|---:|---:|---:|---|");
    for x in &r.oneway_ratios {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.1} | {} |",
            label(x.size),
            x.tls_vs_plain_p50,
            x.tls_vs_plain_p50_round_median,
            x.tls_vs_plain_p99,
            x.tls_extra_p50_ns as f64 / 1e3,
            if x.tls_target_met { "met" } else { "missed" }
        );
    }
    println!();
    println!("One-hop round trip in robot A, with and without a bridge reading the ping's port:");
    println!();
    println!("| payload | system | n | median µs | p99 µs | max µs |");
    println!("|---|---|---:|---:|---:|---:|");
    for x in &r.local {
        println!(
            "| {} | {} | {} | {} | {} | {} |",
            x.label,
            x.system,
            x.rtt.n,
            us(x.rtt.p50_ns),
            us(x.rtt.p99_ns),
            us(x.rtt.max_ns)
        );
    }
    println!();
    println!(
        "| payload | bridged/alone p50 | (median of rounds) | p99 | bridged-100hz/alone p50 | p99 | target ≤{LOCAL_TARGET} |"
    );
    println!("|---|---:|---:|---:|---:|---:|---|");
    for x in &r.local_ratios {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} |",
            label(x.size),
            x.bridged_vs_alone_p50,
            x.bridged_vs_alone_p50_round_median,
            x.bridged_vs_alone_p99,
            x.limited_vs_alone_p50,
            x.limited_vs_alone_p99,
            if x.target_met { "met" } else { "missed" }
        );
    }
}
