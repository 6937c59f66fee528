//! The benchmark's own agents, written with the real SDK exactly as any
//! nerve agent is, and run as processes of this executable through hidden
//! subcommands (`nerve-bench __agent-ping ...`) that call
//! [`agent_sdk::run_with_args`].
//!
//! * `ping` (event-driven): on `nerve resume` it starts a batch: it sends a
//!   sample on `out` and, each time the echo comes back on `in`, sends the
//!   next; after 100 ms of settling it records each round-trip time, and
//!   after `--count` of them it writes them to `<out-dir>/batch-<k>.txt` and
//!   waits for the next resume.
//! * `pong` (event-driven): echoes every sample of `in` on `out`
//!   (`Output::send_uninit`: only the sequence number is written, in place).
//! * `jitter` (periodic): records, for `--cycles` cycles, how late each
//!   wake-up was after its absolute deadline, writes the values to `--out`
//!   and idles until stopped.

use crate::payloads::BenchPayload;
use crate::procs::parse_sub;
use crate::with_payload;
use agent_sdk::clock::now_ns;
use agent_sdk::{Agent, AgentError, CommonArgs, Context, Input, Output, Setup, Task};
use clap::Parser;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

/// Arguments after `--` of the benchmark agents.
#[derive(Debug, Parser)]
#[command(no_binary_name = true)]
pub(crate) struct BenchAgentArgs {
    /// payload size in bytes (8, 4096, 230400 or 6220800)
    #[arg(long, default_value_t = 8)]
    pub(crate) size: usize,
    /// ping: round trips per batch
    #[arg(long, default_value_t = 1000)]
    pub(crate) count: usize,
    /// ping: directory for batch files; jitter: the output file
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// jitter: cycles to record
    #[arg(long, default_value_t = 1000)]
    cycles: usize,
}

pub(crate) fn agent_args(setup: &Setup) -> Result<BenchAgentArgs, AgentError> {
    BenchAgentArgs::try_parse_from(setup.raw_args()).map_err(|e| AgentError::Config(e.to_string()))
}

/// Writes one value per line to `path` atomically (temp file, then rename).
pub fn write_values(path: &Path, values: &[u64]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        for v in values {
            writeln!(f, "{v}")?;
        }
        f.flush()?;
    }
    std::fs::rename(&tmp, path)
}

/// Reads the values [`write_values`] wrote.
pub fn read_values(path: &Path) -> anyhow::Result<Vec<u64>> {
    use anyhow::Context as _;
    let s = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    s.lines()
        .filter(|l| !l.is_empty())
        .map(|l| l.trim().parse::<u64>().with_context(|| format!("bad value {l:?} in {}", path.display())))
        .collect()
}

/// How long a batch ping-pongs before it records: the `nerve resume` that
/// started it is still being answered and exiting meanwhile (the router
/// replies, the command drops its iceoryx2 node and exits: a few ms of CPU
/// on a 2-core machine). A batch of 250 frames at 20 µs lasts 5 ms and used
/// to run entirely beside that work: 45 µs measured where the same pair,
/// settled, takes 20 (BENCHMARKS.md §1, "A settled batch").
const SETTLE_NS: u64 = 100_000_000;

/// The round-trip bookkeeping of a ping agent ([`Ping`], also in the SDK's
/// polling mode, `--poll`).
struct PingSide<P: BenchPayload> {
    input: Input<P>,
    out: Output<P>,
    count: usize,
    dir: PathBuf,
    batch: u64,
    /// echoes of samples sent before this are not recorded ([`SETTLE_NS`])
    settle_until_ns: u64,
    seq: u64,
    /// (seq, send time) of the sample in flight
    outstanding: Option<(u64, u64)>,
    rtts: Vec<u64>,
}

/// What one look at a ping's input found.
struct Collected {
    /// samples drained
    drained: usize,
    /// the echo of the sample in flight came back
    echo: bool,
    /// ... and it completed the batch, which is written
    batch_done: bool,
}

impl<P: BenchPayload> PingSide<P> {
    fn new(setup: &mut Setup, kind: &str) -> Result<Self, AgentError> {
        let a = agent_args(setup)?;
        let dir = a.out.ok_or_else(|| AgentError::Config(format!("{kind} needs --out DIR")))?;
        Ok(PingSide {
            input: setup.input("in")?,
            out: setup.output("out")?,
            count: a.count.max(1),
            dir,
            batch: 0,
            settle_until_ns: 0,
            seq: 0,
            outstanding: None,
            rtts: Vec::with_capacity(a.count.max(1)),
        })
    }

    fn send_next(&mut self) -> Result<(), AgentError> {
        self.seq += 1;
        let seq = self.seq;
        let t0 = now_ns();
        self.outstanding = Some((seq, t0));
        // SAFETY: bench payloads are a sequence number plus plain bytes; any bytes are valid.
        unsafe { self.out.send_uninit(|p| P::write_seq_raw(p.as_mut_ptr(), seq)) }?;
        Ok(())
    }

    /// Whether the sample in flight has waited longer than any echo would.
    fn stalled(&self) -> bool {
        self.outstanding.is_some_and(|(_, t0)| now_ns().saturating_sub(t0) > 500_000_000)
    }

    /// Forgets a batch under way and starts a new one, which records after
    /// [`SETTLE_NS`].
    fn restart(&mut self) {
        self.outstanding = None;
        self.rtts.clear();
        self.settle_until_ns = now_ns().saturating_add(SETTLE_NS);
    }

    /// Drains the input; records the round trip when the echo of the sample
    /// in flight is among it, and writes `batch-<k>.txt` when the batch is full.
    fn collect(&mut self) -> Result<Collected, AgentError> {
        let want = self.outstanding.map(|(s, _)| s);
        let mut seen_at = None;
        let drained = self.input.drain(|_, p| {
            if Some(p.seq()) == want {
                seen_at = Some(now_ns());
            }
        });
        let (Some(t), Some((_, t0))) = (seen_at, self.outstanding) else {
            return Ok(Collected { drained, echo: false, batch_done: false });
        };
        self.outstanding = None;
        if t0 < self.settle_until_ns {
            return Ok(Collected { drained, echo: true, batch_done: false });
        }
        self.rtts.push(t.saturating_sub(t0));
        let batch_done = self.rtts.len() >= self.count;
        if batch_done {
            self.batch += 1;
            let path = self.dir.join(format!("batch-{}.txt", self.batch));
            write_values(&path, &self.rtts)
                .map_err(|e| AgentError::Other(format!("cannot write {}: {e}", path.display())))?;
            self.rtts.clear();
        }
        Ok(Collected { drained, echo: true, batch_done })
    }
}

/// Echoes every sample of `input` on `out`, writing only the sequence number in place.
fn echo_all<P: BenchPayload>(input: &Input<P>, out: &Output<P>) -> Result<(), AgentError> {
    input.try_drain(|_, p| {
        let seq = p.seq();
        // SAFETY: as in `PingSide::send_next`: any bytes are valid beside the sequence number.
        unsafe { out.send_uninit(|q| P::write_seq_raw(q.as_mut_ptr(), seq)) }
    })?;
    Ok(())
}

/// The ping side of the SDK round trip.
struct Ping<P: BenchPayload>(PingSide<P>);

impl<P: BenchPayload> Agent for Ping<P> {
    const KIND: &'static str = "bench-ping";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        Ok(Ping(PingSide::new(setup, "ping")?))
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let side = &mut self.0;
        let c = side.collect()?;
        if c.echo {
            return if c.batch_done { Ok(()) } else { side.send_next() };
        }
        // woken without input: a `nerve resume` starts a batch, or restarts a stalled one
        if c.drained == 0 && (side.outstanding.is_none() || side.stalled()) {
            if side.outstanding.is_none() && side.rtts.is_empty() {
                side.restart();
            }
            return side.send_next();
        }
        Ok(()) // a stale echo, or the echo still on its way
    }
}

/// The pong side: echoes every sample.
struct Pong<P: BenchPayload> {
    input: Input<P>,
    out: Output<P>,
}

impl<P: BenchPayload> Agent for Pong<P> {
    const KIND: &'static str = "bench-pong";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        agent_args(setup)?;
        Ok(Pong { input: setup.input("in")?, out: setup.output("out")? })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        echo_all(&self.input, &self.out)
    }
}

/// A periodic agent that measures its own wake-up lateness: how long after
/// the deadline the SDK slept to (`Context::deadline_ns`) the step began.
/// (It used to reckon its deadlines from the end of `start`; once the
/// start-up did more work after `start`, ahead of the task's first
/// deadline, every value carried that offset: 44 µs measured where the
/// SDK's own figures said 17-23.)
struct Jitter {
    cycles: usize,
    out: PathBuf,
    lateness: Vec<u64>,
    written: bool,
}

impl Agent for Jitter {
    const KIND: &'static str = "bench-jitter";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(1))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let a = agent_args(setup)?;
        let out = a.out.ok_or_else(|| AgentError::Config("jitter needs --out FILE".into()))?;
        Ok(Jitter { cycles: a.cycles.max(1), out, lateness: Vec::with_capacity(a.cycles.max(1)), written: false })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        if self.written {
            return Ok(());
        }
        let deadline = ctx.deadline_ns().ok_or_else(|| AgentError::Other("a periodic step has a deadline".into()))?;
        self.lateness.push(ctx.now_ns().saturating_sub(deadline));
        if self.lateness.len() >= self.cycles {
            self.written = true;
            write_values(&self.out, &self.lateness)
                .map_err(|e| AgentError::Other(format!("cannot write {}: {e}", self.out.display())))?;
        }
        Ok(())
    }
}

/// Entry of the hidden agent subcommands: `args` is everything after the subcommand.
pub fn run_agent(which: &str, args: Vec<String>) -> ExitCode {
    let common: CommonArgs = match parse_sub(&format!("nerve-bench {which}"), args) {
        Ok(c) => c,
        Err(code) => return code,
    };
    let size = match BenchAgentArgs::try_parse_from(&common.args) {
        Ok(a) => a.size,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(2);
        }
    };
    match which {
        "__agent-ping" => with_payload!(size, P => agent_sdk::run_with_args::<Ping<P>>(common), _ => bad_size(size)),
        "__agent-pong" => with_payload!(size, P => agent_sdk::run_with_args::<Pong<P>>(common), _ => bad_size(size)),
        "__agent-jitter" => agent_sdk::run_with_args::<Jitter>(common),
        _ => {
            eprintln!("error: unknown agent subcommand {which}");
            ExitCode::from(2)
        }
    }
}

fn bad_size(size: usize) -> ExitCode {
    eprintln!("error: no payload of {size} bytes; use 8, 4096, 230400 or 6220800");
    ExitCode::from(2)
}
