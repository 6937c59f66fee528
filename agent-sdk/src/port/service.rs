//! The services behind a port: the one place that sets up an output port's
//! publish-subscribe service (its settings, attributes and layout check)
//! and its wake-up event, so that every opener agrees (iceoryx2 refuses an
//! opener that asks for more than the creator set up).
//!
//! A port is one iceoryx2 publish-subscribe service `nerve/<robot>/<agent>/<port>`
//! with the user header [`SampleHeader`], paired with an event service of the
//! same name. What it carries is described by [`Carried`]: the payload's
//! type name, size, alignment ([`TypeDetail`]) and layout fingerprint, the
//! same whether the port was declared with a Rust type or with a
//! [`Schema`]; so a typed port and a port of bytes are the same service.

use super::error::{PortError, perr, port_err};
use crate::world::Ipc;
use iceoryx2::prelude::*;
use iceoryx2::service::attribute::{AttributeKey, AttributeValue, AttributeVerifier};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError as Open, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::marker::{CustomHeaderMarker, CustomPayloadMarker};
use iceoryx2::service::port_factory::{event, publish_subscribe};
use iceoryx2::service::static_config::message_type_details::{TypeDetail, TypeVariant};
use shm_schemas::services::port_attributes::{self, fingerprint_text, parse_fingerprint};
use shm_schemas::{Payload, SampleHeader, Schema};
use std::sync::{Mutex, MutexGuard};

/// Fan-out of one output port: how many inputs may read it at once.
pub const MAX_SUBSCRIBERS: usize = 16;
/// Fan-in of one input port: how many outputs it may read at once. Each
/// source costs a subscriber, a listener, their file descriptors and a line
/// in the agent's statistics, so a flood of `Connect` commands is refused
/// past this (reliability review R10).
pub const MAX_SOURCES: usize = 64;
/// Samples a subscription buffers before the oldest is overwritten (and counted as dropped).
pub const SUBSCRIBER_BUFFER: usize = 16;
pub(crate) const MAX_PUBLISHERS: usize = 4;
pub(crate) const MAX_NODES: usize = 40;

/// How often opening a port's service is tried while its last owner removes
/// it (10 ms apart: half a second in all).
const MARKED_FOR_DESTRUCTION_ATTEMPTS: u32 = 50;

/// The settings of every output port's service, typed or not, so that every opener agrees.
macro_rules! port_settings {
    ($builder:expr) => {
        $builder
            .max_publishers($crate::port::service::MAX_PUBLISHERS)
            .max_subscribers($crate::port::service::MAX_SUBSCRIBERS)
            .max_nodes($crate::port::service::MAX_NODES)
            .subscriber_max_buffer_size($crate::port::service::SUBSCRIBER_BUFFER)
            .history_size(0)
            .enable_safe_overflow(true)
    };
}

/// The settings of an output port's keep-all service (`port::keep_all`):
/// a few readers, each with a buffer up to its depth, and no overwriting:
/// a full reader makes the publisher wait (for a bounded time).
macro_rules! keep_all_settings {
    ($builder:expr) => {
        $builder
            .max_publishers($crate::port::service::MAX_PUBLISHERS)
            .max_subscribers($crate::port::service::KEEP_ALL_READERS)
            .max_nodes($crate::port::service::MAX_NODES)
            .subscriber_max_buffer_size($crate::port::depth::MAX_DEPTH)
            .history_size(0)
            .enable_safe_overflow(false)
    };
}

/// How many keep-all inputs may read one output losslessly; more read it
/// through their own queue of copies (`port::depth`).
pub(crate) const KEEP_ALL_READERS: usize = 4;

/// The guard of `m`. A panic in another thread aborts the process
/// (`abort_on_panic`), so a poisoned lock cannot be observed; the guard is
/// recovered regardless.
pub(crate) fn lock<X>(m: &Mutex<X>) -> MutexGuard<'_, X> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// What a port carries: the payload's iceoryx2 type details (name, size,
/// alignment, fixed size) and its layout fingerprint. Made from a Rust type
/// ([`Carried::of_type`]) or from a checked [`Schema`] ([`Carried::of_schema`]),
/// it gives the same service for the same layout.
#[derive(Debug, Clone)]
pub(crate) struct Carried {
    pub(crate) details: TypeDetail,
    pub(crate) type_name: String,
    pub(crate) fingerprint: u64,
}

impl Carried {
    /// What a port of the Rust payload type `T` carries: the details
    /// iceoryx2 would take from `T` itself (`TypeDetail::new::<T>`).
    pub(crate) fn of_type<T: Payload>(service: &str) -> Result<Self, PortError> {
        Self::from_parts(
            service,
            T::stable_type_name(),
            std::mem::size_of::<T>(),
            std::mem::align_of::<T>(),
            T::layout_fingerprint(),
        )
    }

    /// What a port of the payload layout `schema` carries, with layout
    /// fingerprint `fingerprint`, once the schema is [valid](Schema::validate):
    /// every port made from a schema (Python's, `nerve replay`'s) passes here
    /// before its size and alignment reach iceoryx2's `unsafe` set-up, which
    /// divides by the alignment and builds a `Layout` from it unchecked.
    pub(crate) fn of_schema(service: &str, schema: &Schema, fingerprint: u64) -> Result<Self, PortError> {
        schema.validate().map_err(|e| PortError::InvalidSchema { service: service.into(), source: Box::new(e) })?;
        if schema.sequence_shape().is_some() {
            return Self::of_sequence(service, &schema.type_name, fingerprint);
        }
        Self::from_parts(service, &schema.type_name, schema.size, schema.align, fingerprint)
    }

    /// What a port of a sequence ([`shm_schemas::seq`]) of type name
    /// `type_name` carries: iceoryx2's slice of bytes (a dynamic payload of
    /// one-byte elements), each sample as long as its elements make it.
    pub(crate) fn of_sequence(service: &str, type_name: &str, fingerprint: u64) -> Result<Self, PortError> {
        let details = TypeDetail::__internal_new_from_parts(TypeVariant::Dynamic, type_name, 1, 1).map_err(|e| {
            PortError::Ipc {
                service: service.into(),
                detail: format!("the type name {type_name:?} is too long for iceoryx2: {e:?}"),
            }
        })?;
        Ok(Carried { details, type_name: type_name.into(), fingerprint })
    }

    /// Whether samples are of any length (a sequence), not one fixed size.
    pub(crate) fn is_sequence(&self) -> bool {
        self.details.variant() == TypeVariant::Dynamic
    }

    pub(crate) fn from_parts(
        service: &str,
        type_name: &str,
        size: usize,
        align: usize,
        fingerprint: u64,
    ) -> Result<Self, PortError> {
        let details =
            TypeDetail::__internal_new_from_parts(TypeVariant::FixedSize, type_name, size, align).map_err(|e| {
                PortError::Ipc {
                    service: service.into(),
                    detail: format!("the type name {type_name:?} is too long for iceoryx2: {e:?}"),
                }
            })?;
        Ok(Carried { details, type_name: type_name.into(), fingerprint })
    }

    /// The payload's size, bytes.
    pub(crate) fn size(&self) -> usize {
        self.details.size()
    }

    /// The payload's alignment, bytes.
    pub(crate) fn align(&self) -> usize {
        self.details.alignment()
    }
}

/// The service of an output port as its publisher sees it: payload and
/// header set from their details, written as bytes.
pub(crate) type OutputFactory = publish_subscribe::PortFactory<Ipc, [CustomPayloadMarker], CustomHeaderMarker>;
/// The service of an output port as a reader sees it: bytes of payload after a [`SampleHeader`].
pub(crate) type SourceFactory = publish_subscribe::PortFactory<Ipc, [CustomPayloadMarker], SampleHeader>;

fn service_name(service: &str) -> Result<ServiceName, PortError> {
    service.try_into().map_err(|e| perr(service, e))
}

/// The header's details: a [`SampleHeader`], as iceoryx2 takes them from the type.
fn header_details(service: &str) -> Result<TypeDetail, PortError> {
    // SAFETY: reading the name has no precondition
    let name = unsafe { <SampleHeader as ZeroCopySend>::type_name() };
    TypeDetail::__internal_new_from_parts(
        TypeVariant::FixedSize,
        name,
        std::mem::size_of::<SampleHeader>(),
        std::mem::align_of::<SampleHeader>(),
    )
    .map_err(|e| perr(service, e))
}

type OutputBuilder =
    iceoryx2::service::builder::publish_subscribe::Builder<[CustomPayloadMarker], CustomHeaderMarker, Ipc>;
type SourceBuilder = iceoryx2::service::builder::publish_subscribe::Builder<[CustomPayloadMarker], SampleHeader, Ipc>;

/// The builder of output port `service` carrying `carried`, for its publisher.
fn output_builder(node: &Node<Ipc>, service: &str, carried: &Carried) -> Result<OutputBuilder, PortError> {
    Ok(port_settings!(output_builder_raw(node, service, carried)?))
}

/// [`output_builder`] before the settings.
fn output_builder_raw(node: &Node<Ipc>, service: &str, carried: &Carried) -> Result<OutputBuilder, PortError> {
    let name = service_name(service)?;
    let header = header_details(service)?;
    // SAFETY: the payload's details are `carried`'s (a Rust type's own, or
    // a validated schema's, the layout every agent of that type uses,
    // checked by the fingerprint in the attributes); the header's are
    // SampleHeader's. The publisher writes exactly a SampleHeader and
    // `carried.size()` payload bytes per sample (`bytes::ByteOutput`).
    let builder = unsafe {
        node.service_builder(&name)
            .publish_subscribe::<[CustomPayloadMarker]>()
            .user_header::<CustomHeaderMarker>()
            .__internal_set_user_header_type_details(&header)
            .__internal_set_payload_type_details(&carried.details)
    };
    Ok(builder)
}

/// The builder of output port `service` carrying `carried`, for a reader.
fn source_builder(node: &Node<Ipc>, service: &str, carried: &Carried) -> Result<SourceBuilder, PortError> {
    Ok(port_settings!(source_builder_raw(node, service, carried)?))
}

/// [`source_builder`] before the settings.
fn source_builder_raw(node: &Node<Ipc>, service: &str, carried: &Carried) -> Result<SourceBuilder, PortError> {
    let name = service_name(service)?;
    // SAFETY: the payload's details are `carried`'s (see `output_builder`);
    // samples are handed out as bytes of that size, and as a Rust type only
    // by a typed view whose type has that size and alignment.
    let builder = unsafe {
        node.service_builder(&name)
            .publish_subscribe::<[CustomPayloadMarker]>()
            .user_header::<SampleHeader>()
            .__internal_set_payload_type_details(&carried.details)
    };
    Ok(builder)
}

/// Opens the keep-all service `service` (`port::keep_all`) beside an
/// output port carrying `carried`, for the output's keep-all publisher;
/// `None` when no keep-all reader made it.
pub(crate) fn keep_all_output_service(
    node: &Node<Ipc>,
    service: &str,
    carried: &Carried,
) -> Result<Option<OutputFactory>, PortError> {
    match keep_all_settings!(output_builder_raw(node, service, carried)?).open() {
        Ok(f) => Ok(Some(f)),
        Err(Open::DoesNotExist | Open::IsMarkedForDestruction) => Ok(None),
        Err(source) => Err(PortError::OpenService { service: service.into(), source }),
    }
}

/// Opens or creates the keep-all service `service` beside an output port
/// carrying `carried`, for a keep-all input to subscribe to.
pub(crate) fn keep_all_source_service(
    node: &Node<Ipc>,
    service: &str,
    carried: &Carried,
) -> Result<SourceFactory, PortError> {
    let mut attempt = 0;
    loop {
        attempt += 1;
        match keep_all_settings!(source_builder_raw(node, service, carried)?).open_or_create() {
            Ok(f) => return Ok(f),
            Err(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(Open::IsMarkedForDestruction))
                if attempt < MARKED_FOR_DESTRUCTION_ATTEMPTS =>
            {
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            Err(source) => return Err(PortError::Service { service: service.into(), source }),
        }
    }
}

/// Opens (or creates) the publish-subscribe service of output port
/// `service` carrying `carried`. A service it creates carries the port's
/// attributes ([`port_attributes_of`]); one it opens must have been created
/// for the same type and layout.
pub(crate) fn output_service(node: &Node<Ipc>, service: &str, carried: &Carried) -> Result<OutputFactory, PortError> {
    use PublishSubscribeOpenOrCreateError as OpenOrCreate;
    let attributes = port_attributes_of(service, &carried.type_name, carried.fingerprint)?;
    let mut attempt = 0;
    loop {
        attempt += 1;
        match output_builder(node, service, carried)?.open_or_create_with_attributes(&attributes) {
            Ok(f) => return Ok(f),
            Err(OpenOrCreate::PublishSubscribeOpenError(Open::IncompatibleAttributes)) => {
                // created by another build: say which layouts disagree
                let theirs = output_builder(node, service, carried)?.open().ok().and_then(|f| service_fingerprint(&f));
                return Err(other_attributes(service, &carried.type_name, carried.fingerprint, theirs));
            }
            Err(OpenOrCreate::PublishSubscribeOpenError(Open::IncompatibleTypes)) => {
                return Err(PortError::IncompatibleType {
                    service: service.into(),
                    type_name: carried.type_name.clone(),
                });
            }
            // The last owner of the service (an agent of the same name that
            // was killed while it stopped, or is still leaving) is removing
            // it: once it is gone the service can be created anew. Seen when
            // a supervisor restart came 0.5 s after such a death.
            Err(OpenOrCreate::PublishSubscribeOpenError(Open::IsMarkedForDestruction))
                if attempt < MARKED_FOR_DESTRUCTION_ATTEMPTS =>
            {
                tracing::debug!(service, attempt, "the port's service is being removed; trying again");
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            Err(source) => return Err(PortError::Service { service: service.into(), source }),
        }
    }
}

/// Why output port `service` of `type_name` (layout `ours`) cannot open the
/// service that exists with other attributes: another layout of the type
/// when the service says its fingerprint (`theirs`), else a service made by
/// another program.
fn other_attributes(service: &str, type_name: &str, ours: u64, theirs: Option<u64>) -> PortError {
    match theirs {
        Some(theirs) => {
            PortError::LayoutMismatch { service: service.into(), type_name: type_name.into(), ours, theirs }
        }
        None => PortError::Ipc {
            service: service.into(),
            detail: "the service exists with other attributes (made by another program?)".into(),
        },
    }
}

/// Opens the service of an existing output port carrying `carried`, for an
/// input to read it: never creates it, so a source that no agent has is
/// refused ([`PortError::NoSuchPort`]) and leaves no file behind; another
/// type, or another layout of the type (its fingerprint), is refused.
pub(crate) fn source_service(node: &Node<Ipc>, service: &str, carried: &Carried) -> Result<SourceFactory, PortError> {
    let mut attempt = 0;
    let factory = loop {
        attempt += 1;
        match source_builder(node, service, carried)?.open() {
            Ok(f) => break f,
            Err(Open::DoesNotExist) => return Err(PortError::NoSuchPort { service: service.into() }),
            Err(Open::IncompatibleTypes) => {
                return Err(PortError::IncompatibleType {
                    service: service.into(),
                    type_name: carried.type_name.clone(),
                });
            }
            // its owner is removing it (see output_service): it may come back at once
            Err(Open::IsMarkedForDestruction) if attempt < MARKED_FOR_DESTRUCTION_ATTEMPTS => {
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            Err(source) => return Err(PortError::OpenService { service: service.into(), source }),
        }
    };
    match service_fingerprint(&factory) {
        Some(theirs) if theirs != carried.fingerprint => Err(PortError::LayoutMismatch {
            service: service.into(),
            type_name: carried.type_name.clone(),
            ours: carried.fingerprint,
            theirs,
        }),
        _ => Ok(factory),
    }
}

type PortBuilder<T> = iceoryx2::service::builder::publish_subscribe::Builder<T, SampleHeader, Ipc>;

/// The builder of a port's service as a Rust type `T`, for tools that
/// publish or read a known type through iceoryx2 directly.
fn port_builder<T: Payload>(node: &Node<Ipc>, service: &str) -> Result<PortBuilder<T>, PortError> {
    let name = service_name(service)?;
    Ok(port_settings!(node.service_builder(&name).publish_subscribe::<T>().user_header::<SampleHeader>()))
}

/// The attributes of output port `service` (`nerve/ROBOT/AGENT/PORT`)
/// carrying `type_name` of layout `fingerprint`: its type name, layout
/// fingerprint, agent and port ([`port_attributes`]).
pub(crate) fn port_attributes_of(
    service: &str,
    type_name: &str,
    fingerprint: u64,
) -> Result<AttributeVerifier, PortError> {
    let mut parts = service.splitn(4, '/').skip(2);
    let (agent, port) = (parts.next().unwrap_or_default(), parts.next().unwrap_or_default());
    let fingerprint = fingerprint_text(fingerprint);
    let mut v = AttributeVerifier::new();
    for (key, value) in [
        (port_attributes::TYPE, type_name),
        (port_attributes::FINGERPRINT, fingerprint.as_str()),
        (port_attributes::AGENT, agent),
        (port_attributes::PORT, port),
    ] {
        if value.is_empty() {
            continue;
        }
        let (Ok(key), Ok(value)) = (AttributeKey::try_from(key), AttributeValue::try_from(value)) else {
            return Err(perr(service, format!("the attribute {key}={value} does not fit an iceoryx2 attribute")));
        };
        v = v.require(&key, &value).map_err(|e| perr(service, e))?;
    }
    Ok(v)
}

/// The layout fingerprint a port's service was created with, if it says.
pub fn service_fingerprint(factory: &impl iceoryx2::service::port_factory::PortFactory) -> Option<u64> {
    let key = AttributeKey::try_from(port_attributes::FINGERPRINT).ok()?;
    parse_fingerprint(&factory.attributes().key_value(&key, 0)?.to_string())
}

/// Opens (or creates) the publish-subscribe service of an output port as
/// the Rust type `T`, for a tool that publishes through iceoryx2 directly
/// (`nerve drive`). A service it creates carries the port's attributes;
/// one it opens must have been created for the same layout of `T`. Agents'
/// ports go through [`crate::port::bytes::ByteOutput`], which makes the
/// same service.
pub fn port_service<T: Payload>(
    node: &Node<Ipc>,
    service: &str,
) -> Result<publish_subscribe::PortFactory<Ipc, T, SampleHeader>, PortError> {
    use PublishSubscribeOpenOrCreateError as OpenOrCreate;
    let attributes = port_attributes_of(service, T::stable_type_name(), T::layout_fingerprint())?;
    let mut attempt = 0;
    loop {
        attempt += 1;
        match port_builder::<T>(node, service)?.open_or_create_with_attributes(&attributes) {
            Ok(f) => return Ok(f),
            Err(OpenOrCreate::PublishSubscribeOpenError(Open::IncompatibleAttributes)) => {
                let theirs = port_builder::<T>(node, service)?.open().ok().and_then(|f| service_fingerprint(&f));
                return Err(other_attributes(service, T::stable_type_name(), T::layout_fingerprint(), theirs));
            }
            Err(OpenOrCreate::PublishSubscribeOpenError(Open::IncompatibleTypes)) => {
                return Err(PortError::IncompatibleType {
                    service: service.into(),
                    type_name: T::stable_type_name().into(),
                });
            }
            Err(OpenOrCreate::PublishSubscribeOpenError(Open::IsMarkedForDestruction))
                if attempt < MARKED_FOR_DESTRUCTION_ATTEMPTS =>
            {
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            Err(source) => return Err(PortError::Service { service: service.into(), source }),
        }
    }
}

/// Opens the service of an existing output port as the Rust type `T`;
/// `None` when it does not exist or carries another type (used by tools
/// that probe a port's type).
pub fn existing_port_service<T: Payload>(
    node: &Node<Ipc>,
    service: &str,
) -> Option<publish_subscribe::PortFactory<Ipc, T, SampleHeader>> {
    port_builder::<T>(node, service).ok()?.open().ok()
}

/// Opens the event service of an existing output port, for an input's
/// listener: never creates it.
pub(crate) fn source_event(node: &Node<Ipc>, service: &str) -> Result<event::PortFactory<Ipc>, PortError> {
    use iceoryx2::service::builder::event::EventOpenError;
    let name = service_name(service)?;
    node.service_builder(&name)
        .event()
        .max_listeners(MAX_SUBSCRIBERS + 4)
        .max_notifiers(MAX_PUBLISHERS + 4)
        .max_nodes(MAX_NODES)
        .open()
        .map_err(|source| match source {
            EventOpenError::DoesNotExist => PortError::NoSuchPort { service: service.into() },
            source => PortError::OpenEvent { service: service.into(), source },
        })
}

/// Opens (or creates) the event service paired with an output port.
pub fn port_event(node: &Node<Ipc>, service: &str) -> Result<event::PortFactory<Ipc>, PortError> {
    let name = service_name(service)?;
    node.service_builder(&name)
        .event()
        .max_listeners(MAX_SUBSCRIBERS + 4)
        .max_notifiers(MAX_PUBLISHERS + 4)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(port_err!(Event, service))
}

/// Opens the service of any existing output port for a reader, with the
/// payload size and alignment the service itself says (a tool reading a
/// type it was not built with, [`crate::port::bytes::RawPort`]); returns it
/// and the payload's size. Refuses a service that is not a nerve port.
pub(crate) fn raw_source_service(node: &Node<Ipc>, service: &str) -> Result<(SourceFactory, usize), PortError> {
    let ipc = |detail: String| PortError::Ipc { service: service.into(), detail };
    let name: ServiceName = service.try_into().map_err(|e| ipc(format!("not a service name: {e:?}")))?;
    let details = <Ipc as iceoryx2::service::Service>::details(
        &name,
        node.config(),
        iceoryx2::service::messaging_pattern::MessagingPattern::PublishSubscribe,
    )
    .map_err(|e| ipc(format!("cannot read the service's details: {e:?}")))?
    .ok_or_else(|| PortError::NoSuchPort { service: service.into() })?;
    let types = details.static_details.publish_subscribe().message_type_details();
    let header = types.user_header;
    if header.size() != std::mem::size_of::<SampleHeader>() {
        return Err(ipc(format!(
            "its samples carry a {}-byte header, not nerve's {}-byte one: not a nerve port",
            header.size(),
            std::mem::size_of::<SampleHeader>()
        )));
    }
    let payload = types.payload;
    // the details are whatever the process that made the service wrote:
    // the same bounds as a schema's before they reach iceoryx2 again
    let align = payload.alignment();
    if !align.is_power_of_two()
        || align > shm_schemas::schema::MAX_ALIGN
        || payload.size() > shm_schemas::schema::MAX_SIZE
    {
        return Err(ipc(format!(
            "its payload is {} bytes aligned to {align}: not a layout nerve makes (align a power of two up to {}, \
             at most {} bytes); the process that created the service is not a nerve agent",
            payload.size(),
            shm_schemas::schema::MAX_ALIGN,
            shm_schemas::schema::MAX_SIZE
        )));
    }
    // SAFETY: the payload's type details are the service's own, read just
    // above and bounded; the samples are handed out as bytes only.
    let builder = unsafe {
        node.service_builder(&name)
            .publish_subscribe::<[CustomPayloadMarker]>()
            .user_header::<SampleHeader>()
            .__internal_set_payload_type_details(&payload)
    };
    let factory = builder.open().map_err(|source| match source {
        Open::DoesNotExist => PortError::NoSuchPort { service: service.into() },
        source => PortError::OpenService { service: service.into(), source },
    })?;
    Ok((factory, payload.size()))
}

/// The type name and layout fingerprint of the existing output port
/// `service`, from its attributes, without subscribing.
pub fn port_identity(node: &Node<Ipc>, service: &str) -> Option<(String, Option<u64>)> {
    let name: ServiceName = service.try_into().ok()?;
    let details = <Ipc as iceoryx2::service::Service>::details(
        &name,
        node.config(),
        iceoryx2::service::messaging_pattern::MessagingPattern::PublishSubscribe,
    )
    .ok()??;
    let attrs = details.static_details.attributes();
    let get = |key: &str| {
        let key = AttributeKey::try_from(key).ok()?;
        attrs.key_value(&key, 0).map(|v| v.to_string())
    };
    let type_name = get(port_attributes::TYPE)?;
    Some((type_name, get(port_attributes::FINGERPRINT).and_then(|t| port_attributes::parse_fingerprint(&t))))
}
