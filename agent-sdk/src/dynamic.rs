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
use shm_schemas::{SampleHeader, Schema};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

pub use crate::raw_port::Loan;

/// The iceoryx2 type details of a payload laid out as `schema`.
pub(crate) fn payload_details(service: &str, schema: &Schema) -> Result<TypeDetail, PortError> {
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
pub struct Received {
    sample: Sample<Ipc, [CustomPayloadMarker], SampleHeader>,
}

impl std::fmt::Debug for Received {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Received").field("meta", &self.meta()).field("len", &self.bytes().len()).finish()
    }
}

impl Received {
    /// Who sent it, its number and stamp.
    pub fn meta(&self) -> Meta {
        Meta::of(self.sample.user_header())
    }

    /// The payload's bytes, as the sender wrote them (the schema's layout).
    pub fn bytes(&self) -> &[u8] {
        let payload = self.sample.payload();
        // SAFETY: CustomPayloadMarker is a #[repr(C)] wrapper of one u8: the
        // slice is the sample's payload bytes, alive while the sample is.
        unsafe { std::slice::from_raw_parts(payload.as_ptr().cast::<u8>(), payload.len()) }
    }
}

/// One source of a [`SchemaInput`].
struct Source {
    from_agent: String,
    from_port: String,
    subscriber: Subscriber<Ipc, [CustomPayloadMarker], SampleHeader>,
    listener: Arc<Listener<Ipc>>,
    tally: Tally,
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
            let src = &mut subs[(start + i) % n];
            let sample = src.subscriber.receive().map_err(|e| PortError::Ipc {
                service: format!("{}/{}", src.from_agent, src.from_port),
                detail: format!(
                    "input {:?} cannot take another sample ({e:?}): drop the ones held, or keep copies",
                    self.inner.name
                ),
            })?;
            if let Some(sample) = sample {
                src.tally.account(sample.user_header(), now_ns());
                return Ok(Some(Received { sample }));
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
        let subscriber = self.open(node, &service)?;
        let listener = source_event(node, &service)?
            .listener_builder()
            .create()
            .map_err(|source| PortError::Listener { service: service.clone(), source })?;
        lock(&self.subs).push(Source {
            from_agent: from_agent.into(),
            from_port: from_port.into(),
            subscriber,
            listener: Arc::new(listener),
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
        lock(&self.subs).iter().map(|s| s.listener.clone()).collect()
    }

    fn stats(&self, now: u64) -> Vec<InputStats> {
        lock(&self.subs).iter().map(|s| s.tally.stats(&self.name, &s.from_agent, &s.from_port, now)).collect()
    }

    fn has_queued(&self) -> bool {
        false
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
    /// the iceoryx2 port; none while the agent is described (`--describe`)
    raw: Option<RawOutput>,
}

impl SchemaOutput {
    pub(crate) fn create(node: &Node<Ipc>, service: &str, schema: Schema, sender: &str) -> Result<Self, PortError> {
        let raw = RawOutput::create(node, service, &schema, schema.fingerprint(), sender)?;
        Ok(SchemaOutput { service: service.into(), schema, raw: Some(raw) })
    }

    pub(crate) fn unbound(service: &str, schema: Schema) -> Self {
        SchemaOutput { service: service.into(), schema, raw: None }
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
        match &self.raw {
            Some(raw) => raw.loan(zeroed),
            None => Ok(Loan::detached(self.schema.size)),
        }
    }

    /// Sends a loaned sample, stamped now, and wakes the readers.
    pub fn send(&mut self, loan: Loan) -> Result<(), PortError> {
        match &mut self.raw {
            Some(raw) => raw.send_loan(loan),
            None => Ok(()),
        }
    }

    /// Sends `bytes` (exactly the layout's size), copied into a loaned sample.
    pub fn send_bytes(&mut self, bytes: &[u8]) -> Result<(), PortError> {
        match &mut self.raw {
            Some(raw) => raw.send(bytes),
            None => Ok(()),
        }
    }
}
