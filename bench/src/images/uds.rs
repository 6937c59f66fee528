//! The `uds` transport of the `images` scenario: the writer (in the
//! benchmark process) fills a frame in its own buffer, stamps it, and copies
//! it to each of the batch's readers in turn over a blocking Unix stream
//! socket (`write_all`, reader 0 first); each reader
//! (`nerve-bench __img-uds-reader`, one process per reader) blocks in
//! `poll`, reads the whole frame into its own buffer (`read_exact`) and
//! checks it there.

use super::frame::{self, FrameHead, FramePub, Recorder, Res};
use crate::procs::{exit_status, parse_sub, realtime_like_an_agent};
use agent_sdk::clock::now_ns;
use anyhow::{Context as _, Result, bail};
use clap::Parser;
use std::io::{Read as _, Write as _};
use std::os::fd::AsRawFd as _;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The writer: one connected socket per reader, and the frame buffer.
#[derive(Debug)]
pub struct UdsWriter {
    streams: Vec<UnixStream>,
    buf: Vec<u8>,
}

impl UdsWriter {
    /// Connects to the readers listening at `paths` (reader 0 first).
    pub fn connect(paths: &[PathBuf], res: Res) -> Result<Self> {
        let streams = paths
            .iter()
            .map(|p| UnixStream::connect(p).with_context(|| format!("cannot connect to {}", p.display())))
            .collect::<Result<_>>()?;
        Ok(UdsWriter { streams, buf: vec![0u8; res.bytes()] })
    }
}

impl FramePub for UdsWriter {
    fn publish(&mut self, n: usize, h: &FrameHead) -> Result<(u64, u64)> {
        if n > self.streams.len() {
            bail!("{n} readers asked for, {} connected", self.streams.len());
        }
        frame::fill(&mut self.buf, h);
        let t2 = now_ns();
        frame::set_stamp(&mut self.buf, t2);
        for s in &mut self.streams[..n] {
            s.write_all(&self.buf).context("socket write")?;
        }
        Ok((t2, now_ns() - t2))
    }
}

/// Arguments of `nerve-bench __img-uds-reader`.
#[derive(Debug, Parser)]
#[command(name = "nerve-bench __img-uds-reader")]
struct ReaderArgs {
    #[arg(long)]
    path: PathBuf,
    #[arg(long)]
    res: String,
    #[arg(long)]
    index: usize,
    #[arg(long)]
    dir: PathBuf,
    #[arg(long)]
    acks: PathBuf,
}

/// Entry of `nerve-bench __img-uds-reader`: prints `ready` once it listens; reads until EOF.
pub fn reader_main(args: Vec<String>) -> ExitCode {
    match parse_sub::<ReaderArgs>("__img-uds-reader", args) {
        Ok(a) => exit_status("socket image reader", reader(&a)),
        Err(code) => code,
    }
}

fn wait_readable(s: &UnixStream) -> Result<()> {
    let mut fds = libc::pollfd { fd: s.as_raw_fd(), events: libc::POLLIN, revents: 0 };
    loop {
        // SAFETY: one valid pollfd, for the duration of the call.
        let rc = unsafe { libc::poll(&mut fds, 1, -1) };
        if rc >= 0 {
            return Ok(());
        }
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::Interrupted {
            return Err(e).context("poll");
        }
    }
}

fn reader(a: &ReaderArgs) -> Result<()> {
    realtime_like_an_agent(20);
    let res = Res::parse(&a.res)?;
    let _ = std::fs::remove_file(&a.path);
    let listener = UnixListener::bind(&a.path).with_context(|| format!("cannot bind {}", a.path.display()))?;
    let mut rec = Recorder::new(a.dir.clone(), a.index, &a.acks)?;
    println!("ready");
    std::io::stdout().flush().context("stdout")?;
    let (mut s, _) = listener.accept().context("accept")?;
    remove_quietly(&a.path);
    let mut buf = vec![0u8; res.bytes()];
    loop {
        wait_readable(&s)?;
        let begin = now_ns();
        match s.read_exact(&mut buf) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(()),
            Err(e) => return Err(e).context("socket read"),
        }
        let (h, bad) = frame::check(&buf);
        let done = now_ns();
        rec.frame(&h, bad, begin, done)?;
    }
}

fn remove_quietly(p: &Path) {
    let _ = std::fs::remove_file(p);
}
