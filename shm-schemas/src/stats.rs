//! Statistics an agent reports about itself and its inputs.

use serde::{Deserialize, Serialize};

/// Figures for one subscription of an input port (one incoming connection).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct InputStats {
    /// the input port
    pub input: String,
    /// source agent
    pub from_agent: String,
    /// source port
    pub from_port: String,
    /// samples received since the subscription was made
    pub received: u64,
    /// samples per second over the last seconds
    pub rate_hz: f64,
    /// nanoseconds since the last sample arrived
    pub last_age_ns: Option<u64>,
    /// samples lost (gaps in the sender's sequence numbers)
    pub dropped: u64,
}

/// The wake-up latency bound an agent holds on the CPUs (PM QoS,
/// `/dev/cpu_dma_latency`; see the SDK's `cpu_latency` module).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CpuLatency {
    /// Nothing held: `--cpu-latency off`, or not a real-time agent.
    #[default]
    Off,
    /// A bound of `us` microseconds held for as long as the agent runs.
    Held {
        /// the bound, µs
        us: u32,
    },
    /// Asked for, but the device could not be written (permissions).
    Refused,
}

impl std::fmt::Display for CpuLatency {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CpuLatency::Off => f.write_str("off"),
            CpuLatency::Held { us } => write!(f, "{us}us"),
            CpuLatency::Refused => f.write_str("refused"),
        }
    }
}

/// An agent's view of itself.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct AgentStats {
    /// task cycles run since start
    pub cycles: u64,
    /// cycles per second over the last seconds
    pub rate_hz: f64,
    /// lateness of periodic wake-ups after their deadline, median, ns
    pub jitter_p50_ns: u64,
    /// lateness, 99th percentile, ns
    pub jitter_p99_ns: u64,
    /// lateness, maximum since start, ns
    pub jitter_max_ns: u64,
    /// cycles whose work ran past the next deadline
    pub overruns: u64,
    /// CPU used by the whole process over the last second, percent of one core
    pub cpu_percent: f64,
    /// resident memory, bytes
    pub rss_bytes: u64,
    /// whether the task thread got SCHED_FIFO
    pub realtime: bool,
    /// the wake-up latency bound (PM QoS) the agent holds
    pub cpu_latency: CpuLatency,
    /// per input subscription
    pub inputs: Vec<InputStats>,
    /// read-only figures the agent reports about its own work, (name, value)
    /// sorted by name: the bridge's peers and per-topic counters, say
    pub figures: Vec<(String, String)>,
}
