//! The agent's side of the router: registration at start, noticing a
//! (re)started router through its epoch and registering again, and leaving
//! on stop.
//!
//! The link registers whenever the latest router epoch it has seen differs
//! from the epoch of the router that accepted it ([`Registrar`]): a new
//! router is registered with at once, and an attempt that failed (a router
//! busy starting, a timed-out reply) is retried with back-off, so one lost
//! reply never leaves the agent unknown to the router until its next restart.

use super::Shared;
use crate::control::{ControlClient, ControlError, agent_router_client};
use crate::world::{Ipc, World};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use shm_schemas::ProtocolError;
use shm_schemas::control::agent_to_router::{AgentToRouter, Registration};
use shm_schemas::control::cli_to_router::{RouterError, RouterReply, RouterRequest};
use shm_schemas::control::router_to_agent::AgentCommand;
use shm_schemas::payloads::RouterEpoch;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// How long the router has to answer a registration.
const REGISTER_TIMEOUT: Duration = Duration::from_secs(3);

/// Why a registration did not happen.
pub(super) enum RegisterError {
    /// No router serves the robot.
    NoRouter,
    /// The router refused this agent for good (its name is taken).
    Refused(RouterError),
    /// Anything else (a timeout, a protocol mismatch); worth another try.
    Other(String),
}

/// The first wait before trying to register again after a failed attempt.
const RETRY_FIRST: Duration = Duration::from_millis(250);
/// The longest wait between two attempts.
const RETRY_MAX: Duration = Duration::from_secs(8);

/// When to register: the decision of the link, apart from iceoryx2.
///
/// Registering is due while the latest epoch seen differs from the one the
/// agent is registered under; after a failed attempt, not before a back-off
/// (doubling from [`RETRY_FIRST`] to [`RETRY_MAX`]) has passed. A new epoch
/// makes it due at once.
#[derive(Debug)]
struct Registrar {
    /// the newest epoch published by a router
    latest: Option<u64>,
    /// the epoch of the router that accepted this agent
    registered: Option<u64>,
    /// no attempt before this
    retry_at: Option<Instant>,
    /// the wait after the next failed attempt
    backoff: Duration,
}

impl Registrar {
    fn new() -> Self {
        Registrar { latest: None, registered: None, retry_at: None, backoff: RETRY_FIRST }
    }

    /// A router announced `epoch`.
    fn seen(&mut self, epoch: u64) {
        if self.latest != Some(epoch) {
            self.latest = Some(epoch);
            self.retry_at = None;
            self.backoff = RETRY_FIRST;
        }
    }

    /// When the next attempt is due: `None` while registered with the
    /// latest router (or before any router was seen).
    fn next_attempt(&self, now: Instant) -> Option<Instant> {
        match self.latest {
            Some(latest) if self.registered != Some(latest) => Some(self.retry_at.unwrap_or(now)),
            _ => None,
        }
    }

    fn due(&self, now: Instant) -> bool {
        self.next_attempt(now).is_some_and(|at| at <= now)
    }

    /// A router of `epoch` accepted this agent.
    fn accepted(&mut self, epoch: u64, now: Instant) {
        self.registered = Some(epoch);
        if self.latest.is_some_and(|latest| latest != epoch) {
            // an older router answered: try the newest again, but not at once
            self.failed(now);
        } else {
            self.retry_at = None;
            self.backoff = RETRY_FIRST;
        }
    }

    /// An attempt failed at `now`: wait before the next one.
    fn failed(&mut self, now: Instant) {
        self.retry_at = Some(now + self.backoff);
        self.backoff = (self.backoff * 2).min(RETRY_MAX);
    }
}

/// The agent's side of the router: registration, and noticing a restarted router.
pub(super) struct RouterLink {
    client: Option<ControlClient<RouterRequest, RouterReply>>,
    epoch: Option<Subscriber<Ipc, RouterEpoch, ()>>,
    /// wakes the message checker when a router publishes a new epoch
    epoch_wake: Option<Listener<Ipc>>,
    /// the pid of the newest router seen, for the log
    router_pid: Option<u32>,
    registrar: Registrar,
    /// what the last accepted registration asked to carry out at once
    first: Vec<AgentCommand>,
}

// every agent the router serves must be able to watch its epoch
const _: () = assert!(
    shm_schemas::services::EPOCH_MAX_SUBSCRIBERS >= crate::control::ControlSize::ROUTER.max_clients
        && shm_schemas::services::EPOCH_MAX_NODES >= crate::control::ControlSize::ROUTER.max_nodes
);

/// Opens the router's epoch service (publish-subscribe, history 1), as
/// defined once for the router and every agent in
/// [`shm_schemas::services::router_epoch`].
pub fn epoch_service(
    node: &Node<Ipc>,
    world: &World,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, RouterEpoch, ()>, String> {
    shm_schemas::services::router_epoch(node, world.robot()).map_err(|e| e.to_string())
}

impl RouterLink {
    pub(super) fn new() -> Self {
        RouterLink {
            client: None,
            epoch: None,
            epoch_wake: None,
            router_pid: None,
            registrar: Registrar::new(),
            first: Vec::new(),
        }
    }

    /// What the router's last accepted registration asked to carry out at
    /// once (the connections of this agent's inputs), taken once.
    pub(super) fn take_first(&mut self) -> Vec<AgentCommand> {
        std::mem::take(&mut self.first)
    }

    /// Takes a client of the router's service opened beforehand (the
    /// start-up opens it beside its other set-up).
    pub(super) fn adopt_client(&mut self, client: ControlClient<RouterRequest, RouterReply>) {
        self.client = Some(client);
    }

    /// Subscribes to the router's epoch. Done by the message checker once it
    /// has served the connections the router sent at registration, which
    /// are on the path of a hot-add: the subscription keeps the latest
    /// epoch (history 1), so a router that restarted in between is still
    /// noticed by the next [`RouterLink::poll`].
    pub(super) fn watch_epoch(&mut self, world: &World, node: &Node<Ipc>) {
        self.epoch = match epoch_service(node, world) {
            Ok(f) => f.subscriber_builder().buffer_size(1).history_request(1).create().ok(),
            Err(e) => {
                tracing::warn!("{e}; a restarted router will not be noticed");
                None
            }
        };
        self.epoch_wake = match shm_schemas::services::router_epoch_event(node, world.robot()) {
            Ok(f) => f.listener_builder().create().ok(),
            Err(e) => {
                tracing::warn!("{e}; a restarted router is noticed at the next housekeeping tick");
                None
            }
        };
    }

    /// The listener that wakes when a router publishes a new epoch, for the
    /// message checker's WaitSet (taken once).
    pub(super) fn take_epoch_wake(&mut self) -> Option<Listener<Ipc>> {
        self.epoch_wake.take()
    }

    /// Registers `reg` with the router. A registration too large for the
    /// router's service (an agent with very many port types) is sent again
    /// without its schemas rather than not at all.
    pub(super) fn register(
        &mut self,
        node: &Node<Ipc>,
        world: &World,
        reg: &Registration,
        sh: &Shared,
    ) -> Result<(), RegisterError> {
        if self.client.is_none() {
            match agent_router_client(world, node) {
                Ok(c) => self.client = Some(c),
                Err(ControlError::NoServer { .. }) => return Err(RegisterError::NoRouter),
                Err(e) => return Err(RegisterError::Other(e.to_string())),
            }
        }
        let Some(client) = &self.client else { return Err(RegisterError::NoRouter) };
        let mut reg = reg.clone();
        reg.suspended = sh.suspended.load(Ordering::Acquire);
        let p = sh.period_ns.load(Ordering::Acquire);
        reg.period_ns = (p > 0).then_some(p);
        let mut answer = client.call(&RouterRequest::Agent(AgentToRouter::Register(reg.clone())), REGISTER_TIMEOUT);
        if let Err(ControlError::TooLarge { bytes, max, .. }) = &answer
            && !reg.schemas.is_empty()
        {
            // the ports still carry their fingerprints (stale builds are
            // still refused); only tools lose the schemas to decode them with
            tracing::warn!(
                bytes,
                max,
                "the registration with its {} schemas is too large for the router's service; registering without them (`nerve echo` cannot decode these ports)",
                reg.schemas.len()
            );
            reg.schemas.clear();
            answer = client.call(&RouterRequest::Agent(AgentToRouter::Register(reg)), REGISTER_TIMEOUT);
        }
        match answer {
            Ok(RouterReply::Registered { epoch, first }) => {
                self.registrar.accepted(epoch, Instant::now());
                self.first = first;
                Ok(())
            }
            Ok(RouterReply::Error(e)) => Err(RegisterError::Refused(e)),
            Ok(other) => Err(RegisterError::Other(format!("unexpected reply {other:?}"))),
            Err(ControlError::NoServer { .. }) => Err(RegisterError::NoRouter),
            Err(ControlError::Protocol(e @ ProtocolError::VersionMismatch { .. })) => {
                Err(RegisterError::Other(e.to_string()))
            }
            Err(e) => Err(RegisterError::Other(e.to_string())),
        }
    }

    /// Tells the router that this agent (event id `reply_id`, see
    /// [`crate::control::reply_event_id`]) answered a request, so that it
    /// picks the reply up at once instead of at its next look. Best effort:
    /// a router that misses it finds the reply at that look.
    pub(super) fn replied(&self, reply_id: usize) {
        if let Some(client) = &self.client
            && let Err(e) = client.notify_replied(reply_id)
        {
            tracing::debug!("cannot wake the router after a reply: {e}");
        }
    }

    /// Whether a router accepted this agent.
    pub(super) fn is_registered(&self) -> bool {
        self.registrar.registered.is_some()
    }

    /// When [`RouterLink::poll`] next has an attempt to make, if one is pending.
    pub(super) fn next_attempt(&self) -> Option<Instant> {
        self.registrar.next_attempt(Instant::now())
    }

    /// Reads the newest router epoch and registers when that is due (a new
    /// router, or a failed attempt whose back-off has passed). Returns false
    /// when the router refuses this agent for good (its name was taken
    /// meanwhile).
    pub(super) fn poll(&mut self, node: &Node<Ipc>, world: &World, reg: &Registration, sh: &Shared) -> bool {
        if let Some(sub) = &self.epoch {
            while let Ok(Some(s)) = sub.receive() {
                self.registrar.seen(s.epoch);
                self.router_pid = Some(s.pid);
            }
        }
        if !self.registrar.due(Instant::now()) {
            return true;
        }
        match self.register(node, world, reg, sh) {
            Ok(()) => {
                let pid = self.router_pid.map_or_else(|| "?".to_owned(), |p| p.to_string());
                tracing::info!(router_pid = ?self.router_pid, epoch = ?self.registrar.registered, "registered with the router (pid {pid})");
                true
            }
            Err(RegisterError::Refused(err)) => {
                tracing::error!(%err, "the router refused this agent");
                false
            }
            Err(RegisterError::NoRouter) => {
                self.registrar.failed(Instant::now());
                tracing::debug!(retry_at = ?self.registrar.retry_at, "no router to register with");
                true
            }
            Err(RegisterError::Other(err)) => {
                self.registrar.failed(Instant::now());
                tracing::warn!(%err, backoff = ?self.registrar.backoff, "could not register with the router; will retry");
                true
            }
        }
    }

    pub(super) fn unregister(&mut self, name: &str) {
        if let (Some(client), Some(_)) = (&self.client, self.registrar.registered) {
            let msg = RouterRequest::Agent(AgentToRouter::Unregister { name: name.into(), pid: std::process::id() });
            if let Err(e) = client.call(&msg, Duration::from_millis(500)) {
                tracing::debug!("could not unregister: {e}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(t0: Instant, ms: u64) -> Instant {
        t0 + Duration::from_millis(ms)
    }

    #[test]
    fn nothing_is_due_before_a_router_was_seen() {
        let r = Registrar::new();
        let t0 = Instant::now();
        assert_eq!(r.next_attempt(t0), None);
        assert!(!r.due(t0));
    }

    #[test]
    fn a_new_router_is_registered_with_at_once_and_only_once() {
        let t0 = Instant::now();
        let mut r = Registrar::new();
        r.seen(1);
        assert!(r.due(t0));
        r.accepted(1, t0);
        assert!(!r.due(at(t0, 60_000)));
        r.seen(1); // the same epoch read again
        assert!(!r.due(at(t0, 60_000)));
        r.seen(2); // a restarted router
        assert!(r.due(t0));
    }

    #[test]
    fn a_failed_attempt_is_retried_with_growing_back_off() {
        let t0 = Instant::now();
        let mut r = Registrar::new();
        r.seen(1);
        r.failed(t0);
        assert!(!r.due(at(t0, 249)));
        assert!(r.due(at(t0, 250)));
        let mut now = at(t0, 250);
        let mut waits = Vec::new();
        for _ in 0..8 {
            r.failed(now);
            let next = r.next_attempt(now).expect("still due");
            waits.push((next - now).as_millis());
            now = next;
        }
        assert_eq!(waits, [500, 1000, 2000, 4000, 8000, 8000, 8000, 8000]);
        r.accepted(1, now);
        assert_eq!(r.next_attempt(now), None);
    }

    #[test]
    fn a_new_router_during_back_off_is_tried_at_once() {
        let t0 = Instant::now();
        let mut r = Registrar::new();
        r.seen(1);
        for _ in 0..5 {
            r.failed(t0);
        }
        assert!(!r.due(at(t0, 1000)));
        r.seen(2);
        assert!(r.due(t0));
        r.failed(t0);
        assert_eq!(r.next_attempt(t0), Some(at(t0, 250)), "a new router restarts the back-off");
    }

    #[test]
    fn an_answer_from_an_older_router_is_retried_not_spun_on() {
        let t0 = Instant::now();
        let mut r = Registrar::new();
        r.seen(2);
        r.accepted(1, t0);
        assert!(!r.due(t0), "not again at once");
        assert!(r.due(at(t0, 250)));
        r.accepted(2, at(t0, 250));
        assert_eq!(r.next_attempt(at(t0, 250)), None);
    }

    #[test]
    fn registered_at_start_before_the_epoch_was_read() {
        let t0 = Instant::now();
        let mut r = Registrar::new();
        r.accepted(5, t0);
        r.seen(5);
        assert!(!r.due(t0));
    }
}
