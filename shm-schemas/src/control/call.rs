//! How a call port (a service an agent answers, or a client that calls one)
//! is typed for the router: one [`PortSpec`] whose type name names the
//! request and the response (`call(Req -> Resp)`) and whose fingerprint
//! mixes both layouts' fingerprints, so that the router's one rule for
//! connections (the same type name, the same layout) checks both types of
//! a call at once, and never wires a call port to a publish-subscribe port.

use super::agent_to_router::PortSpec;
use crate::Payload;

/// The prefix of every call port's type name.
pub const CALL_PREFIX: &str = "call(";

/// The type name of a call of `request` answered by `response`.
pub fn call_type_name(request: &str, response: &str) -> String {
    format!("{CALL_PREFIX}{request} -> {response})")
}

/// The request and response type names of call type name `type_name`;
/// `None` when it is not a call's.
pub fn split_call_type_name(type_name: &str) -> Option<(&str, &str)> {
    type_name.strip_prefix(CALL_PREFIX)?.strip_suffix(')')?.split_once(" -> ")
}

/// The fingerprint of a call whose request and response have the layout
/// fingerprints `request` and `response` (order matters: a call of B
/// answered by A is another call).
pub fn call_fingerprint(request: u64, response: u64) -> u64 {
    request.rotate_left(17) ^ response.wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

/// The spec of call port `name` of requests `Req` answered by `Resp`.
pub fn call_spec<Req: Payload, Resp: Payload>(name: &str) -> PortSpec {
    PortSpec {
        name: name.into(),
        type_name: call_type_name(Req::stable_type_name(), Resp::stable_type_name()),
        fingerprint: call_fingerprint(Req::layout_fingerprint(), Resp::layout_fingerprint()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payloads::{Scalar, Tick};

    #[test]
    fn a_call_type_names_both_types_and_their_order() {
        let a = call_spec::<Tick, Scalar>("plan");
        let b = call_spec::<Scalar, Tick>("plan");
        assert_eq!(a.type_name, "call(nerve::Tick -> nerve::Scalar)");
        assert_eq!(split_call_type_name(&a.type_name), Some(("nerve::Tick", "nerve::Scalar")));
        assert_eq!(split_call_type_name("nerve::Tick"), None);
        assert_ne!(a.fingerprint, b.fingerprint, "a swapped call is another call");
        assert_ne!(a.fingerprint, Tick::layout_fingerprint());
    }
}
