//! The byte port: the one place that talks to iceoryx2 publish-subscribe.
//!
//! A [`SchemaOutput`] publishes, and a [`SchemaInput`] reads, samples of a
//! payload layout described by a [`Schema`], as bytes in place in shared
//! memory (zero copy): an output loans a slot ([`Loan`]), the writer fills
//! it, and [`SchemaOutput::send`] stamps its [`SampleHeader`] and wakes the
//! readers; an input hands out each waiting sample in place ([`Received`],
//! or a callback given its bytes), round robin between its sources.
//!
//! Every other port is a view of these: a typed [`crate::Output`] and
//! [`crate::Input`] (`port::typed`) read and write a Rust type in place in
//! the same bytes; Python agents use them directly; `nerve replay` and
//! `nerve pub` publish through [`RawOutput`]; and `nerve echo`, `hz`, the
//! recorder read a port of any type through [`RawPort`], which learns the
//! payload's size and alignment from the service itself (iceoryx2 keeps them
//! in the service's static configuration, as its own `iox2` tool reads them).
//!
//! What a port is bound to is a [`Binding`]: an iceoryx2 service in a
//! running agent, nothing while the agent is described (`--describe`), or
//! in-memory queues in a test (`port::memory`).
//!
//! A sample has the payload's fixed size, or, for a sequence
//! ([`shm_schemas::seq`]), the length its elements make: a loan is made for
//! a given length ([`SchemaOutput::loan_len`]), which a fixed-size port
//! refuses unless it is the layout's size, and a sequence port refuses
//! unless it is a header and whole elements within the port's declared
//! maximum. A sequence port is iceoryx2's slice service of bytes; its
//! publisher's memory grows (power of two) when a sample is larger than any
//! before, and its readers follow.

use super::error::{PortError, perr, port_err};
use super::keep_all::{KeepAllFeed, KeepAllFigures, KeepAllSender};
use super::memory::{Bus, Collected, Queue, SampleBuf};
use super::service::{
    Carried, MAX_SOURCES, OutputFactory, SUBSCRIBER_BUFFER, lock, output_service, port_event, raw_source_service,
    source_event, source_service,
};
use crate::clock::now_ns;
use crate::meters::RateMeter;
use crate::world::Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::service::marker::{CustomHeaderMarker, CustomPayloadMarker};
use shm_schemas::control::agent_to_router::PortSpec;
use shm_schemas::services::port_attributes;
use shm_schemas::stats::{InputStats, QueueStats};
use shm_schemas::{FixedName, SampleHeader, Schema, SeqShape};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// What the ports an agent declares are bound to. The SDK chooses it
/// before it calls [`crate::Agent::new`]; the agent never needs to know which.
pub(crate) enum Binding {
    /// `--describe`: nothing is made (no iceoryx2 node, no shared memory)
    Nothing,
    /// a running agent: iceoryx2 services of the robot, through its node
    Shm(Arc<Node<Ipc>>),
    /// a test ([`crate::testing`]): in-memory queues and lists
    Memory(Arc<Bus>),
}

/// Metadata of a received sample.
#[derive(Debug, Clone, Copy)]
pub struct Meta {
    /// the sending agent
    pub sender: FixedName,
    /// sequence number on the sending port
    pub seq: u64,
    /// when it was sent (CLOCK_MONOTONIC ns)
    pub stamp_ns: u64,
}

impl Meta {
    /// The metadata a sample's header carries.
    pub(crate) fn of(h: &SampleHeader) -> Self {
        Meta { sender: h.sender, seq: h.seq, stamp_ns: h.stamp_ns }
    }
}

/// A subscription to a port, handing out its samples' payloads as bytes.
pub(crate) type ByteSubscriber = Subscriber<Ipc, [CustomPayloadMarker], SampleHeader>;

/// The bytes of a shared-memory payload.
pub(crate) fn payload_bytes(payload: &[CustomPayloadMarker]) -> &[u8] {
    // SAFETY: CustomPayloadMarker is a #[repr(C)] wrapper of one u8: the
    // slice is the sample's payload bytes, alive as long as `payload` is.
    unsafe { std::slice::from_raw_parts(payload.as_ptr().cast::<u8>(), payload.len()) }
}

// ---------------------------------------------------------------- output

/// An output port of the payload layout a [`Schema`] describes: the byte
/// port every output is.
#[derive(Debug)]
pub struct SchemaOutput {
    service: String,
    schema: Schema,
    carried: Carried,
    sender: FixedName,
    seq: AtomicU64,
    sink: Sink,
    /// a sequence port's shape and bound; `None` for a fixed size
    limit: Option<SeqLimit>,
}

/// What a sequence port accepts: a header and whole elements, at most `max_len` of them.
#[derive(Debug, Clone, Copy)]
struct SeqLimit {
    shape: SeqShape,
    max_len: usize,
}

/// The bytes a sequence port's publisher reserves per sample at first
/// (its memory then grows, power of two, with the largest sample sent).
const SEQ_INITIAL_BYTES: usize = 4096;

/// Where an output's samples go.
// A running agent's variant is the large one and the only one on the data
// path; boxing it would add a pointer hop to every send.
#[allow(clippy::large_enum_variant)]
enum Sink {
    /// a running agent: the port's iceoryx2 service and its wake-up event,
    /// and its keep-all readers' service when it has some (`port::keep_all`;
    /// `None` for a tool's output, whose keep-all readers read copies)
    Shm {
        publisher: Publisher<Ipc, [CustomPayloadMarker], CustomHeaderMarker>,
        notifier: Notifier<Ipc>,
        factory: OutputFactory,
        keep_all: Option<KeepAllSender>,
    },
    /// a test: the harness collects them
    Memory(Arc<Collected>),
    /// `--describe`: the agent never steps, nothing is sent
    Nothing,
}

impl std::fmt::Debug for Sink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Sink::Shm { .. } => "Shm",
            Sink::Memory(_) => "Memory",
            Sink::Nothing => "Nothing",
        })
    }
}

impl SchemaOutput {
    /// Output `port` (service `service`) of agent `sender`, carrying
    /// `carried` laid out as `schema`, bound to `binding`. `typed`: declared
    /// with a Rust type (a test's wiring then checks its fingerprint).
    pub(crate) fn bind(
        binding: &Binding,
        port: &str,
        service: &str,
        sender: &str,
        schema: Schema,
        carried: Carried,
        typed: bool,
    ) -> Result<Self, PortError> {
        let sink = match binding {
            Binding::Shm(node) => return Self::shm_with(node, Some(node), service, sender, schema, carried),
            Binding::Nothing => Sink::Nothing,
            Binding::Memory(bus) => {
                Sink::Memory(bus.add_output(port, &carried.type_name, typed.then_some(carried.fingerprint)))
            }
        };
        Ok(Self::with_sink(service, sender, schema, carried, sink))
    }

    /// Opens (or creates) output port `service` of agent `sender` as an
    /// iceoryx2 service (a tool's: its keep-all readers read copies).
    pub(crate) fn shm(
        node: &Node<Ipc>,
        service: &str,
        sender: &str,
        schema: Schema,
        carried: Carried,
    ) -> Result<Self, PortError> {
        Self::shm_with(node, None, service, sender, schema, carried)
    }

    /// [`SchemaOutput::shm`]; with `shared` (the same node, shared), it
    /// also publishes to keep-all readers losslessly (`port::keep_all`).
    pub(crate) fn shm_with(
        node: &Node<Ipc>,
        shared: Option<&Arc<Node<Ipc>>>,
        service: &str,
        sender: &str,
        schema: Schema,
        carried: Carried,
    ) -> Result<Self, PortError> {
        let ps = output_service(node, service, &carried)?;
        let builder = ps.publisher_builder();
        let initial = schema
            .sequence_shape()
            .filter(|_| carried.is_sequence())
            .map(|shape| shape.items_at.max(SEQ_INITIAL_BYTES));
        let builder = match initial {
            // a slice of bytes: as long as the first samples at most, then grown with the largest sent
            Some(len) => builder.initial_max_slice_len(len).allocation_strategy(AllocationStrategy::PowerOfTwo),
            None => builder,
        };
        let publisher = builder.create().map_err(port_err!(Publisher, service))?;
        let notifier = port_event(node, service)?.notifier_builder().create().map_err(port_err!(Notifier, service))?;
        let keep_all = shared.map(|node| KeepAllSender::new(node.clone(), service, carried.clone(), initial));
        let sink = Sink::Shm { publisher, notifier, factory: ps, keep_all };
        Ok(Self::with_sink(service, sender, schema, carried, sink))
    }

    /// Output `port` (service `service`) of agent `sender`, of the payload
    /// layout `schema` (checked: it comes from outside, a Python agent's
    /// class), bound to `binding`.
    pub(crate) fn declare(
        binding: &Binding,
        port: &str,
        service: &str,
        sender: &str,
        schema: Schema,
    ) -> Result<Self, PortError> {
        let carried = Carried::of_schema(service, &schema, schema.fingerprint())?;
        Self::bind(binding, port, service, sender, schema, carried, false)
    }

    /// Output port `service` of layout `schema` in shared memory, sent as `sender`.
    #[cfg(test)]
    pub(crate) fn create(node: &Node<Ipc>, service: &str, schema: Schema, sender: &str) -> Result<Self, PortError> {
        let carried = Carried::of_schema(service, &schema, schema.fingerprint())?;
        Self::shm(node, service, sender, schema, carried)
    }

    /// What it counted of its keep-all readers (`port::keep_all`); `None`
    /// for a port that does not publish to them (a test's, a tool's).
    pub fn keep_all_figures(&self) -> Option<&Arc<KeepAllFigures>> {
        match &self.sink {
            Sink::Shm { keep_all: Some(k), .. } => Some(k.figures()),
            _ => None,
        }
    }

    fn with_sink(service: &str, sender: &str, schema: Schema, carried: Carried, sink: Sink) -> Self {
        let limit = schema
            .sequence_shape()
            .filter(|_| carried.is_sequence())
            .map(|shape| SeqLimit { shape, max_len: shape.count_of_at_most(shm_schemas::schema::MAX_SIZE) });
        SchemaOutput {
            service: service.into(),
            schema,
            carried,
            sender: FixedName::new(sender),
            seq: AtomicU64::new(0),
            sink,
            limit,
        }
    }

    /// The most elements a sample of this sequence port may hold; `None`
    /// for a port of a fixed size.
    pub fn max_len(&self) -> Option<usize> {
        self.limit.map(|l| l.max_len)
    }

    /// Bounds this sequence port's samples to `max_len` elements (and the
    /// [64 MiB](shm_schemas::schema::MAX_SIZE) every payload is bounded
    /// to); a longer loan is refused ([`PortError::TooLong`]), nothing
    /// sent. Refused for a port of a fixed size.
    pub(crate) fn set_max_len(&mut self, max_len: usize) -> Result<(), PortError> {
        let Some(limit) = &mut self.limit else {
            return Err(PortError::Ipc {
                service: self.service.clone(),
                detail: format!("{} is not a sequence: it has no length", self.carried.type_name),
            });
        };
        limit.max_len = max_len.min(limit.shape.count_of_at_most(shm_schemas::schema::MAX_SIZE));
        Ok(())
    }

    /// Loans a sample of a sequence port with room for `n` elements after
    /// its header, not zeroed (its bytes are what the slot last held).
    pub fn loan_items(&self, n: usize) -> Result<Loan, PortError> {
        let Some(limit) = &self.limit else {
            return Err(PortError::Ipc {
                service: self.service.clone(),
                detail: format!("{} is not a sequence: loan it whole", self.carried.type_name),
            });
        };
        let len = limit.shape.len_of(n).filter(|_| n <= limit.max_len).ok_or_else(|| PortError::TooLong {
            service: self.service.clone(),
            len: n,
            max_len: limit.max_len,
        })?;
        self.loan_len(len, false)
    }

    /// The iceoryx2 service name of this port.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The layout of what it sends.
    pub fn schema(&self) -> &Schema {
        &self.schema
    }

    pub(crate) fn carried(&self) -> &Carried {
        &self.carried
    }

    /// Loans a sample to write in place. `zeroed`: every byte is zero
    /// first; otherwise the bytes are what the slot last held, and the
    /// writer must write every field a reader looks at (a large frame then
    /// costs one write, not two).
    pub fn loan(&self, zeroed: bool) -> Result<Loan, PortError> {
        self.loan_len(self.schema.size, zeroed)
    }

    /// Loans `len` bytes of payload. A fixed-size payload is loaned whole:
    /// another length is refused. A sequence's is a header and whole
    /// elements, at most the port's maximum of them: another length is
    /// refused, and nothing is loaned or sent.
    pub fn loan_len(&self, len: usize, zeroed: bool) -> Result<Loan, PortError> {
        let units = match &self.limit {
            None if len != self.carried.size() => {
                return Err(PortError::Ipc {
                    service: self.service.clone(),
                    detail: format!("a {len}-byte loan of a {}-byte type", self.carried.size()),
                });
            }
            None => 1,
            Some(limit) => match limit.shape.count_of(len) {
                Some(n) if n <= limit.max_len => len,
                Some(n) => {
                    return Err(PortError::TooLong { service: self.service.clone(), len: n, max_len: limit.max_len });
                }
                None => {
                    return Err(PortError::Ipc {
                        service: self.service.clone(),
                        detail: format!(
                            "a {len}-byte sample of {} is not its {}-byte header and whole {}-byte elements",
                            self.carried.type_name, limit.shape.items_at, limit.shape.element
                        ),
                    });
                }
            },
        };
        match &self.sink {
            Sink::Shm { publisher, .. } => {
                // SAFETY: one element of a FixedSize type (set in
                // `service::output_builder`): `size` bytes, and the header's
                // element count is set by iceoryx2 to 1; or, for a sequence,
                // `len` one-byte elements of a Dynamic type
                // (`Carried::of_sequence`), the count iceoryx2 sets to `len`
                let mut sample =
                    unsafe { publisher.loan_custom_payload(units) }.map_err(port_err!(Loan, &self.service))?;
                let payload = sample.payload_mut();
                if payload.len() != len {
                    return Err(PortError::Ipc {
                        service: self.service.clone(),
                        detail: format!("loaned {} bytes for a {len}-byte sample", payload.len()),
                    });
                }
                if zeroed {
                    // SAFETY: `payload` is `len` one-byte elements, writable
                    unsafe { std::ptr::write_bytes(payload.as_mut_ptr().cast::<u8>(), 0, len) };
                }
                // SAFETY: the payload lies in the service's shared memory,
                // which is zero when mapped and holds earlier samples' bytes
                // after: every byte is initialised (zeroed above, or as the
                // slot was last written), and any bytes are valid for a byte buffer.
                Ok(Loan(LoanInner::Shm(unsafe { sample.assume_init() })))
            }
            Sink::Memory(_) | Sink::Nothing => {
                Ok(Loan(LoanInner::Detached(SampleBuf::zeroed(&self.service, len, self.carried.align())?)))
            }
        }
    }

    /// Sends a loaned sample, stamped now, and wakes the readers.
    pub fn send(&mut self, loan: Loan) -> Result<(), PortError> {
        self.publish(loan).map(|_| ())
    }

    /// Sends `bytes` (exactly the layout's size), copied into a loaned sample.
    pub fn send_bytes(&mut self, bytes: &[u8]) -> Result<(), PortError> {
        self.publish_bytes(bytes).map(|_| ())
    }

    /// [`SchemaOutput::send_bytes`], returning how many readers it reached.
    pub(crate) fn publish_bytes(&self, bytes: &[u8]) -> Result<usize, PortError> {
        if self.limit.is_none() && bytes.len() != self.carried.size() {
            return Err(PortError::Ipc {
                service: self.service.clone(),
                detail: format!("a {}-byte sample for a {}-byte type", bytes.len(), self.carried.size()),
            });
        }
        let mut loan = self.loan_len(bytes.len(), false)?;
        loan.bytes_mut().copy_from_slice(bytes);
        self.publish(loan)
    }

    /// The header of the next sample: this port's sender, its next
    /// sequence number, stamped now.
    pub(crate) fn next_header(&self) -> SampleHeader {
        let seq = self.seq.fetch_add(1, Ordering::Relaxed).wrapping_add(1);
        SampleHeader { sender: self.sender, seq, stamp_ns: now_ns() }
    }

    /// Sends a loaned sample, stamped now, and wakes the readers; returns
    /// how many readers it reached (0 before a new subscriber is seen).
    pub(crate) fn publish(&self, loan: Loan) -> Result<usize, PortError> {
        self.publish_as(loan, self.next_header())
    }

    /// Sends a loaned sample with `header` (from [`SchemaOutput::next_header`],
    /// taken when the sample was loaned: a typed port stamps a sample when
    /// it starts writing it) and wakes the readers.
    pub(crate) fn publish_as(&self, loan: Loan, header: SampleHeader) -> Result<usize, PortError> {
        match (&self.sink, loan.0) {
            (Sink::Shm { notifier, factory, keep_all, .. }, LoanInner::Shm(mut sample)) => {
                // SAFETY: the service's user header is a SampleHeader (set in
                // `service::output_builder`); the marker is a zero-sized
                // stand-in at its address, which is aligned for it
                unsafe { (sample.user_header_mut() as *mut CustomHeaderMarker).cast::<SampleHeader>().write(header) };
                if let Some(keep_all) = keep_all {
                    // one atomic load and a comparison while no keep-all reader reads this port
                    keep_all.before_send(factory.dynamic_config().number_of_subscribers());
                    keep_all.send(&header, payload_bytes(sample.payload()));
                }
                let reached = sample.send().map_err(port_err!(Send, &self.service))?;
                notifier.notify().map_err(port_err!(Notify, &self.service))?;
                Ok(reached)
            }
            (Sink::Memory(c), LoanInner::Detached(sample)) => {
                c.push(header.sender, header.seq, sample);
                Ok(1)
            }
            (Sink::Nothing, _) => Ok(0),
            _ => Err(PortError::Ipc {
                service: self.service.clone(),
                detail: "the sample was not loaned from this port".into(),
            }),
        }
    }
}

/// A sample loaned from an output port, written in place before it is sent.
pub struct Loan(LoanInner);

enum LoanInner {
    /// a slot of the port's shared memory
    Shm(SampleMut<Ipc, [CustomPayloadMarker], CustomHeaderMarker>),
    /// a port bound to memory or to nothing: bytes of its own
    Detached(SampleBuf),
}

impl std::fmt::Debug for Loan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Loan").field("len", &self.bytes().len()).finish()
    }
}

impl Loan {
    /// The payload's bytes.
    pub fn bytes(&self) -> &[u8] {
        match &self.0 {
            LoanInner::Shm(sample) => payload_bytes(sample.payload()),
            LoanInner::Detached(b) => b.bytes(),
        }
    }

    /// The payload's bytes, to write.
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        match &mut self.0 {
            LoanInner::Shm(sample) => {
                let payload = sample.payload_mut();
                // SAFETY: as in `payload_bytes`, and the loan is the only writer
                unsafe { std::slice::from_raw_parts_mut(payload.as_mut_ptr().cast::<u8>(), payload.len()) }
            }
            LoanInner::Detached(b) => b.bytes_mut(),
        }
    }
}

// ---------------------------------------------------------------- input

/// A sample received on a [`SchemaInput`], read in place: its bytes stay in
/// shared memory, and the slot is not reused by the sender, until it is
/// dropped.
pub struct Received(ReceivedInner);

enum ReceivedInner {
    /// a slot of the source port's shared memory
    Shm(Sample<Ipc, [CustomPayloadMarker], SampleHeader>),
    /// a test's sample ([`crate::testing`])
    Memory(SampleHeader, SampleBuf),
}

impl std::fmt::Debug for Received {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Received").field("meta", &self.meta()).field("len", &self.bytes().len()).finish()
    }
}

impl Received {
    /// Who sent it, its number and stamp.
    pub fn meta(&self) -> Meta {
        match &self.0 {
            ReceivedInner::Shm(sample) => Meta::of(sample.user_header()),
            ReceivedInner::Memory(h, _) => Meta::of(h),
        }
    }

    /// The payload's bytes, as the sender wrote them (the schema's layout).
    pub fn bytes(&self) -> &[u8] {
        match &self.0 {
            ReceivedInner::Shm(sample) => payload_bytes(sample.payload()),
            ReceivedInner::Memory(_, bytes) => bytes.bytes(),
        }
    }
}

/// What an input counts about one source.
#[derive(Default)]
pub(crate) struct Tally {
    received: u64,
    dropped: u64,
    last_seq: u64,
    last_ns: Option<u64>,
    rate: RateMeter,
}

/// Samples lost between `last_seq` and `seq` on one sender's port. A sender
/// is another process: its numbers are not trusted, so nothing here can
/// overflow, and a number going backwards (a restarted sender) loses nothing.
pub(crate) fn gap(last_seq: u64, seq: u64) -> u64 {
    if last_seq == 0 { 0 } else { seq.saturating_sub(last_seq.saturating_add(1)) }
}

impl Tally {
    pub(crate) fn account(&mut self, h: &SampleHeader, now: u64) {
        self.received = self.received.saturating_add(1);
        self.dropped = self.dropped.saturating_add(gap(self.last_seq, h.seq));
        self.last_seq = h.seq;
        self.last_ns = Some(now);
        self.rate.record(now);
    }

    /// What `nerve ps` shows of input `input`'s source `from_agent/from_port`.
    pub(crate) fn stats(&self, input: &str, from_agent: &str, from_port: &str, now: u64) -> InputStats {
        InputStats {
            input: input.into(),
            from_agent: from_agent.into(),
            from_port: from_port.into(),
            received: self.received,
            rate_hz: self.rate.rate(now),
            last_age_ns: self.last_ns.map(|t| now.saturating_sub(t)),
            dropped: self.dropped,
        }
    }
}

/// One source of an input.
struct Source {
    from_agent: String,
    from_port: String,
    feed: Feed,
    tally: Tally,
    /// the input's own queue when it is deeper than iceoryx2's or keeps all ([`super::depth`])
    held: Option<super::depth::Held>,
    /// a keep-all input's lossless subscription ([`super::keep_all`])
    keep_all: Option<KeepAllFeed>,
}

/// Where a source's samples come from.
enum Feed {
    /// a running agent: a subscription to the source port and its wake-up event
    Shm { subscriber: ByteSubscriber, listener: Arc<Listener<Ipc>> },
    /// a test: the samples the harness queued
    Memory(Queue),
}

impl Source {
    fn receive_error(&self, input: &str, e: impl std::fmt::Debug) -> PortError {
        PortError::Ipc {
            service: format!("{}/{}", self.from_agent, self.from_port),
            detail: format!("input {input:?} cannot take another sample ({e:?}): drop the ones held, or keep copies"),
        }
    }

    /// Whether this keep-all source's output publishes to its keep-all
    /// service now (then the port's own service holds only duplicates).
    fn lossless(&mut self) -> bool {
        let Some(feed) = self.keep_all.as_mut() else { return false };
        let delivered = (self.tally.received > 0).then_some(self.tally.last_seq);
        feed.is_live(self.held.as_ref().and_then(|h| h.last_seq()).max(delivered))
    }

    /// A keep-all source read losslessly: what is left in its own queue,
    /// then the next sample of the keep-all service, in place; the port's
    /// own service emptied. `None` when the source is not read so.
    fn take_lossless(&mut self, input: &str) -> Option<Result<Option<(SampleHeader, Received)>, PortError>> {
        if !self.lossless() {
            return None;
        }
        if let Feed::Shm { subscriber, .. } = &self.feed {
            super::keep_all::discard(subscriber);
        }
        if let Some((h, b)) = self.held.as_mut().and_then(|held| held.pop()) {
            return Some(Ok(Some((h, Received(ReceivedInner::Memory(h, b))))));
        }
        let got = self.keep_all.as_mut()?.receive();
        Some(match got {
            Ok(sample) => Ok(sample.map(|s| (*s.user_header(), Received(ReceivedInner::Shm(s))))),
            Err(e) => Err(self.receive_error(input, e)),
        })
    }

    /// The next waiting sample of this source, if any, kept in place.
    fn take(&mut self, input: &str) -> Result<Option<Received>, PortError> {
        if let Some(got) = self.take_lossless(input) {
            return Ok(got?.map(|(h, r)| {
                self.tally.account(&h, now_ns());
                r
            }));
        }
        let got = match &mut self.feed {
            Feed::Shm { subscriber, .. } if self.held.is_some() => self
                .held
                .as_mut()
                .and_then(|held| held.take(subscriber, input))
                .map(|(h, b)| (h, Received(ReceivedInner::Memory(h, b)))),
            Feed::Shm { subscriber, .. } => match subscriber.receive() {
                Ok(sample) => sample.map(|s| (*s.user_header(), Received(ReceivedInner::Shm(s)))),
                Err(e) => return Err(self.receive_error(input, e)),
            },
            Feed::Memory(queue) => queue.pop().map(|(h, b)| (h, Received(ReceivedInner::Memory(h, b)))),
        };
        Ok(got.map(|(h, r)| {
            self.tally.account(&h, now_ns());
            r
        }))
    }

    /// Hands this source's next waiting sample, in place, to `f`; `None`
    /// when none waits. The sample is released when `f` returns.
    fn take_with<R>(&mut self, input: &str, f: impl FnOnce(&SampleHeader, &[u8]) -> R) -> Result<Option<R>, PortError> {
        if let Some(got) = self.take_lossless(input) {
            let Some((h, r)) = got? else { return Ok(None) };
            self.tally.account(&h, now_ns());
            return Ok(Some(f(&h, r.bytes())));
        }
        match &mut self.feed {
            Feed::Shm { subscriber, .. } if self.held.is_some() => {
                let Some((h, b)) = self.held.as_mut().and_then(|held| held.take(subscriber, input)) else {
                    return Ok(None);
                };
                self.tally.account(&h, now_ns());
                Ok(Some(f(&h, b.bytes())))
            }
            Feed::Shm { subscriber, .. } => match subscriber.receive() {
                Ok(Some(sample)) => {
                    let h = *sample.user_header();
                    self.tally.account(&h, now_ns());
                    Ok(Some(f(&h, payload_bytes(sample.payload()))))
                }
                Ok(None) => Ok(None),
                Err(e) => Err(self.receive_error(input, e)),
            },
            Feed::Memory(queue) => {
                let Some((h, bytes)) = queue.pop() else { return Ok(None) };
                self.tally.account(&h, now_ns());
                Ok(Some(f(&h, bytes.bytes())))
            }
        }
    }
}

/// A subscription to a source: the port's own service, its wake-up
/// listener, and a keep-all input's lossless subscription.
type Subscribed = (ByteSubscriber, Listener<Ipc>, Option<KeepAllFeed>);

/// The type-erased side of an input, used by the message checker, the
/// runtime and the test harness.
pub(crate) trait DynInput: Send + Sync {
    fn name(&self) -> &str;
    fn type_name(&self) -> &str;
    /// The port's name, type name and layout fingerprint.
    fn spec(&self) -> PortSpec;
    /// The payload's size and alignment.
    fn payload_layout(&self) -> (usize, usize);
    /// Subscribes to `from_agent/from_port`; `Ok(false)` when already subscribed.
    fn connect(
        &self,
        node: &Node<Ipc>,
        robot: &shm_schemas::RobotName,
        from_agent: &str,
        from_port: &str,
    ) -> Result<bool, PortError>;
    /// Drops the subscription; `false` when there was none.
    fn disconnect(&self, from_agent: &str, from_port: &str) -> bool;
    fn listeners(&self) -> Vec<Arc<Listener<Ipc>>>;
    fn stats(&self, now: u64) -> Vec<InputStats>;
    /// Whether a sample waits in memory (a test's input; always false for iceoryx2 sources).
    fn has_queued(&self) -> bool;
    /// Queues `sample` (exactly the payload's size) from `sender`'s port
    /// `port` as a test's sample, stamped `stamp_ns`; the source is added at
    /// its first sample. Past [`SUBSCRIBER_BUFFER`] waiting samples the
    /// oldest is overwritten and counted as dropped, as with iceoryx2.
    fn queue(&self, sender: &str, port: &str, sample: SampleBuf, stamp_ns: u64) -> Result<(), PortError>;
    /// The input's depth and policy ([`super::depth`]); `None` for a call's side.
    fn depth(&self) -> Option<&super::depth::InputDepth> {
        None
    }
    /// Moves what waits in iceoryx2 into the input's own queues, if it has any.
    fn refill(&self) {}
    /// Each source's depth, policy and queue counts (issue 46); none for a call's side.
    fn queue_stats(&self) -> Vec<QueueStats> {
        Vec::new()
    }
    /// Whether a sample waits, read in shared memory without a system call
    /// (a polling task's look, `runtime::poll`); `None` when the port cannot
    /// tell so (a call's side: its listeners are looked at instead).
    fn waiting(&self) -> Option<bool> {
        None
    }
}

/// The shared state of an input: its sources, made and dropped by the
/// message checker, read by the task.
pub(crate) struct InputInner {
    name: String,
    schema: Schema,
    carried: Carried,
    /// validate `schema` before subscribing (it came from outside)
    check: bool,
    subs: Mutex<Vec<Source>>,
    next: AtomicU64,
    /// depth and policy ([`super::depth`])
    pub(crate) depth: super::depth::InputDepth,
}

impl InputInner {
    /// Takes the next sample from any source (round robin between sources)
    /// and hands it, in place, to `f`. A source that cannot hand out a
    /// sample is logged and skipped.
    pub(crate) fn next_with<R>(&self, mut f: impl FnMut(&SampleHeader, &[u8]) -> R) -> Option<R> {
        let mut subs = lock(&self.subs);
        let n = subs.len();
        if n == 0 {
            return None;
        }
        let start = self.next.fetch_add(1, Ordering::Relaxed) as usize;
        for i in 0..n {
            match subs[(start + i) % n].take_with(&self.name, &mut f) {
                Ok(Some(got)) => return Some(got),
                Ok(None) => {}
                Err(e) => tracing::warn!(input = %self.name, "receive failed: {e}"),
            }
        }
        None
    }

    /// Hands every waiting sample, in place, to `f`: at most `max` from
    /// each source. The first error of `f` ends it (the sample it failed
    /// on is consumed); returns how many samples `f` was given.
    pub(crate) fn visit_up_to<E>(
        &self,
        max: usize,
        mut f: impl FnMut(&SampleHeader, &[u8]) -> Result<(), E>,
    ) -> Result<usize, E> {
        let mut subs = lock(&self.subs);
        let mut count = 0;
        for sub in subs.iter_mut() {
            for _ in 0..max {
                match sub.take_with(&self.name, &mut f) {
                    Ok(Some(done)) => {
                        count += 1;
                        done?;
                    }
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!(input = %self.name, "receive failed: {e}");
                        break;
                    }
                }
            }
        }
        Ok(count)
    }

    /// Hands each iceoryx2 source's own queue, if it has one, to `f` with
    /// its subscriber (the input's depth, [`super::depth`]).
    /// A keep-all source read losslessly has nothing to move: what waits
    /// on the port's own service is dropped (the keep-all service has it).
    pub(crate) fn each_held(&self, mut f: impl FnMut(&ByteSubscriber, &mut super::depth::Held)) {
        for sub in lock(&self.subs).iter_mut() {
            if sub.lossless() {
                if let Feed::Shm { subscriber, .. } = &sub.feed {
                    super::keep_all::discard(subscriber);
                }
                continue;
            }
            if let (Feed::Shm { subscriber, .. }, Some(held)) = (&sub.feed, sub.held.as_mut()) {
                f(subscriber, held);
            }
        }
    }

    pub(crate) fn carried(&self) -> &Carried {
        &self.carried
    }

    pub(crate) fn name(&self) -> &str {
        &self.name
    }

    /// Subscribes to the existing output port `service`, with its wake-up
    /// listener; a keep-all input first to the port's keep-all service
    /// (`port::keep_all`: so that the output, seeing its subscriber count
    /// change, finds it).
    fn subscribe(&self, node: &Node<Ipc>, service: &str) -> Result<Subscribed, PortError> {
        if self.check {
            Carried::of_schema(service, &self.schema, self.carried.fingerprint)?;
        }
        let options = self.depth.options();
        let factory = source_service(node, service, &self.carried)?;
        let keep_all = (options.keep == super::depth::Keep::All)
            .then(|| KeepAllFeed::subscribe(node, service, &self.carried, options.depth))
            .and_then(|made| {
                made.map_err(|e| {
                    tracing::warn!(input = %self.name, error = %e, "no lossless subscription: the input keeps copies of what the port's own service holds");
                })
                .ok()
            });
        let subscriber = factory
            .subscriber_builder()
            .buffer_size(self.depth.options().buffer_size())
            .create()
            .map_err(port_err!(Subscriber, service))?;
        let listener =
            source_event(node, service)?.listener_builder().create().map_err(port_err!(Listener, service))?;
        Ok((subscriber, listener, keep_all))
    }
}

impl DynInput for InputInner {
    fn name(&self) -> &str {
        &self.name
    }

    fn depth(&self) -> Option<&super::depth::InputDepth> {
        Some(&self.depth)
    }

    fn refill(&self) {
        self.refill_held();
    }

    fn type_name(&self) -> &str {
        &self.carried.type_name
    }

    fn spec(&self) -> PortSpec {
        PortSpec {
            name: self.name.clone(),
            type_name: self.carried.type_name.clone(),
            fingerprint: self.carried.fingerprint,
        }
    }

    fn payload_layout(&self) -> (usize, usize) {
        if self.carried.is_sequence() {
            return (self.schema.size, self.schema.align);
        }
        (self.carried.size(), self.carried.align())
    }

    fn connect(
        &self,
        node: &Node<Ipc>,
        robot: &shm_schemas::RobotName,
        from_agent: &str,
        from_port: &str,
    ) -> Result<bool, PortError> {
        {
            let subs = lock(&self.subs);
            if subs.iter().any(|s| s.from_agent == from_agent && s.from_port == from_port) {
                return Ok(false);
            }
            if subs.len() >= MAX_SOURCES {
                return Err(PortError::TooManySources { input: self.name.clone(), max: MAX_SOURCES });
            }
        }
        let service = robot.port_service(from_agent, from_port);
        // a killed reader's ports may hold the source's slots until the router's next sweep
        let (subscriber, listener, keep_all) =
            crate::world::retry_after_cleanup(node.config(), "connect", PortError::blockable, || {
                self.subscribe(node, &service)
            })?;
        lock(&self.subs).push(Source {
            from_agent: from_agent.into(),
            from_port: from_port.into(),
            feed: Feed::Shm { subscriber, listener: Arc::new(listener) },
            tally: Tally::default(),
            held: super::depth::Held::of(self.depth.options(), self.payload_layout().1),
            keep_all,
        });
        Ok(true)
    }

    fn disconnect(&self, from_agent: &str, from_port: &str) -> bool {
        let mut subs = lock(&self.subs);
        let before = subs.len();
        subs.retain(|s| !(s.from_agent == from_agent && s.from_port == from_port));
        subs.len() != before
    }

    fn listeners(&self) -> Vec<Arc<Listener<Ipc>>> {
        lock(&self.subs)
            .iter()
            .filter_map(|s| match &s.feed {
                Feed::Shm { listener, .. } => Some(listener.clone()),
                Feed::Memory(_) => None,
            })
            .collect()
    }

    fn stats(&self, now: u64) -> Vec<InputStats> {
        lock(&self.subs).iter().map(|s| s.tally.stats(&self.name, &s.from_agent, &s.from_port, now)).collect()
    }

    fn queue_stats(&self) -> Vec<QueueStats> {
        let options = self.depth.options();
        lock(&self.subs)
            .iter()
            .map(|s| {
                let counts = s.held.as_ref().map(|h| h.counts()).unwrap_or_default();
                QueueStats {
                    input: self.name.clone(),
                    from_agent: s.from_agent.clone(),
                    from_port: s.from_port.clone(),
                    depth: u32::try_from(options.depth).unwrap_or(u32::MAX),
                    keep_all: options.keep == super::depth::Keep::All,
                    lossless: s.keep_all.as_ref().is_some_and(|k| k.was_live()),
                    overwritten: counts.overwritten,
                    back_pressure: counts.back_pressure,
                }
            })
            .collect()
    }

    fn has_queued(&self) -> bool {
        lock(&self.subs).iter().any(|s| matches!(&s.feed, Feed::Memory(q) if !q.is_empty()))
    }

    fn waiting(&self) -> Option<bool> {
        Some(lock(&self.subs).iter().any(|s| match &s.feed {
            // a source that cannot be looked at has nothing to take either
            Feed::Shm { subscriber, .. } => {
                subscriber.has_samples().unwrap_or(false) || s.keep_all.as_ref().is_some_and(|k| k.has_samples())
            }
            Feed::Memory(q) => !q.is_empty(),
        }))
    }

    fn queue(&self, sender: &str, port: &str, sample: SampleBuf, stamp_ns: u64) -> Result<(), PortError> {
        let (size, align) = self.payload_layout();
        let fits = match self.schema.sequence_shape().filter(|_| self.carried.is_sequence()) {
            Some(shape) => shape.count_of(sample.bytes().len()).is_some(),
            None => sample.bytes().len() == size,
        };
        if !fits || sample.align() < align {
            return Err(PortError::Ipc {
                service: format!("{sender}/{port}"),
                detail: format!(
                    "a {}-byte sample for input {:?} of {}-byte {}",
                    sample.bytes().len(),
                    self.name,
                    self.carried.size(),
                    self.carried.type_name
                ),
            });
        }
        let mut subs = lock(&self.subs);
        let at = match subs.iter().position(|s| s.from_agent == sender && s.from_port == port) {
            Some(at) => at,
            None => {
                if subs.len() >= MAX_SOURCES {
                    return Err(PortError::TooManySources { input: self.name.clone(), max: MAX_SOURCES });
                }
                subs.push(Source {
                    from_agent: sender.into(),
                    from_port: port.into(),
                    feed: Feed::Memory(Queue::default()),
                    tally: Tally::default(),
                    held: None,
                    keep_all: None,
                });
                subs.len() - 1
            }
        };
        let Feed::Memory(queue) = &mut subs[at].feed else {
            return Err(perr(&self.name, format!("{sender}/{port} is an iceoryx2 source, not a test's")));
        };
        queue.push(sender, sample, stamp_ns);
        Ok(())
    }
}

/// An input port of the payload layout a [`Schema`] describes, fed by any
/// number of output ports of that layout: the byte port every input is.
pub struct SchemaInput {
    inner: Arc<InputInner>,
}

impl std::fmt::Debug for SchemaInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SchemaInput")
            .field("name", &self.inner.name)
            .field("type", &self.inner.carried.type_name)
            .finish()
    }
}

impl SchemaInput {
    /// Input `name` of layout `schema`. The schema is checked when the
    /// input connects: a bad one is refused then, with its own message,
    /// before its size and alignment reach iceoryx2.
    pub(crate) fn new(name: &str, schema: Schema) -> Result<(Self, Arc<InputInner>), PortError> {
        let carried = match schema.sequence_shape() {
            Some(_) => Carried::of_sequence(name, &schema.type_name, schema.fingerprint())?,
            None => Carried::from_parts(name, &schema.type_name, schema.size, schema.align, schema.fingerprint())?,
        };
        Ok(Self::with(name, schema, carried, true))
    }

    /// Input `name` carrying `carried`, laid out as `schema`; `check`: the
    /// schema comes from outside (not a Rust type) and is validated before
    /// any subscription.
    pub(crate) fn with(name: &str, schema: Schema, carried: Carried, check: bool) -> (Self, Arc<InputInner>) {
        let inner = Arc::new(InputInner {
            name: name.into(),
            schema,
            carried,
            check,
            subs: Mutex::new(Vec::new()),
            next: AtomicU64::new(0),
            depth: Default::default(),
        });
        (SchemaInput { inner: inner.clone() }, inner)
    }

    pub(crate) fn inner(&self) -> &InputInner {
        &self.inner
    }

    /// The layout of what it receives.
    pub fn schema(&self) -> &Schema {
        &self.inner.schema
    }

    /// Takes the next waiting sample from any source (round robin between
    /// sources), in place. Fails when a source cannot hand out another
    /// sample: the reader holds as many as iceoryx2 lends at once (two per
    /// source) and must drop one first.
    pub fn take(&self) -> Result<Option<Received>, PortError> {
        let mut subs = lock(&self.inner.subs);
        let n = subs.len();
        if n == 0 {
            return Ok(None);
        }
        let start = self.inner.next.fetch_add(1, Ordering::Relaxed) as usize;
        for i in 0..n {
            if let Some(r) = subs[(start + i) % n].take(&self.inner.name)? {
                return Ok(Some(r));
            }
        }
        Ok(None)
    }

    /// Hands every waiting sample's metadata and bytes, in place, to `f`
    /// (at most [`SUBSCRIBER_BUFFER`] per source); returns how many.
    pub fn drain(&self, mut f: impl FnMut(&Meta, &[u8])) -> usize {
        let done: Result<usize, std::convert::Infallible> = self.inner.visit_up_to(SUBSCRIBER_BUFFER, |h, b| {
            f(&Meta::of(h), b);
            Ok(())
        });
        match done {
            Ok(n) => n,
        }
    }

    /// How many sources feed this input now.
    pub fn sources(&self) -> usize {
        lock(&self.inner.subs).len()
    }
}

// ---------------------------------------------------------------- tools

/// A subscription to an output port that hands out each sample's bytes,
/// whatever type it carries: it learns the payload's size and alignment
/// from the service ([`RawPort::open`]). The bytes are then decoded through
/// the port's [`Schema`], which the agent registered with the router; the
/// service's attributes ([`port_attributes`]) say the type name and layout
/// fingerprint.
pub struct RawPort {
    service: String,
    subscriber: ByteSubscriber,
    payload_size: usize,
    attributes: Vec<(String, String)>,
}

impl std::fmt::Debug for RawPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawPort").field("service", &self.service).field("attributes", &self.attributes).finish()
    }
}

impl RawPort {
    /// Subscribes to the existing output port `service`
    /// (`nerve/ROBOT/AGENT/PORT`); never creates it.
    pub fn open(node: &Node<Ipc>, service: &str) -> Result<RawPort, PortError> {
        use iceoryx2::service::port_factory::PortFactory as _;
        let (factory, payload_size) = raw_source_service(node, service)?;
        let attributes = factory.attributes().iter().map(|a| (a.key().to_string(), a.value().to_string())).collect();
        let subscriber = factory
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .create()
            .map_err(port_err!(Subscriber, service))?;
        Ok(RawPort { service: service.into(), subscriber, payload_size, attributes })
    }

    /// The service's name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The payload's size, bytes.
    pub fn payload_size(&self) -> usize {
        self.payload_size
    }

    /// The service's attributes, `(key, value)`.
    pub fn attributes(&self) -> &[(String, String)] {
        &self.attributes
    }

    /// The value of attribute `key`, if the service has it.
    pub fn attribute(&self, key: &str) -> Option<&str> {
        self.attributes.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// The payload's type name, from the service's attributes.
    pub fn type_name(&self) -> Option<&str> {
        self.attribute(port_attributes::TYPE)
    }

    /// The layout fingerprint the port was created with, from its attributes.
    pub fn fingerprint(&self) -> Option<u64> {
        port_attributes::parse_fingerprint(self.attribute(port_attributes::FINGERPRINT)?)
    }

    /// Calls `f` with the header and bytes of every sample waiting; returns
    /// how many there were. Stops early when `f` returns false.
    pub fn receive(&self, mut f: impl FnMut(&SampleHeader, &[u8]) -> bool) -> Result<usize, PortError> {
        let mut n = 0;
        loop {
            let sample = self.subscriber.receive().map_err(|e| perr(&self.service, format!("receive: {e:?}")))?;
            let Some(sample) = sample else { return Ok(n) };
            n += 1;
            if !f(sample.user_header(), payload_bytes(sample.payload())) {
                return Ok(n);
            }
        }
    }
}

/// An output port that publishes bytes laid out as a type this build may
/// not know (`nerve replay`, `nerve pub`): the service is made with the
/// type's name, size and alignment, the same settings and attributes as a
/// typed [`crate::Output`] of it, so the agents built with the type read it
/// as their own.
#[derive(Debug)]
pub struct RawOutput(SchemaOutput);

impl RawOutput {
    /// Opens (or creates) output port `service` for samples of `schema`,
    /// whose layout fingerprint is `fingerprint`, sent as `sender`.
    pub fn create(
        node: &Node<Ipc>,
        service: &str,
        schema: &Schema,
        fingerprint: u64,
        sender: &str,
    ) -> Result<RawOutput, PortError> {
        let carried = Carried::of_schema(service, schema, fingerprint)?;
        match SchemaOutput::shm(node, service, sender, schema.clone(), carried) {
            Ok(out) => Ok(RawOutput(out)),
            Err(PortError::LayoutMismatch { .. } | PortError::IncompatibleType { .. }) => Err(perr(
                service,
                format!(
                    "the port exists with another type or layout than the recorded {} ({}): stop the agent that owns it",
                    schema.type_name,
                    port_attributes::fingerprint_text(fingerprint)
                ),
            )),
            Err(e) => Err(e),
        }
    }

    /// Publishes `bytes` (exactly the type's size) stamped now, and wakes the readers.
    pub fn send(&mut self, bytes: &[u8]) -> Result<(), PortError> {
        self.0.publish_bytes(bytes).map(|_| ())
    }

    /// Loans a sample of the type's size to write in place; its bytes are
    /// zero when `zeroed`, else what the slot last held.
    pub fn loan(&self, zeroed: bool) -> Result<Loan, PortError> {
        self.0.loan(zeroed)
    }

    /// Loans a sample of `len` bytes: the type's size, or for a sequence
    /// its header and whole elements (see [`SchemaOutput::loan_len`]).
    pub fn loan_len(&self, len: usize, zeroed: bool) -> Result<Loan, PortError> {
        self.0.loan_len(len, zeroed)
    }

    /// Sends a sample loaned by [`RawOutput::loan`], stamped now, and wakes the readers.
    pub fn send_loan(&mut self, loan: Loan) -> Result<(), PortError> {
        self.0.publish(loan).map(|_| ())
    }

    /// [`RawOutput::send_loan`], returning how many readers the sample
    /// reached (0 before a new subscriber is seen: `nerve pub` sends again).
    pub fn send_loan_counted(&mut self, loan: Loan) -> Result<usize, PortError> {
        self.0.publish(loan)
    }
}

#[cfg(test)]
mod tests {
    use super::{SchemaInput, SchemaOutput};
    use crate::port::bytes::DynInput as _;
    use crate::port::{Input, Output, PortError};
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::payloads::Scalar;
    use shm_schemas::{Described as _, Payload as _};

    fn bytes_of(v: &Scalar) -> &[u8] {
        // SAFETY: the bytes of a Copy #[repr(C)] value without padding
        unsafe { std::slice::from_raw_parts((v as *const Scalar).cast::<u8>(), std::mem::size_of::<Scalar>()) }
    }

    #[test]
    fn ports_by_layout_and_ports_by_type_read_each_other_in_place() {
        let world = World::new(&format!("dyn{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        assert_eq!(Scalar::schema().fingerprint(), Scalar::layout_fingerprint());

        // a typed output, read by layout
        let typed = Output::<Scalar>::create(&node, &robot.port_service("rust", "value"), "rust").expect("output");
        let (by_layout, inner) = SchemaInput::new("in", Scalar::schema()).expect("input");
        assert!(inner.connect(&node, &robot, "rust", "value").expect("the same layout opens"));
        assert!(!inner.connect(&node, &robot, "rust", "value").expect("twice"), "already subscribed");
        for i in 0..3 {
            typed.send(Scalar { value: f64::from(i) + 0.25, stamp_ns: 9 }).expect("send");
        }
        let first = by_layout.take().expect("take").expect("a sample");
        let second = by_layout.take().expect("take").expect("a sample");
        assert_eq!(first.bytes(), bytes_of(&Scalar { value: 0.25, stamp_ns: 9 }));
        assert_eq!((first.meta().sender.as_str(), first.meta().seq, second.meta().seq), ("rust", 1, 2));
        // iceoryx2 lends two samples per source: a third is refused, saying what to do
        match by_layout.take() {
            Err(e) => assert!(e.to_string().contains("drop the ones held"), "{e}"),
            Ok(s) => panic!("a third sample lent: {s:?}"),
        }
        drop((first, second));
        let third = by_layout.take().expect("take").expect("the third");
        assert_eq!(third.meta().seq, 3);
        assert_eq!(inner.stats(crate::clock::now_ns())[0].received, 3);

        // an output by layout, read by type, written in place
        let service = robot.port_service("py", "value");
        let mut out = SchemaOutput::create(&node, &service, Scalar::schema(), "py").expect("output by layout");
        let (typed_in, typed_inner) = Input::<Scalar>::new("in").expect("input");
        assert!(typed_inner.connect(&node, &robot, "py", "value").expect("a typed reader opens it"));
        let mut loan = out.loan(true).expect("loan");
        assert!(loan.bytes().iter().all(|b| *b == 0), "zeroed");
        loan.bytes_mut().copy_from_slice(bytes_of(&Scalar { value: -2.5, stamp_ns: 77 }));
        out.send(loan).expect("send");
        out.send_bytes(bytes_of(&Scalar { value: 1.0, stamp_ns: 78 })).expect("send bytes");
        let (meta, got) = typed_in.recv().expect("a sample");
        assert_eq!((got.value, got.stamp_ns, meta.sender.as_str(), meta.seq), (-2.5, 77, "py", 1));
        assert_eq!(typed_in.recv().map(|(m, v)| (m.seq, v.value)), Some((2, 1.0)));

        // another layout of the type is refused on both sides
        let mut other = Scalar::schema();
        if let shm_schemas::schema::Kind::Struct { fields } = &mut other.kind {
            fields.swap(0, 1);
            fields[0].offset = 0;
            fields[1].offset = 8;
        }
        let (_, wrong) = SchemaInput::new("in2", other.clone()).expect("input");
        match wrong.connect(&node, &robot, "rust", "value") {
            Err(PortError::LayoutMismatch { .. } | PortError::IncompatibleType { .. }) => {}
            other => panic!("another layout read: {other:?}"),
        }
        let ours = other.fingerprint();
        match SchemaOutput::create(&node, &service, other, "py") {
            Err(PortError::LayoutMismatch { ours: o, theirs, .. }) => {
                assert_eq!((o, theirs), (ours, Scalar::layout_fingerprint()), "both layouts named");
            }
            other => panic!("another layout published: {:?}", other.err()),
        }
    }

    /// What the Python binding's views rely on (issue 40): a loan and a
    /// received sample keep their shared memory mapped after their port is
    /// dropped, so a numpy view of either never outlives its memory. The
    /// port is dropped first, then every byte is written and read back (a
    /// write to memory that was unmapped would kill this test with SIGSEGV).
    #[test]
    fn a_loan_and_a_received_sample_outlive_their_ports() {
        let world = World::new(&format!("dynlive{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let service = robot.port_service("py", "value");
        let mut out = SchemaOutput::create(&node, &service, Scalar::schema(), "py").expect("output");
        let (input, inner) = SchemaInput::new("in", Scalar::schema()).expect("input");
        assert!(inner.connect(&node, &robot, "py", "value").expect("a reader"));
        out.send_bytes(bytes_of(&Scalar { value: 4.5, stamp_ns: 3 })).expect("send");
        let mut loan = out.loan(false).expect("loan");
        let received = input.take().expect("take").expect("a sample");
        drop(out);
        drop((input, inner));
        loan.bytes_mut().fill(0xab);
        assert!(loan.bytes().iter().all(|b| *b == 0xab), "the loan's bytes after its port went");
        assert_eq!(received.bytes(), bytes_of(&Scalar { value: 4.5, stamp_ns: 3 }), "the sample after its port went");
        drop((loan, received));
    }

    /// A schema from outside (Python, a recording) with an alignment
    /// iceoryx2 would divide by, or build a `Layout` from unchecked, never
    /// reaches it: both directions refuse it with the schema's own message.
    #[test]
    fn an_invalid_schema_never_reaches_iceoryx2() {
        let world = World::new(&format!("dynbad{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let _typed = Output::<Scalar>::create(&node, &robot.port_service("rust", "value"), "rust").expect("output");
        for align in [0, 3, 1 << 20] {
            let mut bad = Scalar::schema();
            bad.align = align;
            let service = robot.port_service("py", &format!("bad{align}"));
            match SchemaOutput::create(&node, &service, bad.clone(), "py") {
                Err(e @ PortError::InvalidSchema { .. }) => {
                    let text = e.to_string();
                    assert!(text.contains(&format!("align {align} is not a power of two")), "{text}");
                }
                other => panic!("align {align} published: {other:?}"),
            }
            let (_, input) = SchemaInput::new("in", bad.clone()).expect("input");
            match input.connect(&node, &robot, "rust", "value") {
                Err(PortError::InvalidSchema { .. }) => {}
                other => panic!("align {align} read: {other:?}"),
            }
            match super::RawOutput::create(&node, &service, &bad, bad.fingerprint(), "rec") {
                Err(PortError::InvalidSchema { .. }) => {}
                other => panic!("align {align} replayed: {other:?}"),
            }
        }
    }
}

#[cfg(test)]
mod raw_tests {
    use super::{RawOutput, RawPort};
    use crate::port::bytes::DynInput as _;
    use crate::port::service::port_identity;
    use crate::port::{Input, Output, PortError};
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::payloads::Scalar;
    use shm_schemas::{Described, Payload};

    #[test]
    fn a_port_is_read_by_its_bytes_and_decoded_by_its_schema() {
        let world = World::new(&format!("raw{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let service = world.robot().port_service("a", "value");
        match RawPort::open(&node, &service) {
            Err(PortError::NoSuchPort { .. }) => {}
            other => panic!("no such port yet: {other:?}"),
        }
        let out = Output::<Scalar>::create(&node, &service, "a").expect("output");
        let raw = RawPort::open(&node, &service).expect("raw");
        assert_eq!(raw.payload_size(), std::mem::size_of::<Scalar>());
        assert_eq!(raw.type_name(), Some("nerve::Scalar"));
        assert_eq!(raw.fingerprint(), Some(Scalar::layout_fingerprint()));
        assert_eq!(
            port_identity(&node, &service),
            Some(("nerve::Scalar".to_string(), Some(Scalar::layout_fingerprint())))
        );
        for i in 0..3 {
            out.send(Scalar { value: f64::from(i) + 0.5, stamp_ns: 7 }).expect("send");
        }
        let mut got = Vec::new();
        let n = raw
            .receive(|h, bytes| {
                got.push((h.seq, Scalar::schema().decode(bytes).expect("decodes").to_string()));
                true
            })
            .expect("receive");
        assert_eq!(n, 3);
        assert_eq!(got[2], (3, "{ value: 2.5, stamp_ns: 7 }".to_string()), "{got:?}");
    }

    #[test]
    fn bytes_published_by_schema_are_read_by_an_agent_built_with_the_type() {
        let world = World::new(&format!("rawout{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let service = robot.port_service("rec", "value");
        let schema = Scalar::schema();
        let mut out = RawOutput::create(&node, &service, &schema, Scalar::layout_fingerprint(), "rec").expect("raw");
        let (input, inner) = Input::<Scalar>::new("in").expect("input");
        assert!(inner.connect(&node, &robot, "rec", "value").expect("a typed reader opens it"));
        let sent = Scalar { value: -0.1, stamp_ns: u64::MAX - 3 };
        // SAFETY: the bytes of a Copy #[repr(C)] value without padding
        let bytes =
            unsafe { std::slice::from_raw_parts((&sent as *const Scalar).cast::<u8>(), std::mem::size_of::<Scalar>()) };
        out.send(bytes).expect("send");
        out.send(bytes).expect("send");
        let (meta, got) = input.recv().expect("a sample");
        assert_eq!(got.value.to_bits(), sent.value.to_bits());
        assert_eq!(got.stamp_ns, sent.stamp_ns);
        assert_eq!((meta.sender.as_str(), meta.seq), ("rec", 1));
        assert!(out.send(&bytes[1..]).is_err(), "a sample of the wrong size");
        // another layout of the type on the same port is refused
        let mut other = schema.clone();
        other.type_name = "nerve::Other".into();
        assert!(RawOutput::create(&node, &service, &other, 1, "rec").is_err());
    }
}
