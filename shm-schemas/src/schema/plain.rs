//! Types any bytes are a valid value of ([`AnyBitPattern`]), and [`Bool`],
//! the flag a payload may hold.
//!
//! A sample's bytes do not always come from the Rust type that reads them:
//! `nerve replay` writes a recording's bytes, the bridge a peer's, Python
//! any bytes of the layout (`send_bytes`). A `bool` that holds 2, a `char`
//! that is not a scalar value or an enum with an unknown discriminant is
//! undefined behaviour in the reader, and padding bytes are never written
//! by Rust, so copying a value's bytes reads uninitialised memory.
//! `#[derive(Payload)]` therefore accepts only fields that are
//! [`AnyBitPattern`], and no implicit padding.

use super::{Described, Kind, Primitive, Schema};
use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// A type for which every bit pattern of its size is a valid value and
/// which has no padding bytes: numbers, arrays of them, [`Bool`],
/// [`crate::FixedName`], and every `#[derive(Payload)]` struct (the derive
/// checks both for each field). Not `bool`, `char`, enums or references.
///
/// # Safety
/// Every `size_of::<Self>()` bytes, whatever they hold, must be a valid
/// `Self`, and every byte of a `Self` must belong to a field (no padding).
#[diagnostic::on_unimplemented(
    message = "`{Self}` cannot be a field of a payload: not every bit pattern is a valid `{Self}`",
    label = "a recording, a bridge peer or Python may write any byte here",
    note = "for a flag, store a u8 (0/1) or use shm_schemas::Bool; for an enum, store its u8 code"
)]
pub unsafe trait AnyBitPattern: Copy + 'static {}

macro_rules! any_bit_pattern {
    ($($t:ty),*) => {$(
        // SAFETY: every bit pattern is a valid integer or float (NaNs included), without padding
        unsafe impl AnyBitPattern for $t {}
    )*};
}
any_bit_pattern!(u8, u16, u32, u64, i8, i16, i32, i64, f32, f64);

// SAFETY: an array of such elements has no bytes but its elements' (an
// element's size is a multiple of its alignment), each any bit pattern
unsafe impl<T: AnyBitPattern, const N: usize> AnyBitPattern for [T; N] {}

// SAFETY: a u32 and a [u8; 32], no padding (36 bytes, align 4); `as_str`
// clamps any length and replaces invalid UTF-8
unsafe impl AnyBitPattern for crate::FixedName {}

/// A flag in a payload: one byte, 0 for false and anything else for true,
/// so that any byte a peer or a recording writes is a valid value (a Rust
/// `bool` holding 2 is undefined behaviour). Its schema is a `bool`'s: a
/// field changed from `bool` to `Bool` keeps the layout fingerprint, and
/// tools show it as `true`/`false`.
///
/// ```
/// use shm_schemas::schema::Bool;
/// let b = Bool::from(true);
/// assert!(b.get());
/// assert_eq!(Bool::default(), Bool::FALSE);
/// ```
#[derive(Clone, Copy, Default, PartialEq, Eq, Hash)]
#[repr(transparent)]
pub struct Bool(u8);

impl Bool {
    /// false (0)
    pub const FALSE: Bool = Bool(0);
    /// true (1)
    pub const TRUE: Bool = Bool(1);

    /// The flag: any byte but 0 is true.
    pub const fn get(self) -> bool {
        self.0 != 0
    }

    /// The byte as stored.
    pub const fn byte(self) -> u8 {
        self.0
    }
}

impl From<bool> for Bool {
    fn from(b: bool) -> Self {
        Bool(u8::from(b))
    }
}

impl From<Bool> for bool {
    fn from(b: Bool) -> Self {
        b.get()
    }
}

impl std::fmt::Debug for Bool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(&self.get(), f)
    }
}

impl Serialize for Bool {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bool(self.get())
    }
}

impl<'de> Deserialize<'de> for Bool {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        bool::deserialize(d).map(Bool::from)
    }
}

// SAFETY: one u8, self-contained, #[repr(transparent)]
unsafe impl ZeroCopySend for Bool {
    unsafe fn type_name() -> &'static str {
        "nerve::Bool"
    }
}

// SAFETY: one u8, any value of which is a valid Bool
unsafe impl AnyBitPattern for Bool {}

impl Described for Bool {
    fn schema() -> Schema {
        // a bool's schema: one byte that decodes as a flag (any non-zero
        // byte is true, as the decoder reads a bool)
        Schema { type_name: "bool".into(), size: 1, align: 1, kind: Kind::Primitive { primitive: Primitive::Bool } }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bool_field_becomes_a_bool_with_the_same_schema_and_any_byte_is_valid() {
        assert_eq!(Bool::schema(), <bool as Described>::schema());
        assert_eq!(Bool::schema().fingerprint(), <bool as Described>::schema().fingerprint());
        assert_eq!((std::mem::size_of::<Bool>(), std::mem::align_of::<Bool>()), (1, 1));
        for byte in [0u8, 1, 2, 255] {
            // SAFETY: Bool is a transparent u8
            let b: Bool = unsafe { std::mem::transmute(byte) };
            assert_eq!(b.get(), byte != 0);
            assert_eq!(Bool::schema().decode(&[byte]).expect("decodes"), super::super::Value::Bool(byte != 0));
        }
        assert_eq!(serde_json::to_string(&Bool::TRUE).expect("json"), "true");
        assert_eq!(serde_json::from_str::<Bool>("false").expect("json"), Bool::FALSE);
        assert_eq!(format!("{:?}", Bool::from(true)), "true");
    }
}
