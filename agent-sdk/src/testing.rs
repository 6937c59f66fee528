//! Test an agent in the test's own process: no router, no iceoryx2 ports, no
//! sleeping.
//!
//! A [`Harness`] runs the agent's own [`Agent::new`], with its ports bound to
//! in-memory queues, then its `start`. The test queues samples on inputs,
//! runs steps against a clock it controls, reads what the outputs sent,
//! changes parameters and the period, and suspends and resumes the agent, as
//! the router and `nerve` would. What the agent sees is what it sees when it
//! runs: [`Context::now_ns`], [`Context::woken_by`], samples with their
//! sender, sequence number and stamp, and a full input overwriting its
//! oldest sample.
//!
//! ```
//! use agent_sdk::testing::Harness;
//! use agent_sdk::{Agent, AgentError, Context, Input, Output, Setup, Task};
//! use shm_schemas::payloads::Tick;
//! use std::time::Duration;
//!
//! /// Passes ticks on with `seq` multiplied by `gain`.
//! struct Scale { input: Input<Tick>, out: Output<Tick>, gain: agent_sdk::Param<u64> }
//!
//! impl Agent for Scale {
//!     const KIND: &'static str = "scale";
//!     fn task() -> Task { Task::EventDriven }
//!     fn new(setup: &mut Setup) -> Result<Self, AgentError> {
//!         Ok(Scale { input: setup.input("in")?, out: setup.output("out")?, gain: setup.param("gain", 2) })
//!     }
//!     fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
//!         let gain = self.gain.get();
//!         self.input.try_drain(|_, t| self.out.send(Tick { seq: t.seq * gain, stamp_ns: t.stamp_ns }))?;
//!         Ok(())
//!     }
//! }
//!
//! let mut h = Harness::<Scale>::new().unwrap();
//! h.send("in", Tick { seq: 21, stamp_ns: 0 }).unwrap();
//! h.step().unwrap();
//! assert_eq!(h.output::<Tick>("out").unwrap()[0].seq, 42);
//! h.set_param("gain", "3").unwrap();
//! h.send("in", Tick { seq: 1, stamp_ns: 0 }).unwrap();
//! h.step().unwrap();
//! assert_eq!(h.output::<Tick>("out").unwrap()[0].seq, 3);
//! ```
//!
//! A periodic agent is driven by the clock: [`Harness::advance`] moves it
//! on and runs a step at every deadline it passes, so a thousand cycles of
//! a 100 ms agent take as long as the steps themselves.
//!
//! An agent that opens iceoryx2 services of its own (besides its ports)
//! finds them in a private robot (`test-PID-N`, [`Harness::world`]), whose
//! files the harness removes when dropped.
//!
//! Calls work as on a running agent: the test calls a service the agent
//! serves ([`Harness::call`], [`Harness::ask`]) and its own handler answers
//! at its next step; the calls the agent makes through a client come to
//! the test ([`Harness::requests`]), which answers them
//! ([`Harness::answer`]), or, in a [`Wiring`], to another agent's service.
//!
//! Several agents wired together run in a [`Wiring`]: a harness per agent
//! on one fake clock, outputs connected to inputs as the router connects
//! them (and refused with the router's messages), periodic agents stepping
//! at their deadlines and event-driven ones when a sample arrives, in a
//! fixed order; see [`wiring`] for the order and an example.

use crate::agent::{Agent, AgentError, Binding, Context, Setup, Task};
use crate::params::ParamTable;
use crate::port::PortError;
use crate::port::bytes::{DynInput, Meta};
use crate::port::memory::{Bus, Collected, SampleBuf};
use crate::world::{World, WorldError};
use shm_schemas::stats::InputStats;
use shm_schemas::{AgentName, Payload};
use std::marker::PhantomData;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

mod calls;
pub mod wiring;
pub use wiring::Wiring;

/// Why a harness could not do what the test asked. A failed step is not
/// one of these: steps return the agent's own [`AgentError`].
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    /// The harness's private robot could not be set up.
    #[error("the test robot: {0}")]
    World(#[from] WorldError),
    /// The agent's name is not a valid agent name.
    #[error("agent name {name:?}: {source}")]
    Name {
        /// the name given
        name: String,
        /// why it is refused
        #[source]
        source: shm_schemas::NameError,
    },
    /// `Agent::new` or `Agent::start` failed.
    #[error("agent {kind}: {stage} failed: {source}")]
    Agent {
        /// the agent's kind
        kind: &'static str,
        /// `new` or `start`
        stage: &'static str,
        /// the agent's error
        #[source]
        source: AgentError,
    },
    /// A parameter setting was refused (by its type or the agent's check).
    #[error("parameter {key}={value}: {reason}")]
    Param {
        /// the key
        key: String,
        /// the value given
        value: String,
        /// why it was refused
        reason: String,
    },
    /// The agent has no such port.
    #[error("the agent has no {direction} port {port:?}; it has {known:?}")]
    NoSuchPort {
        /// `input` or `output`
        direction: &'static str,
        /// the port asked for
        port: String,
        /// the ports of that direction it has
        known: Vec<String>,
    },
    /// The port carries another type than the test used.
    #[error("port {port:?} carries {carries}, not {asked}")]
    WrongType {
        /// the port
        port: String,
        /// the type it was declared with
        carries: String,
        /// the type the test used
        asked: &'static str,
    },
    /// A sample could not be queued.
    #[error(transparent)]
    Port(#[from] PortError),
    /// A [`Wiring`] refused a connection, with the message the router
    /// gives for it (no such agent or port, another type, not connected).
    #[error(transparent)]
    Connect(#[from] shm_schemas::control::cli_to_router::RouterError),
    /// A port was not named `AGENT/PORT`.
    #[error("{given:?} is not a port: name it AGENT/PORT, e.g. \"t1/tick\"")]
    PortRef {
        /// what was given
        given: String,
    },
    /// A [`Wiring`] already has an agent of this name.
    #[error("the wiring already has an agent named {name:?}: give each agent its own name")]
    Duplicate {
        /// the name
        name: String,
    },
    /// The agent of this name is of another type than the test asked for.
    #[error("agent {name:?} is a {kind}, not a {asked}")]
    WrongAgent {
        /// the name
        name: String,
        /// its kind
        kind: &'static str,
        /// the kind asked for
        asked: &'static str,
    },
    /// A step of an agent of a [`Wiring`] failed.
    #[error("agent {agent:?}: step failed: {source}")]
    Step {
        /// the agent's name
        agent: String,
        /// the agent's error
        #[source]
        source: AgentError,
    },
    /// A sample could not be carried from an output to an input.
    #[error("carrying {from} to {to:?}: {reason}")]
    Forward {
        /// the output, `AGENT/PORT`
        from: String,
        /// the inputs it goes to
        to: Vec<String>,
        /// why an input refused it
        reason: String,
    },
    /// A call the test made was not answered at the agent's step.
    #[error(
        "service {port:?}: {id} was not answered at the agent's step; does its step serve the port \
         (`serve`/`serve_up_to` with a large enough max)?"
    )]
    NotAnswered {
        /// the service
        port: String,
        /// the call
        id: crate::port::CallId,
    },
    /// The test answered a call that is not in flight.
    #[error("client {port:?}: {id} is not in flight (never made, answered already, timed out or unwired)")]
    NotInFlight {
        /// the client
        port: String,
        /// the call
        id: crate::port::CallId,
    },
    /// A call the test made was answered with an error.
    #[error("service {port:?}: {source}")]
    Call {
        /// the service
        port: String,
        /// what the call ended with
        #[source]
        source: crate::port::CallError,
    },
    /// Event-driven agents kept waking each other at one instant.
    #[error(
        "the agents stepped {steps} times at {at_ns} ns without settling: a loop of connections \
         in which every step sends again; disconnect one of them or make one periodic"
    )]
    Unsettled {
        /// steps run at that instant
        steps: u64,
        /// the instant
        at_ns: u64,
    },
}

/// A sample of `T` as a test's port holds it: `value`, in bytes of its own
/// aligned for `T`.
fn sample_of<T: Payload>(value: T) -> Result<SampleBuf, PortError> {
    let mut buf = SampleBuf::zeroed(T::stable_type_name(), std::mem::size_of::<T>(), std::mem::align_of::<T>())?;
    // SAFETY: the buffer is `size_of::<T>()` bytes aligned for `T`, and ours alone
    unsafe { buf.bytes_mut().as_mut_ptr().cast::<T>().write(value) };
    Ok(buf)
}

/// The value of `T` a test's sample holds, if it is a whole `T`.
fn value_of<T: Payload>(buf: &SampleBuf) -> Option<T> {
    let bytes = buf.bytes();
    if bytes.len() != std::mem::size_of::<T>() || buf.align() < std::mem::align_of::<T>() {
        return None;
    }
    // SAFETY: the bytes are a whole `T`, aligned for it (checked above),
    // written by an output of `T` (the caller checked the type name)
    Some(unsafe { bytes.as_ptr().cast::<T>().read() })
}

/// The clock's reading when a harness starts: 1 s, so that a stamp of 0
/// never looks like "now".
const START_NS: u64 = 1_000_000_000;

/// Tells the harnesses of one process apart (each has its own robot).
static HARNESSES: AtomicU64 = AtomicU64::new(0);

/// How to start a [`Harness`]: name, arguments, parameters, period.
pub struct HarnessBuilder<A: Agent> {
    name: Option<String>,
    args: Vec<String>,
    params: Vec<(String, String)>,
    period: Option<Duration>,
    suspended: bool,
    agent: PhantomData<fn() -> A>,
}

impl<A: Agent> std::fmt::Debug for HarnessBuilder<A> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HarnessBuilder").field("kind", &A::kind()).field("args", &self.args).finish()
    }
}

impl<A: Agent> HarnessBuilder<A> {
    /// The agent's name (default: its kind).
    pub fn name(mut self, name: &str) -> Self {
        self.name = Some(name.into());
        self
    }

    /// The arguments the agent gets after `--` ([`Setup::args`]).
    pub fn args<S: Into<String>>(mut self, args: impl IntoIterator<Item = S>) -> Self {
        self.args = args.into_iter().map(Into::into).collect();
        self
    }

    /// A parameter setting applied after `new`, as `--param KEY=VALUE` is.
    pub fn param(mut self, key: &str, value: &str) -> Self {
        self.params.push((key.into(), value.into()));
        self
    }

    /// The period of a periodic agent, as `--period` sets it (default: the
    /// agent's own).
    pub fn period(mut self, period: Duration) -> Self {
        self.period = Some(period);
        self
    }

    /// Starts the agent suspended, as `nerve start --suspended` does.
    pub fn suspended(mut self) -> Self {
        self.suspended = true;
        self
    }

    /// Runs the agent's `new`, applies the parameters and runs its `start`.
    pub fn start(self) -> Result<Harness<A>, HarnessError> {
        let n = HARNESSES.fetch_add(1, Ordering::Relaxed);
        let world = World::new(&format!("test-{}-{n}", std::process::id()))?;
        let name = self.name.unwrap_or_else(|| A::kind().to_owned());
        let agent_name = AgentName::new(&name).map_err(|source| HarnessError::Name { name: name.clone(), source })?;
        let bus = Arc::new(Bus::new(START_NS));
        let mut setup = Setup::new(world.clone(), agent_name, Binding::Memory(bus.clone()), self.args);
        // from here on the world's files are removed, whatever happens
        let cleanup = WorldCleanup(world);
        let agent =
            A::new(&mut setup).map_err(|source| HarnessError::Agent { kind: A::kind(), stage: "new", source })?;
        let Setup { inputs, params, calls, waker, .. } = setup;
        for (key, value) in self.params {
            params.set(&key, &value).map_err(|reason| HarnessError::Param { key, value, reason })?;
        }
        let period_ns = match (A::task(), self.period) {
            (Task::Periodic(_), Some(p)) | (Task::Periodic(p), None) => crate::clock::nanos(p).max(1),
            (Task::EventDriven, _) => 0,
        };
        let mut ctx = Context {
            name,
            cycle: 0,
            now_ns: START_NS,
            period: None,
            deadline_ns: 0,
            stop: false,
            inputs: inputs.iter().map(|i| i.name().to_owned()).collect(),
            woken: vec![false; inputs.len()],
            waker: false,
        };
        let mut agent = agent;
        agent.start(&mut ctx).map_err(|source| HarnessError::Agent { kind: A::kind(), stage: "start", source })?;
        Ok(Harness {
            agent: Some(agent),
            ctx,
            bus,
            inputs,
            params,
            period_ns,
            last_ns: START_NS,
            suspended: self.suspended,
            errors: 0,
            calls: calls.memory,
            waker,
            _cleanup: cleanup,
        })
    }
}

/// Removes the harness robot's shared-memory and iceoryx2 files (left only
/// by an agent that opens services of its own) when dropped.
struct WorldCleanup(World);

impl Drop for WorldCleanup {
    fn drop(&mut self) {
        for f in self.0.shm_files().into_iter().chain(self.0.iox2_files()) {
            let _ = std::fs::remove_file(f);
        }
    }
}

/// An agent running in the test's own process; see the [module](self).
pub struct Harness<A: Agent> {
    /// `None` once stopped
    agent: Option<A>,
    ctx: Context,
    bus: Arc<Bus>,
    inputs: Vec<Arc<dyn DynInput>>,
    params: ParamTable,
    /// 0 for an event-driven agent
    period_ns: u64,
    /// when the last periodic step ran (or the agent started or resumed):
    /// the next comes one period later
    last_ns: u64,
    suspended: bool,
    errors: u64,
    /// the call ports' in-memory queues
    calls: Vec<crate::port::call::memory::MemCallPort>,
    /// the agent's waker, if it asked for one ([`Setup::waker`])
    waker: Option<crate::agent::Waker>,
    // dropped last: the agent's own services are gone by then
    _cleanup: WorldCleanup,
}

impl<A: Agent> std::fmt::Debug for Harness<A> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Harness")
            .field("kind", &A::kind())
            .field("now_ns", &self.ctx.now_ns)
            .field("cycles", &self.ctx.cycle)
            .finish()
    }
}

impl<A: Agent> Harness<A> {
    /// Starts the agent with its kind as name, no arguments and its own
    /// defaults; [`Harness::builder`] for more.
    pub fn new() -> Result<Self, HarnessError> {
        Self::builder().start()
    }

    /// How to start it with a name, arguments, parameters or a period.
    pub fn builder() -> HarnessBuilder<A> {
        HarnessBuilder {
            name: None,
            args: Vec::new(),
            params: Vec::new(),
            period: None,
            suspended: false,
            agent: PhantomData,
        }
    }

    /// The agent, to look at its state.
    pub fn agent(&self) -> &A {
        self.agent.as_ref().expect("the harness holds its agent until it is stopped")
    }

    /// The agent, to change its state.
    pub fn agent_mut(&mut self) -> &mut A {
        self.agent.as_mut().expect("the harness holds its agent until it is stopped")
    }

    /// The clock the agent sees (CLOCK_MONOTONIC ns in a running agent);
    /// starts at 1 s.
    pub fn now_ns(&self) -> u64 {
        self.ctx.now_ns
    }

    /// How many steps ran.
    pub fn cycles(&self) -> u64 {
        self.ctx.cycle
    }

    /// How many steps returned an error.
    pub fn errors(&self) -> u64 {
        self.errors
    }

    /// Whether a step asked to stop ([`Context::request_stop`]).
    pub fn stop_requested(&self) -> bool {
        self.ctx.stop
    }

    /// The period of a periodic agent.
    pub fn period(&self) -> Option<Duration> {
        (self.period_ns > 0).then(|| Duration::from_nanos(self.period_ns))
    }

    /// The harness's private robot.
    pub fn world(&self) -> &World {
        &self._cleanup.0
    }

    /// Queues `value` on input `input`, from a sender called `test`.
    pub fn send<T: Payload>(&mut self, input: &str, value: T) -> Result<(), HarnessError> {
        self.send_from(input, "test", value)
    }

    /// Queues `value` on input `input` from agent `sender` (its output
    /// `out`), stamped now: each sender is a source of its own, as when the
    /// router connects several outputs to one input. Past 16 waiting
    /// samples of one sender the oldest is overwritten and counted as
    /// dropped.
    pub fn send_from<T: Payload>(&mut self, input: &str, sender: &str, value: T) -> Result<(), HarnessError> {
        let port = self.input_port::<T>(input)?;
        port.queue(sender, "out", sample_of(value)?, self.ctx.now_ns)?;
        Ok(())
    }

    fn find_input(&self, input: &str) -> Result<&Arc<dyn DynInput>, HarnessError> {
        self.inputs.iter().find(|i| i.name() == input).ok_or_else(|| HarnessError::NoSuchPort {
            direction: "input",
            port: input.into(),
            known: self.inputs.iter().map(|i| i.name().to_owned()).collect(),
        })
    }

    fn input_port<T: Payload>(&self, input: &str) -> Result<&Arc<dyn DynInput>, HarnessError> {
        let port = self.find_input(input)?;
        typed_input::<T>(input, port)?;
        Ok(port)
    }

    /// Takes what output `port` sent since the last call, oldest first.
    pub fn output<T: Payload>(&mut self, port: &str) -> Result<Vec<T>, HarnessError> {
        Ok(self.output_with_meta::<T>(port)?.into_iter().map(|(_, v)| v).collect())
    }

    /// Like [`Harness::output`], with each sample's sender, sequence number and stamp.
    pub fn output_with_meta<T: Payload>(&mut self, port: &str) -> Result<Vec<(Meta, T)>, HarnessError> {
        typed_output::<T>(&self.bus, port)
    }

    /// Queues `bytes` on input `input` from agent `sender` (its output
    /// `out`), stamped now; as [`Harness::send_from`] does with a value.
    /// The bytes are the payload's, exactly its size: for an input
    /// declared by layout ([`Setup::input_of`]) or by a type.
    pub fn send_bytes_from(&mut self, input: &str, sender: &str, bytes: &[u8]) -> Result<(), HarnessError> {
        let port = self.find_input(input)?;
        let (_, align) = port.payload_layout();
        port.queue(sender, "out", SampleBuf::copy_of(input, bytes, align)?, self.ctx.now_ns)?;
        Ok(())
    }

    /// Takes what output `port` sent since the last call, oldest first, as
    /// bytes (of an output declared by layout, [`Setup::output_of`], or by a type).
    pub fn output_bytes(&mut self, port: &str) -> Result<Vec<(Meta, Vec<u8>)>, HarnessError> {
        let collected = collected(&self.bus, port)?.1;
        Ok(collected.take().into_iter().map(|(h, b)| (Meta::of(&h), b.bytes().to_vec())).collect())
    }

    /// What each input counts about each source (`nerve ps --json`'s
    /// `inputs`): received, dropped, last age.
    pub fn input_stats(&self) -> Vec<InputStats> {
        self.inputs.iter().flat_map(|i| i.stats(self.ctx.now_ns)).collect()
    }

    /// Sets a parameter as `nerve param set` does; the error is the refusal
    /// `nerve` would print.
    pub fn set_param(&mut self, key: &str, value: &str) -> Result<(), String> {
        self.params.set(key, value)
    }

    /// A parameter's (or figure's) value as `nerve param get` shows it.
    pub fn param(&self, key: &str) -> Result<String, String> {
        self.params.get(key)
    }

    /// Changes the period of a periodic agent, as `nerve rate` does: the
    /// next step comes one new period after the last one. Ignored for an
    /// event-driven agent.
    pub fn set_period(&mut self, period: Duration) {
        if self.period_ns == 0 {
            return;
        }
        self.period_ns = crate::clock::nanos(period).max(1);
    }

    fn next_deadline(&self) -> u64 {
        self.last_ns.saturating_add(self.period_ns)
    }

    /// Suspends the agent (`nerve suspend`): steps and deadlines are
    /// skipped until it resumes.
    pub fn suspend(&mut self) {
        self.suspended = true;
    }

    /// Resumes the agent (`nerve resume`). An event-driven agent steps at
    /// once, with the inputs that got samples meanwhile; a periodic one
    /// starts a new period from now.
    pub fn resume(&mut self) -> Result<(), AgentError> {
        if !self.suspended {
            return Ok(());
        }
        self.suspended = false;
        if self.period_ns == 0 {
            self.run_step()
        } else {
            self.last_ns = self.ctx.now_ns;
            Ok(())
        }
    }

    /// Whether the agent is suspended.
    pub fn is_suspended(&self) -> bool {
        self.suspended
    }

    /// One cycle. An event-driven agent steps now, woken by the inputs that
    /// have samples waiting (it steps even with none: the test asked). A
    /// periodic agent's clock moves to its next deadline and it steps
    /// there. Nothing runs while suspended.
    pub fn step(&mut self) -> Result<(), AgentError> {
        if self.suspended {
            return Ok(());
        }
        if self.period_ns > 0 {
            let deadline = self.next_deadline();
            self.set_clock(deadline);
            self.ctx.deadline_ns = deadline;
            self.last_ns = deadline;
        }
        self.run_step()
    }

    /// Moves the clock on by `by`. A periodic agent steps at every deadline
    /// passed (unless suspended); the first failed step ends the advance
    /// and is returned. Returns how many steps ran.
    pub fn advance(&mut self, by: Duration) -> Result<u64, AgentError> {
        let until = self.ctx.now_ns.saturating_add(crate::clock::nanos(by));
        let before = self.ctx.cycle;
        if self.period_ns > 0 && !self.suspended {
            while self.next_deadline() <= until {
                self.step()?;
            }
        }
        self.set_clock(until);
        Ok(self.ctx.cycle - before)
    }

    /// Whether the agent's waker ([`Setup::waker`]) was woken since the
    /// last step: a running event-driven agent would step now. The harness
    /// never steps on its own; [`Harness::step`] takes the wake (the step
    /// sees [`Context::woken_by_waker`]), [`Harness::step_if_woken`] steps
    /// only if one waits.
    pub fn wake_pending(&self) -> bool {
        self.waker.as_ref().is_some_and(crate::agent::Waker::pending)
    }

    /// Steps as a running event-driven agent would for its waker: when a
    /// wake waits ([`Harness::wake_pending`]) and the agent is not
    /// suspended. Returns whether it stepped.
    pub fn step_if_woken(&mut self) -> Result<bool, AgentError> {
        if self.suspended || !self.wake_pending() {
            return Ok(false);
        }
        self.step()?;
        Ok(true)
    }

    /// Runs `n` cycles: [`Harness::step`] `n` times.
    pub fn run_cycles(&mut self, n: u64) -> Result<(), AgentError> {
        for _ in 0..n {
            self.step()?;
        }
        Ok(())
    }

    fn set_clock(&mut self, ns: u64) {
        self.ctx.now_ns = self.ctx.now_ns.max(ns);
        self.bus.set_now(self.ctx.now_ns);
    }

    fn run_step(&mut self) -> Result<(), AgentError> {
        for (woken, input) in self.ctx.woken.iter_mut().zip(&self.inputs) {
            *woken = self.period_ns == 0 && input.has_queued();
        }
        self.ctx.period = self.period();
        self.ctx.waker = self.waker.as_ref().is_some_and(crate::agent::Waker::take);
        let agent = self.agent.as_mut().expect("the harness holds its agent until it is stopped");
        let result = agent.step(&mut self.ctx);
        self.ctx.cycle += 1;
        self.ctx.woken.fill(false);
        self.ctx.waker = false;
        if result.is_err() {
            self.errors += 1;
        }
        result
    }

    /// Runs the agent's `stop` and hands the agent back.
    pub fn stop(mut self) -> A {
        let mut agent = self.agent.take().expect("the harness holds its agent until it is stopped");
        agent.stop(&mut self.ctx);
        agent
    }
}

/// Refuses input `input` unless it carries `T`.
fn typed_input<T: Payload>(input: &str, port: &Arc<dyn DynInput>) -> Result<(), HarnessError> {
    let layout = (std::mem::size_of::<T>(), std::mem::align_of::<T>());
    if port.type_name() != T::stable_type_name() || port.payload_layout() != layout {
        return Err(HarnessError::WrongType {
            port: input.into(),
            carries: port.type_name().into(),
            asked: T::stable_type_name(),
        });
    }
    Ok(())
}

/// Output `port` of a test's agent: its type name and collected samples.
fn collected(bus: &Bus, port: &str) -> Result<(String, Arc<Collected>), HarnessError> {
    bus.output(port).map_err(|known| HarnessError::NoSuchPort { direction: "output", port: port.into(), known })
}

/// Takes what output `port`, which must carry `T`, sent since the last call.
fn typed_output<T: Payload>(bus: &Bus, port: &str) -> Result<Vec<(Meta, T)>, HarnessError> {
    let (carries, collected) = collected(bus, port)?;
    let wrong =
        || HarnessError::WrongType { port: port.into(), carries: carries.clone(), asked: T::stable_type_name() };
    if carries != T::stable_type_name() {
        return Err(wrong());
    }
    collected.take().into_iter().map(|(h, b)| value_of::<T>(&b).map(|v| (Meta::of(&h), v)).ok_or_else(wrong)).collect()
}

impl<A: Agent> Drop for Harness<A> {
    /// Runs the agent's `stop` if the test did not.
    fn drop(&mut self) {
        if let Some(mut agent) = self.agent.take() {
            agent.stop(&mut self.ctx);
        }
    }
}

#[cfg(test)]
mod tests;
