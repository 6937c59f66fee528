//! The command line's connection to the router of a robot.

use agent_sdk::control::{ControlClient, ControlError, router_client};
use agent_sdk::world::{Ipc, World};
use anyhow::{Context as _, Result, anyhow, bail};
use iceoryx2::prelude::Node;
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply, RouterRequest};
use std::time::Duration;

/// A command-line session with a robot's router.
pub struct RouterSession {
    pub world: World,
    node: Node<Ipc>,
    client: ControlClient<RouterRequest, RouterReply>,
}

/// How long a command waits for the router (which may itself wait for an agent).
pub const ROUTER_TIMEOUT: Duration = Duration::from_secs(10);

pub fn cli_node(world: &World) -> Result<Node<Ipc>> {
    world.node(&format!("cli-{}", std::process::id())).context("cannot join the robot's shared memory")
}

impl RouterSession {
    pub fn open(world: &World) -> Result<Self> {
        let node = cli_node(world)?;
        let client = router_client(world, &node).map_err(|e| no_router(world, e))?;
        Ok(RouterSession { world: world.clone(), node, client })
    }

    /// The session's iceoryx2 node (ports a command makes beside its session).
    pub fn node(&self) -> &Node<Ipc> {
        &self.node
    }

    /// Sends a request; a refusal becomes an error with the router's message.
    pub fn call(&self, req: CliRequest) -> Result<RouterReply> {
        match self.client.call(&RouterRequest::Cli(req), ROUTER_TIMEOUT) {
            Ok(RouterReply::Error(e)) => Err(anyhow!(e)),
            Ok(reply) => Ok(reply),
            Err(e) => Err(no_router(&self.world, e)),
        }
    }

    pub fn ok(&self, req: CliRequest) -> Result<()> {
        match self.call(req)? {
            RouterReply::Ok => Ok(()),
            other => bail!("unexpected reply from the router: {other:?}"),
        }
    }
}

pub fn no_router(world: &World, e: ControlError) -> anyhow::Error {
    match e {
        ControlError::NoServer { .. } => anyhow!(
            "no router runs for robot {r}; start one with `nerve --robot {r} router --daemon` (or `nerve launch FILE`)",
            r = world.robot()
        ),
        e => anyhow!(e),
    }
}
