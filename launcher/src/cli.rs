//! The command-line grammar of `nerve` (clap derive).

use clap::{Args, Parser, Subcommand};

/// nerve: a robot's control system as a society of agents.
#[derive(Debug, Parser)]
#[command(name = "nerve", version, about, long_about = None, propagate_version = true)]
pub struct Cli {
    /// Robot (isolated world) to work on.
    #[arg(long, global = true, env = "NERVE_ROBOT", default_value = agent_sdk::world::DEFAULT_ROBOT)]
    pub robot: String,
    /// Whether `robot` was given (`--robot` or `NERVE_ROBOT`), not defaulted.
    #[arg(skip)]
    pub robot_explicit: bool,
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// Every `nerve` command.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the router of the robot (registry and connection list).
    Router(RouterArgs),
    /// Start an agent as a daemon while the others run (hot add).
    Start(StartArgs),
    /// List the live agents with their statistics.
    Ps(PsArgs),
    /// Show the connection list with live figures per connection.
    Graph(GraphArgs),
    /// Connect an output port to an input port.
    Connect(WireArgs),
    /// Remove a connection.
    Disconnect(WireArgs),
    /// Change the period of a periodic agent.
    Rate {
        /// agent name
        name: String,
        /// new period: 10ms, 1s, 100hz...
        period: String,
    },
    /// Suspend an agent's task (its message checker keeps answering).
    Suspend {
        /// agent name
        name: String,
    },
    /// Resume a suspended agent's task.
    Resume {
        /// agent name
        name: String,
    },
    /// Read or change an agent's parameters.
    #[command(subcommand)]
    Param(ParamCmd),
    /// Stop an agent cleanly.
    Stop {
        /// agent name
        name: String,
    },
    /// Kill an agent with SIGKILL.
    Kill {
        /// agent name
        name: String,
    },
    /// Print the samples of an output port.
    Echo(EchoArgs),
    /// Measure the rate of an output port.
    Hz(HzArgs),
    /// Start a robot from a launch file (router, agents, connections).
    Launch(LaunchArgs),
    /// Stop every agent and the router of the robot, and remove what they left.
    Down(DownArgs),
    /// Show an agent's log.
    Logs(LogsArgs),
    /// Run an agent kind in place of this process (for systemd units).
    Exec(ExecArgs),
    /// Send one command to an actuator agent from the terminal (drive the robot by hand).
    Cmd(crate::cmd::drive::CmdArgs),
    /// Short-term memory: list rings, dump an image slot as PNG.
    #[command(subcommand)]
    Mem(crate::cmd::mem::MemCmd),
    /// Reproduce an experiment of the thesis (`nerve demo explore`).
    #[command(subcommand)]
    Demo(crate::cmd::demo::DemoCmd),
    /// Calibrate a sensor (`nerve calibrate checkpoint`: Appendix A, in the simulator or from samples).
    #[command(subcommand)]
    Calibrate(crate::cmd::calibrate::CalibrateCmd),
    /// Run a benchmark scenario (runs `nerve-bench`; see BENCHMARKS.md).
    Bench(crate::cmd::bench::BenchArgs),
    /// Robots talking to each other: the bridge agents' peers and what crosses.
    #[command(subcommand)]
    Bridge(crate::cmd::bridge::BridgeCmd),
}

/// `nerve launch`
#[derive(Debug, Args)]
pub struct LaunchArgs {
    /// The launch file (TOML).
    pub file: std::path::PathBuf,
    /// Stay attached: stream the agents' logs, stop everything on Ctrl-C.
    #[arg(long)]
    pub foreground: bool,
}

/// `nerve logs`
#[derive(Debug, Args)]
pub struct LogsArgs {
    /// Agent name (or `router`).
    pub name: String,
    /// Keep printing new lines.
    #[arg(long, short)]
    pub follow: bool,
    /// Only the last N lines.
    #[arg(long, short = 'n')]
    pub lines: Option<usize>,
}

/// `nerve exec`
#[derive(Debug, Args)]
pub struct ExecArgs {
    /// Agent kind.
    pub kind: String,
    /// Arguments of the agent (common options, then `--` and its own).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<String>,
}

/// `nerve router`
#[derive(Debug, Args)]
pub struct RouterArgs {
    /// Detach and run as a daemon (log in the robot's state directory).
    #[arg(long)]
    pub daemon: bool,
    /// Log filter; RUST_LOG is used when absent.
    #[arg(long)]
    pub log_level: Option<String>,
}

/// `nerve start`
#[derive(Debug, Args)]
pub struct StartArgs {
    /// Agent kind (ticker, relay, ...) or the path of an agent executable.
    pub kind: String,
    /// Agent name, unique within the robot.
    #[arg(long)]
    pub name: String,
    /// Period of a periodic agent: 10ms, 1s, 100hz...
    #[arg(long)]
    pub period: Option<String>,
    /// Log filter of the agent.
    #[arg(long)]
    pub log_level: Option<String>,
    /// Start with the task suspended.
    #[arg(long)]
    pub suspended: bool,
    /// Arguments for the agent itself.
    #[arg(last = true)]
    pub args: Vec<String>,
}

/// `nerve ps`
#[derive(Debug, Args)]
pub struct PsArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// `nerve graph`
#[derive(Debug, Args)]
pub struct GraphArgs {
    /// Print JSON.
    #[arg(long, conflicts_with = "dot")]
    pub json: bool,
    /// Print Graphviz DOT (pipe into `dot -Tsvg`).
    #[arg(long)]
    pub dot: bool,
}

/// `nerve connect` / `nerve disconnect`
#[derive(Debug, Args)]
pub struct WireArgs {
    /// Output port, AGENT/PORT.
    pub from: String,
    /// Input port, AGENT/PORT.
    pub to: String,
}

/// `nerve param`
#[derive(Debug, Subcommand)]
pub enum ParamCmd {
    /// Print a parameter's value.
    Get {
        /// agent name
        name: String,
        /// parameter
        key: String,
    },
    /// Change a parameter.
    Set {
        /// agent name
        name: String,
        /// parameter
        key: String,
        /// new value
        value: String,
    },
}

/// `nerve echo`
#[derive(Debug, Args)]
pub struct EchoArgs {
    /// Output port, AGENT/PORT.
    pub port: String,
    /// Exit after this many samples.
    #[arg(long)]
    pub count: Option<u64>,
    /// One JSON object per line.
    #[arg(long)]
    pub json: bool,
    /// Give up after this many seconds without a sample (default: wait for ever).
    #[arg(long, value_parser = agent_sdk::clock::parse_seconds)]
    pub timeout: Option<f64>,
}

/// `nerve hz`
#[derive(Debug, Args)]
pub struct HzArgs {
    /// Output port, AGENT/PORT.
    pub port: String,
    /// Seconds per report.
    #[arg(long, default_value_t = 1.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub window: f64,
    /// Exit after this many reports.
    #[arg(long)]
    pub count: Option<u64>,
    /// One JSON object per report.
    #[arg(long)]
    pub json: bool,
}

/// `nerve down`
#[derive(Debug, Args)]
pub struct DownArgs {
    /// Seconds to wait for a clean stop before SIGTERM, and again before SIGKILL.
    #[arg(long, default_value_t = 3.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub grace: f64,
    /// Keep the robot's connection list for its next start (by default a
    /// robot brought down starts unwired next time: its launch file or
    /// `nerve connect` wires it again).
    #[arg(long)]
    pub keep_connections: bool,
}
