//! Calls answered with a sequence: a [`SeqServer`] answers each request
//! with a header `H` and any number of `T` (`Seq<T, H>`, the payload of
//! sequence ports, [`super::seq`]), up to the maximum it was declared
//! with; a [`SeqClient`] takes each answer as an owned `(H, Vec<T>)`.
//!
//! ```ignore
//! // the server, in `Agent::new`: paths of at most 4096 points
//! let plan = setup.serve_seq::<Goal, Point, PathHeader>("plan", 4096)?;
//! // in `step`: each waiting request answered with a path of its own length
//! plan.serve(|goal| (PathHeader { frame: 1 }, planner.path_to(goal)))?;
//!
//! // the client, in `Agent::new`, then in `step`
//! let planner = setup.client_seq::<Goal, Point, PathHeader>("planner")?;
//! planner.call(&Goal { x: 1.0, y: 2.6 })?;
//! while let Some((id, answer)) = planner.take() { let (header, points) = answer?; }
//! ```
//!
//! The same machinery as fixed calls carries them (`call_client`,
//! `call_server`): the same timeout, bound of calls in flight, server-gone
//! and unwired endings. On the wire an answer is an iceoryx2 slice of
//! 8-byte words holding the sequence sample's bytes (`H`, padding, then
//! the `T`s), after a [`SeqAnswerHeader`] that says how many elements it
//! holds and how many bytes. Each of the server's answer slots holds the
//! longest answer it was declared with (iceoryx2's static allocation; its
//! growing one made every new client wait about 1.5 s with iceoryx2 0.10),
//! at most 8 MiB of them (iceoryx2 zeroes them at start, so they are
//! resident) and at least 16: the answers that can wait for their clients
//! at once. An answer longer than the declared maximum is not sent: the
//! server's `serve` returns [`CallError::AnswerTooLong`] (after answering
//! the other requests) and the client's call ends with
//! [`CallError::RefusedTooLong`].

use super::bytes::{Binding, DynInput};
use super::call::memory::{MemCallPort, Unanswered};
use super::call::{Answer, CallError, Factory, MAX_IN_FLIGHT, Pending, ServerPort, Typed, call_settings};
use super::call_client::CallClient;
use super::call_server::CallServer;
use super::seq::{shape_of, view};
use crate::world::Ipc;
use iceoryx2::port::ReceiveError;
use iceoryx2::prelude::*;
use iceoryx2::response::Response;
use iceoryx2::service::attribute::AttributeVerifier;
use iceoryx2::service::builder::request_response::RequestResponseOpenOrCreateError;
use iceoryx2::service::port_factory::server::ServerCreateError;
use shm_schemas::control::agent_to_router::PortSpec;
use shm_schemas::control::call::{SEQ_ANSWERED, SEQ_TOO_LONG, SeqAnswerHeader, call_seq_spec};
use shm_schemas::{Described as _, Payload, Seq, SeqPart, SeqShape};
use std::marker::PhantomData;
use std::mem::{align_of, size_of};
use std::sync::Arc;

/// The most bytes of answer slots a sequence server makes (iceoryx2 zeroes
/// them when the server starts, so they are all resident), at least
/// [`MIN_SLOTS`] slots: answers waiting for their clients at once. Past
/// them an answer cannot be loaned ([`CallError::Loan`]) and its call
/// times out.
const MEMORY_BUDGET: usize = 8 << 20;
/// The fewest answer slots a sequence server makes.
const MIN_SLOTS: usize = 16;
/// One word of an answer's payload.
const WORD: usize = size_of::<u64>();

/// A sequence answer `Seq<T, H>`: the call of [`SeqServer`] and [`SeqClient`].
pub struct SeqAnswer<T, H>(PhantomData<fn() -> (T, H)>);

impl<T: SeqPart, H: SeqPart> std::fmt::Debug for SeqAnswer<T, H> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "SeqAnswer<{}>", Seq::<T, H>::schema().type_name)
    }
}

/// Where `Seq<T, H>`'s parts lie, from the Rust types (the schema says the
/// same: [`shape_of`] checks it when a port is declared).
fn rust_shape<T: SeqPart, H: SeqPart>() -> SeqShape {
    SeqShape {
        items_at: size_of::<H>().next_multiple_of(align_of::<T>().max(1)),
        element: size_of::<T>(),
        align: align_of::<H>().max(align_of::<T>()),
    }
}

/// `words` as the bytes they hold.
fn word_bytes(words: &[u64]) -> &[u8] {
    // SAFETY: u64s are plain bytes, any of them a valid u8, in one allocation
    unsafe { std::slice::from_raw_parts(words.as_ptr().cast::<u8>(), std::mem::size_of_val(words)) }
}

impl<T: SeqPart, H: SeqPart> Answer for SeqAnswer<T, H> {
    type Payload = [u64];
    type Header = SeqAnswerHeader;
    type Value = (H, Vec<T>);
    type View<'a> = (&'a H, &'a [T]);
    fn spec<Req: Payload>(port: &str) -> PortSpec {
        call_seq_spec::<Req, T, H>(port)
    }
    fn add_schemas(schemas: &mut Vec<shm_schemas::Schema>) {
        shm_schemas::control::agent_to_router::add_schema(schemas, Seq::<T, H>::schema());
    }
    fn layout() -> (usize, usize) {
        let shape = rust_shape::<T, H>();
        (shape.items_at, shape.align)
    }
    fn open<Req: Payload>(
        node: &Node<Ipc>,
        name: &ServiceName,
        attributes: &AttributeVerifier,
        create: bool,
    ) -> Result<Factory<Typed<Req, Self>>, RequestResponseOpenOrCreateError> {
        let builder = call_settings!(
            node.service_builder(name).request_response::<Req, [u64]>().response_user_header::<SeqAnswerHeader>()
        );
        if create {
            builder.open_or_create_with_attributes(attributes)
        } else {
            builder.open_with_attributes(attributes).map_err(RequestResponseOpenOrCreateError::RequestResponseOpenError)
        }
    }
    fn server<Req: Payload>(
        factory: &Factory<Typed<Req, Self>>,
        max_len: usize,
    ) -> Result<ServerPort<Typed<Req, Self>>, ServerCreateError> {
        let (words, slots) = answer_slots(&rust_shape::<T, H>(), max_len);
        factory
            .server_builder()
            .initial_max_slice_len(words)
            .allocation_strategy(AllocationStrategy::Static)
            .override_response_preallocation(slots)
            .create()
    }
    fn next_answer<Req: Payload>(
        pending: &Pending<Typed<Req, Self>>,
    ) -> Result<Option<Response<Ipc, [u64], SeqAnswerHeader>>, ReceiveError> {
        pending.receive()
    }
    fn view<'a>(
        response: &'a Response<Ipc, [u64], SeqAnswerHeader>,
        client: &str,
        service: &str,
    ) -> Result<(&'a H, &'a [T]), CallError> {
        let shape = rust_shape::<T, H>();
        let bytes = word_bytes(response.payload());
        let len = answer_len(response.user_header(), &shape, bytes.len(), client, service)?;
        view::<T, H>(&shape, &bytes[..len]).ok_or_else(|| CallError::Malformed {
            client: client.into(),
            service: service.into(),
            detail: format!("{len} bytes that are not a header and whole elements, aligned"),
        })
    }
    fn view_of(value: &(H, Vec<T>)) -> (&H, &[T]) {
        (&value.0, &value.1)
    }
    fn to_value((header, items): (&H, &[T])) -> (H, Vec<T>) {
        (*header, items.to_vec())
    }
}

/// The answer slots of a sequence server whose answers hold at most
/// `max_len` elements of `shape`: the 8-byte words of one slot, and how
/// many slots to make of the `n` iceoryx2 would (every client's every call
/// in flight), at most [`MEMORY_BUDGET`] bytes of them (at least
/// [`MIN_SLOTS`]). Every slot holds the longest answer: iceoryx2 0.10's
/// growing (dynamic) response memory made each new client take about
/// 1.5 s to open and to be answered, and the server spin.
pub(crate) fn answer_slots(shape: &SeqShape, max_len: usize) -> (usize, impl Fn(usize) -> usize + 'static) {
    let slot = shape.len_of(max_len).unwrap_or(usize::MAX).max(WORD);
    (slot.div_ceil(WORD), move |n: usize| n.min((MEMORY_BUDGET / slot).max(MIN_SLOTS)))
}

/// Refuses a sequence service `service` of `type_name` whose answers of
/// `max_len` elements of `shape` would not fit in a payload.
pub(crate) fn check_max_len(service: &str, type_name: &str, shape: &SeqShape, max_len: usize) -> Result<(), CallError> {
    if shape.len_of(max_len).is_none_or(|b| b > shm_schemas::schema::MAX_SIZE) {
        return Err(CallError::Open {
            service: service.into(),
            detail: format!(
                "answers of {max_len} elements of {type_name} would be larger than the {} bytes a payload may \
                 have; declare a smaller max_len",
                shm_schemas::schema::MAX_SIZE
            ),
        });
    }
    Ok(())
}

/// The bytes of the sequence answer `header` says its payload of
/// `payload_len` bytes holds (of `shape`), for client `client` of
/// `service`; why there are none: the server refused an answer too long,
/// or the answer is malformed.
pub(crate) fn answer_len(
    header: &SeqAnswerHeader,
    shape: &SeqShape,
    payload_len: usize,
    client: &str,
    service: &str,
) -> Result<usize, CallError> {
    if header.status == SEQ_TOO_LONG {
        return Err(CallError::RefusedTooLong {
            client: client.into(),
            service: service.into(),
            len: header.items,
            max: header.max,
        });
    }
    let malformed = |detail: String| CallError::Malformed { client: client.into(), service: service.into(), detail };
    if header.status != SEQ_ANSWERED {
        return Err(malformed(format!("an answer of unknown status {}", header.status)));
    }
    usize::try_from(header.items)
        .ok()
        .and_then(|n| shape.len_of(n))
        .filter(|l| *l <= payload_len && *l as u64 == header.bytes)
        .ok_or_else(|| {
            malformed(format!("{} elements in {} bytes said, in {payload_len} bytes", header.items, header.bytes))
        })
}

/// A service an agent answers with sequences: requests `Req`, answers of
/// header `H` and up to the declared maximum of `T`.
pub struct SeqServer<Req: Payload, T: SeqPart, H: SeqPart = shm_schemas::NoHeader> {
    server: CallServer<Typed<Req, SeqAnswer<T, H>>>,
    max_len: usize,
    shape: SeqShape,
}

impl<Req: Payload, T: SeqPart, H: SeqPart> std::fmt::Debug for SeqServer<Req, T, H> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SeqServer").field("server", &self.server).field("max_len", &self.max_len).finish()
    }
}

/// A client of a service answered with sequences of `T` after header `H`;
/// its `take` hands out each answer as an owned `(H, Vec<T>)`.
pub type SeqClient<Req, T, H = shm_schemas::NoHeader> = CallClient<Typed<Req, SeqAnswer<T, H>>>;

impl<Req: Payload, T: SeqPart, H: SeqPart> SeqServer<Req, T, H> {
    /// Service `port` (iceoryx2 service `service`), bound to `binding`,
    /// answering with at most `max_len` elements.
    pub(crate) fn bind(
        binding: &Binding,
        port: &str,
        service: &str,
        max_len: usize,
    ) -> Result<(Self, Arc<dyn DynInput>), CallError> {
        let (schema, shape) = shape_of::<T, H>(service)
            .map_err(|e| CallError::Open { service: service.into(), detail: e.to_string() })?;
        check_max_len(service, &schema.type_name, &shape, max_len)?;
        let (server, side) = CallServer::bind(binding, port, service, max_len)?;
        Ok((SeqServer { server, max_len, shape }, side))
    }

    /// Answers each waiting request with the header and elements `answer`
    /// returns (at most `max` requests: what arrives meanwhile is left for
    /// the next step, whose wake-up is pending); returns how many were
    /// answered. An answer longer than [`SeqServer::max_len`] is not sent:
    /// its client's call ends with [`CallError::RefusedTooLong`], the other
    /// requests are answered, then [`CallError::AnswerTooLong`] is returned.
    pub fn serve_up_to(&self, max: usize, mut answer: impl FnMut(&Req) -> (H, Vec<T>)) -> Result<usize, CallError> {
        let service = self.server.service();
        if let Some(mem) = self.server.memory() {
            let (n, first) = mem.serve::<std::convert::Infallible>(max, |request| {
                let (header, items) = answer(request);
                if items.len() > self.max_len {
                    return Err(Unanswered::TooLong { len: items.len(), max: self.max_len });
                }
                Ok((header, items))
            });
            self.server.count_answered(n);
            return match first {
                Some(Unanswered::TooLong { len, max }) => {
                    tracing::warn!(service, len, max, "an answer longer than the maximum was refused");
                    Err(CallError::AnswerTooLong { service: service.into(), len, max })
                }
                _ => Ok(n),
            };
        }
        self.server.each_request(max, |request| {
            let (header, items) = answer(request.payload());
            let n = items.len();
            let refused = n > self.max_len;
            let len = if refused { 0 } else { self.shape.len_of(n).unwrap_or(0) };
            let words = len.div_ceil(WORD);
            let loan = request.loan_slice_uninit(words).map_err(|source| CallError::Loan {
                service: service.into(),
                len: n,
                source,
            })?;
            let mut response = loan.write_from_fn(|_| 0u64);
            *response.user_header_mut() = SeqAnswerHeader {
                status: if refused { SEQ_TOO_LONG } else { SEQ_ANSWERED },
                reserved: 0,
                items: n as u64,
                max: self.max_len as u64,
                bytes: len as u64,
            };
            if !refused {
                let at = response.payload_mut().as_mut_ptr().cast::<u8>();
                // SAFETY: the payload is `words` 8-byte words, at least
                // `items_at + n * size_of::<T>()` bytes (`len_of`), 8-aligned
                // (a u64 slice), so aligned for `H` and, at `items_at` (a
                // multiple of T's alignment), for `T` (both at most 8:
                // `SEQ_MAX_ALIGN`, checked by `shape_of`'s schema); the
                // response is the only reference to it until sent.
                unsafe {
                    at.cast::<H>().write(header);
                    std::ptr::copy_nonoverlapping(items.as_ptr(), at.add(self.shape.items_at).cast::<T>(), n);
                }
            }
            if let Err(e) = response.send() {
                // the client went away: nobody waits for this answer
                tracing::debug!(service, "an answer found no client: {e:?}");
            }
            if refused {
                tracing::warn!(service, len = n, max = self.max_len, "an answer longer than the maximum was refused");
                return Err(CallError::AnswerTooLong { service: service.into(), len: n, max: self.max_len });
            }
            Ok(true)
        })
    }

    /// Answers every waiting request (at most [`MAX_IN_FLIGHT`] per step),
    /// as [`SeqServer::serve_up_to`] does.
    pub fn serve(&self, answer: impl FnMut(&Req) -> (H, Vec<T>)) -> Result<usize, CallError> {
        self.serve_up_to(MAX_IN_FLIGHT, answer)
    }

    /// The most elements an answer may hold, as declared.
    pub fn max_len(&self) -> usize {
        self.max_len
    }

    /// How many requests it answered so far (refusals included).
    pub fn answered(&self) -> u64 {
        self.server.answered()
    }

    /// The iceoryx2 service name.
    pub fn service(&self) -> &str {
        self.server.service()
    }

    /// In the test harness: the port as the harness reaches it.
    pub(crate) fn memory_port(&self) -> Option<MemCallPort> {
        self.server.memory_port()
    }
}

#[cfg(test)]
mod tests {
    use super::{SeqClient, SeqServer};
    use crate::port::bytes::Binding;
    use crate::port::call::{CallError, CallId, CallOptions, Client};
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::payloads::{Scalar, Tick};
    use std::sync::Arc;
    use std::time::Duration;

    #[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, shm_schemas::Payload)]
    #[repr(C)]
    #[payload(name = "test::Point")]
    struct Point {
        x: f64,
        y: f64,
        id: u32,
        pad: u32,
    }

    fn point(i: usize) -> Point {
        Point { x: i as f64, y: -(i as f64), id: i as u32, pad: 0 }
    }

    /// Takes the client's next finished call, waiting (bounded) for it.
    fn next<R>(take: impl Fn() -> Option<(CallId, R)>) -> (CallId, R) {
        for _ in 0..500 {
            if let Some(done) = take() {
                return done;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        panic!("no call finished within 1 s");
    }

    /// A server answers requests with sequences of the length each asks
    /// for: 0, 1, 300 (7.2 kB, more than a memory page) and the maximum,
    /// each taken whole by the client; one past the maximum is
    /// refused on both sides, and the next call is answered again. A
    /// client of a fixed answer cannot open the sequence service.
    #[test]
    fn a_call_answers_with_a_sequence_of_any_length_up_to_the_maximum() {
        let world = World::new(&format!("callseq{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = Arc::new(world.node("test").expect("node"));
        let robot = world.robot().clone();
        let service = robot.port_service("planner", "plan");
        let max = 1000;
        let (server, _) =
            SeqServer::<Tick, Point, Scalar>::bind(&Binding::Shm(node.clone()), "plan", &service, max).expect("server");
        assert_eq!(server.max_len(), max);
        let options = CallOptions { timeout: Duration::from_secs(5), max_in_flight: 4 };
        let (client, side) =
            SeqClient::<Tick, Point, Scalar>::bind(&Binding::Shm(node.clone()), "planner", options).expect("client");
        assert!(side.connect(&node, &robot, "planner", "plan").expect("wired"));
        let answer = |req: &Tick| {
            let n = req.seq as usize;
            (Scalar { value: n as f64, stamp_ns: req.stamp_ns }, (0..n).map(point).collect::<Vec<_>>())
        };
        for n in [0usize, 1, 300, max] {
            let id = client.call(&Tick { seq: n as u64, stamp_ns: 9 }).expect("call");
            let mut served = 0;
            for _ in 0..500 {
                served += server.serve(answer).expect("served");
                if served > 0 {
                    break;
                }
                std::thread::sleep(Duration::from_millis(2));
            }
            assert_eq!(served, 1, "length {n}");
            let (got, result) = next(|| client.take());
            let (header, items) = result.expect("answered");
            assert_eq!(got, id);
            assert_eq!(header, Scalar { value: n as f64, stamp_ns: 9 }, "length {n}");
            assert_eq!(items, (0..n).map(point).collect::<Vec<_>>(), "length {n}");
        }
        // past the maximum: refused, the client told so
        let id = client.call(&Tick { seq: max as u64 + 1, stamp_ns: 9 }).expect("call");
        let mut refused = None;
        for _ in 0..500 {
            match server.serve(answer) {
                Ok(0) => std::thread::sleep(Duration::from_millis(2)),
                other => {
                    refused = Some(other);
                    break;
                }
            }
        }
        match refused {
            Some(Err(e @ CallError::AnswerTooLong { len, max: m, .. })) => {
                assert_eq!((len, m), (max + 1, max));
                assert!(e.to_string().contains("max_len"), "{e}");
            }
            other => panic!("an answer past the maximum: {other:?}"),
        }
        match next(|| client.take()) {
            (got, Err(e @ CallError::RefusedTooLong { len, max: m, .. })) => {
                assert_eq!((got, len, m), (id, max as u64 + 1, max as u64));
                assert!(!e.maybe_carried_out() && e.to_string().contains("refused"), "{e}");
            }
            other => panic!("the client of a refused answer: {other:?}"),
        }
        let id = client.call(&Tick { seq: 2, stamp_ns: 9 }).expect("call");
        for _ in 0..500 {
            if server.serve(answer).expect("served") > 0 {
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        let (got, result) = next(|| client.take());
        assert_eq!((got, result.expect("answered").1.len()), (id, 2));
        // a client of a fixed answer is refused by the sequence service
        let (_, fixed) = Client::<Tick, Scalar>::bind(&Binding::Shm(node.clone()), "fixed", options).expect("client");
        let e = fixed.connect(&node, &robot, "planner", "plan").expect_err("a fixed client of a sequence service");
        assert!(e.to_string().contains("call(nerve::Tick -> nerve::Scalar)"), "{e}");
    }
}

#[cfg(test)]
mod raw_tests {
    use super::SeqServer;
    use crate::port::RawCaller;
    use crate::port::bytes::Binding;
    use crate::port::call::CallError;
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::payloads::{Scalar, Tick};
    use shm_schemas::{Described as _, Seq};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::Duration;

    fn tick_bytes(t: &Tick) -> Vec<u8> {
        [t.seq.to_le_bytes(), t.stamp_ns.to_le_bytes()].concat()
    }

    /// A tool's caller (`nerve call`), one process after another: each
    /// sequence answer comes as the bytes of its `Seq<Scalar, Tick>`
    /// sample at its own length, decoded by the sequence's schema; one past
    /// the maximum is refused.
    #[test]
    fn a_raw_caller_takes_a_sequence_answer_as_its_sample_bytes() {
        let world = World::new(&format!("callseqraw{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = Arc::new(world.node("test").expect("node"));
        let service = world.robot().port_service("planner", "plan");
        let max = 600;
        let (server, _) =
            SeqServer::<Tick, Scalar, Tick>::bind(&Binding::Shm(node.clone()), "plan", &service, max).expect("server");
        let stop = Arc::new(AtomicBool::new(false));
        let serving = {
            let stop = stop.clone();
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let _ =
                        server.serve(|t| (*t, (0..t.seq).map(|i| Scalar { value: i as f64, stamp_ns: 5 }).collect()));
                    std::thread::sleep(Duration::from_millis(1));
                }
            })
        };
        let schema = Seq::<Scalar, Tick>::schema();
        for n in [0u64, 1, 600, 1, 300] {
            let t0 = std::time::Instant::now();
            let tool = world.node("tool").expect("node");
            let t1 = t0.elapsed();
            let caller = RawCaller::open(&tool, &service).expect("caller");
            let t2 = t0.elapsed();
            let bytes =
                caller.call(&tick_bytes(&Tick { seq: n, stamp_ns: 5 }), Duration::from_secs(2)).expect("answer");
            eprintln!("DEBUG {n}: node {t1:?} open {t2:?} call {:?}", t0.elapsed());
            let value = serde_json::to_value(schema.decode(&bytes).expect("decoded")).expect("json");
            assert_eq!(value["items"].as_array().map(Vec::len), Some(n as usize), "{value}");
            assert_eq!(value["header"]["seq"].as_u64(), Some(n), "{value}");
        }
        let tool = world.node("tool").expect("node");
        let caller = RawCaller::open(&tool, &service).expect("caller");
        match caller.call(&tick_bytes(&Tick { seq: 601, stamp_ns: 5 }), Duration::from_secs(2)) {
            Err(CallError::RefusedTooLong { len: 601, max: 600, .. }) => {}
            other => panic!("past the maximum: {other:?}"),
        }
        stop.store(true, Ordering::Relaxed);
        serving.join().expect("server thread");
    }
}
