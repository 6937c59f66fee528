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
fn shape_of<T: SeqPart, H: SeqPart>(service: &str) -> Result<(Schema, SeqShape), PortError> {
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
fn view<'a, T: SeqPart, H: SeqPart>(shape: &SeqShape, bytes: &'a [u8]) -> Option<(&'a H, &'a [T])> {
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
