//! The payload types a bridge can carry, and the typed ports behind them.
//!
//! A bridge declares its ports at run time from its configuration, but nerve
//! ports are typed. A [`Types`] table maps a stable type name to the code
//! that declares an input or output of that type and moves its bytes. The
//! `nerve-bridge` program carries every built-in payload
//! ([`Types::builtin`]); a team with payloads of its own builds its own
//! bridge in one line: `nerve_bridge::main_with(Types::builtin().with::<MyType>())`.
//!
//! Bytes cross as the payload's in-memory representation. That is sound
//! because a carried type must be [`AnyBitPattern`] (every carrier here is
//! bound by it, so a type that is not cannot be carried): any bytes of its
//! size are a valid value, and it has no padding, so all its bytes are
//! initialised. `#[derive(Payload)]` implements it after checking both for
//! every field (no `bool`, `char` or enum; enums travel as integer codes,
//! names as length-clamped byte arrays). A `Payload` implemented by hand
//! without it is refused at compile time:
//!
//! ```compile_fail,E0277
//! use nerve_bridge::types::Types;
//! // a payload whose bytes are not all valid values: `bool`
//! #[repr(C)]
//! #[derive(Debug, Clone, Copy, Default, serde::Serialize)]
//! struct Grip { closed: bool }
//! // SAFETY: repr(C), a bool is ZeroCopySend (the point: not AnyBitPattern)
//! unsafe impl iceoryx2::prelude::ZeroCopySend for Grip {}
//! impl shm_schemas::schema::Described for Grip {
//!     fn schema() -> shm_schemas::schema::Schema { unimplemented!() }
//! }
//! impl shm_schemas::Payload for Grip {}
//! let _ = Types::default().with::<Grip>(); // error: Grip is not AnyBitPattern
//! ```
//!
//! The same type with a `u8` flag, whose bytes are all values, is carried;
//! `#[derive(Payload)]` gives it its schema and the `AnyBitPattern` promise:
//!
//! ```
//! use nerve_bridge::types::Types;
//! use shm_schemas::Payload;
//! #[derive(Debug, Clone, Copy, Default, Payload, serde::Serialize)]
//! #[repr(C)]
//! #[payload(name = "lab::Grip")]
//! struct Grip { closed: u8 }
//! let _ = Types::default().with::<Grip>();
//! ```
//!
//! The receiver also checks the type name, size and layout fingerprint
//! before it writes a byte.

use agent_sdk::port::{SchemaInput, SchemaOutput};
use agent_sdk::{AgentError, Input, Output, PortError, Setup};
use shm_schemas::schema::{AnyBitPattern, MAX_SIZE};
use shm_schemas::{Described, NoHeader, Payload, Schema, SeqShape, for_each_payload};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

/// What identifies a payload's layout across builds, and the lengths a
/// topic of it carries.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TypeInfo {
    /// the stable type name
    pub name: String,
    /// size in bytes; of a sequence, its header's (where the elements start)
    pub size: usize,
    /// [`Payload::layout_fingerprint`]
    pub fingerprint: u64,
    /// a sequence's shape and the most elements this topic carries
    pub seq: Option<SeqLimit>,
}

/// A sequence topic's shape and bound (`max_len` in the bridge's config).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeqLimit {
    /// where its header and elements lie
    pub shape: SeqShape,
    /// the most elements a sample on this topic may hold
    pub max_len: usize,
}

/// Why bytes are not a sample a topic carries.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LenError {
    /// A fixed-size payload of another size.
    #[error("{len} bytes where the type takes {size}")]
    Size {
        /// the bytes given
        len: usize,
        /// the type's size
        size: usize,
    },
    /// Not a sequence's header and a whole number of elements.
    #[error("{len} bytes are not a {header}-byte header and whole {element}-byte elements")]
    NotWhole {
        /// the bytes given
        len: usize,
        /// the header's bytes (where the elements start)
        header: usize,
        /// one element's bytes
        element: usize,
    },
    /// More elements than the topic's `max_len`.
    #[error("{len} elements, more than the {max_len} this bridge carries on the topic (raise `max_len` in its entry)")]
    TooLong {
        /// the sample's elements
        len: usize,
        /// the topic's bound
        max_len: usize,
    },
}

impl TypeInfo {
    /// The largest sample of this topic, in bytes: a fixed type's size, a
    /// sequence's header and `max_len` elements.
    pub fn max_payload(&self) -> usize {
        match self.seq {
            None => self.size,
            Some(l) => l.shape.len_of(l.max_len).unwrap_or(MAX_SIZE),
        }
    }

    /// Whether `len` bytes are a whole sample this topic carries.
    pub fn check_len(&self, len: usize) -> Result<(), LenError> {
        match self.seq {
            None if len == self.size => Ok(()),
            None => Err(LenError::Size { len, size: self.size }),
            Some(l) => match l.shape.count_of(len) {
                None => Err(LenError::NotWhole { len, header: l.shape.items_at, element: l.shape.element }),
                Some(n) if n > l.max_len => Err(LenError::TooLong { len: n, max_len: l.max_len }),
                Some(_) => Ok(()),
            },
        }
    }

    /// The layout of `schema`; a sequence's bound at most `max_len`
    /// elements and the 64 MiB every sample is bounded to.
    fn of(schema: &Schema, max_len: usize) -> Self {
        let seq = schema
            .sequence_shape()
            .map(|shape| SeqLimit { shape, max_len: max_len.min(shape.count_of_at_most(MAX_SIZE)) });
        TypeInfo { name: schema.type_name.clone(), size: schema.size, fingerprint: schema.fingerprint(), seq }
    }
}

/// A sample read from an export input: who sent it, its number, its bytes.
pub trait ExportTap: Send + Sync {
    /// Hands waiting samples to `f` as (sender agent, its sequence number,
    /// bytes), at most [`DRAIN_BATCH`] per source and call.
    fn drain(&self, f: &mut dyn FnMut(&str, u64, &[u8])) -> usize;
}

/// An import's output port: publishes bytes already checked to be a `T`.
pub trait ImportSink: Send + Sync {
    /// Publishes `bytes` (a whole sample of the type) as one sample.
    fn publish(&self, bytes: &[u8]) -> Result<(), PortError>;
}

/// Samples taken from one source per call of [`ExportTap::drain`]: the
/// subscription's whole buffer, so nothing is missed between two calls, and
/// a sender faster than the link cannot keep the bridge in the loop.
pub const DRAIN_BATCH: usize = agent_sdk::ports::SUBSCRIBER_BUFFER;

type DeclareExport = fn(&mut Setup, &str) -> Result<Box<dyn ExportTap>, AgentError>;
type DeclareImport = fn(&mut Setup, &str) -> Result<Arc<dyn ImportSink>, AgentError>;

/// How a carrier declares its ports.
#[derive(Clone)]
enum Ports {
    /// a Rust payload type's typed ports
    Typed { export: DeclareExport, import: DeclareImport },
    /// a sequence's ports, by its schema (any length, up to the topic's bound)
    Sequence(Schema),
}

/// How one payload type is carried.
#[derive(Clone)]
pub struct Carrier {
    /// its layout
    pub info: TypeInfo,
    ports: Ports,
}

impl std::fmt::Debug for Carrier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Carrier").field("info", &self.info).finish()
    }
}

impl Carrier {
    /// Declares the bridge's input `port` of this type.
    pub fn export(&self, setup: &mut Setup, port: &str) -> Result<Box<dyn ExportTap>, AgentError> {
        match &self.ports {
            Ports::Typed { export, .. } => export(setup, port),
            Ports::Sequence(schema) => Ok(Box::new(SeqTap(setup.input_of(port, schema.clone())?))),
        }
    }

    /// Declares the bridge's output `port` of this type.
    pub fn import(&self, setup: &mut Setup, port: &str) -> Result<Arc<dyn ImportSink>, AgentError> {
        match &self.ports {
            Ports::Typed { import, .. } => import(setup, port),
            Ports::Sequence(schema) => {
                let out = setup.output_of(port, schema.clone())?;
                Ok(Arc::new(SeqSink { info: self.info.clone(), out: Mutex::new(out) }))
            }
        }
    }
}

/// The payload types a bridge carries, by stable type name.
#[derive(Debug, Clone, Default)]
pub struct Types {
    by_name: BTreeMap<&'static str, Carrier>,
    /// what a sequence's header or element may be: the carried types, and
    /// numbers (`nerve::Seq<u8, nerve::NoHeader>` is a string)
    parts: BTreeMap<String, fn() -> Schema>,
}

impl Types {
    /// Every payload type built into nerve (`shm_schemas::for_each_payload!`),
    /// and every sequence of them.
    pub fn builtin() -> Self {
        let mut t = Types::default();
        macro_rules! add {
            ($ty:ty) => {
                t = t.with::<$ty>();
            };
        }
        for_each_payload!(add);
        t
    }

    /// Adds a payload type of the caller's. It must be [`AnyBitPattern`]
    /// (which `#[derive(Payload)]` gives): the bridge fills it with a peer's
    /// bytes and sends its bytes as they are in memory. Sequences of it
    /// (`nerve::Seq<T, H>` of it and any carried type, number or
    /// `nerve::NoHeader`) are carried too.
    pub fn with<T: Payload + AnyBitPattern>(mut self) -> Self {
        let c = carrier::<T>();
        self.parts.insert(c.info.name.clone(), <T as Described>::schema);
        self.by_name.insert(T::stable_type_name(), c);
        self
    }

    /// The carrier of a type name (a sequence's bound at
    /// [`crate::config::DEFAULT_MAX_LEN`]).
    pub fn get(&self, name: &str) -> Option<Carrier> {
        self.carrier(name, None)
    }

    /// The carrier of a type name; a sequence's topics carry at most
    /// `max_len` elements a sample (`None`: [`crate::config::DEFAULT_MAX_LEN`]).
    pub fn carrier(&self, name: &str, max_len: Option<usize>) -> Option<Carrier> {
        if let Some(c) = self.by_name.get(name) {
            return Some(c.clone());
        }
        let schema = self.sequence(name)?;
        let info = TypeInfo::of(&schema, max_len.unwrap_or(crate::config::DEFAULT_MAX_LEN));
        Some(Carrier { info, ports: Ports::Sequence(schema) })
    }

    /// Whether this bridge carries `name`.
    pub fn knows(&self, name: &str) -> bool {
        self.by_name.contains_key(name) || self.sequence(name).is_some()
    }

    /// The schema of sequence `name` (`nerve::Seq<ELEMENT, HEADER>`) if
    /// both of its parts are carried types, numbers or `nerve::NoHeader`.
    fn sequence(&self, name: &str) -> Option<Schema> {
        let inner = name.strip_prefix(crate::config::SEQ_PREFIX)?.strip_suffix('>')?;
        // a part's name may hold ", " itself: try each place the two may meet
        inner.match_indices(", ").find_map(|(at, sep)| {
            let element = self.part(&inner[..at])?;
            let header = self.part(&inner[at + sep.len()..])?;
            let schema = Schema::sequence(header, element);
            (schema.type_name == name && schema.validate().is_ok()).then_some(schema)
        })
    }

    fn part(&self, name: &str) -> Option<Schema> {
        macro_rules! number {
            ($($t:ty),*) => {
                match name {
                    $(stringify!($t) => return Some(<$t as Described>::schema()),)*
                    _ => {}
                }
            };
        }
        // no `bool`: not every byte is one
        number!(u8, u16, u32, u64, i8, i16, i32, i64, f32, f64);
        if name == "nerve::NoHeader" {
            return Some(NoHeader::schema());
        }
        self.parts.get(name).map(|schema| schema())
    }
}

fn carrier<T: Payload + AnyBitPattern>() -> Carrier {
    Carrier {
        info: TypeInfo::of(&<T as Described>::schema(), 0),
        ports: Ports::Typed {
            export: |setup, port| Ok(Box::new(Tap::<T>(setup.input::<T>(port)?))),
            import: |setup, port| Ok(Arc::new(Sink::<T>(setup.output::<T>(port)?))),
        },
    }
}

struct Tap<T: Payload + AnyBitPattern>(Input<T>);

impl<T: Payload + AnyBitPattern> ExportTap for Tap<T> {
    fn drain(&self, f: &mut dyn FnMut(&str, u64, &[u8])) -> usize {
        self.0.drain_up_to(DRAIN_BATCH, |meta, value| {
            // SAFETY: `value` is a valid `T` for the duration of the call, so
            // its size_of::<T>() bytes are readable; `T: AnyBitPattern` has no
            // padding, so every one of them is initialised.
            let bytes =
                unsafe { std::slice::from_raw_parts((value as *const T).cast::<u8>(), std::mem::size_of::<T>()) };
            f(meta.sender.as_str(), meta.seq, bytes)
        })
    }
}

struct Sink<T: Payload + AnyBitPattern>(Output<T>);

impl<T: Payload + AnyBitPattern> ImportSink for Sink<T> {
    fn publish(&self, bytes: &[u8]) -> Result<(), PortError> {
        if bytes.len() != std::mem::size_of::<T>() {
            return Err(PortError::Ipc {
                service: self.0.service().into(),
                detail: format!(
                    "{} bytes where {} takes {}",
                    bytes.len(),
                    T::stable_type_name(),
                    std::mem::size_of::<T>()
                ),
            });
        }
        // SAFETY: `bytes` is exactly size_of::<T>() long (checked above) and
        // is copied over the whole loaned sample, so every byte is written;
        // `T: AnyBitPattern` makes whatever bytes the peer sent a valid `T`.
        unsafe {
            self.0.send_uninit(|slot| {
                std::ptr::copy_nonoverlapping(bytes.as_ptr(), slot.as_mut_ptr().cast::<u8>(), bytes.len());
            })
        }
    }
}

/// An export of a sequence: each sample's bytes at its own length.
struct SeqTap(SchemaInput);

impl ExportTap for SeqTap {
    fn drain(&self, f: &mut dyn FnMut(&str, u64, &[u8])) -> usize {
        self.0.drain(|meta, bytes| f(meta.sender.as_str(), meta.seq, bytes))
    }
}

/// An import of a sequence: a sample loaned at the frame's length, never
/// past the topic's `max_len`.
struct SeqSink {
    info: TypeInfo,
    out: Mutex<SchemaOutput>,
}

impl ImportSink for SeqSink {
    fn publish(&self, bytes: &[u8]) -> Result<(), PortError> {
        let mut out = self.out.lock().unwrap_or_else(|p| p.into_inner());
        if let Err(e) = self.info.check_len(bytes.len()) {
            return Err(PortError::Ipc { service: out.service().into(), detail: e.to_string() });
        }
        out.send_bytes(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_payload_is_carried() {
        let t = Types::builtin();
        for name in shm_schemas::payloads::known_type_names() {
            let c = t.get(name).expect("carried");
            assert_eq!(c.info.name, name);
            assert_eq!(c.info.seq, None, "a fixed type");
        }
        let tick = t.get("nerve::Tick").expect("tick");
        assert_eq!(
            (tick.info.size, tick.info.fingerprint),
            (16, <shm_schemas::payloads::Tick as shm_schemas::Described>::schema().fingerprint())
        );
        assert!(!t.knows("nerve::Nothing"));
    }

    /// A sequence of carried parts is carried by its name, bounded by the
    /// entry's `max_len`, and its schema is the one a Rust agent's port has.
    #[test]
    fn sequences_of_carried_parts_are_carried() {
        use shm_schemas::payloads::{MapCell, MapHeader};
        let t = Types::builtin();
        let name = "nerve::Seq<nerve::MapCell, nerve::MapHeader>";
        let c = t.carrier(name, Some(10)).expect("carried");
        let schema = shm_schemas::Seq::<MapCell, MapHeader>::schema();
        assert_eq!((c.info.name.as_str(), c.info.fingerprint), (name, schema.fingerprint()));
        let shape = schema.sequence_shape().expect("a sequence");
        assert_eq!(c.info.seq.map(|l| (l.shape, l.max_len)), Some((shape, 10)));
        assert_eq!(c.info.max_payload(), shape.items_at + 10 * shape.element);
        assert_eq!(c.info.check_len(shape.items_at), Ok(()), "no element");
        assert!(matches!(
            c.info.check_len(shape.items_at + 11 * shape.element),
            Err(LenError::TooLong { len: 11, .. })
        ));
        assert!(matches!(c.info.check_len(shape.items_at + 1), Err(LenError::NotWhole { .. })));
        let default = t.get(name).expect("carried").info.seq.map(|l| l.max_len);
        assert_eq!(default, Some(crate::config::DEFAULT_MAX_LEN));
        assert!(t.knows("nerve::Seq<u8, nerve::NoHeader>"), "a string");
        assert!(!t.knows("nerve::Seq<bool, nerve::NoHeader>"), "not every byte is a bool");
        assert!(!t.knows("nerve::Seq<nerve::Nothing, nerve::Tick>"));
        assert!(!t.knows("nerve::Seq<nerve::Tick>"));
    }
}
