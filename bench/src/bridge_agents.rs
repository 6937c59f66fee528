//! The processes of the `bridge` scenario that run inside robots, written
//! with the real SDK and run as hidden subcommands of this executable:
//!
//! * `__agent-bsend` (event-driven, no input): each `nerve resume` starts a
//!   batch of `--count` samples on `out`, each stamped with CLOCK_MONOTONIC
//!   in its first 8 bytes at the moment it is written: one every
//!   `--interval-us` (absolute deadlines), or back to back for at most
//!   `--max-ms` when the interval is 0. It then writes `sent-<k>.txt`: how
//!   many were sent, when the batch started and ended.
//! * `__agent-bsink` (event-driven): records for every sample of `in` the
//!   sender's stamp, the stamp of the last hop's header (when the port that
//!   fed it, the bridge's import, published it) and its arrival, and writes
//!   them to `batch-<k>.txt` once `--count` arrived, or when it is resumed
//!   after its input has been quiet for [`QUIET_NS`] (the benchmark's way to
//!   close a batch that lost samples).
//! * `__bridge`: the bridge agent itself ([`nerve_bridge::run_with_args`]),
//!   built to carry the benchmark's payload types, as a team builds a
//!   bridge for its own types.

use crate::agents::write_values;
use crate::payloads::{BenchPayload, Frame4k, Frame230k, Frame1080p, Small8};
use crate::procs::parse_sub;
use crate::with_payload;
use agent_sdk::clock::{now_ns, sleep_until_ns};
use agent_sdk::{Agent, AgentError, CommonArgs, Context, Input, Output, Setup, Task};
use clap::Parser;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// A sink writes a short batch only after its input was quiet this long.
pub const QUIET_NS: u64 = 100_000_000;

/// Arguments after `--` of the sender and the sink.
#[derive(Debug, Parser)]
#[command(no_binary_name = true)]
struct Args {
    /// payload size in bytes (8, 4096 or 230400)
    #[arg(long, default_value_t = 8)]
    size: usize,
    /// samples per batch
    #[arg(long, default_value_t = 100)]
    count: usize,
    /// sender: microseconds between two samples; 0 sends back to back
    #[arg(long, default_value_t = 5000)]
    interval_us: u64,
    /// sender: longest back-to-back batch, ms
    #[arg(long, default_value_t = 500)]
    max_ms: u64,
    /// directory for the batch files
    #[arg(long)]
    out: PathBuf,
}

fn args(setup: &Setup) -> Result<Args, AgentError> {
    Args::try_parse_from(setup.raw_args()).map_err(|e| AgentError::Config(e.to_string()))
}

/// Writes rows of numbers, one row per line, atomically (temp file, then rename).
pub fn write_rows(path: &Path, rows: &[[u64; 3]]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        for r in rows {
            writeln!(f, "{} {} {}", r[0], r[1], r[2])?;
        }
        f.flush()?;
    }
    std::fs::rename(&tmp, path)
}

/// How long a benchmark waits for a sink's batch file once the batch is
/// sent, before it pokes the sink.
pub const SETTLE: std::time::Duration = std::time::Duration::from_millis(300);

/// Takes the sink agent `sink`'s batch file `path` (its rows, the file
/// removed). Samples were lost when it is not there: the sink closes a batch
/// when resumed after its input went quiet, so it is suspended and resumed,
/// up to 20 times, [`SETTLE`] apart.
pub fn take_sink_batch(robot: &crate::procs::Robot, sink: &str, path: &Path) -> anyhow::Result<Vec<[u64; 3]>> {
    let mut done = crate::procs::wait_file(path, SETTLE, &mut [])?;
    for _ in 0..20 {
        if done {
            break;
        }
        robot.run(&["suspend", sink])?;
        robot.run(&["resume", sink])?;
        done = crate::procs::wait_file(path, SETTLE, &mut [])?;
    }
    if !done {
        anyhow::bail!("the sink {sink} wrote no batch ({})", path.display());
    }
    let rows = read_rows(path)?;
    let _ = std::fs::remove_file(path);
    Ok(rows)
}

/// Reads the rows [`write_rows`] wrote (or any file of whitespace-separated
/// numbers, missing columns read 0).
pub fn read_rows(path: &Path) -> anyhow::Result<Vec<[u64; 3]>> {
    use anyhow::Context as _;
    let s = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut rows = Vec::new();
    for l in s.lines().filter(|l| !l.trim().is_empty()) {
        let mut r = [0u64; 3];
        for (i, w) in l.split_whitespace().take(3).enumerate() {
            r[i] = w.parse().with_context(|| format!("bad value {w:?} in {}", path.display()))?;
        }
        rows.push(r);
    }
    Ok(rows)
}

/// The sender: a batch per resume.
struct Sender<P: BenchPayload> {
    out: Output<P>,
    a: Args,
    batch: u64,
}

impl<P: BenchPayload> Sender<P> {
    fn send_stamped(&self) -> bool {
        // SAFETY: bench payloads are a u64 plus plain bytes; any bytes are valid beside it.
        unsafe { self.out.send_uninit(|p| P::write_seq_raw(p.as_mut_ptr(), now_ns())) }.is_ok()
    }
}

impl<P: BenchPayload> Agent for Sender<P> {
    const KIND: &'static str = "bench-bridge-send";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let a = args(setup)?;
        Ok(Sender { out: setup.output("out")?, a, batch: 0 })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        // an agent without inputs is stepped only when resumed: each resume is a batch
        self.batch += 1;
        let mut sent = 0u64;
        let t_start = now_ns();
        if self.a.interval_us > 0 {
            let interval = self.a.interval_us * 1000;
            for i in 0..self.a.count as u64 {
                sleep_until_ns(t_start + (i + 1) * interval);
                sent += u64::from(self.send_stamped());
            }
        } else {
            let end = t_start + self.a.max_ms * 1_000_000;
            for _ in 0..self.a.count {
                if now_ns() >= end {
                    break;
                }
                sent += u64::from(self.send_stamped());
            }
        }
        let t_end = now_ns();
        let path = self.a.out.join(format!("sent-{}.txt", self.batch));
        write_values(&path, &[sent, t_start, t_end])
            .map_err(|e| AgentError::Other(format!("cannot write {}: {e}", path.display())))
    }
}

/// The sink: records (sender's stamp, last hop's stamp, arrival) per sample.
struct Sink<P: BenchPayload> {
    input: Input<P>,
    a: Args,
    batch: u64,
    rows: Vec<[u64; 3]>,
    last_arrival: u64,
}

impl<P: BenchPayload> Agent for Sink<P> {
    const KIND: &'static str = "bench-bridge-sink";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let a = args(setup)?;
        let rows = Vec::with_capacity(a.count.min(1 << 16));
        Ok(Sink { input: setup.input("in")?, a, batch: 0, rows, last_arrival: 0 })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let rows = &mut self.rows;
        let drained = self.input.drain(|meta, p| rows.push([p.seq(), meta.stamp_ns, now_ns()]));
        let now = now_ns();
        if drained > 0 {
            self.last_arrival = now;
        }
        // a full batch; or woken without input (a resume) once the input is quiet
        let close =
            self.rows.len() >= self.a.count || (drained == 0 && now.saturating_sub(self.last_arrival) >= QUIET_NS);
        if close {
            self.batch += 1;
            let path = self.a.out.join(format!("batch-{}.txt", self.batch));
            write_rows(&path, &self.rows)
                .map_err(|e| AgentError::Other(format!("cannot write {}: {e}", path.display())))?;
            self.rows.clear();
        }
        Ok(())
    }
}

/// Entry of `__agent-bsend` and `__agent-bsink`: `rest` is everything after the subcommand.
pub fn run_agent(which: &str, rest: Vec<String>) -> ExitCode {
    let common: CommonArgs = match parse_sub(&format!("nerve-bench {which}"), rest) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let size = match Args::try_parse_from(&common.args) {
        Ok(a) => a.size,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(2);
        }
    };
    let bad = |size: usize| {
        eprintln!("error: no payload of {size} bytes; use 8, 4096 or 230400");
        ExitCode::from(2)
    };
    match which {
        "__agent-bsend" => with_payload!(size, P => agent_sdk::run_with_args::<Sender<P>>(common), _ => bad(size)),
        "__agent-bsink" => with_payload!(size, P => agent_sdk::run_with_args::<Sink<P>>(common), _ => bad(size)),
        _ => bad(size),
    }
}

/// Entry of `__bridge`: the bridge agent, carrying the benchmark's payloads.
pub fn bridge_main(rest: Vec<String>) -> ExitCode {
    let common: CommonArgs = match parse_sub("nerve-bench __bridge", rest) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let types =
        nerve_bridge::Types::builtin().with::<Small8>().with::<Frame4k>().with::<Frame230k>().with::<Frame1080p>();
    nerve_bridge::run_with_args(types, common)
}
