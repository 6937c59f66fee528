//! Scenario `messages`: issue 42's real messages measured beside the fixed
//! payloads they stand next to, as one-hop round trips of SDK agents in a
//! robot of their own, wired with `nerve connect` as users wire them; a
//! batch is a `nerve suspend` + `nerve resume` of the ping agent, which
//! writes its round trips to a file (the hop scenario's [`NervePing`]).
//! Three rows, batch by batch interleaved (the order rotates every round; a
//! warm-up round first):
//!
//! * `fixed`: the hop scenario's ping and pong of a fixed-size payload
//!   (`Output::send_uninit`, only the sequence number written);
//! * `seq`: the same round trip with sequence samples
//!   (`setup.output_seq::<u8, Small8>`, [`agents`]): an 8-byte header and
//!   `size - 8` bytes after it, so a sample is `size` bytes in shared
//!   memory as the fixed payload is; only the header is written, the
//!   elements are loaned in place. Targets: at 1 MB at most
//!   [`SEQ_TARGET`] times `fixed`'s round trip, and flat from 8 B to 8 MB
//!   (the largest size's median at most [`FLAT_TARGET`] times the
//!   smallest's): zero copy, whatever the length;
//! * `call`: a call's round trip (`setup.client` / `setup.serve`, request
//!   and answer both the fixed payload of `size`): the client calls again
//!   when the answer comes, the server answers each request with its
//!   sequence number. Both are written and read in place, as `fixed`'s
//!   samples are (`Client::call_uninit`, `Server::serve_uninit`,
//!   `Client::take_with`: only the sequence number written, nothing
//!   copied). Target: at most [`CALL_TARGET`] times `fixed`'s round trip of
//!   the same size. Measured up to [`CALL_MAX`] bytes.
//!
//! Sizes are any number of bytes from 8 to 8 MiB for `seq`; `fixed` runs at
//! the sizes the benchmark has a type for (8, 4096, 230400, 1048576,
//! 6220800). The agents hold nerve's default PM QoS bound while they run.
//! Agents are `ROW-TAG`: `fping-1m`, `sping-8m`, `cping-4k`...

mod agents;

pub use agents::run_agent;

use crate::hop::{NervePing, spawn_bench_agent};
use crate::machine::Machine;
use crate::procs::{ChildGuard, Robot};
use crate::report::{Pair, PairRow, Plan, Report, interleaved_rows, round_median};
use crate::stats::{ratio, ratio_cell, verdict};
use crate::with_payload;
use anyhow::{Context as _, Result, bail};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Samples dropped at the start of every batch.
const DISCARD: usize = 5;
/// A 1 MB sequence sample's round trip may be this many times a fixed 1 MB payload's.
pub const SEQ_TARGET: f64 = 1.1;
/// The sequence round trip at the largest size may be this many times the smallest's ("flat").
pub const FLAT_TARGET: f64 = 1.1;
/// A call's round trip may be this many times a one-hop ping-pong's of the same size.
pub const CALL_TARGET: f64 = 1.2;
/// The largest payload a call is measured with.
pub const CALL_MAX: usize = 230_400;
/// The largest sequence sample (bytes).
const SEQ_MAX: usize = 8 << 20;
/// The default sizes, bytes.
pub const SIZES: [usize; 5] = [8, 4096, 230_400, 1 << 20, 8 << 20];
/// The rows, in table order.
const ROWS: [&str; 3] = ["fixed", "seq", "call"];

/// Options of the messages scenario.
#[derive(Debug, Clone)]
pub struct MessagesOpts {
    /// smoke run
    pub quick: bool,
    /// sample sizes, bytes
    pub sizes: Vec<usize>,
    /// measured rounds (a warm-up round comes first, but with `quick`)
    pub rounds: usize,
    /// show children's output
    pub verbose: bool,
    /// where batch files go
    pub work: PathBuf,
}

/// One row at one size (`fixed`, `seq` or `call`).
pub type RowResult = PairRow;

/// The ratios of one size (pooled medians), and the median of the per-round ratios.
#[derive(Debug, Clone, Serialize)]
pub struct SizeRatios {
    /// sample bytes
    pub size: usize,
    /// seq / fixed, p50
    pub seq_vs_fixed_p50: Option<f64>,
    /// seq / fixed, median of the rounds' ratios
    pub seq_vs_fixed_round_median: Option<f64>,
    /// call / fixed, p50
    pub call_vs_fixed_p50: Option<f64>,
    /// call / fixed, median of the rounds' ratios
    pub call_vs_fixed_round_median: Option<f64>,
}

/// The messages report: the [`Head`](crate::report::Head) and [`MessagesResults`].
pub type MessagesReport = Report<MessagesResults>;

/// The results of the scenario, after the report's head.
#[derive(Debug, Clone, Serialize)]
pub struct MessagesResults {
    /// measured rounds
    pub rounds: usize,
    /// every row at every size it ran
    pub rows: Vec<RowResult>,
    /// per size
    pub ratios: Vec<SizeRatios>,
    /// seq's p50 at the largest size / at the smallest (pooled medians)
    pub seq_flatness: Option<f64>,
    /// the same, median of the rounds' ratios (each round's two batches a few seconds apart)
    pub seq_flatness_round_median: Option<f64>,
    /// (smallest, largest) size of that figure
    pub seq_flatness_sizes: Option<(usize, usize)>,
    /// targets: seq/fixed at 1 MB, seq flatness, call/fixed
    pub seq_target: f64,
    /// see [`FLAT_TARGET`]
    pub flat_target: f64,
    /// see [`CALL_TARGET`]
    pub call_target: f64,
    /// wall time
    pub seconds: f64,
}

/// Round trips per batch at `size`.
fn count_of(size: usize, quick: bool) -> usize {
    let n = match size {
        0..=4096 => 2000,
        4097..=262_144 => 1000,
        262_145..=2_097_152 => 500,
        _ => 200,
    };
    if quick { n / 10 } else { n }
}

/// The short form of a size in agent names: `8`, `4k`, `230k`, `1m`, `8m`.
fn tag(size: usize) -> String {
    match size {
        s if s >= 1 << 20 && s % (1 << 20) == 0 => format!("{}m", s >> 20),
        s if s >= 1000 => format!("{}k", s / 1000),
        s => s.to_string(),
    }
}

/// A size for tables: `8 B`, `4 KB`, `230 KB`, `1 MB`, `8 MB`.
fn label(size: usize) -> String {
    match size {
        s if s >= 1 << 20 => format!("{} MB", s >> 20),
        s if s >= 1000 => format!("{} KB", s / 1000),
        s => format!("{s} B"),
    }
}

/// Whether `row` runs at `size`.
fn runs_at(row: &str, size: usize) -> bool {
    let typed = with_payload!(size, P => { let _ = std::mem::size_of::<P>(); true }, _ => false);
    match row {
        "fixed" => typed,
        "call" => typed && size <= CALL_MAX,
        _ => true,
    }
}

/// The agent subcommands of a row's (ping, pong), and how they are wired.
fn roles(row: &str) -> (&'static str, &'static str) {
    match row {
        "fixed" => ("ping", "pong"),
        "seq" => ("seqping", "seqpong"),
        _ => ("callping", "callserve"),
    }
}

/// Starts every pair, waits until they are registered, wires them.
fn start(robot: &Robot, opts: &MessagesOpts) -> Result<(Vec<ChildGuard>, Vec<Pair>)> {
    let (mut children, mut pairs, mut names) = (Vec::new(), Vec::new(), Vec::new());
    for &size in &opts.sizes {
        for row in ROWS.into_iter().filter(|r| runs_at(r, size)) {
            let (ping_role, pong_role) = roles(row);
            let first = row.chars().next().unwrap_or('x');
            let (ping, pong) = (format!("{first}ping-{}", tag(size)), format!("{first}pong-{}", tag(size)));
            let dir = opts.work.join(&ping);
            std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
            let count = count_of(size, opts.quick);
            children.push(spawn_bench_agent(robot, ping_role, &ping, size, count, &dir)?);
            children.push(spawn_bench_agent(robot, pong_role, &pong, size, count, &dir)?);
            names.extend([ping.clone(), pong.clone()]);
            pairs.push(Pair { row, size, ping: NervePing::new(ping, dir), pong });
        }
    }
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    robot.wait_registered(&refs, Duration::from_secs(20))?;
    for p in &pairs {
        if p.row == "call" {
            robot.run(&["connect", &format!("{}/call", p.ping.name), &format!("{}/serve", p.pong)])?;
        } else {
            p.wire_echo(robot)?;
        }
    }
    Ok((children, pairs))
}

/// Runs the scenario.
pub fn run(opts: &MessagesOpts) -> Result<MessagesReport> {
    let started = Instant::now();
    for &s in &opts.sizes {
        if !(8..=SEQ_MAX).contains(&s) {
            bail!("a sample of {s} bytes: use sizes from 8 to {SEQ_MAX} bytes");
        }
    }
    let machine = Machine::probe();
    let robot = Robot::new("m", opts.verbose)?;
    eprintln!(
        "messages: robot {} (sizes {:?}, {} rounds, load {:.2})",
        robot.name, opts.sizes, opts.rounds, machine.loadavg_1m
    );
    let router = robot.start_router()?;
    let (children, mut pairs) = start(&robot, opts)?;
    eprintln!("messages: {} pairs running and wired", pairs.len());
    let plan =
        Plan { scenario: "messages", sizes: &opts.sizes, rounds: opts.rounds, quick: opts.quick, discard: DISCARD };
    let rows = interleaved_rows(plan, &robot, &mut pairs, |size| count_of(size, opts.quick))?;
    drop(children);
    drop(router);
    drop(robot);
    let ratios = opts.sizes.iter().map(|&s| size_ratios(&rows, s)).collect();
    let seq: Vec<&RowResult> = rows.iter().filter(|r| r.row == "seq").collect();
    let (lo, hi) = (seq.iter().min_by_key(|r| r.size), seq.iter().max_by_key(|r| r.size));
    let flat = lo.zip(hi).filter(|(a, b)| a.size < b.size).map(|(a, b)| {
        (
            ratio(b.round_trip.p50_ns, a.round_trip.p50_ns),
            round_median(&b.round_p50_ns, &a.round_p50_ns),
            (a.size, b.size),
        )
    });
    Ok(Report::new(
        "messages",
        machine,
        MessagesResults {
            rounds: opts.rounds,
            rows,
            ratios,
            seq_flatness: flat.map(|f| f.0),
            seq_flatness_round_median: flat.map(|f| f.1),
            seq_flatness_sizes: flat.map(|f| f.2),
            seq_target: SEQ_TARGET,
            flat_target: FLAT_TARGET,
            call_target: CALL_TARGET,
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
}

/// The ratios of `size` from the rows measured there.
fn size_ratios(rows: &[RowResult], size: usize) -> SizeRatios {
    let find = |row: &str| rows.iter().find(|r| r.row == row && r.size == size);
    let fixed = find("fixed");
    let pooled = |row: &str| find(row).zip(fixed).map(|(r, f)| ratio(r.round_trip.p50_ns, f.round_trip.p50_ns));
    let per_round = |row: &str| find(row).zip(fixed).map(|(r, f)| round_median(&r.round_p50_ns, &f.round_p50_ns));
    SizeRatios {
        size,
        seq_vs_fixed_p50: pooled("seq"),
        seq_vs_fixed_round_median: per_round("seq"),
        call_vs_fixed_p50: pooled("call"),
        call_vs_fixed_round_median: per_round("call"),
    }
}

/// Prints the tables (markdown).
pub fn print_tables(r: &MessagesReport) {
    let cell = |row: &str, size: usize| PairRow::cells(&r.rows, row, size);
    println!(
        "### Sequences and calls beside fixed payloads (one-hop round trip, µs; load {:.2})\n",
        r.head.machine.loadavg_1m
    );
    println!(
        "| sample | fixed p50 | p99 | seq p50 | p99 | seq/fixed (rounds) | call p50 | p99 | call/fixed (rounds) | target seq ≤{SEQ_TARGET} at 1 MB, call ≤{CALL_TARGET} |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for x in &r.ratios {
        let both = |p: Option<f64>, m: Option<f64>| match (p, m) {
            (Some(p), Some(m)) => format!("{p:.2} ({m:.2})"),
            _ => "-".into(),
        };
        let seq_met = (x.size == 1 << 20).then_some(x.seq_vs_fixed_p50.map(|v| v <= SEQ_TARGET)).flatten();
        let call_met = x.call_vs_fixed_p50.map(|v| v <= CALL_TARGET);
        println!(
            "| {} | {} | {} | {} | {} | {} | seq {}, call {} |",
            label(x.size),
            cell("fixed", x.size),
            cell("seq", x.size),
            both(x.seq_vs_fixed_p50, x.seq_vs_fixed_round_median),
            cell("call", x.size),
            both(x.call_vs_fixed_p50, x.call_vs_fixed_round_median),
            verdict(seq_met),
            verdict(call_met),
        );
    }
    if let (Some(f), Some(m), Some((a, b))) = (r.seq_flatness, r.seq_flatness_round_median, r.seq_flatness_sizes) {
        println!(
            "\nseq p50 at {} / at {}: {} (median of the rounds' ratios {}; flat: ≤{FLAT_TARGET}, {})",
            label(b),
            label(a),
            ratio_cell(Some(f)),
            ratio_cell(Some(m)),
            verdict(Some(f <= FLAT_TARGET))
        );
    }
}

/// Where a run's batch files go.
pub fn work_dir(out: &Path) -> PathBuf {
    out.join(format!("messages-work-{}", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tags_and_labels_name_each_size_once() {
        let tags: Vec<String> = SIZES.iter().map(|&s| tag(s)).collect();
        assert_eq!(tags, ["8", "4k", "230k", "1m", "8m"]);
        assert_eq!(label(1 << 20), "1 MB");
        assert_eq!(label(230_400), "230 KB");
    }

    #[test]
    fn fixed_and_call_rows_run_only_where_they_can() {
        assert!(runs_at("fixed", 1 << 20) && !runs_at("fixed", 8 << 20));
        assert!(runs_at("call", 230_400) && !runs_at("call", 1 << 20));
        assert!(runs_at("seq", 8 << 20));
    }
}
