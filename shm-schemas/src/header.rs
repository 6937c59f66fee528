//! The user header every nerve sample carries: who sent it, its sequence
//! number on that port, and when it was stamped.

use crate::fixed::FixedName;
use iceoryx2::prelude::ZeroCopySend;
use serde::Serialize;

/// Header of every sample on a nerve output port (iceoryx2 user header).
///
/// An input port may hold several subscriptions (fan-in); the header tells
/// the reader which agent sent each sample. Gaps in `seq` from one sender are
/// samples lost to overflow and are counted as drops.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend, Serialize)]
#[repr(C)]
#[type_name("nerve::SampleHeader")]
pub struct SampleHeader {
    /// Name of the sending agent.
    pub sender: FixedName,
    /// Sequence number on the sending port, starting at 1.
    pub seq: u64,
    /// Monotonic clock (CLOCK_MONOTONIC) in nanoseconds when the sample was sent.
    pub stamp_ns: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<SampleHeader>(), 56);
        assert_eq!(std::mem::align_of::<SampleHeader>(), 8);
        // SAFETY: reading the type's name has no precondition
        assert_eq!(unsafe { <SampleHeader as ZeroCopySend>::type_name() }, "nerve::SampleHeader");
    }
}
