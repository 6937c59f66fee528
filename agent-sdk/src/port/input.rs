//! The byte port's receiving side: a [`SchemaInput`] (shared as
//! [`InputInner`] with the runtime, which connects and disconnects its
//! sources and wakes on their listeners through [`DynInput`]) hands out the
//! samples of its sources in place ([`Received`], or a callback given their
//! bytes), round robin between the sources, and counts each source
//! (`port::tally`). A source is a subscription to an output port's
//! iceoryx2 service, or a test's queue (`port::memory`); a deep or
//! keep-all input first moves what waits into its own queue
//! (`port::depth`), and a keep-all source reads the port's lossless service
//! when its output publishes there (`port::keep_all`). The module doc of
//! `port::bytes` has the whole port.

use super::bytes::{ByteSubscriber, Meta, payload_bytes};
use super::error::{PortError, perr, port_err};
use super::keep_all::KeepAllFeed;
use super::memory::{Queue, SampleBuf};
use super::output::PayloadAt;
use super::service::{Carried, MAX_SOURCES, SUBSCRIBER_BUFFER, lock, source_event, source_service};
use super::tally::Tally;
use crate::world::Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::service::marker::CustomPayloadMarker;
use shm_schemas::control::agent_to_router::PortSpec;
use shm_schemas::stats::{InputStats, QueueStats};
use shm_schemas::{SampleHeader, Schema};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// A sample received on a [`SchemaInput`], read in place: its bytes stay in
/// shared memory, and the slot is not reused by the sender, until it is
/// dropped.
pub struct Received(ReceivedInner);

enum ReceivedInner {
    /// a slot of the source port's shared memory, and where its payload lies
    Shm(ShmSample, PayloadAt),
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
            ReceivedInner::Shm(sample, _) => Meta::of(sample.user_header()),
            ReceivedInner::Memory(h, _) => Meta::of(h),
        }
    }

    /// The payload's bytes, as the sender wrote them (the schema's layout).
    pub fn bytes(&self) -> &[u8] {
        match &self.0 {
            // SAFETY: `at` is the payload of the sample this owns, kept until it is dropped
            ReceivedInner::Shm(_, at) => unsafe { at.bytes() },
            ReceivedInner::Memory(_, bytes) => bytes.bytes(),
        }
    }

    /// A sample of a source port's shared memory, kept in place.
    pub(super) fn in_place(sample: ShmSample) -> Self {
        // the one look at the payload's place (iceoryx2 takes a lock for it, `PayloadAt`)
        let bytes = payload_bytes(sample.payload());
        let at = PayloadAt::of(bytes.as_ptr().cast_mut(), bytes.len());
        Received(ReceivedInner::Shm(sample, at))
    }

    /// [`Received::in_place`] for a source whose payloads lie where `place`
    /// says, once it has measured one: without iceoryx2's lock.
    fn in_place_at(sample: ShmSample, place: &mut PayloadPlace) -> Self {
        let at = place.of(&sample);
        Received(ReceivedInner::Shm(sample, at))
    }

    /// A sample copied out of shared memory (an input's own queue, a test's).
    pub(super) fn copied(header: SampleHeader, bytes: SampleBuf) -> Self {
        Received(ReceivedInner::Memory(header, bytes))
    }
}

/// One source of an input.
pub(super) struct Source {
    pub(super) from_agent: String,
    pub(super) from_port: String,
    pub(super) feed: Feed,
    pub(super) tally: Tally,
    /// the input's own queue when it is deeper than iceoryx2's or keeps all ([`super::depth`])
    pub(super) held: Option<super::depth::Held>,
    /// a keep-all input's lossless subscription ([`super::keep_all`])
    pub(super) keep_all: Option<KeepAllFeed>,
    /// the sample the polling task received when it looked ([`Source::look`])
    pub(super) peeked: Option<ShmSample>,
    /// where this source's payloads lie ([`PayloadPlace`])
    pub(super) place: PayloadPlace,
}

/// A sample in place in a source port's shared memory.
pub(super) type ShmSample = Sample<Ipc, [CustomPayloadMarker], SampleHeader>;

/// Where one source's payloads lie in their samples.
///
/// A received sample's payload (`Sample::payload` of a slice) is found under
/// the subscriber's lock, a mutex on the thread-safe service type that
/// nerve's ports use: a second lock per sample beside the receive's, on the
/// hop's path (a polling hop costs about a microsecond, issue 42). iceoryx2
/// places the payload at a fixed distance after the user header, the same
/// for every chunk of a service (as `SchemaOutput::payload_of` uses for
/// loans), and its length is the header's element count times the
/// service's element size. Both are measured at the source's first sample
/// with elements; later samples add them to the user header's address and
/// the header's count, which iceoryx2 hands out without a lock. A debug
/// build (every test) checks every sample against iceoryx2's own answer.
#[derive(Debug, Default)]
pub(super) struct PayloadPlace {
    /// (distance from the user header to the payload, bytes per element)
    measured: Option<(usize, usize)>,
}

impl PayloadPlace {
    /// Where `sample`'s payload lies.
    fn of(&mut self, sample: &ShmSample) -> PayloadAt {
        let header = std::ptr::from_ref(sample.user_header()).addr();
        let elements = usize::try_from(sample.header().number_of_elements()).ok();
        if let Some((offset, unit)) = self.measured
            && let Some(len) = elements.and_then(|n| n.checked_mul(unit))
        {
            // `offset` and `unit` are this source's service's (measured
            // below, the same for every chunk): the sample's payload, made
            // from an address with the shared memory's exposed provenance,
            // as iceoryx2 makes its own pointers into a chunk
            let ptr = std::ptr::with_exposed_provenance_mut::<u8>(header.wrapping_add(offset));
            #[cfg(debug_assertions)]
            {
                let theirs = payload_bytes(sample.payload());
                debug_assert_eq!(
                    (theirs.as_ptr().addr(), theirs.len()),
                    (ptr.addr(), len),
                    "a received sample's payload is not where the source's first one was"
                );
            }
            return PayloadAt::of(ptr, len);
        }
        let bytes = payload_bytes(sample.payload());
        let ptr = bytes.as_ptr().cast_mut();
        let offset = ptr.expose_provenance().checked_sub(header);
        // a sample of no elements (an empty sequence) tells no element size
        let unit = elements.filter(|&n| n > 0).and_then(|n| bytes.len().is_multiple_of(n).then(|| bytes.len() / n));
        self.measured = offset.zip(unit);
        PayloadAt::of(ptr, bytes.len())
    }
}

/// Where a source's samples come from.
pub(super) enum Feed {
    /// a running agent: a subscription to the source port and its wake-up event
    Shm { subscriber: ByteSubscriber, listener: Arc<Listener<Ipc>> },
    /// a test: the samples the harness queued
    Memory(Queue),
}

impl Source {
    pub(super) fn receive_error(&self, input: &str, e: impl std::fmt::Debug) -> PortError {
        PortError::Ipc {
            service: format!("{}/{}", self.from_agent, self.from_port),
            detail: format!("input {input:?} cannot take another sample ({e:?}): drop the ones held, or keep copies"),
        }
    }

    /// The next waiting sample of this source, if any, kept in place, with
    /// its header; counted. A sample the polling task already received
    /// ([`Source::look`]) comes first: it is the oldest.
    fn next(&mut self, input: &str) -> Result<Option<(SampleHeader, Received)>, PortError> {
        let got = match self.take_lossless(input) {
            Some(got) => got?,
            None => match &mut self.feed {
                Feed::Shm { subscriber, .. } if self.held.is_some() => self
                    .held
                    .as_mut()
                    .and_then(|held| held.take(subscriber, input))
                    .map(|(h, b)| (h, Received::copied(h, b))),
                Feed::Shm { subscriber, .. } => match self.peeked.take() {
                    Some(sample) => Some((*sample.user_header(), Received::in_place_at(sample, &mut self.place))),
                    None => match subscriber.receive() {
                        Ok(sample) => sample.map(|s| (*s.user_header(), Received::in_place_at(s, &mut self.place))),
                        Err(e) => return Err(self.receive_error(input, e)),
                    },
                },
                Feed::Memory(queue) => queue.pop().map(|(h, b)| (h, Received::copied(h, b))),
            },
        };
        if let Some((h, _)) = &got {
            // at the step's start, when the task found it (`runtime::step_clock`)
            self.tally.account(h, crate::runtime::step_clock::counted_at());
        }
        Ok(got)
    }

    /// The next waiting sample of this source, if any, kept in place.
    fn take(&mut self, input: &str) -> Result<Option<Received>, PortError> {
        Ok(self.next(input)?.map(|(_, r)| r))
    }

    /// Hands this source's next waiting sample, in place, to `f`; `None`
    /// when none waits. The sample is released when `f` returns.
    fn take_with<R>(&mut self, input: &str, f: impl FnOnce(&SampleHeader, &[u8]) -> R) -> Result<Option<R>, PortError> {
        Ok(self.next(input)?.map(|(h, r)| f(&h, r.bytes())))
    }

    /// Whether a sample waits, looked at in shared memory without a system
    /// call (the polling task's look, `runtime::poll`). A source read
    /// straight from iceoryx2 receives the sample at once and keeps it for
    /// the step's [`Source::next`]: one look at iceoryx2's queue per sample,
    /// as a raw busy-polling subscriber makes, instead of a look and then a
    /// receive. A source with a queue of its own (deep, keep-all) is only
    /// looked at: its refill takes what waits, in order.
    fn look(&mut self) -> bool {
        match &self.feed {
            Feed::Shm { subscriber, .. } if self.held.is_none() && self.keep_all.is_none() => {
                if self.peeked.is_some() {
                    return true;
                }
                match subscriber.receive() {
                    Ok(Some(sample)) => {
                        self.peeked = Some(sample);
                        true
                    }
                    Ok(None) => false,
                    // the reader holds as many samples as iceoryx2 lends: the step's take says so
                    Err(_) => subscriber.has_samples().unwrap_or(false),
                }
            }
            // a source that cannot be looked at has nothing to take either
            Feed::Shm { subscriber, .. } => {
                subscriber.has_samples().unwrap_or(false) || self.keep_all.as_ref().is_some_and(|k| k.has_samples())
            }
            Feed::Memory(q) => !q.is_empty(),
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
    /// (a polling task's look, `runtime::poll`; a byte input receives the
    /// sample then and keeps it for the step, see `Source::look`); `None`
    /// when the port cannot tell so (a call's side: its listeners are
    /// looked at instead).
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
            peeked: None,
            place: PayloadPlace::default(),
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
        Some(lock(&self.subs).iter_mut().any(Source::look))
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
                    peeked: None,
                    place: PayloadPlace::default(),
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

#[cfg(test)]
mod tests {
    use super::DynInput as _;
    use crate::clock::now_ns;
    use crate::port::{Input, Output, SchemaInput};
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::Described as _;
    use shm_schemas::payloads::Scalar;

    /// The polling task's look (`waiting`, issue 42) receives the sample it
    /// finds, and the step's take hands that one out first: every sample
    /// once, in order, counted once, whether it was looked at or not; one
    /// looked at and then unwired is released; a reader holding all that
    /// iceoryx2 lends still sees that more waits, and is told to drop some.
    #[test]
    fn a_polled_look_keeps_the_sample_for_the_step_in_order_and_counted_once() {
        let world = World::new(&format!("look{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let out = Output::<Scalar>::create(&node, &robot.port_service("a", "v"), "a").expect("output");
        let send = |i: u32| out.send(Scalar { value: f64::from(i), stamp_ns: 1 }).expect("send");
        let (input, inner) = Input::<Scalar>::new("in").expect("input");
        assert!(inner.connect(&node, &robot, "a", "v").expect("connects"));
        assert_eq!(inner.waiting(), Some(false), "nothing sent");

        (1..=3).for_each(send);
        assert_eq!(inner.waiting(), Some(true));
        assert_eq!(inner.waiting(), Some(true), "looked at twice: the same sample, still waiting");
        let mut seen = Vec::new();
        assert_eq!(input.drain(|m, v| seen.push((m.seq, v.value))), 3);
        assert_eq!(seen, [(1, 1.0), (2, 2.0), (3, 3.0)], "the looked-at sample first, then the rest");
        assert_eq!(inner.waiting(), Some(false), "all taken");
        send(4);
        assert_eq!(input.recv().map(|(m, v)| (m.seq, v.value)), Some((4, 4.0)), "not looked at: taken as before");
        let stats = inner.stats(now_ns());
        assert_eq!((stats[0].received, stats[0].dropped), (4, 0), "each counted once");

        // looked at, then unwired: the sample goes with the subscription, and a new one reads on
        send(5);
        assert_eq!(inner.waiting(), Some(true));
        assert!(inner.disconnect("a", "v"));
        assert_eq!((inner.waiting(), input.recv().map(|(m, _)| m.seq)), (Some(false), None), "gone with its source");
        assert!(inner.connect(&node, &robot, "a", "v").expect("wired again"));
        send(6);
        assert_eq!(inner.waiting(), Some(true));
        assert_eq!(input.recv().map(|(m, _)| m.seq), Some(6));

        // a reader by layout holding the two samples iceoryx2 lends per source
        let (by_layout, layout_inner) = SchemaInput::new("raw", Scalar::schema()).expect("input");
        assert!(layout_inner.connect(&node, &robot, "a", "v").expect("connects"));
        (7..=9).for_each(send);
        assert_eq!(layout_inner.waiting(), Some(true));
        let held = (by_layout.take().expect("take"), by_layout.take().expect("take"));
        assert_eq!(held.0.as_ref().map(|r| r.meta().seq), Some(7), "the looked-at sample first");
        assert_eq!(held.1.as_ref().map(|r| r.meta().seq), Some(8));
        assert_eq!(layout_inner.waiting(), Some(true), "the third waits, though it cannot be lent yet");
        match by_layout.take() {
            Err(e) => assert!(e.to_string().contains("drop the ones held"), "{e}"),
            Ok(s) => panic!("a third sample lent: {s:?}"),
        }
        drop(held);
        assert_eq!(layout_inner.waiting(), Some(true));
        assert_eq!(by_layout.take().expect("take").map(|r| r.meta().seq), Some(9));
    }
}
