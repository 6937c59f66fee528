//! Scenario `c` (issue 43's measure): a C agent's and a C++ agent's
//! one-hop round trip beside a Rust agent's, at 8 B, 230 KB and 1080p,
//! side by side in one run.
//!
//! Three rows per size, each a pair in one robot, wired with `nerve
//! connect` as users wire agents; every ping is the hop scenario's Rust SDK
//! ping (`__agent-ping`, a batch per `nerve suspend` + `nerve resume`,
//! [`NervePing`]), and only the pong differs:
//!
//! * `rust`: the hop scenario's Rust pong (`__agent-pong`): it drains `in`
//!   and answers each sample with `Output::send_uninit`, writing only the
//!   sequence number in place;
//! * `c`: `bench/c/pong.c`, the same pong in C on libnerve: `nerve_take`
//!   reads the sample in place, `nerve_loan_uninit` + `nerve_send` write
//!   only the sequence number in place;
//! * `cpp`: `bench/c/pong.cpp`, the same in C++17 with `nerve.hpp`
//!   (`context::take`, `context::loan_uninit`, `loan::send`).
//!
//! The payloads are the bench's Rust types (`nerve::bench::Small8`,
//! `Frame230k`, `Frame1080p`); the C and C++ pongs declare them as their
//! own types (`bench/c/bench_payloads.h`), so the router checks their
//! fingerprints against the Rust ping's when it wires them.
//!
//! The span is the ping's: from just before it loans its sample to the
//! moment its step sees the echo, so it covers the ping's send, the pong's
//! wake-up, its step through the C API (or the Rust SDK) and its send, and
//! the ping's wake-up. All six agents of a size run with the SDK's
//! defaults, the same for every row: the task thread at SCHED_FIFO 20 with
//! memory locked, nerve's PM QoS bound, no pinning (the C and C++ agents
//! are run by the same Rust runtime, `nerve_run`). Batches interleave, the
//! order rotating every round; a warm-up round and the first samples of
//! every batch are dropped.
//!
//! The C and C++ sources are compiled when the run starts, with `gcc -O2`
//! and `g++ -O2` against the libnerve beside this executable (the release
//! one for a release `nerve-bench`), into the run's work folder, which is
//! removed at the end. Targets: each row at most [`TARGET`] times `rust`'s
//! round trip at every size, and flat with size: its median at the
//! largest size at most [`FLAT_TARGET`] times its median at the smallest
//! (zero copy: nothing is copied or zeroed per byte of payload).
//! `--loan-zeroed` builds the C and C++ pongs with the zeroing loan
//! (`nerve_loan`, `context::loan`) instead: what writing the whole slot
//! per answer costs.

use crate::hop::{NervePing, default_count, spawn_bench_agent};
use crate::machine::Machine;
use crate::payloads::{SIZES, label};
use crate::procs::{ChildGuard, Robot};
use crate::report::{Pair, PairRow, Plan, Report, interleaved_rows, round_median};
use crate::stats::{ratio, ratio_cell, verdict};
use anyhow::{Context as _, Result, bail};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Samples dropped at the start of every batch.
const DISCARD: usize = 5;
/// A C or C++ agent's round trip may be this many times a Rust agent's.
pub const TARGET: f64 = 1.1;
/// A row's round trip at the largest size may be this many times its round trip at the smallest ("flat").
pub const FLAT_TARGET: f64 = 1.1;
/// The rows, in table order: the pong's language.
const ROWS: [&str; 3] = ["rust", "c", "cpp"];

/// Options of the scenario.
#[derive(Debug, Clone)]
pub struct COpts {
    /// smoke run
    pub quick: bool,
    /// payload sizes, bytes (8, 4096, 230400, 6220800)
    pub sizes: Vec<usize>,
    /// the C and C++ pongs loan zeroed slots (`-DPONG_LOAN_ZEROED`)
    pub loan_zeroed: bool,
    /// measured rounds (a warm-up round comes first, but with `quick`)
    pub rounds: usize,
    /// show children's and compilers' output
    pub verbose: bool,
    /// where the pongs are built and batch files go; removed after the run
    pub work: PathBuf,
}

/// One row at one size (the row is the pong's language: `rust`, `c` or `cpp`).
pub type RowResult = PairRow;

/// A row's ratio to `rust` at one size.
#[derive(Debug, Clone, Serialize)]
pub struct RowRatio {
    /// `c` or `cpp`
    pub row: &'static str,
    /// payload bytes
    pub size: usize,
    /// row / rust, pooled medians
    pub vs_rust_p50: f64,
    /// row / rust, median of the rounds' ratios
    pub vs_rust_round_median: f64,
}

/// A row's median at the largest size over its median at the smallest.
#[derive(Debug, Clone, Serialize)]
pub struct Flatness {
    /// `rust`, `c` or `cpp`
    pub row: &'static str,
    /// (smallest, largest) size, bytes
    pub sizes: (usize, usize),
    /// pooled medians
    pub p50: f64,
    /// median of the rounds' ratios
    pub round_median: f64,
}

/// The scenario's report: the [`Head`](crate::report::Head) and [`CResults`].
pub type CReport = Report<CResults>;

/// The results of the scenario, after the report's head.
#[derive(Debug, Clone, Serialize)]
pub struct CResults {
    /// measured rounds
    pub rounds: usize,
    /// the C and C++ pongs loaned zeroed slots (`--loan-zeroed`), not `nerve_loan_uninit`'s
    pub loan_zeroed: bool,
    /// the compilers that built the pongs (`gcc --version`'s first line, g++'s)
    pub compilers: Vec<String>,
    /// the libnerve the pongs ran on
    pub libnerve: String,
    /// every row at every size
    pub rows: Vec<RowResult>,
    /// `c` and `cpp` against `rust`, per size
    pub ratios: Vec<RowRatio>,
    /// per row, when more than one size ran
    pub flatness: Vec<Flatness>,
    /// see [`TARGET`]
    pub target_ratio: f64,
    /// see [`FLAT_TARGET`]
    pub flat_target: f64,
    /// wall time
    pub seconds: f64,
}

/// The C and C++ pongs, built.
#[derive(Debug)]
struct Pongs {
    c: PathBuf,
    cpp: PathBuf,
    /// what built them
    compilers: Vec<String>,
    /// the libnerve.so they link
    lib: PathBuf,
}

/// The folder of the libnerve.so the pongs link: this executable's own
/// (`target/release` for a release build), checked to hold the library.
fn libnerve_dir() -> Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot find this executable")?;
    let dir = exe.parent().map(Path::to_path_buf).unwrap_or_default();
    if !dir.join("libnerve.so").exists() {
        bail!(
            "{} is missing: build nerve's C API beside this nerve-bench with \
             `cargo build --release -p nerve-agent-c` (or without --release for a debug nerve-bench)",
            dir.join("libnerve.so").display()
        );
    }
    Ok(dir)
}

/// The first line of `compiler --version`, or why it cannot run.
fn compiler_version(compiler: &str) -> Result<String> {
    let out =
        Command::new(compiler).arg("--version").stdin(Stdio::null()).output().with_context(|| {
            format!("cannot run {compiler}: install it (scripts/setup.sh --test installs gcc and g++)")
        })?;
    Ok(String::from_utf8_lossy(&out.stdout).lines().next().unwrap_or_default().to_owned())
}

/// The tree's `bench/c` (the pongs' sources) and `agent-sdk-c/include` (nerve.h, nerve.hpp).
fn source_dirs() -> (PathBuf, PathBuf) {
    let bench = Path::new(env!("CARGO_MANIFEST_DIR"));
    (bench.join("c"), bench.join("../agent-sdk-c/include"))
}

/// The compiler's command for one pong: `compiler -O2 STD FLAGS` with the
/// includes, `source` and `out`, linked to libnerve in `lib` (run path set,
/// so the pong runs without `LD_LIBRARY_PATH`).
fn compile_command(compiler: &str, std: &str, source: &Path, lib: &Path, out: &Path, extra: &[&str]) -> Command {
    let (c_dir, include) = source_dirs();
    let mut cmd = Command::new(compiler);
    cmd.args(["-O2", std, "-Wall", "-Wextra", "-Werror"]).args(extra);
    cmd.arg("-I").arg(&include).arg("-I").arg(&c_dir).arg(source);
    cmd.arg("-L").arg(lib).arg("-lnerve").arg(format!("-Wl,-rpath,{}", lib.display()));
    cmd.arg("-o").arg(out).stdin(Stdio::null());
    cmd
}

/// Compiles `bench/c/pong.c` and `pong.cpp` into `work/build`, with the
/// zeroing loan when `zeroed`.
fn build_pongs(work: &Path, zeroed: bool) -> Result<Pongs> {
    let lib = libnerve_dir()?;
    if lib.ends_with("debug") {
        eprintln!("c: warning: the pongs link a debug libnerve ({}): its numbers say little", lib.display());
    }
    let build = work.join("build");
    std::fs::create_dir_all(&build).with_context(|| format!("cannot create {}", build.display()))?;
    let (c_dir, _) = source_dirs();
    let mut compilers = Vec::new();
    let mut built = Vec::new();
    for (compiler, std, source, exe) in
        [("gcc", "-std=c11", "pong.c", "cpong"), ("g++", "-std=c++17", "pong.cpp", "cpppong")]
    {
        compilers.push(compiler_version(compiler)?);
        let out = build.join(exe);
        let extra: &[&str] = if zeroed { &["-DPONG_LOAN_ZEROED"] } else { &[] };
        let run = compile_command(compiler, std, &c_dir.join(source), &lib, &out, extra)
            .output()
            .with_context(|| format!("cannot run {compiler}"))?;
        if !run.status.success() {
            bail!(
                "{compiler} could not build bench/c/{source} against {}: {}",
                lib.join("libnerve.so").display(),
                String::from_utf8_lossy(&run.stderr).trim()
            );
        }
        built.push(out);
    }
    let cpp = built.pop().unwrap_or_default();
    let c = built.pop().unwrap_or_default();
    Ok(Pongs { c, cpp, compilers, lib: lib.join("libnerve.so") })
}

/// Starts a built pong (`exe`) as agent `name` in `robot`, answering payloads of `size`.
fn spawn_native_pong(robot: &Robot, exe: &Path, name: &str, size: usize) -> Result<ChildGuard> {
    let mut cmd = Command::new(exe);
    cmd.args(["--robot", &robot.name, "--name", name, "--", "--size", &size.to_string()]);
    cmd.env("NERVE_HOME", &robot.home).stdin(Stdio::null());
    robot.quiet(&mut cmd);
    Ok(ChildGuard::spawn(&format!("agent {name}"), cmd)?)
}

/// The short form of a payload size in agent names.
fn tag(size: usize) -> &'static str {
    crate::hop::size_tag(size)
}

/// Starts every pair, waits until they are registered, wires them.
fn start(robot: &Robot, opts: &COpts, pongs: &Pongs) -> Result<(Vec<ChildGuard>, Vec<Pair>)> {
    let (mut children, mut pairs, mut names) = (Vec::new(), Vec::new(), Vec::new());
    for &size in &opts.sizes {
        let count = default_count(size, opts.quick);
        for row in ROWS {
            let (ping, pong) = (format!("ping-{row}-{}", tag(size)), format!("pong-{row}-{}", tag(size)));
            let dir = opts.work.join(&ping);
            std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
            children.push(spawn_bench_agent(robot, "ping", &ping, size, count, &dir)?);
            children.push(match row {
                "rust" => spawn_bench_agent(robot, "pong", &pong, size, count, &dir)?,
                "c" => spawn_native_pong(robot, &pongs.c, &pong, size)?,
                _ => spawn_native_pong(robot, &pongs.cpp, &pong, size)?,
            });
            names.extend([ping.clone(), pong.clone()]);
            pairs.push(Pair { row, size, ping: NervePing::new(ping, dir), pong });
        }
    }
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    robot.wait_registered(&refs, Duration::from_secs(20))?;
    for p in &pairs {
        p.wire_echo(robot)?;
    }
    Ok((children, pairs))
}

/// Runs the scenario.
pub fn run(opts: &COpts) -> Result<CReport> {
    let started = Instant::now();
    for &s in &opts.sizes {
        if !SIZES.contains(&s) && s != 4096 {
            bail!("no payload of {s} bytes: use 8, 4096, 230400 or 6220800");
        }
    }
    let machine = Machine::probe();
    let pongs = build_pongs(&opts.work, opts.loan_zeroed)?;
    eprintln!("c: pongs built against {} ({})", pongs.lib.display(), pongs.compilers.join("; "));
    let robot = Robot::new("c", opts.verbose)?;
    eprintln!(
        "c: robot {} (sizes {:?}, {} rounds, load {:.2})",
        robot.name, opts.sizes, opts.rounds, machine.loadavg_1m
    );
    let router = robot.start_router()?;
    let (children, mut pairs) = start(&robot, opts, &pongs)?;
    eprintln!("c: {} pairs running and wired", pairs.len());
    let plan = Plan { scenario: "c", sizes: &opts.sizes, rounds: opts.rounds, quick: opts.quick, discard: DISCARD };
    let rows = interleaved_rows(plan, &robot, &mut pairs, |size| default_count(size, opts.quick))?;
    drop(children);
    drop(router);
    drop(robot);
    Ok(Report::new(
        "c",
        machine,
        CResults {
            rounds: opts.rounds,
            loan_zeroed: opts.loan_zeroed,
            compilers: pongs.compilers,
            libnerve: pongs.lib.display().to_string(),
            ratios: ratios(&rows),
            flatness: flatness(&rows),
            rows,
            target_ratio: TARGET,
            flat_target: FLAT_TARGET,
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
}

/// `c` and `cpp` against `rust`, at each size where both ran.
fn ratios(rows: &[RowResult]) -> Vec<RowRatio> {
    let find = |row: &str, size: usize| rows.iter().find(|r| r.row == row && r.size == size);
    rows.iter()
        .filter(|r| r.row != "rust")
        .filter_map(|r| {
            let rust = find("rust", r.size)?;
            Some(RowRatio {
                row: r.row,
                size: r.size,
                vs_rust_p50: ratio(r.round_trip.p50_ns, rust.round_trip.p50_ns),
                vs_rust_round_median: round_median(&r.round_p50_ns, &rust.round_p50_ns),
            })
        })
        .collect()
}

/// Each row's median at its largest size over its smallest, when it ran at two sizes or more.
fn flatness(rows: &[RowResult]) -> Vec<Flatness> {
    ROWS.iter()
        .filter_map(|&row| {
            let of_row = || rows.iter().filter(move |r| r.row == row);
            let lo = of_row().min_by_key(|r| r.size)?;
            let hi = of_row().max_by_key(|r| r.size)?;
            (lo.size < hi.size).then(|| Flatness {
                row,
                sizes: (lo.size, hi.size),
                p50: ratio(hi.round_trip.p50_ns, lo.round_trip.p50_ns),
                round_median: round_median(&hi.round_p50_ns, &lo.round_p50_ns),
            })
        })
        .collect()
}

/// Prints the tables (markdown).
pub fn print_tables(r: &CReport) {
    let cell = |row: &str, size: usize| PairRow::cells(&r.rows, row, size);
    let vs = |row: &str, size: usize| {
        r.ratios.iter().find(|x| x.row == row && x.size == size).map(|x| (x.vs_rust_p50, x.vs_rust_round_median))
    };
    let both = |v: Option<(f64, f64)>| v.map(|(p, m)| format!("{p:.2} ({m:.2})")).unwrap_or_else(|| "-".into());
    println!(
        "### C and C++ agents beside a Rust agent (one-hop round trip, Rust ping, µs; load {:.2}{})\n",
        r.head.machine.loadavg_1m,
        if r.loan_zeroed { "; C and C++ pongs with the zeroing loan" } else { "" }
    );
    println!(
        "| payload | rust p50 | p99 | c p50 | p99 | c/rust (rounds) | c++ p50 | p99 | c++/rust (rounds) | target ≤{TARGET} |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let mut sizes: Vec<usize> = r.rows.iter().map(|x| x.size).collect();
    sizes.dedup();
    for size in sizes {
        let (c, cpp) = (vs("c", size), vs("cpp", size));
        let met = c.zip(cpp).map(|(a, b)| a.0 <= TARGET && b.0 <= TARGET);
        println!(
            "| {} | {} | {} | {} | {} | {} | {} |",
            label(size),
            cell("rust", size),
            cell("c", size),
            both(c),
            cell("cpp", size),
            both(cpp),
            verdict(met)
        );
    }
    for f in &r.flatness {
        println!(
            "\n{} p50 at {} / at {}: {} (median of the rounds' ratios {}; flat: ≤{FLAT_TARGET}, {})",
            f.row,
            label(f.sizes.1),
            label(f.sizes.0),
            ratio_cell(Some(f.p50)),
            ratio_cell(Some(f.round_median)),
            verdict(Some(f.p50 <= FLAT_TARGET))
        );
    }
}

/// Where a run's pongs and batch files go.
pub fn work_dir(out: &Path) -> PathBuf {
    out.join(format!("c-work-{}", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::Summary;

    /// The pongs' sources compile against the tree's nerve.h and nerve.hpp
    /// (syntax and types only: no libnerve is needed, nothing is linked),
    /// with the zeroing loan as well, so a change of the C API that breaks
    /// them is caught without running the benchmark.
    #[test]
    fn the_c_and_cpp_pongs_compile_against_the_headers() {
        let (c_dir, _) = source_dirs();
        let nowhere = Path::new("/nonexistent");
        for (compiler, std, source) in [("gcc", "-std=c11", "pong.c"), ("g++", "-std=c++17", "pong.cpp")] {
            for extra in [&["-fsyntax-only"][..], &["-fsyntax-only", "-DPONG_LOAN_ZEROED"]] {
                let out = compile_command(compiler, std, &c_dir.join(source), nowhere, nowhere, extra)
                    .output()
                    .unwrap_or_else(|e| panic!("run {compiler} (scripts/setup.sh --test installs it): {e}"));
                assert!(
                    out.status.success(),
                    "{compiler} {extra:?} refused bench/c/{source}: {}",
                    String::from_utf8_lossy(&out.stderr)
                );
            }
        }
    }

    fn row(row: &'static str, size: usize, p50: u64, rounds: &[u64]) -> RowResult {
        RowResult { row, size, batch: 1, round_trip: Summary::of(&[p50]), round_p50_ns: rounds.to_vec() }
    }

    #[test]
    fn ratios_are_against_rust_of_the_same_size_and_flatness_spans_the_sizes() {
        let rows = [
            row("rust", 8, 10_000, &[10_000, 10_000]),
            row("c", 8, 11_000, &[11_000, 12_000]),
            row("rust", 6_220_800, 20_000, &[20_000, 20_000]),
            row("c", 6_220_800, 22_000, &[22_000, 22_000]),
        ];
        let r = ratios(&rows);
        assert_eq!(r.len(), 2);
        assert!((r[0].vs_rust_p50 - 1.1).abs() < 1e-9 && (r[0].vs_rust_round_median - 1.15).abs() < 1e-9);
        assert!((r[1].vs_rust_p50 - 1.1).abs() < 1e-9);
        let f = flatness(&rows);
        assert_eq!(f.iter().map(|x| x.row).collect::<Vec<_>>(), ["rust", "c"]);
        assert_eq!(f[1].sizes, (8, 6_220_800));
        assert!((f[0].p50 - 2.0).abs() < 1e-9);
    }
}
