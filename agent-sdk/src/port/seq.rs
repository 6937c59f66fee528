//! Sequence ports: [`SeqOutput<T, H>`] and [`SeqInput<T, H>`], views of the
//! byte port (`port::bytes`) whose samples are a header `H` followed by any
//! number of `T` ([`shm_schemas::seq`]), written and read in place.
//!
//! ```ignore
//! // in `Agent::new`: at most 256 detections per sample
//! let dets = setup.output_seq::<Detection, DetectionsHeader>("dets", 256)?;
//! // in `step`: a sample of the length this step needs, written in shared memory
//! dets.send_with(found.len(), |header, items| {
//!     header.frame = frame;
//!     for (slot, d) in items.iter_mut().zip(&found) { *slot = *d; }
//! })?;
//! // a reader: the header and a slice of the sample's own length, zero copy
//! input.drain(|meta, header, items| println!("{} detections", items.len()));
//! ```
//!
//! A sample longer than any sent before grows the port's shared memory
//! (iceoryx2's power-of-two allocation strategy); its readers keep reading.
//! A sample longer than the declared maximum is refused
//! ([`PortError::TooLong`]) and nothing is sent.

use super::bytes::{Binding, InputInner, Meta, SchemaInput, SchemaOutput};
use super::error::PortError;
use super::service::{Carried, SUBSCRIBER_BUFFER};
use shm_schemas::{Described, SampleHeader, Schema, Seq, SeqPart, SeqShape};
use std::marker::PhantomData;
use std::mem::{align_of, size_of};
use std::sync::Arc;

/// The shape of `Seq<T, H>`'s samples, checked against the Rust types: the
/// schema must place the elements where `T`'s alignment puts them after `H`.
pub(crate) fn shape_of<T: SeqPart, H: SeqPart>(service: &str) -> Result<(Schema, SeqShape), PortError> {
    let schema = Seq::<T, H>::schema();
    let shape = schema
        .sequence_shape()
        .filter(|s| s.element == size_of::<T>() && s.items_at == size_of::<H>().next_multiple_of(align_of::<T>()));
    let Some(shape) = shape else {
        return Err(PortError::Ipc {
            service: service.into(),
            detail: format!(
                "the schema of {} does not describe the Rust types (element {} bytes, header {} bytes): derive \
                 them (`#[derive(Payload)]`) instead of writing their schemas by hand",
                schema.type_name,
                size_of::<T>(),
                size_of::<H>()
            ),
        });
    };
    Ok((schema, shape))
}

/// `bytes` read in place as a `Seq<T, H>` sample: its header and its
/// elements; `None` unless they are a header and whole elements, aligned.
pub(crate) fn view<'a, T: SeqPart, H: SeqPart>(shape: &SeqShape, bytes: &'a [u8]) -> Option<(&'a H, &'a [T])> {
    let n = shape.count_of(bytes.len())?;
    let at = bytes.as_ptr() as usize;
    if !at.is_multiple_of(align_of::<H>()) || !at.wrapping_add(shape.items_at).is_multiple_of(align_of::<T>()) {
        return None;
    }
    // SAFETY: the bytes hold a header (`items_at` >= size_of::<H>(), checked
    // in `shape_of`) then `n` whole elements of `size_of::<T>()` bytes
    // (`count_of`), both aligned (checked above); they are a sample of a
    // port of this sequence's type name and layout (the service's
    // fingerprint), and any bytes are a valid `H` and `T` (`AnyBitPattern`).
    unsafe {
        let header = &*bytes.as_ptr().cast::<H>();
        let items = std::slice::from_raw_parts(bytes.as_ptr().add(shape.items_at).cast::<T>(), n);
        Some((header, items))
    }
}

/// An output port of samples of header `H` and any number of `T`, up to
/// the maximum it was declared with.
pub struct SeqOutput<T: SeqPart, H: SeqPart = shm_schemas::NoHeader> {
    port: SchemaOutput,
    shape: SeqShape,
    _type: PhantomData<fn(T, H)>,
}

impl<T: SeqPart, H: SeqPart> std::fmt::Debug for SeqOutput<T, H> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SeqOutput")
            .field("service", &self.port.service())
            .field("type", &self.port.schema().type_name)
            .field("max_len", &self.port.max_len())
            .finish()
    }
}

impl<T: SeqPart, H: SeqPart> SeqOutput<T, H> {
    /// Output `port` (service `service`) of agent `sender`, bound to
    /// `binding`, taking samples of at most `max_len` elements.
    pub(crate) fn bind(
        binding: &Binding,
        port: &str,
        service: &str,
        sender: &str,
        max_len: usize,
    ) -> Result<Self, PortError> {
        let (schema, shape) = shape_of::<T, H>(service)?;
        let carried = Carried::of_schema(service, &schema, schema.fingerprint())?;
        let mut port = SchemaOutput::bind(binding, port, service, sender, schema, carried, false)?;
        port.set_max_len(max_len)?;
        Ok(SeqOutput { port, shape, _type: PhantomData })
    }

    /// An output in shared memory: service `service`, sent as `sender`.
    #[cfg(test)]
    pub(crate) fn create(
        node: &iceoryx2::prelude::Node<crate::world::Ipc>,
        service: &str,
        sender: &str,
        max_len: usize,
    ) -> Result<Self, PortError> {
        let (schema, shape) = shape_of::<T, H>(service)?;
        let carried = Carried::of_schema(service, &schema, schema.fingerprint())?;
        let mut port = SchemaOutput::shm(node, service, sender, schema, carried)?;
        port.set_max_len(max_len)?;
        Ok(SeqOutput { port, shape, _type: PhantomData })
    }

    /// The iceoryx2 service name of this port.
    pub fn service(&self) -> &str {
        self.port.service()
    }

    /// The most elements a sample may hold (as declared, and within the
    /// 64 MiB every payload is bounded to).
    pub fn max_len(&self) -> usize {
        self.port.max_len().unwrap_or(0)
    }

    /// Sends a sample of `n` elements written in place by `fill`: its
    /// header and its `n` elements, in shared memory, hold what the slot
    /// last held (any bytes are a valid `H` and `T`) until `fill` writes
    /// them. Refused, with nothing sent, past [`SeqOutput::max_len`].
    pub fn send_with(&self, n: usize, fill: impl FnOnce(&mut H, &mut [T])) -> Result<(), PortError> {
        let mut loan = self.port.loan_items(n)?;
        // stamped as it starts to be written, as a typed port's sample is
        let header = self.port.next_header();
        let bytes = loan.bytes_mut();
        let at = bytes.as_mut_ptr();
        if !(at as usize).is_multiple_of(self.shape.align) || bytes.len() != self.shape.len_of(n).unwrap_or(0) {
            return Err(PortError::Ipc {
                service: self.port.service().into(),
                detail: format!(
                    "a loan of {} bytes at {at:p} for {n} elements of {}",
                    bytes.len(),
                    self.port.schema().type_name
                ),
            });
        }
        // SAFETY: the loan is `items_at + n * size_of::<T>()` bytes aligned
        // for the sample (checked above), the header first and the
        // elements at `items_at` (aligned for `T`: `shape_of`); it is the
        // only reference to them until sent, and any bytes are a valid `H`
        // and `T` (`AnyBitPattern`), so handing them out unwritten is sound.
        unsafe {
            let items = std::slice::from_raw_parts_mut(at.add(self.shape.items_at).cast::<T>(), n);
            fill(&mut *at.cast::<H>(), items);
        }
        self.port.publish_as(loan, header).map(|_| ())
    }

    /// Sends `header` and a copy of `items` (written once, into shared memory).
    pub fn send(&self, header: &H, items: &[T]) -> Result<(), PortError> {
        self.send_with(items.len(), |h, slots| {
            *h = *header;
            slots.copy_from_slice(items);
        })
    }
}

/// An input port of samples of header `H` and any number of `T`, fed by
/// any number of [`SeqOutput`]s of that type.
pub struct SeqInput<T: SeqPart, H: SeqPart = shm_schemas::NoHeader> {
    port: SchemaInput,
    shape: SeqShape,
    _type: PhantomData<fn() -> (T, H)>,
}

impl<T: SeqPart, H: SeqPart> std::fmt::Debug for SeqInput<T, H> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SeqInput")
            .field("name", &self.inner().name())
            .field("type", &self.port.schema().type_name)
            .finish()
    }
}

impl<T: SeqPart, H: SeqPart> SeqInput<T, H> {
    /// Input `name` of `Seq<T, H>`, and its shared side for the message checker.
    pub(crate) fn new(name: &str) -> Result<(Self, Arc<InputInner>), PortError> {
        let (schema, shape) = shape_of::<T, H>(name)?;
        let carried = Carried::of_schema(name, &schema, schema.fingerprint())?;
        let (port, inner) = SchemaInput::with(name, schema, carried, false);
        Ok((SeqInput { port, shape, _type: PhantomData }, inner))
    }

    fn inner(&self) -> &InputInner {
        self.port.inner()
    }

    /// Hands `bytes` to `f` as a header and elements; a sample that is not
    /// a header and whole elements is logged and passed over.
    fn typed<R>(&self, h: &SampleHeader, bytes: &[u8], f: impl FnOnce(&Meta, &H, &[T]) -> R) -> Option<R> {
        match view::<T, H>(&self.shape, bytes) {
            Some((header, items)) => Some(f(&Meta::of(h), header, items)),
            None => {
                tracing::warn!(input = %self.inner().name(), len = bytes.len(), "a sample that is not a whole {}", self.port.schema().type_name);
                None
            }
        }
    }

    /// Hands every waiting sample, in place (zero copy: the header and a
    /// slice of the sample's own length in shared memory), to `f`; returns
    /// how many. At most a port's buffer ([`SUBSCRIBER_BUFFER`]) per source.
    pub fn drain(&self, mut f: impl FnMut(&Meta, &H, &[T])) -> usize {
        let done: Result<usize, std::convert::Infallible> = self.inner().visit_up_to(SUBSCRIBER_BUFFER, |h, b| {
            self.typed(h, b, &mut f);
            Ok(())
        });
        match done {
            Ok(n) => n,
        }
    }

    /// Like [`SeqInput::drain`], but `f` may fail: the first error ends the
    /// drain and is returned (the sample it failed on is consumed).
    pub fn try_drain<E>(&self, mut f: impl FnMut(&Meta, &H, &[T]) -> Result<(), E>) -> Result<usize, E> {
        self.inner().visit_up_to(SUBSCRIBER_BUFFER, |h, b| self.typed(h, b, &mut f).unwrap_or(Ok(())))
    }

    /// Takes the next sample from any source, copied out: its header and
    /// its elements as a `Vec` (for a reader that keeps it past the step).
    pub fn recv(&self) -> Option<(Meta, H, Vec<T>)> {
        self.inner().next_with(|h, b| self.typed(h, b, |m, header, items| (*m, *header, items.to_vec()))).flatten()
    }

    /// How many sources feed this input now.
    pub fn sources(&self) -> usize {
        self.port.sources()
    }
}

#[cfg(test)]
mod tests {
    use super::{SeqInput, SeqOutput};
    use crate::port::PortError;
    use crate::port::bytes::{DynInput as _, RawPort};
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::payloads::Tick;
    use shm_schemas::{Described as _, Seq};

    #[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, shm_schemas::Payload)]
    #[repr(C)]
    #[payload(name = "test::Detection")]
    struct Detection {
        x: f32,
        y: f32,
        id: u32,
    }

    fn det(i: usize) -> Detection {
        Detection { x: i as f32, y: -(i as f32), id: i as u32 }
    }

    /// Lengths 0 and 1, then one longer than the publisher's memory holds
    /// (it grows), then the largest seen plus one: every one read in place
    /// at its own length by a reader subscribed before the growth; past the
    /// declared maximum, refused and nothing sent (the reader's next sample
    /// is the next one sent, numbered without a gap).
    #[test]
    fn sequences_of_any_length_up_to_the_maximum_are_read_at_their_length() {
        let world = World::new(&format!("seq{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let service = robot.port_service("cam", "dets");
        let max = 2000;
        let out = SeqOutput::<Detection, Tick>::create(&node, &service, "cam", max).expect("output");
        assert_eq!(out.max_len(), max);
        let (input, inner) = SeqInput::<Detection, Tick>::new("dets").expect("input");
        assert!(inner.connect(&node, &robot, "cam", "dets").expect("subscribes"));
        // 1000 detections are 12 kB: more than the 4 kB the publisher starts with
        let lens = [0usize, 1, 1000, 1001, max];
        for (k, n) in lens.iter().enumerate() {
            let items: Vec<Detection> = (0..*n).map(det).collect();
            out.send(&Tick { seq: k as u64, stamp_ns: 7 }, &items).expect("send");
            let mut got = Vec::new();
            input.drain(|meta, header, items| {
                got.push((meta.seq, *header, items.len(), items.first().copied(), items.last().copied()));
            });
            assert_eq!(
                got,
                vec![(
                    k as u64 + 1,
                    Tick { seq: k as u64, stamp_ns: 7 },
                    *n,
                    items.first().copied(),
                    items.last().copied()
                )],
                "length {n}"
            );
        }
        // past the maximum: refused, nothing loaned or sent
        match out.send_with(max + 1, |_, _| panic!("never written")) {
            Err(e @ PortError::TooLong { .. }) => {
                let text = e.to_string();
                assert!(text.contains(&format!("{} elements", max + 1)) && text.contains(&max.to_string()), "{text}");
            }
            other => panic!("{} elements sent: {other:?}", max + 1),
        }
        assert_eq!(input.drain(|_, _, _| {}), 0, "nothing sent");
        out.send_with(2, |h, items| {
            *h = Tick { seq: 99, stamp_ns: 1 };
            items.copy_from_slice(&[det(5), det(6)]);
        })
        .expect("send in place");
        let (meta, header, items) = input.recv().expect("a sample");
        assert_eq!((meta.seq, header.seq, items), (lens.len() as u64 + 1, 99, vec![det(5), det(6)]));
    }

    /// A tool reads a sequence port by its bytes (`nerve echo`): the
    /// sample's bytes are its own length, decoded through the schema; a
    /// reader of another element type is refused, and so is a string of
    /// any length read as detections.
    #[test]
    fn a_sequence_port_is_read_by_its_bytes_and_another_element_is_refused() {
        let world = World::new(&format!("seqraw{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let service = robot.port_service("log", "line");
        let text = SeqOutput::<u8>::create(&node, &service, "log", 1 << 16).expect("output");
        let raw = RawPort::open(&node, &service).expect("raw");
        assert_eq!(raw.type_name(), Some("nerve::Seq<u8, nerve::NoHeader>"));
        assert_eq!(raw.fingerprint(), Some(Seq::<u8>::schema().fingerprint()));
        for line in ["", "a", "a longer line of text"] {
            text.send(&shm_schemas::NoHeader, line.as_bytes()).expect("send");
        }
        let mut got = Vec::new();
        raw.receive(|_, bytes| {
            got.push(String::from_utf8_lossy(bytes).into_owned());
            true
        })
        .expect("receive");
        assert_eq!(got, ["", "a", "a longer line of text"]);
        let (_, wrong) = SeqInput::<Detection>::new("in").expect("input");
        match wrong.connect(&node, &robot, "log", "line") {
            Err(PortError::IncompatibleType { .. } | PortError::LayoutMismatch { .. }) => {}
            other => panic!("detections read from a string: {other:?}"),
        }
        // `nerve replay` and `nerve pub` publish a sequence's bytes by its schema, at their length
        let schema = Seq::<Detection, Tick>::schema();
        let replayed = robot.port_service("rec", "dets");
        let mut raw = crate::port::RawOutput::create(&node, &replayed, &schema, schema.fingerprint(), "rec")
            .expect("a sequence port by schema");
        let (dets, inner) = SeqInput::<Detection, Tick>::new("dets").expect("input");
        assert!(inner.connect(&node, &robot, "rec", "dets").expect("a typed reader opens it"));
        let tick = Tick { seq: 3, stamp_ns: 4 };
        // SAFETY: the bytes of a Copy #[repr(C)] value without padding (16 bytes)
        let mut sample = unsafe { std::slice::from_raw_parts((&tick as *const Tick).cast::<u8>(), 16) }.to_vec();
        for i in 0..2 {
            let d = det(i);
            // SAFETY: the bytes of a Copy #[repr(C)] value without padding (12 bytes)
            sample.extend_from_slice(unsafe { std::slice::from_raw_parts((&d as *const Detection).cast::<u8>(), 12) });
        }
        raw.send(&sample).expect("send");
        assert!(raw.send(&sample[..17]).is_err(), "not a header and whole elements");
        let (_, header, items) = dets.recv().expect("a sample");
        assert_eq!((header.seq, items), (3, vec![det(0), det(1)]));
        assert!(dets.recv().is_none(), "the malformed one was never sent");
        let (_, fixed) = crate::port::Input::<Tick>::new("in").expect("input");
        assert!(fixed.connect(&node, &robot, "log", "line").is_err(), "a fixed type read from a sequence");
    }
}
