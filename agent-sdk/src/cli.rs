//! The command line every agent shares.

use clap::Parser;

/// Common options of every nerve agent. Agent-specific arguments follow `--`.
#[derive(Debug, Clone, Parser)]
#[command(about = "A nerve agent", long_about = None)]
pub struct CommonArgs {
    /// Robot (isolated world) to join.
    #[arg(long, env = "NERVE_ROBOT", default_value = crate::world::DEFAULT_ROBOT)]
    pub robot: String,
    /// Agent name, unique within the robot (default: the agent's kind).
    #[arg(long)]
    pub name: Option<String>,
    /// Period of a periodic task: 10ms, 1s, 100hz...
    #[arg(long)]
    pub period: Option<String>,
    /// Detach and run as a daemon, logging to the robot's state directory.
    #[arg(long)]
    pub daemon: bool,
    /// Log filter (error, warn, info, debug, trace or a tracing filter); RUST_LOG is used when absent.
    #[arg(long, value_parser = crate::daemon::parse_log_level)]
    pub log_level: Option<String>,
    /// Do not ask for SCHED_FIFO and locked memory.
    #[arg(long)]
    pub no_realtime: bool,
    /// Wake-up latency bound a real-time agent holds on the CPUs while it
    /// runs (PM QoS, /dev/cpu_dma_latency), in µs, or `off`.
    #[arg(long, env = "NERVE_CPU_LATENCY", default_value = "0", value_name = "US|off")]
    pub cpu_latency: crate::cpu_latency::CpuLatencySetting,
    /// Keep the agent on these CPUs: 1, 0,1, 0-3. Two agents that pass
    /// samples back and forth wake each other fastest on one CPU.
    #[arg(long, value_name = "LIST")]
    pub cpus: Option<crate::rt::CpuList>,
    /// Poll instead of sleeping: the task looks at its inputs (or its clock)
    /// in a loop, for the fastest hop, and takes its CPU whole; needs --cpus.
    #[arg(long)]
    pub poll: bool,
    /// SCHED_FIFO priority of the task (the message checker runs one above).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(i32).range(1..=98))]
    pub priority: i32,
    /// Share of one CPU (percent) above which a real-time task that keeps it
    /// for 2 s is demoted to SCHED_OTHER until it calms down; 0 never demotes.
    #[arg(long, default_value_t = 90, value_parser = clap::value_parser!(u32).range(0..=100))]
    pub rt_cpu_limit: u32,
    /// Start with the task suspended.
    #[arg(long)]
    pub suspended: bool,
    /// Set a parameter before the task starts (repeatable): --param gain=1.5
    #[arg(long = "param", value_name = "KEY=VALUE")]
    pub params: Vec<String>,
    /// An input's depth and policy (repeatable), as a launch file's
    /// `[agent.inputs]` gives it: --input cmd:depth=64,keep=all
    #[arg(long = "input", value_name = "NAME:depth=N,keep=latest|all")]
    pub inputs: Vec<String>,
    /// Print the agent's kind, task, ports and parameters as JSON, and exit.
    #[arg(long)]
    pub describe: bool,
    /// Arguments for the agent itself.
    #[arg(last = true)]
    pub args: Vec<String>,
}
