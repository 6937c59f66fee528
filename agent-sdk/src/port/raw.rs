//! The tools' ports, for payloads of any type: [`RawPort`] reads an output
//! port's samples as bytes, learning their size from the service (`nerve
//! echo`, `hz`, the recorder), and [`RawOutput`] publishes bytes laid out
//! as a type this build may not know (`nerve replay`, `nerve pub`). Both
//! are the byte port (`port::bytes`) without an agent around it.

use super::bytes::{ByteSubscriber, payload_bytes};
use super::error::{PortError, perr, port_err};
use super::output::{Loan, SchemaOutput};
use super::service::{Carried, SUBSCRIBER_BUFFER, raw_source_service};
use crate::world::Ipc;
use iceoryx2::prelude::*;
use shm_schemas::services::port_attributes;
use shm_schemas::{SampleHeader, Schema};

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
