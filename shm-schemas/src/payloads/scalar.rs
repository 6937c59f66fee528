//! `nerve::Scalar`: one stamped number — a generic signal (a load, a level,
//! a test value).

use super::Payload;
use serde::Serialize;

/// A stamped value.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::Scalar")]
pub struct Scalar {
    /// The value.
    pub value: f64,
    /// CLOCK_MONOTONIC nanoseconds when it was measured.
    pub stamp_ns: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<Scalar>(), 16);
        assert_eq!(std::mem::align_of::<Scalar>(), 8);
        assert_eq!(<Scalar as Payload>::stable_type_name(), "nerve::Scalar");
    }
}
