//! Statuses and errors of the C API: every exported function runs inside
//! [`guard`], which turns a [`Failure`] (or a Rust panic) into a
//! [`nerve_status`] and keeps its message for `nerve_last_error`, per
//! thread.

use agent_sdk::testing::HarnessError;
use agent_sdk::{AgentError, PortError};
use std::cell::RefCell;
use std::ffi::{CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};

/// What a call of the C API ended with. `NERVE_OK` is 0; on anything
/// else, `nerve_last_error()` says what went wrong and what to do.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum nerve_status {
    /// Done.
    NERVE_OK = 0,
    /// A pointer argument was NULL.
    NERVE_NULL_POINTER = 1,
    /// An argument is not valid (a string not UTF-8, a bad kind or period).
    NERVE_INVALID_ARGUMENT = 2,
    /// No port (or parameter) of this agent has this handle (or not of this direction).
    NERVE_UNKNOWN_PORT = 3,
    /// No built-in payload type has this name.
    NERVE_UNKNOWN_TYPE = 4,
    /// The C struct's size, alignment or fingerprint differ from the type's.
    NERVE_LAYOUT_MISMATCH = 5,
    /// No sample waits on the input (not an error of the program).
    NERVE_NO_SAMPLE = 6,
    /// `nerve_send` on an output with nothing loaned.
    NERVE_NO_LOAN = 7,
    /// `nerve_loan` on an output that has a loan not sent yet.
    NERVE_LOAN_PENDING = 8,
    /// A setup or context used after the callback it was given to returned.
    NERVE_STALE = 9,
    /// The port or the SDK failed (shared memory, the router); see the message.
    NERVE_PORT_ERROR = 10,
    /// A bug of nerve: it panicked; the call did nothing.
    NERVE_PANIC = 11,
    /// The agent's own callback (`init`, `start`, `step`) returned an error
    /// in a test harness; the message is the agent's.
    NERVE_AGENT_FAILED = 12,
    /// A sequence loan of more elements than the output's (or the
    /// service's) `max_len`: nothing was loaned.
    NERVE_TOO_LONG = 13,
    /// A call ended without an answer (timed out, its server gone, the
    /// client unwired or not wired, no server, too many in flight); the
    /// message says which.
    NERVE_CALL_FAILED = 14,
    /// A call port used in a test harness that does not carry calls:
    /// test calls with real agents.
    NERVE_NOT_IN_HARNESS = 15,
}

/// Why a call failed, with its cause.
#[derive(Debug, thiserror::Error)]
pub(crate) enum Failure {
    #[error("argument `{0}` is NULL: pass a valid pointer")]
    Null(&'static str),
    #[error("argument `{0}` is not UTF-8 text")]
    NotUtf8(&'static str),
    #[error("{0}")]
    Invalid(String),
    #[error("{0} was used after the callback it was given to returned: use it only inside that call")]
    Stale(&'static str),
    #[error("handle {port} names no {what} of this agent: use a handle nerve_setup_{what} gave")]
    UnknownPort { port: u32, what: &'static str },
    #[error("{0:?} is not a built-in payload type (names are like \"nerve::Tick\"; see shm-schemas' payloads)")]
    UnknownType(String),
    #[error(
        "port {port:?}: the C struct for {type_name} has size {size}, align {align}, fingerprint {fingerprint:#x} \
         but nerve's type has size {their_size}, align {their_align}, fingerprint {their_fingerprint:#x}: \
         make the struct match nerve's layout (fingerprint 0 skips its check)"
    )]
    Layout {
        port: String,
        type_name: String,
        size: usize,
        align: usize,
        fingerprint: u64,
        their_size: usize,
        their_align: usize,
        their_fingerprint: u64,
    },
    #[error("the C struct described as {type_name} is not a layout nerve can carry: fix its NERVE_FIELD table")]
    Schema {
        type_name: String,
        #[source]
        source: shm_schemas::schema::SchemaInvalid,
    },
    #[error("no sample waits on input {0}")]
    NoSample(u32),
    #[error("output {0:?} sent nothing the test has not read yet")]
    NoOutput(String),
    #[error("nothing is loaned on output {0}: call nerve_loan first")]
    NoLoan(u32),
    #[error("output {0} has a loan not sent yet: send it (nerve_send) before loaning again")]
    LoanPending(u32),
    #[error("{port}: {len} elements are more than its max_len of {max_len}; nothing was loaned (loan at most max_len)")]
    TooLong { port: String, len: usize, max_len: usize },
    #[error("the call failed")]
    Call {
        #[source]
        source: agent_sdk::port::CallError,
    },
    #[error(
        "call port {0}: calls are not carried in the test harness (as in the Rust harness); test them with real agents"
    )]
    NotInHarness(u32),
    #[error(
        "client {port}: call {call} had no answer within the client's timeout (in the test harness, whose clock moves \
         only when the test moves it, wait with nerve_call and nerve_call_take instead); it ends later, for nerve_call_take"
    )]
    NoAnswer { port: u32, call: u64 },
    #[error(
        "client {port}: the {what} is {type_name} of {want} bytes, but {given} bytes were given: pass its struct (sizeof)"
    )]
    CallSize { port: u32, what: &'static str, type_name: String, want: usize, given: usize },
    #[error(
        "service {port}: the answer function returned {code}; that request was dropped unanswered (its caller sees the server gone)"
    )]
    AnswerFailed { port: u32, code: i32 },
    #[error("port {port} is {what}: use {use_instead} for it")]
    WrongKind { port: u32, what: &'static str, use_instead: &'static str },
    #[error("too many ports")]
    TooManyPorts,
    #[error("port {port:?} cannot be declared")]
    Sdk {
        port: String,
        #[source]
        source: AgentError,
    },
    #[error("port {port} failed")]
    Port {
        port: u32,
        #[source]
        source: PortError,
    },
    #[error("the agent has no {direction} named {port:?}; it has {known:?}")]
    NoPortNamed { direction: &'static str, port: String, known: Vec<String> },
    #[error(
        "{direction} {port:?} carries {type_name} of {want} bytes, but {given} bytes were given: \
         pass the port's own struct (sizeof)"
    )]
    Size { direction: &'static str, port: String, type_name: String, want: usize, given: usize },
    #[error("the agent's {what} failed")]
    Agent {
        what: &'static str,
        #[source]
        source: AgentError,
    },
    #[error("the test harness could not start the agent")]
    Harness {
        #[source]
        source: HarnessError,
    },
}

impl Failure {
    fn status(&self) -> nerve_status {
        use nerve_status::*;
        match self {
            Failure::Null(_) => NERVE_NULL_POINTER,
            Failure::NotUtf8(_) | Failure::Invalid(_) | Failure::TooManyPorts | Failure::Schema { .. } => {
                NERVE_INVALID_ARGUMENT
            }
            Failure::Stale(_) => NERVE_STALE,
            Failure::UnknownPort { .. } | Failure::WrongKind { .. } => NERVE_UNKNOWN_PORT,
            Failure::UnknownType(_) => NERVE_UNKNOWN_TYPE,
            Failure::Layout { .. } => NERVE_LAYOUT_MISMATCH,
            Failure::NoSample(_) | Failure::NoOutput(_) => NERVE_NO_SAMPLE,
            Failure::NoLoan(_) => NERVE_NO_LOAN,
            Failure::LoanPending(_) => NERVE_LOAN_PENDING,
            Failure::Sdk { .. } | Failure::Port { .. } => NERVE_PORT_ERROR,
            Failure::NoPortNamed { .. } => NERVE_UNKNOWN_PORT,
            Failure::Size { .. } | Failure::CallSize { .. } => NERVE_LAYOUT_MISMATCH,
            Failure::Agent { .. } | Failure::AnswerFailed { .. } => NERVE_AGENT_FAILED,
            Failure::TooLong { .. } => NERVE_TOO_LONG,
            Failure::Call { .. } | Failure::NoAnswer { .. } => NERVE_CALL_FAILED,
            Failure::NotInHarness(_) => NERVE_NOT_IN_HARNESS,
            Failure::Harness { source } => match source {
                HarnessError::Agent { .. } => NERVE_AGENT_FAILED,
                HarnessError::Param { .. } | HarnessError::Name { .. } => NERVE_INVALID_ARGUMENT,
                HarnessError::NoSuchPort { .. } => NERVE_UNKNOWN_PORT,
                _ => NERVE_PORT_ERROR,
            },
        }
    }
}

thread_local! {
    /// The message of this thread's last failed call; empty after a success.
    static LAST: RefCell<CString> = RefCell::new(CString::default());
}

fn set_last(msg: String) {
    // a message cannot hold NUL: drop any a cause carried
    let msg = CString::new(msg.replace('\0', "")).unwrap_or_default();
    LAST.with(|l| *l.borrow_mut() = msg);
}

/// `e` and its causes, one after the other.
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cause = c.source();
    }
    s
}

/// Runs one exported function's body: its status, its message kept for
/// `nerve_last_error`, and a panic caught before it reaches C.
pub(crate) fn guard(f: impl FnOnce() -> Result<(), Failure>) -> nerve_status {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => {
            set_last(String::new());
            nerve_status::NERVE_OK
        }
        Ok(Err(e)) => {
            set_last(chain(&e));
            e.status()
        }
        Err(_) => {
            set_last("nerve panicked inside this call (a bug of nerve: please report it with the log)".into());
            nerve_status::NERVE_PANIC
        }
    }
}

/// The pointer `nerve_last_error` returns: valid until this thread's next call.
pub(crate) fn last_error_ptr() -> *const c_char {
    LAST.with(|l| l.borrow().as_ptr())
}

/// This thread's last message.
pub(crate) fn last_error_string() -> String {
    LAST.with(|l| l.borrow().to_string_lossy().into_owned())
}

/// `": message"` for an agent error after a failed callback, or "".
pub(crate) fn last_error_text() -> String {
    let s = last_error_string();
    if s.is_empty() { s } else { format!(": {s}") }
}
