//! The `messages` scenario's own SDK agents, run as processes of this
//! executable (`nerve-bench __agent-seqping ...`), written as any agent is:
//!
//! * `seqping` / `seqpong`: a round trip of sequence samples
//!   (`setup.output_seq::<u8, Small8>`): the header carries the sequence
//!   number, the `--size - 8` bytes after it are loaned and left as the slot
//!   held them (a camera would have written them once, in place), so a
//!   sample is `--size` bytes in shared memory, as the fixed payload of the
//!   same size is. The pong answers each sample with one of the same length,
//!   writing only its header.
//! * `callping` / `callserve`: a call's round trip (`setup.client` /
//!   `setup.serve`, request and answer both the fixed payload of `--size`),
//!   written and read in place as the ping-pong's samples are: the client
//!   writes only the sequence number of its request in shared memory
//!   (`Client::call_uninit`) and reads the answer's where the server wrote
//!   it (`Client::take_with`), and calls again when the answer comes; the
//!   server answers each request in place (`Server::serve_uninit`), writing
//!   only the request's sequence number into the answer.
//!
//! Both ping sides keep their round trips as the hop scenario's ping does
//! ([`Recorder`]): a batch starts at a `nerve resume`, records after
//! [`SETTLE_NS`], and is written to `<out>/batch-<k>.txt` after `--count`
//! round trips.

use crate::agents::{BenchAgentArgs, agent_args, write_values};
use crate::payloads::{BenchPayload, Small8};
use crate::procs::parse_sub;
use crate::with_payload;
use agent_sdk::clock::now_ns;
use agent_sdk::port::{Client, SeqInput, SeqOutput, Server};
use agent_sdk::{Agent, AgentError, CommonArgs, Context, Setup, Task};
use clap::Parser as _;
use std::path::PathBuf;
use std::process::ExitCode;

/// How long a batch runs before it records (as the hop ping: the `nerve
/// resume` that started it is still being answered meanwhile).
const SETTLE_NS: u64 = 100_000_000;
/// A round trip that has waited this long is lost: the next wake-up starts again.
const STALLED_NS: u64 = 500_000_000;

/// The round trips of one ping agent, batch by batch.
struct Recorder {
    count: usize,
    dir: PathBuf,
    batch: u64,
    /// round trips of requests sent before this are not recorded
    settle_until_ns: u64,
    seq: u64,
    /// (seq, send time) of the round trip under way
    outstanding: Option<(u64, u64)>,
    rtts: Vec<u64>,
}

/// What an answer did to the batch.
#[derive(Debug, PartialEq, Eq)]
enum Answered {
    /// not the answer awaited (a stale one)
    Stale,
    /// the awaited answer: send the next request
    Next,
    /// the awaited answer completed the batch, which is written
    Done,
}

impl Recorder {
    fn new(args: &BenchAgentArgs, kind: &str) -> Result<Self, AgentError> {
        let dir = args.out.clone().ok_or_else(|| AgentError::Config(format!("{kind} needs --out DIR")))?;
        let count = args.count.max(1);
        Ok(Recorder {
            count,
            dir,
            batch: 0,
            settle_until_ns: 0,
            seq: 0,
            outstanding: None,
            rtts: Vec::with_capacity(count),
        })
    }

    /// The sequence number of the next request, its send time taken now.
    fn next(&mut self) -> u64 {
        self.seq += 1;
        self.outstanding = Some((self.seq, now_ns()));
        self.seq
    }

    /// Woken with no answer: whether to send a request (a `nerve resume`
    /// starts a batch, or restarts a stalled one), starting a batch if none is under way.
    fn woken_idle(&mut self) -> bool {
        let stalled = self.outstanding.is_some_and(|(_, t0)| now_ns().saturating_sub(t0) > STALLED_NS);
        if self.outstanding.is_some() && !stalled {
            return false;
        }
        if self.outstanding.is_none() && self.rtts.is_empty() {
            self.settle_until_ns = now_ns().saturating_add(SETTLE_NS);
        }
        self.outstanding = None;
        true
    }

    /// The answer of sequence number `seq` came at `at_ns`.
    fn answer(&mut self, seq: u64, at_ns: u64) -> Result<Answered, AgentError> {
        let Some((want, t0)) = self.outstanding else { return Ok(Answered::Stale) };
        if seq != want {
            return Ok(Answered::Stale);
        }
        self.outstanding = None;
        if t0 < self.settle_until_ns {
            return Ok(Answered::Next);
        }
        self.rtts.push(at_ns.saturating_sub(t0));
        if self.rtts.len() < self.count {
            return Ok(Answered::Next);
        }
        self.batch += 1;
        let path = self.dir.join(format!("batch-{}.txt", self.batch));
        write_values(&path, &self.rtts)
            .map_err(|e| AgentError::Other(format!("cannot write {}: {e}", path.display())))?;
        self.rtts.clear();
        Ok(Answered::Done)
    }
}

/// Elements of a sequence sample of `size` bytes: the 8-byte header first.
fn items_of(size: usize) -> Result<usize, AgentError> {
    size.checked_sub(std::mem::size_of::<Small8>())
        .ok_or_else(|| AgentError::Config(format!("--size {size}: a sequence sample is at least its 8-byte header")))
}

/// The ping side of a sequence round trip.
struct SeqPing {
    input: SeqInput<u8, Small8>,
    out: SeqOutput<u8, Small8>,
    items: usize,
    rec: Recorder,
}

impl SeqPing {
    fn send_next(&mut self) -> Result<(), AgentError> {
        let seq = self.rec.next();
        // the elements are left as the slot held them: zero copy, as the fixed row's send_uninit
        self.out.send_with(self.items, |h, _| h.seq = seq)?;
        Ok(())
    }
}

impl Agent for SeqPing {
    const KIND: &'static str = "bench-seq-ping";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let a = agent_args(setup)?;
        let items = items_of(a.size)?;
        Ok(SeqPing {
            input: setup.input_seq("in")?,
            out: setup.output_seq("out", items.max(1))?,
            items,
            rec: Recorder::new(&a, "seqping")?,
        })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let mut seen = Vec::new();
        let drained = self.input.drain(|_, h, _| seen.push((h.seq, now_ns())));
        let mut next = false;
        for (seq, at) in seen {
            next |= self.rec.answer(seq, at)? == Answered::Next;
        }
        if next || (drained == 0 && self.rec.woken_idle()) {
            return self.send_next();
        }
        Ok(())
    }
}

/// The pong side of a sequence round trip: a sample of the same length
/// back, only its header written.
struct SeqPong {
    input: SeqInput<u8, Small8>,
    out: SeqOutput<u8, Small8>,
}

impl Agent for SeqPong {
    const KIND: &'static str = "bench-seq-pong";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let a = agent_args(setup)?;
        let items = items_of(a.size)?;
        Ok(SeqPong { input: setup.input_seq("in")?, out: setup.output_seq("out", items.max(1))? })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let out = &self.out;
        self.input.try_drain(|_, h, items| out.send_with(items.len(), |back, _| back.seq = h.seq))?;
        Ok(())
    }
}

/// The client side of a call's round trip.
struct CallPing<P: BenchPayload> {
    client: Client<P, P>,
    rec: Recorder,
}

impl<P: BenchPayload> CallPing<P> {
    fn call_next(&mut self) -> Result<(), AgentError> {
        let seq = self.rec.next();
        // SAFETY: bench payloads are a sequence number plus plain bytes; any bytes are valid.
        unsafe { self.client.call_uninit(|req| P::write_seq_raw(req.as_mut_ptr(), seq)) }?;
        Ok(())
    }
}

impl<P: BenchPayload> Agent for CallPing<P> {
    const KIND: &'static str = "bench-call-ping";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let a = agent_args(setup)?;
        Ok(CallPing { client: setup.client("call")?, rec: Recorder::new(&a, "callping")? })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let (mut taken, mut next) = (0usize, false);
        // the answer's sequence number, read in place, and when it was found
        while let Some(answer) = self.client.take_with(|_, answer| answer.map(|resp| (resp.seq(), now_ns()))) {
            taken += 1;
            match answer {
                Ok((seq, at_ns)) => next |= self.rec.answer(seq, at_ns)? == Answered::Next,
                // a lost call: the batch goes on at the next `nerve resume`
                Err(e) => eprintln!("warning: a call of the benchmark failed: {e}"),
            }
        }
        if next || (taken == 0 && self.client.in_flight() == 0 && self.rec.woken_idle()) {
            return self.call_next();
        }
        Ok(())
    }
}

/// The server side of a call's round trip: answers each request in place
/// with its sequence number.
struct CallServe<P: BenchPayload> {
    server: Server<P, P>,
}

impl<P: BenchPayload> Agent for CallServe<P> {
    const KIND: &'static str = "bench-call-serve";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        agent_args(setup)?;
        Ok(CallServe { server: setup.serve("serve")? })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        // SAFETY: as in `CallPing::call_next`: any bytes are valid beside the sequence number.
        unsafe { self.server.serve_uninit(|req, answer| P::write_seq_raw(answer.as_mut_ptr(), req.seq())) }?;
        Ok(())
    }
}

/// Entry of the scenario's hidden agent subcommands: `args` is everything
/// after the subcommand.
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
    let bad = |size: usize| {
        eprintln!("error: no fixed payload of {size} bytes for a call; use 8, 4096, 230400 or 1048576");
        ExitCode::from(2)
    };
    match which {
        "__agent-seqping" => agent_sdk::run_with_args::<SeqPing>(common),
        "__agent-seqpong" => agent_sdk::run_with_args::<SeqPong>(common),
        "__agent-callping" => with_payload!(size, P => agent_sdk::run_with_args::<CallPing<P>>(common), _ => bad(size)),
        "__agent-callserve" => {
            with_payload!(size, P => agent_sdk::run_with_args::<CallServe<P>>(common), _ => bad(size))
        }
        _ => {
            eprintln!("error: unknown agent subcommand {which}");
            ExitCode::from(2)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recorder(count: usize) -> Recorder {
        let args = BenchAgentArgs::try_parse_from(["--count", &count.to_string(), "--out", "/nonexistent"])
            .expect("arguments parse");
        Recorder::new(&args, "test").expect("a recorder")
    }

    #[test]
    fn a_stale_answer_is_not_recorded_and_a_settling_one_is_not_kept() {
        let mut r = recorder(2);
        assert!(r.woken_idle(), "a resume starts a batch");
        let s = r.next();
        assert_eq!(r.answer(s + 7, now_ns()).expect("no file"), Answered::Stale);
        // sent before the batch settled: answered, not recorded
        assert_eq!(r.answer(s, now_ns()).expect("no file"), Answered::Next);
        assert!(r.rtts.is_empty());
        assert!(!r.woken_idle() || r.outstanding.is_none());
    }

    #[test]
    fn a_sequence_sample_holds_its_header() {
        assert_eq!(items_of(8).expect("8 B"), 0);
        assert_eq!(items_of(1 << 20).expect("1 MiB"), (1 << 20) - 8);
        assert!(items_of(4).is_err());
    }
}
