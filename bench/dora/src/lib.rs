//! The two dora-rs nodes that `nerve bench hop` runs as a peer of nerve:
//! `nerve-dora-ping` and `nerve-dora-pong`, written with dora's Rust node
//! API (`dora-node-api` 1.1.0, the released 1.x on crates.io) as a dora user
//! writes a node. They are built once by `scripts/setup.sh --bench` into a
//! cache outside the repository and started by `dora run` from a dataflow
//! the benchmark writes (`bench/src/dora.rs`).
//!
//! Both send with `DoraNode::send_output_raw`, dora's path for raw bytes:
//! the sample is allocated in dora's (zenoh's) shared memory from 4 KB up
//! and the closure writes into it in place; only the first 8 bytes (a
//! sequence number or a stamp) are written, the rest of the payload is left
//! as allocated, as nerve's zero-copy transports leave it. Inputs are read
//! in place (`&[u8]` of the received UInt8 array).
//!
//! Settings, from the environment (the dataflow's `env:`):
//!
//! | variable | node | meaning |
//! |---|---|---|
//! | `NERVE_DORA_MODE` | both | `pingpong` (the next sample as soon as the echo is back) or `periodic` (one sample every `NERVE_DORA_PERIOD_US`) |
//! | `NERVE_DORA_SIZE` | ping | payload bytes (at least 8) |
//! | `NERVE_DORA_COUNT` | ping | samples written |
//! | `NERVE_DORA_WARMUP` | ping | samples sent first and dropped |
//! | `NERVE_DORA_PERIOD_US` | ping | period of `periodic` (5000) |
//! | `NERVE_DORA_OUT` | ping | the file of samples, ns, one per line |
//! | `NERVE_DORA_FIFO` | both | SCHED_FIFO priority of the whole process (0: none) |
//! | `NERVE_DORA_PID_DIR` | both | a directory where the node writes `<id>.pid` |
//!
//! What ping writes: in `pingpong`, round trips (send to the echo's arrival,
//! ping's CLOCK_MONOTONIC); in `periodic`, one-way latencies: ping stamps
//! each sample with CLOCK_MONOTONIC in its first 8 bytes just before it is
//! sent, pong takes the difference to its own CLOCK_MONOTONIC when the input
//! reaches its event loop (one host, one clock) and answers with a 16-byte
//! reply `[stamp, latency]`; ping waits for that reply (so samples never
//! queue behind each other) and sends the next on the next 5 ms deadline
//! still ahead (absolute deadlines, missed ones skipped).

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// How ping paces its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// The next sample as soon as the echo of the previous one is back.
    PingPong,
    /// One sample per period, on absolute deadlines.
    Periodic,
}

/// An error with what was being done.
pub type Result<T> = std::result::Result<T, String>;

/// CLOCK_MONOTONIC in ns (the clock of nerve's `agent_sdk::clock::now_ns`).
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Sleeps until CLOCK_MONOTONIC reads `t` (ns).
pub fn sleep_until_ns(t: u64) {
    let ts = libc::timespec { tv_sec: (t / 1_000_000_000) as libc::time_t, tv_nsec: (t % 1_000_000_000) as _ };
    loop {
        // SAFETY: `ts` is a valid timespec; no remaining time is asked for with TIMER_ABSTIME.
        let rc =
            unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) };
        if rc != libc::EINTR {
            return;
        }
    }
}

/// The variable `name`, or an error naming it.
pub fn env(name: &str) -> Result<String> {
    std::env::var(name).map_err(|_| format!("{name} is not set (the benchmark's dataflow sets it)"))
}

/// The variable `name` as a number, or `default` when it is not set.
pub fn env_num<T: std::str::FromStr>(name: &str, default: T) -> Result<T> {
    match std::env::var(name) {
        Ok(v) => v.trim().parse().map_err(|_| format!("{name}={v:?} is not a number")),
        Err(_) => Ok(default),
    }
}

/// The mode from `NERVE_DORA_MODE`.
pub fn mode() -> Result<Mode> {
    match env("NERVE_DORA_MODE")?.as_str() {
        "pingpong" => Ok(Mode::PingPong),
        "periodic" => Ok(Mode::Periodic),
        other => Err(format!("NERVE_DORA_MODE={other:?}: use pingpong or periodic")),
    }
}

/// Puts the whole process under SCHED_FIFO at `NERVE_DORA_FIFO`, as the
/// benchmark runs every peer (called first thing in `main`, so that every
/// thread dora and zenoh start later inherits it); says so when refused.
pub fn realtime_from_env(who: &str) -> Result<()> {
    let prio: i32 = env_num("NERVE_DORA_FIFO", 0)?;
    if prio <= 0 {
        return Ok(());
    }
    let param = libc::sched_param { sched_priority: prio };
    // SAFETY: a plain system call on this thread with a valid parameter.
    if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
        eprintln!("{who}: warning: SCHED_FIFO {prio} refused ({})", std::io::Error::last_os_error());
    }
    Ok(())
}

/// Writes this process's pid to `$NERVE_DORA_PID_DIR/<id>.pid`, so that the
/// benchmark can make sure the node is gone after the run.
pub fn write_pid(id: &str) -> Result<()> {
    let Ok(dir) = std::env::var("NERVE_DORA_PID_DIR") else { return Ok(()) };
    let path = PathBuf::from(dir).join(format!("{id}.pid"));
    std::fs::write(&path, std::process::id().to_string()).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Writes one value per line to `path` atomically (temp file, then rename),
/// the format nerve-bench's `read_values` reads.
pub fn write_values(path: &Path, values: &[u64]) -> Result<()> {
    let tmp = path.with_extension("tmp");
    let w = || -> std::io::Result<()> {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        for v in values {
            writeln!(f, "{v}")?;
        }
        f.flush()?;
        drop(f);
        std::fs::rename(&tmp, path)
    };
    w().map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// The first 8 bytes of `b` as a little-endian u64 (0 when shorter).
pub fn first_u64(b: &[u8]) -> u64 {
    b.get(..8).and_then(|s| <[u8; 8]>::try_from(s).ok()).map_or(0, u64::from_le_bytes)
}

/// The second 8 bytes of `b` as a little-endian u64 (0 when shorter).
pub fn second_u64(b: &[u8]) -> u64 {
    b.get(8..16).and_then(|s| <[u8; 8]>::try_from(s).ok()).map_or(0, u64::from_le_bytes)
}
