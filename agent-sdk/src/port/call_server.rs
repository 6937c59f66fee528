//! The server side of a call ([`CallServer`]): the service an agent
//! answers, in its own task, which a request wakes like an input. Generic
//! over the call's [`Kind`]: [`Server`] answers Rust requests with a
//! fixed-size payload, [`super::SeqServer`] (`call_seq`) with a sequence,
//! `schema_call`'s server requests and answers of layouts learnt at run
//! time (Python and C agents).

use super::bytes::{Binding, DynInput};
use super::call::memory::{MemCallPort, MemServer};
use super::call::{
    ANSWERED_SUFFIX, Answer, CallError, Factory, Fixed, Kind, MAX_IN_FLIGHT, ServerPort, Typed, call_service,
    event_service, open_err,
};
use super::error::PortError;
use super::memory::SampleBuf;
use super::service::lock;
use crate::world::Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::event;
use shm_schemas::Payload;
use shm_schemas::control::agent_to_router::PortSpec;
use shm_schemas::stats::InputStats;
use std::mem::MaybeUninit;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// A request as the server holds it while it answers.
pub(crate) use super::call::ActiveRequest as Request;

/// A service an agent answers: requests `Req`, answers with a fixed-size `Resp`.
pub type Server<Req, Resp> = CallServer<Typed<Req, Fixed<Resp>>>;

/// A service an agent answers, of the call kind `K` (its request and answer).
pub struct CallServer<K: Kind> {
    side: Arc<ServerSide<K>>,
}

impl<K: Kind> std::fmt::Debug for CallServer<K> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Server").field("service", &self.side.service).field("type", &self.side.spec.type_name).finish()
    }
}

struct ServerLive<K: Kind> {
    port: Mutex<ServerPort<K>>,
    listener: Arc<Listener<Ipc>>,
    answered: Mutex<Notifier<Ipc>>,
    _factories: (Factory<K>, event::PortFactory<Ipc>, event::PortFactory<Ipc>),
}

pub(crate) struct ServerSide<K: Kind> {
    kind: K,
    spec: PortSpec,
    service: String,
    live: Option<ServerLive<K>>,
    /// the most elements an answer holds (1 for a fixed answer)
    max_len: usize,
    /// in the test harness: the requests waiting for the step
    mem: Option<Arc<MemServer<K::Queued, K::Value>>>,
    answered: AtomicU64,
}

impl<Req: Payload, A: Answer> CallServer<Typed<Req, A>> {
    /// Service `port` (iceoryx2 service `service`), bound to `binding`,
    /// answering with at most `max_len` elements (1 for a fixed answer).
    pub(crate) fn bind(
        binding: &Binding,
        port: &str,
        service: &str,
        max_len: usize,
    ) -> Result<(Self, Arc<dyn DynInput>), CallError> {
        let (server, side) = Self::bind_kind(binding, port, service, max_len, Typed::default())?;
        Ok((server, side))
    }
}

impl<K: Kind> CallServer<K> {
    /// Service `port` of `kind` (iceoryx2 service `service`), bound to
    /// `binding`, answering with at most `max_len` elements (1 for a fixed answer).
    pub(crate) fn bind_kind(
        binding: &Binding,
        port: &str,
        service: &str,
        max_len: usize,
        kind: K,
    ) -> Result<(Self, Arc<ServerSide<K>>), CallError> {
        let mut mem = None;
        let live = match binding {
            Binding::Nothing => None,
            Binding::Memory(_) => {
                mem = Some(MemServer::new(kind.spec(port), service));
                None
            }
            Binding::Shm(node) => {
                let factory = crate::world::retry_after_cleanup(
                    node.config(),
                    "serve",
                    |e: &CallError| matches!(e, CallError::Open { .. }),
                    || call_service(node, &kind, service, true),
                )?;
                let server = crate::world::retry_after_cleanup(
                    node.config(),
                    "serve",
                    |_| true,
                    || kind.server(&factory, max_len),
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
            spec: kind.spec(port),
            kind,
            max_len,
            service: service.into(),
            live,
            mem,
            answered: AtomicU64::new(0),
        });
        Ok((CallServer { side: side.clone() }, side))
    }

    /// Hands each waiting request to `answer` (at most `max` of them: what
    /// arrives meanwhile is left for the next step, whose wake-up is
    /// pending), then wakes the clients; returns how many were handled.
    /// An error of `answer` is remembered and the next request handled:
    /// the first one is returned once all are; `Ok(false)` ends the turn
    /// after this request (the rest wait for the next step).
    pub(crate) fn each_request(
        &self,
        max: usize,
        mut answer: impl FnMut(&Request<K>) -> Result<bool, CallError>,
    ) -> Result<usize, CallError> {
        let Some(live) = &self.side.live else { return Ok(0) };
        let mut n = 0;
        let mut first_error = None;
        {
            let port = lock(&live.port);
            while n < max {
                let request = match self.side.kind.next_request(&port) {
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
                n += 1;
                match answer(&request) {
                    Ok(true) => {}
                    Ok(false) => break,
                    Err(e) => {
                        first_error.get_or_insert(e);
                    }
                }
            }
        }
        if n > 0 {
            self.side.answered.fetch_add(n as u64, Ordering::Relaxed);
            if let Err(e) = lock(&live.answered).notify() {
                tracing::warn!(service = %self.side.service, "cannot wake the clients: {e:?}");
            }
        }
        match first_error {
            Some(e) => Err(e),
            None => Ok(n),
        }
    }

    /// How many requests it answered so far.
    pub fn answered(&self) -> u64 {
        self.side.answered.load(Ordering::Relaxed)
    }

    /// In the test harness: the requests waiting for the step.
    pub(crate) fn memory(&self) -> Option<&Arc<MemServer<K::Queued, K::Value>>> {
        self.side.mem.as_ref()
    }

    /// In the test harness: the port as the harness reaches it.
    pub(crate) fn memory_port(&self) -> Option<MemCallPort> {
        self.side.mem.clone().map(|m| MemCallPort::Service(m))
    }

    /// Counts `n` more requests answered (in the harness).
    pub(crate) fn count_answered(&self, n: usize) {
        self.side.answered.fetch_add(n as u64, Ordering::Relaxed);
    }

    /// The iceoryx2 service name.
    pub fn service(&self) -> &str {
        &self.side.service
    }

    /// The service's port name, as the agent declared it.
    pub fn name(&self) -> &str {
        &self.side.spec.name
    }

    /// The call's kind (its request and answer).
    pub(crate) fn kind(&self) -> &K {
        &self.side.kind
    }

    /// The most elements an answer may hold, as declared (1 for a fixed answer).
    pub fn max_len(&self) -> usize {
        self.side.max_len
    }
}

impl<Req: Payload, Resp: Payload> CallServer<Typed<Req, Fixed<Resp>>> {
    /// Answers each waiting request with `answer` (at most `max` of them:
    /// what arrives meanwhile is left for the next step, whose wake-up is
    /// pending); returns how many were answered. The answer is returned by
    /// value and copied into shared memory; [`CallServer::serve_in_place`]
    /// writes it there.
    pub fn serve_up_to(&self, max: usize, mut answer: impl FnMut(&Req) -> Resp) -> Result<usize, CallError> {
        // SAFETY: the answer is written whole
        unsafe {
            self.serve_uninit_up_to(max, |request, slot| {
                slot.write(answer(request));
            })
        }
    }

    /// Answers every waiting request with `answer` (at most
    /// [`MAX_IN_FLIGHT`] per step); returns how many were answered.
    pub fn serve(&self, answer: impl FnMut(&Req) -> Resp) -> Result<usize, CallError> {
        self.serve_up_to(MAX_IN_FLIGHT, answer)
    }

    /// Answers every waiting request in place (at most [`MAX_IN_FLIGHT`]
    /// per step): `answer` reads the request where the client wrote it and
    /// writes its answer straight into the response's shared memory,
    /// which holds a default `Resp` first. Nothing is copied, so a large
    /// answer costs what writing it costs. Returns how many were answered.
    pub fn serve_in_place(&self, answer: impl FnMut(&Req, &mut Resp)) -> Result<usize, CallError>
    where
        Resp: Default,
    {
        self.serve_in_place_up_to(MAX_IN_FLIGHT, answer)
    }

    /// As [`CallServer::serve_in_place`], for at most `max` requests.
    pub fn serve_in_place_up_to(&self, max: usize, mut answer: impl FnMut(&Req, &mut Resp)) -> Result<usize, CallError>
    where
        Resp: Default,
    {
        // SAFETY: a default value is written whole before `answer` changes it
        unsafe { self.serve_uninit_up_to(max, |request, slot| answer(request, slot.write(Resp::default()))) }
    }

    /// Answers every waiting request in place (at most [`MAX_IN_FLIGHT`]
    /// per step), without a default value written first: a large answer
    /// costs one write into shared memory. Returns how many were answered.
    ///
    /// # Safety
    /// `answer` must leave the answer initialised: every field the client
    /// looks at written, and only bit patterns valid for `Resp` in the rest
    /// (for plain numeric and byte-array payloads any bytes are valid).
    pub unsafe fn serve_uninit(&self, answer: impl FnMut(&Req, &mut MaybeUninit<Resp>)) -> Result<usize, CallError> {
        // SAFETY: the caller's guarantee, passed on
        unsafe { self.serve_uninit_up_to(MAX_IN_FLIGHT, answer) }
    }

    /// As [`CallServer::serve_uninit`], for at most `max` requests.
    ///
    /// # Safety
    /// As [`CallServer::serve_uninit`].
    pub unsafe fn serve_uninit_up_to(
        &self,
        max: usize,
        mut answer: impl FnMut(&Req, &mut MaybeUninit<Resp>),
    ) -> Result<usize, CallError> {
        if let Some(mem) = &self.side.mem {
            let (n, _) = mem.serve::<std::convert::Infallible>(max, |request| {
                let mut slot = Box::new(MaybeUninit::<Resp>::uninit());
                answer(request, &mut slot);
                // SAFETY: the caller guarantees that `answer` initialised it
                Ok(unsafe { slot.assume_init_read() })
            });
            self.count_answered(n);
            return Ok(n);
        }
        let service = &self.side.service;
        self.each_request(max, |request| {
            let mut loan = match request.loan_uninit() {
                Ok(loan) => loan,
                Err(e) => {
                    // no memory for this answer: the handler still runs, its
                    // answer is dropped, and the client's call times out
                    tracing::warn!(service = %service, "cannot loan an answer: {e:?}");
                    answer(request.payload(), &mut Box::new(MaybeUninit::uninit()));
                    return Ok(true);
                }
            };
            answer(request.payload(), loan.payload_mut());
            // SAFETY: the caller guarantees that `answer` initialised the payload
            if let Err(e) = unsafe { loan.assume_init() }.send() {
                // the client went away: nobody waits for this answer
                tracing::debug!(service = %service, "an answer found no client: {e:?}");
            }
            Ok(true)
        })
    }
}

pub(crate) fn not_an_input(port: &str) -> PortError {
    PortError::Ipc {
        service: port.into(),
        detail: "a call port is wired to a service, never to an output: \
                 `nerve connect CLIENT_AGENT/CLIENT SERVER_AGENT/SERVICE`"
            .into(),
    }
}

impl<K: Kind> DynInput for ServerSide<K> {
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
        self.kind.request_layout()
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
        self.mem.as_ref().is_some_and(|m| m.has_requests())
    }
    fn queue(&self, _sender: &str, _port: &str, _sample: SampleBuf, _stamp_ns: u64) -> Result<(), PortError> {
        Err(not_an_input(&self.spec.name))
    }
}
