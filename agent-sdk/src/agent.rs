//! The agent template (thesis Fig. 3-4): the author implements [`Agent`],
//! the SDK runs the message checker, the task and the daemon plumbing.
//!
//! ```no_run
//! use agent_sdk::{Agent, AgentError, Context, Output, Setup, Task};
//! use shm_schemas::payloads::Tick;
//! use std::time::Duration;
//!
//! struct Ticker { out: Output<Tick>, seq: u64 }
//!
//! impl Agent for Ticker {
//!     const KIND: &'static str = "ticker";
//!     fn task() -> Task { Task::Periodic(Duration::from_millis(100)) }
//!     fn new(setup: &mut Setup) -> Result<Self, AgentError> {
//!         Ok(Ticker { out: setup.output("tick")?, seq: 0 })
//!     }
//!     fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
//!         self.seq += 1;
//!         self.out.send(Tick { seq: self.seq, stamp_ns: ctx.now_ns() })?;
//!         Ok(())
//!     }
//! }
//!
//! fn main() -> std::process::ExitCode { agent_sdk::run::<Ticker>() }
//! ```

use crate::params::{Param, ParamTable};
pub(crate) use crate::port::bytes::Binding;
use crate::port::bytes::{DynInput, SchemaInput, SchemaOutput};
use crate::port::{Input, Output, PortError, SeqInput, SeqOutput};
use crate::world::World;
use shm_schemas::control::agent_to_router::{PortSpec, add_schema};
use shm_schemas::names::validate_port_name;
use shm_schemas::{AgentName, Described as _, Payload, Schema, SeqPart};
use std::fmt::Display;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;

pub mod args;
mod waker;

pub use waker::{Waker, WakerError};

/// How the task is driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Task {
    /// Every period (the default period; `--period` and `nerve rate` change it).
    Periodic(Duration),
    /// When an input arrives; never re-entered.
    EventDriven,
}

/// An error of an agent, with a message for the user.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    /// A port could not be made or used.
    #[error(transparent)]
    Port(#[from] PortError),
    /// Bad configuration (arguments, parameters).
    #[error("configuration: {0}")]
    Config(String),
    /// A call port could not be made or used.
    #[error(transparent)]
    Call(#[from] crate::port::call::CallError),
    /// An input's depth or policy is out of range (`setup.input_with`).
    #[error("input {input:?}: {source}")]
    InputOptions {
        /// the input
        input: String,
        /// what is wrong with its options
        #[source]
        source: crate::port::depth::OptionsError,
    },
    /// The agent's waker could not be made (`setup.waker()`).
    #[error(transparent)]
    Waker(#[from] WakerError),
    /// A device failed.
    #[error("device: {0}")]
    Device(String),
    /// Anything else.
    #[error("{0}")]
    Other(String),
}

/// The agent's algorithm. [`Agent::KIND`], [`Agent::task`], [`Agent::new`] and
/// [`Agent::step`] are required; every other hook has a default.
pub trait Agent: Sized + Send + 'static {
    /// The kind of agent, as shown by `nerve ps`.
    const KIND: &'static str;

    /// How the task is driven.
    fn task() -> Task;

    /// The kind the SDK reports: [`Agent::KIND`], unless the kind is only
    /// known at run time (a Python agent's class names it).
    fn kind() -> &'static str {
        Self::KIND
    }

    /// Creates the agent: declare its ports and parameters on `setup`. Open
    /// devices in [`Agent::start`], not here: `new` also runs for
    /// `--describe` (what `nerve launch` checks a launch file with), which
    /// must touch no device.
    fn new(setup: &mut Setup) -> Result<Self, AgentError>;

    /// Called once in the task thread before the first step: open devices
    /// here.
    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        Ok(())
    }

    /// One cycle of the task. Event-driven agents should drain their inputs
    /// ([`Context::woken_by`] says which have new samples).
    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError>;

    /// Called once in the task thread after the last step.
    fn stop(&mut self, _ctx: &mut Context) {}
}

/// What [`Agent::new`] gets: the place to declare ports and parameters.
///
/// Declaring is all `new` does: the same declarations serve a running
/// agent (ports bound to iceoryx2), `--describe` (bound to nothing, so
/// describing makes no shared memory) and a test
/// (the test harness, `testing::Harness`, ports bound to in-memory queues).
pub struct Setup {
    pub(crate) world: World,
    pub(crate) name: AgentName,
    pub(crate) binding: Binding,
    pub(crate) args: Vec<String>,
    pub(crate) inputs: Vec<Arc<dyn DynInput>>,
    pub(crate) outputs: Vec<PortSpec>,
    /// the schema of each type the ports carry, once per layout
    pub(crate) schemas: Vec<shm_schemas::Schema>,
    pub(crate) params: ParamTable,
    /// the services it answers and the clients it calls through (also in `inputs`, for wake-ups)
    pub(crate) calls: crate::port::call::Declared,
    /// the task's waker, once asked for ([`Setup::waker`])
    pub(crate) waker: Option<Waker>,
}

impl std::fmt::Debug for Setup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Setup").field("name", &self.name).field("outputs", &self.outputs).finish()
    }
}

impl Setup {
    /// A setup with no port or parameter declared yet.
    pub(crate) fn new(world: World, name: AgentName, binding: Binding, args: Vec<String>) -> Self {
        Setup {
            world,
            name,
            binding,
            args,
            inputs: Vec::new(),
            outputs: Vec::new(),
            schemas: Vec::new(),
            params: ParamTable::default(),
            calls: Default::default(),
            waker: None,
        }
    }

    /// The agent's name.
    pub fn name(&self) -> &str {
        self.name.as_str()
    }

    /// The robot's world (state directory, iceoryx2 configuration).
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The agent's own arguments (those after `--` on its command line)
    /// parsed into `T`, its `#[derive(clap::Parser)]` struct, as clap
    /// parses them; see [`crate::agent::args`]. A refusal is an [`AgentError::Config`]
    /// that names the agent, clap's reason and how to list the arguments.
    /// `--help` prints them and ends the process with status 0 (in a
    /// the test harness it is a refusal holding the help text).
    pub fn args<T: clap::Parser>(&self) -> Result<T, AgentError> {
        match args::parse::<T>(self.name(), &self.args) {
            Ok(t) => Ok(t),
            // `nerve-sonar -- --help` at a terminal: nothing of the agent
            // is registered yet (the router hears of it after `new`)
            Err(args::ArgsError::Help(help)) if !matches!(self.binding, Binding::Memory(_)) => {
                let _ = help.print();
                std::process::exit(0)
            }
            Err(e) => Err(AgentError::Config(e.to_string())),
        }
    }

    /// The agent's own arguments as given, unparsed (see [`Setup::args`]).
    pub fn raw_args(&self) -> &[String] {
        &self.args
    }

    /// Declares an output port.
    pub fn output<T: Payload>(&mut self, port: &str) -> Result<Output<T>, AgentError> {
        self.check_port(port)?;
        let service = self.world.robot().port_service(self.name.as_str(), port);
        let out = Output::bind(&self.binding, port, &service, self.name.as_str())?;
        self.outputs.push(PortSpec::of::<T>(port));
        add_schema(&mut self.schemas, T::schema());
        Ok(out)
    }

    /// Declares an input port holding `options.depth` samples per source,
    /// overwriting the oldest or keeping all ([`crate::port::InputOptions`],
    /// docs/inputs.md); a launch file's `depth`/`keep` for it wins.
    pub fn input_with<T: Payload>(
        &mut self,
        port: &str,
        options: crate::port::InputOptions,
    ) -> Result<Input<T>, AgentError> {
        let options = options.check().map_err(|source| AgentError::InputOptions { input: port.into(), source })?;
        self.check_port(port)?;
        let (input, inner) = Input::<T>::new(port)?;
        inner.depth.set(options);
        self.inputs.push(inner);
        add_schema(&mut self.schemas, T::schema());
        Ok(input)
    }

    /// Declares an input port; the router connects it to outputs.
    pub fn input<T: Payload>(&mut self, port: &str) -> Result<Input<T>, AgentError> {
        self.check_port(port)?;
        let (input, inner) = Input::<T>::new(port)?;
        self.inputs.push(inner);
        add_schema(&mut self.schemas, T::schema());
        Ok(input)
    }

    /// Declares an output port of variable-size samples: a header `H`, then
    /// any number of `T`, at most `max_len` of them ([`crate::port::seq`]).
    pub fn output_seq<T: SeqPart, H: SeqPart>(
        &mut self,
        port: &str,
        max_len: usize,
    ) -> Result<SeqOutput<T, H>, AgentError> {
        self.check_port(port)?;
        let service = self.world.robot().port_service(self.name.as_str(), port);
        let out = SeqOutput::bind(&self.binding, port, &service, self.name.as_str(), max_len)?;
        let schema = shm_schemas::Seq::<T, H>::schema();
        self.outputs.push(PortSpec {
            name: port.into(),
            type_name: schema.type_name.clone(),
            fingerprint: schema.fingerprint(),
        });
        add_schema(&mut self.schemas, schema);
        Ok(out)
    }

    /// Declares an input port of variable-size samples (see [`Setup::output_seq`]).
    pub fn input_seq<T: SeqPart, H: SeqPart>(&mut self, port: &str) -> Result<SeqInput<T, H>, AgentError> {
        self.check_port(port)?;
        let (input, inner) = SeqInput::<T, H>::new(port)?;
        self.inputs.push(inner);
        add_schema(&mut self.schemas, shm_schemas::Seq::<T, H>::schema());
        Ok(input)
    }

    /// Declares an output port of the payload layout `schema`, for an agent
    /// that learns its types at run time (a Python agent): the port is the
    /// one a [`Setup::output`] of a Rust type of that layout makes.
    pub fn output_of(&mut self, port: &str, schema: Schema) -> Result<SchemaOutput, AgentError> {
        self.check_port(port)?;
        let service = self.world.robot().port_service(self.name.as_str(), port);
        let out = SchemaOutput::declare(&self.binding, port, &service, self.name.as_str(), schema.clone())?;
        self.outputs.push(PortSpec {
            name: port.into(),
            type_name: schema.type_name.clone(),
            fingerprint: schema.fingerprint(),
        });
        add_schema(&mut self.schemas, schema);
        Ok(out)
    }

    /// Declares an input port of the payload layout `schema` (see
    /// [`Setup::output_of`]); the router connects it to outputs of that layout.
    pub fn input_of(&mut self, port: &str, schema: Schema) -> Result<SchemaInput, AgentError> {
        self.check_port(port)?;
        let (input, inner) = SchemaInput::new(port, schema.clone())?;
        self.inputs.push(inner);
        add_schema(&mut self.schemas, schema);
        Ok(input)
    }

    /// Declares service `port`: requests `Req` answered by `Resp`, in the
    /// agent's task, which a request wakes like an input (see [`crate::port::call`]).
    pub fn serve<Req: Payload, Resp: Payload>(
        &mut self,
        port: &str,
    ) -> Result<crate::port::Server<Req, Resp>, AgentError> {
        self.check_port(port)?;
        let service = self.world.robot().port_service(self.name.as_str(), port);
        let (server, inner) = crate::port::Server::bind(&self.binding, port, &service, 1)?;
        self.calls.add_service::<Req, crate::port::call::Fixed<Resp>>(port, &mut self.schemas);
        self.calls.add_memory(server.memory_port());
        self.inputs.push(inner);
        Ok(server)
    }

    /// Declares client `port` of a service of `Req` answered by `Resp`, with
    /// the default timeout and bound of calls in flight; the router wires it
    /// to a service (`nerve connect AGENT/PORT SERVER/SERVICE`).
    pub fn client<Req: Payload, Resp: Payload>(
        &mut self,
        port: &str,
    ) -> Result<crate::port::Client<Req, Resp>, AgentError> {
        self.client_with(port, crate::port::CallOptions::default())
    }

    /// [`Setup::client`] with its own timeout and bound of calls in flight.
    pub fn client_with<Req: Payload, Resp: Payload>(
        &mut self,
        port: &str,
        options: crate::port::CallOptions,
    ) -> Result<crate::port::Client<Req, Resp>, AgentError> {
        self.check_port(port)?;
        let (client, inner) = crate::port::Client::bind(&self.binding, port, options)?;
        self.calls.add_client::<Req, crate::port::call::Fixed<Resp>>(port, &mut self.schemas);
        self.calls.add_memory(client.memory_port());
        self.inputs.push(inner);
        Ok(client)
    }

    /// Declares service `port` answered with sequences: requests `Req`,
    /// answers of header `H` and at most `max_len` elements `T`
    /// ([`crate::port::call_seq`]).
    pub fn serve_seq<Req: Payload, T: SeqPart, H: SeqPart>(
        &mut self,
        port: &str,
        max_len: usize,
    ) -> Result<crate::port::SeqServer<Req, T, H>, AgentError> {
        self.check_port(port)?;
        let service = self.world.robot().port_service(self.name.as_str(), port);
        let (server, inner) = crate::port::SeqServer::bind(&self.binding, port, &service, max_len)?;
        self.calls.add_service::<Req, crate::port::call_seq::SeqAnswer<T, H>>(port, &mut self.schemas);
        self.calls.add_memory(server.memory_port());
        self.inputs.push(inner);
        Ok(server)
    }

    /// Declares client `port` of a service answered with sequences (see
    /// [`Setup::serve_seq`]), with the default timeout and bound of calls
    /// in flight.
    pub fn client_seq<Req: Payload, T: SeqPart, H: SeqPart>(
        &mut self,
        port: &str,
    ) -> Result<crate::port::SeqClient<Req, T, H>, AgentError> {
        self.client_seq_with(port, crate::port::CallOptions::default())
    }

    /// [`Setup::client_seq`] with its own timeout and bound of calls in flight.
    pub fn client_seq_with<Req: Payload, T: SeqPart, H: SeqPart>(
        &mut self,
        port: &str,
        options: crate::port::CallOptions,
    ) -> Result<crate::port::SeqClient<Req, T, H>, AgentError> {
        self.check_port(port)?;
        let (client, inner) = crate::port::SeqClient::bind(&self.binding, port, options)?;
        self.calls.add_client::<Req, crate::port::call_seq::SeqAnswer<T, H>>(port, &mut self.schemas);
        self.calls.add_memory(client.memory_port());
        self.inputs.push(inner);
        Ok(client)
    }

    /// Declares a parameter with a default value.
    pub fn param<T>(&mut self, key: &str, default: T) -> Param<T>
    where
        T: FromStr + Display + Send + 'static,
        T::Err: Display,
    {
        self.params.declare(key, default, None)
    }

    /// Declares a parameter whose values `check` must accept.
    pub fn param_checked<T>(
        &mut self,
        key: &str,
        default: T,
        check: impl Fn(&T) -> Result<(), String> + Send + Sync + 'static,
    ) -> Param<T>
    where
        T: FromStr + Display + Send + 'static,
        T::Err: Display,
    {
        self.params.declare(key, default, Some(Box::new(check)))
    }

    /// Reports read-only figures: `source` is called whenever they are read
    /// (`nerve param get`, `nerve ps`), from the message-checker thread, so
    /// it should only read counters the agent keeps (atomics, a short lock).
    pub fn figures(&mut self, source: impl Fn() -> Vec<(String, String)> + Send + Sync + 'static) {
        self.params.set_figures(Box::new(source));
    }

    /// The agent's [`Waker`]: another thread of the agent (a network
    /// session's callbacks, a device thread) calls [`Waker::wake`] and the
    /// event-driven task steps, with [`Context::woken_by_waker`] true, as
    /// it does when an input gets a sample. Every call returns the same
    /// waker (clone it for each thread). See [`Waker`]
    /// for what it promises and an example.
    pub fn waker(&mut self) -> Result<Waker, AgentError> {
        if let Some(w) = &self.waker {
            return Ok(w.clone());
        }
        let w = Waker::new()?;
        self.waker = Some(w.clone());
        Ok(w)
    }

    fn check_port(&self, port: &str) -> Result<(), AgentError> {
        validate_port_name(port).map_err(|e| AgentError::Config(e.to_string()))?;
        if self.outputs.iter().any(|p| p.name == port) || self.inputs.iter().any(|p| p.name() == port) {
            return Err(AgentError::Config(format!("port {port:?} is declared twice")));
        }
        Ok(())
    }
}

impl crate::params::Declare for Setup {
    fn checked<T>(&mut self, key: &str, default: T, check: fn(&T) -> Result<(), String>) -> Param<T>
    where
        T: FromStr + Display + Send + 'static,
        T::Err: Display,
    {
        self.param_checked(key, default, check)
    }
}

/// What [`Agent::step`] gets each cycle.
#[derive(Debug)]
pub struct Context {
    pub(crate) name: String,
    pub(crate) cycle: u64,
    pub(crate) now_ns: u64,
    pub(crate) period: Option<Duration>,
    /// the deadline this periodic step was woken for (0: event-driven)
    pub(crate) deadline_ns: u64,
    pub(crate) stop: bool,
    /// the input ports, in the order they were declared
    pub(crate) inputs: Vec<String>,
    /// per input (same order): whether it woke the task for this step
    pub(crate) woken: Vec<bool>,
    /// the agent's waker was woken since the last step ([`Setup::waker`])
    pub(crate) waker: bool,
}

impl Context {
    /// The agent's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// How many cycles ran before this one.
    pub fn cycle(&self) -> u64 {
        self.cycle
    }

    /// CLOCK_MONOTONIC ns at the start of this cycle.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// The current period of a periodic task.
    pub fn period(&self) -> Option<Duration> {
        self.period
    }

    /// The absolute deadline (CLOCK_MONOTONIC ns) this step of a periodic
    /// task was woken for; `now_ns() - deadline_ns()` is how late it woke.
    /// `None` for an event-driven task.
    pub fn deadline_ns(&self) -> Option<u64> {
        (self.deadline_ns != 0).then_some(self.deadline_ns)
    }

    /// The inputs whose new samples woke this step of an event-driven task
    /// (in the order they were declared): it need only read those. Samples
    /// that came while the agent was suspended count for the first step
    /// after it resumes. Empty for a periodic task, which is woken by its
    /// clock, and for a step run only because the agent resumed.
    pub fn woken_by(&self) -> impl Iterator<Item = &str> {
        self.inputs.iter().zip(&self.woken).filter(|(_, w)| **w).map(|(n, _)| n.as_str())
    }

    /// Whether input `input` has new samples that woke this step; see
    /// [`Context::woken_by`]. False for an input that is not declared.
    pub fn has_new(&self, input: &str) -> bool {
        self.inputs.iter().zip(&self.woken).any(|(n, w)| *w && n == input)
    }

    /// Whether the agent's [`Waker`] was woken since the last step (by
    /// another thread of the agent; see [`Setup::waker`]). Any number of
    /// wakes since then count as one. False for an agent without a waker.
    pub fn woken_by_waker(&self) -> bool {
        self.waker
    }

    /// Asks the SDK to stop the agent after this cycle.
    pub fn request_stop(&mut self) {
        self.stop = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn context(inputs: &[&str]) -> Context {
        Context {
            name: "t".into(),
            cycle: 0,
            now_ns: 0,
            period: None,
            deadline_ns: 0,
            stop: false,
            inputs: inputs.iter().map(|s| s.to_string()).collect(),
            woken: vec![false; inputs.len()],
            waker: false,
        }
    }

    #[test]
    fn the_step_knows_which_inputs_woke_it() {
        let mut ctx = context(&["scan", "pose", "goal"]);
        assert_eq!(ctx.woken_by().count(), 0);
        ctx.woken[0] = true;
        ctx.woken[2] = true;
        assert_eq!(ctx.woken_by().collect::<Vec<_>>(), ["scan", "goal"]);
        assert!(ctx.has_new("scan") && ctx.has_new("goal"));
        assert!(!ctx.has_new("pose"));
        assert!(!ctx.has_new("nonesuch"));
    }
}
