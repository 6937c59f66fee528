//! The client side of a call ([`CallClient`]): calls the service the
//! router wired it to, never blocking its step. Generic over the call's
//! [`Kind`]: [`Client`] takes fixed-size answers, [`super::SeqClient`]
//! (`call_seq`) sequences, `schema_call`'s client requests and answers of
//! layouts learnt at run time (Python and C agents).

use super::bytes::{Binding, DynInput};
use super::call::memory::{MemCallPort, MemClient};
use super::call::{
    ANSWERED_SUFFIX, Answer, Answered, CallError, CallId, CallOptions, ClientPort, Factory, Fixed, Kind, MAX_IN_FLIGHT,
    Pending, Typed, call_service, event_service, open_err,
};
use super::call_server::not_an_input;
use super::error::PortError;
use super::memory::SampleBuf;
use super::service::lock;
use crate::clock::now_ns;
use crate::world::Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::event;
use shm_schemas::Payload;
use shm_schemas::control::agent_to_router::PortSpec;
use shm_schemas::stats::InputStats;
use std::collections::VecDeque;
use std::mem::MaybeUninit;
use std::sync::{Arc, Mutex};

/// A client of a service of requests `Req` answered by a fixed-size `Resp`.
pub type Client<Req, Resp> = CallClient<Typed<Req, Fixed<Resp>>>;

/// A client: calls a service of the call kind `K` (its request and
/// answer), once the router wired it to one.
pub struct CallClient<K: Kind> {
    side: Arc<ClientSide<K>>,
}

impl<K: Kind> std::fmt::Debug for CallClient<K> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client").field("name", &self.side.spec.name).field("type", &self.side.spec.type_name).finish()
    }
}

/// The service a client is wired to.
struct Target<K: Kind> {
    agent: String,
    port: String,
    service: String,
    client: ClientPort<K>,
    requests: Notifier<Ipc>,
    listener: Arc<Listener<Ipc>>,
    _factories: (Factory<K>, event::PortFactory<Ipc>, event::PortFactory<Ipc>),
}

struct InFlight<K: Kind> {
    id: CallId,
    deadline_ns: u64,
    service: String,
    pending: Pending<K>,
}

/// A finished call, as its client holds it until taken.
enum Finished<K: Kind> {
    /// answered, the answer left in the server's shared memory for
    /// `take_with` to read in place; its call is let go after its answer
    /// (fields drop in order)
    Held { response: Answered<K>, _call: Pending<K>, service: String },
    /// answered and copied out (for `take`), or why there is no answer;
    /// a value is boxed so that the queue's entries stay small: an entry
    /// as large as the answer (230 KB for an image) would be copied
    /// whole at each push and pop, held answers too (two passes over the
    /// answer's size per call, found by a profile of the messages bench)
    Done(Result<Box<K::Value>, CallError>),
}

struct ClientState<K: Kind> {
    target: Option<Target<K>>,
    in_flight: Vec<InFlight<K>>,
    done: VecDeque<(CallId, Finished<K>)>,
    next_id: u64,
    answered: u64,
    last_answer_ns: Option<u64>,
}

pub(crate) struct ClientSide<K: Kind> {
    kind: K,
    spec: PortSpec,
    options: CallOptions,
    state: Mutex<ClientState<K>>,
    /// in the test harness: the calls, answered by the test or another agent
    mem: Option<Arc<MemClient<K::Queued, K::Value>>>,
}

impl<Req: Payload, A: Answer> CallClient<Typed<Req, A>> {
    /// Client `port` with `options`, bound to `binding` (it is wired later).
    pub(crate) fn bind(
        binding: &Binding,
        port: &str,
        options: CallOptions,
    ) -> Result<(Self, Arc<dyn DynInput>), CallError> {
        let (client, side) = Self::bind_kind(binding, port, options, Typed::default());
        Ok((client, side))
    }
}

impl<Req: Payload, A: Answer> CallClient<Typed<Req, A>> {
    /// Sends a request written in place by `fill`, in shared memory (a
    /// default `Req` first, which `fill` changes), as [`CallClient::call`]
    /// sends: for requests too large to build on the stack and copy.
    pub fn call_with(&self, fill: impl FnOnce(&mut Req)) -> Result<CallId, CallError>
    where
        Req: Default,
    {
        // SAFETY: a default value is written whole before `fill` changes it
        unsafe { self.call_uninit(|slot| fill(slot.write(Req::default()))) }
    }

    /// Sends a request written in place by `fill`, without a default value
    /// written first: a large request costs one write into shared memory.
    /// Otherwise as [`CallClient::call`].
    ///
    /// # Safety
    /// `fill` must leave the request initialised: every field the server
    /// looks at written, and only bit patterns valid for `Req` in the rest
    /// (for plain numeric and byte-array payloads any bytes are valid).
    pub unsafe fn call_uninit(&self, fill: impl FnOnce(&mut MaybeUninit<Req>)) -> Result<CallId, CallError> {
        if let Some(mem) = &self.side.mem {
            let mut request = Box::new(MaybeUninit::<Req>::uninit());
            fill(&mut request);
            // SAFETY: the caller guarantees that `fill` initialised it
            return mem.call(unsafe { request.assume_init_read() });
        }
        self.send(|port, client, service| {
            let send_err = |source| CallError::Send { client: client.into(), service: service.into(), source };
            let mut loan = port.loan_uninit().map_err(|e| send_err(e.into()))?;
            fill(loan.payload_mut());
            // SAFETY: the caller guarantees that `fill` initialised the payload
            unsafe { loan.assume_init() }.send().map_err(send_err)
        })
    }
}

impl<K: Kind> CallClient<K> {
    /// Client `port` of `kind` with `options`, bound to `binding` (it is wired later).
    pub(crate) fn bind_kind(
        binding: &Binding,
        port: &str,
        options: CallOptions,
        kind: K,
    ) -> (Self, Arc<ClientSide<K>>) {
        let options =
            CallOptions { max_in_flight: options.max_in_flight.clamp(1, MAX_IN_FLIGHT), timeout: options.timeout };
        let mem = match binding {
            Binding::Memory(bus) => Some(MemClient::new(kind.spec(port), options, bus.clone())),
            _ => None,
        };
        let side = Arc::new(ClientSide {
            mem,
            spec: kind.spec(port),
            kind,
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
        (CallClient { side: side.clone() }, side)
    }

    /// Sends `request` to the service the client is wired to and returns
    /// at once; the answer (or why there is none) comes from
    /// [`Client::take`]. Refused, with nothing sent, when the client is not
    /// wired, when no server answers the service, or past the bound of
    /// calls in flight.
    pub fn call(&self, request: &K::Request) -> Result<CallId, CallError> {
        if let Some(mem) = &self.side.mem {
            return mem.call(self.side.kind.queued(request, &self.side.spec.name)?);
        }
        self.send(|port, name, service| self.side.kind.send(port, request, name, service))
    }

    /// Sends the request `send` sends through the client's port (for
    /// client `name` of `service`), if the client is wired and below its
    /// bound of calls in flight; refused, with nothing sent, otherwise.
    fn send(
        &self,
        send: impl FnOnce(&ClientPort<K>, &str, &str) -> Result<Pending<K>, CallError>,
    ) -> Result<CallId, CallError> {
        let name = &self.side.spec.name;
        let mut st = lock(&self.side.state);
        let st = &mut *st;
        let Some(t) = &st.target else { return Err(CallError::NotWired { client: name.clone() }) };
        if st.in_flight.len() >= self.side.options.max_in_flight {
            return Err(CallError::TooManyInFlight { client: name.clone(), max: self.side.options.max_in_flight });
        }
        let pending = send(&t.client, name, &t.service)?;
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
    pub fn take(&self) -> Option<(CallId, Result<K::Value, CallError>)> {
        if let Some(mem) = &self.side.mem {
            return mem.take();
        }
        let (id, finished) = {
            let mut st = lock(&self.side.state);
            self.side.settle(&mut st, now_ns(), false);
            st.done.pop_front()?
        };
        let answer = match finished {
            // copied out when it settled: handed out as it is, not copied again
            Finished::Done(outcome) => outcome.map(|value| *value),
            held @ Finished::Held { .. } => {
                let kind = &self.side.kind;
                self.side.read(held, |answer| answer.map(|view| kind.to_value(view)))
            }
        };
        Some((id, answer))
    }

    /// The next finished call, oldest first, handed to `read` with its
    /// answer read in place, in the server's shared memory (a fixed
    /// answer as `&Resp`, a sequence's as `(&H, &[T])`), or why there is
    /// none, as [`CallClient::take`] says; returns what `read` returns.
    /// Nothing is copied: a large answer costs what reading it costs. An
    /// answer waits in the server's memory from the moment this finds it
    /// until it is taken (at most the client's calls in flight).
    /// `None` while no call has finished. Never blocks.
    pub fn take_with<R>(&self, read: impl FnOnce(CallId, Result<K::View<'_>, CallError>) -> R) -> Option<R> {
        let kind = &self.side.kind;
        if let Some(mem) = &self.side.mem {
            let (id, outcome) = mem.take()?;
            return Some(match outcome {
                Ok(value) => read(id, Ok(kind.view_of(&value))),
                Err(e) => read(id, Err(e)),
            });
        }
        let (id, finished) = {
            let mut st = lock(&self.side.state);
            self.side.settle(&mut st, now_ns(), true);
            st.done.pop_front()?
        };
        // the lock is not held while `read` runs: it may call again
        Some(self.side.read(finished, |answer| read(id, answer)))
    }

    /// How many calls are in flight (sent, not yet finished).
    pub fn in_flight(&self) -> usize {
        if let Some(mem) = &self.side.mem {
            return mem.in_flight();
        }
        lock(&self.side.state).in_flight.len()
    }

    /// Whether the client is wired to a service now (in the test harness:
    /// to the test, until a wiring wires it to another agent's service).
    pub fn is_wired(&self) -> bool {
        if let Some(mem) = &self.side.mem {
            return mem.is_wired();
        }
        lock(&self.side.state).target.is_some()
    }

    /// In the test harness: the port as the harness reaches it.
    pub(crate) fn memory_port(&self) -> Option<MemCallPort> {
        self.side.mem.clone().map(|m| MemCallPort::Client(m))
    }

    /// The client's settings.
    pub fn options(&self) -> CallOptions {
        self.side.options
    }

    /// The call's kind (its request and answer).
    pub(crate) fn kind(&self) -> &K {
        &self.side.kind
    }
}

impl<K: Kind> ClientSide<K> {
    /// Hands `finished`'s answer, read in place, or why there is none, to `read`.
    fn read<R>(&self, finished: Finished<K>, read: impl FnOnce(Result<K::View<'_>, CallError>) -> R) -> R {
        match finished {
            Finished::Held { response, service, .. } => read(self.kind.view(&response, &self.spec.name, &service)),
            Finished::Done(Ok(value)) => read(Ok(self.kind.view_of(&value))),
            Finished::Done(Err(e)) => read(Err(e)),
        }
    }

    /// Moves every call that finished (answered, timed out, its server
    /// gone) from in flight to done; an answer is copied out, or (`hold`)
    /// left in the server's memory for `take_with`.
    fn settle(&self, st: &mut ClientState<K>, now: u64, hold: bool) {
        let name = &self.spec.name;
        let mut i = 0;
        while i < st.in_flight.len() {
            let f = &st.in_flight[i];
            let answer = |f: &InFlight<K>| match self.kind.next_answer(&f.pending) {
                Ok(Some(response)) => Some(Ok(response)),
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
                    let finished = match o {
                        Ok(response) => {
                            // a refused or malformed answer is its error, as `take` gives it
                            let checked = self
                                .kind
                                .view(&response, name, &f.service)
                                .map(|view| (!hold).then(|| self.kind.to_value(view)));
                            match checked {
                                Ok(None) => Finished::Held { response, _call: f.pending, service: f.service },
                                Ok(Some(value)) => Finished::Done(Ok(Box::new(value))),
                                Err(e) => Finished::Done(Err(e)),
                            }
                        }
                        Err(e) => Finished::Done(Err(e)),
                    };
                    if !matches!(finished, Finished::Done(Err(_))) {
                        st.answered = st.answered.saturating_add(1);
                        st.last_answer_ns = Some(now);
                    }
                    st.done.push_back((f.id, finished));
                }
                None => i += 1,
            }
        }
    }
}

impl<K: Kind> DynInput for ClientSide<K> {
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
        self.kind.answer_layout()
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
        let wire = || -> Result<Target<K>, CallError> {
            let factory = call_service(node, &self.kind, &service, false)?;
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
        self.mem.as_ref().is_some_and(|m| m.has_answers())
    }

    fn queue(&self, _sender: &str, _port: &str, _sample: SampleBuf, _stamp_ns: u64) -> Result<(), PortError> {
        Err(not_an_input(&self.spec.name))
    }
}

impl<K: Kind> ClientSide<K> {
    /// Drops the wire; the calls in flight finish as [`CallError::Unwired`].
    fn unwire(&self, st: &mut ClientState<K>) {
        self.settle(st, now_ns(), false);
        for f in st.in_flight.drain(..) {
            let unwired = CallError::Unwired { client: self.spec.name.clone(), service: f.service };
            st.done.push_back((f.id, Finished::Done(Err(unwired))));
        }
        if let Some(t) = st.target.take() {
            tracing::info!(client = %self.spec.name, service = %t.service, "client unwired");
        }
    }
}
