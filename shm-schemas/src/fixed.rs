//! Bounded, fixed-size strings that can live in shared memory.

use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Capacity of a [`FixedName`] in bytes; agent and port names are at most this long.
pub const FIXED_NAME_CAPACITY: usize = 32;

/// A name of at most [`FIXED_NAME_CAPACITY`] bytes, stored inline (`#[repr(C)]`)
/// so that it can be part of a shared-memory payload.
#[derive(Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("nerve::FixedName")]
pub struct FixedName {
    len: u32,
    bytes: [u8; FIXED_NAME_CAPACITY],
}

impl FixedName {
    /// An empty name.
    pub const EMPTY: FixedName = FixedName { len: 0, bytes: [0; FIXED_NAME_CAPACITY] };

    /// Stores `s`, cut at the capacity (on a character boundary).
    pub fn new(s: &str) -> Self {
        let mut end = s.len().min(FIXED_NAME_CAPACITY);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        let mut bytes = [0u8; FIXED_NAME_CAPACITY];
        bytes[..end].copy_from_slice(&s.as_bytes()[..end]);
        FixedName { len: end as u32, bytes }
    }

    /// The stored text. A corrupt length (from a misbehaving peer) is clamped
    /// and invalid UTF-8 yields `"?"`.
    pub fn as_str(&self) -> &str {
        let len = (self.len as usize).min(FIXED_NAME_CAPACITY);
        std::str::from_utf8(&self.bytes[..len]).unwrap_or("?")
    }
}

impl Default for FixedName {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl std::fmt::Debug for FixedName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

impl std::fmt::Display for FixedName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for FixedName {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for FixedName {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        Ok(FixedName::new(&s))
    }
}

impl crate::schema::Described for FixedName {
    fn schema() -> crate::schema::Schema {
        crate::schema::Schema {
            // SAFETY: reading the name has no precondition; the unsafety of
            // `ZeroCopySend::type_name` concerns implementing it
            type_name: unsafe { <FixedName as ZeroCopySend>::type_name() }.into(),
            size: std::mem::size_of::<FixedName>(),
            align: std::mem::align_of::<FixedName>(),
            kind: crate::schema::Kind::String { capacity: FIXED_NAME_CAPACITY },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation() {
        assert_eq!(FixedName::new("relay").as_str(), "relay");
        let long = "x".repeat(40);
        assert_eq!(FixedName::new(&long).as_str().len(), FIXED_NAME_CAPACITY);
        // a multi-byte character across the boundary is not split
        let s = format!("{}é", "a".repeat(31));
        assert_eq!(FixedName::new(&s).as_str(), "a".repeat(31));
    }

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<FixedName>(), 36);
        assert_eq!(std::mem::align_of::<FixedName>(), 4);
    }
}
