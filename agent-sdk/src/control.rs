//! The control channel: request-response over iceoryx2, paired with an event
//! service of the same name so that a server blocks until a request arrives.
//!
//! Requests and replies are postcard bytes in a versioned envelope
//! (`shm_schemas::control`). Used for the router's service
//! (`nerve/<robot>/router`) and each agent's control service
//! (`nerve/<robot>/<agent>/ctl`).
//!
//! Nobody polls for a reply where it matters. The router, which asks every
//! agent at once (`nerve ps`), is woken by the agent that answered: it
//! notifies the router's own event with its [`reply_event_id`], and the
//! router looks only at the calls of agents whose id came (see
//! `router::calls`). Programs calling the router (the decision maker's
//! rewiring) sleep on a listener of `<service>/replies`, which the router
//! notifies after each reply on that service ([`ControlSize::reply_wake`]);
//! a program that finds every listener slot taken polls. Agents' other
//! clients (tools, the router's own calls when it waits in place) poll
//! with a short back-off: a listener per client of every agent would cost
//! more than the rare waits it saves.
//!
//! Tools (`nerve` commands) reach the router through its [`ToolSocket`]
//! instead, a Unix stream socket beside the robot's state: a command that
//! only asks the router needs no iceoryx2 node, client port or shared
//! memory of its own, which were most of its time (BENCHMARKS.md §6), and
//! it sleeps in `read` until the reply comes. The router serves both; a
//! request taken from either is answered through the same [`Responder`].

use crate::world::{Ipc, World};
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;
use serde::{Serialize, de::DeserializeOwned};
use shm_schemas::control::{ProtocolError, decode, encode, unanswered};
use std::marker::PhantomData;
use std::rc::Rc;
use std::time::{Duration, Instant};

mod stream;
pub use stream::{ToolConnection, ToolSocket};

/// How big a control service is.
///
/// Messages of a service with `max_message: None` grow on demand (iceoryx2's
/// power-of-two allocation: up to 256 segments). The price is paid per
/// client: each server-to-client connection keeps the state of every
/// response slot of every possible segment, and the server has a slot per
/// client. With 512 clients that was a 10 MiB connection file per agent,
/// fully resident in the agent and in the router (1 GiB for 100 agents).
/// A service with many clients therefore uses fixed-size messages
/// (`Some(bytes)`: one static segment).
#[derive(Debug, Clone, Copy)]
pub struct ControlSize {
    /// clients that may be connected at once
    pub max_clients: usize,
    /// nodes that may open the service
    pub max_nodes: usize,
    /// the largest message, fixed; `None`: any size
    pub max_message: Option<usize>,
    /// client slots that [`ControlClient::open`] leaves free, for the
    /// service's owner's [`ControlClient::open_reserved`] (the router)
    pub reserved_clients: usize,
    /// the server wakes its clients after each reply (an event service
    /// `<service>/replies`), so that a waiting client sleeps instead of
    /// polling: for a service with few clients, each of which a reply
    /// wakes (see [`ControlClient::call`])
    pub reply_wake: bool,
}

impl ControlSize {
    /// The router's service for agents (registration): every agent of the
    /// robot, small fixed-size messages.
    pub const ROUTER: ControlSize = ControlSize {
        max_clients: 512,
        max_nodes: 640,
        max_message: Some(8192),
        reserved_clients: 0,
        reply_wake: false,
    };
    /// The router's service for tools and programs (`nerve ps` of 500 agents
    /// is a large reply): a few clients at once, each woken by a reply
    /// (a program's rewire waits for its answer, issue 18).
    pub const ROUTER_CLI: ControlSize =
        ControlSize { max_clients: 32, max_nodes: 64, max_message: None, reserved_clients: 0, reply_wake: true };
    /// An agent's control service: the router, a restarted router, tools.
    /// Fixed 64 KiB messages (statistics of an agent with a few hundred
    /// ports): with growing messages the router's client of each agent
    /// cost 0.85 MiB of heap (17 of the router's 40 MiB with 20 agents).
    /// One slot is kept for the router: tools (`nerve drive`, test
    /// injectors, clients of killed tools not yet cleaned up) take at most
    /// seven, so that they never leave the agent unreachable for the router.
    pub const AGENT: ControlSize =
        ControlSize { max_clients: 8, max_nodes: 16, max_message: Some(65536), reserved_clients: 1, reply_wake: false };

    fn slice_len(&self) -> usize {
        self.max_message.unwrap_or(INITIAL_MESSAGE_BYTES)
    }

    fn allocation(&self) -> AllocationStrategy {
        if self.max_message.is_some() { AllocationStrategy::Static } else { AllocationStrategy::PowerOfTwo }
    }
}

/// Errors of the control channel.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// Nobody serves the service.
    #[error("no server on {service}")]
    NoServer {
        /// the service
        service: String,
    },
    /// The server is busy: another server already runs on this service.
    #[error("{service} is already served by another process")]
    AlreadyServed {
        /// the service
        service: String,
    },
    /// No reply came in time.
    #[error("no reply from {service} within {timeout:?}")]
    Timeout {
        /// the service
        service: String,
        /// how long we waited
        timeout: Duration,
    },
    /// Every client slot a tool may take is taken.
    #[error(
        "{service} has no free client slot ({taken} clients connected, {max} at most for tools): close other tools talking to it, or wait a few seconds for the clients of killed ones to be cleaned up, and try again"
    )]
    Full {
        /// the service
        service: String,
        /// clients connected now
        taken: usize,
        /// the most a tool may find connected and still join
        max: usize,
    },
    /// A message larger than the service allows.
    #[error("a message of {bytes} bytes is larger than the {max} bytes {service} takes")]
    TooLarge {
        /// the service
        service: String,
        /// the message's size
        bytes: usize,
        /// the service's limit
        max: usize,
    },
    /// The peer speaks another protocol or sent garbage.
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
    /// The tools' socket failed (see [`ToolSocket`]).
    #[error("cannot {what} {}: {source}", path.display())]
    Io {
        /// what was being done
        what: &'static str,
        /// the socket
        path: std::path::PathBuf,
        /// what the system said
        #[source]
        source: std::io::Error,
    },
    /// iceoryx2 failed: which operation, and iceoryx2's own error as the
    /// source (downcast it to that operation's iceoryx2 error type).
    #[error("iceoryx2 could not {op} of {service}: {source:?}")]
    Ipc {
        /// the service
        service: String,
        /// what nerve asked of iceoryx2
        op: IpcOp,
        /// what iceoryx2 said
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// The iceoryx2 operation a [`ControlError::Ipc`] comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IpcOp {
    /// turn the service's name into an iceoryx2 service name
    Name,
    /// open or create the request-response service
    Service,
    /// open or create the wake-up event service
    Event,
    /// create the server port
    Server,
    /// create a client port
    Client,
    /// create the wake-up listener
    Listener,
    /// create the wake-up notifier
    Notifier,
    /// loan memory for a request
    Loan,
    /// send a request
    Send,
    /// notify the server
    Notify,
    /// receive a request or a reply
    Receive,
}

impl std::fmt::Display for IpcOp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            IpcOp::Name => "name the service",
            IpcOp::Service => "open the service",
            IpcOp::Event => "open the wake-up event",
            IpcOp::Server => "create the server",
            IpcOp::Client => "create a client",
            IpcOp::Listener => "create the wake-up listener",
            IpcOp::Notifier => "create the wake-up notifier",
            IpcOp::Loan => "loan memory for a request",
            IpcOp::Send => "send a request",
            IpcOp::Notify => "wake the server",
            IpcOp::Receive => "receive",
        })
    }
}

fn ipc_err<E: std::error::Error + Send + Sync + 'static>(service: &str, op: IpcOp) -> impl FnOnce(E) -> ControlError {
    move |e| ControlError::Ipc { service: service.into(), op, source: Box::new(e) }
}

type Bytes = [u8];

/// Requests a client may have in flight. A call waits for its reply, so one
/// is in flight; one more covers a call abandoned on time-out. Every slot is
/// multiplied by the number of clients in the server's shared memory: with
/// 4 x 4 x 4 slots of 4 KiB the router's segment was 136 MB and each call of
/// the `nerve` command spent half a second mapping and unmapping it.
const MAX_ACTIVE_REQUESTS: usize = 2;
/// First size of a message buffer; larger messages (a `ps` of 100 agents)
/// grow it by powers of two.
const INITIAL_MESSAGE_BYTES: usize = 512;

/// The longest sleep between two looks for a reply. A control call nests
/// (a `nerve connect` waits for the router, which waits for the agent), so
/// each level's polling granularity adds up: at 2 ms it was a good part of a
/// 10 ms rewire. A waiting caller now looks at least every 200 µs, which
/// costs a few thousand wake-ups a second only while a call is pending.
const MAX_POLL_INTERVAL: Duration = Duration::from_micros(200);

/// How long a client woken by replies ([`ControlSize::reply_wake`]) sleeps
/// at most before it looks for its reply anyway: only a wake-up the server
/// could not send (it logs why) or a server gone are found this way.
const REPLY_WAIT_BOUND: Duration = Duration::from_millis(50);

/// Reply wake-ups a control service's event tells apart: event id 0 (a
/// notifier's default) says that a request came; ids 1 to this say that an
/// agent whose name hashes to the id answered one (see
/// [`reply_event_id`]). Also the event's largest id.
pub const REPLY_EVENT_IDS: usize = 255;

/// The event id with which agent `name` tells the router that it answered:
/// 1 to [`REPLY_EVENT_IDS`], from a hash of the name (FNV-1a). Agents that
/// share an id only make the router look at each other's calls as well.
pub fn reply_event_id(name: &str) -> usize {
    let hash = name.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3));
    // the remainder is below REPLY_EVENT_IDS, which fits a usize
    1 + (hash % REPLY_EVENT_IDS as u64) as usize
}

/// The serving side: receives requests and answers them.
#[derive(Debug)]
pub struct ControlServer<Req, Resp> {
    service: String,
    size: ControlSize,
    server: Server<Ipc, Bytes, (), Bytes, ()>,
    listener: Listener<Ipc>,
    /// wakes the clients after a reply (`size.reply_wake`)
    replies: Option<Rc<Notifier<Ipc>>>,
    _types: PhantomData<fn(Req) -> Resp>,
}

impl<Req: DeserializeOwned, Resp: Serialize> ControlServer<Req, Resp> {
    /// [`ControlServer::create`] where a dead or exiting process's server
    /// may be in the way (a killed run of this agent, a killed router):
    /// when the creation fails in a way `blockable` says such leftovers
    /// could explain, cleans up after dead processes and tries again,
    /// waiting a little while the server in the way belongs only to
    /// processes that are exiting ([`served_only_by_the_gone`]) or another
    /// process is cleaning up ([`crate::world::retry_after_cleanup_while`]).
    /// `what` names the service in the log lines.
    pub fn create_clearing(
        node: &Node<Ipc>,
        service: &str,
        size: ControlSize,
        what: &str,
        blockable: impl Fn(&ControlError) -> bool,
    ) -> Result<Self, ControlError> {
        let exiting = || served_only_by_the_gone(node, service, size);
        crate::world::retry_after_cleanup_while(node.config(), what, blockable, exiting, || {
            Self::create(node, service, size)
        })
    }

    /// Serves `service`. Only one server may serve a service at a time: a
    /// second one gets [`ControlError::AlreadyServed`].
    pub fn create(node: &Node<Ipc>, service: &str, size: ControlSize) -> Result<Self, ControlError> {
        // before the server, so that a client that finds the server finds it too
        let replies = if size.reply_wake {
            let ev = open_replies(node, service, size, true)?;
            Some(Rc::new(ev.notifier_builder().create().map_err(ipc_err(service, IpcOp::Notifier))?))
        } else {
            None
        };
        let rr = rr_builder(node, service, size)?.open_or_create().map_err(ipc_err(service, IpcOp::Service))?;
        let server = rr
            .server_builder()
            .initial_max_slice_len(size.slice_len())
            .allocation_strategy(size.allocation())
            .max_loaned_responses_per_request(1)
            .override_response_preallocation(move |_| responses_needed(size))
            .create()
            .map_err(|e| match e {
                iceoryx2::service::port_factory::server::ServerCreateError::ExceedsMaxSupportedServers => {
                    ControlError::AlreadyServed { service: service.into() }
                }
                e => ipc_err(service, IpcOp::Server)(e),
            })?;
        let ev = open_event(node, service, size)?;
        let listener = ev.listener_builder().create().map_err(ipc_err(service, IpcOp::Listener))?;
        Ok(ControlServer { service: service.into(), size, server, listener, replies, _types: PhantomData })
    }

    /// The listener that wakes when a request arrives (attach it to a WaitSet).
    pub fn listener(&self) -> &Listener<Ipc> {
        &self.listener
    }

    /// Brings the server's connections up to date with the clients that came
    /// and went, off the request path: a client that left (a `nerve` command
    /// that exited) is otherwise cleaned up by the next `serve`, and the next
    /// caller waits for it.
    pub fn tidy(&self) {
        let _ = self.server.has_requests();
    }

    /// Drains the wake-ups of the listener, so that a request arriving
    /// after this call wakes the server again. Call it before receiving.
    pub fn drain_wakeups(&self) {
        self.take_wakeups(|_| {});
    }

    /// Drains the wake-ups like [`ControlServer::drain_wakeups`], calling
    /// `replied` with every reply id that came (see [`reply_event_id`]).
    pub fn take_wakeups(&self, mut replied: impl FnMut(usize)) {
        let _ = self.listener.try_wait(|a| {
            let id = a.id.as_value();
            if id != 0 {
                replied(id);
            }
        });
    }

    /// Takes the next pending request, if any, with the [`Responder`] that
    /// answers it, now or later: a server that must ask others before it
    /// can answer (the router) keeps the responder and goes on serving.
    #[allow(clippy::type_complexity)]
    pub fn receive(&self) -> Result<Option<(Result<Req, ProtocolError>, Responder<Resp>)>, ControlError> {
        let Some(active) = self.server.receive().map_err(ipc_err(&self.service, IpcOp::Receive))? else {
            return Ok(None);
        };
        let req = decode::<Req>(active.payload());
        let responder = Responder {
            active: Some(Caller::Shm(active)),
            service: self.service.clone(),
            max_message: self.size.max_message,
            replies: self.replies.clone(),
            _types: PhantomData,
        };
        Ok(Some((req, responder)))
    }

    /// Answers every pending request with `handler`; returns how many were
    /// served. A reply larger than the service carries is replaced by
    /// `handler`'s answer to [`ProtocolError::TooLarge`] (an error reply).
    pub fn serve(&self, mut handler: impl FnMut(Result<Req, ProtocolError>) -> Resp) -> Result<usize, ControlError> {
        // drain the wake-ups first, so that a request arriving while we serve wakes us again
        self.drain_wakeups();
        let mut n = 0;
        while let Some((req, responder)) = self.receive()? {
            let reply = handler(req);
            responder.respond_or(&reply, |e| handler(Err(e)));
            n += 1;
        }
        Ok(n)
    }
}

/// A request taken by a [`ControlServer`] and not answered yet.
///
/// Dropping it unanswered (a server that stops with requests in hand) sends
/// the caller [`ProtocolError::Unanswered`]: it learns at once that the
/// request was taken, and does not send it again (reliability review: a
/// request dropped unanswered looked like one never taken, and was resent).
#[derive(Debug)]
pub struct Responder<Resp> {
    /// `None` once answered
    active: Option<Caller>,
    service: String,
    max_message: Option<usize>,
    /// the server's notifier that wakes its waiting clients
    replies: Option<Rc<Notifier<Ipc>>>,
    _types: PhantomData<fn(Resp)>,
}

/// Where a request came from, and so where its answer goes.
#[derive(Debug)]
enum Caller {
    /// an iceoryx2 client: the answer is loaned and sent on its connection
    Shm(ActiveRequest<Ipc, Bytes, (), Bytes, ()>),
    /// a tool on a [`ToolSocket`]: the answer is written as one frame
    Stream(stream::Connection),
}

impl Caller {
    fn is_connected(&self) -> bool {
        match self {
            Caller::Shm(a) => a.is_connected(),
            Caller::Stream(c) => c.is_open(),
        }
    }
}

impl<Resp: Serialize> Responder<Resp> {
    /// Whether the caller still waits for the answer (it has not given up
    /// or gone).
    pub fn is_connected(&self) -> bool {
        self.active.as_ref().is_some_and(Caller::is_connected)
    }

    /// Sends `reply`; a reply larger than the service carries is replaced by
    /// `too_large`'s answer to [`ProtocolError::TooLarge`]. Failures to send
    /// are logged: the caller's time-out tells it.
    pub fn respond_or(mut self, reply: &Resp, too_large: impl FnOnce(ProtocolError) -> Resp) {
        let mut bytes = encode(reply);
        if let Some(max) = self.max_message.filter(|&m| bytes.len() > m) {
            tracing::warn!(service = %self.service, bytes = bytes.len(), max, "a reply exceeds the service's limit");
            bytes = encode(&too_large(ProtocolError::TooLarge { bytes: bytes.len(), max }));
        }
        self.send(&bytes);
    }
}

impl<Resp> Responder<Resp> {
    fn send(&mut self, bytes: &[u8]) {
        match self.active.take() {
            None => {}
            Some(Caller::Shm(active)) => {
                match active.loan_slice_uninit(bytes.len()) {
                    Ok(resp) => {
                        if let Err(e) = resp.write_from_slice(bytes).send() {
                            tracing::warn!(service = %self.service, "could not send a reply: {e:?}");
                        }
                    }
                    Err(e) => tracing::warn!(service = %self.service, "could not loan a reply: {e:?}"),
                }
                // a client that misses this wake-up still looks within
                // REPLY_WAIT_BOUND
                if let Some(n) = &self.replies
                    && let Err(e) = n.notify()
                {
                    tracing::debug!(service = %self.service, "could not wake the clients: {e:?}");
                }
            }
            Some(Caller::Stream(mut c)) => {
                if let Err(e) = c.answer(bytes) {
                    tracing::warn!(service = %self.service, error = %e, "could not answer a tool: {e}");
                }
            }
        }
    }
}

impl<Resp> Drop for Responder<Resp> {
    fn drop(&mut self) {
        if self.active.as_ref().is_some_and(|a| a.is_connected()) {
            tracing::debug!(service = %self.service, "a request is let go unanswered");
            self.send(&unanswered());
        }
    }
}

/// The calling side.
#[derive(Debug)]
pub struct ControlClient<Req, Resp> {
    service: String,
    size: ControlSize,
    client: Client<Ipc, Bytes, (), Bytes, ()>,
    notifier: Notifier<Ipc>,
    /// woken by the server after each of its replies (`size.reply_wake`);
    /// `None`: the client polls
    replies: Option<Listener<Ipc>>,
    /// waits for a reply that a wake-up ended (for the tests)
    reply_wakes: std::cell::Cell<u64>,
    _types: PhantomData<fn(Req) -> Resp>,
}

impl<Req: Serialize, Resp: DeserializeOwned> ControlClient<Req, Resp> {
    /// Opens `service`; [`ControlError::NoServer`] when it does not exist,
    /// [`ControlError::Full`] when only the slots kept for the service's
    /// owner (`size.reserved_clients`) are free.
    pub fn open(node: &Node<Ipc>, service: &str, size: ControlSize) -> Result<Self, ControlError> {
        Self::open_with(node, service, size, size.reserved_clients)
    }

    /// Opens `service`, taking a slot kept for the service's owner if
    /// needed: for the router only.
    pub fn open_reserved(node: &Node<Ipc>, service: &str, size: ControlSize) -> Result<Self, ControlError> {
        Self::open_with(node, service, size, 0)
    }

    fn open_with(node: &Node<Ipc>, service: &str, size: ControlSize, leave: usize) -> Result<Self, ControlError> {
        let rr = rr_builder(node, service, size)?.open().map_err(|e| match e {
            iceoryx2::service::builder::request_response::RequestResponseOpenError::DoesNotExist => {
                ControlError::NoServer { service: service.into() }
            }
            e => ipc_err(service, IpcOp::Service)(e),
        })?;
        if servers_all_dead(&rr) {
            // A killed server's port stays in the service until someone
            // cleans up after it (iceoryx2 no longer does on every open,
            // `World::new`), and a request sent to it would wait out its
            // whole time-out: cleaned now, so that a call finds no server.
            let cleaned = crate::world::cleanup_dead_nodes_of(node.config());
            if cleaned > 0 {
                tracing::info!(
                    service,
                    cleaned,
                    "the server of {service} is dead: cleaned the shared memory of {cleaned} dead process(es)"
                );
            }
        }
        let max = size.max_clients.saturating_sub(leave);
        let taken = rr.dynamic_config().number_of_clients();
        if leave > 0 && taken >= max {
            return Err(ControlError::Full { service: service.into(), taken, max });
        }
        let client = rr
            .client_builder()
            .initial_max_slice_len(size.slice_len())
            .allocation_strategy(size.allocation())
            .create()
            .map_err(ipc_err(service, IpcOp::Client))?;
        let ev = open_event(node, service, size)?;
        let notifier = ev.notifier_builder().create().map_err(ipc_err(service, IpcOp::Notifier))?;
        // every listener slot taken (more programs than the service has
        // clients, or killed ones not cleaned up yet): this one polls
        let replies = if size.reply_wake {
            open_replies(node, service, size, false)
                .and_then(|ev| ev.listener_builder().create().map_err(ipc_err(service, IpcOp::Listener)))
                .inspect_err(|e| tracing::debug!(service, "no reply wake-ups, polling instead: {e}"))
                .ok()
        } else {
            None
        };
        Ok(ControlClient {
            service: service.into(),
            size,
            client,
            notifier,
            replies,
            reply_wakes: std::cell::Cell::new(0),
            _types: PhantomData,
        })
    }

    /// The service this client calls.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// Sends `req` and waits up to `timeout` for the reply.
    pub fn call(&self, req: &Req, timeout: Duration) -> Result<Resp, ControlError> {
        let bytes = encode(req);
        if let Some(max) = self.size.max_message.filter(|&m| bytes.len() > m) {
            return Err(ControlError::TooLarge { service: self.service.clone(), bytes: bytes.len(), max });
        }
        let start = Instant::now();
        let mut attempt = 0;
        loop {
            attempt += 1;
            match self.attempt(&bytes, start, timeout)? {
                Some(resp) => return Ok(resp),
                // The request was not taken. A client that has just appeared can
                // race the server's set-up of its reply connection (iceoryx2 then
                // drops the request unanswered: about 1 call in 600 of freshly
                // started `nerve` commands did so). The server did not handle it,
                // so sending it again is safe; a server that is really gone stays
                // gone.
                None if attempt < SEND_ATTEMPTS && start.elapsed() < timeout => {
                    tracing::debug!(service = %self.service, "request not taken (attempt {attempt}); sending it again");
                    std::thread::sleep(Duration::from_millis(2 * attempt as u64));
                }
                None => return Err(ControlError::NoServer { service: self.service.clone() }),
            }
        }
    }

    /// Sends the request once and waits for the reply; `None` when no server
    /// took it (none connected, or the request was dropped unanswered).
    fn attempt(&self, bytes: &[u8], start: Instant, timeout: Duration) -> Result<Option<Resp>, ControlError> {
        // wake-ups of earlier replies (to this client or others) would
        // only make it look once more: dropped before the request goes
        if let Some(l) = &self.replies {
            let _ = l.try_wait(|_| {});
        }
        let Some(pending) = self.send_bytes(bytes)? else { return Ok(None) };
        let mut backoff = Duration::from_micros(10);
        loop {
            match pending.poll() {
                Ok(Some(resp)) => return Ok(Some(resp)),
                Ok(None) => {}
                Err(ControlError::NoServer { .. }) => return Ok(None),
                Err(e) => return Err(e),
            }
            let waited = start.elapsed();
            if waited > timeout {
                return Err(ControlError::Timeout { service: self.service.clone(), timeout });
            }
            match &self.replies {
                // sleeps until the server replied to someone, looking
                // anyway now and then (a server gone, a wake-up lost)
                Some(l) => {
                    let bound = REPLY_WAIT_BOUND.min(timeout.saturating_sub(waited)).max(Duration::from_micros(1));
                    match l.timed_wait(|_| {}, bound) {
                        Ok(0) => {}
                        Ok(_) => self.reply_wakes.set(self.reply_wakes.get().saturating_add(1)),
                        Err(_) => std::thread::sleep(backoff),
                    }
                }
                None => std::thread::sleep(backoff),
            }
            backoff = (backoff * 2).min(MAX_POLL_INTERVAL);
        }
    }

    /// Wakes the server's owner with event id `id` (an agent telling the
    /// router that it answered: [`reply_event_id`]).
    pub fn notify_replied(&self, id: usize) -> Result<(), ControlError> {
        self.notifier
            .notify_with_custom_event_id(EventId::new(id))
            .map(|_| ())
            .map_err(ipc_err(&self.service, IpcOp::Notify))
    }

    /// Sends `req` and returns at once: the reply is picked up later with
    /// [`PendingCall::poll`]. [`ControlError::NoServer`] when no server took
    /// the request (none is connected); a caller that sends to a server it
    /// has just seen appear may send again (see [`ControlClient::call`]).
    pub fn send(&self, req: &Req) -> Result<PendingCall<Resp>, ControlError> {
        let bytes = encode(req);
        if let Some(max) = self.size.max_message.filter(|&m| bytes.len() > m) {
            return Err(ControlError::TooLarge { service: self.service.clone(), bytes: bytes.len(), max });
        }
        self.send_bytes(&bytes)?.ok_or_else(|| ControlError::NoServer { service: self.service.clone() })
    }

    fn send_bytes(&self, bytes: &[u8]) -> Result<Option<PendingCall<Resp>>, ControlError> {
        let loan = self.client.loan_slice_uninit(bytes.len()).map_err(ipc_err(&self.service, IpcOp::Loan))?;
        let pending = loan.write_from_slice(bytes).send().map_err(ipc_err(&self.service, IpcOp::Send))?;
        if pending.number_of_server_connections() == 0 {
            return Ok(None);
        }
        self.notifier.notify().map_err(ipc_err(&self.service, IpcOp::Notify))?;
        Ok(Some(PendingCall { pending, service: self.service.clone(), _types: PhantomData }))
    }
}

/// Whether `service` has a server and every one of its servers belongs to
/// a process that has exited or is exiting: a process killed a moment ago
/// shows as a zombie before all its threads are gone and its files closed,
/// and until then its iceoryx2 node is alive and its server blocks
/// [`ControlServer::create`] (a router or an agent started again at once
/// after a `kill -9`: the chaos test in a fresh-clone CI run of 2026-11-27).
pub fn served_only_by_the_gone(node: &Node<Ipc>, service: &str, size: ControlSize) -> bool {
    rr_builder(node, service, size).ok().and_then(|b| b.open().ok()).is_some_and(|rr| servers_all_dead(&rr))
}

/// Whether `rr` has servers and every one of them belongs to a process
/// that is gone (a pid reused meanwhile counts as alive: the caller then
/// waits out its time-out, as before).
fn servers_all_dead(
    rr: &iceoryx2::service::port_factory::request_response::PortFactory<Ipc, Bytes, (), Bytes, ()>,
) -> bool {
    let (mut servers, mut dead) = (0usize, 0usize);
    rr.dynamic_config().list_servers(|d| {
        servers += 1;
        if d.node_id.pid::<Ipc>().is_ok_and(|p| u32::try_from(p.value()).is_ok_and(|p| !crate::world::pid_alive(p))) {
            dead += 1;
        }
        CallbackProgression::Continue
    });
    servers > 0 && dead == servers
}

/// A request sent and not answered yet.
#[derive(Debug)]
pub struct PendingCall<Resp> {
    pending: PendingResponse<Ipc, Bytes, (), Bytes, ()>,
    service: String,
    _types: PhantomData<fn() -> Resp>,
}

impl<Resp: DeserializeOwned> PendingCall<Resp> {
    /// The reply if it has come; [`ControlError::NoServer`] when the server
    /// is gone or dropped the request unanswered. Dropping the call
    /// abandons it.
    pub fn poll(&self) -> Result<Option<Resp>, ControlError> {
        // Look whether the server still holds the request *before* reading:
        // a server answers, then lets go, so an answer sent by a server seen
        // gone is already here to read (read first, and the answer could
        // land between the two looks and be taken for a server gone).
        let connected = self.pending.is_connected();
        if let Some(resp) = self.pending.receive().map_err(ipc_err(&self.service, IpcOp::Receive))? {
            return Ok(Some(decode::<Resp>(resp.payload())?));
        }
        if !connected {
            return Err(ControlError::NoServer { service: self.service.clone() });
        }
        Ok(None)
    }
}

/// How often a call sends a request that no server took before it gives up.
const SEND_ATTEMPTS: u32 = 3;

type RrBuilder = iceoryx2::service::builder::request_response::Builder<Bytes, (), Bytes, (), Ipc>;

/// The one place that sets up a control service, so that server and clients agree.
/// How many responses a server of `size` needs at most: it answers each
/// request once, loaning the response just before it sends it, and a client
/// has at most [`MAX_ACTIVE_REQUESTS`] requests pending, each with one
/// response in its buffer or in its hands. iceoryx2 would reserve four
/// times as many (old requests a client dropped, several loans per
/// request), and the cost is more than memory: when a client leaves, the
/// server walks every slot of its connection in every segment (255 for a
/// growing reply), which made the router's first `receive` after a `nerve`
/// command exited take 3.6 ms, on the next command's time.
fn responses_needed(size: ControlSize) -> usize {
    size.max_clients * MAX_ACTIVE_REQUESTS * 2 + 1
}

fn rr_builder(node: &Node<Ipc>, service: &str, size: ControlSize) -> Result<RrBuilder, ControlError> {
    let name: ServiceName = service.try_into().map_err(ipc_err(service, IpcOp::Name))?;
    Ok(node
        .service_builder(&name)
        .request_response::<Bytes, Bytes>()
        .max_clients(size.max_clients)
        .max_servers(1)
        .max_nodes(size.max_nodes)
        .max_active_requests_per_client(MAX_ACTIVE_REQUESTS)
        .max_response_buffer_size(1)
        .max_borrowed_responses_per_pending_response(1)
        .max_loaned_requests(1))
}

/// The event with which a server of `service` wakes its clients after a
/// reply ([`ControlSize::reply_wake`]): a listener per client. The server
/// creates it (`create`); a client only opens it, so that a client of a
/// server without it (an older router) polls instead of waiting for
/// wake-ups that never come.
fn open_replies(
    node: &Node<Ipc>,
    service: &str,
    size: ControlSize,
    create: bool,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Ipc>, ControlError> {
    let replies = format!("{service}/replies");
    let name: ServiceName = replies.as_str().try_into().map_err(ipc_err(service, IpcOp::Name))?;
    let builder = node
        .service_builder(&name)
        .event()
        .max_notifiers(2)
        .max_listeners(size.max_clients + 2)
        .max_nodes(size.max_nodes);
    if create {
        builder.open_or_create().map_err(ipc_err(service, IpcOp::Event))
    } else {
        builder.open().map_err(ipc_err(service, IpcOp::Event))
    }
}

fn open_event(
    node: &Node<Ipc>,
    service: &str,
    size: ControlSize,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<Ipc>, ControlError> {
    let name: ServiceName = service.try_into().map_err(ipc_err(service, IpcOp::Name))?;
    node.service_builder(&name)
        .event()
        .event_id_max_value(REPLY_EVENT_IDS)
        .max_notifiers(size.max_clients + 2)
        .max_listeners(2)
        .max_nodes(size.max_nodes)
        .open_or_create()
        .map_err(ipc_err(service, IpcOp::Event))
}

/// Opens the router's service for tools and programs of `world`
/// (`nerve` commands, the decision maker, benchmarks).
pub fn router_client<Req: Serialize, Resp: DeserializeOwned>(
    world: &World,
    node: &Node<Ipc>,
) -> Result<ControlClient<Req, Resp>, ControlError> {
    ControlClient::open(node, &world.robot().router_cli_service(), ControlSize::ROUTER_CLI)
}

/// Opens the router's service for agents of `world` (registration).
pub fn agent_router_client<Req: Serialize, Resp: DeserializeOwned>(
    world: &World,
    node: &Node<Ipc>,
) -> Result<ControlClient<Req, Resp>, ControlError> {
    ControlClient::open(node, &world.robot().router_service(), ControlSize::ROUTER)
}

#[cfg(test)]
mod tests;
