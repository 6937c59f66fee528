//! Typed ports, under the path agents and tools have always used: they
//! live in [`crate::port`] (the typed views in [`crate::port::typed`], the
//! services in [`crate::port::service`]).

pub(crate) use crate::port::bytes::DynInput;
pub use crate::port::bytes::Meta;
pub use crate::port::error::PortError;
pub use crate::port::service::{
    MAX_SOURCES, MAX_SUBSCRIBERS, SUBSCRIBER_BUFFER, existing_port_service, port_event, port_service,
    service_fingerprint,
};
pub use crate::port::typed::{Input, Output};
