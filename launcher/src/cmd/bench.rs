//! `nerve bench SCENARIO [--quick] [--json] [...]`: runs a scenario of the
//! benchmark program `nerve-bench` (crate `bench/`), found next to `nerve` or
//! on `PATH`, in place of this process, so that its progress, tables, exit
//! status and Ctrl-C behave exactly as if it had been called directly.
//!
//! The scenarios and what they measure are described in BENCHMARKS.md. Every
//! scenario starts robots of its own (`b<pid>...`) and takes them down; the
//! `--robot` option of `nerve` does not apply. [`exec_program`], which runs
//! a program beside `nerve` in its place, serves `nerve demo` and `nerve
//! calibrate` too.

use crate::kinds::find_program;
use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use std::ffi::OsStr;
use std::os::unix::process::CommandExt as _;
use std::process::{Command, ExitCode};

/// The program that holds the scenarios.
const BENCH_PROGRAM: &str = "nerve-bench";

/// The benchmark scenarios (issue 7 of the project; `bridge`: issue 11).
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Scenario {
    /// One hop: nerve ports vs raw iceoryx2 vs a Unix socket vs Cyclone DDS (ddsperf) vs dora-rs, 8 B to 1080p.
    Hop,
    /// Three hops end to end (sonar → safety → motor shape) against one hop.
    Pipeline,
    /// Lateness of a periodic task at 1 kHz and 100 Hz beside cyclictest.
    Jitter,
    /// The short-term-memory image path with 1, 4 and 8 readers.
    Images,
    /// Control plane: hot-add, rewire, launch of 10 and 50 agents.
    Control,
    /// 100 agents at 10 Hz: CPU, router CPU, memory per agent, `nerve ps` time.
    Scale,
    /// The Zenoh bridge: one way across it vs raw Zenoh, and its cost on the local round trip.
    Bridge,
    /// The exploration robot plus churn for N minutes (`--minutes N`): memory, descriptors, files, latencies.
    Soak,
    /// What recording costs: one hop with `nerve record --all` vs without, images to MCAP, echo of a custom type.
    Record,
    /// What watching costs: one hop while `nerve ui` serves a browser showing the page vs without.
    Ui,
    /// What `nerve foxglove` costs: one hop with a client on every channel vs without; a camera to one client.
    Foxglove,
    /// Issue 42's messages: a sequence sample's hop beside a fixed payload's (8 B to 8 MB), a call's round trip.
    Messages,
    /// Robots meeting through one Zenoh router, 2 to 16, each in its own network namespace: join time, latency, router CPU.
    Fleet,
    /// C and C++ agents: their one-hop round trip beside a Rust agent's, 8 B to 1080p (issue 43).
    C,
    /// Issue 44's ROS 2 measures: a 640x480 Image from the ring onto the wire; Twist through the ros2 agent vs a raw Zenoh put.
    Ros2,
}

/// `nerve bench`
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// The scenario to run.
    pub scenario: Scenario,
    /// Options of the scenario, passed on to `nerve-bench SCENARIO`: `--quick`
    /// (a smoke run of a few seconds), `--json` (machine-readable results with
    /// the ratios), `--out DIR`, ... (`nerve bench SCENARIO --help` lists them).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<String>,
}

/// Replaces this process with `nerve-bench SCENARIO ARGS...`.
pub fn bench(a: BenchArgs) -> Result<ExitCode> {
    let scenario = a.scenario.to_possible_value().map(|v| v.get_name().to_owned()).unwrap_or_default();
    let hint =
        "build it with `cargo build --release -p nerve-bench -p nerve --bins` and run target/release/nerve bench";
    exec_program(BENCH_PROGRAM, hint, std::iter::once(scenario.as_str()).chain(a.args.iter().map(String::as_str)))
}

/// Replaces this process with `program ARGS...`, found next to `nerve` or on
/// `PATH`, with `NERVE_BIN` naming this `nerve` (the program starts robots
/// with it); where it is not found, says so and how to build it (`build`).
/// Returns only on failure.
pub fn exec_program<S: AsRef<OsStr>>(
    program: &str,
    build: &str,
    args: impl IntoIterator<Item = S>,
) -> Result<ExitCode> {
    let Some(path) = find_program(program) else {
        bail!("{program} is not installed next to nerve or on PATH; {build}");
    };
    let mut cmd = Command::new(&path);
    cmd.args(args);
    if let Ok(me) = std::env::current_exe() {
        cmd.env("NERVE_BIN", me);
    }
    let err = cmd.exec();
    bail!("cannot run {}: {err}", path.display())
}
