//! Every type that crosses a nerve process boundary, and the rules that name
//! the iceoryx2 services carrying them.
//!
//! Two families live here:
//!
//! * **Data payloads** (`tick`, `sonar`, ...): `#[repr(C)]` + `ZeroCopySend`
//!   with a stable `type_name` such as `nerve::Tick`, sent zero-copy through
//!   iceoryx2 publish-subscribe. Their layout is pinned by the tests at the
//!   bottom of each module, so a change that would break a running peer fails
//!   the build.
//! * **Control messages** (`agent_to_router`, `router_to_agent`,
//!   `cli_to_router`): serde types encoded with postcard inside an
//!   [`control::Envelope`] that carries [`PROTOCOL_VERSION`]. A peer speaking
//!   another version is refused with one shared, actionable message.
#![warn(missing_docs)]

// `#[derive(Payload)]` names `::shm_schemas`, here too
extern crate self as shm_schemas;

pub mod control;
pub mod cycles;
pub mod encode;
pub mod fixed;
pub mod geom;
pub mod header;
pub mod names;
pub mod payloads;
pub mod ring;
pub mod schema;
pub mod seq;
pub mod services;
pub mod stats;

pub use control::{PROTOCOL_VERSION, ProtocolError};
pub use fixed::FixedName;
pub use header::SampleHeader;
pub use names::{AgentName, NameError, PortRef, RobotName};
/// The trait, and `#[derive(Payload)]` (see the `shm-schemas-derive` crate).
pub use payloads::Payload;
pub use schema::{Described, Schema};
pub use seq::{NoHeader, Seq, SeqPart, SeqShape};

/// What `#[derive(Payload)]` expands to names; not an interface.
#[doc(hidden)]
pub mod __private {
    pub use iceoryx2::prelude::ZeroCopySend;
}
