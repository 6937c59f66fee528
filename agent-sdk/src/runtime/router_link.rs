//! The agent's side of the router: registration at start, noticing a
//! (re)started router through its epoch and registering again, and leaving
//! on stop.

use super::Shared;
use crate::control::{ControlClient, ControlError, agent_router_client};
use crate::world::{Ipc, World};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use shm_schemas::ProtocolError;
use shm_schemas::control::agent_to_router::{AgentToRouter, Registration};
use shm_schemas::control::cli_to_router::{RouterError, RouterReply, RouterRequest};
use shm_schemas::payloads::RouterEpoch;
use std::sync::atomic::Ordering;
use std::time::Duration;

pub(super) enum RegisterError {
    NoRouter,
    Refused(RouterError),
    Other(String),
}

/// The agent's side of the router: registration, and noticing a restarted router.
pub(super) struct RouterLink {
    pub(super) client: Option<ControlClient<RouterRequest, RouterReply>>,
    pub(super) epoch: Option<Subscriber<Ipc, RouterEpoch, ()>>,
    pub(super) registered: Option<u64>,
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
        RouterLink { client: None, epoch: None, registered: None }
    }

    /// Subscribes to the router's epoch. Done after the first registration,
    /// which is on the path of a hot-add: the subscription keeps the latest
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
    }

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
        match client.call(&RouterRequest::Agent(AgentToRouter::Register(reg)), Duration::from_secs(3)) {
            Ok(RouterReply::Registered { epoch }) => {
                self.registered = Some(epoch);
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

    /// Re-registers when a router with a new epoch has started. Returns false
    /// when the router refuses this agent for good (its name was taken meanwhile).
    pub(super) fn poll(&mut self, node: &Node<Ipc>, world: &World, reg: &Registration, sh: &Shared) -> bool {
        let Some(sub) = &self.epoch else { return true };
        let mut newest = None;
        while let Ok(Some(s)) = sub.receive() {
            newest = Some(*s.payload());
        }
        let Some(e) = newest else { return true };
        if Some(e.epoch) == self.registered {
            return true;
        }
        match self.register(node, world, reg, sh) {
            Ok(()) => {
                tracing::info!("registered with the router (pid {})", e.pid);
                true
            }
            Err(RegisterError::Refused(err)) => {
                tracing::error!("the router refused this agent: {err}");
                false
            }
            Err(RegisterError::NoRouter) => true,
            Err(RegisterError::Other(err)) => {
                tracing::warn!("could not register with the router: {err}");
                true
            }
        }
    }

    pub(super) fn unregister(&mut self, name: &str) {
        if let (Some(client), Some(_)) = (&self.client, self.registered) {
            let msg = RouterRequest::Agent(AgentToRouter::Unregister { name: name.into(), pid: std::process::id() });
            if let Err(e) = client.call(&msg, Duration::from_millis(500)) {
                tracing::debug!("could not unregister: {e}");
            }
        }
    }
}
