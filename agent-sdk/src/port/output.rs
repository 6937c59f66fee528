//! The byte port's sending side: [`SchemaOutput`] loans a slot of the
//! port's shared memory ([`Loan`]) at the payload's size, or at the length
//! a sequence sample needs (refused past the port's maximum), and
//! [`SchemaOutput::send`] stamps its [`SampleHeader`], hands it to the
//! port's keep-all readers if it has some (`port::keep_all`), sends it and
//! wakes the readers. Bound to nothing (`--describe`) or to a test's memory
//! (`port::memory`), a loan is bytes of its own. The module doc of
//! `port::bytes` has the whole port.

use super::bytes::Binding;
use super::error::{PortError, port_err};
use super::keep_all::{KeepAllFigures, KeepAllSender};
use super::memory::{Collected, SampleBuf};
use super::service::{Carried, OutputFactory, output_service, port_event};
use crate::clock::now_ns;
use crate::world::Ipc;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::sample_mut_uninit::SampleMutUninit;
use iceoryx2::service::marker::{CustomHeaderMarker, CustomPayloadMarker};
use shm_schemas::{FixedName, SampleHeader, Schema, SeqShape};
use std::mem::MaybeUninit;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

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
    /// how far a loaned sample's payload lies after its user header
    /// ([`UNKNOWN_OFFSET`] until the first loan): the same for every sample
    /// of the port, so that a loan finds its payload without iceoryx2's look
    payload_offset: AtomicUsize,
    /// a sequence port's shape and bound; `None` for a fixed size
    limit: Option<SeqLimit>,
}

/// What a sequence port accepts: a header and whole elements, at most `max_len` of them.
#[derive(Debug, Clone, Copy)]
struct SeqLimit {
    shape: SeqShape,
    max_len: usize,
}

/// [`SchemaOutput::payload_offset`] before the port's first loan.
const UNKNOWN_OFFSET: usize = usize::MAX;

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
            payload_offset: AtomicUsize::new(UNKNOWN_OFFSET),
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
                let at = self.payload_of(&mut sample, len)?;
                if zeroed {
                    // SAFETY: `at` is the loan's `len` payload bytes, writable
                    unsafe { std::ptr::write_bytes(at.ptr.as_ptr(), 0, len) };
                }
                // SAFETY: the payload lies in the service's shared memory,
                // which is zero when mapped and holds earlier samples' bytes
                // after: every byte is initialised (zeroed above, or as the
                // slot was last written), and any bytes are valid for a byte buffer.
                Ok(Loan(LoanInner::Shm(unsafe { sample.assume_init() }, at)))
            }
            Sink::Memory(_) | Sink::Nothing => {
                Ok(Loan(LoanInner::Detached(SampleBuf::zeroed(&self.service, len, self.carried.align())?)))
            }
        }
    }

    /// Where the payload of `sample`, a loan of `len` bytes, lies.
    ///
    /// iceoryx2 places a sample's payload at a fixed distance after its user
    /// header (`align(user header + its size, payload alignment)` in a chunk
    /// aligned for both), the same for every chunk of the service. The
    /// first loan asks iceoryx2 (`payload_mut`, which takes the port's two
    /// locks for a custom payload's length) and keeps that distance; later
    /// loans add it to the user header's address, which iceoryx2 hands out
    /// without a lock. A debug build (every test) checks every later loan
    /// against iceoryx2's own answer.
    fn payload_of(
        &self,
        sample: &mut SampleMutUninit<Ipc, [MaybeUninit<CustomPayloadMarker>], CustomHeaderMarker>,
        len: usize,
    ) -> Result<PayloadAt, PortError> {
        // an address: iceoryx2 makes its own pointers into a chunk from
        // addresses too (`message_type_details`), so the payload's pointer is
        // made from one the same way, with the shared memory's exposed provenance
        let header = std::ptr::from_mut(sample.user_header_mut()).addr();
        let offset = self.payload_offset.load(Ordering::Relaxed);
        if offset != UNKNOWN_OFFSET {
            // `offset` is the distance from a user header of this port's
            // samples to its payload (measured at the first loan, the same
            // for every chunk): the loaned chunk's payload
            let ptr = std::ptr::with_exposed_provenance_mut::<u8>(header.wrapping_add(offset));
            #[cfg(debug_assertions)]
            {
                let payload = sample.payload_mut();
                let theirs = (payload.as_mut_ptr().addr(), payload.len());
                debug_assert_eq!(theirs, (ptr.addr(), len), "a sample's payload is not where the port's first one was");
            }
            return Ok(PayloadAt::of(ptr, len));
        }
        let payload = sample.payload_mut();
        if payload.len() != len {
            return Err(PortError::Ipc {
                service: self.service.clone(),
                detail: format!("loaned {} bytes for a {len}-byte sample", payload.len()),
            });
        }
        let ptr = payload.as_mut_ptr().cast::<u8>();
        if let Some(measured) = ptr.expose_provenance().checked_sub(header) {
            self.payload_offset.store(measured, Ordering::Relaxed);
        }
        Ok(PayloadAt::of(ptr, len))
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
            (Sink::Shm { notifier, factory, keep_all, .. }, LoanInner::Shm(mut sample, at)) => {
                // SAFETY: the service's user header is a SampleHeader (set in
                // `service::output_builder`); the marker is a zero-sized
                // stand-in at its address, which is aligned for it
                unsafe { (sample.user_header_mut() as *mut CustomHeaderMarker).cast::<SampleHeader>().write(header) };
                if let Some(keep_all) = keep_all {
                    // one atomic load and a comparison while no keep-all reader reads this port
                    keep_all.before_send(factory.dynamic_config().number_of_subscribers());
                    // SAFETY: `at` is `sample`'s payload, lent until it is sent below
                    keep_all.send(&header, unsafe { at.bytes() });
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
    /// a slot of the port's shared memory, and where its payload lies
    Shm(SampleMut<Ipc, [CustomPayloadMarker], CustomHeaderMarker>, PayloadAt),
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
            // SAFETY: `at` is the payload of the sample this loan owns, lent to it until it is sent or dropped
            LoanInner::Shm(_, at) => unsafe { at.bytes() },
            LoanInner::Detached(b) => b.bytes(),
        }
    }

    /// The payload's bytes, to write.
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        match &mut self.0 {
            // SAFETY: as in `bytes`, borrowed mutably through the loan: the only writer
            LoanInner::Shm(_, at) => unsafe { std::slice::from_raw_parts_mut(at.ptr.as_ptr(), at.len) },
            LoanInner::Detached(b) => b.bytes_mut(),
        }
    }
}

/// Where a sample's payload lies in shared memory, taken once when the
/// sample is loaned or received. A port's payload is iceoryx2's custom
/// payload (a slice of bytes), whose length iceoryx2 computes under the
/// port's locks on every look (two pthread mutexes for a loan, one for a
/// received sample, on the thread-safe service type); a typed iceoryx2
/// sample is a pointer cast. Looked at once, a hop's send takes those
/// locks once instead of three times (the loan's check, the writer's
/// bytes, the keep-all glue's bytes).
#[derive(Debug, Clone, Copy)]
pub(crate) struct PayloadAt {
    pub(crate) ptr: std::ptr::NonNull<u8>,
    pub(crate) len: usize,
}

// SAFETY: a `PayloadAt` is an address, used only beside the iceoryx2 sample
// that owns the memory (the same `LoanInner::Shm` or `Received`), through
// `&self` for reading and `&mut self` for writing: it moves and is shared
// between threads exactly as that sample is, under the same borrow rules
// as the sample's own payload accessors.
unsafe impl Send for PayloadAt {}
// SAFETY: see `Send`
unsafe impl Sync for PayloadAt {}

impl PayloadAt {
    /// The payload at `ptr`, `len` bytes (a sample's payload pointer is never null).
    pub(crate) fn of(ptr: *mut u8, len: usize) -> Self {
        PayloadAt { ptr: std::ptr::NonNull::new(ptr).unwrap_or(std::ptr::NonNull::dangling()), len }
    }

    /// The payload's bytes.
    ///
    /// # Safety
    /// The sample whose payload this is must be alive (neither sent nor
    /// dropped) for the returned lifetime, and not written meanwhile.
    pub(crate) unsafe fn bytes<'a>(self) -> &'a [u8] {
        // SAFETY: `len` initialised bytes at `ptr` (the caller's promise)
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}
