//! Several agents wired together in the test's own process, on one fake
//! clock: a [`Wiring`].
//!
//! Each agent runs in a [`Harness`] of its own (its ports bound to
//! in-memory queues); the wiring connects an output of one to an input of
//! another as the router does (`nerve connect`), refusing what the router
//! refuses with the router's own message, and carries each sample sent to
//! every input connected to its output, with its sender, output port and
//! stamp.
//!
//! The order of things is fixed, so a test sees the same run every time:
//!
//! - the clock is one for all: [`Wiring::advance`] moves it from deadline
//!   to deadline of the periodic agents, the earliest first (at one
//!   instant, in the order the agents were added), and steps that agent;
//! - after every step, and after [`Wiring::send`], what outputs sent is
//!   carried to the inputs connected to them, and each event-driven agent
//!   that got a sample steps (the first added first), until none got any:
//!   a chain of event-driven agents settles at the instant the sample that
//!   started it was sent;
//! - an output connected to an input gives its samples to the inputs; one
//!   connected to none keeps them for [`Wiring::output`];
//! - a client connected to a service (`connect("a/planner", "b/plan")`)
//!   sends its calls there: a request wakes the server's agent, if
//!   event-driven, and its answer the client's, at the same instant; a
//!   client connected to none calls the test ([`Harness::requests`]), and
//!   one disconnected from its service is not wired (its calls refused).

use super::calls::{client_of, service_of};
use super::{Bus, Harness, HarnessBuilder, HarnessError, START_NS, sample_of, typed_input, typed_output};
use crate::agent::{Agent, AgentError};
use crate::port::bytes::DynInput;
use crate::port::call::memory::MemCallPort;
use shm_schemas::Payload;
use shm_schemas::control::cli_to_router::RouterError;
use std::any::Any;
use std::sync::Arc;
use std::time::Duration;

/// How many steps may run at one instant before the wiring gives up
/// ([`HarnessError::Unsettled`]): a loop of event-driven agents that each
/// send on every step would otherwise never settle.
const MAX_STEPS_PER_INSTANT: u64 = 10_000;

/// What the wiring needs of a [`Harness`], whatever its agent's type.
trait Member: Any {
    fn name(&self) -> &str;
    fn kind(&self) -> &'static str;
    /// 0 for an event-driven agent
    fn period_ns(&self) -> u64;
    fn next_deadline(&self) -> u64;
    fn suspended(&self) -> bool;
    fn set_clock(&mut self, ns: u64);
    /// a periodic agent starts its period at `ns`
    fn restart_period(&mut self, ns: u64);
    fn step(&mut self) -> Result<(), AgentError>;
    fn inputs(&self) -> &[Arc<dyn DynInput>];
    /// names, type names and fingerprints of the outputs
    fn outputs(&self) -> Vec<(String, String, Option<u64>)>;
    /// takes output `port`'s samples and queues them on `targets`
    fn forward(&self, port: &str, targets: &[Arc<dyn DynInput>]) -> Result<usize, String>;
    fn set_suspended(&mut self, suspended: bool);
    fn bus(&self) -> &Bus;
    fn calls(&self) -> &[MemCallPort];
    /// the agent's waker was woken ([`Harness::wake_pending`])
    fn wake_pending(&self) -> bool;
    fn as_any(&self) -> &dyn Any;
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

impl<A: Agent> Member for Harness<A> {
    fn name(&self) -> &str {
        &self.ctx.name
    }
    fn kind(&self) -> &'static str {
        A::kind()
    }
    fn period_ns(&self) -> u64 {
        self.period_ns
    }
    fn next_deadline(&self) -> u64 {
        Harness::next_deadline(self)
    }
    fn suspended(&self) -> bool {
        self.suspended
    }
    fn set_clock(&mut self, ns: u64) {
        Harness::set_clock(self, ns);
    }
    fn restart_period(&mut self, ns: u64) {
        self.last_ns = ns;
    }
    fn step(&mut self) -> Result<(), AgentError> {
        Harness::step(self)
    }
    fn inputs(&self) -> &[Arc<dyn DynInput>] {
        &self.inputs
    }
    fn outputs(&self) -> Vec<(String, String, Option<u64>)> {
        self.bus.outputs()
    }
    fn forward(&self, port: &str, targets: &[Arc<dyn DynInput>]) -> Result<usize, String> {
        let Ok((_, collected)) = self.bus.output(port) else { return Ok(0) };
        let taken = collected.take();
        for (header, sample) in &taken {
            for target in targets {
                target
                    .queue(header.sender.as_str(), port, sample.clone(), header.stamp_ns)
                    .map_err(|e| e.to_string())?;
            }
        }
        Ok(taken.len())
    }
    fn set_suspended(&mut self, suspended: bool) {
        self.suspended = suspended;
    }
    fn bus(&self) -> &Bus {
        &self.bus
    }
    fn calls(&self) -> &[MemCallPort] {
        self.call_ports()
    }
    fn wake_pending(&self) -> bool {
        Harness::wake_pending(self)
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// One connection: output `from_port` of agent `from` (an index into the
/// wiring's agents) to input `to_port` of agent `to`.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Link {
    from: usize,
    from_port: String,
    to: usize,
    to_port: String,
}

/// Several agents wired together on one fake clock; see the
/// [module](self) for the order of things.
///
/// ```
/// use agent_sdk::testing::{Harness, Wiring};
/// use agent_sdk::{Agent, AgentError, Context, Input, Output, Setup, Task};
/// use shm_schemas::payloads::Tick;
/// use std::time::Duration;
///
/// /// Sends a tick every 100 ms.
/// struct Ticker { out: Output<Tick> }
/// impl Agent for Ticker {
///     const KIND: &'static str = "ticker";
///     fn task() -> Task { Task::Periodic(Duration::from_millis(100)) }
///     fn new(setup: &mut Setup) -> Result<Self, AgentError> { Ok(Ticker { out: setup.output("tick")? }) }
///     fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
///         self.out.send(Tick { seq: ctx.cycle(), stamp_ns: ctx.now_ns() })?;
///         Ok(())
///     }
/// }
///
/// /// Passes what it gets on, when it gets it.
/// struct Relay { input: Input<Tick>, out: Output<Tick> }
/// impl Agent for Relay {
///     const KIND: &'static str = "relay";
///     fn task() -> Task { Task::EventDriven }
///     fn new(setup: &mut Setup) -> Result<Self, AgentError> {
///         Ok(Relay { input: setup.input("in")?, out: setup.output("out")? })
///     }
///     fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
///         self.input.try_drain(|_, t| self.out.send(*t))?;
///         Ok(())
///     }
/// }
///
/// let mut w = Wiring::new();
/// w.add::<Ticker>("t1").unwrap();
/// w.add_built(Harness::<Relay>::builder().name("r1")).unwrap();
/// w.connect("t1/tick", "r1/in").unwrap();
/// // 3 ticks, each relayed at once: 6 steps
/// assert_eq!(w.advance(Duration::from_millis(300)).unwrap(), 6);
/// let seqs: Vec<u64> = w.output::<Tick>("r1/out").unwrap().iter().map(|t| t.seq).collect();
/// assert_eq!(seqs, [0, 1, 2]);
///
/// // refused as the router refuses it
/// let e = w.connect("t1/tick", "r1/nope").unwrap_err().to_string();
/// assert!(e.contains("has no input port \"nope\""), "{e}");
///
/// w.disconnect("t1/tick", "r1/in").unwrap();
/// w.advance(Duration::from_millis(100)).unwrap();
/// assert!(w.output::<Tick>("r1/out").unwrap().is_empty());
/// assert_eq!(w.output::<Tick>("t1/tick").unwrap().len(), 1, "kept for the test");
/// ```
pub struct Wiring {
    members: Vec<Box<dyn Member>>,
    links: Vec<Link>,
    /// clients (`from`) wired to services (`to`)
    call_links: Vec<Link>,
    /// per agent: a sample came since its last step
    notified: Vec<bool>,
    now_ns: u64,
}

impl std::fmt::Debug for Wiring {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Wiring")
            .field("agents", &self.members.iter().map(|m| m.name().to_owned()).collect::<Vec<_>>())
            .field("links", &self.links)
            .field("now_ns", &self.now_ns)
            .finish()
    }
}

impl Default for Wiring {
    fn default() -> Self {
        Self::new()
    }
}

impl Wiring {
    /// No agents yet; the clock at 1 s, as a [`Harness`]'s.
    pub fn new() -> Self {
        Wiring {
            members: Vec::new(),
            links: Vec::new(),
            call_links: Vec::new(),
            notified: Vec::new(),
            now_ns: START_NS,
        }
    }

    /// Starts agent `A` named `name` with its own defaults and adds it.
    pub fn add<A: Agent>(&mut self, name: &str) -> Result<(), HarnessError> {
        self.add_built(Harness::<A>::builder().name(name))
    }

    /// Starts an agent as `builder` says (name, arguments, parameters,
    /// period, suspended) and adds it. Its clock is the wiring's; a
    /// periodic agent's first step comes one period after now.
    pub fn add_built<A: Agent>(&mut self, builder: HarnessBuilder<A>) -> Result<(), HarnessError> {
        let name = builder.name.clone().unwrap_or_else(|| A::kind().to_owned());
        if self.find(&name).is_some() {
            return Err(HarnessError::Duplicate { name });
        }
        let mut h = builder.start()?;
        Harness::set_clock(&mut h, self.now_ns);
        h.last_ns = self.now_ns;
        self.members.push(Box::new(h));
        self.notified.push(false);
        Ok(())
    }

    /// The clock all the agents see.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    fn find(&self, name: &str) -> Option<usize> {
        self.members.iter().position(|m| m.name() == name)
    }

    fn agent_index(&self, name: &str) -> Result<usize, HarnessError> {
        self.find(name).ok_or_else(|| {
            RouterError::UnknownAgent {
                name: name.into(),
                running: self.members.iter().map(|m| m.name().to_owned()).collect(),
            }
            .into()
        })
    }

    /// The harness of agent `name`, to look at its agent, parameters,
    /// statistics. What it is asked directly (its `step`, `advance`) runs
    /// outside the wiring.
    pub fn harness<A: Agent>(&self, name: &str) -> Result<&Harness<A>, HarnessError> {
        let m = &self.members[self.agent_index(name)?];
        m.as_any().downcast_ref::<Harness<A>>().ok_or_else(|| HarnessError::WrongAgent {
            name: name.into(),
            kind: m.kind(),
            asked: A::kind(),
        })
    }

    /// The harness of agent `name`, to set its parameters, suspend or
    /// resume it; see [`Wiring::harness`].
    pub fn harness_mut<A: Agent>(&mut self, name: &str) -> Result<&mut Harness<A>, HarnessError> {
        let i = self.agent_index(name)?;
        let kind = self.members[i].kind();
        self.members[i].as_any_mut().downcast_mut::<Harness<A>>().ok_or_else(|| HarnessError::WrongAgent {
            name: name.into(),
            kind,
            asked: A::kind(),
        })
    }

    /// Agent `name`, to look at its state.
    pub fn agent<A: Agent>(&self, name: &str) -> Result<&A, HarnessError> {
        Ok(self.harness::<A>(name)?.agent())
    }

    /// `AGENT/PORT` split, the agent's index and the port.
    fn port_ref<'a>(&self, given: &'a str) -> Result<(usize, &'a str), HarnessError> {
        let (agent, port) = given
            .split_once('/')
            .filter(|(a, p)| !a.is_empty() && !p.is_empty())
            .ok_or_else(|| HarnessError::PortRef { given: given.into() })?;
        Ok((self.agent_index(agent)?, port))
    }

    /// Output `port` of agent `i`: its type name and fingerprint, or the
    /// router's refusal.
    fn output_spec(&self, i: usize, port: &str) -> Result<(String, Option<u64>), HarnessError> {
        let outputs = self.members[i].outputs();
        match outputs.iter().find(|(p, ..)| p == port) {
            Some((_, type_name, fingerprint)) => Ok((type_name.clone(), *fingerprint)),
            None => Err(RouterError::UnknownPort {
                agent: self.members[i].name().into(),
                port: port.into(),
                direction: "output".into(),
                available: outputs.into_iter().map(|(p, ..)| p).collect(),
            }
            .into()),
        }
    }

    /// Input `port` of agent `i`, or the router's refusal.
    fn input(&self, i: usize, port: &str) -> Result<Arc<dyn DynInput>, HarnessError> {
        let inputs = self.members[i].inputs();
        inputs.iter().find(|p| p.name() == port).cloned().ok_or_else(|| {
            RouterError::UnknownPort {
                agent: self.members[i].name().into(),
                port: port.into(),
                direction: "input".into(),
                available: inputs.iter().map(|p| p.name().to_owned()).collect(),
            }
            .into()
        })
    }

    /// Connects output `from` to input `to` (both `AGENT/PORT`), as
    /// `nerve connect` does; connecting twice is one connection. Refused,
    /// with the router's message, for an unknown agent or port, another
    /// type, or one type name of two layouts.
    pub fn connect(&mut self, from: &str, to: &str) -> Result<(), HarnessError> {
        let link = self.link(from, to)?;
        if self.is_client(&link) {
            return self.connect_call(from, to, link);
        }
        let (type_name, fingerprint) = self.output_spec(link.from, &link.from_port)?;
        let spec = self.input(link.to, &link.to_port)?.spec();
        if type_name != spec.type_name {
            return Err(RouterError::TypeMismatch {
                from: from.into(),
                from_type: type_name,
                to: to.into(),
                to_type: spec.type_name,
            }
            .into());
        }
        if let Some(fp) = fingerprint.filter(|fp| spec.fingerprint != 0 && *fp != spec.fingerprint) {
            return Err(RouterError::LayoutMismatch {
                from: from.into(),
                to: to.into(),
                type_name,
                from_fingerprint: fp,
                to_fingerprint: spec.fingerprint,
                rebuild: "both are built into this test: declare the port with the payload type's own definition"
                    .into(),
            }
            .into());
        }
        if !self.links.contains(&link) {
            tracing::debug!(from, to, "wiring: connected");
            self.links.push(link);
        }
        Ok(())
    }

    /// Disconnects output `from` from input `to`, as `nerve disconnect`
    /// does. Samples already queued on the input stay there.
    pub fn disconnect(&mut self, from: &str, to: &str) -> Result<(), HarnessError> {
        let link = self.link(from, to)?;
        if let Some(at) = self.call_links.iter().position(|l| *l == link) {
            let client = client_of(self.members[link.from].calls(), &link.from_port)?;
            client.unwire(self.members[link.to].name(), &link.to_port);
            self.call_links.remove(at);
            tracing::debug!(from, to, "wiring: client unwired");
            return Ok(());
        }
        let Some(at) = self.links.iter().position(|l| *l == link) else {
            return Err(RouterError::NotConnected { from: from.into(), to: to.into() }.into());
        };
        self.links.remove(at);
        tracing::debug!(from, to, "wiring: disconnected");
        Ok(())
    }

    /// Whether `link` starts at a client port.
    fn is_client(&self, link: &Link) -> bool {
        self.members[link.from]
            .calls()
            .iter()
            .any(|c| matches!(c, MemCallPort::Client(_)) && c.name() == link.from_port)
    }

    /// Wires client `from` to service `to`, typed as the router types them.
    fn connect_call(&mut self, from: &str, to: &str, link: Link) -> Result<(), HarnessError> {
        let client = client_of(self.members[link.from].calls(), &link.from_port)?;
        let server_calls = self.members[link.to].calls();
        let service = service_of(server_calls, &link.to_port).map_err(|_| RouterError::UnknownPort {
            agent: self.members[link.to].name().into(),
            port: link.to_port.clone(),
            direction: "service".into(),
            available: server_calls
                .iter()
                .filter(|c| matches!(c, MemCallPort::Service(_)))
                .map(|c| c.name().to_owned())
                .collect(),
        })?;
        let (c, s) = (client.spec(), service.spec());
        if c.type_name != s.type_name {
            return Err(RouterError::TypeMismatch {
                from: from.into(),
                from_type: c.type_name.clone(),
                to: to.into(),
                to_type: s.type_name.clone(),
            }
            .into());
        }
        if c.fingerprint != 0 && s.fingerprint != 0 && c.fingerprint != s.fingerprint {
            return Err(RouterError::LayoutMismatch {
                from: from.into(),
                to: to.into(),
                type_name: c.type_name.clone(),
                from_fingerprint: c.fingerprint,
                to_fingerprint: s.fingerprint,
                rebuild: "both are built into this test: declare the port with the payload type's own definition"
                    .into(),
            }
            .into());
        }
        if !client.wire(self.members[link.to].name(), &link.to_port, service.clone().as_any()) {
            return Err(HarnessError::WrongType {
                port: to.into(),
                carries: format!("{} ({})", s.type_name, service.value_type().1),
                asked: client.value_type().1,
            });
        }
        // one service per client, as the router wires it
        self.call_links.retain(|l| !(l.from == link.from && l.from_port == link.from_port));
        tracing::debug!(from, to, "wiring: client wired");
        self.call_links.push(link);
        Ok(())
    }

    fn link(&self, from: &str, to: &str) -> Result<Link, HarnessError> {
        let (f, from_port) = self.port_ref(from)?;
        let (t, to_port) = self.port_ref(to)?;
        Ok(Link { from: f, from_port: from_port.into(), to: t, to_port: to_port.into() })
    }

    /// Queues `value` on input `to` (`AGENT/PORT`) from a sender called
    /// `test`, then lets the agents settle: the agent, if event-driven,
    /// steps, and so on down its connections. Returns how many steps ran.
    pub fn send<T: Payload>(&mut self, to: &str, value: T) -> Result<u64, HarnessError> {
        let (i, port) = self.port_ref(to)?;
        let input = self.input(i, port)?;
        typed_input::<T>(to, &input)?;
        input.queue("test", "out", sample_of(value)?, self.now_ns)?;
        self.notified[i] = true;
        self.settle()
    }

    /// Takes what output `from` (`AGENT/PORT`) sent since the last call
    /// and kept: an output connected to inputs gives its samples to them.
    pub fn output<T: Payload>(&mut self, from: &str) -> Result<Vec<T>, HarnessError> {
        let (i, port) = self.port_ref(from)?;
        self.output_spec(i, port)?;
        Ok(typed_output::<T>(self.members[i].bus(), port)?.into_iter().map(|(_, v)| v).collect())
    }

    /// Carries what the outputs sent to the inputs connected to them and
    /// marks the agents that got samples.
    fn deliver(&mut self) -> Result<(), HarnessError> {
        let mut done: Vec<(usize, &str)> = Vec::new();
        for link in &self.links {
            if done.contains(&(link.from, link.from_port.as_str())) {
                continue;
            }
            done.push((link.from, link.from_port.as_str()));
            let to: Vec<&Link> =
                self.links.iter().filter(|l| l.from == link.from && l.from_port == link.from_port).collect();
            let mut targets = Vec::with_capacity(to.len());
            for l in &to {
                let Some(input) = self.members[l.to].inputs().iter().find(|p| p.name() == l.to_port) else {
                    continue;
                };
                targets.push(input.clone());
            }
            let n =
                self.members[link.from].forward(&link.from_port, &targets).map_err(|reason| HarnessError::Forward {
                    from: format!("{}/{}", self.members[link.from].name(), link.from_port),
                    to: to.iter().map(|l| format!("{}/{}", self.members[l.to].name(), l.to_port)).collect(),
                    reason,
                })?;
            if n > 0 {
                for l in &to {
                    self.notified[l.to] = true;
                }
            }
        }
        Ok(())
    }

    /// Carries samples and steps the event-driven agents that got some (or
    /// whose waker was woken, [`Harness::wake_pending`]), the first added
    /// first, until none did. Returns how many steps ran.
    pub fn settle(&mut self) -> Result<u64, HarnessError> {
        let mut steps = 0;
        loop {
            self.deliver()?;
            for (m, notified) in self.members.iter().zip(&mut self.notified) {
                // every port looked at: each one's flag is cleared
                let woken = m.calls().iter().fold(false, |w, c| c.take_woken() | w);
                // a wake of the agent's waker steps it as a sample does
                *notified |= woken || m.wake_pending();
            }
            let next = self
                .members
                .iter()
                .zip(&self.notified)
                .position(|(m, notified)| *notified && m.period_ns() == 0 && !m.suspended());
            let Some(i) = next else {
                return Ok(steps);
            };
            self.notified[i] = false;
            if steps >= MAX_STEPS_PER_INSTANT {
                return Err(HarnessError::Unsettled { steps, at_ns: self.now_ns });
            }
            steps += 1;
            self.step(i)?;
        }
    }

    fn step(&mut self, i: usize) -> Result<(), HarnessError> {
        let m = &mut self.members[i];
        m.step().map_err(|source| HarnessError::Step { agent: m.name().to_owned(), source })
    }

    fn set_clock(&mut self, ns: u64) {
        self.now_ns = self.now_ns.max(ns);
        for m in &mut self.members {
            m.set_clock(self.now_ns);
        }
    }

    /// Moves the clock on by `by`: each periodic agent steps at each of its
    /// deadlines passed (the earliest first; at one instant, the first
    /// added first), and what it sends settles before the next. The first
    /// failed step ends the advance and is returned. Returns how many
    /// steps ran.
    pub fn advance(&mut self, by: Duration) -> Result<u64, HarnessError> {
        let until = self.now_ns.saturating_add(crate::clock::nanos(by));
        let mut steps = self.settle()?;
        loop {
            let next = self
                .members
                .iter()
                .enumerate()
                .filter(|(_, m)| m.period_ns() > 0 && !m.suspended())
                .map(|(i, m)| (m.next_deadline(), i))
                .min();
            let Some((deadline, i)) = next.filter(|(d, _)| *d <= until) else {
                break;
            };
            self.set_clock(deadline);
            self.step(i)?;
            steps += 1;
            steps += self.settle()?;
        }
        self.set_clock(until);
        Ok(steps)
    }

    /// Suspends agent `name` (`nerve suspend`): it does not step until
    /// resumed; samples for it wait on its inputs.
    pub fn suspend(&mut self, name: &str) -> Result<(), HarnessError> {
        let i = self.agent_index(name)?;
        let m = self.members[i].as_mut();
        if !m.suspended() {
            m.set_suspended(true);
        }
        Ok(())
    }

    /// Resumes agent `name` (`nerve resume`): an event-driven one steps at
    /// once if samples came meanwhile, a periodic one starts a period now.
    pub fn resume(&mut self, name: &str) -> Result<u64, HarnessError> {
        let i = self.agent_index(name)?;
        let now = self.now_ns;
        let m = self.members[i].as_mut();
        if !m.suspended() {
            return Ok(0);
        }
        m.set_suspended(false);
        m.restart_period(now);
        if m.period_ns() == 0 && m.inputs().iter().any(|p| p.has_queued()) {
            self.notified[i] = true;
        }
        self.settle()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::{Context, Setup, Task};
    use crate::{Input, Output};
    use shm_schemas::payloads::{Scalar, Tick};

    /// Sends a tick stamped with the clock at each period (100 ms by default).
    struct Ticker {
        out: Output<Tick>,
    }

    impl Agent for Ticker {
        const KIND: &'static str = "ticker";
        fn task() -> Task {
            Task::Periodic(Duration::from_millis(100))
        }
        fn new(setup: &mut Setup) -> Result<Self, AgentError> {
            Ok(Ticker { out: setup.output("tick")? })
        }
        fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
            self.out.send(Tick { seq: ctx.cycle(), stamp_ns: ctx.now_ns() })?;
            Ok(())
        }
    }

    /// Passes each tick on; remembers who sent what, and when it ran.
    /// Fails on a tick of seq 99.
    struct Relay {
        input: Input<Tick>,
        out: Output<Tick>,
        got: Vec<(String, u64, u64)>,
        steps_at: Vec<u64>,
    }

    impl Agent for Relay {
        const KIND: &'static str = "relay";
        fn task() -> Task {
            Task::EventDriven
        }
        fn new(setup: &mut Setup) -> Result<Self, AgentError> {
            Ok(Relay { input: setup.input("in")?, out: setup.output("out")?, got: Vec::new(), steps_at: Vec::new() })
        }
        fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
            self.steps_at.push(ctx.now_ns());
            let (got, out) = (&mut self.got, &self.out);
            self.input.try_drain(|meta, t| {
                if t.seq == 99 {
                    return Err(AgentError::Other("seq 99".into()));
                }
                got.push((meta.sender.as_str().to_owned(), t.seq, meta.stamp_ns));
                Ok(out.send(*t)?)
            })?;
            Ok(())
        }
    }

    /// Takes a scalar (to be connected wrongly).
    struct Gauge {
        _level: Input<Scalar>,
    }

    impl Agent for Gauge {
        const KIND: &'static str = "gauge";
        fn task() -> Task {
            Task::EventDriven
        }
        fn new(setup: &mut Setup) -> Result<Self, AgentError> {
            Ok(Gauge { _level: setup.input("level")? })
        }
        fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
            Ok(())
        }
    }

    const MS: u64 = 1_000_000;

    #[test]
    fn periodic_agents_step_on_one_clock_and_an_event_driven_one_when_a_sample_arrives() {
        let mut w = Wiring::new();
        w.add::<Ticker>("fast").expect("fast");
        w.add_built(Harness::<Ticker>::builder().name("slow").period(Duration::from_millis(150))).expect("slow");
        w.add::<Relay>("r1").expect("r1");
        w.add::<Relay>("r2").expect("r2");
        w.connect("fast/tick", "r1/in").expect("fast to r1");
        w.connect("slow/tick", "r1/in").expect("slow to r1");
        w.connect("r1/out", "r2/in").expect("r1 to r2");
        w.connect("r1/out", "r2/in").expect("twice is once");

        // fast at 100, 200, 300; slow at 150, 300 (fast first: added first);
        // each tick relayed twice at once
        assert_eq!(w.advance(Duration::from_millis(300)).expect("advance"), 15);
        assert_eq!(w.now_ns(), START_NS + 300 * MS);
        let r1 = w.agent::<Relay>("r1").expect("r1");
        let got: Vec<(&str, u64)> = r1.got.iter().map(|(s, seq, _)| (s.as_str(), *seq)).collect();
        assert_eq!(got, [("fast", 0), ("slow", 0), ("fast", 1), ("fast", 2), ("slow", 1)]);
        let at: Vec<u64> = r1.steps_at.iter().map(|t| (t - START_NS) / MS).collect();
        assert_eq!(at, [100, 150, 200, 300, 300], "stepped when each tick came, on the one clock");
        let stamps: Vec<u64> = r1.got.iter().map(|(_, _, stamp)| (stamp - START_NS) / MS).collect();
        assert_eq!(stamps, [100, 150, 200, 300, 300], "samples keep their stamps");
        // r2 got r1's samples as sent by r1, in the same order
        let r2 = w.agent::<Relay>("r2").expect("r2");
        let from_r1: Vec<(&str, u64)> = r2.got.iter().map(|(s, seq, _)| (s.as_str(), *seq)).collect();
        assert_eq!(from_r1, [("r1", 0), ("r1", 0), ("r1", 1), ("r1", 2), ("r1", 1)]);
        assert_eq!(w.output::<Tick>("r2/out").expect("r2 out").len(), 5, "unconnected: kept for the test");
        assert!(w.output::<Tick>("r1/out").expect("r1 out").is_empty(), "connected: given to r2");
        let stats = w.harness::<Relay>("r1").expect("r1").input_stats();
        let sources: Vec<_> = stats.iter().map(|s| (s.from_agent.as_str(), s.received)).collect();
        assert_eq!(sources, [("fast", 3), ("slow", 2)], "each output a source of its own");

        // a sample sent by the test settles at once
        assert_eq!(w.send("r1/in", Tick { seq: 7, stamp_ns: 0 }).expect("send"), 2);
        assert_eq!(w.output::<Tick>("r2/out").expect("r2 out")[0].seq, 7);

        // a step's error names the agent and ends the advance
        let e = w.send("r1/in", Tick { seq: 99, stamp_ns: 0 }).expect_err("seq 99").to_string();
        assert!(e.contains("\"r1\"") && e.contains("seq 99"), "{e}");
    }

    #[test]
    fn connections_change_at_run_time_and_a_suspended_agent_waits() {
        let mut w = Wiring::new();
        w.add::<Ticker>("t1").expect("t1");
        w.add::<Relay>("r1").expect("r1");
        w.connect("t1/tick", "r1/in").expect("connect");
        assert_eq!(w.advance(Duration::from_millis(100)).expect("advance"), 2);
        w.disconnect("t1/tick", "r1/in").expect("disconnect");
        let e = w.disconnect("t1/tick", "r1/in").expect_err("not connected").to_string();
        assert_eq!(e, "t1/tick is not connected to r1/in; see `nerve graph`");
        assert_eq!(w.advance(Duration::from_millis(200)).expect("advance"), 2, "the ticker alone");
        assert_eq!(w.output::<Tick>("t1/tick").expect("t1").len(), 2, "kept while unconnected");
        assert_eq!(w.agent::<Relay>("r1").expect("r1").got.len(), 1);

        // a suspended relay keeps the samples for when it resumes
        w.connect("t1/tick", "r1/in").expect("connect again");
        w.suspend("r1").expect("suspend");
        assert_eq!(w.advance(Duration::from_millis(200)).expect("advance"), 2, "the ticker alone");
        assert_eq!(w.resume("r1").expect("resume"), 1, "one step for both samples");
        let r1 = w.agent::<Relay>("r1").expect("r1");
        assert_eq!(r1.got.len(), 3);
        assert_eq!(r1.steps_at.last().copied(), Some(START_NS + 500 * MS), "stepped at resume");

        // a suspended ticker skips its deadlines; resumed, a period starts now
        w.suspend("t1").expect("suspend");
        assert_eq!(w.advance(Duration::from_millis(250)).expect("advance"), 0);
        assert_eq!(w.resume("t1").expect("resume"), 0);
        assert_eq!(w.advance(Duration::from_millis(99)).expect("advance"), 0);
        assert_eq!(w.advance(Duration::from_millis(1)).expect("advance"), 2);
    }

    #[test]
    fn a_wrong_connection_is_refused_with_the_routers_message() {
        let mut w = Wiring::new();
        w.add::<Ticker>("t1").expect("t1");
        w.add::<Gauge>("g1").expect("g1");
        let e = w.connect("t1/tick", "g1/level").expect_err("another type").to_string();
        let router = RouterError::TypeMismatch {
            from: "t1/tick".into(),
            from_type: "nerve::Tick".into(),
            to: "g1/level".into(),
            to_type: "nerve::Scalar".into(),
        };
        assert_eq!(e, router.to_string());
        assert_eq!(e, "cannot connect t1/tick to g1/level: t1/tick sends nerve::Tick but g1/level takes nerve::Scalar");
        let e = w.connect("t1/tock", "g1/level").expect_err("no output tock").to_string();
        assert!(e.contains("agent \"t1\" has no output port \"tock\"") && e.contains("tick"), "{e}");
        let e = w.connect("t1/tick", "g1/lvl").expect_err("no input lvl").to_string();
        assert!(e.contains("agent \"g1\" has no input port \"lvl\"") && e.contains("level"), "{e}");
        let e = w.connect("t2/tick", "g1/level").expect_err("no agent t2").to_string();
        assert!(e.contains("no agent named \"t2\"") && e.contains("t1"), "{e}");
        let e = w.connect("t1", "g1/level").expect_err("not AGENT/PORT").to_string();
        assert!(e.contains("AGENT/PORT"), "{e}");
        let e = w.add::<Gauge>("g1").expect_err("two g1").to_string();
        assert!(e.contains("already has an agent named \"g1\""), "{e}");
        let e = w.agent::<Relay>("g1").err().expect("g1 is a gauge").to_string();
        assert!(e.contains("gauge") && e.contains("relay"), "{e}");
        let e = w.send("g1/level", Tick::default()).expect_err("level takes Scalar").to_string();
        assert!(e.contains("nerve::Scalar") && e.contains("nerve::Tick"), "{e}");
        assert!(w.output::<Scalar>("t1/tick").is_err(), "tick carries Tick");
    }

    #[test]
    fn a_loop_of_event_driven_agents_that_never_settles_is_stopped_and_named() {
        let mut w = Wiring::new();
        w.add::<Relay>("a").expect("a");
        w.add::<Relay>("b").expect("b");
        w.connect("a/out", "b/in").expect("a to b");
        w.connect("b/out", "a/in").expect("b to a");
        let e = w.send("a/in", Tick::default()).expect_err("a loop");
        assert!(matches!(e, HarnessError::Unsettled { steps: MAX_STEPS_PER_INSTANT, .. }), "{e}");
        assert!(e.to_string().contains("disconnect one"), "{e}");
        // broken, the loop settles
        w.disconnect("b/out", "a/in").expect("disconnect");
        w.settle().expect("settles");
    }
}
