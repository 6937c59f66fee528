//! The Unix-domain-socket round trip: a blocking `SOCK_STREAM` socket, the
//! whole payload copied through the kernel each way. The pong side runs as a
//! child process (`nerve-bench __uds-pong`), the ping side in the benchmark
//! process; both at the same SCHED_FIFO priority as an agent's task.

use crate::procs::{ChildGuard, exit_status, parse_sub, realtime_like_an_agent, self_command};
use agent_sdk::clock::now_ns;
use anyhow::{Context as _, Result, bail};
use clap::Parser;
use std::io::{Read as _, Write as _};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::{ExitCode, Stdio};

/// The ping side: a connected socket and a buffer of the payload size.
#[derive(Debug)]
pub struct UdsPing {
    stream: UnixStream,
    buf: Vec<u8>,
    seq: u64,
}

impl UdsPing {
    /// Connects to the pong listening at `path`.
    pub fn connect(path: &Path, size: usize) -> Result<Self> {
        let stream = UnixStream::connect(path).with_context(|| format!("cannot connect to {}", path.display()))?;
        // a pong that stopped answering is an error, not a benchmark that never ends
        stream.set_read_timeout(Some(std::time::Duration::from_secs(10))).context("socket read timeout")?;
        Ok(UdsPing { stream, buf: vec![0u8; size.max(8)], seq: 0 })
    }

    /// Starts a pong (`__uds-pong`) listening in `dir` for `size`-byte
    /// messages, and connects to it.
    pub fn with_pong(dir: &Path, size: usize, verbose: bool) -> Result<(ChildGuard, Self)> {
        let path = dir.join(format!("uds-{size}.sock"));
        let mut cmd = self_command("__uds-pong")?;
        cmd.arg("--path").arg(&path).args(["--size", &size.to_string()]).stdout(Stdio::piped());
        if !verbose {
            cmd.stderr(Stdio::null());
        }
        let mut c = ChildGuard::spawn(&format!("socket pong {size}"), cmd)?;
        c.await_ready("socket pong")?;
        Ok((c, UdsPing::connect(&path, size)?))
    }

    /// One batch of `count` round trips; returns the round-trip times in ns.
    pub fn ping_batch(&mut self, count: usize) -> Result<Vec<u64>> {
        let mut rtts = Vec::with_capacity(count);
        for _ in 0..count {
            self.seq += 1;
            let t0 = now_ns();
            self.buf[..8].copy_from_slice(&self.seq.to_ne_bytes());
            self.stream.write_all(&self.buf).context("socket write")?;
            self.stream.read_exact(&mut self.buf).context("socket read")?;
            let t = now_ns();
            let got = u64::from_ne_bytes(self.buf[..8].try_into().context("short buffer")?);
            if got != self.seq {
                bail!("socket echo out of order: sent {}, got {got}", self.seq);
            }
            rtts.push(t.saturating_sub(t0));
        }
        Ok(rtts)
    }
}

/// Arguments of `nerve-bench __uds-pong`.
#[derive(Debug, Parser)]
#[command(name = "nerve-bench __uds-pong")]
struct PongArgs {
    #[arg(long)]
    path: PathBuf,
    #[arg(long)]
    size: usize,
}

/// Entry of `nerve-bench __uds-pong`: prints `ready` once it listens; echoes until EOF.
pub fn pong_main(args: Vec<String>) -> ExitCode {
    match parse_sub::<PongArgs>("__uds-pong", args) {
        Ok(a) => exit_status("socket pong", pong(&a)),
        Err(code) => code,
    }
}

fn pong(a: &PongArgs) -> Result<()> {
    realtime_like_an_agent(20);
    let _ = std::fs::remove_file(&a.path);
    let listener = UnixListener::bind(&a.path).with_context(|| format!("cannot bind {}", a.path.display()))?;
    println!("ready");
    std::io::stdout().flush().context("stdout")?;
    let (mut s, _) = listener.accept().context("accept")?;
    let mut buf = vec![0u8; a.size.max(8)];
    loop {
        match s.read_exact(&mut buf) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(()),
            Err(e) => return Err(e).context("socket read"),
        }
        s.write_all(&buf).context("socket write")?;
    }
}
