//! Calls answered with sequences, for C agents (issue 43): a service
//! whose answer is a header and any number of elements, up to the
//! `max_len` it declares, and a client of such a service (the map
//! builder's `plan`, whose answer is a `PlannedPath`). They are the SDK's
//! calls declared by layout with a sequence answer
//! ([`agent_sdk::dynamic::SchemaServer`], `Setup::serve_seq_of`): the
//! very iceoryx2 service a Rust `setup.serve_seq::<Req, T, H>` makes, so a
//! Rust `client_seq` and `nerve call` call a C server, and a C client
//! calls a Rust one; the router checks both sides' types on connect.
//!
//! The server answers in place: its answer function gets a
//! [`nerve_answer`], loans it at the length it needs
//! ([`nerve_answer_loan`], refused past `max_len` with `NERVE_TOO_LONG`:
//! the caller is then told its answer was too long) and writes the header
//! and elements in the service's shared memory. The client sends with
//! [`crate::call::nerve_call`] as for any call and takes each answer with
//! [`nerve_call_take_seq`]: header, elements and length, valid until its
//! next take on that client.

use crate::call::{AnswerDecl, SERVE_AT_MOST, client, declare_call, serving};
use crate::error::{Failure, guard, nerve_status};
use crate::own_type::nerve_type;
use crate::seq::{nerve_seq, nerve_seq_loan};
use crate::{nerve_ctx, nerve_port, nerve_setup, zeroed_out};
use agent_sdk::dynamic::{SeqAnswerLoan, ServeError};
use agent_sdk::port::CallError;
use std::ffi::{c_char, c_int, c_void};

/// The answer to one request of a sequence service, given to a
/// [`nerve_answer_seq_fn`] during its call only: loan it with
/// [`nerve_answer_loan`], then write it in place. Opaque.
#[allow(non_camel_case_types)]
#[derive(Debug)]
pub struct nerve_answer {
    /// the SDK's loan of this answer, alive during the answer function's call
    loan: *mut c_void,
    /// whether the answer's sequence has a header
    has_header: bool,
}

/// Answers one request of a sequence service: reads the request (the
/// request struct), loans the answer at the length it needs with
/// [`nerve_answer_loan`] and writes its header and elements in place.
/// Returns 0 to send it (an answer never loaned is one of 0 elements and a
/// zeroed header; after a loan refused past `max_len`, its caller is told
/// the answer was too long); anything else drops the request unanswered
/// (its caller sees the server gone).
#[allow(non_camel_case_types)]
pub type nerve_answer_seq_fn =
    Option<unsafe extern "C" fn(request: *const c_void, answer: *mut nerve_answer, user: *mut c_void) -> c_int>;

/// Declares service `name`: requests of layout `request` (a fixed-size
/// `nerve_type`) answered with sequences of `element` after `header`
/// (NULL: none), at most `max_len` elements an answer; element and header
/// are the agent's own structs (`NERVE_TYPE`) or built-ins
/// (`NERVE_BUILTIN`), as for `nerve_setup_output_seq`. It is the service
/// a Rust agent's `setup.serve_seq::<Req, T, H>(name, max_len)` of those
/// layouts makes: `nerve call AGENT/NAME '<json>'` and any client of those
/// layouts call it. A request wakes the agent's task like an input;
/// answer in `step` with [`nerve_serve_seq`]. Writes its handle to `*port`.
///
/// Call it in `init` only, with the `setup` given to it, from that thread.
/// The layouts and strings are read during the call and not kept.
///
/// # Safety
/// `setup` is null or the pointer given to `init`; `name` is null or a
/// NUL-terminated string; `request`, `element` and `header` are null or
/// valid `nerve_type`s; `port` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_serve_seq(
    setup: *mut nerve_setup,
    name: *const c_char,
    request: *const nerve_type,
    element: *const nerve_type,
    header: *const nerve_type,
    max_len: usize,
    port: *mut nerve_port,
) -> nerve_status {
    let answer = AnswerDecl::Seq { element, header, max_len };
    // SAFETY: the caller's contract
    guard(|| unsafe { declare_call(setup, name, request, answer, None, port) })
}

/// Declares client `name` of a service of requests `request` answered
/// with sequences of `element` after `header` (NULL: none), as
/// [`nerve_setup_serve_seq`] takes them; each call waits at most
/// `timeout_ns` for its answer (0: the SDK's default), at most 16 calls in
/// flight. Send with `nerve_call`, take answers with
/// [`nerve_call_take_seq`]. It calls the service it is wired to (`nerve
/// connect AGENT/NAME SERVER/SERVICE`, or `[[connect]]` in a launch file).
/// Writes its handle to `*port`.
///
/// # Safety
/// As for [`nerve_setup_serve_seq`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_client_seq(
    setup: *mut nerve_setup,
    name: *const c_char,
    request: *const nerve_type,
    element: *const nerve_type,
    header: *const nerve_type,
    timeout_ns: u64,
    port: *mut nerve_port,
) -> nerve_status {
    let answer = AnswerDecl::Seq { element, header, max_len: 0 };
    // SAFETY: the caller's contract
    guard(|| unsafe { declare_call(setup, name, request, answer, Some(timeout_ns), port) })
}

/// Loans `answer` at `n` elements and writes where to write it to
/// `*loan`: its header (zeroed; NULL for a sequence without one), room for
/// `n` elements (zeroed; NULL when `n` is 0) and `n`. A second loan
/// replaces the first. Past the service's `max_len`, `NERVE_TOO_LONG`:
/// nothing is loaned (`*loan` is zeroed), and if the answer function
/// returns 0 its caller is told the answer was too long.
///
/// Call it from inside the answer function only, with the `answer` it got.
///
/// # Safety
/// `answer` is null or the pointer given to the running answer function;
/// `loan` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_answer_loan(
    answer: *mut nerve_answer,
    n: usize,
    loan: *mut nerve_seq_loan,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let out = unsafe { loan.as_mut() }.ok_or(Failure::Null("loan"))?;
        *out = nerve_seq_loan { header: std::ptr::null_mut(), items: std::ptr::null_mut(), len: 0 };
        // SAFETY: the caller's contract
        let answer = unsafe { answer.as_mut() }.ok_or(Failure::Null("answer"))?;
        // SAFETY: `loan` is the running answer function's `SeqAnswerLoan`
        // (set by `nerve_serve_seq` for that call only)
        let seq = unsafe { answer.loan.cast::<SeqAnswerLoan<'_>>().as_mut() }.ok_or(Failure::Stale("answer"))?;
        let max_len = seq.max_len();
        let (header, items) = seq.loan(n).map_err(|e| match e {
            CallError::AnswerTooLong { service, len, max } => Failure::TooLong { port: service, len, max_len: max },
            source => Failure::Call { source },
        })?;
        debug_assert!(n <= max_len);
        *out = nerve_seq_loan {
            header: if answer.has_header { header.as_mut_ptr().cast() } else { std::ptr::null_mut() },
            items: if n == 0 { std::ptr::null_mut() } else { items.as_mut_ptr().cast() },
            len: n,
        };
        Ok(())
    })
}

/// Answers the requests waiting on sequence service `port` (at most 64;
/// the rest wait for the next step, which they wake): `answer` is called
/// once per request, in this thread, before this returns, with the
/// request, a [`nerve_answer`] to loan and fill, and `user`. Writes how
/// many were answered to `*answered` (may be NULL). When `answer` returns
/// non-zero, that request is dropped unanswered, the others are kept for
/// the next call, and the status is `NERVE_AGENT_FAILED`. When an answer
/// was refused past `max_len`, the other requests are answered and the
/// status is `NERVE_TOO_LONG`.
///
/// Call it from inside a `start`, `step` or `stop` callback, in its thread.
/// The pointers `answer` gets are valid during its call only.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `answer`
/// is null or a function of this signature, safe to call with `user`;
/// `answered` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_serve_seq(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    answer: nerve_answer_seq_fn,
    user: *mut c_void,
    answered: *mut usize,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let (count, f, server) = unsafe { serving(ctx, port, answer, answered, true) }?;
        let has_header = server.response_schema().sequence_shape().is_some_and(|s| s.items_at > 0);
        let result = server.serve_seq_up_to(SERVE_AT_MOST, |request, seq| {
            let mut handle = nerve_answer { loan: std::ptr::from_mut(seq).cast(), has_header };
            // SAFETY: `f` is the caller's function of this signature; the
            // request's bytes and the answer handle are valid during the call
            let code = unsafe { f(request.as_ptr().cast(), &raw mut handle, user) };
            if code == 0 { Ok(()) } else { Err(code) }
        });
        match result {
            Ok(n) => {
                if let Some(c) = count {
                    *c = n;
                }
                Ok(())
            }
            Err(ServeError::Call(CallError::AnswerTooLong { service, len, max })) => {
                Err(Failure::TooLong { port: service, len, max_len: max })
            }
            Err(ServeError::Call(source)) => Err(Failure::Call { source }),
            Err(ServeError::Answer(code)) => Err(Failure::AnswerFailed { port, code }),
        }
    })
}

/// Takes the oldest finished call of sequence client `port`: writes its
/// id to `*call` (may be NULL) and its answer to `*answer`: the header
/// (NULL for a sequence without one), the elements (NULL when there are
/// none) and their number, valid until the next `nerve_call_take_seq` on
/// this client. `NERVE_NO_SAMPLE` while none has finished;
/// `NERVE_CALL_FAILED` for a call that ended without an answer (timed out,
/// its server gone, the client unwired, or its answer refused as longer
/// than the service's `max_len`), `*call` naming it and the message saying
/// why. Never blocks.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `answer`
/// is null or writable; `call` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_call_take_seq(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    call: *mut u64,
    answer: *mut nerve_seq,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let id_out = unsafe { zeroed_out(call) };
        // SAFETY: the caller's contract
        let out = unsafe { answer.as_mut() }.ok_or(Failure::Null("answer"))?;
        *out = nerve_seq { header: std::ptr::null(), items: std::ptr::null(), len: 0 };
        // SAFETY: the caller's contract
        let c = unsafe { client(ctx, port) }?;
        let Some(shape) = c.client.response_schema().sequence_shape() else {
            return Err(Failure::WrongKind {
                port,
                what: "a client of fixed-size answers",
                use_instead: "nerve_call_take",
            });
        };
        let (id, result) = match c.stash.pop_front() {
            Some(f) => f,
            None => c.client.take().ok_or(Failure::NoSample(port))?,
        };
        if let Some(o) = id_out {
            *o = id.0;
        }
        let bytes = result.map_err(|source| Failure::Call { source })?;
        let n = shape.count_of(bytes.len()).ok_or(Failure::Invalid(format!(
            "client {port}: an answer of {} bytes is not a header and whole elements",
            bytes.len()
        )))?;
        // the elements' alignment: copied into 8-byte words (a sequence's alignment is at most 8)
        c.held.clear();
        c.held.resize(bytes.len().div_ceil(8), 0);
        let base = c.held.as_mut_ptr().cast::<u8>();
        // SAFETY: `held` has room for `bytes.len()` bytes, not overlapping `bytes`
        unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), base, bytes.len()) };
        *out = nerve_seq {
            header: if shape.items_at > 0 { base.cast_const().cast() } else { std::ptr::null() },
            // SAFETY: `items_at` is within the held bytes (`count_of` checked the length)
            items: if n == 0 { std::ptr::null() } else { unsafe { base.add(shape.items_at) }.cast_const().cast() },
            len: n,
        };
        Ok(())
    })
}
