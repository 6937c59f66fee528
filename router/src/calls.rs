//! Commands to agents, sent without waiting: the router never blocks on an
//! agent (reliability review R5, F2c).
//!
//! Each agent has a link: its control client, a queue of commands and at
//! most one command in flight, so that an agent sees its commands in the
//! order they were given. [`Calls::pump`] sends what is queued, collects
//! the replies that have come and times out the calls that waited too long;
//! the serving loop calls it on every pass. A hung agent therefore delays
//! its own commands only: `ps`, `connect` of other agents, registrations
//! and the liveness check go on.
//!
//! When a call to an agent times out, the commands queued behind it fail at
//! once with the same cause instead of waiting their own time-outs: an
//! agent that did not answer one command is not expected to answer the next.
//!
//! An agent that answered wakes the router with its reply id
//! ([`agent_sdk::control::reply_event_id`]); a pass given the ids that came
//! ([`Looks::Replied`]) looks only at the calls of those agents, so that
//! a `ps` of 100 agents costs a look per reply instead of a look at every
//! pending call on every pass. A full look ([`Looks::All`]) now and then
//! catches what no wake-up announces: time-outs, agents gone, a wake-up lost.

use agent_sdk::control::{ControlClient, ControlError, ControlSize, PendingCall};
use agent_sdk::world::{Ipc, World};
use iceoryx2::prelude::Node;
use shm_schemas::control::cli_to_router::RouterError;
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use shm_schemas::{AgentName, ProtocolError};
use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

/// How long the router waits for an agent's message checker to answer.
pub const AGENT_TIMEOUT: Duration = Duration::from_millis(1000);
/// How long it waits for statistics (for `ps` and `graph`; asked of every
/// agent at once).
pub const STATS_TIMEOUT: Duration = Duration::from_millis(300);

/// Names one command given to [`Calls::submit`]; its [`Outcome`] carries it.
pub type Ticket = u64;

/// How a command ended.
#[derive(Debug)]
pub struct Outcome {
    /// the command's ticket
    pub ticket: Ticket,
    /// the agent it was sent to
    pub agent: String,
    /// its reply, or why there is none
    pub result: Result<AgentReply, RouterError>,
}

#[derive(Debug)]
struct Queued {
    ticket: Ticket,
    cmd: AgentCommand,
    timeout: Duration,
}

#[derive(Debug)]
struct InFlight {
    queued: Queued,
    call: PendingCall<AgentReply>,
    sent: Instant,
    /// sent again through a reopened client already
    retried: bool,
}

#[derive(Debug, Default)]
struct Link {
    client: Option<ControlClient<AgentCommand, AgentReply>>,
    /// open the client afresh before the next send
    reopen: bool,
    queue: VecDeque<Queued>,
    in_flight: Option<InFlight>,
    /// the agent left while a command was pending: dropped once idle
    gone: bool,
}

/// Which calls in flight a [`Calls::pump`] looks at (queued commands are
/// always sent).
#[derive(Debug, Clone)]
pub enum Looks {
    /// every one: for time-outs, agents gone and wake-ups lost
    All,
    /// only those of agents whose reply id came
    Replied(ReplyIds),
}

/// A set of reply ids (1 to [`agent_sdk::control::REPLY_EVENT_IDS`]).
#[derive(Debug, Clone, Default)]
pub struct ReplyIds([u64; 4]);

impl ReplyIds {
    /// Adds `id`; ids out of range are ignored.
    pub fn insert(&mut self, id: usize) {
        if let Some(word) = self.0.get_mut(id / 64) {
            *word |= 1 << (id % 64);
        }
    }

    /// Whether `id` is in the set.
    pub fn contains(&self, id: usize) -> bool {
        self.0.get(id / 64).is_some_and(|w| w & (1 << (id % 64)) != 0)
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.0.iter().all(|w| *w == 0)
    }
}

// the set holds every id an agent can send
const _: () = assert!(agent_sdk::control::REPLY_EVENT_IDS < 4 * 64);

/// The router's commands to its agents.
#[derive(Debug, Default)]
pub struct Calls {
    links: BTreeMap<String, Link>,
    next: Ticket,
}

fn unreachable(name: &str, detail: impl Into<String>) -> RouterError {
    RouterError::AgentUnreachable { name: name.into(), detail: detail.into() }
}

fn outcome_of(name: &str, reply: AgentReply) -> Result<AgentReply, RouterError> {
    match reply {
        AgentReply::Error(message) => Err(RouterError::AgentRefused { name: name.into(), message }),
        reply => Ok(reply),
    }
}

impl Calls {
    /// Queues `cmd` for the agent `name`; its outcome comes from a later
    /// [`Calls::pump`], `timeout` after it is sent at the latest.
    pub fn submit(&mut self, name: &str, cmd: AgentCommand, timeout: Duration) -> Ticket {
        self.next = self.next.wrapping_add(1);
        let ticket = self.next;
        self.links.entry(name.to_owned()).or_default().queue.push_back(Queued { ticket, cmd, timeout });
        ticket
    }

    /// Queues `cmd` for the agent `name` under `ticket`, numbered by the
    /// caller (the router's core numbers the commands it asks for); its
    /// outcome comes as for [`Calls::submit`].
    pub fn queue(&mut self, ticket: Ticket, name: &str, cmd: AgentCommand, timeout: Duration) {
        self.links.entry(name.to_owned()).or_default().queue.push_back(Queued { ticket, cmd, timeout });
    }

    /// An agent of this name registered (again): its next command goes
    /// through a freshly opened client, bound to the new instance's service.
    pub fn registered(&mut self, name: &str) {
        if let Some(link) = self.links.get_mut(name) {
            link.reopen = true;
            link.gone = false;
        }
    }

    /// The agent is gone for good: drops its client once nothing is pending.
    pub fn left(&mut self, name: &str) {
        match self.links.get_mut(name) {
            Some(l) if l.in_flight.is_none() && l.queue.is_empty() => {
                self.links.remove(name);
            }
            // the reply to a `stop` comes after the agent said goodbye:
            // without this its client stayed for ever, one per agent that
            // ever stopped (found by the soak benchmark)
            Some(l) => l.gone = true,
            None => {}
        }
    }

    /// Whether a command is queued or waits for its reply.
    pub fn busy(&self) -> bool {
        self.links.values().any(|l| l.in_flight.is_some() || !l.queue.is_empty())
    }

    /// Whether a command waits for its reply (and not only in a queue).
    pub fn in_flight(&self) -> bool {
        self.links.values().any(|l| l.in_flight.is_some())
    }

    /// Sends what can be sent, collects replies and time-outs of the calls
    /// that `looks` names.
    pub fn pump(&mut self, world: &World, node: &Node<Ipc>, now: Instant, looks: &Looks) -> Vec<Outcome> {
        let mut out = Vec::new();
        for (name, link) in self.links.iter_mut() {
            if let (Looks::Replied(ids), Some(_)) = (looks, &link.in_flight)
                && !ids.contains(agent_sdk::control::reply_event_id(name))
            {
                continue;
            }
            // at most a few rounds: a reply, then the next command sent
            for _ in 0..4 {
                if !link.step(name, world, node, now, &mut out) {
                    break;
                }
            }
        }
        self.links.retain(|_, l| {
            let pending = l.in_flight.is_some() || !l.queue.is_empty();
            pending || (l.client.is_some() && !l.gone)
        });
        out
    }
}

impl Link {
    /// One step of this link; whether another may make progress.
    fn step(&mut self, name: &str, world: &World, node: &Node<Ipc>, now: Instant, out: &mut Vec<Outcome>) -> bool {
        if let Some(f) = self.in_flight.take() {
            match f.call.poll() {
                Ok(Some(reply)) => {
                    out.push(Outcome { ticket: f.queued.ticket, agent: name.into(), result: outcome_of(name, reply) });
                    return true;
                }
                Ok(None) if now.saturating_duration_since(f.sent) > f.queued.timeout => {
                    let detail = format!("no reply within {:?}", f.queued.timeout);
                    tracing::warn!(agent = name, command = ?f.queued.cmd, "the agent did not answer in time");
                    out.push(Outcome {
                        ticket: f.queued.ticket,
                        agent: name.into(),
                        result: Err(unreachable(name, &detail)),
                    });
                    for q in self.queue.drain(..) {
                        let detail = format!("it did not answer the command before this one ({detail})");
                        out.push(Outcome {
                            ticket: q.ticket,
                            agent: name.into(),
                            result: Err(unreachable(name, detail)),
                        });
                    }
                    return false;
                }
                Ok(None) => {
                    self.in_flight = Some(f);
                    return false;
                }
                Err(ControlError::NoServer { .. } | ControlError::Protocol(ProtocolError::Unanswered))
                    if matches!(f.queued.cmd, AgentCommand::Stop) =>
                {
                    // A stopping agent answers, then takes its control
                    // service down; the answer can be lost with it. Gone is
                    // what a stop asks for (found by the soak benchmark:
                    // `nerve stop` said "did not answer" of agents that had
                    // stopped). A hung agent keeps its service and times out.
                    tracing::info!(agent = name, "the agent's control service went away after a stop: it stopped");
                    out.push(Outcome { ticket: f.queued.ticket, agent: name.into(), result: Ok(AgentReply::Ok) });
                    return true;
                }
                Err(ControlError::NoServer { .. }) if !f.retried => {
                    // The client was opened while the agent's previous
                    // instance (same name) was still leaving, and may be bound
                    // to the service it tore down: open it afresh and try once
                    // more (seen about once in 40 hot-add/stop cycles).
                    self.reopen = true;
                    return self.send(name, f.queued, true, world, node, now, out);
                }
                Err(e) => {
                    out.push(Outcome {
                        ticket: f.queued.ticket,
                        agent: name.into(),
                        result: Err(unreachable(name, e.to_string())),
                    });
                    return true;
                }
            }
        }
        let Some(q) = self.queue.pop_front() else { return false };
        self.send(name, q, false, world, node, now, out)
    }

    #[allow(clippy::too_many_arguments)]
    fn send(
        &mut self,
        name: &str,
        q: Queued,
        retried: bool,
        world: &World,
        node: &Node<Ipc>,
        now: Instant,
        out: &mut Vec<Outcome>,
    ) -> bool {
        if self.reopen || self.client.is_none() {
            self.reopen = false;
            self.client = open(name, world, node);
        }
        let Some(client) = &self.client else {
            out.push(Outcome {
                ticket: q.ticket,
                agent: name.into(),
                result: Err(unreachable(name, "its control service is missing")),
            });
            return true;
        };
        match client.send(&q.cmd) {
            Ok(call) => {
                self.in_flight = Some(InFlight { queued: q, call, sent: now, retried });
                true
            }
            Err(ControlError::NoServer { .. }) if !retried => {
                self.reopen = true;
                self.send(name, q, true, world, node, now, out)
            }
            Err(e) => {
                out.push(Outcome {
                    ticket: q.ticket,
                    agent: name.into(),
                    result: Err(unreachable(name, e.to_string())),
                });
                true
            }
        }
    }
}

/// Opens the control client of `name`, cleaning up after dead processes
/// once if every client slot seems taken (some by tools that were killed).
fn open(name: &str, world: &World, node: &Node<Ipc>) -> Option<ControlClient<AgentCommand, AgentReply>> {
    let agent = AgentName::new(name).ok()?;
    let service = world.robot().ctl_service(&agent);
    let _reach = tracing::info_span!("reach", agent = name).entered();
    let blockable = |e: &ControlError| matches!(e, ControlError::Ipc { .. } | ControlError::Full { .. });
    let opened =
        agent_sdk::world::retry_after_cleanup(world.config(), "the agent's control service", blockable, || {
            ControlClient::open_reserved(node, &service, ControlSize::AGENT)
        });
    match opened {
        Ok(c) => Some(c),
        Err(e) => {
            tracing::warn!(agent = name, "cannot open the agent's control service: {e}");
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::control::{ControlServer, ControlSize};
    use shm_schemas::AgentName;

    /// Removes the test robot's files when dropped, even when the test fails.
    struct Files(World);

    impl Drop for Files {
        fn drop(&mut self) {
            for f in self.0.shm_files().into_iter().chain(self.0.iox2_files()) {
                let _ = std::fs::remove_file(f);
            }
        }
    }

    /// An agent's control service, and a `stop` the router sent to it.
    /// Fields drop in this order: the ports and nodes first, the files last.
    struct StopSent {
        server: Option<ControlServer<AgentCommand, AgentReply>>,
        agent: Option<Node<Ipc>>,
        calls: Calls,
        node: Node<Ipc>,
        ticket: Ticket,
        t0: Instant,
        world: World,
        _files: Files,
    }

    impl StopSent {
        fn new(tag: &str, name: &str) -> StopSent {
            let world = World::new(&format!("{tag}{}", std::process::id())).expect("world");
            let _files = Files(world.clone());
            let node = world.node("router").expect("node");
            let agent = world.node("agent").expect("agent node");
            let service = world.robot().ctl_service(&AgentName::new(name).expect("name"));
            let server = ControlServer::create(&agent, &service, ControlSize::AGENT).expect("server");
            let mut calls = Calls::default();
            let ticket = calls.submit(name, AgentCommand::Stop, Duration::from_secs(5));
            assert!(calls.pump(&world, &node, Instant::now(), &Looks::All).is_empty(), "sent, not answered yet");
            StopSent {
                world,
                _files,
                node,
                agent: Some(agent),
                server: Some(server),
                calls,
                ticket,
                t0: Instant::now(),
            }
        }

        fn server(&self) -> &ControlServer<AgentCommand, AgentReply> {
            self.server.as_ref().expect("the agent's service")
        }

        /// Pumps until the stop has an outcome.
        fn outcome(&mut self) -> Outcome {
            loop {
                assert!(self.t0.elapsed() < Duration::from_secs(5), "no outcome");
                let mut out = self.calls.pump(&self.world, &self.node, Instant::now(), &Looks::All);
                if let Some(o) = out.pop() {
                    assert_eq!(o.ticket, self.ticket);
                    return o;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    }

    #[test]
    fn an_agent_that_leaves_before_its_reply_has_its_client_dropped_after_it() {
        let mut s = StopSent::new("calls", "a1");
        // the agent says goodbye before it answers (as a stopping agent does)
        s.calls.left("a1");
        assert!(s.calls.links.contains_key("a1"), "kept while the reply is pending");
        while s.server().serve(|_| AgentReply::Ok).expect("serve") == 0 {
            assert!(s.t0.elapsed() < Duration::from_secs(5), "the stop never arrived");
            std::thread::sleep(Duration::from_millis(1));
        }
        s.outcome();
        assert!(!s.calls.links.contains_key("a1"), "the client of an agent that left is dropped once idle");
    }

    #[test]
    fn a_stop_whose_agent_went_away_before_its_answer_arrived_is_done() {
        let mut s = StopSent::new("callstop", "a2");
        // the agent goes away without an answer that arrives
        while s.server().receive().expect("receive").is_none() {
            assert!(s.t0.elapsed() < Duration::from_secs(5), "the stop never arrived");
            std::thread::sleep(Duration::from_millis(1));
        }
        s.server = None;
        s.agent = None;
        let o = s.outcome();
        assert!(matches!(o.result, Ok(AgentReply::Ok)), "{:?}", o.result);
    }

    #[test]
    fn a_pass_looks_only_at_the_calls_of_agents_that_said_they_replied() {
        use shm_schemas::control::cli_to_router::{RouterReply, RouterRequest};
        let mut s = StopSent::new("callwake", "a3");
        // the router's own service, which an agent wakes with its reply id
        let router: ControlServer<RouterRequest, RouterReply> =
            ControlServer::create(&s.node, &s.world.robot().router_service(), ControlSize::ROUTER)
                .expect("router service");
        let agent = s.agent.as_ref().expect("agent node");
        let to_router = agent_sdk::control::agent_router_client::<RouterRequest, RouterReply>(&s.world, agent)
            .expect("the agent's client of the router");
        while s.server().serve(|_| AgentReply::Ok).expect("serve") == 0 {
            assert!(s.t0.elapsed() < Duration::from_secs(5), "the stop never arrived");
            std::thread::sleep(Duration::from_millis(1));
        }
        // answered, but nothing said so: a pass given other ids skips it
        let mut other = ReplyIds::default();
        let mine = agent_sdk::control::reply_event_id("a3");
        other.insert(if mine == 1 { 2 } else { 1 });
        assert!(s.calls.pump(&s.world, &s.node, Instant::now(), &Looks::Replied(other)).is_empty());
        assert!(s.calls.in_flight(), "still in flight");
        // the agent says so; the router's wake-ups carry its id
        to_router.notify_replied(mine).expect("notify");
        let mut ids = ReplyIds::default();
        router.take_wakeups(|id| ids.insert(id));
        assert!(ids.contains(mine) && !ids.is_empty(), "the reply id came");
        let out = s.calls.pump(&s.world, &s.node, Instant::now(), &Looks::Replied(ids));
        assert_eq!(out.len(), 1, "{out:?}");
        assert!(matches!(out[0].result, Ok(AgentReply::Ok)), "{:?}", out[0].result);
        assert!(!s.calls.in_flight());
    }

    #[test]
    fn reply_ids_are_a_set_of_the_ids_agents_send() {
        let mut ids = ReplyIds::default();
        assert!(ids.is_empty());
        for id in [1, 63, 64, 200, agent_sdk::control::REPLY_EVENT_IDS] {
            ids.insert(id);
            assert!(ids.contains(id));
        }
        assert!(!ids.contains(2) && !ids.contains(65));
        ids.insert(10_000); // out of range: ignored, never a panic
        assert!(!ids.contains(10_000));
        for name in ["a", "t1", "r1", "sonar", "a-very-long-agent-name-0123456789"] {
            let id = agent_sdk::control::reply_event_id(name);
            assert!((1..=agent_sdk::control::REPLY_EVENT_IDS).contains(&id), "{name}: {id}");
            assert_eq!(id, agent_sdk::control::reply_event_id(name), "the same name, the same id");
        }
    }
}
