//! [`PortError`]: why a port could not be made or used, one variant per
//! iceoryx2 operation, each keeping iceoryx2's own error as its source.

use shm_schemas::services::port_attributes::fingerprint_text;

/// Why a port could not be made or used. Each variant names the iceoryx2
/// operation that failed and keeps iceoryx2's own error as its source, so a
/// caller can tell a full subscriber list from a missing service.
#[derive(Debug, thiserror::Error)]
pub enum PortError {
    /// The port's publish-subscribe service could not be opened or created.
    #[error("port {service}: cannot open its service: {source:?}")]
    Service {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError,
    },
    /// The service exists with another payload type.
    #[error("port {service}: the service exists with another payload type than {type_name}")]
    IncompatibleType {
        /// service name
        service: String,
        /// the type this side asked for
        type_name: String,
    },
    /// The service carries the same type name built from another
    /// definition (another layout fingerprint): a stale build on one side.
    #[error(
        "port {service} carries {type_name} with layout {}, this program was built with layout {}: \
         the two were built from different definitions of {type_name}; rebuild the older one (`cargo build`) and restart it",
        fingerprint_text(*theirs), fingerprint_text(*ours)
    )]
    LayoutMismatch {
        /// service name
        service: String,
        /// the payload type name
        type_name: String,
        /// the fingerprint of this side's build
        ours: u64,
        /// the fingerprint the service was created with
        theirs: u64,
    },
    /// The port's wake-up event service could not be opened or created.
    #[error("port {service}: cannot open its wake-up event: {source:?}")]
    Event {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::service::builder::event::EventOpenOrCreateError,
    },
    /// The publisher could not be created.
    #[error("port {service}: cannot create the publisher: {source:?}")]
    Publisher {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::publisher::PublisherCreateError,
    },
    /// The subscriber could not be created (e.g. the service has its most subscribers).
    #[error("port {service}: cannot subscribe: {source:?}")]
    Subscriber {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::subscriber::SubscriberCreateError,
    },
    /// The event notifier could not be created.
    #[error("port {service}: cannot create the wake-up notifier: {source:?}")]
    Notifier {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::notifier::NotifierCreateError,
    },
    /// The event listener could not be created.
    #[error("port {service}: cannot create the wake-up listener: {source:?}")]
    Listener {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::listener::ListenerCreateError,
    },
    /// No sample could be loaned (every slot is held by subscribers or unsent).
    #[error("port {service}: cannot loan a sample: {source:?}")]
    Loan {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::LoanError,
    },
    /// The sample could not be sent.
    #[error("port {service}: cannot send: {source:?}")]
    Send {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::SendError,
    },
    /// The subscribers could not be woken.
    #[error("port {service}: cannot wake the subscribers: {source:?}")]
    Notify {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::port::notifier::NotifierNotifyError,
    },
    /// The output port an input was asked to read does not exist: no agent
    /// of the robot has it (an input opens a source, it never creates one).
    #[error("port {service} does not exist: no running agent of this robot has that output; see `nerve ps`")]
    NoSuchPort {
        /// service name
        service: String,
    },
    /// The source port's services exist but could not be opened.
    #[error("port {service}: cannot open its service: {source:?}")]
    OpenService {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError,
    },
    /// The source port's wake-up event could not be opened.
    #[error("port {service}: cannot open its wake-up event: {source:?}")]
    OpenEvent {
        /// service name
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::service::builder::event::EventOpenError,
    },
    /// An input reads from as many sources as it may.
    #[error(
        "input {input} already reads {max} sources, the most an input may: disconnect one first (`nerve disconnect`)"
    )]
    TooManySources {
        /// the input
        input: String,
        /// [`super::MAX_SOURCES`]
        max: usize,
    },
    /// The payload's schema describes no layout a type could have (a
    /// damaged recording, a hand-written layout): refused before iceoryx2 sees it.
    #[error("port {service}: {source}")]
    InvalidSchema {
        /// service name
        service: String,
        /// what is wrong with the schema (boxed: it names the type and
        /// the field, and every `Result` of a port would carry its size)
        #[source]
        source: Box<shm_schemas::schema::SchemaInvalid>,
    },
    /// A typed port was asked to view a byte port whose payload has another
    /// size or alignment than the Rust type: reading it as the type would
    /// read past the sample or misaligned. A derive or a hand-written
    /// `Described` that disagrees with the type's layout.
    #[error(
        "port {service}: the type {type_name} is {size} bytes aligned to {align}, but the port's layout is \
         {port_size} bytes aligned to {port_align}: its schema does not describe the Rust type; derive it \
         (`#[derive(Payload)]`) instead of writing it by hand"
    )]
    TypeLayout {
        /// service name
        service: String,
        /// the Rust type's name
        type_name: String,
        /// `size_of` the Rust type
        size: usize,
        /// `align_of` the Rust type
        align: usize,
        /// the byte port's payload size
        port_size: usize,
        /// the byte port's payload alignment
        port_align: usize,
    },
    /// A sample of a sequence port with more elements than the port
    /// declared it would ever send: refused before anything is loaned, so
    /// nothing is sent.
    #[error(
        "port {service}: a sample of {len} elements is longer than the {max_len} the port declared; send at most \
         {max_len} (split it), or declare a larger maximum where the output is declared"
    )]
    TooLong {
        /// service name
        service: String,
        /// the elements asked for
        len: usize,
        /// the most the port takes
        max_len: usize,
    },
    /// Anything else: an invalid service name, a sample of the wrong size.
    #[error("port {service}: {detail}")]
    Ipc {
        /// service name
        service: String,
        /// what went wrong
        detail: String,
    },
}

impl PortError {
    /// Whether a dead process's leftover ports could explain this error
    /// (iceoryx2 refused a port or an open because the service's slots
    /// for ports or nodes were taken), so that cleaning them up and trying
    /// again may help; not for a missing port or a type that differs.
    pub(crate) fn blockable(&self) -> bool {
        matches!(
            self,
            PortError::Service { .. }
                | PortError::Event { .. }
                | PortError::OpenService { .. }
                | PortError::OpenEvent { .. }
                | PortError::Publisher { .. }
                | PortError::Subscriber { .. }
                | PortError::Notifier { .. }
                | PortError::Listener { .. }
        )
    }
}

/// An [`PortError::Ipc`] of `service` saying what `e` is.
pub(crate) fn perr(service: &str, e: impl std::fmt::Debug) -> PortError {
    PortError::Ipc { service: service.into(), detail: format!("{e:?}") }
}

/// Wraps iceoryx2's error `source` into the [`PortError`] variant `$v` for `$service`.
macro_rules! port_err {
    ($v:ident, $service:expr) => {
        |source| PortError::$v { service: String::from($service), source }
    };
}

pub(crate) use port_err;
