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
//!
//! This file sets the run up and measures it; the paths driven batch by
//! batch are in [`paths`], the results and their ratios in [`results`], the
//! tables in [`tables`].

mod paths;
mod results;
mod tables;

pub use results::BridgeReport;
pub use tables::print_tables;

use crate::hop::{NervePing, size_tag, spawn_bench_agent};
use crate::machine::Machine;
use crate::payloads::label;
use crate::procs::{ChildGuard, Robot, self_command};
use crate::stats::{Rounds, us};
use crate::with_payload;
use anyhow::{Context as _, Result, anyhow, bail};
use paths::{LineChild, RawPath, SdkPath, one_way, rates, spawn_agent};
use results::report;
use shm_schemas::Payload as _;
use std::path::PathBuf;
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

/// `s` as a TOML basic string (quotes and backslashes escaped).
fn toml_str(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

/// A free TCP port on 127.0.0.1 (bound to port 0, then released).
fn free_port() -> Result<u16> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").context("cannot bind 127.0.0.1:0 to find a free port")?;
    Ok(l.local_addr().context("local address")?.port())
}

fn type_name(size: usize) -> Result<&'static str> {
    with_payload!(size, P => Ok(P::stable_type_name()), _ => bail!("no payload of {size} bytes; use 8, 4096 or 230400"))
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
