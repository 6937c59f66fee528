//! The `stm` transport of the `images` scenario: two SDK agents, written
//! as any nerve agent is and run in the benchmark's robot with its router
//! (hidden subcommands `__agent-img-writer`, `__agent-img-reader`).
//!
//! * writer (event-driven, started suspended): one [`RingOutput`] per reader
//!   count `n` (port `f<n>`, ring `<res key><n>`, 8 slots of one frame).
//!   Each `nerve resume` runs the batch named in `<dir>/request.txt`: it
//!   stores every frame with `RingOutput::write_with` (filled in place in
//!   the ring slot, stamped by the ring, announced by a `RingNotice` on the
//!   port) and writes `<dir>/writer-<batch>.txt`;
//! * reader (event-driven): one [`RingInput`] `in`, wired by the benchmark
//!   with `nerve connect <writer>/f<n> <reader>/in` for every `n` above its
//!   index. Woken by the notice, it maps the ring once and reads the frame
//!   in place with `read_notice_with`, the seqlock verified.

use super::frame::{self, Acks, BatchReq, FrameHead, FramePub, Recorder, Res};
use crate::procs::parse_sub;
use agent_sdk::clock::now_ns;
use agent_sdk::memory::{DEFAULT_SLOTS, FrameDesc, MemorySetup as _, PixelFormat, RingInput, RingOutput, RingSpec};
use agent_sdk::{Agent, AgentError, CommonArgs, Context, Setup, Task};
use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments after `--` of the two agents.
#[derive(Debug, Parser)]
#[command(no_binary_name = true)]
struct ImgArgs {
    /// frame size, e.g. 640x480
    #[arg(long)]
    res: String,
    /// directory of the request, writer and reader files
    #[arg(long)]
    dir: PathBuf,
    /// the acknowledgement file
    #[arg(long)]
    acks: PathBuf,
    /// writer: reader counts (one port and ring each)
    #[arg(long, value_delimiter = ',', default_values_t = [1usize, 4, 8])]
    counts: Vec<usize>,
    /// reader: its index (0..)
    #[arg(long, default_value_t = 0)]
    index: usize,
}

fn img_args(setup: &Setup) -> Result<(ImgArgs, Res), AgentError> {
    let a = ImgArgs::try_parse_from(setup.raw_args()).map_err(|e| AgentError::Config(e.to_string()))?;
    let res = Res::parse(&a.res).map_err(|e| AgentError::Config(format!("{e:#}")))?;
    Ok((a, res))
}

fn other(e: anyhow::Error) -> AgentError {
    AgentError::Other(format!("{e:#}"))
}

/// The name of the ring of reader count `n`.
pub fn ring_name(res: Res, n: usize) -> String {
    format!("{}{n}", res.key)
}

/// The ring writer.
struct ImgWriter {
    outs: Vec<(usize, RingOutput)>,
    res: Res,
    dir: PathBuf,
    acks: Acks,
    last_batch: u64,
    seq: u64,
}

/// Publishing into the rings: `RingOutput::write_with`.
struct RingPub<'a> {
    outs: &'a mut [(usize, RingOutput)],
    res: Res,
}

impl FramePub for RingPub<'_> {
    fn publish(&mut self, n: usize, h: &FrameHead) -> anyhow::Result<(u64, u64)> {
        let out = &mut self
            .outs
            .iter_mut()
            .find(|(k, _)| *k == n)
            .ok_or_else(|| anyhow::anyhow!("no ring for {n} readers"))?
            .1;
        let desc = FrameDesc::image(self.res.width, self.res.height, PixelFormat::Rgb8);
        let (mut t1, mut t2) = (0, 0);
        let t0 = now_ns();
        let notice = out.write_with(desc, self.res.bytes(), |buf| {
            t1 = now_ns();
            frame::fill(buf, h);
            t2 = now_ns();
        })?;
        let t3 = now_ns();
        Ok((notice.stamp_ns, t1.saturating_sub(t0) + t3.saturating_sub(t2)))
    }
}

impl Agent for ImgWriter {
    const KIND: &'static str = "bench-img-writer";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let (a, res) = img_args(setup)?;
        let mut outs = Vec::new();
        for &n in &a.counts {
            let spec = RingSpec::new(DEFAULT_SLOTS, res.bytes()).named(&ring_name(res, n));
            outs.push((n, setup.ring_output(&format!("f{n}"), spec)?));
        }
        let acks = Acks::open(&a.acks).map_err(other)?;
        Ok(ImgWriter { outs, res, dir: a.dir, acks, last_batch: 0, seq: 0 })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        for (_, o) in &mut self.outs {
            o.open().map_err(AgentError::from)?;
        }
        Ok(())
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        // woken by `nerve resume`: run the batch asked for, once
        let path = frame::request_file(&self.dir);
        let Ok(text) = std::fs::read_to_string(&path) else { return Ok(()) };
        let req = BatchReq::parse(&text).map_err(other)?;
        if req.batch <= self.last_batch {
            return Ok(());
        }
        self.last_batch = req.batch;
        let mut p = RingPub { outs: &mut self.outs, res: self.res };
        let out = frame::run_batch(&mut p, &req, &self.acks, &mut self.seq).map_err(other)?;
        let path = frame::writer_file(&self.dir, req.batch);
        frame::write_atomic(&path, &out.to_text())
            .map_err(|e| AgentError::Other(format!("cannot write {}: {e}", path.display())))
    }
}

/// A ring reader.
struct ImgReader {
    input: RingInput,
    rec: Recorder,
}

impl Agent for ImgReader {
    const KIND: &'static str = "bench-img-reader";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let (a, _) = img_args(setup)?;
        let input = setup.ring_input("in")?;
        let rec = Recorder::new(a.dir, a.index, &a.acks).map_err(other)?;
        Ok(ImgReader { input, rec })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        // the SDK stamps the wake-up right after its WaitSet returned
        let mut begin = ctx.now_ns();
        while let Some((_, notice)) = self.input.recv() {
            let r = self.input.read_notice_with(&notice, |_, bytes| frame::check(bytes));
            let done = now_ns();
            match r {
                Ok((h, bad)) => self.rec.frame(&h, bad, begin, done).map_err(other)?,
                Err(_) => self.rec.failed(notice.seq, begin, done),
            }
            begin = done;
        }
        Ok(())
    }
}

/// Entry of `__agent-img-writer` and `__agent-img-reader`.
pub fn run_agent(which: &str, args: Vec<String>) -> ExitCode {
    let common: CommonArgs = match parse_sub(&format!("nerve-bench {which}"), args) {
        Ok(c) => c,
        Err(code) => return code,
    };
    match which {
        "__agent-img-writer" => agent_sdk::run_with_args::<ImgWriter>(common),
        "__agent-img-reader" => agent_sdk::run_with_args::<ImgReader>(common),
        _ => {
            eprintln!("error: unknown agent subcommand {which}");
            ExitCode::from(2)
        }
    }
}
