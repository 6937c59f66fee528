//! `nerve::RouterEpoch`: how a (re)started router announces itself, so that
//! running agents re-register by themselves.

use super::Payload;
use serde::Serialize;

/// Published by the router on `nerve/<robot>/router/epoch` (history 1) when it starts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::RouterEpoch")]
pub struct RouterEpoch {
    /// A number that differs for every router start.
    pub epoch: u64,
    /// The router's pid.
    pub pid: u32,
    /// Padding, zero.
    pub reserved: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<RouterEpoch>(), 16);
        assert_eq!(<RouterEpoch as Payload>::stable_type_name(), "nerve::RouterEpoch");
    }
}
