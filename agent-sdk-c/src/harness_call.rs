//! Calls in the C test harness: the test calls the agent's services (fixed
//! or sequence answers) and takes their answers, as the Rust harness's
//! `Harness::call` and `answers` do. A request waits for the agent's next
//! step, whose `nerve_serve` or `nerve_serve_seq` answers it; the answer
//! (or its refusal past a sequence's `max_len`) is then taken with
//! [`nerve_harness_call_take`], a sequence answer as the bytes of its
//! sample (header, then elements), as `nerve_harness_output` gives
//! sequence samples.

use crate::error::{Failure, guard, nerve_status};
use crate::harness::{harness, nerve_harness};
use crate::{text, zeroed_out};
use agent_sdk::port::{CallError, CallId};
use std::ffi::{c_char, c_void};

/// An answer to one of the test's calls: its bytes, or why there are none.
pub(crate) type Answered = (CallId, Result<Vec<u8>, CallError>);

/// Calls service `service` of the agent with a copy of the `len` bytes at
/// `request` (the request struct: another size is `NERVE_LAYOUT_MISMATCH`)
/// and writes the call's id to `*call` (may be NULL). The request waits for
/// the agent's next step (`nerve_harness_step`, or a deadline of
/// `nerve_harness_advance`), which answers it; take the answer with
/// [`nerve_harness_call_take`].
///
/// # Safety
/// `h` is null or a live harness; `service` is null or a NUL-terminated
/// string; `request` is null or readable for `len` bytes; `call` is null
/// or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_call(
    h: *mut nerve_harness,
    service: *const c_char,
    request: *const c_void,
    len: usize,
    call: *mut u64,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let id_out = unsafe { zeroed_out(call) };
        // SAFETY: the caller's contract
        let h = unsafe { harness(h) }?;
        // SAFETY: the caller's contract
        let service = unsafe { text(service, "service") }?;
        if request.is_null() {
            return Err(Failure::Null("request"));
        }
        let servers = &h.h.agent().ctx.calls.servers;
        let server = servers.iter().flatten().find(|s| s.name() == service).ok_or_else(|| Failure::NoPortNamed {
            direction: "service",
            port: service.to_owned(),
            known: servers.iter().flatten().map(|s| s.name().to_owned()).collect(),
        })?;
        let schema = server.request_schema();
        if len != schema.size {
            return Err(Failure::Size {
                direction: "service",
                port: service.to_owned(),
                type_name: schema.type_name.clone(),
                want: schema.size,
                given: len,
            });
        }
        // SAFETY: `request` is readable for `len` bytes by the caller's contract
        let bytes = unsafe { std::slice::from_raw_parts(request.cast::<u8>(), len) }.to_vec();
        let id = h.h.call(service, bytes).map_err(|source| Failure::Harness { source })?;
        if let Some(o) = id_out {
            *o = id.0;
        }
        Ok(())
    })
}

/// Takes the oldest answer service `service` gave the test's calls: writes
/// its call's id to `*call` (may be NULL), copies the answer into `dst`
/// (`size` bytes: at least the answer's; a sequence answer is its
/// sample's bytes, header then elements) and writes its size to `*len`.
/// `NERVE_NO_SAMPLE` when no answer is left; `NERVE_CALL_FAILED` for a
/// call that ended without one (its answer refused past the service's
/// `max_len`, or the answer function failed), `*call` naming it and the
/// message saying why.
///
/// # Safety
/// `h` is null or a live harness; `service` is null or a NUL-terminated
/// string; `dst` is null or writable for `size` bytes; `call` and `len`
/// are null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_call_take(
    h: *mut nerve_harness,
    service: *const c_char,
    call: *mut u64,
    dst: *mut c_void,
    size: usize,
    len: *mut usize,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let len = unsafe { len.as_mut() }.ok_or(Failure::Null("len"))?;
        *len = 0;
        // SAFETY: the caller's contract
        let id_out = unsafe { zeroed_out(call) };
        // SAFETY: the caller's contract
        let h = unsafe { harness(h) }?;
        // SAFETY: the caller's contract
        let service = unsafe { text(service, "service") }?;
        if dst.is_null() {
            return Err(Failure::Null("dst"));
        }
        let answered = h.h.answers::<Vec<u8>>(service).map_err(|source| Failure::Harness { source })?;
        let queue = h.answers.entry(service.to_owned()).or_default();
        queue.extend(answered);
        let Some((_, result)) = queue.front() else {
            return Err(Failure::NoOutput(service.to_owned()));
        };
        if let Ok(bytes) = result
            && bytes.len() > size
        {
            return Err(Failure::Size {
                direction: "service",
                port: service.to_owned(),
                type_name: "an answer".into(),
                want: bytes.len(),
                given: size,
            });
        }
        let Some((id, result)) = queue.pop_front() else { return Err(Failure::NoOutput(service.to_owned())) };
        if let Some(o) = id_out {
            *o = id.0;
        }
        let bytes = result.map_err(|source| Failure::Call { source })?;
        // SAFETY: `dst` is writable for `size` >= `bytes.len()` bytes by the
        // caller's contract, and cannot overlap the harness's own copy
        unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), dst.cast::<u8>(), bytes.len()) };
        *len = bytes.len();
        Ok(())
    })
}
