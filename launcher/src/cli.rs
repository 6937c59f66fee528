//! The command-line grammar of `nerve` (clap derive): the global options and
//! the list of commands. Each command's own arguments are defined in its
//! module under `cmd/`, next to the code that reads them.

use crate::cmd::{
    bench, bridge, demo, down, drive, echo, inspect, launch, logs, mem, new, plot, record, replay, start, ui, wire,
};
use clap::{Parser, Subcommand};

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
    Router(start::RouterArgs),
    /// Make a new agent project: the agent, its tests, a launch file, a README.
    New(new::NewArgs),
    /// Start an agent as a daemon while the others run (hot add).
    Start(start::StartArgs),
    /// List the live agents with their statistics.
    Ps(inspect::PsArgs),
    /// Show the connection list with live figures per connection.
    Graph(inspect::GraphArgs),
    /// Connect an output port to an input port.
    Connect(wire::ConnectArgs),
    /// Remove a connection.
    Disconnect(wire::WireArgs),
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
    Param(wire::ParamCmd),
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
    Echo(echo::EchoArgs),
    /// Measure the rate of an output port.
    Hz(echo::HzArgs),
    /// Publish a sample of any type into an input port, from JSON (as `ros2 topic pub`).
    #[command(name = "pub")]
    Pub(crate::cmd::publish::PubArgs),
    /// Call a service of an agent with a JSON request and print the answer (as `ros2 service call`).
    Call(crate::cmd::call::CallArgs),
    /// List the payload types of this build and of the robot's agents, or show one's fields.
    Types(crate::cmd::types::TypesArgs),
    /// Print this robot's iceoryx2 configuration, for iceoryx2's own tools (`iox2`).
    #[command(name = "iox2-config")]
    Iox2Config,
    /// Record output ports to an MCAP file.
    Record(record::RecordArgs),
    /// Publish a recording's ports into the robot again, under the recorded agents' names.
    Replay(replay::ReplayArgs),
    /// Plot numeric fields of output ports over time (PNG or SVG), from a recording or live.
    Plot(plot::PlotArgs),
    /// Copy a recording with every sample as JSON, for viewers such as Foxglove and Lichtblick.
    Export(crate::cmd::export::ExportArgs),
    /// Write the black box's last seconds to an MCAP file (a `blackbox` agent keeps them).
    Snapshot(crate::cmd::snapshot::SnapshotArgs),
    /// Start a robot from a launch file (router, agents, connections).
    Launch(launch::LaunchArgs),
    /// Stop every agent and the router of the robot, and remove what they left.
    Down(down::DownArgs),
    /// Show an agent's log.
    Logs(logs::LogsArgs),
    /// Run an agent kind in place of this process (for systemd units).
    Exec(start::ExecArgs),
    /// Send one command to an actuator agent from the terminal (drive the robot by hand).
    Cmd(drive::CmdArgs),
    /// Short-term memory: list rings, dump an image slot as PNG.
    #[command(subcommand)]
    Mem(mem::MemCmd),
    /// Reproduce an experiment of the thesis (`nerve demo explore`; runs `nerve-demo`).
    Demo(demo::DemoArgs),
    /// Calibrate a sensor (`nerve calibrate checkpoint`: Appendix A, in the simulator or from samples; runs `nerve-demo`).
    Calibrate(demo::DemoArgs),
    /// Run a benchmark scenario (runs `nerve-bench`; see BENCHMARKS.md).
    Bench(bench::BenchArgs),
    /// Serve the robot's live graph to a browser: watch and rewire it.
    Ui(ui::UiArgs),
    /// Serve the robot live to Foxglove and Lichtblick (the Foxglove WebSocket protocol).
    Foxglove(crate::cmd::foxglove::FoxgloveArgs),
    /// Robots talking to each other: the bridge agents' peers and what crosses.
    #[command(subcommand)]
    Bridge(bridge::BridgeCmd),
}
