//! Calls in the test harness (`testing::Harness`): a server's requests and
//! a client's calls as in-memory queues, with the step model a running
//! agent has.
//!
//! A [`MemServer`] holds the requests waiting for the agent's next step
//! (which they wake, like an input's samples); its `serve` answers them
//! with the agent's own handler and hands each answer to whoever asked:
//! the test ([`crate::testing::Harness::call`]) or a [`MemClient`] of
//! another agent of a `testing::Wiring`. A [`MemClient`] starts wired to
//! the test: the calls its agent makes wait for the test to see them
//! ([`crate::testing::Harness::requests`]) and answer them; a wiring wires
//! it to a server of another agent instead. A call's timeout counts on the
//! harness's clock, and its bound of calls in flight is the client's own.
//!
//! Both are generic over the request `Q` and the answer's value `V` as the
//! client takes it (`Resp`, `(H, Vec<T>)`, or bytes for calls declared by
//! layout); the harness reaches them through [`MemService`] and
//! [`MemCaller`], which check the test's types at run time.

use super::{CallError, CallId, CallOptions};
use crate::port::memory::Bus;
use crate::port::service::lock;
use shm_schemas::control::agent_to_router::PortSpec;
use std::any::{Any, TypeId, type_name};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, Weak};

/// What a call ends with, as its client takes it.
pub(crate) type Outcome<V> = Result<V, CallError>;

/// A boxed value the harness hands in or takes out, of a type checked at run time.
pub(crate) type AnyBox = Box<dyn Any + Send>;

/// Whom an answer goes to.
enum ReplyTo<Q, V> {
    /// the test, which asked through the harness
    Test(CallId),
    /// a client of another agent (gone: the answer is dropped)
    Client(Weak<MemClient<Q, V>>, CallId),
}

/// Why the server's handler gave no answer to one request.
#[derive(Debug)]
pub(crate) enum Unanswered<E> {
    /// the answer was longer than the service's declared maximum: the
    /// client is told so ([`CallError::RefusedTooLong`]), the next request
    /// is answered
    TooLong {
        /// the answer's length
        len: usize,
        /// the declared maximum
        max: usize,
    },
    /// the handler failed: its request goes unanswered (its client's call
    /// ends as the server gone) and the turn ends
    Failed(E),
}

struct ServerQueues<Q, V> {
    requests: VecDeque<(Q, ReplyTo<Q, V>)>,
    /// answers to the test's calls, oldest first
    for_test: VecDeque<(CallId, Outcome<V>)>,
    next_test_id: u64,
}

/// A served port in the harness: the requests waiting for the agent's step.
pub(crate) struct MemServer<Q, V> {
    spec: PortSpec,
    service: String,
    queues: Mutex<ServerQueues<Q, V>>,
    /// a request came since the wiring last looked
    woken: AtomicBool,
}

impl<Q: Send + 'static, V: Send + 'static> MemServer<Q, V> {
    pub(crate) fn new(spec: PortSpec, service: &str) -> Arc<Self> {
        Arc::new(MemServer {
            spec,
            service: service.into(),
            queues: Mutex::new(ServerQueues { requests: VecDeque::new(), for_test: VecDeque::new(), next_test_id: 1 }),
            woken: AtomicBool::new(false),
        })
    }

    fn push(&self, request: Q, reply: ReplyTo<Q, V>) {
        lock(&self.queues).requests.push_back((request, reply));
        self.woken.store(true, Ordering::Release);
    }

    /// Whether requests wait for the agent's step.
    pub(crate) fn has_requests(&self) -> bool {
        !lock(&self.queues).requests.is_empty()
    }

    /// Answers at most `max` waiting requests with `answer`, each answer
    /// handed to whoever asked. Returns how many were handled and the
    /// first thing that went wrong: an answer too long (the next request is
    /// still answered) or the handler's failure (the turn ends there).
    pub(crate) fn serve<E>(
        &self,
        max: usize,
        mut answer: impl FnMut(&Q) -> Result<V, Unanswered<E>>,
    ) -> (usize, Option<Unanswered<E>>) {
        let mut n = 0;
        let mut first = None;
        while n < max {
            // the lock is not held while the agent's handler runs
            let Some((request, reply)) = lock(&self.queues).requests.pop_front() else { break };
            n += 1;
            let (client, id, to) = match &reply {
                ReplyTo::Test(id) => ("test".to_owned(), *id, None),
                ReplyTo::Client(c, id) => match c.upgrade() {
                    Some(c) => (c.spec.name.clone(), *id, Some(c)),
                    None => (String::new(), *id, None),
                },
            };
            let (outcome, stop) = match answer(&request) {
                Ok(v) => (Ok(v), false),
                Err(Unanswered::TooLong { len, max }) => {
                    first.get_or_insert(Unanswered::TooLong { len, max });
                    let refused = CallError::RefusedTooLong {
                        client,
                        service: self.service.clone(),
                        len: len as u64,
                        max: max as u64,
                    };
                    (Err(refused), false)
                }
                Err(Unanswered::Failed(e)) => {
                    first = Some(Unanswered::Failed(e));
                    (Err(CallError::ServerGone { client, service: self.service.clone() }), true)
                }
            };
            match (reply, to) {
                (ReplyTo::Test(_), _) => lock(&self.queues).for_test.push_back((id, outcome)),
                (ReplyTo::Client(..), Some(c)) => {
                    c.arrive(id, outcome);
                }
                // the client's agent is gone: nobody waits for this answer
                (ReplyTo::Client(..), None) => {}
            }
            if stop {
                break;
            }
        }
        (n, first)
    }
}

/// What the harness and the wiring need of a served port, whatever its types.
pub(crate) trait MemService: Send + Sync {
    /// the port's spec (name, call type)
    fn spec(&self) -> &PortSpec;
    /// the request's Rust type, and its name
    fn request_type(&self) -> (TypeId, &'static str);
    /// the answer's Rust type as a client takes it, and its name
    fn value_type(&self) -> (TypeId, &'static str);
    /// queues the test's request (of [`MemService::request_type`]) for the agent's next step
    fn test_call(&self, request: AnyBox) -> Option<CallId>;
    /// the answers to the test's calls (`Vec<(CallId, Outcome<V>)>`),
    /// oldest first; only call `only`'s if given
    fn take_test_answers(&self, only: Option<CallId>) -> AnyBox;
    /// whether a request came since the last look
    fn take_woken(&self) -> bool;
    /// itself, for a client of the same types to wire to
    fn as_any(self: Arc<Self>) -> Arc<dyn Any + Send + Sync>;
}

impl<Q: Send + 'static, V: Send + 'static> MemService for MemServer<Q, V> {
    fn spec(&self) -> &PortSpec {
        &self.spec
    }
    fn request_type(&self) -> (TypeId, &'static str) {
        (TypeId::of::<Q>(), type_name::<Q>())
    }
    fn value_type(&self) -> (TypeId, &'static str) {
        (TypeId::of::<V>(), type_name::<V>())
    }
    fn test_call(&self, request: AnyBox) -> Option<CallId> {
        let request = *request.downcast::<Q>().ok()?;
        let id = {
            let mut q = lock(&self.queues);
            let id = CallId(q.next_test_id);
            q.next_test_id = q.next_test_id.saturating_add(1);
            id
        };
        self.push(request, ReplyTo::Test(id));
        Some(id)
    }
    fn take_test_answers(&self, only: Option<CallId>) -> AnyBox {
        let mut q = lock(&self.queues);
        let taken: Vec<(CallId, Outcome<V>)> = match only {
            None => q.for_test.drain(..).collect(),
            Some(id) => match q.for_test.iter().position(|(i, _)| *i == id) {
                Some(at) => q.for_test.remove(at).into_iter().collect(),
                None => Vec::new(),
            },
        };
        Box::new(taken)
    }
    fn take_woken(&self) -> bool {
        self.woken.swap(false, Ordering::AcqRel)
    }
    fn as_any(self: Arc<Self>) -> Arc<dyn Any + Send + Sync> {
        self
    }
}

/// Where a harness client's calls go.
enum MemTarget<Q, V> {
    /// nowhere: its calls are refused ([`CallError::NotWired`])
    None,
    /// the test, which sees them and answers
    Test,
    /// a served port of another agent of a wiring
    Server { agent: String, port: String, server: Arc<MemServer<Q, V>> },
}

struct ClientQueues<Q, V> {
    target: MemTarget<Q, V>,
    /// id, deadline on the harness clock, service
    in_flight: Vec<(CallId, u64, String)>,
    /// the calls made while wired to the test, for it to see
    for_test: VecDeque<(CallId, Q)>,
    done: VecDeque<(CallId, Outcome<V>)>,
    next_id: u64,
}

/// A client port in the harness.
pub(crate) struct MemClient<Q, V> {
    spec: PortSpec,
    options: CallOptions,
    bus: Arc<Bus>,
    me: Weak<MemClient<Q, V>>,
    queues: Mutex<ClientQueues<Q, V>>,
    /// an answer came since the wiring last looked
    woken: AtomicBool,
}

impl<Q: Send + 'static, V: Send + 'static> MemClient<Q, V> {
    /// A client wired to the test, timing its calls on `bus`'s clock.
    pub(crate) fn new(spec: PortSpec, options: CallOptions, bus: Arc<Bus>) -> Arc<Self> {
        Arc::new_cyclic(|me| MemClient {
            spec,
            options,
            bus,
            me: me.clone(),
            queues: Mutex::new(ClientQueues {
                target: MemTarget::Test,
                in_flight: Vec::new(),
                for_test: VecDeque::new(),
                done: VecDeque::new(),
                next_id: 1,
            }),
            woken: AtomicBool::new(false),
        })
    }

    /// As `CallClient::call`: refused with nothing sent when unwired or
    /// past the bound of calls in flight.
    pub(crate) fn call(&self, request: Q) -> Result<CallId, CallError> {
        let name = &self.spec.name;
        let mut q = lock(&self.queues);
        let service = match &q.target {
            MemTarget::None => return Err(CallError::NotWired { client: name.clone() }),
            MemTarget::Test => "test".to_owned(),
            MemTarget::Server { server, .. } => server.service.clone(),
        };
        if q.in_flight.len() >= self.options.max_in_flight {
            return Err(CallError::TooManyInFlight { client: name.clone(), max: self.options.max_in_flight });
        }
        let id = CallId(q.next_id);
        q.next_id = q.next_id.saturating_add(1);
        let deadline = self.bus.now_ns().saturating_add(crate::clock::nanos(self.options.timeout));
        q.in_flight.push((id, deadline, service));
        match &q.target {
            MemTarget::Server { server, .. } => {
                let server = server.clone();
                drop(q);
                server.push(request, ReplyTo::Client(self.me.clone(), id));
            }
            _ => q.for_test.push_back((id, request)),
        }
        Ok(id)
    }

    /// An answer to call `id`: finishes it, if it is still in flight.
    fn arrive(&self, id: CallId, outcome: Outcome<V>) -> bool {
        let mut q = lock(&self.queues);
        let Some(at) = q.in_flight.iter().position(|(i, ..)| *i == id) else { return false };
        q.in_flight.remove(at);
        q.done.push_back((id, outcome));
        self.woken.store(true, Ordering::Release);
        true
    }

    /// Finishes the calls whose timeout passed on the harness clock.
    fn expire(&self, q: &mut ClientQueues<Q, V>) {
        let now = self.bus.now_ns();
        let name = &self.spec.name;
        let mut i = 0;
        while i < q.in_flight.len() {
            if q.in_flight[i].1 <= now {
                let (id, _, service) = q.in_flight.remove(i);
                let e = CallError::TimedOut { client: name.clone(), service, timeout: self.options.timeout };
                q.done.push_back((id, Err(e)));
            } else {
                i += 1;
            }
        }
    }

    /// As `CallClient::take`: the next finished call, oldest first.
    pub(crate) fn take(&self) -> Option<(CallId, Outcome<V>)> {
        let mut q = lock(&self.queues);
        self.expire(&mut q);
        q.done.pop_front()
    }

    pub(crate) fn in_flight(&self) -> usize {
        lock(&self.queues).in_flight.len()
    }

    pub(crate) fn is_wired(&self) -> bool {
        !matches!(lock(&self.queues).target, MemTarget::None)
    }

    /// Whether finished calls wait for the agent's step.
    pub(crate) fn has_answers(&self) -> bool {
        !lock(&self.queues).done.is_empty()
    }

    /// Drops the wire; its calls in flight finish as unwired.
    fn unwire_locked(&self, q: &mut ClientQueues<Q, V>) {
        for (id, _, service) in q.in_flight.drain(..) {
            q.done.push_back((id, Err(CallError::Unwired { client: self.spec.name.clone(), service })));
            self.woken.store(true, Ordering::Release);
        }
        q.for_test.clear();
        q.target = MemTarget::None;
    }
}

/// What the harness and the wiring need of a client port, whatever its types.
pub(crate) trait MemCaller: Send + Sync {
    /// the port's spec (name, call type)
    fn spec(&self) -> &PortSpec;
    /// the request's Rust type, and its name
    fn request_type(&self) -> (TypeId, &'static str);
    /// the answer's Rust type as the client takes it, and its name
    fn value_type(&self) -> (TypeId, &'static str);
    /// the calls the agent made to the test since the last look
    /// (`Vec<(CallId, Q)>`), oldest first
    fn take_requests(&self) -> AnyBox;
    /// the test's answer (an `Outcome<V>`) to call `id`; `Ok(false)` if the
    /// call is not in flight, `Err` gives back an answer of another type
    fn answer(&self, id: CallId, outcome: AnyBox) -> Result<bool, AnyBox>;
    /// wires the client to `server` (a [`MemServer`] of the same types),
    /// service `port` of agent `agent`; false if its types are others
    fn wire(&self, agent: &str, port: &str, server: Arc<dyn Any + Send + Sync>) -> bool;
    /// unwires it from service `port` of `agent`, if wired there
    fn unwire(&self, agent: &str, port: &str) -> bool;
    /// whether an answer came since the last look
    fn take_woken(&self) -> bool;
}

impl<Q: Send + 'static, V: Send + 'static> MemCaller for MemClient<Q, V> {
    fn spec(&self) -> &PortSpec {
        &self.spec
    }
    fn request_type(&self) -> (TypeId, &'static str) {
        (TypeId::of::<Q>(), type_name::<Q>())
    }
    fn value_type(&self) -> (TypeId, &'static str) {
        (TypeId::of::<V>(), type_name::<V>())
    }
    fn take_requests(&self) -> AnyBox {
        let taken: Vec<(CallId, Q)> = lock(&self.queues).for_test.drain(..).collect();
        Box::new(taken)
    }
    fn answer(&self, id: CallId, outcome: AnyBox) -> Result<bool, AnyBox> {
        let outcome = *outcome.downcast::<Outcome<V>>()?;
        Ok(self.arrive(id, outcome))
    }
    fn wire(&self, agent: &str, port: &str, server: Arc<dyn Any + Send + Sync>) -> bool {
        let Ok(server) = server.downcast::<MemServer<Q, V>>() else { return false };
        let mut q = lock(&self.queues);
        if let MemTarget::Server { agent: a, port: p, .. } = &q.target
            && a == agent
            && p == port
        {
            return true;
        }
        self.unwire_locked(&mut q);
        q.target = MemTarget::Server { agent: agent.into(), port: port.into(), server };
        true
    }
    fn unwire(&self, agent: &str, port: &str) -> bool {
        let mut q = lock(&self.queues);
        let wired = matches!(&q.target, MemTarget::Server { agent: a, port: p, .. } if a == agent && p == port);
        if wired {
            self.unwire_locked(&mut q);
        }
        wired
    }
    fn take_woken(&self) -> bool {
        self.woken.swap(false, Ordering::AcqRel)
    }
}

/// A call port of an agent in the harness.
#[derive(Clone)]
pub(crate) enum MemCallPort {
    /// a service it answers
    Service(Arc<dyn MemService>),
    /// a client it calls through
    Client(Arc<dyn MemCaller>),
}

impl MemCallPort {
    /// The port's name.
    pub(crate) fn name(&self) -> &str {
        match self {
            MemCallPort::Service(s) => &s.spec().name,
            MemCallPort::Client(c) => &c.spec().name,
        }
    }

    /// Whether a request or an answer came since the last look.
    pub(crate) fn take_woken(&self) -> bool {
        match self {
            MemCallPort::Service(s) => s.take_woken(),
            MemCallPort::Client(c) => c.take_woken(),
        }
    }
}

impl std::fmt::Debug for MemCallPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MemCallPort::Service(s) => write!(f, "Service({})", s.spec().name),
            MemCallPort::Client(c) => write!(f, "Client({})", c.spec().name),
        }
    }
}
