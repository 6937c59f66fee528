//! Calls declared by layout instead of Rust type, for agents that learn
//! their types at run time (the Python agents): a [`SchemaServer`] and a
//! [`SchemaClient`] carry requests and fixed-size answers as bytes of the
//! layouts two [`Schema`]s describe. They make and open the very iceoryx2
//! service a typed [`super::Server`] of Rust types of those layouts makes
//! (the same type details, attributes and events), so a Python client
//! calls a Rust server, a Rust client or `nerve call` calls a Python one,
//! and the router types them with the same call spec
//! ([`shm_schemas::control::call`]).
//!
//! Requests are copied in and answers copied out (calls are small and
//! rare next to a port's samples); the rest is the typed call's: a request
//! wakes the server's task like an input, a client never blocks, each call
//! ends answered, timed out, its server gone or unwired, and past the bound
//! of calls in flight a call is refused with nothing sent.

use super::bytes::{Binding, DynInput, payload_bytes};
use super::call::memory::{MemCallPort, MemClient, MemServer, Unanswered};
use super::call::{
    ANSWERED_SUFFIX, CallError, CallId, CallOptions, MAX_IN_FLIGHT, call_settings, event_service, open_err,
    service_name,
};
use super::error::PortError;
use super::memory::SampleBuf;
use super::service::{lock, port_attributes_of};
use crate::agent::{AgentError, Setup};
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
use iceoryx2::service::static_config::message_type_details::{TypeDetail, TypeVariant};
use shm_schemas::Schema;
use shm_schemas::control::agent_to_router::{PortSpec, add_schema};
use shm_schemas::control::call::{call_fingerprint, call_type_name};
use shm_schemas::stats::InputStats;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

type Markers = [CustomPayloadMarker];
type RawFactory = request_response::PortFactory<Ipc, Markers, CustomHeaderMarker, Markers, CustomHeaderMarker>;
type RawServerPort = IoxServer<Ipc, Markers, CustomHeaderMarker, Markers, CustomHeaderMarker>;
type RawClientPort = IoxClient<Ipc, Markers, CustomHeaderMarker, Markers, CustomHeaderMarker>;
type RawPending = PendingResponse<Ipc, Markers, CustomHeaderMarker, Markers, CustomHeaderMarker>;

/// The request and answer layouts of a call, checked, and its spec.
#[derive(Debug, Clone)]
struct Layouts {
    request: Schema,
    response: Schema,
    spec: PortSpec,
}

impl Layouts {
    /// Checks both layouts (from outside: valid, of a fixed size) and types the call port `port`.
    fn of(port: &str, request: Schema, response: Schema) -> Result<Self, CallError> {
        for (what, s) in [("request", &request), ("answer", &response)] {
            let refused = |detail: String| CallError::Open { service: port.into(), detail };
            s.validate().map_err(|e| refused(format!("its {what} layout {}: {e}", s.type_name)))?;
            if s.sequence_shape().is_some() {
                return Err(refused(format!(
                    "its {what} {} is a sequence: a call declared by layout takes fixed-size requests and answers",
                    s.type_name
                )));
            }
        }
        let spec = PortSpec {
            name: port.into(),
            type_name: call_type_name(&request.type_name, &response.type_name),
            fingerprint: call_fingerprint(request.fingerprint(), response.fingerprint()),
        };
        Ok(Layouts { request, response, spec })
    }

    /// The iceoryx2 type details a Rust type of `schema`'s layout has.
    fn detail(service: &str, schema: &Schema) -> Result<TypeDetail, CallError> {
        TypeDetail::__internal_new_from_parts(TypeVariant::FixedSize, &schema.type_name, schema.size, schema.align)
            .map_err(|e| open_err(service, e))
    }

    /// Opens (`create`: or creates) the call service `service`, with the
    /// type details and attributes a typed call of these layouts has.
    fn open(&self, node: &Node<Ipc>, service: &str, create: bool) -> Result<RawFactory, CallError> {
        use iceoryx2::service::builder::request_response::{
            RequestResponseOpenError as Open, RequestResponseOpenOrCreateError as OpenOrCreate,
        };
        let attributes = port_attributes_of(service, &self.spec.type_name, self.spec.fingerprint)
            .map_err(|e| open_err(service, e))?;
        let name = service_name(service)?;
        let (request, response) = (Self::detail(service, &self.request)?, Self::detail(service, &self.response)?);
        // a typed call's user headers are `()`
        let unit = TypeDetail::new::<()>(TypeVariant::FixedSize);
        for _attempt in 0..50 {
            // SAFETY: the payloads' details are those of a `#[repr(C)]` type
            // of these layouts (checked in `Layouts::of`), the headers `()`'s;
            // requests are written and answers read as bytes of exactly the
            // layouts' sizes, and the headers (0 bytes) are never touched.
            let builder = unsafe {
                node.service_builder(&name)
                    .request_response::<Markers, Markers>()
                    .request_user_header::<CustomHeaderMarker>()
                    .response_user_header::<CustomHeaderMarker>()
                    .__internal_set_request_header_type_details(&unit)
                    .__internal_set_response_header_type_details(&unit)
                    .__internal_set_request_payload_type_details(&request)
                    .__internal_set_response_payload_type_details(&response)
            };
            let builder = call_settings!(builder);
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
                            "it is not a call of {} (another request or answer layout); declare the same layouts \
                             on both sides",
                            self.spec.type_name
                        ),
                    });
                }
                Err(OpenOrCreate::RequestResponseOpenError(Open::IsMarkedForDestruction)) => {
                    std::thread::sleep(Duration::from_millis(10));
                }
                Err(e) => return Err(open_err(service, e)),
            }
        }
        Err(CallError::Open {
            service: service.into(),
            detail: "its last owner is still removing it; try again".into(),
        })
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

// ---------------------------------------------------------------- server

/// A service an agent answers, declared by layout ([`Setup::serve_of`]).
pub struct SchemaServer {
    side: Arc<ServerSide>,
}

impl std::fmt::Debug for SchemaServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SchemaServer")
            .field("service", &self.side.service)
            .field("type", &self.side.layouts.spec.type_name)
            .finish()
    }
}

struct ServerLive {
    port: Mutex<RawServerPort>,
    listener: Arc<Listener<Ipc>>,
    answered: Mutex<Notifier<Ipc>>,
    _factories: (RawFactory, event::PortFactory<Ipc>, event::PortFactory<Ipc>),
}

struct ServerSide {
    layouts: Layouts,
    service: String,
    live: Option<ServerLive>,
    /// in the test harness: the requests (bytes) waiting for the step
    mem: Option<Arc<MemServer<Vec<u8>, Vec<u8>>>>,
    answered: AtomicU64,
}

/// Why an answer was not sent: the call's error, or the answering function's.
#[derive(Debug)]
pub enum ServeError<E> {
    /// receiving a request or loaning an answer failed
    Call(CallError),
    /// the answering function failed; its request is dropped unanswered
    /// (its client's call ends as the server gone)
    Answer(E),
}

impl SchemaServer {
    fn bind(binding: &Binding, service: &str, layouts: Layouts) -> Result<(Self, Arc<ServerSide>), CallError> {
        let mut mem = None;
        let live = match binding {
            Binding::Nothing => None,
            Binding::Memory(_) => {
                mem = Some(MemServer::new(layouts.spec.clone(), service));
                None
            }
            Binding::Shm(node) => {
                let factory = crate::world::retry_after_cleanup(
                    node.config(),
                    "serve",
                    |e: &CallError| matches!(e, CallError::Open { .. }),
                    || layouts.open(node, service, true),
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
        let side = Arc::new(ServerSide { layouts, service: service.into(), live, mem, answered: AtomicU64::new(0) });
        Ok((SchemaServer { side: side.clone() }, side))
    }

    /// Answers each waiting request (at most `max`: what arrives meanwhile
    /// waits for the next step, whose wake-up is pending): `answer` gets the
    /// request's bytes and writes the answer's in place (zeroed first, of
    /// the answer layout's size). Returns how many were answered; the first
    /// error of `answer` ends the turn.
    pub fn serve_up_to<E>(
        &self,
        max: usize,
        mut answer: impl FnMut(&[u8], &mut [u8]) -> Result<(), E>,
    ) -> Result<usize, ServeError<E>> {
        if let Some(mem) = &self.side.mem {
            let size = self.side.layouts.response.size;
            let (n, first) = mem.serve(max, |request| {
                let mut out = vec![0u8; size];
                answer(request, &mut out).map_err(Unanswered::Failed)?;
                Ok(out)
            });
            self.side.answered.fetch_add(n as u64, Ordering::Relaxed);
            return match first {
                Some(Unanswered::Failed(e)) => Err(ServeError::Answer(e)),
                _ => Ok(n),
            };
        }
        let Some(live) = &self.side.live else { return Ok(0) };
        let service = &self.side.service;
        let size = self.side.layouts.response.size;
        let mut n = 0;
        let mut failed = None;
        {
            let port = lock(&live.port);
            while n < max {
                let request = match port.receive() {
                    Ok(Some(r)) => r,
                    Ok(None) => break,
                    Err(source) => {
                        failed = Some(ServeError::Call(CallError::Receive {
                            port: self.side.layouts.spec.name.clone(),
                            service: service.clone(),
                            source,
                        }));
                        break;
                    }
                };
                // SAFETY: one element of the FixedSize answer type (`Layouts::open`): `size` bytes
                let mut loan = match unsafe { request.loan_custom_payload(1) } {
                    Ok(l) => l,
                    Err(source) => {
                        failed = Some(ServeError::Call(CallError::Loan { service: service.clone(), len: 1, source }));
                        break;
                    }
                };
                let slots = loan.payload_mut();
                if slots.len() != size {
                    failed = Some(ServeError::Call(CallError::Open {
                        service: service.clone(),
                        detail: format!("loaned {} bytes for a {size}-byte answer", slots.len()),
                    }));
                    break;
                }
                // SAFETY: `slots` is `size` writable one-byte elements: zeroed, then
                // handed out as bytes (every byte initialised)
                let bytes = unsafe {
                    std::ptr::write_bytes(slots.as_mut_ptr().cast::<u8>(), 0, size);
                    std::slice::from_raw_parts_mut(slots.as_mut_ptr().cast::<u8>(), size)
                };
                if let Err(e) = answer(payload_bytes(request.payload()), bytes) {
                    failed = Some(ServeError::Answer(e));
                    break;
                }
                // SAFETY: every byte of the answer was written (zeroed, then by `answer`)
                if let Err(e) = unsafe { loan.assume_init() }.send() {
                    // the client went away: nobody waits for this answer
                    tracing::debug!(service = %service, "an answer found no client: {e:?}");
                }
                n += 1;
            }
        }
        if n > 0 {
            self.side.answered.fetch_add(n as u64, Ordering::Relaxed);
            if let Err(e) = lock(&live.answered).notify() {
                tracing::warn!(service = %service, "cannot wake the clients: {e:?}");
            }
        }
        match failed {
            Some(e) => Err(e),
            None => Ok(n),
        }
    }

    /// How many requests it answered so far.
    pub fn answered(&self) -> u64 {
        self.side.answered.load(Ordering::Relaxed)
    }

    /// The iceoryx2 service name.
    pub fn service(&self) -> &str {
        &self.side.service
    }

    /// The request's layout.
    pub fn request_schema(&self) -> &Schema {
        &self.side.layouts.request
    }

    /// The answer's layout.
    pub fn response_schema(&self) -> &Schema {
        &self.side.layouts.response
    }
}

impl DynInput for ServerSide {
    fn name(&self) -> &str {
        &self.layouts.spec.name
    }
    fn type_name(&self) -> &str {
        &self.layouts.spec.type_name
    }
    fn spec(&self) -> PortSpec {
        self.layouts.spec.clone()
    }
    fn payload_layout(&self) -> (usize, usize) {
        (self.layouts.request.size, self.layouts.request.align)
    }
    fn connect(
        &self,
        _node: &Node<Ipc>,
        _robot: &shm_schemas::RobotName,
        _from_agent: &str,
        _from_port: &str,
    ) -> Result<bool, PortError> {
        Err(not_an_input(&self.layouts.spec.name))
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
        self.mem.as_ref().is_some_and(|m| m.has_requests())
    }
    fn queue(&self, _sender: &str, _port: &str, _sample: SampleBuf, _stamp_ns: u64) -> Result<(), PortError> {
        Err(not_an_input(&self.layouts.spec.name))
    }
}

// ---------------------------------------------------------------- client

/// A client of a service, declared by layout ([`Setup::client_of`]).
pub struct SchemaClient {
    side: Arc<ClientSide>,
}

impl std::fmt::Debug for SchemaClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SchemaClient")
            .field("name", &self.side.layouts.spec.name)
            .field("type", &self.side.layouts.spec.type_name)
            .finish()
    }
}

struct Target {
    agent: String,
    port: String,
    service: String,
    client: RawClientPort,
    requests: Notifier<Ipc>,
    listener: Arc<Listener<Ipc>>,
    _factories: (RawFactory, event::PortFactory<Ipc>, event::PortFactory<Ipc>),
}

struct InFlight {
    id: CallId,
    deadline_ns: u64,
    service: String,
    pending: RawPending,
}

/// A finished call: its answer's bytes, or why there is none.
pub type Finished = (CallId, Result<Vec<u8>, CallError>);

struct ClientState {
    target: Option<Target>,
    in_flight: Vec<InFlight>,
    done: VecDeque<Finished>,
    next_id: u64,
    answered: u64,
    last_answer_ns: Option<u64>,
}

struct ClientSide {
    layouts: Layouts,
    options: CallOptions,
    state: Mutex<ClientState>,
    /// in the test harness: the calls (bytes), answered by the test or another agent
    mem: Option<Arc<MemClient<Vec<u8>, Vec<u8>>>>,
}

impl SchemaClient {
    fn bind(binding: &Binding, layouts: Layouts, options: CallOptions) -> Result<(Self, Arc<ClientSide>), CallError> {
        let options =
            CallOptions { max_in_flight: options.max_in_flight.clamp(1, MAX_IN_FLIGHT), timeout: options.timeout };
        let mem = match binding {
            Binding::Memory(bus) => Some(MemClient::new(layouts.spec.clone(), options, bus.clone())),
            _ => None,
        };
        let side = Arc::new(ClientSide {
            mem,
            layouts,
            options,
            state: Mutex::new(ClientState {
                target: None,
                in_flight: Vec::new(),
                done: VecDeque::new(),
                next_id: 1,
                answered: 0,
                last_answer_ns: None,
            }),
        });
        Ok((SchemaClient { side: side.clone() }, side))
    }

    /// Sends `request` (exactly the request layout's size) to the service
    /// the client is wired to and returns at once; the answer (or why there
    /// is none) comes from [`SchemaClient::take`]. Refused, with nothing
    /// sent, when the client is not wired, no server answers, or past the
    /// bound of calls in flight.
    pub fn call(&self, request: &[u8]) -> Result<CallId, CallError> {
        let name = &self.side.layouts.spec.name;
        let size = self.side.layouts.request.size;
        if let Some(mem) = &self.side.mem {
            if request.len() != size {
                return Err(CallError::Open {
                    service: name.clone(),
                    detail: format!(
                        "a {}-byte request for the {size}-byte {}",
                        request.len(),
                        self.side.layouts.request.type_name
                    ),
                });
            }
            return mem.call(request.to_vec());
        }
        let mut st = lock(&self.side.state);
        let st = &mut *st;
        let Some(t) = &st.target else { return Err(CallError::NotWired { client: name.clone() }) };
        if request.len() != size {
            return Err(CallError::Open {
                service: t.service.clone(),
                detail: format!(
                    "a {}-byte request for the {size}-byte {}",
                    request.len(),
                    self.side.layouts.request.type_name
                ),
            });
        }
        if st.in_flight.len() >= self.side.options.max_in_flight {
            return Err(CallError::TooManyInFlight { client: name.clone(), max: self.side.options.max_in_flight });
        }
        // SAFETY: one element of the FixedSize request type (`Layouts::open`): `size` bytes
        let mut loan = unsafe { t.client.loan_custom_payload(1) }.map_err(|e| CallError::Open {
            service: t.service.clone(),
            detail: format!("cannot loan a request: {e:?}"),
        })?;
        let payload = loan.payload_mut();
        if payload.len() != size {
            return Err(CallError::Open {
                service: t.service.clone(),
                detail: format!("loaned {} bytes for a {size}-byte request", payload.len()),
            });
        }
        // SAFETY: `payload` is `size` writable one-byte elements, not overlapping `request`
        unsafe { std::ptr::copy_nonoverlapping(request.as_ptr(), payload.as_mut_ptr().cast::<u8>(), size) };
        // SAFETY: every byte of the request was written just above
        let pending = unsafe { loan.assume_init() }.send().map_err(|source| CallError::Send {
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

    /// The next finished call, oldest first: its answer's bytes, or why
    /// there is none. `None` while no call has finished. Never blocks.
    pub fn take(&self) -> Option<Finished> {
        if let Some(mem) = &self.side.mem {
            return mem.take();
        }
        let mut st = lock(&self.side.state);
        self.side.settle(&mut st, now_ns());
        st.done.pop_front()
    }

    /// How many calls are in flight.
    pub fn in_flight(&self) -> usize {
        if let Some(mem) = &self.side.mem {
            return mem.in_flight();
        }
        lock(&self.side.state).in_flight.len()
    }

    /// Whether the client is wired to a service now.
    pub fn is_wired(&self) -> bool {
        if let Some(mem) = &self.side.mem {
            return mem.is_wired();
        }
        lock(&self.side.state).target.is_some()
    }

    /// The client's settings.
    pub fn options(&self) -> CallOptions {
        self.side.options
    }

    /// The request's layout.
    pub fn request_schema(&self) -> &Schema {
        &self.side.layouts.request
    }

    /// The answer's layout.
    pub fn response_schema(&self) -> &Schema {
        &self.side.layouts.response
    }
}

impl ClientSide {
    /// The answer `f` received, if any, as bytes of the answer's size.
    fn answer(&self, f: &InFlight) -> Option<Result<Vec<u8>, CallError>> {
        let name = &self.layouts.spec.name;
        match f.pending.receive() {
            Ok(Some(r)) => {
                let bytes = payload_bytes(r.payload());
                Some(if bytes.len() == self.layouts.response.size {
                    Ok(bytes.to_vec())
                } else {
                    Err(CallError::Malformed {
                        client: name.clone(),
                        service: f.service.clone(),
                        detail: format!("{} bytes for the {}-byte answer", bytes.len(), self.layouts.response.size),
                    })
                })
            }
            Ok(None) => None,
            Err(source) => Some(Err(CallError::Receive { port: name.clone(), service: f.service.clone(), source })),
        }
    }

    /// Moves every call that finished (answered, timed out, its server
    /// gone) from in flight to done.
    fn settle(&self, st: &mut ClientState, now: u64) {
        let name = &self.layouts.spec.name;
        let mut i = 0;
        while i < st.in_flight.len() {
            let f = &st.in_flight[i];
            let outcome = match self.answer(f) {
                Some(o) => Some(o),
                // gone: look once more, the answer may have come just before the server let go
                None if !f.pending.is_connected() => Some(self.answer(f).unwrap_or_else(|| {
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

    /// Drops the wire; the calls in flight finish as [`CallError::Unwired`].
    fn unwire(&self, st: &mut ClientState) {
        self.settle(st, now_ns());
        let name = &self.layouts.spec.name;
        for f in st.in_flight.drain(..) {
            st.done.push_back((f.id, Err(CallError::Unwired { client: name.clone(), service: f.service })));
        }
        if let Some(t) = st.target.take() {
            tracing::info!(client = %name, service = %t.service, "client unwired");
        }
    }
}

impl DynInput for ClientSide {
    fn name(&self) -> &str {
        &self.layouts.spec.name
    }
    fn type_name(&self) -> &str {
        &self.layouts.spec.type_name
    }
    fn spec(&self) -> PortSpec {
        self.layouts.spec.clone()
    }
    fn payload_layout(&self) -> (usize, usize) {
        (self.layouts.response.size, self.layouts.response.align)
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
        let wire = || -> Result<Target, CallError> {
            let factory = self.layouts.open(node, &service, false)?;
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
        tracing::info!(client = %self.layouts.spec.name, service = %service, "client wired");
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
                input: self.layouts.spec.name.clone(),
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
        self.mem.as_ref().is_some_and(|m| m.has_answers())
    }

    fn queue(&self, _sender: &str, _port: &str, _sample: SampleBuf, _stamp_ns: u64) -> Result<(), PortError> {
        Err(not_an_input(&self.layouts.spec.name))
    }
}

// ---------------------------------------------------------------- declaring

impl Setup {
    /// Declares service `port`, requests of layout `request` answered with
    /// `response` (both fixed-size), for an agent that learns its types at
    /// run time (a Python agent): the service a [`Setup::serve`] of Rust
    /// types of those layouts makes.
    pub fn serve_of(&mut self, port: &str, request: Schema, response: Schema) -> Result<SchemaServer, AgentError> {
        self.check_call_port(port)?;
        let layouts = Layouts::of(port, request, response)?;
        let service = self.world.robot().port_service(self.name.as_str(), port);
        let (server, side) = SchemaServer::bind(&self.binding, &service, layouts.clone())?;
        self.declare_call(&layouts, true);
        self.calls.add_memory(side.mem.clone().map(|m| MemCallPort::Service(m)));
        self.inputs.push(side);
        Ok(server)
    }

    /// Declares client `port` of a service of layouts `request` and
    /// `response` (see [`Setup::serve_of`]), with `options`.
    pub fn client_of(
        &mut self,
        port: &str,
        request: Schema,
        response: Schema,
        options: CallOptions,
    ) -> Result<SchemaClient, AgentError> {
        self.check_call_port(port)?;
        let layouts = Layouts::of(port, request, response)?;
        let (client, side) = SchemaClient::bind(&self.binding, layouts.clone(), options)?;
        self.declare_call(&layouts, false);
        self.calls.add_memory(side.mem.clone().map(|m| MemCallPort::Client(m)));
        self.inputs.push(side);
        Ok(client)
    }

    fn check_call_port(&self, port: &str) -> Result<(), AgentError> {
        shm_schemas::names::validate_port_name(port).map_err(|e| AgentError::Config(e.to_string()))?;
        if self.outputs.iter().any(|p| p.name == port) || self.inputs.iter().any(|p| p.name() == port) {
            return Err(AgentError::Config(format!("port {port:?} is declared twice")));
        }
        Ok(())
    }

    fn declare_call(&mut self, layouts: &Layouts, service: bool) {
        let list = if service { &mut self.calls.services } else { &mut self.calls.clients };
        list.push(layouts.spec.clone());
        add_schema(&mut self.schemas, layouts.request.clone());
        add_schema(&mut self.schemas, layouts.response.clone());
    }
}
