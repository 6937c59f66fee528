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
//!
//! Its files: this one (the [`Binding`], a sample's [`Meta`], the bytes of
//! a payload in shared memory), `port::output` (the sending side),
//! `port::input` (the receiving side, and [`DynInput`], the runtime's view
//! of an input), `port::tally` (what an input counts per source) and
//! `port::raw` (the tools' ports); the items are re-exported here.

use super::memory::Bus;
use crate::world::Ipc;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::marker::CustomPayloadMarker;
use shm_schemas::{FixedName, SampleHeader};
use std::sync::Arc;

pub(crate) use super::input::{DynInput, InputInner};
pub use super::input::{Received, SchemaInput};
pub use super::output::{Loan, SchemaOutput};
pub use super::raw::{RawOutput, RawPort};
#[cfg(test)]
pub(crate) use super::tally::gap;

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
