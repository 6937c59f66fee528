//! Control messages between agents, the router and the command line.
//!
//! Modules are named by direction, as in dora: [`agent_to_router`],
//! [`router_to_agent`], [`cli_to_router`]. Every message travels inside an
//! [`Envelope`] stamped with [`PROTOCOL_VERSION`] and encoded with postcard;
//! a message from a peer speaking another version is refused with
//! [`ProtocolError::VersionMismatch`], whose text says what to do.

pub mod agent_to_router;
pub mod call;
pub mod cli_to_router;
pub mod describe;
pub mod router_to_agent;

use serde::{Deserialize, Serialize, de::DeserializeOwned};

/// Version of the control protocol. Bump it on any change to a control type.
pub const PROTOCOL_VERSION: u16 = 12;

/// A control message with the protocol version of its sender.
#[derive(Debug, Serialize, Deserialize)]
pub struct Envelope<T> {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u16,
    /// The message.
    pub body: T,
}

/// A control message that could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProtocolError {
    /// The peer was built from another version of nerve.
    #[error(
        "protocol version mismatch: the peer speaks nerve control protocol v{peer}, this program v{ours}; \
         rebuild and restart the older side (`cargo build --workspace`, then restart the router and agents)"
    )]
    VersionMismatch {
        /// the peer's version
        peer: u16,
        /// ours
        ours: u16,
    },
    /// The bytes are not a valid message.
    #[error("malformed control message: {0}")]
    Malformed(String),
    /// The server took the request and let it go without an answer (it
    /// stopped, or dropped the request): it may or may not have been
    /// carried out, and a caller must not send it again blindly.
    #[error(
        "the server took the request and stopped before answering it: it may or may not have been carried out; check (`nerve ps`, `nerve graph`) and try again"
    )]
    Unanswered,
    /// A reply is larger than the control service carries.
    #[error("the reply ({bytes} bytes) is larger than the {max} bytes this control service carries")]
    TooLarge {
        /// the reply's size
        bytes: usize,
        /// the service's limit
        max: usize,
    },
}

/// Encodes `body` in an envelope of the current version.
pub fn encode<T: Serialize>(body: &T) -> Vec<u8> {
    // Serialising plain data into a Vec cannot fail except on out-of-memory.
    postcard::to_stdvec(&Envelope { version: PROTOCOL_VERSION, body }).unwrap_or_default()
}

/// The version word of the reply a server sends for a request it took and
/// lets go unanswered ([`unanswered`]); never a real protocol version.
const UNANSWERED: u16 = u16::MAX;

/// The reply to a request the server took and will not answer: decodes as
/// [`ProtocolError::Unanswered`] whatever the caller expected. It tells the
/// caller that the request was taken, so that it does not send it again.
pub fn unanswered() -> Vec<u8> {
    postcard::to_stdvec(&Envelope { version: UNANSWERED, body: () }).unwrap_or_default()
}

/// Decodes an envelope, checking the version first.
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ProtocolError> {
    let (version, _) = postcard::take_from_bytes::<u16>(bytes).map_err(|e| ProtocolError::Malformed(e.to_string()))?;
    if version == UNANSWERED {
        return Err(ProtocolError::Unanswered);
    }
    if version != PROTOCOL_VERSION {
        return Err(ProtocolError::VersionMismatch { peer: version, ours: PROTOCOL_VERSION });
    }
    postcard::from_bytes::<Envelope<T>>(bytes).map(|e| e.body).map_err(|e| ProtocolError::Malformed(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::router_to_agent::AgentCommand;

    #[test]
    fn round_trip() {
        let bytes = encode(&AgentCommand::SetPeriod { period_ns: 5_000_000 });
        let back: AgentCommand = decode(&bytes).expect("decodes");
        assert!(matches!(back, AgentCommand::SetPeriod { period_ns: 5_000_000 }));
    }

    #[test]
    fn other_version_is_refused_with_advice() {
        let bytes = postcard::to_stdvec(&Envelope { version: 999u16, body: AgentCommand::Stop }).expect("encodes");
        let err = decode::<AgentCommand>(&bytes).expect_err("must refuse");
        assert_eq!(err, ProtocolError::VersionMismatch { peer: 999, ours: PROTOCOL_VERSION });
        assert!(err.to_string().contains("rebuild"));
    }

    #[test]
    fn an_unanswered_request_decodes_as_such_whatever_was_expected() {
        assert_eq!(decode::<AgentCommand>(&unanswered()).expect_err("unanswered"), ProtocolError::Unanswered);
        assert_eq!(decode::<String>(&unanswered()).expect_err("unanswered"), ProtocolError::Unanswered);
    }

    #[test]
    fn garbage_is_malformed() {
        assert!(matches!(
            decode::<AgentCommand>(&[PROTOCOL_VERSION as u8, 0xff, 0xff]),
            Err(ProtocolError::Malformed(_))
        ));
    }
}
