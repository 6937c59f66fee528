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

use agent_sdk::{AgentError, Input, Output, PortError, Setup};
use shm_schemas::schema::AnyBitPattern;
use shm_schemas::{Payload, for_each_payload};
use std::collections::BTreeMap;
use std::sync::Arc;

/// What identifies a payload's layout across builds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TypeInfo {
    /// the stable type name
    pub name: &'static str,
    /// size in bytes
    pub size: usize,
    /// [`Payload::layout_fingerprint`]
    pub fingerprint: u64,
}

/// A sample read from an export input: who sent it, its number, its bytes.
pub trait ExportTap: Send + Sync {
    /// Hands waiting samples to `f` as (sender agent, its sequence number,
    /// bytes), at most [`DRAIN_BATCH`] per source and call.
    fn drain(&self, f: &mut dyn FnMut(&str, u64, &[u8])) -> usize;
}

/// An import's output port: publishes bytes already checked to be a `T`.
pub trait ImportSink: Send + Sync {
    /// Publishes `bytes` (exactly the type's size) as one sample.
    fn publish(&self, bytes: &[u8]) -> Result<(), PortError>;
}

/// Samples taken from one source per call of [`ExportTap::drain`]: the
/// subscription's whole buffer, so nothing is missed between two calls, and
/// a sender faster than the link cannot keep the bridge in the loop.
pub const DRAIN_BATCH: usize = agent_sdk::ports::SUBSCRIBER_BUFFER;

type DeclareExport = fn(&mut Setup, &str) -> Result<Box<dyn ExportTap>, AgentError>;
type DeclareImport = fn(&mut Setup, &str) -> Result<Arc<dyn ImportSink>, AgentError>;

/// How one payload type is carried.
#[derive(Clone, Copy)]
pub struct Carrier {
    /// its layout
    pub info: TypeInfo,
    /// declares an input port of this type
    pub export: DeclareExport,
    /// declares an output port of this type
    pub import: DeclareImport,
}

impl std::fmt::Debug for Carrier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Carrier").field("info", &self.info).finish()
    }
}

/// The payload types a bridge carries, by stable type name.
#[derive(Debug, Clone, Default)]
pub struct Types {
    by_name: BTreeMap<&'static str, Carrier>,
}

impl Types {
    /// Every payload type built into nerve (`shm_schemas::for_each_payload!`).
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
    /// bytes and sends its bytes as they are in memory.
    pub fn with<T: Payload + AnyBitPattern>(mut self) -> Self {
        self.by_name.insert(T::stable_type_name(), carrier::<T>());
        self
    }

    /// The carrier of a type name.
    pub fn get(&self, name: &str) -> Option<&Carrier> {
        self.by_name.get(name)
    }

    /// Whether this bridge carries `name`.
    pub fn knows(&self, name: &str) -> bool {
        self.by_name.contains_key(name)
    }
}

fn carrier<T: Payload + AnyBitPattern>() -> Carrier {
    Carrier {
        info: TypeInfo {
            name: T::stable_type_name(),
            size: std::mem::size_of::<T>(),
            fingerprint: T::layout_fingerprint(),
        },
        export: |setup, port| Ok(Box::new(Tap::<T>(setup.input::<T>(port)?))),
        import: |setup, port| Ok(Arc::new(Sink::<T>(setup.output::<T>(port)?))),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_payload_is_carried() {
        let t = Types::builtin();
        for name in shm_schemas::payloads::known_type_names() {
            let c = t.get(name).expect("carried");
            assert_eq!(c.info.name, name);
        }
        let tick = t.get("nerve::Tick").expect("tick");
        assert_eq!(
            (tick.info.size, tick.info.fingerprint),
            (16, <shm_schemas::payloads::Tick as shm_schemas::Described>::schema().fingerprint())
        );
        assert!(!t.knows("nerve::Nothing"));
    }
}
