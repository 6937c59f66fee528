//! `nerve call`'s caller ([`RawCaller`]): a client built from the layouts
//! the service records, not from Rust types, one call at a time, waited for.
//! A sequence answer (`call_seq`) is handed out as the bytes of its
//! `Seq<T, H>` sample, at their own length, which the sequence's schema
//! decodes.

use super::call::{ANSWERED_SUFFIX, CallError, call_settings, event_service, open_err, service_name};
use crate::world::Ipc;
use iceoryx2::port::client::Client as IoxClient;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::service::marker::{CustomHeaderMarker, CustomPayloadMarker};
use iceoryx2::service::port_factory::{event, request_response};
use shm_schemas::control::call::{SEQ_ANSWERED, SEQ_TOO_LONG, SeqAnswerHeader};
use std::time::Duration;

type RawClientPort =
    IoxClient<Ipc, [CustomPayloadMarker], CustomHeaderMarker, [CustomPayloadMarker], CustomHeaderMarker>;
type RawFactory = request_response::PortFactory<
    Ipc,
    [CustomPayloadMarker],
    CustomHeaderMarker,
    [CustomPayloadMarker],
    CustomHeaderMarker,
>;

/// A call made by a tool that was not built with the call's types
/// (`nerve call`): requests and answers as bytes of the layouts the
/// service itself says, one call at a time, waited for.
pub struct RawCaller {
    service: String,
    type_name: String,
    fingerprint: Option<u64>,
    request_size: usize,
    response_size: usize,
    /// whether answers are sequences (a [`SeqAnswerHeader`] before them)
    sequence: bool,
    client: RawClientPort,
    requests: Notifier<Ipc>,
    answered: Listener<Ipc>,
    _factories: (RawFactory, event::PortFactory<Ipc>, event::PortFactory<Ipc>),
}

impl std::fmt::Debug for RawCaller {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RawCaller").field("service", &self.service).field("type", &self.type_name).finish()
    }
}

/// Whether `detail` is a layout nerve makes (the bounds of a schema's).
fn sane(detail: &iceoryx2::service::static_config::message_type_details::TypeDetail) -> bool {
    let align = detail.alignment();
    align.is_power_of_two() && align <= shm_schemas::schema::MAX_ALIGN && detail.size() <= shm_schemas::schema::MAX_SIZE
}

impl RawCaller {
    /// Opens the existing call service `service` with the request and
    /// response layouts it was made with (never creates it).
    pub fn open(node: &Node<Ipc>, service: &str) -> Result<Self, CallError> {
        use iceoryx2::service::attribute::AttributeKey;
        use shm_schemas::services::port_attributes;
        let name = service_name(service)?;
        let details = <Ipc as iceoryx2::service::Service>::details(
            &name,
            node.config(),
            iceoryx2::service::messaging_pattern::MessagingPattern::RequestResponse,
        )
        .map_err(|e| open_err(service, e))?
        .ok_or_else(|| CallError::Open {
            service: service.into(),
            detail: "no agent offers it (is the server running, and is the name right? `nerve ps` lists the services)"
                .into(),
        })?;
        let attrs = details.static_details.attributes();
        let get = |key: &str| {
            let key = AttributeKey::try_from(key).ok()?;
            attrs.key_value(&key, 0).map(|v| v.to_string())
        };
        let type_name = get(port_attributes::TYPE).ok_or_else(|| CallError::Open {
            service: service.into(),
            detail: "it has no nerve type attribute: not a service of a nerve agent".into(),
        })?;
        let fingerprint = get(port_attributes::FINGERPRINT).and_then(|t| port_attributes::parse_fingerprint(&t));
        let config = details.static_details.request_response();
        let (req, resp) = (config.request_message_type_details(), config.response_message_type_details());
        if !sane(&req.payload) || !sane(&resp.payload) || !sane(&req.user_header) || !sane(&resp.user_header) {
            return Err(CallError::Open {
                service: service.into(),
                detail: "its layouts are not ones nerve makes; the process that created it is not a nerve agent".into(),
            });
        }
        // SAFETY: the payloads' and user headers' type details are the
        // service's own, read just above and bounded; requests are written
        // and answers read as bytes of exactly those sizes.
        let builder = unsafe {
            node.service_builder(&name)
                .request_response::<[CustomPayloadMarker], [CustomPayloadMarker]>()
                .request_user_header::<CustomHeaderMarker>()
                .response_user_header::<CustomHeaderMarker>()
                .__internal_set_request_header_type_details(&req.user_header)
                .__internal_set_response_header_type_details(&resp.user_header)
                .__internal_set_request_payload_type_details(&req.payload)
                .__internal_set_response_payload_type_details(&resp.payload)
        };
        // SAFETY: reading the name has no precondition
        let seq_header = unsafe { <SeqAnswerHeader as ZeroCopySend>::type_name() };
        let sequence = *resp.user_header.type_name() == seq_header;
        if sequence && resp.user_header.size() != std::mem::size_of::<SeqAnswerHeader>() {
            return Err(CallError::Open {
                service: service.into(),
                detail: format!(
                    "its answers' header is a {}-byte {seq_header}, not this build's {} bytes; rebuild the older side",
                    resp.user_header.size(),
                    std::mem::size_of::<SeqAnswerHeader>()
                ),
            });
        }
        let factory = call_settings!(builder).open().map_err(|e| open_err(service, e))?;
        let client = factory.client_builder().create().map_err(|e| open_err(service, e))?;
        let requests = event_service(node, service, false)?;
        let notifier = requests.notifier_builder().create().map_err(|e| open_err(service, e))?;
        let answered_name = format!("{service}{ANSWERED_SUFFIX}");
        let answered = event_service(node, &answered_name, true)?;
        let listener = answered.listener_builder().create().map_err(|e| open_err(&answered_name, e))?;
        Ok(RawCaller {
            service: service.into(),
            type_name,
            fingerprint,
            request_size: req.payload.size(),
            response_size: resp.payload.size(),
            sequence,
            client,
            requests: notifier,
            answered: listener,
            _factories: (factory, requests, answered),
        })
    }

    /// The call's type name, `call(Req -> Resp)`, as the service says.
    pub fn type_name(&self) -> &str {
        &self.type_name
    }

    /// The call's fingerprint ([`shm_schemas::control::call::call_fingerprint`]), if the service says.
    pub fn fingerprint(&self) -> Option<u64> {
        self.fingerprint
    }

    /// Sends `request` (exactly the request's size) and waits at most
    /// `timeout` for the answer, returned as bytes.
    pub fn call(&self, request: &[u8], timeout: Duration) -> Result<Vec<u8>, CallError> {
        let client = "nerve call".to_owned();
        let service = self.service.clone();
        if request.len() != self.request_size {
            return Err(CallError::Open {
                service,
                detail: format!("a {}-byte request for a {}-byte request type", request.len(), self.request_size),
            });
        }
        // SAFETY: one element of a FixedSize request type (set from the
        // service's details in `open`): `request_size` bytes
        let mut loan = unsafe { self.client.loan_custom_payload(1) }.map_err(|e| CallError::Open {
            service: service.clone(),
            detail: format!("cannot loan a request: {e:?}"),
        })?;
        let payload = loan.payload_mut();
        if payload.len() != request.len() {
            return Err(CallError::Open {
                service,
                detail: format!("loaned {} bytes for a {}-byte request", payload.len(), request.len()),
            });
        }
        // SAFETY: `payload` is `request.len()` writable one-byte elements, not overlapping `request`
        unsafe { std::ptr::copy_nonoverlapping(request.as_ptr(), payload.as_mut_ptr().cast::<u8>(), request.len()) };
        // SAFETY: every byte of the payload was written just above
        let pending = unsafe { loan.assume_init() }.send().map_err(|source| CallError::Send {
            client: client.clone(),
            service: service.clone(),
            source,
        })?;
        if pending.number_of_server_connections() == 0 {
            return Err(CallError::NoServer { client, service });
        }
        if let Err(e) = self.requests.notify() {
            tracing::warn!(service = %self.service, "cannot wake the server: {e:?}");
        }
        let deadline = std::time::Instant::now() + timeout;
        loop {
            match pending.receive() {
                Ok(Some(r)) if self.sequence => {
                    // SAFETY: the service's answers carry a SeqAnswerHeader
                    // (its type name and size, checked in `open`) as their
                    // user header; read unaligned, by value
                    let header =
                        unsafe { std::ptr::from_ref(r.user_header()).cast::<SeqAnswerHeader>().read_unaligned() };
                    return self.sequence_bytes(&header, super::bytes::payload_bytes(r.payload()));
                }
                Ok(Some(r)) => {
                    let bytes = super::bytes::payload_bytes(r.payload());
                    if bytes.len() != self.response_size {
                        return Err(CallError::Open {
                            service,
                            detail: format!("a {}-byte answer of a {}-byte type", bytes.len(), self.response_size),
                        });
                    }
                    return Ok(bytes.to_vec());
                }
                Ok(None) => {}
                Err(source) => return Err(CallError::Receive { port: client, service, source }),
            }
            if !pending.is_connected() {
                // an answer that came just before the server let go is read on the next turn
                if pending.has_response() {
                    continue;
                }
                return Err(CallError::ServerGone { client, service });
            }
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            if left.is_zero() {
                return Err(CallError::TimedOut { client, service, timeout });
            }
            // woken by the server's answer; at most 50 ms, to see a server gone
            let _ = self.answered.timed_wait(|_| {}, left.min(Duration::from_millis(50)));
        }
    }

    /// The sample bytes of a sequence answer of header `header` in `payload`,
    /// or why there are none.
    fn sequence_bytes(&self, header: &SeqAnswerHeader, payload: &[u8]) -> Result<Vec<u8>, CallError> {
        let (client, service) = ("nerve call".to_owned(), self.service.clone());
        match header.status {
            SEQ_ANSWERED => {}
            SEQ_TOO_LONG => {
                return Err(CallError::RefusedTooLong { client, service, len: header.items, max: header.max });
            }
            other => {
                return Err(CallError::Malformed { client, service, detail: format!("an answer of status {other}") });
            }
        }
        match usize::try_from(header.bytes).ok().and_then(|n| payload.get(..n)) {
            Some(bytes) => Ok(bytes.to_vec()),
            None => Err(CallError::Malformed {
                client,
                service,
                detail: format!("{} bytes said, {} sent", header.bytes, payload.len()),
            }),
        }
    }
}
