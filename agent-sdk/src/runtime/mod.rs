//! The runtime behind [`crate::run`]: builds the agent, registers it with the
//! router, runs the task thread and, in the main thread, the message checker.
//!
//! Threads:
//! * **message checker** (main thread, SCHED_FIFO one above the task): sleeps
//!   on the control service, the task's wake-up event and a 2 s housekeeping
//!   tick (`checker::HOUSEKEEPING`); applies commands to shared state and
//!   answers at once; notices a (re)started router and registers again,
//!   retrying with back-off; stops on SIGTERM/SIGINT, a `Stop` command or the
//!   task's request. An idle agent wakes once per tick and not otherwise.
//! * **task**: periodic (absolute deadlines, run-time period, lateness and
//!   overruns measured) or event-driven (blocked on a WaitSet of its inputs'
//!   listeners, a private wake-up event and, when the agent asked for one,
//!   its waker's eventfd ([`crate::Waker`]); never re-entered). A suspended
//!   periodic task waits at a gate until resumed, without polling.
//!
//! The modules, one per seam:
//! * `startup`: the command line, `--describe`, and the start of an agent
//!   (node, control service, ports, registration, threads) up to its stop;
//! * `task`: the task thread (periodic and event loops, the suspend gate);
//! * `router_link`: the agent's side of the router (register, notice a
//!   restarted router, unregister);
//! * `checker`: the message checker, serving the control service;
//! * `poll`: polling mode (`--poll`), the task that never sleeps;
//! * `step_clock`: the time the running step began, which the inputs count
//!   what it takes at;
//! * `runaway`: the guard that demotes a real-time task that takes a whole
//!   CPU for seconds (a step that never yields, an event storm).

mod checker;
mod poll;
mod router_link;
mod runaway;
mod startup;
pub(crate) mod step_clock;
mod task;
#[cfg(test)]
mod waker_tests;

pub use poll::PollError;
pub use router_link::epoch_service;
pub use startup::{EXIT_STARTUP, StartupError, abort_on_panic, run, run_status, run_with_args};

use crate::agent::AgentError;
use crate::meters::{LatenessRecorder, RateMeter};
use crate::world::Ipc;
use iceoryx2::port::notifier::Notifier;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Figures the task thread keeps about itself.
#[derive(Debug, Default)]
struct TaskFigures {
    cycles: u64,
    overruns: u64,
    rate: RateMeter,
    lateness: LatenessRecorder,
    errors: u64,
    last_cycle_ns: u64,
}

/// State shared by the message checker and the task.
struct Shared {
    period_ns: AtomicU64,
    suspended: AtomicBool,
    stop: AtomicBool,
    generation: AtomicU64,
    realtime: AtomicBool,
    /// the PM QoS bound held (fixed at start-up)
    cpu_latency: shm_schemas::stats::CpuLatency,
    figures: Mutex<TaskFigures>,
    /// when the running step started; 0 between steps (the watchdog's look,
    /// `checker`): an atomic, so that a step's start takes no lock
    in_step_since_ns: AtomicU64,
    gate: task::SuspendGate,
    wake: Notifier<Ipc>,
    /// `--poll`: the task polls instead of sleeping (`poll`)
    polling: Option<poll::Polling>,
}

impl Shared {
    /// Tells the other thread that the shared state changed: wakes the task
    /// (at its suspend gate or in its event loop's WaitSet) and the message
    /// checker (its WaitSet also listens to the wake-up event).
    fn poke(&self) {
        self.gate.notify();
        let _ = self.wake.notify();
    }

    /// Stops the agent from the task's side (the agent asked for it, or the
    /// task cannot go on); the message checker wakes and shuts down.
    fn request_stop(&self) {
        self.stop.store(true, Ordering::Release);
        self.poke();
    }

    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    fn figures(&self) -> std::sync::MutexGuard<'_, TaskFigures> {
        self.figures.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Keeps `AgentError` in the public path of this module for agent authors.
pub type StepResult = Result<(), AgentError>;
