//! Ports declared by a payload's [`Schema`] instead of its Rust type, for
//! agents that learn their types at run time: the Python agents
//! (`python/`), whose payload types are layouts written in Python or
//! looked up by name among the built-in ones.
//!
//! A [`SchemaInput`] and a [`SchemaOutput`] make the same iceoryx2 services,
//! with the same type name, size, alignment and attributes, as an
//! [`crate::Input`] and an [`crate::Output`] of a Rust type of that layout:
//! a Rust agent and a Python agent are wired to each other by the router
//! like any two agents, and a layout that differs from the Rust one (its
//! fingerprint) is refused on both sides. Samples are read in place
//! ([`Received`] keeps one alive) and written in place ([`Loan`]), zero
//! copy like the typed ports.

use crate::clock::now_ns;
use crate::ports::{
    DynInput, MAX_SOURCES, Meta, PortError, SUBSCRIBER_BUFFER, Tally, lock, port_settings, service_fingerprint,
    source_event,
};
use crate::raw_port::RawOutput;
use crate::world::Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError as Open;
use iceoryx2::service::marker::CustomPayloadMarker;
use iceoryx2::service::static_config::message_type_details::{TypeDetail, TypeVariant};
use shm_schemas::control::agent_to_router::PortSpec;
use shm_schemas::stats::InputStats;
use shm_schemas::{FixedName, SampleHeader, Schema};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

pub use crate::raw_port::Loan;

/// The iceoryx2 type details of a payload laid out as `schema`, once the
/// schema is [valid](Schema::validate): every port made from a schema
/// (Python's, `nerve replay`'s) passes here before its size and alignment
/// reach iceoryx2's `unsafe` set-up, which divides by the alignment and
/// builds a `Layout` from it unchecked.
pub(crate) fn payload_details(service: &str, schema: &Schema) -> Result<TypeDetail, PortError> {
    schema.validate().map_err(|e| PortError::InvalidSchema { service: service.into(), source: Box::new(e) })?;
    TypeDetail::__internal_new_from_parts(TypeVariant::FixedSize, &schema.type_name, schema.size, schema.align).map_err(
        |e| PortError::Ipc {
            service: service.into(),
            detail: format!("the type name {:?} is too long for iceoryx2: {e:?}", schema.type_name),
        },
    )
}

/// A sample received on a [`SchemaInput`], read in place: its bytes stay in
/// shared memory, and the slot is not reused by the sender, until it is
/// dropped.
pub struct Received(ReceivedInner);

enum ReceivedInner {
    /// a slot of the source port's shared memory
    Shm(Sample<Ipc, [CustomPayloadMarker], SampleHeader>),
    /// a test's sample ([`crate::testing`])
    Memory(SampleHeader, Box<[u8]>),
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
            ReceivedInner::Shm(sample) => {
                let payload = sample.payload();
                // SAFETY: CustomPayloadMarker is a #[repr(C)] wrapper of one
                // u8: the slice is the sample's payload bytes, alive while
                // the sample is.
                unsafe { std::slice::from_raw_parts(payload.as_ptr().cast::<u8>(), payload.len()) }
            }
            ReceivedInner::Memory(_, bytes) => bytes,
        }
    }
}

/// One source of a [`SchemaInput`].
struct Source {
    from_agent: String,
    from_port: String,
    feed: Feed,
    tally: Tally,
}

/// Where a source's samples come from.
enum Feed {
    /// a running agent: a subscription to the source port and its wake-up event
    Shm { subscriber: Subscriber<Ipc, [CustomPayloadMarker], SampleHeader>, listener: Arc<Listener<Ipc>> },
    /// a test: the samples the harness queued, at most [`SUBSCRIBER_BUFFER`]
    /// (the oldest overwritten past it), and how many were queued in all
    Memory { queue: VecDeque<(SampleHeader, Box<[u8]>)>, sent: u64 },
}

impl Source {
    /// The next waiting sample of this source, if any.
    fn take(&mut self, input: &str) -> Result<Option<Received>, PortError> {
        let got = match &mut self.feed {
            Feed::Shm { subscriber, .. } => subscriber
                .receive()
                .map_err(|e| PortError::Ipc {
                    service: format!("{}/{}", self.from_agent, self.from_port),
                    detail: format!(
                        "input {input:?} cannot take another sample ({e:?}): drop the ones held, or keep copies"
                    ),
                })?
                .map(|sample| (*sample.user_header(), Received(ReceivedInner::Shm(sample)))),
            Feed::Memory { queue, .. } => queue.pop_front().map(|(h, b)| (h, Received(ReceivedInner::Memory(h, b)))),
        };
        Ok(got.map(|(h, r)| {
            self.tally.account(&h, now_ns());
            r
        }))
    }
}

pub(crate) struct SchemaInputInner {
    name: String,
    schema: Schema,
    fingerprint: u64,
    subs: Mutex<Vec<Source>>,
    next: AtomicU64,
}

/// An input port of the payload layout a [`Schema`] describes, fed by any
/// number of output ports of that layout.
pub struct SchemaInput {
    inner: Arc<SchemaInputInner>,
}

impl std::fmt::Debug for SchemaInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SchemaInput")
            .field("name", &self.inner.name)
            .field("type", &self.inner.schema.type_name)
            .finish()
    }
}

impl SchemaInput {
    pub(crate) fn new(name: &str, schema: Schema) -> (Self, Arc<SchemaInputInner>) {
        let fingerprint = schema.fingerprint();
        let inner = Arc::new(SchemaInputInner {
            name: name.into(),
            schema,
            fingerprint,
            subs: Mutex::new(Vec::new()),
            next: AtomicU64::new(0),
        });
        (SchemaInput { inner: inner.clone() }, inner)
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

    /// How many sources feed this input now.
    pub fn sources(&self) -> usize {
        lock(&self.inner.subs).len()
    }
}

impl SchemaInputInner {
    /// Queues `bytes` (exactly the layout's size) from `sender`'s port
    /// `port` as a test's sample, stamped `stamp_ns`; as
    /// [`crate::ports::InputInner`]'s `queue` does for a typed input.
    pub(crate) fn queue(&self, sender: &str, port: &str, bytes: &[u8], stamp_ns: u64) -> Result<(), PortError> {
        if bytes.len() != self.schema.size {
            return Err(PortError::Ipc {
                service: format!("{sender}/{port}"),
                detail: format!(
                    "a {}-byte sample for input {:?} of {}-byte {}",
                    bytes.len(),
                    self.name,
                    self.schema.size,
                    self.schema.type_name
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
                    feed: Feed::Memory { queue: VecDeque::new(), sent: 0 },
                    tally: Tally::default(),
                });
                subs.len() - 1
            }
        };
        let Feed::Memory { queue, sent } = &mut subs[at].feed else {
            return Err(PortError::Ipc {
                service: format!("{sender}/{port}"),
                detail: "an iceoryx2 source, not a test's".into(),
            });
        };
        *sent = sent.saturating_add(1);
        let seq = *sent;
        if queue.len() >= SUBSCRIBER_BUFFER {
            queue.pop_front();
        }
        queue.push_back((SampleHeader { sender: FixedName::new(sender), seq, stamp_ns }, bytes.into()));
        Ok(())
    }

    /// Opens the source port `service` with this input's layout: never
    /// creates it, and refuses another type or another layout of the type.
    fn open(
        &self,
        node: &Node<Ipc>,
        service: &str,
    ) -> Result<Subscriber<Ipc, [CustomPayloadMarker], SampleHeader>, PortError> {
        let name: ServiceName = service.try_into().map_err(|e| crate::ports::perr(service, e))?;
        let details = payload_details(service, &self.schema)?;
        // SAFETY: the payload's details are the schema's, the layout every
        // agent of this type uses (checked by the fingerprint below); the
        // samples are handed out as bytes only.
        let builder = unsafe {
            node.service_builder(&name)
                .publish_subscribe::<[CustomPayloadMarker]>()
                .user_header::<SampleHeader>()
                .__internal_set_payload_type_details(&details)
        };
        let factory = port_settings!(builder).open().map_err(|source| match source {
            Open::DoesNotExist => PortError::NoSuchPort { service: service.into() },
            Open::IncompatibleTypes => {
                PortError::IncompatibleType { service: service.into(), type_name: self.schema.type_name.clone() }
            }
            source => PortError::OpenService { service: service.into(), source },
        })?;
        match service_fingerprint(&factory) {
            Some(theirs) if theirs != self.fingerprint => {
                return Err(PortError::LayoutMismatch {
                    service: service.into(),
                    type_name: self.schema.type_name.clone(),
                    ours: self.fingerprint,
                    theirs,
                });
            }
            _ => {}
        }
        factory
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .create()
            .map_err(|source| PortError::Subscriber { service: service.into(), source })
    }
}

impl DynInput for SchemaInputInner {
    fn name(&self) -> &str {
        &self.name
    }

    fn type_name(&self) -> &str {
        &self.schema.type_name
    }

    fn spec(&self) -> PortSpec {
        PortSpec { name: self.name.clone(), type_name: self.schema.type_name.clone(), fingerprint: self.fingerprint }
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
        let (subscriber, listener) =
            crate::world::retry_after_cleanup(node.config(), "connect", PortError::blockable, || {
                let subscriber = self.open(node, &service)?;
                let listener = source_event(node, &service)?
                    .listener_builder()
                    .create()
                    .map_err(|source| PortError::Listener { service: service.clone(), source })?;
                Ok((subscriber, listener))
            })?;
        lock(&self.subs).push(Source {
            from_agent: from_agent.into(),
            from_port: from_port.into(),
            feed: Feed::Shm { subscriber, listener: Arc::new(listener) },
            tally: Tally::default(),
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
                Feed::Memory { .. } => None,
            })
            .collect()
    }

    fn stats(&self, now: u64) -> Vec<InputStats> {
        lock(&self.subs).iter().map(|s| s.tally.stats(&self.name, &s.from_agent, &s.from_port, now)).collect()
    }

    fn has_queued(&self) -> bool {
        lock(&self.subs).iter().any(|s| matches!(&s.feed, Feed::Memory { queue, .. } if !queue.is_empty()))
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

/// An output port of the payload layout a [`Schema`] describes.
#[derive(Debug)]
pub struct SchemaOutput {
    service: String,
    schema: Schema,
    sink: Sink,
}

/// Where a [`SchemaOutput`]'s samples go.
// A running agent's variant is the large one and the only one on the data
// path; boxing it would add a pointer hop to every send (as `ports::Sink`).
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
enum Sink {
    /// a running agent: the port's iceoryx2 service
    Shm(RawOutput),
    /// a test: the harness collects them
    Memory(Arc<CollectedBytes>),
    /// `--describe`: nothing is sent
    Nothing,
}

/// The samples a [`SchemaOutput`] sent in a test, in order, for [`crate::testing`].
#[derive(Debug)]
pub(crate) struct CollectedBytes {
    samples: Mutex<Vec<(Meta, Vec<u8>)>>,
    /// the harness's clock, which stamps them
    clock: Arc<AtomicU64>,
    sender: FixedName,
    seq: AtomicU64,
}

impl CollectedBytes {
    /// Takes every sample sent since the last call.
    pub(crate) fn take(&self) -> Vec<(Meta, Vec<u8>)> {
        std::mem::take(&mut *lock(&self.samples))
    }

    fn push(&self, bytes: &[u8]) {
        let seq = self.seq.fetch_add(1, Ordering::Relaxed) + 1;
        let meta = Meta { sender: self.sender, seq, stamp_ns: self.clock.load(Ordering::Acquire) };
        lock(&self.samples).push((meta, bytes.to_vec()));
    }
}

impl SchemaOutput {
    pub(crate) fn create(node: &Node<Ipc>, service: &str, schema: Schema, sender: &str) -> Result<Self, PortError> {
        let raw = RawOutput::create(node, service, &schema, schema.fingerprint(), sender)?;
        Ok(SchemaOutput { service: service.into(), schema, sink: Sink::Shm(raw) })
    }

    pub(crate) fn unbound(service: &str, schema: Schema) -> Self {
        SchemaOutput { service: service.into(), schema, sink: Sink::Nothing }
    }

    /// An output whose samples a test collects, stamped by `clock`.
    pub(crate) fn in_memory(
        service: &str,
        schema: Schema,
        sender: &str,
        clock: Arc<AtomicU64>,
    ) -> (Self, Arc<CollectedBytes>) {
        let collected = Arc::new(CollectedBytes {
            samples: Mutex::new(Vec::new()),
            clock,
            sender: FixedName::new(sender),
            seq: AtomicU64::new(0),
        });
        (SchemaOutput { service: service.into(), schema, sink: Sink::Memory(collected.clone()) }, collected)
    }

    /// The iceoryx2 service name of this port.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The layout of what it sends.
    pub fn schema(&self) -> &Schema {
        &self.schema
    }

    /// Loans a sample to write in place. `zeroed`: every byte is zero
    /// first; otherwise the bytes are what the slot last held, and the
    /// writer must write every field a reader looks at (a large frame then
    /// costs one write, not two).
    pub fn loan(&self, zeroed: bool) -> Result<Loan, PortError> {
        match &self.sink {
            Sink::Shm(raw) => raw.loan(zeroed),
            Sink::Memory(_) | Sink::Nothing => Ok(Loan::detached(self.schema.size)),
        }
    }

    /// Sends a loaned sample, stamped now, and wakes the readers.
    pub fn send(&mut self, loan: Loan) -> Result<(), PortError> {
        match &mut self.sink {
            Sink::Shm(raw) => raw.send_loan(loan),
            Sink::Memory(c) => {
                c.push(loan.bytes());
                Ok(())
            }
            Sink::Nothing => Ok(()),
        }
    }

    /// Sends `bytes` (exactly the layout's size), copied into a loaned sample.
    pub fn send_bytes(&mut self, bytes: &[u8]) -> Result<(), PortError> {
        match &mut self.sink {
            Sink::Shm(raw) => raw.send(bytes),
            Sink::Memory(c) if bytes.len() == self.schema.size => {
                c.push(bytes);
                Ok(())
            }
            Sink::Memory(_) => Err(PortError::Ipc {
                service: self.service.clone(),
                detail: format!("a {}-byte sample for a {}-byte type", bytes.len(), self.schema.size),
            }),
            Sink::Nothing => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{SchemaInput, SchemaOutput};
    use crate::ports::{DynInput as _, Input, Output, PortError};
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
        let (by_layout, inner) = SchemaInput::new("in", Scalar::schema());
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
        let (typed_in, typed_inner) = Input::<Scalar>::new("in");
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
        let (_, wrong) = SchemaInput::new("in2", other.clone());
        match wrong.connect(&node, &robot, "rust", "value") {
            Err(PortError::LayoutMismatch { .. } | PortError::IncompatibleType { .. }) => {}
            other => panic!("another layout read: {other:?}"),
        }
        assert!(SchemaOutput::create(&node, &service, other, "py").is_err(), "another layout published");
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
        let (input, inner) = SchemaInput::new("in", Scalar::schema());
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
            let (_, input) = SchemaInput::new("in", bad.clone());
            match input.connect(&node, &robot, "rust", "value") {
                Err(PortError::InvalidSchema { .. }) => {}
                other => panic!("align {align} read: {other:?}"),
            }
            match crate::raw_port::RawOutput::create(&node, &service, &bad, bad.fingerprint(), "rec") {
                Err(PortError::InvalidSchema { .. }) => {}
                other => panic!("align {align} replayed: {other:?}"),
            }
        }
    }
}
