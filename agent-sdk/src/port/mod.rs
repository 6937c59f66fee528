//! Ports: one stack, from the iceoryx2 service up to the typed port.
//!
//! * [`error`]: [`PortError`], one variant per iceoryx2 operation;
//! * [`service`]: the services behind a port (settings, attributes, the
//!   layout check, the wake-up event), the same for every port;
//! * [`bytes`]: THE port, samples of a layout a schema describes, read and
//!   written in place as bytes; with the tools' [`RawPort`] and [`RawOutput`]
//!   (its files: `tally`, `output`, `input`, `raw`);
//! * [`typed`]: [`Output<T>`] and [`Input<T>`], views of the byte port as a
//!   Rust type, zero copy;
//! * [`call`]: calls between agents, a [`Server`] and a [`Client`] on
//!   iceoryx2 request-response (`call_server`, `call_client`, `call_raw`);
//!   [`call_seq`]: calls answered with a sequence, [`SeqServer`], [`SeqClient`];
//! * [`depth`]: an input's depth and policy ([`InputOptions`]), its own queue;
//! * [`keep_all`]: a keep-all input's lossless service, the sender's bounded wait;
//! * `memory`: the in-memory binding a test's ports use instead of iceoryx2.
//!
//! Each file uses only those above it in this list (`memory` only
//! `error` and `service`), so there is no circle.

pub mod bytes;
pub mod call;
mod call_client;
mod call_raw;
pub mod call_seq;
mod call_server;
pub mod depth;
pub mod error;
mod input;
pub mod keep_all;
pub(crate) mod memory;
mod output;
mod raw;
pub mod schema_call;
pub mod seq;
pub mod service;
mod tally;
pub mod typed;

pub use bytes::{Loan, Meta, RawOutput, RawPort, Received, SchemaInput, SchemaOutput};
pub use call::{CallClient, CallError, CallId, CallOptions, CallServer, Client, RawCaller, Server};
pub use call_seq::{SeqClient, SeqServer};
pub use depth::{InputOptions, Keep};
pub use error::PortError;
pub use seq::{SeqInput, SeqOutput};
pub use service::{
    MAX_SOURCES, MAX_SUBSCRIBERS, SUBSCRIBER_BUFFER, existing_port_service, port_event, port_identity, port_service,
    service_fingerprint,
};
pub use typed::{Input, Output};
