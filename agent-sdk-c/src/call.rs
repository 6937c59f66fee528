//! Calls for C agents (issue 43 over the SDK's calls, docs/calls.md): a
//! service the agent answers and a client of another agent's service,
//! each declared in `init` by its request and answer layouts (fixed-size
//! `nerve_type`s). They are the SDK's calls declared by layout
//! ([`agent_sdk::dynamic::SchemaServer`]/[`SchemaClient`]): the same
//! iceoryx2 service a Rust `setup.serve::<Req, Resp>` makes, so `nerve
//! call`, a Rust client or a Python one call a C server, and a C client
//! calls any of theirs. The router wires them as any call
//! (`nerve connect AGENT/CLIENT SERVER/SERVICE`).
//!
//! The step model is the runtime's: a request wakes the server's task
//! like an input, and the agent answers what waits in its step
//! ([`nerve_serve`], a C function called once per request, in the step's
//! thread). A client never blocks unless asked to: [`nerve_call`] sends
//! and returns an id, [`nerve_call_take`] gives finished calls in a later
//! step; [`nerve_call_wait`] sends and waits in the step, at most the
//! client's timeout. Requests and answers are copied (calls are small).
//!
//! In the test harness the ports are the SDK harness's: where it does not
//! carry calls, a call port declared there is kept (the agent's `init`
//! succeeds) and each use of it is `NERVE_NOT_IN_HARNESS`.

use crate::error::{Failure, guard, nerve_status};
use crate::own_type::{nerve_type, part_schema};
use crate::seq::sequence;
use crate::{live, nerve_ctx, nerve_port, nerve_setup, text, zeroed_out};
use agent_sdk::AgentError;
use agent_sdk::dynamic::{SchemaClient, SchemaServer, ServeError};
use agent_sdk::port::{CallError, CallOptions};
use std::collections::VecDeque;
use std::ffi::{c_char, c_int, c_void};
use std::time::{Duration, Instant};

/// The first server handle: servers are `SERVER_BASE`, ... (apart from
/// inputs, outputs and clients, so one given for another is refused).
pub(crate) const SERVER_BASE: nerve_port = 0x0002_0000;
/// The first client handle.
const CLIENT_BASE: nerve_port = 0x0003_0000;
/// The most requests one [`nerve_serve`] answers; what arrives meanwhile
/// waits for the next step, which its wake-up brings.
pub(crate) const SERVE_AT_MOST: usize = 64;

/// A finished call as the SDK gives it.
type Finished = (agent_sdk::port::CallId, Result<Vec<u8>, CallError>);

/// A client and the finished calls [`nerve_call_wait`] took while it waited
/// for its own, for [`nerve_call_take`] to give out.
#[derive(Debug)]
pub(crate) struct ClientPort {
    pub(crate) client: SchemaClient,
    pub(crate) stash: VecDeque<Finished>,
    /// the last sequence answer `nerve_call_take_seq` gave (8-aligned), valid until the next
    pub(crate) held: Vec<u64>,
}

/// The call ports of a C agent: `None` for one declared in the test
/// harness, which does not carry calls.
#[derive(Debug, Default)]
pub(crate) struct Calls {
    pub(crate) servers: Vec<Option<SchemaServer>>,
    pub(crate) clients: Vec<Option<ClientPort>>,
}

/// Answers one request: reads the request (`request`, the request
/// struct) and writes the answer in place (`answer`, the answer struct,
/// zeroed first). Returns 0 to send it; anything else drops the request
/// unanswered (its caller's call ends as the server gone).
#[allow(non_camel_case_types)]
pub type nerve_answer_fn =
    Option<unsafe extern "C" fn(request: *const c_void, answer: *mut c_void, user: *mut c_void) -> c_int>;

/// The port's index past `base`, or the failure naming what it is not.
pub(crate) fn index(port: nerve_port, base: nerve_port, len: usize, what: &'static str) -> Result<usize, Failure> {
    port.checked_sub(base)
        .and_then(|i| usize::try_from(i).ok())
        .filter(|i| *i < len)
        .ok_or(Failure::UnknownPort { port, what })
}

/// How a call port's answer is declared.
pub(crate) enum AnswerDecl {
    /// a fixed-size answer of this layout
    Fixed(*const nerve_type),
    /// a sequence of `element` after `header` (null: none); a service's
    /// answers hold at most `max_len` elements
    Seq { element: *const nerve_type, header: *const nerve_type, max_len: usize },
}

/// Declares a call port (`serve`: a service, else a client with `timeout_ns`).
///
/// # Safety
/// As for [`nerve_setup_serve`]; the types in `answer` null or valid.
pub(crate) unsafe fn declare_call(
    setup: *mut nerve_setup,
    name: *const c_char,
    request: *const nerve_type,
    answer: AnswerDecl,
    client_timeout_ns: Option<u64>,
    port: *mut nerve_port,
) -> Result<(), Failure> {
    // SAFETY: the caller's contract
    let (setup, out) = unsafe { (setup.as_mut(), port.as_mut()) };
    let setup = setup.ok_or(Failure::Null("setup"))?;
    let out = out.ok_or(Failure::Null("port"))?;
    // SAFETY: the caller's contract
    let name = unsafe { text(name, "name") }?;
    // SAFETY: `sdk` is the SDK's setup during `init`, null after it
    let sdk = unsafe { setup.sdk.as_mut() }.ok_or(Failure::Stale("setup"))?;
    // SAFETY: the caller's contract
    let request = unsafe { part_schema(request, name, "request") }?;
    let (answer, max_len) = match answer {
        // SAFETY: the caller's contract
        AnswerDecl::Fixed(answer) => (unsafe { part_schema(answer, name, "answer") }?, None),
        // SAFETY: the caller's contract
        AnswerDecl::Seq { element, header, max_len } => (unsafe { sequence(name, element, header) }?, Some(max_len)),
    };
    let sdk_err = |source| Failure::Sdk { port: name.to_owned(), source };
    // a call port in the test harness: kept, refused when used
    let harness = |e: &AgentError| matches!(e, AgentError::Call(CallError::NotInHarness { .. }));
    let (base, index) = match client_timeout_ns {
        None => {
            let server = match max_len {
                None => sdk.serve_of(name, request, answer),
                Some(max_len) => sdk.serve_seq_of(name, request, answer, max_len),
            };
            let server = match server {
                Ok(s) => Some(s),
                Err(e) if harness(&e) => None,
                Err(e) => return Err(sdk_err(e)),
            };
            setup.calls.servers.push(server);
            (SERVER_BASE, setup.calls.servers.len() - 1)
        }
        Some(ns) => {
            let timeout = if ns == 0 { CallOptions::default().timeout } else { Duration::from_nanos(ns) };
            let options = CallOptions { timeout, ..CallOptions::default() };
            let client = match sdk.client_of(name, request, answer, options) {
                Ok(client) => Some(ClientPort { client, stash: VecDeque::new(), held: Vec::new() }),
                Err(e) if harness(&e) => None,
                Err(e) => return Err(sdk_err(e)),
            };
            setup.calls.clients.push(client);
            (CLIENT_BASE, setup.calls.clients.len() - 1)
        }
    };
    let index = nerve_port::try_from(index).map_err(|_| Failure::TooManyPorts)?;
    *out = base.checked_add(index).filter(|p| *p < base.saturating_add(0x0001_0000)).ok_or(Failure::TooManyPorts)?;
    Ok(())
}

/// Declares service `name`: requests of layout `request` answered with
/// layout `answer` (both fixed-size `nerve_type`s: the agent's own struct,
/// `NERVE_TYPE`, or a built-in one by name, `NERVE_BUILTIN(nerve_Tick)`).
/// It is the service a Rust agent's `setup.serve::<Req, Resp>(name)` of
/// those layouts makes: `nerve call AGENT/NAME '<json>'` and any client of
/// those layouts call it. A request wakes the agent's task like an input;
/// answer in `step` with [`nerve_serve`]. Writes its handle to `*port`.
///
/// Call it in `init` only, with the `setup` given to it, from that thread.
/// The layouts and strings are read during the call and not kept.
///
/// # Safety
/// `setup` is null or the pointer given to `init`; `name` is null or a
/// NUL-terminated string; `request` and `answer` are null or valid
/// `nerve_type`s; `port` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_serve(
    setup: *mut nerve_setup,
    name: *const c_char,
    request: *const nerve_type,
    answer: *const nerve_type,
    port: *mut nerve_port,
) -> nerve_status {
    // SAFETY: the caller's contract
    guard(|| unsafe { declare_call(setup, name, request, AnswerDecl::Fixed(answer), None, port) })
}

/// Declares client `name` of a service of layouts `request` and `answer`
/// (as [`nerve_setup_serve`] takes them), each call waiting at most
/// `timeout_ns` for its answer (0: the SDK's default, 2 s), at most 16
/// calls in flight. It calls the service it is wired to (`nerve connect
/// AGENT/NAME SERVER/SERVICE`, or `[[connect]]` in a launch file). Writes
/// its handle to `*port`.
///
/// # Safety
/// As for [`nerve_setup_serve`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_client(
    setup: *mut nerve_setup,
    name: *const c_char,
    request: *const nerve_type,
    answer: *const nerve_type,
    timeout_ns: u64,
    port: *mut nerve_port,
) -> nerve_status {
    // SAFETY: the caller's contract
    guard(|| unsafe { declare_call(setup, name, request, AnswerDecl::Fixed(answer), Some(timeout_ns), port) })
}

/// What `nerve_serve` and `nerve_serve_seq` first do: `*answered` zeroed
/// (when given), the answer function present, and server `port`, whose
/// answers are sequences when `seq` (else the status names the function
/// to use instead).
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `answered`
/// is null or writable.
pub(crate) unsafe fn serving<'a, F>(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    answer: Option<F>,
    answered: *mut usize,
    seq: bool,
) -> Result<(Option<&'a mut usize>, F, &'a SchemaServer), Failure> {
    // SAFETY: the caller's contract
    let count = unsafe { zeroed_out(answered) };
    let f = answer.ok_or(Failure::Null("answer"))?;
    // SAFETY: the caller's contract
    let ctx = unsafe { live(ctx) }?;
    let i = index(port, SERVER_BASE, ctx.calls.servers.len(), "serve")?;
    let server = ctx.calls.servers.get(i).and_then(Option::as_ref).ok_or(Failure::NotInHarness(port))?;
    if server.response_schema().sequence_shape().is_some() != seq {
        let (what, use_instead) = if seq {
            ("a service of fixed-size answers", "nerve_serve")
        } else {
            ("a service of sequence answers", "nerve_serve_seq")
        };
        return Err(Failure::WrongKind { port, what, use_instead });
    }
    Ok((count, f, server))
}

/// Answers the requests waiting on service `port` (at most 64; the rest
/// wait for the next step, which they wake): `answer` is called once per
/// request, in this thread, before this returns, with the request, an
/// answer zeroed to fill in, and `user`. Writes how many were answered to
/// `*answered` (may be NULL). When `answer` returns non-zero, that
/// request is dropped unanswered (its caller sees the server gone), the
/// others are kept for the next call, and the status is
/// `NERVE_AGENT_FAILED`.
///
/// Call it from inside a `start`, `step` or `stop` callback, in its thread.
/// The pointers `answer` gets are valid during its call only.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `answer`
/// is null or a function of this signature, safe to call with `user`;
/// `answered` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_serve(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    answer: nerve_answer_fn,
    user: *mut c_void,
    answered: *mut usize,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let (count, f, server) = unsafe { serving(ctx, port, answer, answered, false) }?;
        let result = server.serve_up_to(SERVE_AT_MOST, |request, slot| {
            // SAFETY: `f` is the caller's function of this signature; the
            // request's bytes and the answer's slot (zeroed, of the answer
            // layout's size) are valid during the call
            let code = unsafe { f(request.as_ptr().cast(), slot.as_mut_ptr().cast(), user) };
            if code == 0 { Ok(()) } else { Err(code) }
        });
        match result {
            Ok(n) => {
                if let Some(c) = count {
                    *c = n;
                }
                Ok(())
            }
            Err(ServeError::Call(source)) => Err(Failure::Call { source }),
            Err(ServeError::Answer(code)) => Err(Failure::AnswerFailed { port, code }),
        }
    })
}

/// The live context and client `port`.
///
/// # Safety
/// `ctx` is null or a callback's context.
pub(crate) unsafe fn client<'a>(ctx: *mut nerve_ctx, port: nerve_port) -> Result<&'a mut ClientPort, Failure> {
    // SAFETY: the caller's contract
    let ctx = unsafe { live(ctx) }?;
    let i = index(port, CLIENT_BASE, ctx.calls.clients.len(), "client")?;
    ctx.calls.clients.get_mut(i).and_then(Option::as_mut).ok_or(Failure::NotInHarness(port))
}

/// `len` bytes at `request`, checked against the request layout's size.
///
/// # Safety
/// `request` is null or readable for `len` bytes, for `'a`.
unsafe fn request_bytes<'a>(
    c: &ClientPort,
    port: nerve_port,
    request: *const c_void,
    len: usize,
) -> Result<&'a [u8], Failure> {
    if request.is_null() {
        return Err(Failure::Null("request"));
    }
    let schema = c.client.request_schema();
    if len != schema.size {
        return Err(Failure::CallSize {
            port,
            what: "request",
            type_name: schema.type_name.clone(),
            want: schema.size,
            given: len,
        });
    }
    // SAFETY: readable for `len` bytes by the caller's contract
    Ok(unsafe { std::slice::from_raw_parts(request.cast::<u8>(), len) })
}

/// Copies a finished call's answer into `answer` (`size` bytes), or its failure.
///
/// # Safety
/// `answer` is writable for `size` bytes (checked not null).
unsafe fn give(
    c: &ClientPort,
    port: nerve_port,
    result: Result<Vec<u8>, CallError>,
    answer: *mut c_void,
    size: usize,
) -> Result<(), Failure> {
    let bytes = result.map_err(|source| Failure::Call { source })?;
    if bytes.len() != size {
        return Err(Failure::CallSize {
            port,
            what: "answer",
            type_name: c.client.response_schema().type_name.clone(),
            want: bytes.len(),
            given: size,
        });
    }
    // SAFETY: writable for `size` = `bytes.len()` bytes by the caller's contract
    unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), answer.cast::<u8>(), size) };
    Ok(())
}

/// Checks that `answer` is not null and `size` is the answer layout's.
fn check_answer(c: &ClientPort, port: nerve_port, answer: *mut c_void, size: usize) -> Result<(), Failure> {
    if answer.is_null() {
        return Err(Failure::Null("answer"));
    }
    let schema = c.client.response_schema();
    if schema.sequence_shape().is_some() {
        return Err(Failure::WrongKind {
            port,
            what: "a client of sequence answers",
            use_instead: "nerve_call_take_seq",
        });
    }
    if size != schema.size {
        return Err(Failure::CallSize {
            port,
            what: "answer",
            type_name: schema.type_name.clone(),
            want: schema.size,
            given: size,
        });
    }
    Ok(())
}

/// Sends a copy of `request` (`len` bytes: the request struct) on client
/// `port` and returns at once, writing the call's id (never 0; 0 on a
/// failure) to `*call` (may be NULL); its answer comes from [`nerve_call_take`] in this or a later
/// step. `NERVE_CALL_FAILED`, with nothing sent, when the client is not
/// wired, no server answers, or 16 calls are in flight already.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `request`
/// is null or readable for `len` bytes; `call` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_call(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    request: *const c_void,
    len: usize,
    call: *mut u64,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let id_out = unsafe { zeroed_out(call) };
        // SAFETY: the caller's contract
        let c = unsafe { client(ctx, port) }?;
        // SAFETY: the caller's contract
        let bytes = unsafe { request_bytes(c, port, request, len) }?;
        let id = c.client.call(bytes).map_err(|source| Failure::Call { source })?;
        if let Some(o) = id_out {
            *o = id.0;
        }
        Ok(())
    })
}

/// Takes the oldest finished call of client `port`: writes its id to
/// `*call` (may be NULL) and copies its answer into `answer` (`size`
/// bytes: the answer struct). `NERVE_NO_SAMPLE` while none has finished;
/// `NERVE_CALL_FAILED` for a call that ended without an answer (timed
/// out, its server gone, the client unwired), `*call` naming it and the
/// message saying why. Never blocks.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `answer`
/// is null or writable for `size` bytes; `call` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_call_take(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    call: *mut u64,
    answer: *mut c_void,
    size: usize,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let id_out = unsafe { zeroed_out(call) };
        // SAFETY: the caller's contract
        let c = unsafe { client(ctx, port) }?;
        check_answer(c, port, answer, size)?;
        let (id, result) = match c.stash.pop_front() {
            Some(f) => f,
            None => c.client.take().ok_or(Failure::NoSample(port))?,
        };
        if let Some(o) = id_out {
            *o = id.0;
        }
        // SAFETY: `answer` is writable for `size` bytes by the caller's contract
        unsafe { give(c, port, result, answer, size) }
    })
}

/// Calls and waits: sends a copy of `request` (`len` bytes) on client
/// `port`, then blocks this step until its answer comes, copied into
/// `answer` (`size` bytes), or until the client's timeout
/// (`NERVE_CALL_FAILED`, saying why). The agent does nothing else
/// meanwhile: its step takes that long. Calls of [`nerve_call`] that
/// finish meanwhile are kept for [`nerve_call_take`]. In the test
/// harness, whose clock moves only when the test moves it and which
/// answers nothing while the step runs, a call cannot be waited for:
/// `NERVE_CALL_FAILED` after the timeout in real time (use `nerve_call`
/// and `nerve_call_take` there).
///
/// # Safety
/// As for [`nerve_call`] and [`nerve_call_take`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_call_wait(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    request: *const c_void,
    len: usize,
    answer: *mut c_void,
    size: usize,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let c = unsafe { client(ctx, port) }?;
        check_answer(c, port, answer, size)?;
        // SAFETY: the caller's contract
        let bytes = unsafe { request_bytes(c, port, request, len) }?;
        let id = c.client.call(bytes).map_err(|source| Failure::Call { source })?;
        // the SDK ends the call at its timeout; past that (and a margin) this stops looking
        let give_up = Instant::now() + c.client.options().timeout + Duration::from_secs(1);
        let mut pause = Duration::from_micros(20);
        loop {
            while let Some((done, result)) = c.client.take() {
                if done == id {
                    // SAFETY: `answer` is writable for `size` bytes by the caller's contract
                    return unsafe { give(c, port, result, answer, size) };
                }
                c.stash.push_back((done, result));
            }
            if Instant::now() >= give_up {
                // the call stays in flight: nerve_call_take gives its end later
                return Err(Failure::NoAnswer { port, call: id.0 });
            }
            std::thread::sleep(pause);
            pause = (pause * 2).min(Duration::from_millis(1));
        }
    })
}
