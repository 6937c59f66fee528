//! Calls between agents: an agent answers a service
//! ([`crate::Setup::serve`], a [`Server`]) and another calls it through a
//! client ([`crate::Setup::client`], a [`Client`]) that the router wires to
//! the service like a connection (`nerve connect a/planner b/plan`).
//!
//! A call is an iceoryx2 request-response service `nerve/ROBOT/AGENT/SERVICE`
//! of fixed-size payloads (`Req` asked, `Resp` answered), created by the
//! server with the port attributes of a call type ([`call_spec`]), paired
//! with two event services: the service's own name, which a client
//! notifies when it sends a request (it wakes the server's task like an
//! input), and `…/SERVICE/answered`, which the server notifies when it
//! answered (it wakes an event-driven client's task).
//!
//! A client's step is never blocked: [`Client::call`] sends and returns a
//! [`CallId`] at once, [`Client::take`] later hands out each finished call
//! with its answer or why there is none: no answer within the call's
//! timeout, the server gone (its process died or was disconnected while
//! the call was in flight), the client unwired. Past a bound of calls in
//! flight a call is refused and nothing is sent.
//!
//! Both sides take part in the task's wake-ups as inputs do: they are in
//! the agent's input list (so [`crate::Context::woken_by`] names them), but
//! are registered with the router as services and clients, never as inputs.

use super::bytes::{Binding, DynInput};
use super::error::PortError;
use super::memory::SampleBuf;
use super::service::{MAX_SUBSCRIBERS, lock, port_attributes_of};
use crate::clock::now_ns;
use crate::world::Ipc;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client as IoxClient;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::server::Server as IoxServer;
use iceoryx2::prelude::*;
use iceoryx2::service::marker::{CustomHeaderMarker, CustomPayloadMarker};
use iceoryx2::service::port_factory::{event, request_response};
use shm_schemas::Payload;
use shm_schemas::control::agent_to_router::PortSpec;
pub use shm_schemas::control::call::call_spec;
use shm_schemas::stats::InputStats;
use std::collections::VecDeque;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The most calls one client may have in flight (the service is made for
/// this many per client; [`CallOptions::max_in_flight`] may be lower).
pub const MAX_IN_FLIGHT: usize = 64;
/// The most clients one service takes.
pub const MAX_CLIENTS: usize = 16;
/// How long a call waits for its answer unless the client says otherwise.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(1);
/// The suffix of the event service a server notifies when it answered.
pub const ANSWERED_SUFFIX: &str = "/answered";

/// The settings of every call service, so that every opener agrees
/// (iceoryx2 refuses an opener that asks for more than the creator set up).
macro_rules! call_settings {
    ($builder:expr) => {
        $builder
            .max_active_requests_per_client(MAX_IN_FLIGHT)
            .max_clients(MAX_CLIENTS)
            // a restarted server's port is made while its dead predecessor's may still count
            .max_servers(2)
            .max_nodes(MAX_CLIENTS + 4)
            .max_response_buffer_size(2)
            .enable_safe_overflow_for_requests(true)
            .enable_safe_overflow_for_responses(true)
    };
}

/// Why a call port could not be made, or a call could not be sent or
/// answered. Each variant says which client or service, and what to do.
#[derive(Debug, thiserror::Error)]
pub enum CallError {
    /// The client is not wired to a service.
    #[error("client {client}: not wired to a service; wire it with `nerve connect AGENT/{client} SERVER/SERVICE`")]
    NotWired {
        /// the client's name
        client: String,
    },
    /// The bound of calls in flight is reached: nothing was sent.
    #[error(
        "client {client}: {max} calls are in flight already, the most it may have; nothing was sent (take finished calls with `take`, or raise `max_in_flight`)"
    )]
    TooManyInFlight {
        /// the client's name
        client: String,
        /// the bound
        max: usize,
    },
    /// No server answers the service the client is wired to: nothing was sent.
    #[error("client {client}: no server answers {service} (its agent is not running); nothing was sent")]
    NoServer {
        /// the client's name
        client: String,
        /// the service
        service: String,
    },
    /// The server went away with the call in flight (it died, or its port
    /// was closed), or the client was unwired: the call may or may not have
    /// been carried out.
    #[error(
        "client {client}: the server of {service} went away before it answered (it may or may not have carried out the call); check it with `nerve ps`"
    )]
    ServerGone {
        /// the client's name
        client: String,
        /// the service
        service: String,
    },
    /// No answer came within the call's timeout.
    #[error(
        "client {client}: no answer from {service} within {timeout:?}; the server may be busy, hung or gone (`nerve ps`)"
    )]
    TimedOut {
        /// the client's name
        client: String,
        /// the service
        service: String,
        /// the call's timeout
        timeout: Duration,
    },
    /// The client was unwired (`nerve disconnect`) with the call in flight.
    #[error("client {client}: unwired from {service} with the call in flight")]
    Unwired {
        /// the client's name
        client: String,
        /// the service
        service: String,
    },
    /// iceoryx2 could not send the request.
    #[error("client {client}: cannot send the request to {service}: {source:?}")]
    Send {
        /// the client's name
        client: String,
        /// the service
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::client::RequestSendError,
    },
    /// iceoryx2 could not receive.
    #[error("{port}: cannot receive from {service}: {source:?}")]
    Receive {
        /// the client's or service's name
        port: String,
        /// the service
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::ReceiveError,
    },
    /// The call service could not be made or opened.
    #[error("{service}: cannot open the call service: {detail}")]
    Open {
        /// the service
        service: String,
        /// what went wrong, and what to do
        detail: String,
    },
    /// Calls are not carried by this binding (the test harness).
    #[error("call port {port}: calls are not yet carried in the test harness; test calls with real agents")]
    NotInHarness {
        /// the port
        port: String,
    },
}

impl CallError {
    /// Whether the call may have reached the server (a timeout, a server
    /// gone mid-call): such a call must not be sent again blindly.
    pub fn maybe_carried_out(&self) -> bool {
        matches!(self, CallError::ServerGone { .. } | CallError::TimedOut { .. } | CallError::Unwired { .. })
    }
}

fn open_err(service: &str, detail: impl std::fmt::Debug) -> CallError {
    CallError::Open { service: service.into(), detail: format!("{detail:?}") }
}

/// The id of one call of a client, unique for the client's life.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct CallId(pub u64);

impl std::fmt::Display for CallId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "call {}", self.0)
    }
}

/// A client's settings.
#[derive(Debug, Clone, Copy)]
pub struct CallOptions {
    /// how long each call waits for its answer
    pub timeout: Duration,
    /// how many calls may be in flight at once (at most [`MAX_IN_FLIGHT`])
    pub max_in_flight: usize,
}

impl Default for CallOptions {
    fn default() -> Self {
        CallOptions { timeout: DEFAULT_TIMEOUT, max_in_flight: 16 }
    }
}

type Factory<Req, Resp> = request_response::PortFactory<Ipc, Req, (), Resp, ()>;

fn service_name(service: &str) -> Result<ServiceName, CallError> {
    service.try_into().map_err(|e| open_err(service, e))
}

/// Opens (`create` true: or creates) the event service `name`.
fn event_service(node: &Node<Ipc>, name: &str, create: bool) -> Result<event::PortFactory<Ipc>, CallError> {
    let sn = service_name(name)?;
    let b = node
        .service_builder(&sn)
        .event()
        .max_listeners(MAX_SUBSCRIBERS + 4)
        .max_notifiers(MAX_CLIENTS + 4)
        .max_nodes(MAX_CLIENTS + 4);
    if create { b.open_or_create().map_err(|e| open_err(name, e)) } else { b.open().map_err(|e| open_err(name, e)) }
}

/// The call service `service` of `Req` answered by `Resp`, with the
/// attributes of its call type; created only by the server (`create`).
fn call_service<Req: Payload, Resp: Payload>(
    node: &Node<Ipc>,
    service: &str,
    create: bool,
) -> Result<Factory<Req, Resp>, CallError> {
    use iceoryx2::service::builder::request_response::{
        RequestResponseOpenError as Open, RequestResponseOpenOrCreateError as OpenOrCreate,
    };
    let spec = call_spec::<Req, Resp>("");
    let attributes =
        port_attributes_of(service, &spec.type_name, spec.fingerprint).map_err(|e| open_err(service, e))?;
    let name = service_name(service)?;
    for _attempt in 0..50 {
        let builder = call_settings!(node.service_builder(&name).request_response::<Req, Resp>());
        let result = if create {
            builder.open_or_create_with_attributes(&attributes)
        } else {
            builder.open_with_attributes(&attributes).map_err(OpenOrCreate::RequestResponseOpenError)
        };
        match result {
            Ok(f) => return Ok(f),
            Err(OpenOrCreate::RequestResponseOpenError(Open::DoesNotExist)) => {
                return Err(CallError::Open {
                    service: service.into(),
                    detail: "no agent offers it (is the server running, and is the name right?)".into(),
                });
            }
            Err(OpenOrCreate::RequestResponseOpenError(
                Open::IncompatibleAttributes | Open::IncompatibleRequestOrResponseType,
            )) => {
                return Err(CallError::Open {
                    service: service.into(),
                    detail: format!(
                        "it is not a call of {} (another request or response type, or another build of them); \
                         rebuild the older side and restart it",
                        spec.type_name
                    ),
                });
            }
            Err(OpenOrCreate::RequestResponseOpenError(Open::IsMarkedForDestruction)) => {
                std::thread::sleep(Duration::from_millis(10));
            }
            Err(e) => return Err(open_err(service, e)),
        }
    }
    Err(CallError::Open { service: service.into(), detail: "its last owner is still removing it; try again".into() })
}

// ---------------------------------------------------------------- server

/// A service an agent answers: requests `Req`, answers `Resp`.
pub struct Server<Req: Payload, Resp: Payload> {
    side: Arc<ServerSide<Req, Resp>>,
}

impl<Req: Payload, Resp: Payload> std::fmt::Debug for Server<Req, Resp> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Server").field("service", &self.side.service).field("type", &self.side.spec.type_name).finish()
    }
}

struct ServerLive<Req: Payload, Resp: Payload> {
    port: Mutex<IoxServer<Ipc, Req, (), Resp, ()>>,
    listener: Arc<Listener<Ipc>>,
    answered: Mutex<Notifier<Ipc>>,
    _factories: (Factory<Req, Resp>, event::PortFactory<Ipc>, event::PortFactory<Ipc>),
}

pub(crate) struct ServerSide<Req: Payload, Resp: Payload> {
    spec: PortSpec,
    service: String,
    live: Option<ServerLive<Req, Resp>>,
    answered: AtomicU64,
}

impl<Req: Payload, Resp: Payload> Server<Req, Resp> {
    /// Service `port` (iceoryx2 service `service`), bound to `binding`.
    pub(crate) fn bind(binding: &Binding, port: &str, service: &str) -> Result<(Self, Arc<dyn DynInput>), CallError> {
        let live = match binding {
            Binding::Nothing => None,
            Binding::Memory(_) => return Err(CallError::NotInHarness { port: port.into() }),
            Binding::Shm(node) => {
                let factory = crate::world::retry_after_cleanup(
                    node.config(),
                    "serve",
                    |e: &CallError| matches!(e, CallError::Open { .. }),
                    || call_service::<Req, Resp>(node, service, true),
                )?;
                let server = crate::world::retry_after_cleanup(
                    node.config(),
                    "serve",
                    |_| true,
                    || factory.server_builder().create(),
                )
                .map_err(|e| open_err(service, e))?;
                let requests = event_service(node, service, true)?;
                let listener = requests.listener_builder().create().map_err(|e| open_err(service, e))?;
                let answered_name = format!("{service}{ANSWERED_SUFFIX}");
                let answered = event_service(node, &answered_name, true)?;
                let notifier = answered.notifier_builder().create().map_err(|e| open_err(&answered_name, e))?;
                Some(ServerLive {
                    port: Mutex::new(server),
                    listener: Arc::new(listener),
                    answered: Mutex::new(notifier),
                    _factories: (factory, requests, answered),
                })
            }
        };
        let side = Arc::new(ServerSide {
            spec: call_spec::<Req, Resp>(port),
            service: service.into(),
            live,
            answered: AtomicU64::new(0),
        });
        Ok((Server { side: side.clone() }, side))
    }

    /// Answers each waiting request with `answer` (at most `max` of them:
    /// what arrives meanwhile is left for the next step, whose wake-up is
    /// pending); returns how many were answered.
    pub fn serve_up_to(&self, max: usize, mut answer: impl FnMut(&Req) -> Resp) -> Result<usize, CallError> {
        let Some(live) = &self.side.live else { return Ok(0) };
        let mut n = 0;
        {
            let port = lock(&live.port);
            while n < max {
                let request = match port.receive() {
                    Ok(Some(r)) => r,
                    Ok(None) => break,
                    Err(source) => {
                        return Err(CallError::Receive {
                            port: self.side.spec.name.clone(),
                            service: self.side.service.clone(),
                            source,
                        });
                    }
                };
                let response = answer(request.payload());
                if let Err(e) = request.send_copy(response) {
                    // the client went away: nobody waits for this answer
                    tracing::debug!(service = %self.side.service, "an answer found no client: {e:?}");
                }
                n += 1;
            }
        }
        if n > 0 {
            self.side.answered.fetch_add(n as u64, Ordering::Relaxed);
            if let Err(e) = lock(&live.answered).notify() {
                tracing::warn!(service = %self.side.service, "cannot wake the clients: {e:?}");
            }
        }
        Ok(n)
    }

    /// Answers every waiting request with `answer` (at most
    /// [`MAX_IN_FLIGHT`] per step); returns how many were answered.
    pub fn serve(&self, answer: impl FnMut(&Req) -> Resp) -> Result<usize, CallError> {
        self.serve_up_to(MAX_IN_FLIGHT, answer)
    }

    /// How many requests it answered so far.
    pub fn answered(&self) -> u64 {
        self.side.answered.load(Ordering::Relaxed)
    }

    /// The iceoryx2 service name.
    pub fn service(&self) -> &str {
        &self.side.service
    }
}

fn not_an_input(port: &str) -> PortError {
    PortError::Ipc {
        service: port.into(),
        detail: "a call port is wired to a service, never to an output: \
                 `nerve connect CLIENT_AGENT/CLIENT SERVER_AGENT/SERVICE`"
            .into(),
    }
}

impl<Req: Payload, Resp: Payload> DynInput for ServerSide<Req, Resp> {
    fn name(&self) -> &str {
        &self.spec.name
    }
    fn type_name(&self) -> &str {
        &self.spec.type_name
    }
    fn spec(&self) -> PortSpec {
        self.spec.clone()
    }
    fn payload_layout(&self) -> (usize, usize) {
        (std::mem::size_of::<Req>(), std::mem::align_of::<Req>())
    }
    fn connect(
        &self,
        _node: &Node<Ipc>,
        _robot: &shm_schemas::RobotName,
        _from_agent: &str,
        _from_port: &str,
    ) -> Result<bool, PortError> {
        Err(not_an_input(&self.spec.name))
    }
    fn disconnect(&self, _from_agent: &str, _from_port: &str) -> bool {
        false
    }
    fn listeners(&self) -> Vec<Arc<Listener<Ipc>>> {
        self.live.iter().map(|l| l.listener.clone()).collect()
    }
    fn stats(&self, _now: u64) -> Vec<InputStats> {
        Vec::new()
    }
    fn has_queued(&self) -> bool {
        false
    }
    fn queue(&self, _sender: &str, _port: &str, _sample: SampleBuf, _stamp_ns: u64) -> Result<(), PortError> {
        Err(not_an_input(&self.spec.name))
    }
}

// ---------------------------------------------------------------- client

/// A client: calls a service of requests `Req` answered by `Resp`, once
/// the router wired it to one.
pub struct Client<Req: Payload, Resp: Payload> {
    side: Arc<ClientSide<Req, Resp>>,
}

impl<Req: Payload, Resp: Payload> std::fmt::Debug for Client<Req, Resp> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client").field("name", &self.side.spec.name).field("type", &self.side.spec.type_name).finish()
    }
}

/// The service a client is wired to.
struct Target<Req: Payload, Resp: Payload> {
    agent: String,
    port: String,
    service: String,
    client: IoxClient<Ipc, Req, (), Resp, ()>,
    requests: Notifier<Ipc>,
    listener: Arc<Listener<Ipc>>,
    _factories: (Factory<Req, Resp>, event::PortFactory<Ipc>, event::PortFactory<Ipc>),
}

struct InFlight<Req: Payload, Resp: Payload> {
    id: CallId,
    deadline_ns: u64,
    service: String,
    pending: PendingResponse<Ipc, Req, (), Resp, ()>,
}

struct ClientState<Req: Payload, Resp: Payload> {
    target: Option<Target<Req, Resp>>,
    in_flight: Vec<InFlight<Req, Resp>>,
    done: VecDeque<(CallId, Result<Resp, CallError>)>,
    next_id: u64,
    answered: u64,
    last_answer_ns: Option<u64>,
}

pub(crate) struct ClientSide<Req: Payload, Resp: Payload> {
    spec: PortSpec,
    options: CallOptions,
    state: Mutex<ClientState<Req, Resp>>,
    _types: PhantomData<fn(Req) -> Resp>,
}

impl<Req: Payload, Resp: Payload> Client<Req, Resp> {
    /// Client `port` with `options`, bound to `binding` (it is wired later).
    pub(crate) fn bind(
        binding: &Binding,
        port: &str,
        options: CallOptions,
    ) -> Result<(Self, Arc<dyn DynInput>), CallError> {
        if matches!(binding, Binding::Memory(_)) {
            return Err(CallError::NotInHarness { port: port.into() });
        }
        let options =
            CallOptions { max_in_flight: options.max_in_flight.clamp(1, MAX_IN_FLIGHT), timeout: options.timeout };
        let side = Arc::new(ClientSide {
            spec: call_spec::<Req, Resp>(port),
            options,
            state: Mutex::new(ClientState {
                target: None,
                in_flight: Vec::new(),
                done: VecDeque::new(),
                next_id: 1,
                answered: 0,
                last_answer_ns: None,
            }),
            _types: PhantomData,
        });
        Ok((Client { side: side.clone() }, side))
    }

    /// Sends `request` to the service the client is wired to and returns
    /// at once; the answer (or why there is none) comes from
    /// [`Client::take`]. Refused, with nothing sent, when the client is not
    /// wired, when no server answers the service, or past the bound of
    /// calls in flight.
    pub fn call(&self, request: &Req) -> Result<CallId, CallError> {
        let name = &self.side.spec.name;
        let mut st = lock(&self.side.state);
        let st = &mut *st;
        let Some(t) = &st.target else { return Err(CallError::NotWired { client: name.clone() }) };
        if st.in_flight.len() >= self.side.options.max_in_flight {
            return Err(CallError::TooManyInFlight { client: name.clone(), max: self.side.options.max_in_flight });
        }
        let pending = t.client.send_copy(*request).map_err(|source| CallError::Send {
            client: name.clone(),
            service: t.service.clone(),
            source,
        })?;
        if pending.number_of_server_connections() == 0 {
            return Err(CallError::NoServer { client: name.clone(), service: t.service.clone() });
        }
        if let Err(e) = t.requests.notify() {
            tracing::warn!(client = %name, service = %t.service, "cannot wake the server: {e:?}");
        }
        let id = CallId(st.next_id);
        st.next_id = st.next_id.saturating_add(1);
        let deadline_ns = now_ns().saturating_add(crate::clock::nanos(self.side.options.timeout));
        st.in_flight.push(InFlight { id, deadline_ns, service: t.service.clone(), pending });
        Ok(id)
    }

    /// The next finished call, oldest first: its answer, or why there is
    /// none (a timeout, the server gone mid-call, the client unwired).
    /// `None` while no call has finished. Never blocks.
    pub fn take(&self) -> Option<(CallId, Result<Resp, CallError>)> {
        let mut st = lock(&self.side.state);
        self.side.settle(&mut st, now_ns());
        st.done.pop_front()
    }

    /// How many calls are in flight (sent, not yet finished).
    pub fn in_flight(&self) -> usize {
        lock(&self.side.state).in_flight.len()
    }

    /// Whether the client is wired to a service now.
    pub fn is_wired(&self) -> bool {
        lock(&self.side.state).target.is_some()
    }

    /// The client's settings.
    pub fn options(&self) -> CallOptions {
        self.side.options
    }
}

impl<Req: Payload, Resp: Payload> ClientSide<Req, Resp> {
    /// Moves every call that finished (answered, timed out, its server
    /// gone) from in flight to done.
    fn settle(&self, st: &mut ClientState<Req, Resp>, now: u64) {
        let name = &self.spec.name;
        let mut i = 0;
        while i < st.in_flight.len() {
            let f = &st.in_flight[i];
            let answer = |f: &InFlight<Req, Resp>| match f.pending.receive() {
                Ok(Some(r)) => Some(Ok(*r.payload())),
                Ok(None) => None,
                Err(source) => Some(Err(CallError::Receive { port: name.clone(), service: f.service.clone(), source })),
            };
            let outcome = match answer(f) {
                Some(o) => Some(o),
                // gone: look once more, the answer may have come just before the server let go
                None if !f.pending.is_connected() => Some(answer(f).unwrap_or_else(|| {
                    Err(CallError::ServerGone { client: name.clone(), service: f.service.clone() })
                })),
                None if now >= f.deadline_ns => Some(Err(CallError::TimedOut {
                    client: name.clone(),
                    service: f.service.clone(),
                    timeout: self.options.timeout,
                })),
                None => None,
            };
            match outcome {
                Some(o) => {
                    let f = st.in_flight.remove(i);
                    if o.is_ok() {
                        st.answered = st.answered.saturating_add(1);
                        st.last_answer_ns = Some(now);
                    }
                    st.done.push_back((f.id, o));
                }
                None => i += 1,
            }
        }
    }
}

impl<Req: Payload, Resp: Payload> DynInput for ClientSide<Req, Resp> {
    fn name(&self) -> &str {
        &self.spec.name
    }
    fn type_name(&self) -> &str {
        &self.spec.type_name
    }
    fn spec(&self) -> PortSpec {
        self.spec.clone()
    }
    fn payload_layout(&self) -> (usize, usize) {
        (std::mem::size_of::<Resp>(), std::mem::align_of::<Resp>())
    }

    /// Wires the client to service `from_port` of `from_agent`; one
    /// service at a time (a wire to another replaces it, its calls in
    /// flight finished as unwired).
    fn connect(
        &self,
        node: &Node<Ipc>,
        robot: &shm_schemas::RobotName,
        from_agent: &str,
        from_port: &str,
    ) -> Result<bool, PortError> {
        {
            let st = lock(&self.state);
            if st.target.as_ref().is_some_and(|t| t.agent == from_agent && t.port == from_port) {
                return Ok(false);
            }
        }
        let service = robot.port_service(from_agent, from_port);
        let wire = || -> Result<Target<Req, Resp>, CallError> {
            let factory = call_service::<Req, Resp>(node, &service, false)?;
            let client = factory.client_builder().create().map_err(|e| open_err(&service, e))?;
            let requests = event_service(node, &service, false)?;
            let notifier = requests.notifier_builder().create().map_err(|e| open_err(&service, e))?;
            let answered_name = format!("{service}{ANSWERED_SUFFIX}");
            let answered = event_service(node, &answered_name, true)?;
            let listener = answered.listener_builder().create().map_err(|e| open_err(&answered_name, e))?;
            Ok(Target {
                agent: from_agent.into(),
                port: from_port.into(),
                service: service.clone(),
                client,
                requests: notifier,
                listener: Arc::new(listener),
                _factories: (factory, requests, answered),
            })
        };
        let target = wire().map_err(|e| PortError::Ipc { service: service.clone(), detail: e.to_string() })?;
        let mut st = lock(&self.state);
        self.unwire(&mut st);
        st.target = Some(target);
        tracing::info!(client = %self.spec.name, service = %service, "client wired");
        Ok(true)
    }

    fn disconnect(&self, from_agent: &str, from_port: &str) -> bool {
        let mut st = lock(&self.state);
        if !st.target.as_ref().is_some_and(|t| t.agent == from_agent && t.port == from_port) {
            return false;
        }
        self.unwire(&mut st);
        true
    }

    fn listeners(&self) -> Vec<Arc<Listener<Ipc>>> {
        lock(&self.state).target.iter().map(|t| t.listener.clone()).collect()
    }

    fn stats(&self, now: u64) -> Vec<InputStats> {
        let st = lock(&self.state);
        st.target
            .iter()
            .map(|t| InputStats {
                input: self.spec.name.clone(),
                from_agent: t.agent.clone(),
                from_port: t.port.clone(),
                received: st.answered,
                rate_hz: 0.0,
                last_age_ns: st.last_answer_ns.map(|t| now.saturating_sub(t)),
                dropped: 0,
            })
            .collect()
    }

    fn has_queued(&self) -> bool {
        false
    }

    fn queue(&self, _sender: &str, _port: &str, _sample: SampleBuf, _stamp_ns: u64) -> Result<(), PortError> {
        Err(not_an_input(&self.spec.name))
    }
}

impl<Req: Payload, Resp: Payload> ClientSide<Req, Resp> {
    /// Drops the wire; the calls in flight finish as [`CallError::Unwired`].
    fn unwire(&self, st: &mut ClientState<Req, Resp>) {
        self.settle(st, now_ns());
        for f in st.in_flight.drain(..) {
            st.done.push_back((f.id, Err(CallError::Unwired { client: self.spec.name.clone(), service: f.service })));
        }
        if let Some(t) = st.target.take() {
            tracing::info!(client = %self.spec.name, service = %t.service, "client unwired");
        }
    }
}

/// The call ports an agent declared, for its registration and description.
#[derive(Debug, Default, Clone)]
pub(crate) struct Declared {
    pub(crate) services: Vec<PortSpec>,
    pub(crate) clients: Vec<PortSpec>,
}

impl Declared {
    pub(crate) fn add_service<Req: Payload, Resp: Payload>(
        &mut self,
        port: &str,
        schemas: &mut Vec<shm_schemas::Schema>,
    ) {
        self.services.push(call_spec::<Req, Resp>(port));
        add_schemas::<Req, Resp>(schemas);
    }

    pub(crate) fn add_client<Req: Payload, Resp: Payload>(
        &mut self,
        port: &str,
        schemas: &mut Vec<shm_schemas::Schema>,
    ) {
        self.clients.push(call_spec::<Req, Resp>(port));
        add_schemas::<Req, Resp>(schemas);
    }

    /// Whether `port` is a call port (so not an input).
    pub(crate) fn is_call(&self, port: &str) -> bool {
        self.services.iter().chain(&self.clients).any(|p| p.name == port)
    }
}

fn add_schemas<Req: Payload, Resp: Payload>(schemas: &mut Vec<shm_schemas::Schema>) {
    use shm_schemas::control::agent_to_router::add_schema;
    add_schema(schemas, Req::schema());
    add_schema(schemas, Resp::schema());
}

// ---------------------------------------------------------------- tools

type RawClientPort =
    IoxClient<Ipc, [CustomPayloadMarker], CustomHeaderMarker, [CustomPayloadMarker], CustomHeaderMarker>;
type RawFactory = request_response::PortFactory<
    Ipc,
    [CustomPayloadMarker],
    CustomHeaderMarker,
    [CustomPayloadMarker],
    CustomHeaderMarker,
>;

/// A call made by a tool that was not built with the call's types
/// (`nerve call`): requests and answers as bytes of the layouts the
/// service itself says, one call at a time, waited for.
pub struct RawCaller {
    service: String,
    type_name: String,
    fingerprint: Option<u64>,
    request_size: usize,
    response_size: usize,
    client: RawClientPort,
    requests: Notifier<Ipc>,
    answered: Listener<Ipc>,
    _factories: (RawFactory, event::PortFactory<Ipc>, event::PortFactory<Ipc>),
}

impl std::fmt::Debug for RawCaller {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawCaller").field("service", &self.service).field("type", &self.type_name).finish()
    }
}

/// Whether `detail` is a layout nerve makes (the bounds of a schema's).
fn sane(detail: &iceoryx2::service::static_config::message_type_details::TypeDetail) -> bool {
    let align = detail.alignment();
    align.is_power_of_two() && align <= shm_schemas::schema::MAX_ALIGN && detail.size() <= shm_schemas::schema::MAX_SIZE
}

impl RawCaller {
    /// Opens the existing call service `service` with the request and
    /// response layouts it was made with (never creates it).
    pub fn open(node: &Node<Ipc>, service: &str) -> Result<Self, CallError> {
        use iceoryx2::service::attribute::AttributeKey;
        use shm_schemas::services::port_attributes;
        let name = service_name(service)?;
        let details = <Ipc as iceoryx2::service::Service>::details(
            &name,
            node.config(),
            iceoryx2::service::messaging_pattern::MessagingPattern::RequestResponse,
        )
        .map_err(|e| open_err(service, e))?
        .ok_or_else(|| CallError::Open {
            service: service.into(),
            detail: "no agent offers it (is the server running, and is the name right? `nerve ps` lists the services)"
                .into(),
        })?;
        let attrs = details.static_details.attributes();
        let get = |key: &str| {
            let key = AttributeKey::try_from(key).ok()?;
            attrs.key_value(&key, 0).map(|v| v.to_string())
        };
        let type_name = get(port_attributes::TYPE).ok_or_else(|| CallError::Open {
            service: service.into(),
            detail: "it has no nerve type attribute: not a service of a nerve agent".into(),
        })?;
        let fingerprint = get(port_attributes::FINGERPRINT).and_then(|t| port_attributes::parse_fingerprint(&t));
        let config = details.static_details.request_response();
        let (req, resp) = (config.request_message_type_details(), config.response_message_type_details());
        if !sane(&req.payload) || !sane(&resp.payload) || !sane(&req.user_header) || !sane(&resp.user_header) {
            return Err(CallError::Open {
                service: service.into(),
                detail: "its layouts are not ones nerve makes; the process that created it is not a nerve agent".into(),
            });
        }
        // SAFETY: the payloads' and user headers' type details are the
        // service's own, read just above and bounded; requests are written
        // and answers read as bytes of exactly those sizes.
        let builder = unsafe {
            node.service_builder(&name)
                .request_response::<[CustomPayloadMarker], [CustomPayloadMarker]>()
                .request_user_header::<CustomHeaderMarker>()
                .response_user_header::<CustomHeaderMarker>()
                .__internal_set_request_header_type_details(&req.user_header)
                .__internal_set_response_header_type_details(&resp.user_header)
                .__internal_set_request_payload_type_details(&req.payload)
                .__internal_set_response_payload_type_details(&resp.payload)
        };
        let factory = call_settings!(builder).open().map_err(|e| open_err(service, e))?;
        let client = factory.client_builder().create().map_err(|e| open_err(service, e))?;
        let requests = event_service(node, service, false)?;
        let notifier = requests.notifier_builder().create().map_err(|e| open_err(service, e))?;
        let answered_name = format!("{service}{ANSWERED_SUFFIX}");
        let answered = event_service(node, &answered_name, true)?;
        let listener = answered.listener_builder().create().map_err(|e| open_err(&answered_name, e))?;
        Ok(RawCaller {
            service: service.into(),
            type_name,
            fingerprint,
            request_size: req.payload.size(),
            response_size: resp.payload.size(),
            client,
            requests: notifier,
            answered: listener,
            _factories: (factory, requests, answered),
        })
    }

    /// The call's type name, `call(Req -> Resp)`, as the service says.
    pub fn type_name(&self) -> &str {
        &self.type_name
    }

    /// The call's fingerprint ([`shm_schemas::control::call::call_fingerprint`]), if the service says.
    pub fn fingerprint(&self) -> Option<u64> {
        self.fingerprint
    }

    /// Sends `request` (exactly the request's size) and waits at most
    /// `timeout` for the answer, returned as bytes.
    pub fn call(&self, request: &[u8], timeout: Duration) -> Result<Vec<u8>, CallError> {
        let client = "nerve call".to_owned();
        let service = self.service.clone();
        if request.len() != self.request_size {
            return Err(CallError::Open {
                service,
                detail: format!("a {}-byte request for a {}-byte request type", request.len(), self.request_size),
            });
        }
        // SAFETY: one element of a FixedSize request type (set from the
        // service's details in `open`): `request_size` bytes
        let mut loan = unsafe { self.client.loan_custom_payload(1) }.map_err(|e| CallError::Open {
            service: service.clone(),
            detail: format!("cannot loan a request: {e:?}"),
        })?;
        let payload = loan.payload_mut();
        if payload.len() != request.len() {
            return Err(CallError::Open {
                service,
                detail: format!("loaned {} bytes for a {}-byte request", payload.len(), request.len()),
            });
        }
        // SAFETY: `payload` is `request.len()` writable one-byte elements, not overlapping `request`
        unsafe { std::ptr::copy_nonoverlapping(request.as_ptr(), payload.as_mut_ptr().cast::<u8>(), request.len()) };
        // SAFETY: every byte of the payload was written just above
        let pending = unsafe { loan.assume_init() }.send().map_err(|source| CallError::Send {
            client: client.clone(),
            service: service.clone(),
            source,
        })?;
        if pending.number_of_server_connections() == 0 {
            return Err(CallError::NoServer { client, service });
        }
        if let Err(e) = self.requests.notify() {
            tracing::warn!(service = %self.service, "cannot wake the server: {e:?}");
        }
        let deadline = std::time::Instant::now() + timeout;
        loop {
            match pending.receive() {
                Ok(Some(r)) => {
                    let bytes = super::bytes::payload_bytes(r.payload());
                    if bytes.len() != self.response_size {
                        return Err(CallError::Open {
                            service,
                            detail: format!("a {}-byte answer of a {}-byte type", bytes.len(), self.response_size),
                        });
                    }
                    return Ok(bytes.to_vec());
                }
                Ok(None) => {}
                Err(source) => return Err(CallError::Receive { port: client, service, source }),
            }
            if !pending.is_connected() {
                if let Ok(Some(r)) = pending.receive() {
                    return Ok(super::bytes::payload_bytes(r.payload()).to_vec());
                }
                return Err(CallError::ServerGone { client, service });
            }
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return Err(CallError::TimedOut { client, service, timeout });
            }
            // woken by the server's answer; at most 50 ms, to see a server gone
            let _ = self.answered.timed_wait(|_| {}, left.min(Duration::from_millis(50)));
        }
    }
}
