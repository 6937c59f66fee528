//! Reading an output port by its bytes, whatever type it carries.
//!
//! Tools (`nerve echo`, `nerve hz`, the recorder) must read ports whose
//! payload type they were not built with: an agent crate outside the
//! workspace with a type of its own. A [`RawPort`] learns the payload's size
//! and alignment from the service itself (iceoryx2 keeps them in the
//! service's static configuration, as its own `iox2` tool reads them) and
//! subscribes with them, zero copy like any input; the bytes are then
//! decoded through the port's [`shm_schemas::Schema`], which the agent
//! registered with the router. The service's attributes
//! ([`shm_schemas::services::port_attributes`]) say the type name and the
//! layout fingerprint.

use crate::ports::{PortError, SUBSCRIBER_BUFFER, port_attributes_of};
use crate::world::Ipc;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::service::attribute::{AttributeKey, AttributeSet};
use iceoryx2::service::builder::publish_subscribe::{PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError};
use iceoryx2::service::marker::{CustomHeaderMarker, CustomPayloadMarker};
use iceoryx2::service::static_config::message_type_details::{TypeDetail, TypeVariant};
use shm_schemas::services::port_attributes;
use shm_schemas::{FixedName, SampleHeader};

/// A subscription to an output port that hands out each sample's bytes.
pub struct RawPort {
    service: String,
    subscriber: Subscriber<Ipc, [CustomPayloadMarker], SampleHeader>,
    payload: TypeDetail,
    attributes: Vec<(String, String)>,
}

impl std::fmt::Debug for RawPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawPort").field("service", &self.service).field("attributes", &self.attributes).finish()
    }
}

fn attribute_list(set: &AttributeSet) -> Vec<(String, String)> {
    set.iter().map(|a| (a.key().to_string(), a.value().to_string())).collect()
}

impl RawPort {
    /// Subscribes to the existing output port `service`
    /// (`nerve/ROBOT/AGENT/PORT`); never creates it.
    pub fn open(node: &Node<Ipc>, service: &str) -> Result<RawPort, PortError> {
        let ipc = |detail: String| PortError::Ipc { service: service.into(), detail };
        let name: ServiceName = service.try_into().map_err(|e| ipc(format!("not a service name: {e:?}")))?;
        let details = <Ipc as iceoryx2::service::Service>::details(
            &name,
            node.config(),
            iceoryx2::service::messaging_pattern::MessagingPattern::PublishSubscribe,
        )
        .map_err(|e| ipc(format!("cannot read the service's details: {e:?}")))?
        .ok_or_else(|| PortError::NoSuchPort { service: service.into() })?;
        let types = details.static_details.publish_subscribe().message_type_details();
        let header = types.user_header;
        if header.size() != std::mem::size_of::<SampleHeader>() {
            return Err(ipc(format!(
                "its samples carry a {}-byte header, not nerve's {}-byte one: not a nerve port",
                header.size(),
                std::mem::size_of::<SampleHeader>()
            )));
        }
        let payload = types.payload;
        // the details are whatever the process that made the service wrote:
        // the same bounds as a schema's before they reach iceoryx2 again
        let align = payload.alignment();
        if !align.is_power_of_two()
            || align > shm_schemas::schema::MAX_ALIGN
            || payload.size() > shm_schemas::schema::MAX_SIZE
        {
            return Err(ipc(format!(
                "its payload is {} bytes aligned to {align}: not a layout nerve makes (align a power of two up to {}, \
                 at most {} bytes); the process that created the service is not a nerve agent",
                payload.size(),
                shm_schemas::schema::MAX_ALIGN,
                shm_schemas::schema::MAX_SIZE
            )));
        }
        // SAFETY: the payload's type details are the service's own, read
        // just above and bounded; the samples are handed out as bytes only
        // (`receive`), never as a typed value.
        let builder = unsafe {
            node.service_builder(&name)
                .publish_subscribe::<[CustomPayloadMarker]>()
                .user_header::<SampleHeader>()
                .__internal_set_payload_type_details(&payload)
        };
        let factory = builder.open().map_err(|source| match source {
            iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError::DoesNotExist => {
                PortError::NoSuchPort { service: service.into() }
            }
            source => PortError::OpenService { service: service.into(), source },
        })?;
        use iceoryx2::service::port_factory::PortFactory as _;
        let attributes = attribute_list(factory.attributes());
        let subscriber = factory
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .create()
            .map_err(|source| PortError::Subscriber { service: service.into(), source })?;
        Ok(RawPort { service: service.into(), subscriber, payload, attributes })
    }

    /// The service's name.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// The payload's size, bytes.
    pub fn payload_size(&self) -> usize {
        self.payload.size()
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
            let sample = self
                .subscriber
                .receive()
                .map_err(|e| PortError::Ipc { service: self.service.clone(), detail: format!("receive: {e:?}") })?;
            let Some(sample) = sample else { return Ok(n) };
            n += 1;
            let payload = sample.payload();
            // SAFETY: CustomPayloadMarker is a #[repr(C)] wrapper of one u8:
            // the slice is the sample's payload bytes, alive while `sample` is.
            let bytes = unsafe { std::slice::from_raw_parts(payload.as_ptr().cast::<u8>(), payload.len()) };
            if !f(sample.user_header(), bytes) {
                return Ok(n);
            }
        }
    }
}

/// An output port that publishes bytes laid out as a type this build does
/// not know (`nerve replay`): the service is made with the type's name,
/// size and alignment, the same settings and attributes as a typed
/// [`crate::Output`] of it, so the agents built with the type read it as
/// their own.
pub struct RawOutput {
    service: String,
    publisher: Publisher<Ipc, [CustomPayloadMarker], CustomHeaderMarker>,
    notifier: Notifier<Ipc>,
    sender: FixedName,
    size: usize,
    seq: u64,
}

impl std::fmt::Debug for RawOutput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawOutput").field("service", &self.service).field("size", &self.size).finish()
    }
}

impl RawOutput {
    /// Opens (or creates) output port `service` for samples of `schema`,
    /// whose layout fingerprint is `fingerprint`, sent as `sender`.
    pub fn create(
        node: &Node<Ipc>,
        service: &str,
        schema: &shm_schemas::Schema,
        fingerprint: u64,
        sender: &str,
    ) -> Result<RawOutput, PortError> {
        let ipc = |detail: String| PortError::Ipc { service: service.into(), detail };
        let name: ServiceName = service.try_into().map_err(|e| ipc(format!("not a service name: {e:?}")))?;
        let payload = crate::dynamic::payload_details(service, schema)?;
        // SAFETY: reading the name has no precondition
        let header_name = unsafe { <SampleHeader as ZeroCopySend>::type_name() };
        let header = TypeDetail::__internal_new_from_parts(
            TypeVariant::FixedSize,
            header_name,
            std::mem::size_of::<SampleHeader>(),
            std::mem::align_of::<SampleHeader>(),
        )
        .map_err(|e| ipc(format!("{e:?}")))?;
        // SAFETY: the payload's details are the schema's (the layout the
        // agents built with the type use, checked by the fingerprint in the
        // attributes), the header's are SampleHeader's; `send` writes
        // exactly a SampleHeader and `size` payload bytes.
        let builder = unsafe {
            node.service_builder(&name)
                .publish_subscribe::<[CustomPayloadMarker]>()
                .user_header::<CustomHeaderMarker>()
                .__internal_set_user_header_type_details(&header)
                .__internal_set_payload_type_details(&payload)
        };
        let verifier = port_attributes_of(service, &schema.type_name, fingerprint)?;
        let factory = crate::ports::port_settings!(builder).open_or_create_with_attributes(&verifier).map_err(
            |source| match source {
                PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                    PublishSubscribeOpenError::IncompatibleAttributes | PublishSubscribeOpenError::IncompatibleTypes,
                ) => ipc(format!(
                    "the port exists with another type or layout than the recorded {} ({}): stop the agent that owns it",
                    schema.type_name,
                    port_attributes::fingerprint_text(fingerprint)
                )),
                source => PortError::Service { service: service.into(), source },
            },
        )?;
        let publisher = factory
            .publisher_builder()
            .create()
            .map_err(|source| PortError::Publisher { service: service.into(), source })?;
        let notifier = crate::ports::port_event(node, service)?
            .notifier_builder()
            .create()
            .map_err(|source| PortError::Notifier { service: service.into(), source })?;
        Ok(RawOutput {
            service: service.into(),
            publisher,
            notifier,
            sender: FixedName::new(sender),
            size: schema.size,
            seq: 0,
        })
    }

    /// Publishes `bytes` (exactly the type's size) stamped now, and wakes the readers.
    pub fn send(&mut self, bytes: &[u8]) -> Result<(), PortError> {
        if bytes.len() != self.size {
            return Err(PortError::Ipc {
                service: self.service.clone(),
                detail: format!("a {}-byte sample for a {}-byte type", bytes.len(), self.size),
            });
        }
        let mut loan = self.loan(false)?;
        loan.bytes_mut().copy_from_slice(bytes);
        self.send_loan(loan)
    }

    /// Loans a sample of the type's size to write in place; its bytes are
    /// zero when `zeroed`, else what the slot last held.
    pub fn loan(&self, zeroed: bool) -> Result<Loan, PortError> {
        // SAFETY: one element of a FixedSize type: `size` bytes
        let mut sample = unsafe { self.publisher.loan_custom_payload(1) }
            .map_err(|source| PortError::Loan { service: self.service.clone(), source })?;
        let payload = sample.payload_mut();
        if payload.len() != self.size {
            return Err(PortError::Ipc {
                service: self.service.clone(),
                detail: format!("loaned {} bytes for a {}-byte sample", payload.len(), self.size),
            });
        }
        if zeroed {
            // SAFETY: `payload` is `size` one-byte elements, writable
            unsafe { std::ptr::write_bytes(payload.as_mut_ptr().cast::<u8>(), 0, payload.len()) };
        }
        // SAFETY: the payload lies in the service's shared memory, which is
        // zero when mapped and holds earlier samples' bytes after: every
        // byte is initialised (zeroed above, or as the slot was last
        // written), and any bytes are valid for a byte buffer.
        Ok(Loan(LoanInner::Shm(unsafe { sample.assume_init() })))
    }

    /// Sends a sample loaned by [`RawOutput::loan`], stamped now, and wakes the readers.
    pub fn send_loan(&mut self, loan: Loan) -> Result<(), PortError> {
        self.send_loan_counted(loan).map(|_| ())
    }

    /// [`RawOutput::send_loan`], returning how many readers the sample
    /// reached (0 before a new subscriber is seen: `nerve pub` sends again).
    pub fn send_loan_counted(&mut self, loan: Loan) -> Result<usize, PortError> {
        let LoanInner::Shm(mut sample) = loan.0 else {
            return Err(PortError::Ipc {
                service: self.service.clone(),
                detail: "the sample was not loaned from this port".into(),
            });
        };
        self.seq += 1;
        let header = SampleHeader { sender: self.sender, seq: self.seq, stamp_ns: crate::clock::now_ns() };
        // SAFETY: the service's user header is a SampleHeader (set in
        // `create`); the marker is a zero-sized stand-in at its address
        unsafe { (sample.user_header_mut() as *mut CustomHeaderMarker).cast::<SampleHeader>().write(header) };
        let reached = sample.send().map_err(|source| PortError::Send { service: self.service.clone(), source })?;
        self.notifier.notify().map_err(|source| PortError::Notify { service: self.service.clone(), source })?;
        Ok(reached)
    }
}

/// A sample loaned from an output port, written in place before it is sent.
pub struct Loan(LoanInner);

enum LoanInner {
    /// a slot of the port's shared memory
    Shm(SampleMut<Ipc, [CustomPayloadMarker], CustomHeaderMarker>),
    /// an agent being described sends nothing: bytes of its own
    Detached(Box<[u8]>),
}

impl std::fmt::Debug for Loan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Loan").field("len", &self.bytes().len()).finish()
    }
}

impl Loan {
    /// Zeroed bytes of no port, for an agent that is only described.
    pub(crate) fn detached(size: usize) -> Self {
        Loan(LoanInner::Detached(vec![0; size].into_boxed_slice()))
    }

    /// The payload's bytes.
    pub fn bytes(&self) -> &[u8] {
        match &self.0 {
            LoanInner::Shm(sample) => {
                let payload = sample.payload();
                // SAFETY: CustomPayloadMarker wraps one u8 (#[repr(C)]);
                // the bytes live as long as the sample
                unsafe { std::slice::from_raw_parts(payload.as_ptr().cast::<u8>(), payload.len()) }
            }
            LoanInner::Detached(b) => b,
        }
    }

    /// The payload's bytes, to write.
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        match &mut self.0 {
            LoanInner::Shm(sample) => {
                let payload = sample.payload_mut();
                // SAFETY: as in `bytes`, and the loan is the only writer
                unsafe { std::slice::from_raw_parts_mut(payload.as_mut_ptr().cast::<u8>(), payload.len()) }
            }
            LoanInner::Detached(b) => b,
        }
    }
}

/// The type name and layout fingerprint of the existing output port
/// `service`, from its attributes, without subscribing.
pub fn port_identity(node: &Node<Ipc>, service: &str) -> Option<(String, Option<u64>)> {
    let name: ServiceName = service.try_into().ok()?;
    let details = <Ipc as iceoryx2::service::Service>::details(
        &name,
        node.config(),
        iceoryx2::service::messaging_pattern::MessagingPattern::PublishSubscribe,
    )
    .ok()??;
    let attrs = details.static_details.attributes();
    let get = |key: &str| {
        let key = AttributeKey::try_from(key).ok()?;
        attrs.key_value(&key, 0).map(|v| v.to_string())
    };
    let type_name = get(port_attributes::TYPE)?;
    Some((type_name, get(port_attributes::FINGERPRINT).and_then(|t| port_attributes::parse_fingerprint(&t))))
}

#[cfg(test)]
mod tests {
    use super::{RawOutput, RawPort, port_identity};
    use crate::ports::{DynInput as _, Input, Output, PortError};
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
        let (input, inner) = Input::<Scalar>::new("in");
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
