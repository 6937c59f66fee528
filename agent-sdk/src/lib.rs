//! The nerve agent SDK: the template every agent is built from.
//!
//! An agent author implements [`Agent`] (ports and parameters in
//! [`Agent::new`], the algorithm in [`Agent::step`]) and calls [`run`] from
//! `main`. The SDK provides the rest, as in the thesis' Fig. 3-4:
//!
//! * a **message checker** thread serving the agent's control service
//!   (`nerve/<robot>/<agent>/ctl`): connect and disconnect inputs, period,
//!   suspend and resume, parameters, stop, statistics — each answered at once;
//! * the **task**, periodic (absolute deadlines, period changeable at run
//!   time, overruns and lateness measured) or event-driven (woken by input
//!   through iceoryx2 events, never re-entered, told which inputs woke it by
//!   [`Context::woken_by`]);
//! * the common command line (`--robot`, `--name`, `--period`, `--daemon`,
//!   `--log-level`), registration with the router and re-registration with a
//!   restarted one, SCHED_FIFO, locked memory and a PM QoS wake-up bound
//!   ([`cpu_latency`]) where permitted, sd_notify,
//!   clean stop on SIGTERM and SIGINT; a panic in any of its threads ends
//!   the process ([`abort_on_panic`], in every build profile), so that its
//!   supervisor sees a death rather than an agent that answers but never
//!   steps again.
//!
//! Ports are iceoryx2 publish-subscribe services of `#[repr(C)]` payloads
//! (see `shm-schemas`): a sample is written once in shared memory and read in
//! place by every subscriber.

#![warn(missing_docs)]

pub mod agent;
pub mod cli;
pub mod clock;
pub mod control;
pub mod cpu_latency;
pub mod daemon;
pub mod device;
pub mod dynamic;
pub mod memory;
pub mod meters;
pub mod params;
pub mod port;
pub mod ports;
pub mod process;
pub mod raw_port;
pub mod router_events;
pub mod rt;
pub mod runtime;
pub mod simclock;
pub mod termination;
pub mod testing;
pub mod world;

pub use agent::{Agent, AgentError, Context, Setup, Task, Waker};
pub use cli::CommonArgs;
pub use params::Param;
pub use port::{SeqInput, SeqOutput};
pub use ports::{Input, Meta, Output, PortError};
pub use runtime::{abort_on_panic, run, run_with_args};
pub use world::{Ipc, World};
