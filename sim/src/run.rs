//! Running the simulator in real time: the loop behind the `nerve-sim`
//! binary, kept in the library so it can be embedded.
//!
//! The loop is fixed-step (default 100 Hz). Each cycle the device hub reads
//! commands, steps the world and sends due reports; the truth log gets a
//! row; then the thread sleeps to the next **absolute** deadline on the
//! monotonic clock (`clock_nanosleep(TIMER_ABSTIME)`), so timing errors do
//! not accumulate. If the loop falls more than 10 periods behind (the
//! machine was busy), it counts an overrun and restarts its deadlines from
//! now instead of racing to catch up. SIGTERM and SIGINT set a stop flag;
//! the loop then flushes the log and the hub removes its device links.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use nix::errno::Errno;
use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
use nix::sys::time::TimeSpec;
use nix::time::{ClockId, ClockNanosleepFlags, clock_gettime, clock_nanosleep};

use crate::hub::DeviceHub;
use crate::pty::PtyError;
use crate::robot::{NoiseModel, RobotKind, RobotModel};
use crate::sim::{SimConfig, SimError, Simulation};
use crate::truth::{TruthError, TruthLog};
use crate::world::{World, WorldError};

/// What to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// World file.
    pub world: PathBuf,
    /// Which robot.
    pub robot: RobotKind,
    /// Where to publish the device links.
    pub dev_dir: PathBuf,
    /// Ground-truth CSV, if wanted.
    pub truth: Option<PathBuf>,
    /// Seed of all noise.
    pub seed: u64,
    /// Stop after this much simulated time, seconds.
    pub duration: Option<f64>,
    /// Steps per second.
    pub rate_hz: f64,
    /// Noise levels.
    pub noise: NoiseModel,
}

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The world file.
    #[error(transparent)]
    World(#[from] WorldError),
    /// The simulation set-up.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// Publishing the devices.
    #[error(transparent)]
    Pty(#[from] PtyError),
    /// The truth log.
    #[error(transparent)]
    Truth(#[from] TruthError),
    /// The step rate.
    #[error("step rate {0} Hz is invalid; use a value between 1 and 10000")]
    Rate(f64),
    /// The clock or signal set-up.
    #[error("{what} failed: {source}")]
    Os {
        /// What was being done.
        what: &'static str,
        /// OS error.
        source: Errno,
    },
}

/// What a run did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunSummary {
    /// Steps taken.
    pub steps: u64,
    /// Simulated seconds.
    pub sim_time: f64,
    /// Collisions.
    pub collisions: u64,
    /// Times the loop fell behind and re-based its deadlines.
    pub overruns: u64,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_stop_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Installs SIGTERM and SIGINT handlers that set the returned flag.
pub fn install_stop_handler() -> Result<&'static AtomicBool, RunError> {
    let action = SigAction::new(SigHandler::Handler(on_stop_signal), SaFlags::empty(), SigSet::empty());
    for sig in [Signal::SIGTERM, Signal::SIGINT] {
        // SAFETY: the handler only stores to an atomic, which is
        // async-signal-safe, and replaces no handler anyone relies on.
        unsafe { sigaction(sig, &action) }
            .map_err(|source| RunError::Os { what: "installing the SIGTERM/SIGINT handler", source })?;
    }
    Ok(&STOP)
}

/// Runs until `stop` is set or the duration is over.
pub fn run(opts: &RunOptions, stop: &AtomicBool) -> Result<RunSummary, RunError> {
    if !(1.0..=10_000.0).contains(&opts.rate_hz) {
        return Err(RunError::Rate(opts.rate_hz));
    }
    let world = World::load(&opts.world)?;
    let cfg = SimConfig { seed: opts.seed, dt: 1.0 / opts.rate_hz, noise: opts.noise };
    let mut sim = Simulation::new(world, RobotModel::for_kind(opts.robot), cfg)?;
    let mut truth = opts.truth.as_deref().map(TruthLog::create).transpose()?;
    let mut hub = DeviceHub::open(&opts.dev_dir, &sim)?;
    tracing::info!(
        world = %sim.world().name, robot = %opts.robot, seed = opts.seed,
        dev_dir = %opts.dev_dir.display(), rate_hz = opts.rate_hz, "simulator running"
    );

    let clock = |what| clock_gettime(ClockId::CLOCK_MONOTONIC).map_err(|source| RunError::Os { what, source });
    let period = TimeSpec::from(Duration::from_secs_f64(cfg.dt));
    let slack = TimeSpec::from(Duration::from_secs_f64(cfg.dt * 10.0));
    let mut next = clock("reading the monotonic clock")?;
    let mut overruns = 0;
    while !stop.load(Ordering::SeqCst) {
        if opts.duration.is_some_and(|d| sim.time() >= d - 1e-9) {
            break;
        }
        hub.step(&mut sim);
        if let Some(t) = truth.as_mut() {
            t.write(&sim.truth())?;
            if sim.steps() % 100 == 0 {
                t.flush()?;
            }
        }
        next = next + period;
        let now = clock("reading the monotonic clock")?;
        if now > next + slack {
            overruns += 1;
            tracing::warn!(overruns, t = sim.time(), "simulation fell behind real time");
            next = now;
        }
        match clock_nanosleep(ClockId::CLOCK_MONOTONIC, ClockNanosleepFlags::TIMER_ABSTIME, &next) {
            Ok(_) | Err(Errno::EINTR) => {}
            Err(source) => {
                return Err(RunError::Os { what: "sleeping to the next step", source });
            }
        }
    }
    if let Some(t) = truth.as_mut() {
        t.flush()?;
    }
    let summary = RunSummary { steps: sim.steps(), sim_time: sim.time(), collisions: sim.collisions(), overruns };
    for d in hub.devices() {
        tracing::info!(device = %d.kind(), stats = ?d.stats(), decode = ?d.decode_stats(), "device totals");
    }
    drop(hub);
    tracing::info!(?summary, "simulator stopped");
    Ok(summary)
}
