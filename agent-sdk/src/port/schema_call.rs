//! Calls declared by layout instead of Rust type, for agents that learn
//! their types at run time (the Python and C agents): the third kind of
//! call ([`Layout`]) beside the Rust types' fixed and sequence answers,
//! carried by the same server and client ([`super::CallServer`],
//! [`super::CallClient`]). A [`SchemaServer`] and a [`SchemaClient`] carry
//! requests and answers as bytes of the layouts [`Schema`]s describe: a
//! fixed-size request, and a fixed-size answer or a sequence answer (a
//! header and any number of elements, up to a declared maximum). They make
//! and open the very iceoryx2 service a typed [`super::Server`] or
//! [`super::SeqServer`] of Rust types of those layouts makes (the same
//! type details, attributes and events), so a Python or C client calls a
//! Rust server, a Rust client or `nerve call` calls a Python or C one, and
//! the router types them with the same call spec
//! ([`shm_schemas::control::call`]).
//!
//! Requests are copied in and answers copied out at the client (calls are
//! small and rare next to a port's samples); a server writes its answer in
//! place, a sequence answer loaned at the length it needs
//! ([`SeqAnswerLoan`]). The rest is every call's: a request wakes the
//! server's task like an input, a client never blocks, each call ends
//! answered, timed out, its server gone or unwired, and past the bound of
//! calls in flight a call is refused with nothing sent.

use super::bytes::payload_bytes;
use super::call::memory::Unanswered;
use super::call::{
    ActiveRequest, Answered, CallError, CallOptions, ClientPort, Factory, Kind, Pending, ServerPort, call_settings,
};
use super::call_seq::{answer_len, answer_slots, check_max_len};
use super::{CallClient, CallServer};
use crate::agent::{AgentError, Setup};
use crate::world::Ipc;
use iceoryx2::port::ReceiveError;
use iceoryx2::prelude::*;
use iceoryx2::response_mut_uninit::ResponseMutUninit;
use iceoryx2::service::attribute::AttributeVerifier;
use iceoryx2::service::builder::request_response::RequestResponseOpenOrCreateError;
use iceoryx2::service::marker::{CustomHeaderMarker, CustomPayloadMarker};
use iceoryx2::service::port_factory::server::ServerCreateError;
use iceoryx2::service::static_config::message_type_details::{TypeDetail, TypeVariant};
use shm_schemas::control::agent_to_router::{PortSpec, add_schema};
use shm_schemas::control::call::{SEQ_ANSWERED, SEQ_TOO_LONG, SeqAnswerHeader, call_fingerprint, call_type_name};
use shm_schemas::{Schema, SeqShape};
use std::mem::MaybeUninit;

type Markers = [CustomPayloadMarker];
/// An answer loaned, before it is written.
type Loaned = ResponseMutUninit<Ipc, [MaybeUninit<CustomPayloadMarker>], CustomHeaderMarker>;

/// A service an agent answers, declared by layout ([`Setup::serve_of`],
/// [`Setup::serve_seq_of`]).
pub type SchemaServer = CallServer<Layout>;

/// A client of a service, declared by layout ([`Setup::client_of`]); its
/// `take` hands out each answer's bytes: the answer layout's, or a
/// sequence sample's (header, padding, elements) at its own length.
pub type SchemaClient = CallClient<Layout>;

/// A finished call: its answer's bytes, or why there is none.
pub type Finished = (super::CallId, Result<Vec<u8>, CallError>);

/// The kind of a call declared by layout: a fixed-size request, answered
/// with a fixed-size answer or a sequence ([`Layout::sequence`]).
#[derive(Debug, Clone)]
pub struct Layout {
    request: Schema,
    response: Schema,
    type_name: String,
    fingerprint: u64,
    /// where a sequence answer's parts lie; `None` for a fixed answer
    seq: Option<SeqShape>,
}

impl Layout {
    /// Checks both layouts (from outside: valid, the request of a fixed
    /// size) for call port `port`: `response` is a fixed-size answer or a
    /// sequence's ([`Schema::sequence`]).
    pub fn of(port: &str, request: Schema, response: Schema) -> Result<Self, CallError> {
        for (what, s) in [("request", &request), ("answer", &response)] {
            s.validate().map_err(|e| CallError::Open {
                service: port.into(),
                detail: format!("its {what} layout {}: {e}", s.type_name),
            })?;
        }
        if request.sequence_shape().is_some() {
            return Err(CallError::Open {
                service: port.into(),
                detail: format!(
                    "its request {} is a sequence: a call takes fixed-size requests (its answer may be a sequence)",
                    request.type_name
                ),
            });
        }
        Ok(Layout {
            type_name: call_type_name(&request.type_name, &response.type_name),
            fingerprint: call_fingerprint(request.fingerprint(), response.fingerprint()),
            seq: response.sequence_shape(),
            request,
            response,
        })
    }

    /// Where a sequence answer's parts lie; `None` for a fixed answer.
    pub fn sequence(&self) -> Option<SeqShape> {
        self.seq
    }

    /// The request's layout.
    pub fn request(&self) -> &Schema {
        &self.request
    }

    /// The answer's layout (a sequence's schema for a sequence answer).
    pub fn response(&self) -> &Schema {
        &self.response
    }

    /// The iceoryx2 type details a Rust type of `schema`'s layout has.
    fn detail(schema: &Schema) -> Result<TypeDetail, String> {
        TypeDetail::__internal_new_from_parts(TypeVariant::FixedSize, &schema.type_name, schema.size, schema.align)
            .map_err(|e| format!("{e:?}"))
    }
}

impl Kind for Layout {
    type ReqPayload = Markers;
    type ReqHeader = CustomHeaderMarker;
    type Payload = Markers;
    type Header = CustomHeaderMarker;
    type Request = [u8];
    type Queued = Vec<u8>;
    type Value = Vec<u8>;
    type View<'a> = &'a [u8];

    fn spec(&self, port: &str) -> PortSpec {
        PortSpec { name: port.into(), type_name: self.type_name.clone(), fingerprint: self.fingerprint }
    }
    fn add_schemas(&self, schemas: &mut Vec<Schema>) {
        add_schema(schemas, self.request.clone());
        add_schema(schemas, self.response.clone());
    }
    fn request_layout(&self) -> (usize, usize) {
        (self.request.size, self.request.align)
    }
    fn answer_layout(&self) -> (usize, usize) {
        (self.response.size, self.response.align)
    }

    /// The builder of the service a typed call of these layouts makes: a
    /// typed call's request header is `()`, its answer a `Resp` after `()`
    /// or (a sequence) 8-byte words after a [`SeqAnswerHeader`].
    fn open(
        &self,
        node: &Node<Ipc>,
        name: &ServiceName,
        attributes: &AttributeVerifier,
        create: bool,
    ) -> Result<Factory<Self>, RequestResponseOpenOrCreateError> {
        use iceoryx2::service::builder::request_response::RequestResponseOpenError as Open;
        let details = || -> Result<_, String> {
            let request = Self::detail(&self.request)?;
            let (response, header) = match self.seq {
                None => (Self::detail(&self.response)?, TypeDetail::new::<()>(TypeVariant::FixedSize)),
                Some(_) => (
                    TypeDetail::new::<u64>(TypeVariant::Dynamic),
                    TypeDetail::new::<SeqAnswerHeader>(TypeVariant::FixedSize),
                ),
            };
            Ok((request, response, header))
        };
        let (request, response, header) = details().map_err(|e| {
            tracing::warn!(service = %name, "the layouts are not iceoryx2 types: {e}");
            RequestResponseOpenOrCreateError::RequestResponseOpenError(Open::IncompatibleRequestOrResponseType)
        })?;
        let unit = TypeDetail::new::<()>(TypeVariant::FixedSize);
        // SAFETY: the payloads' details are those of a `#[repr(C)]` type of
        // these layouts (checked in `Layout::of`) or of the sequence
        // answer's u64 words, the headers `()`'s or `SeqAnswerHeader`'s;
        // requests are written and answers read as bytes of exactly those
        // sizes (`send`, `receive`, `SeqAnswerLoan`), a sequence answer's
        // header as a `SeqAnswerHeader`, and `()` headers never touched.
        let builder = unsafe {
            node.service_builder(name)
                .request_response::<Markers, Markers>()
                .request_user_header::<CustomHeaderMarker>()
                .response_user_header::<CustomHeaderMarker>()
                .__internal_set_request_header_type_details(&unit)
                .__internal_set_response_header_type_details(&header)
                .__internal_set_request_payload_type_details(&request)
                .__internal_set_response_payload_type_details(&response)
        };
        let builder = call_settings!(builder);
        if create {
            builder.open_or_create_with_attributes(attributes)
        } else {
            builder.open_with_attributes(attributes).map_err(RequestResponseOpenOrCreateError::RequestResponseOpenError)
        }
    }

    fn server(&self, factory: &Factory<Self>, max_len: usize) -> Result<ServerPort<Self>, ServerCreateError> {
        match &self.seq {
            None => factory.server_builder().create(),
            Some(shape) => {
                let (words, slots) = answer_slots(shape, max_len);
                factory
                    .server_builder()
                    .initial_max_slice_len(words)
                    .allocation_strategy(AllocationStrategy::Static)
                    .override_response_preallocation(slots)
                    .create()
            }
        }
    }

    fn next_request(&self, port: &ServerPort<Self>) -> Result<Option<ActiveRequest<Self>>, ReceiveError> {
        port.receive()
    }

    fn send(
        &self,
        port: &ClientPort<Self>,
        request: &[u8],
        client: &str,
        service: &str,
    ) -> Result<Pending<Self>, CallError> {
        let size = self.request.size;
        let refused = |detail: String| CallError::Open { service: service.into(), detail };
        if request.len() != size {
            return Err(refused(format!(
                "a {}-byte request for the {size}-byte {}",
                request.len(),
                self.request.type_name
            )));
        }
        // SAFETY: one element of the FixedSize request type (`open`): `size` bytes
        let mut loan =
            unsafe { port.loan_custom_payload(1) }.map_err(|e| refused(format!("cannot loan a request: {e:?}")))?;
        let payload = loan.payload_mut();
        if payload.len() != size {
            return Err(refused(format!("loaned {} bytes for a {size}-byte request", payload.len())));
        }
        // SAFETY: `payload` is `size` writable one-byte elements, not overlapping `request`
        unsafe { std::ptr::copy_nonoverlapping(request.as_ptr(), payload.as_mut_ptr().cast::<u8>(), size) };
        // SAFETY: every byte of the request was written just above
        unsafe { loan.assume_init() }.send().map_err(|source| CallError::Send {
            client: client.into(),
            service: service.into(),
            source,
        })
    }

    fn queued(&self, request: &[u8], client: &str) -> Result<Vec<u8>, CallError> {
        if request.len() != self.request.size {
            return Err(CallError::Open {
                service: client.into(),
                detail: format!(
                    "a {}-byte request for the {}-byte {}",
                    request.len(),
                    self.request.size,
                    self.request.type_name
                ),
            });
        }
        Ok(request.to_vec())
    }

    fn next_answer(&self, pending: &Pending<Self>) -> Result<Option<Answered<Self>>, ReceiveError> {
        pending.receive()
    }
    fn view<'a>(&self, response: &'a Answered<Self>, client: &str, service: &str) -> Result<&'a [u8], CallError> {
        let bytes = payload_bytes(response.payload());
        let len = match &self.seq {
            None if bytes.len() == self.response.size => Ok(bytes.len()),
            None => Err(CallError::Malformed {
                client: client.into(),
                service: service.into(),
                detail: format!("{} bytes for the {}-byte answer", bytes.len(), self.response.size),
            }),
            Some(shape) => {
                // SAFETY: the service's answers carry a SeqAnswerHeader (`open`)
                let header =
                    unsafe { std::ptr::from_ref(response.user_header()).cast::<SeqAnswerHeader>().read_unaligned() };
                answer_len(&header, shape, bytes.len(), client, service)
            }
        }?;
        Ok(&bytes[..len])
    }
    fn view_of<'a>(&self, value: &'a Vec<u8>) -> &'a [u8] {
        value
    }
    fn to_value(&self, view: &[u8]) -> Vec<u8> {
        view.to_vec()
    }
}

/// Why an answer was not sent: the call's error, or the answering function's.
#[derive(Debug)]
pub enum ServeError<E> {
    /// receiving a request or loaning an answer failed, or (a sequence)
    /// an answer was longer than the declared maximum
    Call(CallError),
    /// the answering function failed; its request is dropped unanswered
    /// (its client's call ends as the server gone)
    Answer(E),
}

impl CallServer<Layout> {
    /// Answers each waiting request (at most `max`: what arrives meanwhile
    /// waits for the next step, whose wake-up is pending): `answer` gets the
    /// request's bytes and writes the answer's in place (zeroed first, of
    /// the answer layout's size). Returns how many were answered; the first
    /// error of `answer` ends the turn. For a service of fixed answers
    /// ([`Setup::serve_of`]); a sequence service answers with
    /// [`CallServer::serve_seq_up_to`].
    pub fn serve_up_to<E>(
        &self,
        max: usize,
        mut answer: impl FnMut(&[u8], &mut [u8]) -> Result<(), E>,
    ) -> Result<usize, ServeError<E>> {
        if self.kind().seq.is_some() {
            return Err(ServeError::Call(self.not_this_kind("a sequence", "serve_seq_up_to")));
        }
        let size = self.kind().response.size;
        self.serve_layout(max, |request, loan: &mut SeqAnswerLoan<'_>| {
            let out = loan.fixed(size).map_err(ServeError::Call)?;
            answer(request, out).map_err(ServeError::Answer)
        })
    }

    /// Answers each waiting request of a sequence service
    /// ([`Setup::serve_seq_of`]), at most `max` of them: `answer` gets the
    /// request's bytes and a [`SeqAnswerLoan`], loans the answer at the
    /// length it needs ([`SeqAnswerLoan::loan`]) and writes it in place.
    /// An answer loaned past the declared maximum is not sent: its client's
    /// call ends with [`CallError::RefusedTooLong`], the other requests are
    /// answered, then [`CallError::AnswerTooLong`] is returned. An answer
    /// never loaned is one of 0 elements (a zeroed header). The first error
    /// of `answer` ends the turn.
    pub fn serve_seq_up_to<E>(
        &self,
        max: usize,
        mut answer: impl FnMut(&[u8], &mut SeqAnswerLoan<'_>) -> Result<(), E>,
    ) -> Result<usize, ServeError<E>> {
        if self.kind().seq.is_none() {
            return Err(ServeError::Call(self.not_this_kind("a fixed-size", "serve_up_to")));
        }
        self.serve_layout(max, |request, loan| answer(request, loan).map_err(ServeError::Answer))
    }

    fn not_this_kind(&self, what: &str, instead: &str) -> CallError {
        CallError::Open {
            service: self.service().into(),
            detail: format!("it was declared with {what} answer: answer it with `{instead}`"),
        }
    }

    /// Each waiting request (at most `max`) handed to `answer` with a loan
    /// of its answer, sent when `answer` returns (a refusal when it loaned
    /// past the maximum); the first error of `answer` ends the turn.
    fn serve_layout<E>(
        &self,
        max: usize,
        mut answer: impl FnMut(&[u8], &mut SeqAnswerLoan<'_>) -> Result<(), ServeError<E>>,
    ) -> Result<usize, ServeError<E>> {
        let layout = self.kind();
        let max_len = self.max_len();
        if let Some(mem) = self.memory() {
            let (n, first) = mem.serve(max, |request| {
                let mut loan = SeqAnswerLoan { layout, max_len, to: Target::Memory(None), refused: None };
                answer(request, &mut loan).map_err(Unanswered::Failed)?;
                if let Some(len) = loan.refused {
                    return Err(Unanswered::TooLong { len, max: max_len });
                }
                Ok(loan.memory_bytes())
            });
            self.count_answered(n);
            return match first {
                Some(Unanswered::Failed(e)) => Err(e),
                Some(Unanswered::TooLong { len, max }) => {
                    tracing::warn!(service = self.service(), len, max, "an answer longer than the maximum was refused");
                    Err(ServeError::Call(CallError::AnswerTooLong { service: self.service().into(), len, max }))
                }
                None => Ok(n),
            };
        }
        let service = self.service();
        let mut failed = None;
        let result = self.each_request(max, |request| {
            let mut loan = SeqAnswerLoan { layout, max_len, to: Target::Request(request, None), refused: None };
            if let Err(e) = answer(payload_bytes(request.payload()), &mut loan) {
                failed = Some(e);
                return Ok(false);
            }
            loan.send(service)
        });
        match (failed, result) {
            (Some(e), _) => Err(e),
            (None, Ok(n)) => Ok(n),
            (None, Err(e)) => Err(ServeError::Call(e)),
        }
    }

    /// The request's layout.
    pub fn request_schema(&self) -> &Schema {
        &self.kind().request
    }

    /// The answer's layout (a sequence's schema for a sequence service).
    pub fn response_schema(&self) -> &Schema {
        &self.kind().response
    }
}

impl CallClient<Layout> {
    /// The request's layout.
    pub fn request_schema(&self) -> &Schema {
        &self.kind().request
    }

    /// The answer's layout (a sequence's schema for a sequence service).
    pub fn response_schema(&self) -> &Schema {
        &self.kind().response
    }
}

/// An answer's memory before it is loaned, and once loaned.
// one lives on the stack per answer: boxing the loan would allocate for each
#[allow(clippy::large_enum_variant)]
enum Target<'a> {
    /// a request at the iceoryx2 server, and its answer once loaned
    Request(&'a ActiveRequest<Layout>, Option<(Loaned, usize)>),
    /// in the test harness: the answer's bytes once loaned
    Memory(Option<(Vec<u8>, usize)>),
}

/// The answer to one request of a service declared by layout, loaned at
/// the length the server needs and written in place
/// ([`CallServer::serve_seq_up_to`]; a fixed answer is loaned for the
/// server by [`CallServer::serve_up_to`]).
pub struct SeqAnswerLoan<'a> {
    layout: &'a Layout,
    max_len: usize,
    to: Target<'a>,
    /// the length of an answer refused, past the maximum
    refused: Option<usize>,
}

impl std::fmt::Debug for SeqAnswerLoan<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SeqAnswerLoan")
            .field("type", &self.layout.response.type_name)
            .field("max_len", &self.max_len)
            .finish()
    }
}

impl SeqAnswerLoan<'_> {
    /// The most elements the answer may hold (the service's declared maximum).
    pub fn max_len(&self) -> usize {
        self.max_len
    }

    /// Loans the answer at `n` elements: its header's bytes (the header
    /// layout's size) and its elements' (`n` elements), all zeroed, to
    /// write in place. A second loan replaces the first. Past the declared
    /// maximum nothing is loaned, the request is answered with a refusal
    /// ([`CallError::RefusedTooLong`] at its client) and
    /// [`CallError::AnswerTooLong`] is returned.
    pub fn loan(&mut self, n: usize) -> Result<(&mut [u8], &mut [u8]), CallError> {
        let Some(shape) = self.layout.seq else {
            return Err(CallError::Open {
                service: self.layout.type_name.clone(),
                detail: "a fixed-size answer is not loaned by length".into(),
            });
        };
        if n > self.max_len {
            self.refused = Some(n);
            self.to.drop_loan();
            return Err(CallError::AnswerTooLong { service: self.layout.type_name.clone(), len: n, max: self.max_len });
        }
        self.refused = None;
        let len = shape.len_of(n).ok_or_else(|| CallError::AnswerTooLong {
            service: self.layout.type_name.clone(),
            len: n,
            max: self.max_len,
        })?;
        let header = header_size(self.layout);
        let bytes = self.to.loan(len, n, true)?;
        let (h, rest) = bytes.split_at_mut(shape.items_at);
        Ok((&mut h[..header], rest))
    }

    /// The whole answer of a fixed-size service, `size` bytes, zeroed.
    fn fixed(&mut self, size: usize) -> Result<&mut [u8], CallError> {
        self.to.loan(size, 1, false)
    }

    /// In the harness: the answer's bytes (a sequence of 0 elements if never loaned).
    fn memory_bytes(self) -> Vec<u8> {
        match self.to {
            Target::Memory(Some((bytes, _))) => bytes,
            _ => vec![0; self.layout.seq.map_or(self.layout.response.size, |s| s.items_at)],
        }
    }

    /// Sends the answer (a sequence of 0 elements if never loaned) or its
    /// refusal; `Err` is the refusal, for the server.
    fn send(mut self, service: &str) -> Result<bool, CallError> {
        if self.refused.is_none() && !self.to.is_loaned() {
            match self.layout.seq {
                Some(_) => self.loan(0).map(|_| ())?,
                None => self.fixed(self.layout.response.size).map(|_| ())?,
            }
        }
        let Target::Request(request, loaned) = self.to else { return Ok(true) };
        let refused = self.refused;
        let (mut response, n) = match (loaned, refused) {
            (Some(l), None) => l,
            _ => {
                // a refusal: no payload, its header says why
                // SAFETY: 0 elements of the answer's type (`Layout::open`)
                let l = unsafe { request.loan_custom_payload(0) }.map_err(|source| CallError::Loan {
                    service: service.into(),
                    len: 0,
                    source,
                })?;
                (l, 0)
            }
        };
        if self.layout.seq.is_some() {
            let header = SeqAnswerHeader {
                status: if refused.is_some() { SEQ_TOO_LONG } else { SEQ_ANSWERED },
                reserved: 0,
                items: refused.unwrap_or(n) as u64,
                max: self.max_len as u64,
                bytes: if refused.is_some() {
                    0
                } else {
                    self.layout.seq.and_then(|s| s.len_of(n)).unwrap_or(0) as u64
                },
            };
            // SAFETY: the service's answers carry a SeqAnswerHeader (`Layout::open`),
            // the response is the only reference to it until sent
            unsafe { std::ptr::from_mut(response.user_header_mut()).cast::<SeqAnswerHeader>().write_unaligned(header) };
        }
        // SAFETY: every byte of the answer was written (zeroed when loaned, then by the server)
        if let Err(e) = unsafe { response.assume_init() }.send() {
            // the client went away: nobody waits for this answer
            tracing::debug!(service, "an answer found no client: {e:?}");
        }
        match refused {
            Some(len) => {
                tracing::warn!(service, len, max = self.max_len, "an answer longer than the maximum was refused");
                Err(CallError::AnswerTooLong { service: service.into(), len, max: self.max_len })
            }
            None => Ok(true),
        }
    }
}

/// The size of a sequence answer's header (0 for none), or of a fixed answer.
fn header_size(layout: &Layout) -> usize {
    match &layout.response.kind {
        shm_schemas::schema::Kind::Sequence { header, .. } => header.size,
        _ => layout.response.size,
    }
}

impl Target<'_> {
    fn is_loaned(&self) -> bool {
        matches!(self, Target::Request(_, Some(_)) | Target::Memory(Some(_)))
    }

    fn drop_loan(&mut self) {
        match self {
            Target::Request(_, l) => *l = None,
            Target::Memory(l) => *l = None,
        }
    }

    /// Loans `len` bytes (of `n` elements, or the fixed answer), zeroed.
    fn loan(&mut self, len: usize, n: usize, seq: bool) -> Result<&mut [u8], CallError> {
        match self {
            Target::Memory(l) => Ok(&mut l.insert((vec![0; len], n)).0[..]),
            Target::Request(request, l) => {
                *l = None;
                // a sequence answer is 8-byte words (`Layout::open`), a fixed one 1 element
                let elements = if seq { len.div_ceil(8) } else { 1 };
                // SAFETY: `elements` elements of the answer's type (`Layout::open`)
                let mut loan = unsafe { request.loan_custom_payload(elements) }.map_err(|source| CallError::Loan {
                    service: String::new(),
                    len: n,
                    source,
                })?;
                let slots = loan.payload_mut();
                if slots.len() < len {
                    return Err(CallError::Open {
                        service: String::new(),
                        detail: format!("loaned {} bytes for a {len}-byte answer", slots.len()),
                    });
                }
                let all = slots.len();
                // SAFETY: `slots` is `all` writable one-byte elements: zeroed, so every byte initialised
                unsafe { std::ptr::write_bytes(slots.as_mut_ptr().cast::<u8>(), 0, all) };
                let (loan, _) = l.insert((loan, n));
                let slots = loan.payload_mut();
                // SAFETY: the first `len` of the `all` bytes, initialised just above
                Ok(unsafe { std::slice::from_raw_parts_mut(slots.as_mut_ptr().cast::<u8>(), len) })
            }
        }
    }
}

// ---------------------------------------------------------------- declaring

impl Setup {
    /// Declares service `port`, requests of layout `request` answered with
    /// `response` (both fixed-size), for an agent that learns its types at
    /// run time (a Python or C agent): the service a [`Setup::serve`] of
    /// Rust types of those layouts makes.
    pub fn serve_of(&mut self, port: &str, request: Schema, response: Schema) -> Result<SchemaServer, AgentError> {
        if response.sequence_shape().is_some() {
            return Err(AgentError::Config(format!(
                "service {port:?}: its answer {} is a sequence; declare it with `serve_seq_of` and its max_len",
                response.type_name
            )));
        }
        self.serve_layout(port, Layout::of(port, request, response)?, 1)
    }

    /// Declares service `port`, requests of layout `request` answered with
    /// sequences of `answer` ([`Schema::sequence`] of a header and an
    /// element) of at most `max_len` elements: the service a
    /// [`Setup::serve_seq`] of Rust types of those layouts makes.
    pub fn serve_seq_of(
        &mut self,
        port: &str,
        request: Schema,
        answer: Schema,
        max_len: usize,
    ) -> Result<SchemaServer, AgentError> {
        let layout = Layout::of(port, request, answer)?;
        let Some(shape) = layout.seq else {
            return Err(AgentError::Config(format!(
                "service {port:?}: its answer {} is not a sequence; declare it with `serve_of`",
                layout.response.type_name
            )));
        };
        check_max_len(port, &layout.response.type_name, &shape, max_len)?;
        self.serve_layout(port, layout, max_len)
    }

    fn serve_layout(&mut self, port: &str, layout: Layout, max_len: usize) -> Result<SchemaServer, AgentError> {
        self.check_call_port(port)?;
        let service = self.world.robot().port_service(self.name.as_str(), port);
        self.calls.add(&layout, port, true, &mut self.schemas);
        let (server, side) = CallServer::bind_kind(&self.binding, port, &service, max_len, layout)?;
        self.calls.add_memory(server.memory_port());
        self.inputs.push(side);
        Ok(server)
    }

    /// Declares client `port` of a service of layouts `request` and
    /// `response` (see [`Setup::serve_of`]; `response` a sequence's schema
    /// for a service of sequence answers, [`Setup::serve_seq_of`]), with
    /// `options`.
    pub fn client_of(
        &mut self,
        port: &str,
        request: Schema,
        response: Schema,
        options: CallOptions,
    ) -> Result<SchemaClient, AgentError> {
        self.check_call_port(port)?;
        let layout = Layout::of(port, request, response)?;
        self.calls.add(&layout, port, false, &mut self.schemas);
        let (client, side) = CallClient::bind_kind(&self.binding, port, options, layout);
        self.calls.add_memory(client.memory_port());
        self.inputs.push(side);
        Ok(client)
    }

    fn check_call_port(&self, port: &str) -> Result<(), AgentError> {
        shm_schemas::names::validate_port_name(port).map_err(|e| AgentError::Config(e.to_string()))?;
        if self.outputs.iter().any(|p| p.name == port) || self.inputs.iter().any(|p| p.name() == port) {
            return Err(AgentError::Config(format!("port {port:?} is declared twice")));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::Layout;
    use crate::port::bytes::{Binding, DynInput as _};
    use crate::port::call::{CallError, CallId, CallOptions, Kind as _};
    use crate::port::{CallClient, CallServer, SeqClient, SeqServer};
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::control::call::call_seq_spec;
    use shm_schemas::payloads::{Scalar, Tick};
    use shm_schemas::{Described as _, Seq};
    use std::sync::Arc;
    use std::time::Duration;

    fn tick_bytes(t: &Tick) -> Vec<u8> {
        [t.seq.to_le_bytes(), t.stamp_ns.to_le_bytes()].concat()
    }

    fn word(bytes: &[u8], at: usize) -> u64 {
        let mut w = [0u8; 8];
        w.copy_from_slice(&bytes[at..at + 8]);
        u64::from_le_bytes(w)
    }

    /// Takes the client's next finished call, waiting (bounded) for it.
    fn next<R>(take: impl Fn() -> Option<(CallId, R)>) -> (CallId, R) {
        for _ in 0..500 {
            if let Some(done) = take() {
                return done;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        panic!("no call finished within 1 s");
    }

    /// Serves (bounded in time) until one request is handled; returns what serving said.
    fn serve_one<T>(serve: impl Fn() -> Result<usize, T>) -> Result<usize, T> {
        for _ in 0..500 {
            match serve() {
                Ok(0) => std::thread::sleep(Duration::from_millis(2)),
                other => return other,
            }
        }
        panic!("no request came within 1 s");
    }

    /// A service declared by layout with a sequence answer is the typed
    /// one's (the same call spec, the same iceoryx2 service): a typed Rust
    /// `client_seq` calls it and reads answers of 0 and 3 elements written
    /// in place, one past its max_len is refused on both sides; and a
    /// client declared by layout calls a typed `serve_seq` and gets the
    /// sample's bytes.
    #[test]
    fn a_sequence_service_by_layout_is_the_typed_one() {
        let world = World::new(&format!("layoutseq{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = Arc::new(world.node("test").expect("node"));
        let robot = world.robot().clone();
        let layout = Layout::of("plan", Tick::schema(), Seq::<Scalar, Tick>::schema()).expect("layout");
        let typed = call_seq_spec::<Tick, Scalar, Tick>("plan");
        let spec = layout.spec("plan");
        assert_eq!((spec.type_name, spec.fingerprint), (typed.type_name, typed.fingerprint));
        let binding = Binding::Shm(node.clone());
        let service = robot.port_service("c", "plan");
        let (server, _) = CallServer::bind_kind(&binding, "plan", &service, 5, layout.clone()).expect("server");
        let options = CallOptions { timeout: Duration::from_secs(5), max_in_flight: 4 };
        let (client, side) = SeqClient::<Tick, Scalar, Tick>::bind(&binding, "planner", options).expect("client");
        assert!(side.connect(&node, &robot, "c", "plan").expect("wired"));
        let serve = || {
            server.serve_seq_up_to(8, |request, loan| -> Result<(), ()> {
                let n = word(request, 0) as usize;
                if let Ok((header, items)) = loan.loan(n) {
                    header.copy_from_slice(request);
                    for (i, item) in items.chunks_exact_mut(16).enumerate() {
                        item[..8].copy_from_slice(&(i as f64).to_le_bytes());
                        item[8..].copy_from_slice(&request[8..16]);
                    }
                }
                Ok(())
            })
        };
        for n in [0u64, 3] {
            let id = client.call(&Tick { seq: n, stamp_ns: 9 }).expect("call");
            assert_eq!(serve_one(serve).expect("served"), 1);
            let (got, answer) = next(|| client.take());
            let (header, items) = answer.expect("answered");
            assert_eq!((got, header), (id, Tick { seq: n, stamp_ns: 9 }));
            assert_eq!(items, (0..n).map(|i| Scalar { value: i as f64, stamp_ns: 9 }).collect::<Vec<_>>());
        }
        let id = client.call(&Tick { seq: 6, stamp_ns: 9 }).expect("call");
        match serve_one(serve) {
            Err(super::ServeError::Call(CallError::AnswerTooLong { len: 6, max: 5, .. })) => {}
            other => panic!("an answer past max_len: {other:?}"),
        }
        match next(|| client.take()) {
            (got, Err(CallError::RefusedTooLong { len: 6, max: 5, .. })) => assert_eq!(got, id),
            other => panic!("the client of a refused answer: {other:?}"),
        }

        // a client by layout of a typed sequence server
        let typed_service = robot.port_service("rust", "plan");
        let (typed, _) = SeqServer::<Tick, Scalar, Tick>::bind(&binding, "plan", &typed_service, 5).expect("server");
        let (by_layout, side) = CallClient::bind_kind(&binding, "lplanner", options, layout);
        assert!(side.connect(&node, &robot, "rust", "plan").expect("wired"));
        let id = by_layout.call(&tick_bytes(&Tick { seq: 2, stamp_ns: 4 })).expect("call");
        let answer = |t: &Tick| (*t, (0..t.seq).map(|i| Scalar { value: i as f64, stamp_ns: 5 }).collect());
        assert_eq!(serve_one(|| typed.serve(answer)).expect("served"), 1);
        let (got, bytes) = next(|| by_layout.take());
        let bytes = bytes.expect("answered");
        assert_eq!((got, bytes.len()), (id, 16 + 2 * 16));
        assert_eq!((word(&bytes, 0), word(&bytes, 8), word(&bytes, 40)), (2, 4, 5));
        assert_eq!(f64::from_le_bytes(bytes[32..40].try_into().expect("8 bytes")), 1.0);
    }
}
