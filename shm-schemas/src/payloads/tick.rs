//! `nerve::Tick`: the output of the `ticker` example agent.

use super::Payload;
use serde::Serialize;

/// A numbered tick, stamped when it was made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::Tick")]
pub struct Tick {
    /// Sequence number, starting at 1.
    pub seq: u64,
    /// CLOCK_MONOTONIC nanoseconds when the tick was made.
    pub stamp_ns: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<Tick>(), 16);
        assert_eq!(std::mem::align_of::<Tick>(), 8);
        assert_eq!(<Tick as Payload>::stable_type_name(), "nerve::Tick");
    }
}
