//! `nerve-bench`: the benchmarks behind BENCHMARKS.md.
//!
//! ```text
//! nerve-bench hop    [--quick] [--json] [--out DIR] [--payloads 8,230400,6220800] [--rounds N] [--rows R,..]
//! nerve-bench jitter [--quick] [--json] [--out DIR] [--rates 1000,100] [--seconds S] [--rounds N]
//! nerve-bench control [--quick] [--json] [--out DIR] [--rounds N] [--launch 10,50]
//! nerve-bench bridge [--quick] [--json] [--out DIR] [--payloads 8,4096,230400] [--rounds N]
//! nerve-bench foxglove [--quick] [--json] [--out DIR] [--payloads 8,4096] [--rounds N] [--seconds S]
//! ```
//!
//! * `hop`: one-hop round-trip latency, event-driven, nerve SDK agents
//!   against raw iceoryx2 (WaitSet and listener) and a Unix socket, and,
//!   when installed, Cyclone DDS (`ddsperf`) and dora-rs (two nodes run by
//!   `dora run`, built by `scripts/setup.sh --bench`).
//! * `jitter`: lateness of a periodic SDK agent against `cyclictest`.
//! * `control`: hot-add, rewire and launch latencies of the control plane.
//! * `bridge`: one way across the Zenoh bridge agent against raw Zenoh, and
//!   the cost of a bridge on the local one-hop round trip.
//! * `foxglove`: one hop while `nerve foxglove` serves a Foxglove client
//!   subscribed to every channel vs without, and a 640x480 camera at 30 fps
//!   to one client.
//!
//! Results go to `DIR/<scenario>.json` (and `DIR/hop-latency.png`); the
//! tables are printed as markdown on stdout, or the JSON with `--json`.
//! Progress goes to stderr. Every run uses a robot of its own (`b<pid>h`,
//! `b<pid>j`) and takes it down at the end.
//!
//! The same executable also runs the processes of the benchmarks, through
//! hidden subcommands: `__agent-ping`, `__agent-pong`, `__agent-jitter` (SDK
//! agents), `__raw-pong`, `__uds-pong`, `__futex-pong` and `__busy`; for `bridge`,
//! `__agent-bsend`, `__agent-bsink`, `__bridge` (the bridge agent, carrying
//! the benchmark's payloads), `__zenoh-pub` and `__zenoh-sub`.

mod agents;
mod bridge;
mod bridge_agents;
mod c_hop;
mod control;
mod dds;
mod dora;
mod fleet;
mod foxglove_cost;
mod futex;
mod hop;
mod idle;
mod images;
mod jitter;
mod machine;
mod messages;
mod observed;
mod payloads;
mod pipeline;
mod plot;
mod plot_images;
mod procs;
mod raw;
mod recording;
mod report;
mod ros2;
mod scale;
mod shared_page;
mod soak;
mod stats;
mod uds;
mod ui_cost;
mod zenoh_raw;

use anyhow::{Context as _, Result};
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// Benchmarks of nerve.
#[derive(Debug, Parser)]
#[command(name = "nerve-bench", about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    scenario: Scenario,
}

#[derive(Debug, clap::Args)]
struct Common {
    /// A smoke run of a few seconds.
    #[arg(long)]
    quick: bool,
    /// Print the results as JSON on stdout instead of tables.
    #[arg(long)]
    json: bool,
    /// Directory for the JSON results (and the plot).
    #[arg(long, default_value = "bench-results")]
    out: PathBuf,
    /// Show the output of the processes the benchmark starts.
    #[arg(long)]
    verbose: bool,
}

#[derive(Debug, Subcommand)]
enum Scenario {
    /// One-hop round-trip latency: nerve SDK vs raw iceoryx2 vs Unix socket.
    Hop {
        #[command(flatten)]
        common: Common,
        /// Payload sizes in bytes.
        #[arg(long, value_delimiter = ',', default_values_t = payloads::SIZES)]
        payloads: Vec<usize>,
        /// Measured rounds (each transport one batch per round, interleaved).
        #[arg(long)]
        rounds: Option<usize>,
        /// Round trips per batch (default by payload size).
        #[arg(long)]
        count: Option<usize>,
        /// Only these rows (e.g. `nerve-poll,iox2-poll,iox2-poll-ts`); all by default.
        #[arg(long, value_delimiter = ',')]
        rows: Option<Vec<String>>,
    },
    /// Control plane: hot-add, rewire, launch of 10 and 50 agents.
    Control {
        #[command(flatten)]
        common: Common,
        /// Hot-add and rewire repetitions.
        #[arg(long)]
        rounds: Option<usize>,
        /// Launch sizes (agents per launch file).
        #[arg(long, value_delimiter = ',')]
        launch: Option<Vec<usize>>,
        /// Another relay executable (another build's `nerve-relay`) hot-added
        /// in alternate rounds beside `relay`, and reported as a row of its
        /// own: a change in an agent's start-up measured side by side.
        #[arg(long, value_name = "PATH")]
        hot_add_beside: Option<std::path::PathBuf>,
    },
    /// Three hops end to end (sonar → safety → motor shape) against one hop, SDK agents.
    Pipeline {
        #[command(flatten)]
        common: Common,
        /// Payload sizes in bytes.
        #[arg(long, value_delimiter = ',', default_values_t = [8usize, 230_400])]
        payloads: Vec<usize>,
        /// Measured rounds (each path one batch per round, interleaved).
        #[arg(long)]
        rounds: Option<usize>,
    },
    /// 100 agents at 10 Hz: machine, agent and router CPU, memory per agent (RSS, PSS), `nerve ps` time.
    Scale {
        #[command(flatten)]
        common: Common,
        /// Agents in all (half tickers, half relays).
        #[arg(long, default_value_t = 100)]
        agents: usize,
        /// Period of the tickers, in ms.
        #[arg(long, default_value_t = 100)]
        period_ms: u64,
        /// Measuring window, in seconds.
        #[arg(long)]
        window: Option<f64>,
    },
    /// Frames to 1, 4 and 8 readers: nerve's short-term memory vs iceoryx2 slices vs Unix socket.
    Images {
        #[command(flatten)]
        common: Common,
        /// Resolutions (RGB).
        #[arg(long, value_delimiter = ',', default_values_t = ["320x240".to_owned(), "640x480".to_owned(), "1920x1080".to_owned()])]
        resolutions: Vec<String>,
        /// Reader counts, 1 to 8 (default 1,4,8; 1,8 with --quick).
        #[arg(long, value_delimiter = ',')]
        readers: Option<Vec<usize>>,
        /// Measured rounds (each transport one paced and one closed-loop batch per round, interleaved).
        #[arg(long)]
        rounds: Option<usize>,
        /// Frames per second of the paced batches.
        #[arg(long, default_value_t = 200.0)]
        rate: f64,
        /// Seconds per paced batch.
        #[arg(long)]
        seconds: Option<f64>,
        /// Seconds per closed-loop batch.
        #[arg(long)]
        max_seconds: Option<f64>,
    },
    /// The Zenoh bridge: one way across it vs raw Zenoh (8 B, 4 KB, 230 KB), and its cost on the local round trip.
    Bridge {
        #[command(flatten)]
        common: Common,
        /// Payload sizes in bytes.
        #[arg(long, value_delimiter = ',', default_values_t = bridge::SIZES)]
        payloads: Vec<usize>,
        /// Measured rounds (each system one batch per round and size, interleaved).
        #[arg(long)]
        rounds: Option<usize>,
        /// One-way samples per latency batch.
        #[arg(long)]
        count: Option<usize>,
        /// Microseconds between two samples of a latency batch.
        #[arg(long, default_value_t = 5000)]
        interval_us: u64,
        /// Longest back-to-back throughput batch, ms.
        #[arg(long)]
        tput_ms: Option<u64>,
        /// Round trips per local batch.
        #[arg(long)]
        hop_count: Option<usize>,
    },
    /// The exploration robot plus churn for N minutes: memory, descriptors, files and latencies sampled and plotted.
    Soak {
        #[command(flatten)]
        common: Common,
        /// How long, in minutes (--quick: a quarter).
        #[arg(long, default_value_t = 10.0)]
        minutes: f64,
        /// Seconds between two samples.
        #[arg(long, default_value_t = 10.0)]
        every: f64,
        /// Seconds between two churn cycles (hot-add, wire, unwire, stop).
        #[arg(long, default_value_t = 5.0)]
        churn: f64,
        /// The robot's launch file (its paths are taken from the folder above the file's).
        #[arg(long)]
        launch: Option<PathBuf>,
    },
    /// What recording costs: one hop with `nerve record --all` vs without, camera frames to MCAP, echo of a custom type.
    Record {
        #[command(flatten)]
        common: Common,
        /// Payload sizes of the hop, in bytes.
        #[arg(long, value_delimiter = ',', default_values_t = [8usize, 230_400])]
        payloads: Vec<usize>,
        /// Measured hop rounds (each condition one batch per round, interleaved).
        #[arg(long)]
        rounds: Option<usize>,
        /// Seconds per image recording (default 60; 10 with --quick).
        #[arg(long)]
        seconds: Option<f64>,
    },
    /// What watching costs: one hop while `nerve ui` serves a browser showing the page vs without.
    Ui {
        #[command(flatten)]
        common: Common,
        /// Payload sizes of the hop, in bytes.
        #[arg(long, value_delimiter = ',', default_values_t = [8usize, 230_400])]
        payloads: Vec<usize>,
        /// Measured rounds (each condition one batch per round, interleaved).
        #[arg(long)]
        rounds: Option<usize>,
    },
    /// What Foxglove costs: one hop while `nerve foxglove` serves a client subscribed to every channel vs
    /// without, and a 640x480 camera at 30 fps to one client (server CPU per frame, frames delivered).
    Foxglove {
        #[command(flatten)]
        common: Common,
        /// Payload sizes of the hop, in bytes.
        #[arg(long, value_delimiter = ',', default_values_t = [8usize, 4096])]
        payloads: Vec<usize>,
        /// Measured rounds (each condition one batch per round, interleaved).
        #[arg(long)]
        rounds: Option<usize>,
        /// Seconds the camera's frames are counted (default 20; 2 with --quick).
        #[arg(long)]
        seconds: Option<f64>,
        /// The client script (default: tests/js/foxglove/client.js of this build's tree, `npm ci` done there).
        #[arg(long)]
        client: Option<PathBuf>,
    },
    /// Issue 42's messages: a sequence sample's hop beside a fixed payload's (8 B to 8 MB), a call's round trip.
    Messages {
        #[command(flatten)]
        common: Common,
        /// Sample sizes in bytes (8 to 8388608).
        #[arg(long, value_delimiter = ',', default_values_t = messages::SIZES)]
        payloads: Vec<usize>,
        /// Measured rounds (each row one batch per round and size, interleaved).
        #[arg(long)]
        rounds: Option<usize>,
    },
    /// Robots meeting through one Zenoh router (issue 44): join time, latency and the router's CPU for 2 to 16 robots, each in its own network namespace.
    Fleet {
        #[command(flatten)]
        common: Common,
        /// Fleet sizes (2 to 64 robots).
        #[arg(long, value_delimiter = ',', default_values_t = fleet::ROBOTS)]
        robots: Vec<usize>,
        /// Measured window per fleet size, in seconds (default 5; 2 with --quick).
        #[arg(long)]
        seconds: Option<f64>,
        /// Period of every robot's ticker, in ms.
        #[arg(long, default_value_t = 20)]
        period_ms: u64,
        /// All robots on loopback instead of a network namespace each (no root needed).
        #[arg(long)]
        no_netns: bool,
    },
    /// C and C++ agents (issue 43): their one-hop round trip beside a Rust agent's, 8 B to 1080p.
    C {
        #[command(flatten)]
        common: Common,
        /// Payload sizes in bytes (8, 4096, 230400, 6220800).
        #[arg(long, value_delimiter = ',', default_values_t = payloads::SIZES)]
        payloads: Vec<usize>,
        /// Measured rounds (each row one batch per round and size, interleaved).
        #[arg(long)]
        rounds: Option<usize>,
        /// Build the C and C++ pongs with the zeroing loan (`nerve_loan`, the C API's only one
        /// before `nerve_loan_uninit`): what writing the whole slot costs.
        #[arg(long)]
        loan_zeroed: bool,
    },
    /// Issue 44's ROS 2 measures: a 640x480 Image from the ring onto rmw_zenoh's wire, Twist through the ros2 agent vs a raw Zenoh put.
    Ros2 {
        #[command(flatten)]
        common: Common,
        /// Image events, as many Twist events, and as many raw puts of each (default 300; 40 with --quick).
        #[arg(long)]
        count: Option<usize>,
    },
    /// Periodic-task lateness: an SDK periodic agent vs cyclictest.
    Jitter {
        #[command(flatten)]
        common: Common,
        /// Rates in Hz.
        #[arg(long, value_delimiter = ',', default_values_t = [1000u64, 100])]
        rates: Vec<u64>,
        /// Seconds per chunk.
        #[arg(long)]
        seconds: Option<f64>,
        /// Chunks per system and condition (interleaved).
        #[arg(long)]
        rounds: Option<usize>,
    },
}

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    if let Some(first) = args.next() {
        let rest: Vec<String> = args.collect();
        match first.as_str() {
            "__agent-ping" | "__agent-pong" | "__agent-jitter" => {
                return agents::run_agent(&first, rest);
            }
            "__raw-pong" => return raw::pong_main(rest),
            "__uds-pong" => return uds::pong_main(rest),
            "__futex-pong" => return futex::pong_main(rest),
            "__busy" => return jitter::busy_main(),
            "__agent-bsend" | "__agent-bsink" => return bridge_agents::run_agent(&first, rest),
            "__bridge" => return bridge_agents::bridge_main(rest),
            "__zenoh-pub" => return zenoh_raw::pub_main(rest),
            "__zenoh-sub" => return zenoh_raw::sub_main(rest),
            "__agent-img-writer" | "__agent-img-reader" => return images::run_agent(&first, rest),
            "__img-iox2-reader" => return images::iox2_reader_main(rest),
            "__img-uds-reader" => return images::uds_reader_main(rest),
            "__agent-seqping" | "__agent-seqpong" | "__agent-callping" | "__agent-callserve" => {
                return messages::run_agent(&first, rest);
            }
            "__agent-ros2-src" => return ros2::run_agent(rest),
            _ => {}
        }
    }
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// Fewest samples per batch: more than the ones dropped at its start.
const DISCARD_MIN: usize = 10;

fn write_json(out: &std::path::Path, name: &str, value: &impl serde::Serialize) -> Result<PathBuf> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let path = out.join(name);
    let s = serde_json::to_string_pretty(value).context("cannot encode the results")?;
    std::fs::write(&path, s + "\n").with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// Writes `report` to `OUT/NAME.json`, then its figures (`plot` returns
/// the files it wrote), says where they are on stderr, and prints the
/// report on stdout: as JSON with `--json`, else as markdown tables.
fn publish<R: serde::Serialize>(
    common: &Common,
    name: &str,
    report: &R,
    seconds: f64,
    plot: impl FnOnce(&R) -> Result<Vec<PathBuf>>,
    tables: fn(&R),
) -> Result<()> {
    let mut files = vec![write_json(&common.out, &format!("{name}.json"), report)?];
    files.extend(plot(report)?);
    let files: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    eprintln!("{name}: results in {} ({seconds:.0} s)", files.join(" and "));
    if common.json {
        println!("{}", serde_json::to_string_pretty(report).context("cannot encode the results")?);
    } else {
        tables(report);
    }
    Ok(())
}

/// Runs a scenario whose files go in `work`, then removes `work`, also
/// when the run failed.
fn removing_work<R>(work: &std::path::Path, run: impl FnOnce() -> Result<R>) -> Result<R> {
    let report = run();
    let _ = std::fs::remove_dir_all(work);
    report
}

/// The plot step of [`publish`] for a figure that may fail without failing
/// the run: `draw` writes `OUT/FILE`; its error is a warning.
fn plot_or_warn<R>(
    out: &std::path::Path,
    file: &str,
    draw: fn(&R, &std::path::Path) -> Result<()>,
) -> impl FnOnce(&R) -> Result<Vec<PathBuf>> {
    let png = out.join(file);
    move |r| {
        if let Err(e) = draw(r, &png) {
            eprintln!("warning: no plot: {e:#}");
        }
        Ok(vec![png])
    }
}

fn run(cli: Cli) -> Result<()> {
    if cfg!(debug_assertions) {
        eprintln!(
            "warning: this nerve-bench is a debug build: its numbers say little. \
             Build with `cargo build --release -p nerve-bench -p nerve --bins`."
        );
    }
    match cli.scenario {
        Scenario::Pipeline { common, payloads, rounds } => {
            let opts = pipeline::PipelineOpts {
                quick: common.quick,
                sizes: payloads,
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 7 }).max(1),
                verbose: common.verbose,
                work: common.out.join(format!("pipeline-work-{}", std::process::id())),
            };
            let report = removing_work(&opts.work, || pipeline::run(&opts))?;
            publish(&common, "pipeline", &report, report.seconds, |_| Ok(vec![]), pipeline::print_tables)?;
        }
        Scenario::Record { common, payloads, rounds, seconds } => {
            let opts = recording::RecordOpts {
                quick: common.quick,
                sizes: payloads,
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 7 }).max(1),
                image_seconds: seconds.unwrap_or(if common.quick { 10.0 } else { 60.0 }).max(1.0),
                echo_runs: if common.quick { 3 } else { 9 },
                verbose: common.verbose,
                work: recording::work_dir(&common.out),
            };
            let report = removing_work(&opts.work, || recording::run(&opts))?;
            publish(&common, "record", &report, report.seconds, |_| Ok(vec![]), recording::print_tables)?;
        }
        Scenario::Ui { common, payloads, rounds } => {
            let opts = ui_cost::UiOpts {
                quick: common.quick,
                sizes: payloads,
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 7 }).max(1),
                verbose: common.verbose,
                work: ui_cost::work_dir(&common.out),
            };
            let report = removing_work(&opts.work, || ui_cost::run(&opts))?;
            publish(&common, "ui", &report, report.seconds, |_| Ok(vec![]), ui_cost::print_tables)?;
        }
        Scenario::Foxglove { common, payloads, rounds, seconds, client } => {
            let opts = foxglove_cost::FoxOpts {
                quick: common.quick,
                sizes: payloads,
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 7 }).max(1),
                camera_seconds: seconds.unwrap_or(if common.quick { 2.0 } else { 20.0 }).clamp(0.5, 3600.0),
                client: client.unwrap_or_else(foxglove_cost::default_client),
                verbose: common.verbose,
                work: foxglove_cost::work_dir(&common.out),
            };
            let report = removing_work(&opts.work, || foxglove_cost::run(&opts))?;
            publish(&common, "foxglove", &report, report.seconds, |_| Ok(vec![]), foxglove_cost::print_tables)?;
        }
        Scenario::Scale { common, agents, period_ms, window } => {
            let opts = scale::ScaleOpts {
                agents: if common.quick { agents.min(20) } else { agents }.max(2),
                period_ms: period_ms.max(1),
                window_s: window.unwrap_or(if common.quick { 2.0 } else { 20.0 }),
                ps_runs: if common.quick { 3 } else { 20 },
                verbose: common.verbose,
            };
            let report = scale::run(&opts)?;
            publish(&common, "scale", &report, report.seconds, |_| Ok(vec![]), scale::print_tables)?;
        }
        Scenario::Soak { common, minutes, every, churn, launch } => {
            let launch =
                launch.unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../launch/explore.toml"));
            let opts = soak::SoakOpts {
                minutes: if common.quick { 0.25 } else { minutes },
                every_s: if common.quick { 2.0 } else { every },
                churn_s: churn,
                launch,
                verbose: common.verbose,
            };
            let report = soak::run(&opts)?;
            let plot = |r: &_| {
                let png = common.out.join("soak.png");
                soak::png(r, &png)?;
                Ok(vec![png])
            };
            publish(&common, "soak", &report, report.seconds, plot, soak::print_tables)?;
        }
        Scenario::Hop { common, payloads, rounds, count, rows } => {
            let opts = hop::HopOpts {
                quick: common.quick,
                sizes: payloads,
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 7 }).max(1),
                count,
                rows,
                verbose: common.verbose,
                work: hop::work_dir(&common.out),
            };
            let report = removing_work(&opts.work, || hop::run(&opts))?;
            let plot = plot_or_warn(&common.out, "hop-latency.png", plot::hop_png);
            publish(&common, "hop", &report, report.seconds, plot, hop::print_tables)?;
        }
        Scenario::Control { common, rounds, launch, hot_add_beside } => {
            let opts = control::ControlOpts {
                hot_add_beside,
                rounds: rounds.unwrap_or(if common.quick { 3 } else { 20 }).max(1),
                launch_sizes: launch.unwrap_or(if common.quick { vec![10] } else { vec![10, 50] }),
                launch_rounds: if common.quick { 1 } else { 3 },
                verbose: common.verbose,
            };
            let report = control::run(&opts)?;
            publish(&common, "control", &report, report.seconds, |_| Ok(vec![]), control::print_tables)?;
        }
        Scenario::Images { common, resolutions, readers, rounds, rate, seconds, max_seconds } => {
            let opts = images::ImagesOpts {
                quick: common.quick,
                resolutions,
                readers: readers.unwrap_or(if common.quick { vec![1, 8] } else { vec![1, 4, 8] }),
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 5 }).max(1),
                rate,
                paced_seconds: seconds.unwrap_or(if common.quick { 0.25 } else { 0.5 }),
                max_seconds: max_seconds.unwrap_or(if common.quick { 0.15 } else { 0.3 }),
                verbose: common.verbose,
                work: images::work_dir(&common.out),
            };
            let report = removing_work(&opts.work, || images::run(&opts))?;
            let plot = plot_or_warn(&common.out, "images-latency.png", plot_images::images_png);
            publish(&common, "images", &report, report.seconds, plot, images::print_tables)?;
        }
        Scenario::Bridge { common, payloads, rounds, count, interval_us, tput_ms, hop_count } => {
            let opts = bridge::BridgeOpts {
                quick: common.quick,
                sizes: payloads,
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 5 }).max(1),
                count: count.unwrap_or(if common.quick { 30 } else { 300 }).max(DISCARD_MIN),
                interval_us: interval_us.max(1),
                tput_ms: tput_ms.unwrap_or(if common.quick { 150 } else { 500 }).max(1),
                hop_count: hop_count.unwrap_or(if common.quick { 100 } else { 2000 }).max(DISCARD_MIN),
                verbose: common.verbose,
                work: common.out.join(format!("bridge-work-{}", std::process::id())),
            };
            let report = removing_work(&opts.work, || bridge::run(&opts))?;
            publish(&common, "bridge", &report, report.seconds, |_| Ok(vec![]), bridge::print_tables)?;
        }
        Scenario::Messages { common, payloads, rounds } => {
            let opts = messages::MessagesOpts {
                quick: common.quick,
                sizes: payloads,
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 9 }).max(1),
                verbose: common.verbose,
                work: messages::work_dir(&common.out),
            };
            let report = removing_work(&opts.work, || messages::run(&opts))?;
            publish(&common, "messages", &report, report.seconds, |_| Ok(vec![]), messages::print_tables)?;
        }
        Scenario::Fleet { common, robots, seconds, period_ms, no_netns } => {
            let opts = fleet::FleetOpts {
                robots: if common.quick { vec![2, 4] } else { robots },
                seconds: seconds.unwrap_or(if common.quick { 2.0 } else { 5.0 }).clamp(0.5, 600.0),
                period_ms: period_ms.clamp(1, 10_000),
                netns: !no_netns,
                verbose: common.verbose,
            };
            let report = fleet::run(&opts)?;
            publish(&common, "fleet", &report, report.seconds, |_| Ok(vec![]), fleet::print_tables)?;
        }
        Scenario::C { common, payloads, rounds, loan_zeroed } => {
            let opts = c_hop::COpts {
                quick: common.quick,
                sizes: payloads,
                loan_zeroed,
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 7 }).max(1),
                verbose: common.verbose,
                work: c_hop::work_dir(&common.out),
            };
            let report = removing_work(&opts.work, || c_hop::run(&opts))?;
            publish(&common, "c", &report, report.seconds, |_| Ok(vec![]), c_hop::print_tables)?;
        }
        Scenario::Ros2 { common, count } => {
            let opts = ros2::Ros2Opts {
                count: count.unwrap_or(if common.quick { 40 } else { 300 }),
                verbose: common.verbose,
                work: ros2::work_dir(&common.out),
            };
            let report = removing_work(&opts.work, || ros2::run(&opts))?;
            publish(&common, "ros2", &report, report.seconds, |_| Ok(vec![]), ros2::print_tables)?;
        }
        Scenario::Jitter { common, rates, seconds, rounds } => {
            let opts = jitter::JitterOpts {
                rates,
                seconds: seconds.unwrap_or(if common.quick { 1.0 } else { 5.0 }),
                rounds: rounds.unwrap_or(if common.quick { 1 } else { 3 }).max(1),
                verbose: common.verbose,
                work: common.out.join(format!("jitter-work-{}", std::process::id())),
            };
            let report = removing_work(&opts.work, || jitter::run(&opts))?;
            publish(&common, "jitter", &report, report.seconds, |_| Ok(vec![]), jitter::print_tables)?;
        }
    }
    Ok(())
}
