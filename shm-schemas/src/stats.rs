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

/// The depth and policy of one source of an input (issue 46), and what its
/// queue counted. Listed for every source of every data input.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct QueueStats {
    /// the input port
    pub input: String,
    /// source agent
    pub from_agent: String,
    /// source port
    pub from_port: String,
    /// samples held per source
    pub depth: u32,
    /// `keep = "all"`: never overwrite (else the oldest is overwritten)
    pub keep_all: bool,
    /// the source publishes to this keep-all input losslessly: its sends
    /// wait (bounded) while the input is full
    pub lossless: bool,
    /// samples overwritten in the input's own queue (a deep `latest` input)
    pub overwritten: u64,
    /// times the input's own queue was full with the sender's samples
    /// waiting behind it (a keep-all input not yet read losslessly)
    pub back_pressure: u64,
}

/// What an output counted of its keep-all readers (issue 46): listed for
/// outputs that have had one.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputStats {
    /// the output port
    pub output: String,
    /// keep-all inputs it publishes to losslessly now
    pub keep_all_readers: u64,
    /// samples whose send waited for a full keep-all reader
    pub back_pressure: u64,
    /// samples given up for a keep-all reader after the bounded wait
    pub lost: u64,
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
    /// per input subscription: its depth, policy and queue's counts
    #[serde(default)]
    pub queues: Vec<QueueStats>,
    /// outputs with keep-all readers: their back-pressure
    #[serde(default)]
    pub outputs: Vec<OutputStats>,
    /// read-only figures the agent reports about its own work, (name, value)
    /// sorted by name: the bridge's peers and per-topic counters, say
    pub figures: Vec<(String, String)>,
}
