//! The payloads the benchmarks send: 8 bytes, one 320x240 RGB frame
//! (230,400 B) and one 1920x1080 RGB frame (6,220,800 B) for `hop`, and a
//! 4 KB message beside 8 B and 230 KB for `bridge`, and a 1 MiB message
//! for `messages` (beside a sequence sample of the same size).
//!
//! Each is `#[repr(C)]` with `#[derive(Payload)]` and a stable
//! `nerve::bench::*` type name, so the same type
//! travels on SDK ports and on the raw iceoryx2 services. The first 8 bytes
//! carry the sequence number of the round trip; the rest is image data that
//! the zero-copy transports never touch (a camera would have written it once,
//! in place) and that the Unix socket copies in full.

use serde::{Serialize, Serializer};
use shm_schemas::Payload;

/// A payload the hop benchmark can send: a sequence number in its first 8 bytes.
pub trait BenchPayload: Payload + Default {
    /// Size in bytes.
    const SIZE: usize = std::mem::size_of::<Self>();
    /// Short label for tables (`8 B`, `230 KB`, `6.2 MB`).
    const LABEL: &'static str;
    /// The sequence number.
    fn seq(&self) -> u64;
    /// Sets the sequence number.
    fn set_seq(&mut self, seq: u64);
    /// Writes `seq` into an uninitialised sample without touching the rest.
    ///
    /// # Safety
    /// `p` must point to writable memory for a `Self`.
    unsafe fn write_seq_raw(p: *mut Self, seq: u64);
}

/// 8 bytes: just the sequence number.
#[derive(Debug, Clone, Copy, Default, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::bench::Small8")]
pub struct Small8 {
    /// sequence number of the round trip
    pub seq: u64,
}

impl BenchPayload for Small8 {
    const LABEL: &'static str = "8 B";
    fn seq(&self) -> u64 {
        self.seq
    }
    fn set_seq(&mut self, seq: u64) {
        self.seq = seq;
    }
    unsafe fn write_seq_raw(p: *mut Self, seq: u64) {
        // SAFETY: the caller guarantees `p` is valid for writes.
        unsafe { std::ptr::addr_of_mut!((*p).seq).write(seq) };
    }
}

macro_rules! frame {
    ($name:ident, $tn:literal, $size:expr, $label:literal, $doc:literal) => {
        #[doc = $doc]
        #[derive(Clone, Copy, Payload)]
        #[repr(C)]
        #[payload(name = $tn)]
        pub struct $name {
            /// sequence number of the round trip
            pub seq: u64,
            /// pixel data
            pub rest: [u8; $size - 8],
        }

        impl Default for $name {
            fn default() -> Self {
                $name { seq: 0, rest: [0; $size - 8] }
            }
        }

        impl std::fmt::Debug for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.debug_struct(stringify!($name)).field("seq", &self.seq).field("bytes", &$size).finish()
            }
        }

        // serde has no Serialize for arrays this long; `nerve echo` prints the sequence and size
        impl Serialize for $name {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                use serde::ser::SerializeStruct;
                let mut st = s.serialize_struct(stringify!($name), 2)?;
                st.serialize_field("seq", &self.seq)?;
                st.serialize_field("bytes", &$size)?;
                st.end()
            }
        }

        impl BenchPayload for $name {
            const LABEL: &'static str = $label;
            fn seq(&self) -> u64 {
                self.seq
            }
            fn set_seq(&mut self, seq: u64) {
                self.seq = seq;
            }
            unsafe fn write_seq_raw(p: *mut Self, seq: u64) {
                // SAFETY: the caller guarantees `p` is valid for writes.
                unsafe { std::ptr::addr_of_mut!((*p).seq).write(seq) };
            }
        }
    };
}

frame!(Frame230k, "nerve::bench::Frame230k", 320 * 240 * 3, "230 KB", "One 320x240 RGB frame (230,400 B).");
frame!(Frame4k, "nerve::bench::Frame4k", 4096, "4 KB", "A 4 KB message (4,096 B), between a command and a frame.");
frame!(
    Frame1M,
    "nerve::bench::Frame1M",
    1_048_576,
    "1 MB",
    "A 1 MiB message (1,048,576 B): the fixed payload beside a sequence sample of 1 MiB."
);
frame!(Frame1080p, "nerve::bench::Frame1080p", 1920 * 1080 * 3, "6.2 MB", "One 1920x1080 RGB frame (6,220,800 B).");

/// The payload sizes the hop benchmark knows, in bytes.
pub const SIZES: [usize; 3] = [8, 320 * 240 * 3, 1920 * 1080 * 3];

/// Label of a payload size.
pub fn label(size: usize) -> &'static str {
    match size {
        8 => Small8::LABEL,
        4096 => Frame4k::LABEL,
        230_400 => Frame230k::LABEL,
        1_048_576 => Frame1M::LABEL,
        6_220_800 => Frame1080p::LABEL,
        _ => "?",
    }
}

/// Calls `$body` with `$t` bound to the payload type of `$size`, or evaluates `$other`.
#[macro_export]
macro_rules! with_payload {
    ($size:expr, $t:ident => $body:expr, _ => $other:expr) => {
        match $size {
            8 => {
                type $t = $crate::payloads::Small8;
                $body
            }
            4096 => {
                type $t = $crate::payloads::Frame4k;
                $body
            }
            230_400 => {
                type $t = $crate::payloads::Frame230k;
                $body
            }
            1_048_576 => {
                type $t = $crate::payloads::Frame1M;
                $body
            }
            6_220_800 => {
                type $t = $crate::payloads::Frame1080p;
                $body
            }
            _ => $other,
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_names() {
        assert_eq!(std::mem::size_of::<Small8>(), 8);
        assert_eq!(std::mem::size_of::<Frame4k>(), 4096);
        assert_eq!(std::mem::size_of::<Frame230k>(), 230_400);
        assert_eq!(std::mem::size_of::<Frame1080p>(), 6_220_800);
        assert_eq!(std::mem::size_of::<Frame1M>(), 1_048_576);
        assert_eq!(Frame230k::stable_type_name(), "nerve::bench::Frame230k");
        assert_eq!(Small8::stable_type_name(), "nerve::bench::Small8");
    }
}
