//! `__agent-ros2-src`: what feeds the `ros2` agent in the `ros2` scenario,
//! an SDK agent as a camera and a planner are.
//!
//! Event-driven with no input, started suspended: its one step (at `nerve
//! resume`) runs the whole schedule: `2 * count` events after
//! pseudo-random gaps (so that the agent is idle when each comes), image
//! and Twist events in turn:
//!
//! * image event `i`: a 640x480 rgb8 frame into the ring of port `frames`,
//!   its first 8 bytes `i`;
//! * Twist event `i`: `VelocityCommand { v: i, omega: 0 }` on `cmd`, then an
//!   8x1 mono8 frame holding `i` into the ring of port `clock`.
//!
//! Every frame is stamped an hour ahead on purpose: the `ros2` agent stamps
//! an Image with the epoch time of its step less the frame's age, and
//! counts a frame from the future as new, so that the Image's header stamp
//! is the epoch time at which the step that took the frame began
//! ([`nerve_ros2::convert::ros_stamp`]): when the agent took the frame, on
//! the clock of the ROS stamps. The tiny `clock` frame gives the step of a
//! Twist without a large frame in that step.
//!
//! It then writes `<out>/src.txt`: one line `I i t_written` or `T i t_send
//! t_clock` per event, epoch nanoseconds, each right after the command
//! went out or the frame was stored and announced.

use crate::procs::parse_sub;
use agent_sdk::clock::{now_ns, sleep_until_ns};
use agent_sdk::memory::{DEFAULT_SLOTS, FrameDesc, MemorySetup as _, PixelFormat, RingOutput, RingSpec};
use agent_sdk::{Agent, AgentError, CommonArgs, Context, Output, Setup, Task};
use clap::Parser;
use shm_schemas::payloads::motion::VelocityCommand;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The frame: 640x480 rgb8.
pub const WIDTH: u32 = 640;
/// The frame's height.
pub const HEIGHT: u32 = 480;
/// Bytes of a frame.
pub const FRAME_BYTES: usize = (WIDTH * HEIGHT * 3) as usize;
/// The clock frame of a Twist event: 8x1 mono8, its event number.
pub const CLOCK_WIDTH: u32 = 8;
/// How far ahead of the robot's clock a frame is stamped (1 h).
const AHEAD_NS: u64 = 3_600_000_000_000;

/// Arguments after `--`.
#[derive(Debug, Parser)]
#[command(no_binary_name = true)]
struct Args {
    /// image events, and as many Twist events
    #[arg(long)]
    count: usize,
    /// shortest gap between two events, µs
    #[arg(long, default_value_t = 25_000)]
    gap_min_us: u64,
    /// longest gap between two events, µs
    #[arg(long, default_value_t = 45_000)]
    gap_max_us: u64,
    /// seed of the gaps
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// directory of `src.txt`
    #[arg(long)]
    out: PathBuf,
}

/// The epoch time, ns (CLOCK_REALTIME: the clock of the ROS stamps and of
/// rmw_zenoh's attachment).
pub fn epoch_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

/// A small deterministic generator (xorshift64*) for the gaps.
#[derive(Debug, Clone)]
pub struct Gaps {
    state: u64,
    min_ns: u64,
    span_ns: u64,
}

impl Gaps {
    /// Gaps uniform in `[min_us, max_us]`.
    pub fn new(seed: u64, min_us: u64, max_us: u64) -> Self {
        let (lo, hi) = (min_us.min(max_us), min_us.max(max_us));
        Gaps {
            state: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1,
            min_ns: lo.saturating_mul(1000),
            span_ns: (hi - lo).saturating_mul(1000).saturating_add(1),
        }
    }

    /// The next gap, ns.
    pub fn next_ns(&mut self) -> u64 {
        self.state ^= self.state >> 12;
        self.state ^= self.state << 25;
        self.state ^= self.state >> 27;
        let r = self.state.wrapping_mul(0x2545_F491_4F6C_DD1D);
        self.min_ns + r % self.span_ns
    }
}

struct Source {
    cmd: Output<VelocityCommand>,
    frames: RingOutput,
    clock: RingOutput,
    args: Args,
    done: bool,
}

impl Agent for Source {
    const KIND: &'static str = "bench-ros2-src";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args = Args::try_parse_from(setup.raw_args()).map_err(|e| AgentError::Config(e.to_string()))?;
        let cmd = setup.output("cmd")?;
        let frames = setup.ring_output("frames", RingSpec::new(DEFAULT_SLOTS, FRAME_BYTES))?;
        let clock = setup.ring_output("clock", RingSpec::new(DEFAULT_SLOTS, CLOCK_WIDTH as usize))?;
        Ok(Source { cmd, frames, clock, args, done: false })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        self.frames.open().map_err(AgentError::from)?;
        self.clock.open().map_err(AgentError::from)?;
        Ok(())
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        // an agent without inputs steps only when resumed: one schedule, once
        if self.done {
            return Ok(());
        }
        self.done = true;
        let a = &self.args;
        let mut gaps = Gaps::new(a.seed, a.gap_min_us, a.gap_max_us);
        let mut rows = Vec::with_capacity(2 * a.count);
        let mut next = now_ns();
        let image = FrameDesc::image(WIDTH, HEIGHT, PixelFormat::Rgb8);
        let clock = FrameDesc::image(CLOCK_WIDTH, 1, PixelFormat::Gray8);
        for e in 0..2 * a.count {
            next = next.saturating_add(gaps.next_ns());
            sleep_until_ns(next);
            let i = e / 2;
            let seq = (i as u64).to_le_bytes();
            let ahead = now_ns().saturating_add(AHEAD_NS);
            if e % 2 == 0 {
                self.frames
                    .write_with(image.stamped(ahead), FRAME_BYTES, |buf| buf[..8].copy_from_slice(&seq))
                    .map_err(AgentError::from)?;
                rows.push(Row::Image { i, t_written: epoch_ns() });
            } else {
                self.cmd.send(VelocityCommand { v: i as f64, omega: 0.0, stamp_ns: now_ns() })?;
                let t_send = epoch_ns();
                self.clock
                    .write_with(clock.stamped(ahead), 8, |buf| buf.copy_from_slice(&seq))
                    .map_err(AgentError::from)?;
                rows.push(Row::Twist { i, t_send, t_clock: epoch_ns() });
            }
        }
        write_rows(&a.out.join("src.txt"), &rows)
            .map_err(|e| AgentError::Other(format!("cannot write {}: {e}", a.out.display())))
    }
}

/// One event of the schedule, as `src.txt` says it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Row {
    /// image event `i`: the frame stored and announced
    Image {
        /// event number
        i: usize,
        /// epoch ns
        t_written: i64,
    },
    /// Twist event `i`: the command sent, then its clock frame stored
    Twist {
        /// event number
        i: usize,
        /// epoch ns
        t_send: i64,
        /// epoch ns
        t_clock: i64,
    },
}

fn write_rows(path: &Path, rows: &[Row]) -> std::io::Result<()> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        for r in rows {
            match r {
                Row::Image { i, t_written } => writeln!(f, "I {i} {t_written}")?,
                Row::Twist { i, t_send, t_clock } => writeln!(f, "T {i} {t_send} {t_clock}")?,
            }
        }
        f.flush()?;
    }
    std::fs::rename(&tmp, path)
}

/// The events of `src.txt`: `(t_written)` of image event `i` and `(t_send,
/// t_clock)` of Twist event `i`, by event number.
#[derive(Debug, Default, PartialEq, Eq)]
pub struct Schedule {
    /// image events' `t_written`
    pub images: Vec<i64>,
    /// Twist events' `(t_send, t_clock)`
    pub twists: Vec<(i64, i64)>,
}

/// Reads `src.txt`.
pub fn read_rows(path: &Path) -> anyhow::Result<Schedule> {
    use anyhow::Context as _;
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut s = Schedule::default();
    for (n, line) in text.lines().enumerate() {
        let w: Vec<&str> = line.split_whitespace().collect();
        let num = |k: usize| w.get(k).and_then(|x| x.parse::<i64>().ok());
        let bad = || anyhow::anyhow!("{} line {}: expected `I i t` or `T i t t`: {line:?}", path.display(), n + 1);
        match (w.first(), num(1)) {
            (Some(&"I"), Some(i)) if usize::try_from(i).ok() == Some(s.images.len()) => {
                s.images.push(num(2).ok_or_else(bad)?);
            }
            (Some(&"T"), Some(i)) if usize::try_from(i).ok() == Some(s.twists.len()) => {
                s.twists.push((num(2).ok_or_else(bad)?, num(3).ok_or_else(bad)?));
            }
            _ => return Err(bad()),
        }
    }
    Ok(s)
}

/// Entry of `__agent-ros2-src`.
pub fn run_agent(rest: Vec<String>) -> ExitCode {
    match parse_sub::<CommonArgs>("nerve-bench __agent-ros2-src", rest) {
        Ok(common) => agent_sdk::run_with_args::<Source>(common),
        Err(code) => code,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_stay_in_their_range_and_spread() {
        let mut g = Gaps::new(7, 25_000, 45_000);
        let v: Vec<u64> = (0..2000).map(|_| g.next_ns()).collect();
        assert!(v.iter().all(|&x| (25_000_000..=45_000_000).contains(&x)), "out of range");
        // every 2 ms bin of the range is hit: the phases are spread
        let mut bins = [0u32; 10];
        for x in &v {
            bins[((x - 25_000_000) / 2_000_001) as usize] += 1;
        }
        assert!(bins.iter().all(|&b| b > 100), "{bins:?}");
    }

    #[test]
    fn rows_read_back() {
        let dir = std::env::temp_dir().join(format!("ros2-src-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let p = dir.join("src.txt");
        let rows = [Row::Image { i: 0, t_written: 5 }, Row::Twist { i: 0, t_send: 7, t_clock: 9 }];
        write_rows(&p, &rows).expect("written");
        assert_eq!(read_rows(&p).expect("read"), Schedule { images: vec![5], twists: vec![(7, 9)] });
        std::fs::write(&p, "I 0 1\nI 2 3\n").expect("written");
        assert!(read_rows(&p).expect_err("a gap").to_string().contains("line 2"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
