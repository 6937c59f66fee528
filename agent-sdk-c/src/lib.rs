//! `libnerve`: the agent SDK for agents written in C (issue 43).
//!
//! A C agent is an ordinary SDK agent ([`CAgent`]) whose `new`, `start`,
//! `step` and `stop` call the C functions of a [`nerve_agent_vtable`]. As
//! for Python agents, the Rust runtime keeps `main`, the message checker
//! and the task thread: a C program calls [`nerve_run`] from its `main`
//! and gets registration, rewiring, `nerve rate`, suspend/resume, `nerve
//! ps` figures, `--describe`, `--daemon` and a clean stop as a Rust agent
//! does.
//!
//! Ports are the SDK's byte ports ([`agent_sdk::dynamic`]), declared by a
//! built-in payload type's name (`nerve::Tick`): the schema comes from
//! `shm-schemas`, and the C struct's size and alignment are checked
//! against it when the port is declared. Samples are zero copy both ways:
//! [`nerve_take`]/[`nerve_latest`] give a pointer into shared memory and
//! [`nerve_loan`] a slot to write in place, both valid until the callback
//! returns.
//!
//! Sequences (a header and any number of an element, [`seq`]) and calls
//! (a service the agent answers in its step and a client, [`call`]) are
//! declared by layout too, on the same SDK ports a Rust agent's
//! `output_seq`, `serve` and `client` make.
//!
//! Every exported function returns a [`nerve_status`]; on an error,
//! [`nerve_last_error`] says what went wrong and what to do. Null pointers,
//! unknown ports and a context used after its callback returned are
//! errors, never crashes, and no Rust panic crosses into C (each function
//! runs inside `catch_unwind`). The header is `include/nerve.h`, made by
//! cbindgen from this file (`tests/header.rs` keeps it current).

mod call;
mod call_seq;
mod error;
mod harness;
mod harness_call;
mod loan;
mod own_type;
mod seq;

use agent_sdk::dynamic::{Loan, Received, SchemaInput, SchemaOutput};
use agent_sdk::{Agent, AgentError, CommonArgs, Context, Param, Setup, Task};
use error::{Failure, guard, last_error_text};
use shm_schemas::Schema;
use std::ffi::{CStr, c_char, c_int, c_void};
use std::sync::OnceLock;
use std::time::Duration;

pub use call::nerve_answer_fn;
pub use call_seq::{nerve_answer, nerve_answer_seq_fn};
pub use error::nerve_status;
pub use harness::nerve_harness;
pub use own_type::{
    NERVE_BOOL, NERVE_F32, NERVE_F64, NERVE_I8, NERVE_I16, NERVE_I32, NERVE_I64, NERVE_U8, NERVE_U16, NERVE_U32,
    NERVE_U64, nerve_field, nerve_type,
};
pub use seq::{nerve_seq, nerve_seq_loan};

/// A port handle, as `nerve_setup_input`/`nerve_setup_output` give it:
/// never 0; inputs and outputs are numbered apart, so an input's handle
/// given where an output is expected is refused as an unknown port.
#[allow(non_camel_case_types)]
pub type nerve_port = u32;

/// The first output handle: inputs are 1, 2, ..., outputs `OUTPUT_BASE`, ...
const OUTPUT_BASE: nerve_port = 0x0001_0000;

/// The shortest period nerve runs (as `--period` and `nerve rate` accept).
const MIN_PERIOD: Duration = Duration::from_micros(10);

/// `new`: declares the agent's ports (and, later, parameters) on `setup`.
/// Returns 0 (`NERVE_OK`) on success; anything else fails the agent's start.
/// (An `int`, not a `nerve_status`: any value C returns is defined.)
#[allow(non_camel_case_types)]
pub type nerve_new_fn = Option<unsafe extern "C" fn(setup: *mut nerve_setup, user: *mut c_void) -> c_int>;

/// `start`, `step`: one call of the agent's cycle, with its context.
/// Returns 0 (`NERVE_OK`) on success; anything else fails the call.
#[allow(non_camel_case_types)]
pub type nerve_step_fn = Option<unsafe extern "C" fn(ctx: *mut nerve_ctx, user: *mut c_void) -> c_int>;

/// `stop`: the agent's last call, with its context.
#[allow(non_camel_case_types)]
pub type nerve_stop_fn = Option<unsafe extern "C" fn(ctx: *mut nerve_ctx, user: *mut c_void)>;

/// What a C agent is: its kind, its period and its callbacks.
///
/// The runtime copies it in [`nerve_run`]; `kind` is read there only.
/// `init` (the agent's `new`) is called once in the main thread (and once more, with a
/// throw-away world, for `--describe`); `start`, `step` and `stop` in the
/// agent's task thread, never two at once. A callback returning anything
/// but `NERVE_OK` fails that call: a failed `new` or `start` ends the
/// agent, a failed `step` is counted and logged (`nerve ps` shows it).
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy)]
pub struct nerve_agent_vtable {
    /// The agent's kind as `nerve ps` shows it (letters, digits, `-`, `_`).
    pub kind: *const c_char,
    /// The period in nanoseconds for a periodic agent (at least 10000);
    /// 0 for an event-driven agent, which steps when an input has news.
    pub period_ns: u64,
    /// Required: the agent's `new`, declaring its ports (named `init`, as
    /// `new` is a C++ keyword and the header is for C++ too).
    pub init: nerve_new_fn,
    /// Optional (NULL): runs once before the first step.
    pub start: nerve_step_fn,
    /// Required: one cycle.
    pub step: nerve_step_fn,
    /// Optional (NULL): runs once when the agent stops.
    pub stop: nerve_stop_fn,
}

/// The C agent this process runs, set once by [`nerve_run`].
#[derive(Debug, Clone, Copy)]
struct Spec {
    kind: &'static str,
    task: Task,
    new: nerve_new_fn,
    start: nerve_step_fn,
    step: nerve_step_fn,
    stop: nerve_stop_fn,
    /// the C program's `user` pointer, handed back to every callback
    user: usize,
}

static SPEC: OnceLock<Spec> = OnceLock::new();

thread_local! {
    /// The C agent a test harness of this thread is starting
    /// (`nerve_harness_new`): it takes the place of [`SPEC`] while the
    /// agent's `new` and `start` run, so a test process holds several.
    static STARTING: std::cell::Cell<Option<Spec>> = const { std::cell::Cell::new(None) };
}

/// The kinds given to harnesses, kept once each for the process's life
/// (the SDK wants a `'static` kind; a static holds them, so a leak checker
/// sees them reachable).
static KINDS: std::sync::Mutex<Vec<&'static str>> = std::sync::Mutex::new(Vec::new());

/// `kind` as a `'static` string, made once per distinct kind.
fn intern(kind: &str) -> &'static str {
    let mut kinds = KINDS.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(k) = kinds.iter().find(|k| **k == kind) {
        return k;
    }
    let k: &'static str = Box::leak(kind.to_owned().into_boxed_str());
    kinds.push(k);
    k
}

/// What `new` declares ports on. Valid during the `new` call only.
#[allow(non_camel_case_types)]
#[derive(Debug)]
pub struct nerve_setup {
    sdk: *mut Setup,
    inputs: Vec<SchemaInput>,
    outputs: Vec<SchemaOutput>,
    /// the ports' names, by handle order (inputs, then outputs)
    names: PortNames,
    params: Vec<Param<f64>>,
    /// the `max_len` of each sequence output, by output index
    seq_max: std::collections::HashMap<usize, usize>,
    /// its services and clients
    calls: call::Calls,
}

/// The names of an agent's inputs and outputs, in the order of their
/// handles (a test harness finds a port's layout by name).
#[derive(Debug, Default)]
struct PortNames {
    inputs: Vec<String>,
    outputs: Vec<String>,
}

/// A parameter handle, as `nerve_setup_param_f64` gives it: never 0.
#[allow(non_camel_case_types)]
pub type nerve_param = u32;

/// What `start`, `step` and `stop` get: the agent's ports and the
/// samples and loans handed out during the call. It lives as long as the
/// agent, so a pointer kept past its call is refused (`NERVE_STALE`)
/// rather than read.
#[allow(non_camel_case_types)]
#[derive(Debug)]
pub struct nerve_ctx {
    /// the SDK's context during a callback, null outside one
    sdk: *mut Context,
    inputs: Vec<SchemaInput>,
    outputs: Vec<SchemaOutput>,
    /// samples given to C during this call: their bytes stay mapped until it returns
    held: Vec<Received>,
    /// one pending loan per output
    loans: Vec<Option<Loan>>,
    params: Vec<Param<f64>>,
    names: PortNames,
    /// the `max_len` of each sequence output, by output index
    seq_max: std::collections::HashMap<usize, usize>,
    /// its services and clients
    calls: call::Calls,
}

/// An SDK agent whose algorithm is C functions.
#[derive(Debug)]
pub struct CAgent {
    ctx: Box<nerve_ctx>,
    /// its callbacks and `user` pointer (the process's, or a harness's)
    spec: Spec,
}

// SAFETY: the only field that is not `Send` is `nerve_ctx::sdk`, a raw
// pointer that is null except during a callback, which runs in the thread
// that holds the agent; the ports, samples and loans are the SDK's, which
// move between threads as a Rust agent's do.
unsafe impl Send for CAgent {}

/// The C agent being made: a harness's of this thread while it starts
/// one, else the one given to `nerve_run`.
fn current_spec() -> Option<Spec> {
    STARTING.with(std::cell::Cell::get).or_else(|| SPEC.get().copied())
}

fn spec() -> Result<Spec, AgentError> {
    current_spec().ok_or_else(|| AgentError::Other("no C agent was given to nerve_run".into()))
}

impl Agent for CAgent {
    const KIND: &'static str = "c";

    fn kind() -> &'static str {
        current_spec().map_or(Self::KIND, |s| s.kind)
    }

    fn task() -> Task {
        current_spec().map_or(Task::EventDriven, |s| s.task)
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let spec = spec()?;
        let new = spec.new.ok_or_else(|| AgentError::Other("the C agent's vtable has no `init`".into()))?;
        let mut s = nerve_setup {
            sdk: setup as *mut Setup,
            inputs: Vec::new(),
            outputs: Vec::new(),
            names: PortNames::default(),
            params: Vec::new(),
            seq_max: std::collections::HashMap::new(),
            calls: call::Calls::default(),
        };
        // SAFETY: `new` is the C program's function of this signature
        // (nerve_run's contract); `s` outlives the call.
        let status = unsafe { new(&mut s, spec.user as *mut c_void) };
        s.sdk = std::ptr::null_mut();
        if status != 0 {
            return Err(AgentError::Other(format!("the C agent's new returned {status}{}", last_error_text())));
        }
        let loans = s.outputs.iter().map(|_| None).collect();
        Ok(CAgent {
            ctx: Box::new(nerve_ctx {
                sdk: std::ptr::null_mut(),
                inputs: s.inputs,
                outputs: s.outputs,
                held: Vec::new(),
                loans,
                params: s.params,
                names: s.names,
                seq_max: s.seq_max,
                calls: s.calls,
            }),
            spec,
        })
    }

    fn start(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        match self.spec.start {
            Some(f) => self.call("start", f, ctx),
            None => Ok(()),
        }
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let f = self.spec.step.ok_or_else(|| AgentError::Other("the C agent's vtable has no `step`".into()))?;
        self.call("step", f, ctx)
    }

    fn stop(&mut self, ctx: &mut Context) {
        let spec = self.spec;
        if let Some(f) = spec.stop {
            self.ctx.sdk = ctx as *mut Context;
            // SAFETY: `f` is the C program's function of this signature;
            // the context is valid for the call and marked stale after it.
            unsafe { f(&mut *self.ctx, spec.user as *mut c_void) };
            self.end_call();
        }
    }
}

impl CAgent {
    /// Calls C callback `f` (`what`) with this cycle's context.
    fn call(
        &mut self,
        what: &str,
        f: unsafe extern "C" fn(*mut nerve_ctx, *mut c_void) -> c_int,
        ctx: &mut Context,
    ) -> Result<(), AgentError> {
        let user = self.spec.user;
        self.ctx.sdk = ctx as *mut Context;
        // SAFETY: `f` is the C program's function of this signature
        // (nerve_run's contract); the context is valid for the call and
        // marked stale after it.
        let status = unsafe { f(&mut *self.ctx, user as *mut c_void) };
        self.end_call();
        if status == 0 {
            Ok(())
        } else {
            Err(AgentError::Other(format!("the C agent's {what} returned {status}{}", last_error_text())))
        }
    }

    /// Ends a callback: the context goes stale, samples are released and
    /// loans not sent are given back.
    fn end_call(&mut self) {
        self.ctx.sdk = std::ptr::null_mut();
        self.ctx.held.clear();
        for l in &mut self.ctx.loans {
            *l = None;
        }
    }
}

/// Sets the out-pointers of [`nerve_take`] and [`nerve_latest`] to "no
/// sample" (NULL and 0), or fails naming the one that is null.
///
/// # Safety
/// `data` and `len` are null or writable.
unsafe fn no_sample_yet(data: *mut *const c_void, len: *mut usize) -> Result<(), Failure> {
    if data.is_null() || len.is_null() {
        return Err(Failure::Null(if data.is_null() { "data" } else { "len" }));
    }
    // SAFETY: checked not null; writable by the caller's contract
    unsafe { (*data, *len) = (std::ptr::null(), 0) };
    Ok(())
}

/// An optional out-pointer (a call's id, a count) set to 0 before anything
/// can fail, so a failed call leaves 0 there; `None` when it is null.
///
/// # Safety
/// `p` is null or writable for `'a`.
pub(crate) unsafe fn zeroed_out<'a, T: Default>(p: *mut T) -> Option<&'a mut T> {
    // SAFETY: the caller's contract
    let out = unsafe { p.as_mut() };
    out.map(|o| {
        *o = T::default();
        o
    })
}

/// A C string argument as UTF-8, or the failure naming `what`.
///
/// # Safety
/// `p` is null or a NUL-terminated string that stays valid for `'a`.
unsafe fn text<'a>(p: *const c_char, what: &'static str) -> Result<&'a str, Failure> {
    if p.is_null() {
        return Err(Failure::Null(what));
    }
    // SAFETY: not null, and NUL-terminated by the caller's contract
    let s = unsafe { CStr::from_ptr(p) };
    s.to_str().map_err(|_| Failure::NotUtf8(what))
}

/// The schema for a port of `type_name` declared with C struct `size` and
/// `align` (and `fingerprint`, unless 0), or why they disagree.
fn port_schema(port: &str, type_name: &str, size: usize, align: usize, fingerprint: u64) -> Result<Schema, Failure> {
    let schema =
        shm_schemas::schema::built_in_named(type_name).ok_or_else(|| Failure::UnknownType(type_name.to_owned()))?;
    let theirs = schema.fingerprint();
    if schema.size != size || schema.align != align || (fingerprint != 0 && fingerprint != theirs) {
        return Err(Failure::Layout {
            port: port.to_owned(),
            type_name: type_name.to_owned(),
            size,
            align,
            fingerprint,
            their_size: schema.size,
            their_align: schema.align,
            their_fingerprint: theirs,
        });
    }
    Ok(schema)
}

/// The checked arguments of [`nerve_setup_input`] and
/// [`nerve_setup_output`].
struct PortDecl<'a> {
    setup: &'a mut nerve_setup,
    out: &'a mut nerve_port,
    name: &'a str,
    sdk: &'a mut Setup,
    schema: Schema,
}

/// Checks a port declaration's arguments: no null pointer, UTF-8 names, a
/// setup still in `new`, and the port's schema (`schema`, given the port's
/// name: a built-in type matching the C struct, or the agent's own type).
///
/// # Safety
/// As for [`nerve_setup_input`].
unsafe fn port_decl<'a>(
    setup: *mut nerve_setup,
    name: *const c_char,
    port: *mut nerve_port,
    schema: impl FnOnce(&str) -> Result<Schema, Failure>,
) -> Result<PortDecl<'a>, Failure> {
    // SAFETY: the caller's contract
    let (setup, out) = unsafe { (setup.as_mut(), port.as_mut()) };
    let setup = setup.ok_or(Failure::Null("setup"))?;
    let out = out.ok_or(Failure::Null("port"))?;
    // SAFETY: the caller's contract
    let name = unsafe { text(name, "name") }?;
    // SAFETY: `sdk` is the SDK's setup during `new`, null after it
    let sdk = unsafe { setup.sdk.as_mut() }.ok_or(Failure::Stale("setup"))?;
    let schema = schema(name)?;
    Ok(PortDecl { setup, out, name, sdk, schema })
}

/// The schema of a port of built-in type `type_name` declared with a C
/// struct of `size`, `align` and `fingerprint`.
///
/// # Safety
/// `type_name` is null or a NUL-terminated string.
unsafe fn built_in_port(
    type_name: *const c_char,
    size: usize,
    align: usize,
    fingerprint: u64,
) -> impl FnOnce(&str) -> Result<Schema, Failure> {
    move |port| {
        // SAFETY: the caller's contract
        let type_name = unsafe { text(type_name, "type_name") }?;
        port_schema(port, type_name, size, align, fingerprint)
    }
}

/// Declares an input or output (`input`) on the checked `decl`.
fn declare(decl: PortDecl<'_>, input: bool) -> Result<(), Failure> {
    let PortDecl { setup, out, name, sdk, schema } = decl;
    let sdk_err = |source| Failure::Sdk { port: name.to_owned(), source };
    if input {
        setup.inputs.push(sdk.input_of(name, schema).map_err(sdk_err)?);
        setup.names.inputs.push(name.to_owned());
        *out = nerve_port::try_from(setup.inputs.len()).map_err(|_| Failure::TooManyPorts)?;
    } else {
        let output = sdk.output_of(name, schema).map_err(sdk_err)?;
        let index = nerve_port::try_from(setup.outputs.len()).map_err(|_| Failure::TooManyPorts)?;
        *out = OUTPUT_BASE.checked_add(index).ok_or(Failure::TooManyPorts)?;
        setup.outputs.push(output);
        setup.names.outputs.push(name.to_owned());
    }
    Ok(())
}

/// Declares input `name` of built-in payload type `type_name`
/// (`"nerve::Tick"`); `size` and `align` are the C struct's (`sizeof`,
/// `_Alignof`) and `fingerprint` its layout fingerprint, or 0 not to check
/// it. Writes the port's handle to `*port`.
///
/// Call it in `new` only, with the `setup` given to it, from that thread.
/// The strings are read during the call and not kept.
///
/// # Safety
/// `setup` is null or the pointer given to `new`; `name` and `type_name`
/// are null or NUL-terminated strings; `port` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_input(
    setup: *mut nerve_setup,
    name: *const c_char,
    type_name: *const c_char,
    size: usize,
    align: usize,
    fingerprint: u64,
    port: *mut nerve_port,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract, which is `port_decl`'s and `built_in_port`'s
        let decl = unsafe { port_decl(setup, name, port, built_in_port(type_name, size, align, fingerprint)) }?;
        declare(decl, true)
    })
}

/// Declares output `name`, as [`nerve_setup_input`] declares an input.
///
/// # Safety
/// As for [`nerve_setup_input`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_output(
    setup: *mut nerve_setup,
    name: *const c_char,
    type_name: *const c_char,
    size: usize,
    align: usize,
    fingerprint: u64,
    port: *mut nerve_port,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract, which is `port_decl`'s and `built_in_port`'s
        let decl = unsafe { port_decl(setup, name, port, built_in_port(type_name, size, align, fingerprint)) }?;
        declare(decl, false)
    })
}

/// Declares input `name` of the agent's own payload type `*layout` (a C
/// struct described by its type name, size, alignment and fields; see
/// `NERVE_TYPE` in `nerve_types.h`). The layout is checked as nerve checks
/// any (`NERVE_INVALID_ARGUMENT` naming what is wrong), refused when a
/// built-in type of that name has another (`NERVE_LAYOUT_MISMATCH`), and
/// its fingerprint is a Rust type's of the same name and layout: the
/// router connects it only to ports of the same name and layout, and
/// refuses one whose layout drifted, naming both. Writes the port's handle
/// to `*port`.
///
/// Call it in `init` only, with the `setup` given to it, from that thread.
/// `layout` and its strings are read during the call and not kept.
///
/// # Safety
/// `setup` is null or the pointer given to `init`; `name` is null or a
/// NUL-terminated string; `layout` is null or a valid `nerve_type` (its
/// strings NUL-terminated, `fields` holding `field_count` fields); `port`
/// is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_input_type(
    setup: *mut nerve_setup,
    name: *const c_char,
    layout: *const nerve_type,
    port: *mut nerve_port,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract, which is `port_decl`'s and `schema_of`'s
        let decl = unsafe { port_decl(setup, name, port, |p| own_type::schema_of(layout, p)) }?;
        declare(decl, true)
    })
}

/// Declares output `name` of the agent's own payload type `*layout`, as
/// [`nerve_setup_input_type`] declares an input.
///
/// # Safety
/// As for [`nerve_setup_input_type`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_output_type(
    setup: *mut nerve_setup,
    name: *const c_char,
    layout: *const nerve_type,
    port: *mut nerve_port,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract, which is `port_decl`'s and `schema_of`'s
        let decl = unsafe { port_decl(setup, name, port, |p| own_type::schema_of(layout, p)) }?;
        declare(decl, false)
    })
}

/// Declares parameter `key`, a number with `default`, and bounds `min` and
/// `max` (inclusive; NaN for no bound): a value outside them is refused at
/// start (`--param`) and by `nerve param set`, with a message naming the
/// range. Writes its handle to `*param`; read it in a step with
/// [`nerve_param_f64`].
///
/// Call it in `init` only, with the `setup` given to it, from that thread.
///
/// # Safety
/// `setup` is null or the pointer given to `init`; `key` is null or a
/// NUL-terminated string; `param` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_param_f64(
    setup: *mut nerve_setup,
    key: *const c_char,
    default: f64,
    min: f64,
    max: f64,
    param: *mut nerve_param,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let (setup, out) = unsafe { (setup.as_mut(), param.as_mut()) };
        let setup = setup.ok_or(Failure::Null("setup"))?;
        let out = out.ok_or(Failure::Null("param"))?;
        // SAFETY: the caller's contract
        let key = unsafe { text(key, "key") }?;
        // SAFETY: `sdk` is the SDK's setup during `init`, null after it
        let sdk = unsafe { setup.sdk.as_mut() }.ok_or(Failure::Stale("setup"))?;
        let (lo, hi) = (Some(min).filter(|x| !x.is_nan()), Some(max).filter(|x| !x.is_nan()));
        if let (Some(l), Some(h)) = (lo, hi)
            && l > h
        {
            return Err(Failure::Invalid(format!("parameter {key:?}: min {l} is above max {h}")));
        }
        let name = key.to_owned();
        let check = move |v: &f64| -> Result<(), String> {
            let inside = !v.is_nan() && lo.is_none_or(|l| *v >= l) && hi.is_none_or(|h| *v <= h);
            if inside {
                return Ok(());
            }
            Err(match (lo, hi) {
                (Some(l), Some(h)) => format!("{name} is in [{l}, {h}]"),
                (Some(l), None) => format!("{name} must be >= {l}"),
                (None, Some(h)) => format!("{name} must be <= {h}"),
                (None, None) => format!("{name} must be a number"),
            })
        };
        check(&default)
            .map_err(|e| Failure::Invalid(format!("parameter {key:?}: its default is out of its bounds ({e})")))?;
        setup.params.push(sdk.param_checked(key, default, check));
        *out = nerve_param::try_from(setup.params.len()).map_err(|_| Failure::TooManyPorts)?;
        Ok(())
    })
}

/// Writes parameter `param`'s current value to `*value` (it changes when
/// `nerve param set` changes it).
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `value` is
/// null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_param_f64(ctx: *mut nerve_ctx, param: nerve_param, value: *mut f64) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let value = unsafe { value.as_mut() }.ok_or(Failure::Null("value"))?;
        // SAFETY: the caller's contract
        let ctx = unsafe { live(ctx) }?;
        let p = param
            .checked_sub(1)
            .and_then(|i| ctx.params.get(usize::try_from(i).ok()?))
            .ok_or(Failure::UnknownPort { port: param, what: "param_f64" })?;
        *value = p.get();
        Ok(())
    })
}

/// The live context behind `ctx`, or why not.
///
/// # Safety
/// `ctx` is null or a pointer the runtime gave a callback of this agent.
unsafe fn live<'a>(ctx: *mut nerve_ctx) -> Result<&'a mut nerve_ctx, Failure> {
    // SAFETY: the caller's contract; the context lives as long as the agent
    let ctx = unsafe { ctx.as_mut() }.ok_or(Failure::Null("ctx"))?;
    if ctx.sdk.is_null() {
        return Err(Failure::Stale("ctx"));
    }
    Ok(ctx)
}

impl nerve_ctx {
    fn input(&self, port: nerve_port) -> Result<&SchemaInput, Failure> {
        port.checked_sub(1)
            .and_then(|i| self.inputs.get(usize::try_from(i).ok()?))
            .ok_or(Failure::UnknownPort { port, what: "input" })
    }

    fn output_index(&self, port: nerve_port) -> Result<usize, Failure> {
        port.checked_sub(OUTPUT_BASE)
            .and_then(|i| usize::try_from(i).ok())
            .filter(|i| *i < self.outputs.len())
            .ok_or(Failure::UnknownPort { port, what: "output" })
    }

    /// Keeps `sample` until the call returns and gives out its bytes.
    fn hold(&mut self, sample: Received, data: *mut *const c_void, len: *mut usize) -> Result<(), Failure> {
        // SAFETY: checked for null by the callers before the sample was taken
        let (data, len) = unsafe { (&mut *data, &mut *len) };
        let bytes = sample.bytes();
        *data = bytes.as_ptr().cast();
        *len = bytes.len();
        // the bytes are in shared memory (or a heap box in a test): they do
        // not move with the `Received`
        self.held.push(sample);
        Ok(())
    }
}

/// Takes the next sample waiting on input `port`: `*data` points at its
/// payload and `*len` is its size in bytes. `NERVE_NO_SAMPLE` when none
/// waits (`*data` is then NULL and `*len` 0).
///
/// The bytes are the sender's, in shared memory, read-only and valid until
/// the callback that got `ctx` returns; copy what must outlive it. Call
/// from inside a `start`, `step` or `stop` callback, in its thread.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `data` and
/// `len` are null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_take(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    data: *mut *const c_void,
    len: *mut usize,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract, which is `no_sample_yet`'s
        unsafe { no_sample_yet(data, len) }?;
        // SAFETY: the caller's contract
        let ctx = unsafe { live(ctx) }?;
        let input = ctx.input(port)?;
        let sample = input.take().map_err(|source| Failure::Port { port, source })?.ok_or(Failure::NoSample(port))?;
        ctx.hold(sample, data, len)
    })
}

/// As [`nerve_take`], but the newest sample waiting: the older ones are
/// dropped. `NERVE_NO_SAMPLE` when none waits.
///
/// # Safety
/// As for [`nerve_take`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_latest(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    data: *mut *const c_void,
    len: *mut usize,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract, which is `no_sample_yet`'s
        unsafe { no_sample_yet(data, len) }?;
        // SAFETY: the caller's contract
        let ctx = unsafe { live(ctx) }?;
        let input = ctx.input(port)?;
        let mut newest = None;
        while let Some(s) = input.take().map_err(|source| Failure::Port { port, source })? {
            newest = Some(s);
        }
        ctx.hold(newest.ok_or(Failure::NoSample(port))?, data, len)
    })
}

/// Loans a zeroed sample of output `port` to write in place: `*data`
/// points at its payload (the port's type's size). Send it with
/// [`nerve_send`] before the callback returns; a loan not sent is given
/// back then. One loan per output at a time (`NERVE_LOAN_PENDING`).
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `data` is
/// null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_loan(ctx: *mut nerve_ctx, port: nerve_port, data: *mut *mut c_void) -> nerve_status {
    // SAFETY: the caller's contract, which is `loan_on`'s
    guard(|| unsafe { loan::loan_on(ctx, port, data, true) })
}

/// Sends the sample loaned on output `port` and wakes its readers; the
/// loan is spent and its pointer must not be used again.
/// `NERVE_NO_LOAN` when nothing is loaned on it.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_send(ctx: *mut nerve_ctx, port: nerve_port) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let ctx = unsafe { live(ctx) }?;
        let i = ctx.output_index(port)?;
        let loan = ctx.loans.get_mut(i).and_then(Option::take).ok_or(Failure::NoLoan(port))?;
        let output = ctx.outputs.get_mut(i).ok_or(Failure::UnknownPort { port, what: "output" })?;
        output.send(loan).map_err(|source| Failure::Port { port, source })
    })
}

/// Writes how many steps ran before this one to `*cycle`.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `cycle` is
/// null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_cycle(ctx: *mut nerve_ctx, cycle: *mut u64) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let cycle = unsafe { cycle.as_mut() }.ok_or(Failure::Null("cycle"))?;
        // SAFETY: the caller's contract
        let ctx = unsafe { live(ctx) }?;
        // SAFETY: `live` checked that `sdk` is the running callback's context
        *cycle = unsafe { &*ctx.sdk }.cycle();
        Ok(())
    })
}

/// Stops the agent after this callback, as `nerve stop` would.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_request_stop(ctx: *mut nerve_ctx) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let ctx = unsafe { live(ctx) }?;
        // SAFETY: `live` checked that `sdk` is the running callback's context
        unsafe { &mut *ctx.sdk }.request_stop();
        Ok(())
    })
}

/// What the last failed call of this thread said: what went wrong, where,
/// and what to do; "" when the last call succeeded.
///
/// The string is owned by nerve and stays valid until this thread's next
/// nerve call; copy it to keep it. Any thread may call it (each has its own).
#[unsafe(no_mangle)]
pub extern "C" fn nerve_last_error() -> *const c_char {
    error::last_error_ptr()
}

/// The checked C agent `agent` (its kind a valid agent name, `init` and
/// `step` given, a period nerve runs) with `user`.
///
/// # Safety
/// `agent` is null or points at a vtable whose non-null functions have the
/// declared signatures and whose `kind` is a NUL-terminated string.
unsafe fn spec_of(agent: *const nerve_agent_vtable, user: *mut c_void) -> Result<Spec, Failure> {
    // SAFETY: the caller's contract
    let vt = unsafe { agent.as_ref() }.ok_or(Failure::Null("agent"))?;
    // SAFETY: the caller's contract
    let kind = unsafe { text(vt.kind, "agent->kind") }?;
    shm_schemas::AgentName::new(kind).map_err(|e| Failure::Invalid(format!("kind {kind:?}: {e}")))?;
    if vt.init.is_none() || vt.step.is_none() {
        return Err(Failure::Invalid("the agent's vtable needs `init` and `step` (not NULL)".into()));
    }
    let task = match vt.period_ns {
        0 => Task::EventDriven,
        ns if Duration::from_nanos(ns) < MIN_PERIOD => {
            return Err(Failure::Invalid(format!(
                "period_ns {ns} is below nerve's shortest period, 10000 ns (give 0 for an event-driven agent)"
            )));
        }
        ns => Task::Periodic(Duration::from_nanos(ns)),
    };
    Ok(Spec {
        kind: intern(kind),
        task,
        new: vt.init,
        start: vt.start,
        step: vt.step,
        stop: vt.stop,
        user: user as usize,
    })
}

/// Runs the C agent `agent` under the nerve runtime with the program's
/// command line (`argc`, `argv` as `main` got them: `--name`, `--period`,
/// `--describe`, `--daemon`, ...) and returns the exit status for `main`
/// to return. It returns when the agent stops (`nerve stop`, a signal,
/// `nerve_request_stop`).
///
/// Call it once per process, from `main`'s thread. `agent` is copied;
/// `user` is handed to every callback and never read by nerve; the
/// callbacks are called from one thread at a time (see
/// [`nerve_agent_vtable`]).
///
/// # Safety
/// `argv` holds `argc` NUL-terminated strings (or `argc` is 0); `agent` is
/// null or points at a vtable whose non-null functions have the declared
/// signatures and whose `kind` is a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_run(
    argc: c_int,
    argv: *const *mut c_char,
    agent: *const nerve_agent_vtable,
    user: *mut c_void,
) -> c_int {
    let mut args = Vec::new();
    let status = guard(|| {
        // SAFETY: the caller's contract
        let spec = unsafe { spec_of(agent, user) }?;
        let kind = spec.kind;
        let n = usize::try_from(argc).map_err(|_| Failure::Invalid(format!("argc {argc} is negative")))?;
        if n > 0 && argv.is_null() {
            return Err(Failure::Null("argv"));
        }
        args.push(kind.to_owned());
        for i in 1..n {
            // SAFETY: `argv` holds `argc` strings by the caller's contract
            let a = unsafe { text(*argv.add(i), "argv[i]") }?;
            args.push(a.to_owned());
        }
        SPEC.set(spec).map_err(|_| Failure::Invalid("nerve_run runs one agent per process, and it ran already".into()))
    });
    if status != nerve_status::NERVE_OK {
        eprintln!("error: nerve_run: {}", error::last_error_string());
        return 2;
    }
    let args = match <CommonArgs as clap::Parser>::try_parse_from(args) {
        Ok(a) => a,
        Err(e) => {
            // --help and --version print and succeed; a bad argument prints and fails
            let _ = e.print();
            return if e.use_stderr() { 2 } else { 0 };
        }
    };
    match std::panic::catch_unwind(|| agent_sdk::runtime::run_status::<CAgent>(args)) {
        Ok(code) => c_int::from(code),
        Err(_) => {
            eprintln!("error: nerve_run: the nerve runtime panicked (a bug of nerve: please report it with the log)");
            101
        }
    }
}

#[cfg(test)]
mod tests;
