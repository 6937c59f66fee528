//! How a call port (a service an agent answers, or a client that calls one)
//! is typed for the router: one [`PortSpec`] whose type name names the
//! request and the response (`call(Req -> Resp)`) and whose fingerprint
//! mixes both layouts' fingerprints, so that the router's one rule for
//! connections (the same type name, the same layout) checks both types of
//! a call at once, and never wires a call port to a publish-subscribe port.
//!
//! A call may answer with a sequence (`Seq<T, H>`, [`crate::seq`]): its
//! type name is `call(Req -> nerve::Seq<T, H>)` and its fingerprint mixes
//! the request's with the sequence's (header and element), so a client of
//! a fixed answer and a server of a sequence answer (or of another
//! element) are refused as two different calls. On the wire the answer is
//! an iceoryx2 slice of 8-byte words, the sequence sample's bytes, after a
//! [`SeqAnswerHeader`] that says how many elements it holds, or why the
//! server refused to answer.

use super::agent_to_router::PortSpec;
use crate::Payload;
use crate::schema::Described;
use crate::seq::{Seq, SeqPart};
use iceoryx2::prelude::ZeroCopySend;

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

/// The spec of call port `name` of requests `Req` answered by a sequence
/// of `T` after header `H` (`Seq<T, H>`).
pub fn call_seq_spec<Req: Payload, T: SeqPart, H: SeqPart>(name: &str) -> PortSpec {
    let answer = Seq::<T, H>::schema();
    PortSpec {
        name: name.into(),
        type_name: call_type_name(Req::stable_type_name(), &answer.type_name),
        fingerprint: call_fingerprint(Req::layout_fingerprint(), answer.fingerprint()),
    }
}

/// A sequence answer's status: answered.
pub const SEQ_ANSWERED: u32 = 0;
/// A sequence answer's status: the server's answer was longer than the
/// service's declared maximum, so it sent none ([`SeqAnswerHeader::items`]
/// is the refused length, [`SeqAnswerHeader::max`] the maximum).
pub const SEQ_TOO_LONG: u32 = 1;

/// The iceoryx2 user header of a sequence answer: what the payload (the
/// sample's bytes, `Seq<T, H>`'s layout, in 8-byte words) holds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("nerve::SeqAnswerHeader")]
pub struct SeqAnswerHeader {
    /// [`SEQ_ANSWERED`] or [`SEQ_TOO_LONG`]
    pub status: u32,
    /// reserved, 0
    pub reserved: u32,
    /// the elements in the answer (or, refused, in the answer that was too long)
    pub items: u64,
    /// the service's declared maximum of elements
    pub max: u64,
    /// the answer's bytes in the payload (`Seq<T, H>`'s header, padding
    /// and elements), so that a tool without the Rust types reads it whole
    pub bytes: u64,
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

    #[test]
    fn a_sequence_answer_is_another_call_than_a_fixed_one_or_another_element() {
        let seq = call_seq_spec::<Tick, Scalar, Tick>("plan");
        assert_eq!(seq.type_name, "call(nerve::Tick -> nerve::Seq<nerve::Scalar, nerve::Tick>)");
        assert_eq!(
            split_call_type_name(&seq.type_name),
            Some(("nerve::Tick", "nerve::Seq<nerve::Scalar, nerve::Tick>"))
        );
        assert_ne!(seq.fingerprint, call_spec::<Tick, Scalar>("plan").fingerprint);
        assert_ne!(seq.fingerprint, call_seq_spec::<Tick, Tick, Tick>("plan").fingerprint);
        assert_ne!(seq.fingerprint, call_seq_spec::<Tick, Scalar, crate::NoHeader>("plan").fingerprint);
    }
}
