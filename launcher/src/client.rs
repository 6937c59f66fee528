//! The command line's connection to the router of a robot.

use agent_sdk::control::{ControlClient, ControlError, ToolConnection, router_client};
use agent_sdk::world::{Ipc, World};
use anyhow::{Context as _, Result, anyhow, bail};
use iceoryx2::prelude::Node;
use shm_schemas::control::cli_to_router::{CliRequest, RouterError, RouterReply, RouterRequest};
use std::cell::{OnceCell, RefCell};
use std::time::Duration;

/// A command-line session with a robot's router.
///
/// It talks to the router over the router's socket for tools
/// ([`agent_sdk::control::ToolSocket`]): a command that only asks the router
/// makes no iceoryx2 node, port or shared memory. Where nothing listens on
/// that socket (a router that could not make it), or with
/// `NERVE_TOOL_SOCKET=off` in the environment, it uses the router's
/// iceoryx2 service for tools, as every command did before. A command that
/// needs ports of its own beside the session makes its node with
/// [`RouterSession::node`].
pub struct RouterSession {
    pub world: World,
    /// the connection `open` made to the socket, for the first call; later
    /// calls connect again (one request per connection)
    first: RefCell<Option<ToolConnection>>,
    node: OnceCell<Node<Ipc>>,
    /// the iceoryx2 client, where the socket is not used
    client: Option<ControlClient<RouterRequest, RouterReply>>,
}

/// How long a command waits for the router (which may itself wait for an agent).
pub const ROUTER_TIMEOUT: Duration = Duration::from_secs(10);

pub fn cli_node(world: &World) -> Result<Node<Ipc>> {
    world.node(&format!("cli-{}", std::process::id())).context("cannot join the robot's shared memory")
}

/// Whether `NERVE_TOOL_SOCKET=off` asks commands to use iceoryx2 alone.
fn socket_wanted() -> bool {
    std::env::var_os("NERVE_TOOL_SOCKET").is_none_or(|v| v != "off")
}

impl RouterSession {
    /// Opens a session; fails with "no router runs" where none does.
    pub fn open(world: &World) -> Result<Self> {
        if socket_wanted() {
            match ToolConnection::connect(&world.tool_socket()) {
                Ok(c) => {
                    return Ok(RouterSession {
                        world: world.clone(),
                        first: RefCell::new(Some(c)),
                        node: OnceCell::new(),
                        client: None,
                    });
                }
                Err(e) => tracing::debug!(error = %e, "no router on the tool socket; trying iceoryx2"),
            }
        }
        let node = cli_node(world)?;
        let client = router_client(world, &node).map_err(|e| no_router(world, e))?;
        Ok(RouterSession {
            world: world.clone(),
            first: RefCell::new(None),
            node: OnceCell::from(node),
            client: Some(client),
        })
    }

    /// The session's iceoryx2 node (ports a command makes beside its
    /// session), made on first use.
    pub fn node(&self) -> Result<&Node<Ipc>> {
        if let Some(n) = self.node.get() {
            return Ok(n);
        }
        let n = cli_node(&self.world)?;
        Ok(self.node.get_or_init(|| n))
    }

    fn raw_call(&self, req: CliRequest, timeout: Duration) -> Result<RouterReply, ControlError> {
        let req = RouterRequest::Cli(req);
        match &self.client {
            Some(client) => client.call(&req, timeout),
            None => {
                // the connection `open` made, unless it waited so long that
                // the router may have let it go
                let conn = match self.first.borrow_mut().take().filter(ToolConnection::fresh) {
                    Some(c) => c,
                    None => ToolConnection::connect(&self.world.tool_socket()).map_err(|_| ControlError::NoServer {
                        service: self.world.tool_socket().display().to_string(),
                    })?,
                };
                conn.call(&req, timeout)
            }
        }
    }

    /// Sends a request; a refusal becomes an error with the router's message.
    pub fn call(&self, req: CliRequest) -> Result<RouterReply> {
        self.call_within(req, ROUTER_TIMEOUT)
    }

    /// [`RouterSession::call`] for a request the router answers late by
    /// design (a [`CliRequest::Start`] waits for the agents' start-ups):
    /// waits up to `timeout` for the answer.
    pub fn call_within(&self, req: CliRequest, timeout: Duration) -> Result<RouterReply> {
        match self.raw_call(req, timeout) {
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

/// The session a long-running command (`nerve ui`, `nerve foxglove`) keeps
/// in `kept`: opened on first use, and again after [`call_kept`] dropped it.
pub fn kept_session<'a>(kept: &'a mut Option<RouterSession>, world: &World) -> Result<&'a RouterSession, String> {
    match kept {
        Some(s) => Ok(s),
        None => Ok(kept.insert(RouterSession::open(world).map_err(|e| format!("{e:#}"))?)),
    }
}

/// [`RouterSession::call`] on the session kept in `kept`. A refusal is the
/// router's answer; any other failure means no router (or a new one), so the
/// session is dropped and the next call opens a fresh one.
pub fn call_kept(kept: &mut Option<RouterSession>, world: &World, req: CliRequest) -> Result<RouterReply, String> {
    let reply = kept_session(kept, world)?.call(req);
    if reply.as_ref().is_err_and(|e| e.downcast_ref::<RouterError>().is_none()) {
        *kept = None;
    }
    reply.map_err(|e| format!("{e:#}"))
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
