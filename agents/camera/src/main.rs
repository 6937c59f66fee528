//! `camera`: the robot's eye. A periodic agent (default 15 frames per
//! second) that stores RGB8 frames in the short-term-memory ring `cam` and
//! announces each on its output port `frames` (`nerve::RingNotice`), so any
//! number of agents read them in place, woken by the notice.
//!
//! ```text
//! nerve start camera --name cam -- --source test-pattern
//! nerve start camera --name cam -- --source v4l --device /dev/video0 --width 320 --height 240 --fps 15
//! nerve start camera --name cam -- --source sim [--sim-ring simcam]
//! ```
//!
//! Sources: `v4l` (a webcam through V4L2, see `device`), `test-pattern` (a
//! moving red disc, see `pattern`; no hardware needed), `sim` (frames the
//! simulator renders into a ring, see `sim`).
//!
//! Devices are opened in the task (`step`), never in `Agent::new`, which also
//! runs for `--describe` in a throw-away world. A missing, busy or failing
//! device is logged with its path and what to do, then retried with
//! exponential backoff (0.5 s doubling to 8 s); meanwhile each period costs
//! one clock comparison, no busy loop. `--fps` also sets the task period
//! unless `--period` is given (`nerve rate` changes the period at run time;
//! the device keeps the rate it was opened with).

mod convert;
mod device;
mod pattern;
mod sim;

use agent_sdk::memory::{FrameDesc, MemoryError, MemorySetup, PixelFormat, RingName, RingOutput, RingSpec};
use agent_sdk::{Agent, AgentError, CommonArgs, Context, Setup, Task};
use clap::{Parser, ValueEnum};
use std::path::PathBuf;
use std::time::Duration;

/// Where frames come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum SourceKind {
    /// A V4L2 camera (`--device`).
    V4l,
    /// A moving red disc on a textured background; no hardware needed.
    TestPattern,
    /// Frames the simulator renders into a ring (`--sim-ring`).
    Sim,
}

/// The camera's own options (after `--`).
#[derive(Debug, Clone, Parser)]
#[command(name = "nerve-camera --", about = "camera options", no_binary_name = false)]
struct CameraArgs {
    /// Where frames come from.
    #[arg(long, value_enum, default_value = "v4l")]
    source: SourceKind,
    /// V4L2 device of `--source v4l`.
    #[arg(long, default_value = "/dev/video0")]
    device: PathBuf,
    /// Frame width in pixels.
    #[arg(long, default_value_t = 320, value_parser = clap::value_parser!(u32).range(1..=8192))]
    width: u32,
    /// Frame height in pixels.
    #[arg(long, default_value_t = 240, value_parser = clap::value_parser!(u32).range(1..=8192))]
    height: u32,
    /// Frames per second (also the task rate unless --period is given).
    #[arg(long, default_value_t = 15.0)]
    fps: f64,
    /// The ring the frames are stored in (1-6 of a-z, 0-9, _; or id-N).
    #[arg(long, default_value = "cam")]
    ring: String,
    /// Slots of the ring (frames kept).
    #[arg(long, default_value_t = agent_sdk::memory::DEFAULT_SLOTS, value_parser = clap::value_parser!(u32).range(2..=1024))]
    slots: u32,
    /// The simulator's camera ring read by `--source sim`.
    #[arg(long, default_value = "simcam")]
    sim_ring: String,
}

impl CameraArgs {
    /// The camera's own arguments, before the SDK runs (`main` derives the
    /// period from `--fps`); `new` has them from [`Setup::args`].
    fn parse_agent_args(args: &[String]) -> Result<Self, agent_sdk::agent::args::ArgsError> {
        agent_sdk::agent::args::parse(Camera::KIND, args)
    }
}

/// What a source did in one period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Grab {
    /// A frame was stored and announced.
    Frame,
    /// No new frame this period.
    Nothing,
}

/// Why a source failed.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The device (camera, simulator ring) failed; the message says what to do.
    /// The agent closes the source and opens it again later.
    #[error("{0}")]
    Device(String),
    /// Storing or announcing the frame failed (not the device's fault).
    #[error(transparent)]
    Memory(#[from] MemoryError),
}

/// A frame source: opened in the task, dropped on failure and opened again.
pub trait Source: Send {
    /// What it is, for the log.
    fn describe(&self) -> String;
    /// Stores the next frame (number `n` of this agent) in `out` and announces it.
    fn grab(&mut self, out: &mut RingOutput, n: u64) -> Result<Grab, SourceError>;
}

/// The test pattern source.
#[derive(Debug)]
struct PatternSource {
    width: u32,
    height: u32,
}

impl Source for PatternSource {
    fn describe(&self) -> String {
        format!("test pattern {}x{}", self.width, self.height)
    }

    fn grab(&mut self, out: &mut RingOutput, n: u64) -> Result<Grab, SourceError> {
        let (w, h) = (self.width, self.height);
        out.write_with(FrameDesc::image(w, h, PixelFormat::Rgb8), w as usize * h as usize * 3, |buf| {
            pattern::render(n, w, h, buf)
        })?;
        Ok(Grab::Frame)
    }
}

/// Exponential backoff between attempts to open a failing source.
#[derive(Debug, Default)]
struct Backoff {
    failures: u32,
    next_try_ns: u64,
}

impl Backoff {
    const FIRST: Duration = Duration::from_millis(500);
    const MAX: Duration = Duration::from_secs(8);

    fn due(&self, now_ns: u64) -> bool {
        now_ns >= self.next_try_ns
    }

    /// Records a failure at `now_ns` and returns the delay before the next attempt.
    fn failed(&mut self, now_ns: u64) -> Duration {
        let delay = Self::FIRST.saturating_mul(1u32 << self.failures.min(8)).min(Self::MAX);
        self.failures += 1;
        self.next_try_ns = now_ns + delay.as_nanos() as u64;
        delay
    }

    fn succeeded(&mut self) {
        self.failures = 0;
    }
}

struct Camera {
    args: CameraArgs,
    robot: shm_schemas::RobotName,
    out: RingOutput,
    source: Option<Box<dyn Source>>,
    backoff: Backoff,
    frames: u64,
}

impl Camera {
    fn open_source(&self) -> Result<Box<dyn Source>, SourceError> {
        let a = &self.args;
        Ok(match a.source {
            SourceKind::TestPattern => Box::new(PatternSource { width: a.width, height: a.height }),
            SourceKind::V4l => Box::new(device::V4lSource::open(&a.device, a.width, a.height, a.fps)?),
            SourceKind::Sim => {
                let ring = RingName::parse(&a.sim_ring)
                    .map_err(|e| SourceError::Device(format!("--sim-ring {}: {e}", a.sim_ring)))?;
                Box::new(sim::SimSource::open(&self.robot, &ring)?)
            }
        })
    }

    fn device_failed(&mut self, now_ns: u64, e: &SourceError) {
        let delay = self.backoff.failed(now_ns);
        tracing::error!(
            attempt = self.backoff.failures,
            "{e}; retrying in {}",
            agent_sdk::clock::format_duration(delay)
        );
    }
}

impl Agent for Camera {
    const KIND: &'static str = "camera";

    fn task() -> Task {
        Task::Periodic(Duration::from_nanos(1_000_000_000 / 15))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: CameraArgs = setup.args()?;
        if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0) {
            return Err(AgentError::Config(format!("--fps {}: give a rate between 0 and 1000", args.fps)));
        }
        let len = args.width as usize * args.height as usize * 3;
        let out =
            setup.ring_output("frames", RingSpec::new(args.slots, len).named(&args.ring)).map_err(|e| match e {
                AgentError::Config(m) => {
                    AgentError::Config(format!("{m}; this camera's ring is set with -- --ring NAME"))
                }
                e => e,
            })?;
        Ok(Camera {
            args,
            robot: setup.world().robot().clone(),
            out,
            source: None,
            backoff: Backoff::default(),
            frames: 0,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        if matches!(self.args.source, SourceKind::V4l) {
            // a real camera beside a simulated robot's clock is refused with what to do
            agent_sdk::simclock::refuse_real_device(&self.args.device)
                .map_err(|e| AgentError::Config(e.to_string()))?;
        }
        // the ring now (a clash with another writer stops the agent here);
        // the device at the first step, so that a missing one is retried
        let w = self.out.open()?;
        tracing::info!(
            "frames go to ring {} ({} slots of {} bytes), announced on port frames",
            w.name(),
            w.slot_count(),
            w.slot_capacity()
        );
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        if self.source.is_none() {
            if !self.backoff.due(now) {
                return Ok(());
            }
            match self.open_source() {
                Ok(s) => {
                    tracing::info!("capturing from {}", s.describe());
                    self.source = Some(s);
                }
                Err(e) => {
                    self.device_failed(now, &e);
                    return Ok(());
                }
            }
        }
        let Some(source) = self.source.as_mut() else { return Ok(()) };
        match source.grab(&mut self.out, self.frames) {
            Ok(Grab::Frame) => {
                self.frames += 1;
                if self.backoff.failures > 0 {
                    tracing::info!("frames flow again after {} failed attempt(s)", self.backoff.failures);
                }
                self.backoff.succeeded();
                Ok(())
            }
            Ok(Grab::Nothing) => Ok(()),
            Err(SourceError::Memory(e)) => Err(e.into()),
            Err(e) => {
                self.source = None; // closes the device
                self.device_failed(now, &e);
                Ok(())
            }
        }
    }

    fn stop(&mut self, _ctx: &mut Context) {
        self.source = None;
        tracing::info!("{} frames captured", self.frames);
    }
}

fn main() -> std::process::ExitCode {
    let mut args = <CommonArgs as Parser>::parse();
    // --fps sets the task period unless --period says otherwise; bad camera
    // options are reported by Agent::new, through the usual startup path
    if args.period.is_none()
        && let Ok(cam) = CameraArgs::parse_agent_args(&args.args)
        && cam.fps.is_finite()
        && cam.fps > 0.0
    {
        args.period = Some(format!("{}hz", cam.fps));
    }
    agent_sdk::run_with_args::<Camera>(args)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse_with_defaults() {
        let a = CameraArgs::parse_agent_args(&[]).expect("defaults");
        assert_eq!((a.source, a.width, a.height, a.fps, a.ring.as_str()), (SourceKind::V4l, 320, 240, 15.0, "cam"));
        let a = CameraArgs::parse_agent_args(
            &["--source", "test-pattern", "--width", "64", "--height", "48", "--fps", "30"].map(String::from),
        )
        .expect("parse");
        assert_eq!((a.source, a.width, a.height, a.fps), (SourceKind::TestPattern, 64, 48, 30.0));
        assert!(CameraArgs::parse_agent_args(&["--source".into(), "webcam".into()]).is_err());
    }

    #[test]
    fn backoff_doubles_to_a_cap() {
        let mut b = Backoff::default();
        assert!(b.due(0));
        let delays: Vec<u64> = (0..8).map(|_| b.failed(0).as_millis() as u64).collect();
        assert_eq!(delays, [500, 1000, 2000, 4000, 8000, 8000, 8000, 8000]);
        assert!(!b.due(1));
        b.succeeded();
        assert_eq!(b.failed(0), Duration::from_millis(500));
    }
}
