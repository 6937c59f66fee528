//! Following the router's event log (`CliRequest::Events`): what happened
//! in the graph since the last look (agents registered, left, died; edges
//! made and removed). Tools that react to the graph (`nerve record --all`,
//! the black box) ask for the events after the last one they saw, instead of
//! comparing `ps` listings every second: a `ps` asks every agent for its
//! statistics, and cannot tell a death from a clean stop.

use crate::control::{ControlClient, router_client};
use crate::world::{Ipc, World};
use iceoryx2::prelude::Node;
use shm_schemas::control::cli_to_router::{CliRequest, RouterEvent, RouterReply, RouterRequest};
use std::time::Duration;

/// How long a look may take (the router answers it at once).
const TIMEOUT: Duration = Duration::from_secs(2);

/// What a look found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Look {
    /// The events since the last look, oldest first.
    Events(Vec<RouterEvent>),
    /// The first look, or a router that started anew since the last one:
    /// what happened before is not known; look at the whole graph.
    Fresh,
    /// No router answered.
    NoRouter,
}

/// Follows one robot's router event log.
pub struct EventFollower {
    world: World,
    node: Node<Ipc>,
    client: Option<ControlClient<RouterRequest, RouterReply>>,
    /// (epoch, next event number) of the last look
    seen: Option<(u64, u64)>,
}

impl std::fmt::Debug for EventFollower {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EventFollower").field("seen", &self.seen).finish_non_exhaustive()
    }
}

impl EventFollower {
    /// Follows `world`'s router through `node`, a node of the caller's.
    pub fn new(world: &World, node: Node<Ipc>) -> EventFollower {
        EventFollower { world: world.clone(), node, client: None, seen: None }
    }

    /// What happened since the last look.
    pub fn look(&mut self) -> Look {
        if self.client.is_none() {
            self.client = router_client(&self.world, &self.node).ok();
        }
        let Some(client) = &self.client else { return Look::NoRouter };
        let after = self.seen.map_or(0, |(_, next)| next.saturating_sub(1));
        match client.call(&RouterRequest::Cli(CliRequest::Events { after }), TIMEOUT) {
            Ok(RouterReply::Events { epoch, next, events }) => {
                let fresh = self.seen.is_none_or(|(e, _)| e != epoch);
                self.seen = Some((epoch, next));
                if fresh { Look::Fresh } else { Look::Events(events) }
            }
            Ok(other) => {
                tracing::debug!("the router answered events with {other:?}");
                Look::NoRouter
            }
            Err(e) => {
                tracing::debug!("the router did not answer for its events: {e}");
                self.client = None;
                Look::NoRouter
            }
        }
    }
}
