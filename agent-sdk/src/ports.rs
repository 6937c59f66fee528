//! Typed ports.
//!
//! An [`Output`] is one iceoryx2 publish-subscribe service
//! `nerve/<robot>/<agent>/<port>`, paired with an event service of the same
//! name that wakes event-driven readers. An [`Input`] holds zero or more
//! subscriptions (fan-in), made and dropped by the message checker when the
//! router says so; the task sees a new subscription at its next cycle.
//!
//! Both sides open the services through [`port_service`] and [`port_event`],
//! so their settings always agree (iceoryx2 refuses an opener that asks for
//! more than the creator set up).

use crate::clock::now_ns;
use crate::meters::RateMeter;
use crate::world::Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::attribute::{AttributeKey, AttributeValue, AttributeVerifier};
use iceoryx2::service::port_factory::{event, publish_subscribe};
use shm_schemas::services::port_attributes::{self, fingerprint_text, parse_fingerprint};
use shm_schemas::stats::InputStats;
use shm_schemas::{FixedName, Payload, SampleHeader};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

/// Fan-out of one output port: how many inputs may read it at once.
pub const MAX_SUBSCRIBERS: usize = 16;
/// Fan-in of one input port: how many outputs it may read at once. Each
/// source costs a subscriber, a listener, their file descriptors and a line
/// in the agent's statistics, so a flood of `Connect` commands is refused
/// past this (reliability review R10).
pub const MAX_SOURCES: usize = 64;
/// Samples a subscription buffers before the oldest is overwritten (and counted as dropped).
pub const SUBSCRIBER_BUFFER: usize = 16;
pub(crate) const MAX_PUBLISHERS: usize = 4;
pub(crate) const MAX_NODES: usize = 40;

/// Why a port could not be made or used. Each variant names the iceoryx2
/// operation that failed and keeps iceoryx2's own error as its source, so a
/// caller can tell a full subscriber list from a missing service.
#[derive(Debug, thiserror::Error)]
pub enum PortError {
    /// The port's publish-subscribe service could not be opened or created.
    #[error("port {service}: cannot open its service: {source:?}")]
    Service {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError,
    },
    /// The service exists with another payload type.
    #[error("port {service}: the service exists with another payload type than {type_name}")]
    IncompatibleType {
        /// service name
        service: String,
        /// the type this side asked for
        type_name: String,
    },
    /// The service carries the same type name built from another
    /// definition (another layout fingerprint): a stale build on one side.
    #[error(
        "port {service} carries {type_name} with layout {}, this program was built with layout {}: \
         the two were built from different definitions of {type_name}; rebuild the older one (`cargo build`) and restart it",
        fingerprint_text(*theirs), fingerprint_text(*ours)
    )]
    LayoutMismatch {
        /// service name
        service: String,
        /// the payload type name
        type_name: String,
        /// the fingerprint of this side's build
        ours: u64,
        /// the fingerprint the service was created with
        theirs: u64,
    },
    /// The port's wake-up event service could not be opened or created.
    #[error("port {service}: cannot open its wake-up event: {source:?}")]
    Event {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::service::builder::event::EventOpenOrCreateError,
    },
    /// The publisher could not be created.
    #[error("port {service}: cannot create the publisher: {source:?}")]
    Publisher {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::publisher::PublisherCreateError,
    },
    /// The subscriber could not be created (e.g. the service has its most subscribers).
    #[error("port {service}: cannot subscribe: {source:?}")]
    Subscriber {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::subscriber::SubscriberCreateError,
    },
    /// The event notifier could not be created.
    #[error("port {service}: cannot create the wake-up notifier: {source:?}")]
    Notifier {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::notifier::NotifierCreateError,
    },
    /// The event listener could not be created.
    #[error("port {service}: cannot create the wake-up listener: {source:?}")]
    Listener {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::listener::ListenerCreateError,
    },
    /// No sample could be loaned (every slot is held by subscribers or unsent).
    #[error("port {service}: cannot loan a sample: {source:?}")]
    Loan {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::LoanError,
    },
    /// The sample could not be sent.
    #[error("port {service}: cannot send: {source:?}")]
    Send {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::SendError,
    },
    /// The subscribers could not be woken.
    #[error("port {service}: cannot wake the subscribers: {source:?}")]
    Notify {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::notifier::NotifierNotifyError,
    },
    /// The output port an input was asked to read does not exist: no agent
    /// of the robot has it (an input opens a source, it never creates one).
    #[error("port {service} does not exist: no running agent of this robot has that output; see `nerve ps`")]
    NoSuchPort {
        /// service name
        service: String,
    },
    /// The source port's services exist but could not be opened.
    #[error("port {service}: cannot open its service: {source:?}")]
    OpenService {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError,
    },
    /// The source port's wake-up event could not be opened.
    #[error("port {service}: cannot open its wake-up event: {source:?}")]
    OpenEvent {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::service::builder::event::EventOpenError,
    },
    /// An input reads from as many sources as it may.
    #[error(
        "input {input} already reads {max} sources, the most an input may: disconnect one first (`nerve disconnect`)"
    )]
    TooManySources {
        /// the input
        input: String,
        /// [`MAX_SOURCES`]
        max: usize,
    },
    /// The payload's schema describes no layout a type could have (a
    /// damaged recording, a hand-written layout): refused before iceoryx2 sees it.
    #[error("port {service}: {source}")]
    InvalidSchema {
        /// service name
        service: String,
        /// what is wrong with the schema (boxed: it names the type and
        /// the field, and every `Result` of a port would carry its size)
        #[source]
        source: Box<shm_schemas::schema::SchemaInvalid>,
    },
    /// Anything else: an invalid service name, a sample of the wrong size.
    #[error("port {service}: {detail}")]
    Ipc {
        /// service name
        service: String,
        /// what went wrong
        detail: String,
    },
}

impl PortError {
    /// Whether a dead process's leftover ports could explain this error
    /// (iceoryx2 refused a port or an open because the service's slots
    /// for ports or nodes were taken), so that cleaning them up and trying
    /// again may help; not for a missing port or a type that differs.
    pub(crate) fn blockable(&self) -> bool {
        matches!(
            self,
            PortError::Service { .. }
                | PortError::Event { .. }
                | PortError::OpenService { .. }
                | PortError::OpenEvent { .. }
                | PortError::Publisher { .. }
                | PortError::Subscriber { .. }
                | PortError::Notifier { .. }
                | PortError::Listener { .. }
        )
    }
}

pub(crate) fn perr(service: &str, e: impl std::fmt::Debug) -> PortError {
    PortError::Ipc { service: service.into(), detail: format!("{e:?}") }
}

/// Wraps iceoryx2's error `source` into the [`PortError`] variant `$v` for `$service`.
macro_rules! port_err {
    ($v:ident, $service:expr) => {
        |source| PortError::$v { service: String::from($service), source }
    };
}

type PortBuilder<T> = iceoryx2::service::builder::publish_subscribe::Builder<T, SampleHeader, Ipc>;

/// The settings of every output port's service, typed or not (a replayed
/// port, [`crate::raw_port::RawOutput`]), so that every opener agrees.
macro_rules! port_settings {
    ($builder:expr) => {
        $builder
            .max_publishers($crate::ports::MAX_PUBLISHERS)
            .max_subscribers($crate::ports::MAX_SUBSCRIBERS)
            .max_nodes($crate::ports::MAX_NODES)
            .subscriber_max_buffer_size($crate::ports::SUBSCRIBER_BUFFER)
            .history_size(0)
            .enable_safe_overflow(true)
    };
}
pub(crate) use port_settings;

/// The one place that sets up an output port's service, so that every opener agrees.
fn port_builder<T: Payload>(node: &Node<Ipc>, service: &str) -> Result<PortBuilder<T>, PortError> {
    let name: ServiceName = service.try_into().map_err(|e| perr(service, e))?;
    Ok(port_settings!(node.service_builder(&name).publish_subscribe::<T>().user_header::<SampleHeader>()))
}

/// The attributes of the service of output port `service`
/// (`nerve/ROBOT/AGENT/PORT`) carrying `T`: its type name, layout
/// fingerprint, agent and port ([`port_attributes`]).
fn port_attributes<T: Payload>(service: &str) -> Result<AttributeVerifier, PortError> {
    port_attributes_of(service, T::stable_type_name(), T::layout_fingerprint())
}

/// The attributes of output port `service` carrying `type_name` of layout `fingerprint`.
pub(crate) fn port_attributes_of(
    service: &str,
    type_name: &str,
    fingerprint: u64,
) -> Result<AttributeVerifier, PortError> {
    let mut parts = service.splitn(4, '/').skip(2);
    let (agent, port) = (parts.next().unwrap_or_default(), parts.next().unwrap_or_default());
    let fingerprint = fingerprint_text(fingerprint);
    let mut v = AttributeVerifier::new();
    for (key, value) in [
        (port_attributes::TYPE, type_name),
        (port_attributes::FINGERPRINT, fingerprint.as_str()),
        (port_attributes::AGENT, agent),
        (port_attributes::PORT, port),
    ] {
        if value.is_empty() {
            continue;
        }
        let (Ok(key), Ok(value)) = (AttributeKey::try_from(key), AttributeValue::try_from(value)) else {
            return Err(perr(service, format!("the attribute {key}={value} does not fit an iceoryx2 attribute")));
        };
        v = v.require(&key, &value).map_err(|e| perr(service, e))?;
    }
    Ok(v)
}

/// The layout fingerprint a port's service was created with, if it says.
pub fn service_fingerprint(factory: &impl iceoryx2::service::port_factory::PortFactory) -> Option<u64> {
    let key = AttributeKey::try_from(port_attributes::FINGERPRINT).ok()?;
    parse_fingerprint(&factory.attributes().key_value(&key, 0)?.to_string())
}

/// Refuses a service created for another layout of `T` than this build's.
fn check_layout<T: Payload>(
    service: &str,
    factory: &impl iceoryx2::service::port_factory::PortFactory,
) -> Result<(), PortError> {
    match service_fingerprint(factory) {
        Some(theirs) if theirs != T::layout_fingerprint() => Err(PortError::LayoutMismatch {
            service: service.into(),
            type_name: T::stable_type_name().into(),
            ours: T::layout_fingerprint(),
            theirs,
        }),
        _ => Ok(()),
    }
}

/// Opens (or creates) the publish-subscribe service of an output port. A
/// service it creates carries the port's attributes ([`port_attributes`]);
/// one it opens must have been created for the same layout of `T`.
pub fn port_service<T: Payload>(
    node: &Node<Ipc>,
    service: &str,
) -> Result<publish_subscribe::PortFactory<Ipc, T, SampleHeader>, PortError> {
    use iceoryx2::service::builder::publish_subscribe::{
        PublishSubscribeOpenError as Open, PublishSubscribeOpenOrCreateError as OpenOrCreate,
    };
    let mut attempt = 0;
    loop {
        attempt += 1;
        match port_builder::<T>(node, service)?.open_or_create_with_attributes(&port_attributes::<T>(service)?) {
            Ok(f) => return Ok(f),
            Err(OpenOrCreate::PublishSubscribeOpenError(Open::IncompatibleAttributes)) => {
                // created by another build: say which layouts disagree
                let theirs = port_builder::<T>(node, service)?.open().ok().and_then(|f| service_fingerprint(&f));
                return Err(match theirs {
                    Some(theirs) => PortError::LayoutMismatch {
                        service: service.into(),
                        type_name: T::stable_type_name().into(),
                        ours: T::layout_fingerprint(),
                        theirs,
                    },
                    None => PortError::Ipc {
                        service: service.into(),
                        detail: "the service exists with other attributes (made by another program?)".into(),
                    },
                });
            }
            Err(OpenOrCreate::PublishSubscribeOpenError(Open::IncompatibleTypes)) => {
                return Err(PortError::IncompatibleType {
                    service: service.into(),
                    type_name: T::stable_type_name().into(),
                });
            }
            // The last owner of the service (an agent of the same name that
            // was killed while it stopped, or is still leaving) is removing
            // it: once it is gone the service can be created anew. Seen when
            // a supervisor restart came 0.5 s after such a death.
            Err(OpenOrCreate::PublishSubscribeOpenError(Open::IsMarkedForDestruction))
                if attempt < MARKED_FOR_DESTRUCTION_ATTEMPTS =>
            {
                tracing::debug!(service, attempt, "the port's service is being removed; trying again");
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            Err(source) => return Err(PortError::Service { service: service.into(), source }),
        }
    }
}

/// How often opening a port's service is tried while its last owner removes
/// it (10 ms apart: half a second in all).
const MARKED_FOR_DESTRUCTION_ATTEMPTS: u32 = 50;

/// Opens the service of an existing output port; `None` when it does not
/// exist or carries another type (used by tools that probe a port's type).
pub fn existing_port_service<T: Payload>(
    node: &Node<Ipc>,
    service: &str,
) -> Option<publish_subscribe::PortFactory<Ipc, T, SampleHeader>> {
    port_builder::<T>(node, service).ok()?.open().ok()
}

/// The publish-subscribe and event services of a source port.
type SourceServices<T> = (publish_subscribe::PortFactory<Ipc, T, SampleHeader>, event::PortFactory<Ipc>);

/// Opens the services of an existing output port, for an input to read it:
/// never creates them, so a source that no agent has is refused
/// ([`PortError::NoSuchPort`]) and leaves no file behind.
fn source_services<T: Payload>(node: &Node<Ipc>, service: &str) -> Result<SourceServices<T>, PortError> {
    use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError as Open;
    let mut attempt = 0;
    let ps = loop {
        attempt += 1;
        match port_builder::<T>(node, service)?.open() {
            Ok(f) => {
                check_layout::<T>(service, &f)?;
                break f;
            }
            Err(Open::DoesNotExist) => return Err(PortError::NoSuchPort { service: service.into() }),
            Err(Open::IncompatibleTypes) => {
                return Err(PortError::IncompatibleType {
                    service: service.into(),
                    type_name: T::stable_type_name().into(),
                });
            }
            // its owner is removing it (see port_service): it may come back at once
            Err(Open::IsMarkedForDestruction) if attempt < MARKED_FOR_DESTRUCTION_ATTEMPTS => {
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            Err(source) => return Err(PortError::OpenService { service: service.into(), source }),
        }
    };
    Ok((ps, source_event(node, service)?))
}

/// Opens the event service of an existing output port, for an input's
/// listener: never creates it.
pub(crate) fn source_event(node: &Node<Ipc>, service: &str) -> Result<event::PortFactory<Ipc>, PortError> {
    use iceoryx2::service::builder::event::EventOpenError;
    let name: ServiceName = service.try_into().map_err(|e| perr(service, e))?;
    node.service_builder(&name)
        .event()
        .max_listeners(MAX_SUBSCRIBERS + 4)
        .max_notifiers(MAX_PUBLISHERS + 4)
        .max_nodes(MAX_NODES)
        .open()
        .map_err(|source| match source {
            EventOpenError::DoesNotExist => PortError::NoSuchPort { service: service.into() },
            source => PortError::OpenEvent { service: service.into(), source },
        })
}

/// Opens (or creates) the event service paired with an output port.
pub fn port_event(node: &Node<Ipc>, service: &str) -> Result<event::PortFactory<Ipc>, PortError> {
    let name: ServiceName = service.try_into().map_err(|e| perr(service, e))?;
    node.service_builder(&name)
        .event()
        .max_listeners(MAX_SUBSCRIBERS + 4)
        .max_notifiers(MAX_PUBLISHERS + 4)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(port_err!(Event, service))
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

/// An output port of payload type `T`.
///
/// What it is bound to is the SDK's choice, never the agent's: an iceoryx2
/// service in a running agent, nothing while the agent is described
/// (`--describe`), an in-memory list in a test ([`crate::testing`]).
#[derive(Debug)]
pub struct Output<T: Payload> {
    service: String,
    sender: FixedName,
    sink: Sink<T>,
    seq: AtomicU64,
}

/// Where an output's samples go.
// A running agent's variant is the large one and the only one on the data
// path; boxing it would add a pointer hop to every send.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
enum Sink<T: Payload> {
    /// a running agent: the port's iceoryx2 service and its wake-up event
    Shm { publisher: Publisher<Ipc, T, SampleHeader>, notifier: Notifier<Ipc> },
    /// a test: the harness collects them
    Memory(Arc<Collected<T>>),
    /// `--describe`: the agent never steps, nothing is sent
    Nothing,
}

/// The samples an output sent in a test, in order, for [`crate::testing`].
#[derive(Debug)]
pub(crate) struct Collected<T: Payload> {
    samples: Mutex<Vec<(Meta, Box<T>)>>,
    /// the harness's clock, which stamps them
    clock: Arc<AtomicU64>,
}

impl<T: Payload> Collected<T> {
    /// Takes every sample sent since the last call.
    pub(crate) fn take(&self) -> Vec<(Meta, Box<T>)> {
        std::mem::take(&mut *lock(&self.samples))
    }
}

impl<T: Payload> Output<T> {
    pub(crate) fn create(node: &Node<Ipc>, service: &str, sender: &str) -> Result<Self, PortError> {
        let ps = port_service::<T>(node, service)?;
        let publisher = ps.publisher_builder().create().map_err(port_err!(Publisher, service))?;
        let notifier = port_event(node, service)?.notifier_builder().create().map_err(port_err!(Notifier, service))?;
        Ok(Self::with_sink(service, sender, Sink::Shm { publisher, notifier }))
    }

    /// An output bound to nothing (`--describe`): no service is made.
    pub(crate) fn unbound(service: &str, sender: &str) -> Self {
        Self::with_sink(service, sender, Sink::Nothing)
    }

    /// An output whose samples a test collects, stamped by `clock`.
    pub(crate) fn in_memory(service: &str, sender: &str, clock: Arc<AtomicU64>) -> (Self, Arc<Collected<T>>) {
        let collected = Arc::new(Collected { samples: Mutex::new(Vec::new()), clock });
        (Self::with_sink(service, sender, Sink::Memory(collected.clone())), collected)
    }

    fn with_sink(service: &str, sender: &str, sink: Sink<T>) -> Self {
        Output { service: service.into(), sender: FixedName::new(sender), sink, seq: AtomicU64::new(0) }
    }

    /// The iceoryx2 service name of this port.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// Sends `value` (written once, in place, into shared memory) and wakes the readers.
    pub fn send(&self, value: T) -> Result<(), PortError> {
        match &self.sink {
            Sink::Shm { publisher, notifier } => {
                let mut sample = publisher.loan_uninit().map_err(port_err!(Loan, &self.service))?;
                *sample.user_header_mut() = self.next_header();
                sample.write_payload(value).send().map_err(port_err!(Send, &self.service))?;
                notifier.notify().map_err(port_err!(Notify, &self.service))?;
            }
            Sink::Memory(c) => self.collect(c, Box::new(value)),
            Sink::Nothing => {}
        }
        Ok(())
    }

    /// Sends a value built in place by `fill`, for payloads too large to build on the stack.
    pub fn send_with(&self, fill: impl FnOnce(&mut T)) -> Result<(), PortError>
    where
        T: Default,
    {
        match &self.sink {
            Sink::Shm { publisher, notifier } => {
                let mut sample = publisher.loan_uninit().map_err(port_err!(Loan, &self.service))?;
                *sample.user_header_mut() = self.next_header();
                let mut sample = sample.write_payload(T::default());
                fill(sample.payload_mut());
                sample.send().map_err(port_err!(Send, &self.service))?;
                notifier.notify().map_err(port_err!(Notify, &self.service))?;
            }
            Sink::Memory(c) => {
                let mut value = Box::<T>::default();
                fill(&mut value);
                self.collect(c, value);
            }
            Sink::Nothing => {}
        }
        Ok(())
    }

    /// Sends a payload written in place by `fill`, without writing a default
    /// value first: a large frame costs one write into shared memory, not two.
    ///
    /// # Safety
    /// `fill` must leave the payload initialised: every field a reader will
    /// look at written, and only bit patterns valid for `T` in the rest (for
    /// plain numeric and byte-array payloads any bytes are valid).
    pub unsafe fn send_uninit(&self, fill: impl FnOnce(&mut std::mem::MaybeUninit<T>)) -> Result<(), PortError> {
        match &self.sink {
            Sink::Shm { publisher, notifier } => {
                let mut sample = publisher.loan_uninit().map_err(port_err!(Loan, &self.service))?;
                *sample.user_header_mut() = self.next_header();
                fill(sample.payload_mut());
                // SAFETY: the caller guarantees that `fill` initialised the payload.
                let sample = unsafe { sample.assume_init() };
                sample.send().map_err(port_err!(Send, &self.service))?;
                notifier.notify().map_err(port_err!(Notify, &self.service))?;
            }
            Sink::Memory(c) => {
                let mut value = Box::<T>::new_uninit();
                fill(&mut value);
                // SAFETY: the caller guarantees that `fill` initialised the payload.
                self.collect(c, unsafe { value.assume_init() });
            }
            Sink::Nothing => {}
        }
        Ok(())
    }

    fn collect(&self, c: &Collected<T>, value: Box<T>) {
        let h = self.header_at(c.clock.load(Ordering::Acquire));
        lock(&c.samples).push((Meta::of(&h), value));
    }

    fn next_header(&self) -> SampleHeader {
        self.header_at(now_ns())
    }

    fn header_at(&self, stamp_ns: u64) -> SampleHeader {
        let seq = self.seq.fetch_add(1, Ordering::Relaxed) + 1;
        SampleHeader { sender: self.sender, seq, stamp_ns }
    }
}

/// Where an input's samples from one source come from.
enum Source<T: Payload> {
    /// a running agent: a subscription to the source port and its wake-up event
    Shm { subscriber: Subscriber<Ipc, T, SampleHeader>, listener: Arc<Listener<Ipc>> },
    /// a test: samples the harness queued, at most [`SUBSCRIBER_BUFFER`]
    /// (the oldest is overwritten past it, as iceoryx2 does), and how many
    /// were queued in all (the sender's sequence number)
    Memory { queue: VecDeque<(SampleHeader, Box<T>)>, sent: u64 },
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

struct Subscription<T: Payload> {
    from_agent: String,
    from_port: String,
    source: Source<T>,
    tally: Tally,
}

/// Samples lost between `last_seq` and `seq` on one sender's port. A sender
/// is another process: its numbers are not trusted, so nothing here can
/// overflow, and a number going backwards (a restarted sender) loses nothing.
fn gap(last_seq: u64, seq: u64) -> u64 {
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

impl<T: Payload> Subscription<T> {
    /// Takes this source's next sample, if one waits, and hands it to `f`
    /// in place; `None` when none waits or receiving failed (logged).
    fn take<R>(&mut self, input: &str, f: impl FnOnce(&SampleHeader, &T) -> R) -> Option<R> {
        match &mut self.source {
            Source::Shm { subscriber, .. } => match subscriber.receive() {
                Ok(Some(sample)) => {
                    let h = *sample.user_header();
                    self.tally.account(&h, now_ns());
                    Some(f(&h, sample.payload()))
                }
                Ok(None) => None,
                Err(e) => {
                    tracing::warn!(input, "receive failed: {e:?}");
                    None
                }
            },
            Source::Memory { queue, .. } => {
                let (h, value) = queue.pop_front()?;
                self.tally.account(&h, now_ns());
                Some(f(&h, &value))
            }
        }
    }
}

pub(crate) struct InputInner<T: Payload> {
    name: String,
    subs: Mutex<Vec<Subscription<T>>>,
    next: AtomicU64,
}

/// An input port of payload type `T`, fed by any number of output ports.
pub struct Input<T: Payload> {
    inner: Arc<InputInner<T>>,
}

impl<T: Payload> std::fmt::Debug for Input<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Input").field("name", &self.inner.name).field("type", &T::stable_type_name()).finish()
    }
}

impl<T: Payload> Input<T> {
    pub(crate) fn new(name: &str) -> (Self, Arc<InputInner<T>>) {
        let inner = Arc::new(InputInner { name: name.into(), subs: Mutex::new(Vec::new()), next: AtomicU64::new(0) });
        (Input { inner: inner.clone() }, inner)
    }

    fn subs(&self) -> MutexGuard<'_, Vec<Subscription<T>>> {
        lock(&self.inner.subs)
    }

    /// Takes the next sample from any source (round robin between sources).
    pub fn recv(&self) -> Option<(Meta, T)> {
        let mut subs = self.subs();
        let n = subs.len();
        if n == 0 {
            return None;
        }
        let start = self.inner.next.fetch_add(1, Ordering::Relaxed) as usize;
        for i in 0..n {
            let sub = &mut subs[(start + i) % n];
            let got = sub.take(&self.inner.name, |h, v| (Meta::of(h), *v));
            if got.is_some() {
                return got;
            }
        }
        None
    }

    /// Hands every waiting sample, in place (zero copy), to `f`; returns how
    /// many. At most a port's buffer ([`SUBSCRIBER_BUFFER`]) per source:
    /// what arrives meanwhile is left for the next step (whose wake-up is
    /// already pending). Unbounded, a step that sends what it drains along
    /// an allowed loop back to itself never returned, and held the input,
    /// so that even `nerve ps` could not read its statistics.
    pub fn drain(&self, f: impl FnMut(&Meta, &T)) -> usize {
        self.drain_up_to(SUBSCRIBER_BUFFER, f)
    }

    /// Like [`Input::drain`], but takes at most `max` samples from each
    /// source: a sender that refills the port faster than `f` works cannot
    /// keep the caller in the loop for ever. What is left stays queued (and
    /// the oldest of it is overwritten, and counted, if the sender goes on).
    pub fn drain_up_to(&self, max: usize, mut f: impl FnMut(&Meta, &T)) -> usize {
        let done: Result<usize, std::convert::Infallible> = self.try_drain_up_to(max, |m, v| {
            f(m, v);
            Ok(())
        });
        match done {
            Ok(n) => n,
        }
    }

    /// Like [`Input::drain`], but `f` may fail: the first error ends the
    /// drain and is returned, so that a step can use `?` on what it does with
    /// each sample:
    ///
    /// ```ignore
    /// self.input.try_drain(|_, tick| self.out.send(*tick))?;
    /// ```
    ///
    /// The sample `f` failed on is consumed; those after it stay queued for
    /// the next step.
    pub fn try_drain<E>(&self, f: impl FnMut(&Meta, &T) -> Result<(), E>) -> Result<usize, E> {
        self.try_drain_up_to(SUBSCRIBER_BUFFER, f)
    }

    /// [`Input::try_drain`] with at most `max` samples from each source (see
    /// [`Input::drain_up_to`]).
    pub fn try_drain_up_to<E>(&self, max: usize, mut f: impl FnMut(&Meta, &T) -> Result<(), E>) -> Result<usize, E> {
        let mut subs = self.subs();
        let mut count = 0;
        for sub in subs.iter_mut() {
            for _ in 0..max {
                match sub.take(&self.inner.name, |h, v| f(&Meta::of(h), v)) {
                    Some(done) => {
                        count += 1;
                        done?;
                    }
                    None => break,
                }
            }
        }
        Ok(count)
    }

    /// Drains every waiting sample and returns the newest (by stamp).
    pub fn latest(&self) -> Option<(Meta, T)> {
        let mut best: Option<(Meta, T)> = None;
        self.drain(|m, v| {
            if best.as_ref().is_none_or(|(b, _)| m.stamp_ns >= b.stamp_ns) {
                best = Some((*m, *v));
            }
        });
        best
    }

    /// How many sources feed this input now.
    pub fn sources(&self) -> usize {
        self.subs().len()
    }
}

pub(crate) fn lock<X>(m: &Mutex<X>) -> MutexGuard<'_, X> {
    // A panic in another thread aborts the process (`abort_on_panic`), so a
    // poisoned lock cannot be observed; recover the guard regardless.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// The type-erased side of an input, used by the message checker and the runtime.
pub(crate) trait DynInput: Send + Sync {
    fn name(&self) -> &str;
    fn type_name(&self) -> &str;
    /// The port's name, type name and layout fingerprint.
    fn spec(&self) -> shm_schemas::control::agent_to_router::PortSpec;
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
    /// For a test to find the typed input ([`InputInner::queue`]).
    fn as_any(&self) -> &dyn std::any::Any;
}

impl<T: Payload> InputInner<T> {
    /// Queues `value` from `sender`'s port `port` as a test's sample,
    /// stamped `stamp_ns`; the source is added at its first sample. Past
    /// [`SUBSCRIBER_BUFFER`] waiting samples the oldest is overwritten and
    /// counted as dropped, as with iceoryx2.
    pub(crate) fn queue(&self, sender: &str, port: &str, value: T, stamp_ns: u64) -> Result<(), PortError> {
        let mut subs = lock(&self.subs);
        let at = match subs.iter().position(|s| s.from_agent == sender && s.from_port == port) {
            Some(at) => at,
            None => {
                if subs.len() >= MAX_SOURCES {
                    return Err(PortError::TooManySources { input: self.name.clone(), max: MAX_SOURCES });
                }
                subs.push(Subscription {
                    from_agent: sender.into(),
                    from_port: port.into(),
                    source: Source::Memory { queue: VecDeque::new(), sent: 0 },
                    tally: Tally::default(),
                });
                subs.len() - 1
            }
        };
        let Source::Memory { queue, sent } = &mut subs[at].source else {
            return Err(perr(&self.name, format!("{sender}/{port} is an iceoryx2 source, not a test's")));
        };
        // numbered as a sender numbers its samples, so that an overwritten
        // one shows as a gap and is counted as dropped
        *sent = sent.saturating_add(1);
        let seq = *sent;
        if queue.len() >= SUBSCRIBER_BUFFER {
            queue.pop_front();
        }
        queue.push_back((SampleHeader { sender: FixedName::new(sender), seq, stamp_ns }, Box::new(value)));
        Ok(())
    }
}

impl<T: Payload> DynInput for InputInner<T> {
    fn name(&self) -> &str {
        &self.name
    }

    fn type_name(&self) -> &str {
        T::stable_type_name()
    }

    fn spec(&self) -> shm_schemas::control::agent_to_router::PortSpec {
        shm_schemas::control::agent_to_router::PortSpec::of::<T>(&self.name)
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
        let (ps, ev) = source_services::<T>(node, &service)?;
        // a killed reader's ports may hold the source's slots until the router's next sweep
        let (subscriber, listener) =
            crate::world::retry_after_cleanup(node.config(), "connect", PortError::blockable, || {
                let subscriber = ps
                    .subscriber_builder()
                    .buffer_size(SUBSCRIBER_BUFFER)
                    .create()
                    .map_err(port_err!(Subscriber, &service))?;
                let listener = ev.listener_builder().create().map_err(port_err!(Listener, &service))?;
                Ok((subscriber, listener))
            })?;
        lock(&self.subs).push(Subscription {
            from_agent: from_agent.into(),
            from_port: from_port.into(),
            source: Source::Shm { subscriber, listener: Arc::new(listener) },
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
            .filter_map(|s| match &s.source {
                Source::Shm { listener, .. } => Some(listener.clone()),
                Source::Memory { .. } => None,
            })
            .collect()
    }

    fn stats(&self, now: u64) -> Vec<InputStats> {
        lock(&self.subs).iter().map(|s| s.tally.stats(&self.name, &s.from_agent, &s.from_port, now)).collect()
    }

    fn has_queued(&self) -> bool {
        lock(&self.subs).iter().any(|s| matches!(&s.source, Source::Memory { queue, .. } if !queue.is_empty()))
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::{DynInput, Input, MAX_SOURCES, PortError, gap, port_event, port_service};
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::payloads::{Scalar, Tick};

    /// `Pose` as an old build defined it: the same name and size as the
    /// new one, the fields in another order (iceoryx2 alone cannot tell).
    mod old {
        #[derive(Debug, Clone, Copy, Default, serde::Serialize, shm_schemas::Payload)]
        #[payload(name = "test::Pose")]
        #[repr(C)]
        pub struct Pose {
            pub x: f64,
            pub y: f64,
        }
    }
    mod new {
        #[derive(Debug, Clone, Copy, Default, serde::Serialize, shm_schemas::Payload)]
        #[payload(name = "test::Pose")]
        #[repr(C)]
        pub struct Pose {
            pub y: f64,
            pub x: f64,
        }
    }

    #[test]
    fn a_port_carries_its_attributes_and_another_layout_of_its_type_is_refused() {
        use iceoryx2::service::port_factory::PortFactory as _;
        use shm_schemas::Payload as _;
        let world = World::new(&format!("layout{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let service = robot.port_service("arm", "pose");
        let out = port_service::<old::Pose>(&node, &service).expect("created");
        let _ev = port_event(&node, &service).expect("event");
        let attrs: Vec<String> = out.attributes().iter().map(|a| format!("{}={}", a.key(), a.value())).collect();
        let fp = old::Pose::layout_fingerprint();
        assert_ne!(fp, new::Pose::layout_fingerprint());
        for want in [
            "nerve.type=test::Pose".to_string(),
            format!("nerve.fingerprint={fp:#018x}"),
            "nerve.agent=arm".into(),
            "nerve.port=pose".into(),
        ] {
            assert!(attrs.contains(&want), "{want} in {attrs:?}");
        }
        assert_eq!(super::service_fingerprint(&out), Some(fp));
        // an input of the new build refuses the old port, saying both layouts
        let (_input, inner) = Input::<new::Pose>::new("in");
        match inner.connect(&node, &robot, "arm", "pose") {
            Err(e @ PortError::LayoutMismatch { .. }) => {
                let text = e.to_string();
                assert!(text.contains(&format!("{fp:#018x}")) && text.contains("rebuild the older one"), "{text}");
            }
            other => panic!("another layout of test::Pose: {:?}", other.err()),
        }
        // and so does a second publisher of the new build
        match port_service::<new::Pose>(&node, &service) {
            Err(PortError::LayoutMismatch { theirs, ours, .. }) => {
                assert_eq!((theirs, ours), (fp, new::Pose::layout_fingerprint()))
            }
            other => panic!("a publisher of another layout: {:?}", other.err()),
        }
        // the same build reads it
        let (_input, inner) = Input::<old::Pose>::new("in");
        assert!(inner.connect(&node, &robot, "arm", "pose").expect("same layout"));
    }

    #[test]
    fn a_port_error_says_which_operation_failed_and_keeps_iceoryx2s_cause() {
        let world = World::new(&format!("perr{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let service = format!("nerve/{}/a/out", world.robot());
        let _ticks = port_service::<Tick>(&node, &service).expect("created");
        match port_service::<Scalar>(&node, &service) {
            Err(PortError::IncompatibleType { service: s, type_name }) => {
                assert_eq!(s, service);
                assert_eq!(type_name, "nerve::Scalar");
            }
            other => panic!("another type on the same port: {:?}", other.err()),
        }
        // an operation's failure keeps iceoryx2's error as its source
        let e = PortError::Loan { service: service.clone(), source: iceoryx2::port::LoanError::OutOfMemory };
        let source = std::error::Error::source(&e).expect("a source");
        assert!(source.downcast_ref::<iceoryx2::port::LoanError>().is_some(), "{source:?}");
        assert!(e.to_string().contains("cannot loan a sample") && e.to_string().contains(&service), "{e}");
    }

    /// A Connect can come from anyone who opens the agent's control service
    /// (review R10): a source that does not exist is refused and leaves no
    /// file, and an input takes at most MAX_SOURCES sources.
    #[test]
    fn an_input_opens_existing_sources_only_and_at_most_max_sources() {
        let world = World::new(&format!("fanin{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let (input, inner) = Input::<Tick>::new("in");
        let files = |w: &World| {
            let mut f = w.shm_files();
            f.extend(w.iox2_files());
            f.sort();
            f
        };
        let before = files(&world);
        match inner.connect(&node, &robot, "ghost", "out") {
            Err(PortError::NoSuchPort { service }) => assert_eq!(service, robot.port_service("ghost", "out")),
            other => panic!("a source nobody has: {:?}", other.err()),
        }
        assert_eq!(files(&world), before, "refusing a source created files");
        assert_eq!(input.sources(), 0);

        let sources: Vec<_> = (0..=MAX_SOURCES)
            .map(|i| {
                let service = robot.port_service(&format!("a{i}"), "out");
                (port_service::<Tick>(&node, &service).expect("service"), port_event(&node, &service).expect("event"))
            })
            .collect();
        for i in 0..MAX_SOURCES {
            assert!(inner.connect(&node, &robot, &format!("a{i}"), "out").expect("an existing source"));
        }
        assert!(!inner.connect(&node, &robot, "a0", "out").expect("again"), "already read: nothing changes");
        match inner.connect(&node, &robot, &format!("a{MAX_SOURCES}"), "out") {
            Err(e @ PortError::TooManySources { .. }) => {
                assert!(e.to_string().contains(&format!("{MAX_SOURCES} sources")), "{e}")
            }
            other => panic!("source {} of one input: {:?}", MAX_SOURCES + 1, other.err()),
        }
        assert_eq!(input.sources(), MAX_SOURCES);
        drop(sources);
    }

    #[test]
    fn gaps_are_counted_without_overflow() {
        assert_eq!(gap(0, 5), 0, "the first sample starts the count");
        assert_eq!(gap(5, 6), 0);
        assert_eq!(gap(5, 9), 3);
        assert_eq!(gap(9, 2), 0, "a restarted sender counts again from its own start");
        assert_eq!(gap(u64::MAX, 1), 0, "a hostile u64::MAX does not overflow (review R9)");
        assert_eq!(gap(1, u64::MAX), u64::MAX - 2);
        assert_eq!(gap(u64::MAX - 1, u64::MAX), 0);
    }
}
