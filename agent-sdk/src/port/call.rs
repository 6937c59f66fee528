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
//!
//! One machinery carries every kind of call ([`Kind`]): Rust types
//! ([`Typed`]) answered with a fixed-size `Resp` ([`Fixed`]: [`Server`],
//! [`Client`]) or a sequence of any length (`call_seq`:
//! [`super::SeqServer`], [`super::SeqClient`]), and calls declared by
//! layout at run time, answered either way (`schema_call`: the Python and
//! C agents' [`super::schema_call::SchemaServer`]). This file
//! holds what they share (errors, settings, the services); the server is
//! in `call_server`, the client in `call_client`, `nerve call`'s
//! byte-level caller in `call_raw`.

use super::service::{MAX_SUBSCRIBERS, port_attributes_of};
use crate::world::Ipc;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::ReceiveError;
use iceoryx2::port::client::Client as IoxClient;
use iceoryx2::port::server::Server as IoxServer;
use iceoryx2::prelude::*;
use iceoryx2::response::Response;
use iceoryx2::service::attribute::AttributeVerifier;
use iceoryx2::service::builder::request_response::RequestResponseOpenOrCreateError;
use iceoryx2::service::port_factory::server::ServerCreateError;
use iceoryx2::service::port_factory::{event, request_response};
use shm_schemas::Payload;
use shm_schemas::control::agent_to_router::PortSpec;
pub use shm_schemas::control::call::call_spec;
use std::marker::PhantomData;
use std::time::Duration;

// in port/ beside this file: the harness's half of calls
#[path = "call_memory.rs"]
pub(crate) mod memory;

pub use super::call_client::{CallClient, Client};
pub use super::call_raw::RawCaller;
pub use super::call_server::{CallServer, Server};

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
            .max_active_requests_per_client($crate::port::call::MAX_IN_FLIGHT)
            .max_clients($crate::port::call::MAX_CLIENTS)
            // a restarted server's port is made while its dead predecessor's may still count
            .max_servers(2)
            .max_nodes($crate::port::call::MAX_CLIENTS + 4)
            .max_response_buffer_size(2)
            .enable_safe_overflow_for_requests(true)
            .enable_safe_overflow_for_responses(true)
    };
}

pub(crate) use call_settings;

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
    /// A server's answer was longer than its service's declared maximum:
    /// nothing was sent but a refusal, which its client takes as
    /// [`CallError::RefusedTooLong`].
    #[error(
        "service {service}: an answer of {len} elements is longer than the {max} the service was declared with \
         (`serve_seq(port, max_len)`); the client was told so and got no answer; declare a larger max_len or \
         answer with fewer elements"
    )]
    AnswerTooLong {
        /// the service
        service: String,
        /// the answer's length
        len: usize,
        /// the declared maximum
        max: usize,
    },
    /// The server refused to answer: its answer was longer than the
    /// service's declared maximum ([`CallError::AnswerTooLong`] on its side).
    #[error(
        "client {client}: the server of {service} refused its answer of {len} elements, longer than the {max} it \
         was declared with; ask for less, or have the server declare a larger max_len"
    )]
    RefusedTooLong {
        /// the client's name
        client: String,
        /// the service
        service: String,
        /// the refused answer's length
        len: u64,
        /// the declared maximum
        max: u64,
    },
    /// iceoryx2 could not loan the memory of an answer.
    #[error("service {service}: cannot loan the memory of an answer of {len} elements: {source:?}")]
    Loan {
        /// the service
        service: String,
        /// the answer's length
        len: usize,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::LoanError,
    },
    /// An answer that is not what its type says (a sequence answer whose
    /// bytes are not a header and whole elements): a peer of another build.
    #[error("client {client}: a malformed answer from {service}: {detail}; rebuild the older side and restart it")]
    Malformed {
        /// the client's name
        client: String,
        /// the service
        service: String,
        /// what is wrong
        detail: String,
    },
    /// Calls are not carried by this binding. No binding of nerve's
    /// refuses calls any more (the test harness carries them); kept so
    /// that code matching it still builds.
    #[error("call port {port}: calls are not carried here; test calls with `agent_sdk::testing::Harness`")]
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

pub(crate) fn open_err(service: &str, detail: impl std::fmt::Debug) -> CallError {
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

/// The iceoryx2 service of a call of kind `K`.
pub(crate) type Factory<K> = request_response::PortFactory<
    Ipc,
    <K as Kind>::ReqPayload,
    <K as Kind>::ReqHeader,
    <K as Kind>::Payload,
    <K as Kind>::Header,
>;
/// A server port of a call of kind `K`.
pub(crate) type ServerPort<K> =
    IoxServer<Ipc, <K as Kind>::ReqPayload, <K as Kind>::ReqHeader, <K as Kind>::Payload, <K as Kind>::Header>;
/// A client port of a call of kind `K`.
pub(crate) type ClientPort<K> =
    IoxClient<Ipc, <K as Kind>::ReqPayload, <K as Kind>::ReqHeader, <K as Kind>::Payload, <K as Kind>::Header>;
/// A request as the server holds it while it answers.
pub(crate) type ActiveRequest<K> = iceoryx2::active_request::ActiveRequest<
    Ipc,
    <K as Kind>::ReqPayload,
    <K as Kind>::ReqHeader,
    <K as Kind>::Payload,
    <K as Kind>::Header,
>;
/// A call in flight, as its client holds it.
pub(crate) type Pending<K> =
    PendingResponse<Ipc, <K as Kind>::ReqPayload, <K as Kind>::ReqHeader, <K as Kind>::Payload, <K as Kind>::Header>;

/// An answer as its client holds it until taken: the response sample in
/// the server's shared memory.
pub(crate) type Answered<K> = Response<Ipc, <K as Kind>::Payload, <K as Kind>::Header>;
/// A received response of an answer travelling as `A` says.
pub(crate) type Received<A> = Response<Ipc, <A as Answer>::Payload, <A as Answer>::Header>;

/// The kind of a call: its request and how its answer travels, as the
/// generic server ([`CallServer`]) and client ([`CallClient`]) need them.
/// Either Rust types ([`Typed`]: a request `Req` and an [`Answer`]) or
/// layouts learnt at run time (`schema_call::Layout`: calls declared by
/// layout, for Python and C agents), which is why it is a value: a
/// layout's kind carries its schemas. Implemented by nerve only.
pub trait Kind: Send + Sync + 'static {
    /// The iceoryx2 request payload.
    type ReqPayload: ?Sized + std::fmt::Debug + IceoryxSend + 'static;
    /// The iceoryx2 request user header.
    type ReqHeader: std::fmt::Debug + ZeroCopySend + 'static;
    /// The iceoryx2 response payload.
    type Payload: ?Sized + std::fmt::Debug + IceoryxSend + 'static;
    /// The iceoryx2 response user header.
    type Header: std::fmt::Debug + ZeroCopySend + 'static;
    /// What a client's `call` sends.
    type Request: ?Sized;
    /// A request as the test harness queues it.
    type Queued: Send + 'static;
    /// What the client's `take` hands out for an answer.
    type Value: Send + 'static;
    /// An answer as the client's `take_with` reads it, in place.
    type View<'a>;
    /// The spec of call port `port` of this kind (its call type and fingerprint).
    fn spec(&self, port: &str) -> PortSpec;
    /// Adds the schemas of the request and the answer to an agent's registration.
    fn add_schemas(&self, schemas: &mut Vec<shm_schemas::Schema>);
    /// The size and alignment of the request.
    fn request_layout(&self) -> (usize, usize);
    /// The size and alignment of the answer (its fixed part).
    fn answer_layout(&self) -> (usize, usize);
    /// Opens (`create`: or creates) the call service `name` with `attributes`.
    fn open(
        &self,
        node: &Node<Ipc>,
        name: &ServiceName,
        attributes: &AttributeVerifier,
        create: bool,
    ) -> Result<Factory<Self>, RequestResponseOpenOrCreateError>;
    /// A server port of `factory`, whose answers hold at most `max_len` elements.
    fn server(&self, factory: &Factory<Self>, max_len: usize) -> Result<ServerPort<Self>, ServerCreateError>;
    /// The next request waiting at `port`, if any.
    fn next_request(&self, port: &ServerPort<Self>) -> Result<Option<ActiveRequest<Self>>, ReceiveError>;
    /// Sends `request` through `port`, for client `client` of `service`.
    fn send(
        &self,
        port: &ClientPort<Self>,
        request: &Self::Request,
        client: &str,
        service: &str,
    ) -> Result<Pending<Self>, CallError>;
    /// `request` as the test harness queues it, or why it is not one (for `client`).
    fn queued(&self, request: &Self::Request, client: &str) -> Result<Self::Queued, CallError>;
    /// The answer that came for `pending`, if any.
    fn next_answer(&self, pending: &Pending<Self>) -> Result<Option<Answered<Self>>, ReceiveError>;
    /// The answer `response` holds, read in place in its shared memory,
    /// for client `client` of `service`; or why it is none (a refusal, a
    /// malformed answer).
    fn view<'a>(&self, response: &'a Answered<Self>, client: &str, service: &str) -> Result<Self::View<'a>, CallError>;
    /// An answer the test harness holds as a value, as a view.
    fn view_of<'a>(&self, value: &'a Self::Value) -> Self::View<'a>;
    /// A view copied out: what the client's `take` hands out.
    fn to_value(&self, view: Self::View<'_>) -> Self::Value;
}

/// A call of Rust types: requests `Req` answered as `A` says
/// ([`Fixed`], `call_seq::SeqAnswer`).
pub struct Typed<Req, A>(PhantomData<fn() -> (Req, A)>);

impl<Req: Payload, A> std::fmt::Debug for Typed<Req, A> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Typed<{}>", Req::stable_type_name())
    }
}

impl<Req, A> Default for Typed<Req, A> {
    fn default() -> Self {
        Typed(PhantomData)
    }
}

impl<Req: Payload, A: Answer> Kind for Typed<Req, A> {
    type ReqPayload = Req;
    type ReqHeader = ();
    type Payload = A::Payload;
    type Header = A::Header;
    type Request = Req;
    type Queued = Req;
    type Value = A::Value;
    type View<'a> = A::View<'a>;
    fn spec(&self, port: &str) -> PortSpec {
        A::spec::<Req>(port)
    }
    fn add_schemas(&self, schemas: &mut Vec<shm_schemas::Schema>) {
        shm_schemas::control::agent_to_router::add_schema(schemas, Req::schema());
        A::add_schemas(schemas);
    }
    fn request_layout(&self) -> (usize, usize) {
        (std::mem::size_of::<Req>(), std::mem::align_of::<Req>())
    }
    fn answer_layout(&self) -> (usize, usize) {
        A::layout()
    }
    fn open(
        &self,
        node: &Node<Ipc>,
        name: &ServiceName,
        attributes: &AttributeVerifier,
        create: bool,
    ) -> Result<Factory<Self>, RequestResponseOpenOrCreateError> {
        A::open::<Req>(node, name, attributes, create)
    }
    fn server(&self, factory: &Factory<Self>, max_len: usize) -> Result<ServerPort<Self>, ServerCreateError> {
        A::server::<Req>(factory, max_len)
    }
    fn next_request(&self, port: &ServerPort<Self>) -> Result<Option<ActiveRequest<Self>>, ReceiveError> {
        port.receive()
    }
    fn send(
        &self,
        port: &ClientPort<Self>,
        request: &Req,
        client: &str,
        service: &str,
    ) -> Result<Pending<Self>, CallError> {
        port.send_copy(*request).map_err(|source| CallError::Send {
            client: client.into(),
            service: service.into(),
            source,
        })
    }
    fn queued(&self, request: &Req, _client: &str) -> Result<Req, CallError> {
        Ok(*request)
    }
    fn next_answer(&self, pending: &Pending<Self>) -> Result<Option<Answered<Self>>, ReceiveError> {
        A::next_answer::<Req>(pending)
    }
    fn view<'a>(&self, response: &'a Answered<Self>, client: &str, service: &str) -> Result<A::View<'a>, CallError> {
        A::view(response, client, service)
    }
    fn view_of<'a>(&self, value: &'a A::Value) -> A::View<'a> {
        A::view_of(value)
    }
    fn to_value(&self, view: A::View<'_>) -> A::Value {
        A::to_value(view)
    }
}

/// How a call's answer travels: a fixed-size payload ([`Fixed`]) or a
/// sequence (`call_seq::SeqAnswer`). It names the iceoryx2 response
/// payload and user header, types the port for the router, and turns a
/// received response into what the client reads in place and what its
/// `take` hands out. Implemented by nerve only.
pub trait Answer: Sized + Send + Sync + 'static {
    /// The iceoryx2 response payload.
    type Payload: ?Sized + std::fmt::Debug + IceoryxSend + 'static;
    /// The iceoryx2 response user header.
    type Header: std::fmt::Debug + ZeroCopySend + Default + 'static;
    /// What the client's `take` hands out for an answer.
    type Value: Send + 'static;
    /// An answer as the client's `take_with` reads it, in place.
    type View<'a>;
    /// The spec of call port `port` of requests `Req` answered this way.
    fn spec<Req: Payload>(port: &str) -> PortSpec;
    /// Adds the schemas of the answer to an agent's registration.
    fn add_schemas(schemas: &mut Vec<shm_schemas::Schema>);
    /// The size and alignment of the answer (its fixed part).
    fn layout() -> (usize, usize);
    /// Opens (`create`: or creates) the call service `name` with `attributes`.
    fn open<Req: Payload>(
        node: &Node<Ipc>,
        name: &ServiceName,
        attributes: &AttributeVerifier,
        create: bool,
    ) -> Result<Factory<Typed<Req, Self>>, RequestResponseOpenOrCreateError>;
    /// A server port of `factory`, whose answers hold at most `max_len` elements.
    fn server<Req: Payload>(
        factory: &Factory<Typed<Req, Self>>,
        max_len: usize,
    ) -> Result<ServerPort<Typed<Req, Self>>, ServerCreateError>;
    /// The answer that came for `pending`, if any.
    fn next_answer<Req: Payload>(pending: &Pending<Typed<Req, Self>>) -> Result<Option<Received<Self>>, ReceiveError>;
    /// The answer `response` holds, read in place, for client `client` of
    /// `service`; or why it is none.
    fn view<'a>(response: &'a Received<Self>, client: &str, service: &str) -> Result<Self::View<'a>, CallError>;
    /// An answer the test harness holds as a value, as a view.
    fn view_of(value: &Self::Value) -> Self::View<'_>;
    /// A view copied out: what the client's `take` hands out.
    fn to_value(view: Self::View<'_>) -> Self::Value;
}

/// A fixed-size answer `Resp`: the call of [`Server`] and [`Client`].
pub struct Fixed<Resp>(PhantomData<fn() -> Resp>);

impl<Resp: Payload> std::fmt::Debug for Fixed<Resp> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Fixed<{}>", Resp::stable_type_name())
    }
}

impl<Resp: Payload> Answer for Fixed<Resp> {
    type Payload = Resp;
    type Header = ();
    type Value = Resp;
    type View<'a> = &'a Resp;
    fn spec<Req: Payload>(port: &str) -> PortSpec {
        call_spec::<Req, Resp>(port)
    }
    fn add_schemas(schemas: &mut Vec<shm_schemas::Schema>) {
        shm_schemas::control::agent_to_router::add_schema(schemas, Resp::schema());
    }
    fn layout() -> (usize, usize) {
        (std::mem::size_of::<Resp>(), std::mem::align_of::<Resp>())
    }
    fn open<Req: Payload>(
        node: &Node<Ipc>,
        name: &ServiceName,
        attributes: &AttributeVerifier,
        create: bool,
    ) -> Result<Factory<Typed<Req, Self>>, RequestResponseOpenOrCreateError> {
        let builder = call_settings!(node.service_builder(name).request_response::<Req, Resp>());
        if create {
            builder.open_or_create_with_attributes(attributes)
        } else {
            builder.open_with_attributes(attributes).map_err(RequestResponseOpenOrCreateError::RequestResponseOpenError)
        }
    }
    fn server<Req: Payload>(
        factory: &Factory<Typed<Req, Self>>,
        _max_len: usize,
    ) -> Result<ServerPort<Typed<Req, Self>>, ServerCreateError> {
        factory.server_builder().create()
    }
    fn next_answer<Req: Payload>(
        pending: &Pending<Typed<Req, Self>>,
    ) -> Result<Option<Response<Ipc, Resp, ()>>, ReceiveError> {
        pending.receive()
    }
    fn view<'a>(response: &'a Response<Ipc, Resp, ()>, _client: &str, _service: &str) -> Result<&'a Resp, CallError> {
        Ok(response.payload())
    }
    fn view_of(value: &Resp) -> &Resp {
        value
    }
    fn to_value(view: &Resp) -> Resp {
        *view
    }
}

pub(crate) fn service_name(service: &str) -> Result<ServiceName, CallError> {
    service.try_into().map_err(|e| open_err(service, e))
}

/// Opens (`create` true: or creates) the event service `name`.
pub(crate) fn event_service(node: &Node<Ipc>, name: &str, create: bool) -> Result<event::PortFactory<Ipc>, CallError> {
    let sn = service_name(name)?;
    let b = node
        .service_builder(&sn)
        .event()
        .max_listeners(MAX_SUBSCRIBERS + 4)
        .max_notifiers(MAX_CLIENTS + 4)
        .max_nodes(MAX_CLIENTS + 4);
    if create { b.open_or_create().map_err(|e| open_err(name, e)) } else { b.open().map_err(|e| open_err(name, e)) }
}

/// The call service `service` of kind `kind`, with the attributes of its
/// call type; created only by the server (`create`).
pub(crate) fn call_service<K: Kind>(
    node: &Node<Ipc>,
    kind: &K,
    service: &str,
    create: bool,
) -> Result<Factory<K>, CallError> {
    use iceoryx2::service::builder::request_response::{
        RequestResponseOpenError as Open, RequestResponseOpenOrCreateError as OpenOrCreate,
    };
    let spec = kind.spec("");
    let attributes =
        port_attributes_of(service, &spec.type_name, spec.fingerprint).map_err(|e| open_err(service, e))?;
    let name = service_name(service)?;
    for _attempt in 0..50 {
        match kind.open(node, &name, &attributes, create) {
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
                        "it is not a call of {} (another request or answer type or layout, or another build \
                         of them); declare the same types on both sides, rebuild the older side and restart it",
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

/// The call ports an agent declared, for its registration and description.
#[derive(Debug, Default, Clone)]
pub(crate) struct Declared {
    pub(crate) services: Vec<PortSpec>,
    pub(crate) clients: Vec<PortSpec>,
    /// in the test harness: the call ports' in-memory queues
    pub(crate) memory: Vec<memory::MemCallPort>,
}

impl Declared {
    pub(crate) fn add_service<Req: Payload, A: Answer>(&mut self, port: &str, schemas: &mut Vec<shm_schemas::Schema>) {
        self.add(&Typed::<Req, A>::default(), port, true, schemas);
    }

    pub(crate) fn add_client<Req: Payload, A: Answer>(&mut self, port: &str, schemas: &mut Vec<shm_schemas::Schema>) {
        self.add(&Typed::<Req, A>::default(), port, false, schemas);
    }

    /// Declares call port `port` of `kind`: a service (`service`) or a client.
    pub(crate) fn add<K: Kind>(&mut self, kind: &K, port: &str, service: bool, schemas: &mut Vec<shm_schemas::Schema>) {
        let list = if service { &mut self.services } else { &mut self.clients };
        list.push(kind.spec(port));
        kind.add_schemas(schemas);
    }

    /// Remembers the in-memory queues of a call port bound in the harness.
    pub(crate) fn add_memory(&mut self, port: Option<memory::MemCallPort>) {
        self.memory.extend(port);
    }

    /// Whether `port` is a call port (so not an input).
    pub(crate) fn is_call(&self, port: &str) -> bool {
        self.services.iter().chain(&self.clients).any(|p| p.name == port)
    }
}

// in port/ beside this file: calls answered and read in place, over iceoryx2
#[cfg(test)]
#[path = "call_tests.rs"]
mod tests;
