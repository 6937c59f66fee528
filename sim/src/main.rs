//! `nerve-sim`: run a simulated robot in real time, its devices published as
//! pseudo-terminals.
//!
//! ```text
//! nerve-sim --world worlds/test-room.toml --robot-model h1 --dev-dir /tmp/h1 \
//!           --truth truth.csv --seed 7 [--duration 60]
//! ```
//! An agent then opens `/tmp/h1/sonar`, `/tmp/h1/motor`, ... as serial ports.
//! SIGTERM or SIGINT stops it cleanly and removes the links.

use std::path::PathBuf;

use anyhow::Context;
use clap::Parser;
use nerve_sim::{NoiseModel, RobotKind, RunOptions};

/// Simulate a nerve robot (H1 or H2) and expose its devices as serial ports.
#[derive(Debug, Parser)]
#[command(name = "nerve-sim", version)]
struct Cli {
    /// World file (TOML).
    #[arg(long)]
    world: PathBuf,
    /// Robot model: h1 (sonar, pan-tilt camera, IR) or h2 (arm, camera, IR).
    #[arg(long, default_value = "h1", value_parser = parse_robot)]
    robot_model: RobotKind,
    /// Directory in which to publish the device links (sonar, motor, head, ir, arm).
    #[arg(long)]
    dev_dir: PathBuf,
    /// Ground-truth CSV log, one row per step.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Seed of every random draw (slip, sonar, IR).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Stop after this many simulated seconds (default: run until SIGTERM/SIGINT).
    #[arg(long)]
    duration: Option<f64>,
    /// Simulation steps per second.
    #[arg(long, default_value_t = 100.0)]
    rate: f64,
    /// Turn every noise source off (exact geometry).
    #[arg(long)]
    no_noise: bool,
    /// Log filter (tracing env-filter syntax), e.g. `info` or `nerve_sim=debug`.
    #[arg(long, env = "NERVE_LOG", default_value = "info")]
    log: String,
}

fn parse_robot(s: &str) -> Result<RobotKind, String> {
    s.parse()
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_new(&cli.log)
                .with_context(|| format!("invalid --log filter {:?}", cli.log))?,
        )
        .with_writer(std::io::stderr)
        .init();
    let stop = nerve_sim::install_stop_handler()?;
    let opts = RunOptions {
        world: cli.world,
        robot: cli.robot_model,
        dev_dir: cli.dev_dir,
        truth: cli.truth,
        seed: cli.seed,
        duration: cli.duration,
        rate_hz: cli.rate,
        noise: if cli.no_noise { NoiseModel::none() } else { NoiseModel::default() },
    };
    nerve_sim::run(&opts, stop).context("nerve-sim failed")?;
    Ok(())
}
