//! Sequence ports for C agents (issue 43 over issue 42's sequences): a
//! header and any number of a fixed-size element, the layout a Rust
//! agent's `setup.output_seq::<T, H>(port, max_len)` makes
//! ([`shm_schemas::seq`]), so a C agent and a Rust or Python agent of one
//! sequence type are wired to each other.
//!
//! The ports are the byte ports every C port is ([`agent_sdk::dynamic`])
//! with a sequence's schema, which carry samples of any length on
//! iceoryx2's slice service. What this module adds is the layout (from an
//! element and a header [`nerve_type`]), the bound an output declared
//! (a loan past it is refused before anything is loaned), and the split of
//! a sample into its header and its elements, zero copy both ways.

use crate::error::{Failure, guard, nerve_status};
use crate::own_type::{nerve_type, part_schema};
use crate::{declare, live, nerve_ctx, nerve_port, nerve_setup, port_decl};
use agent_sdk::dynamic::Received;
use shm_schemas::{Described as _, NoHeader, Schema, SeqShape};
use std::ffi::{c_char, c_void};

/// A received sequence sample, read in place: its header (`header`, NULL
/// for a sequence without one), its `len` elements at `items` (NULL when
/// `len` is 0). Both point into shared memory, read-only, valid until the
/// callback that got them returns.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy)]
pub struct nerve_seq {
    /// The sample's header (the header struct), or NULL if it has none.
    pub header: *const c_void,
    /// Its first element (an array of `len` element structs), or NULL if `len` is 0.
    pub items: *const c_void,
    /// How many elements it holds.
    pub len: usize,
}

/// A loaned sequence sample to write in place before `nerve_send`: its
/// header (zeroed; NULL for a sequence without one) and room for `len`
/// elements at `items` (NULL when `len` is 0), which hold what the slot
/// last held until written: write every element.
#[repr(C)]
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy)]
pub struct nerve_seq_loan {
    /// The sample's header to fill in, or NULL if it has none.
    pub header: *mut c_void,
    /// Its first element slot (an array of `len` element structs), or NULL if `len` is 0.
    pub items: *mut c_void,
    /// How many elements it holds (the `n` asked for).
    pub len: usize,
}

/// The sequence schema of `element` after `header` (NULL: none), for port `port`.
///
/// # Safety
/// `element` and `header` are null or valid `nerve_type`s.
pub(crate) unsafe fn sequence(
    port: &str,
    element: *const nerve_type,
    header: *const nerve_type,
) -> Result<Schema, Failure> {
    // SAFETY: the caller's contract
    let element = unsafe { part_schema(element, port, "element") }?;
    let header = if header.is_null() {
        NoHeader::schema()
    } else {
        // SAFETY: the caller's contract
        unsafe { part_schema(header, port, "header") }?
    };
    let s = Schema::sequence(header, element);
    s.validate().map_err(|source| Failure::Schema { type_name: s.type_name.clone(), source })?;
    Ok(s)
}

/// The shape of a sequence port, or the failure saying it is none.
fn shape_of(schema: &Schema, port: nerve_port) -> Result<SeqShape, Failure> {
    schema.sequence_shape().ok_or_else(|| {
        Failure::Invalid(format!(
            "port {port} carries {}, not a sequence: use nerve_take/nerve_latest/nerve_loan",
            schema.type_name
        ))
    })
}

/// Declares input `name` of sequences of `element` structs after a
/// `header` struct (NULL: no header, `nerve::NoHeader`), as a Rust agent's
/// `setup.input_seq::<T, H>(name)` does: the router connects it to any
/// output of that sequence type (element and header named and laid out
/// alike). Each is a `nerve_type`: the agent's own struct (`NERVE_TYPE`),
/// or a built-in payload or primitive by name (`NERVE_BUILTIN(nerve_Tick)`,
/// `NERVE_BUILTIN_PRIMITIVE(uint8_t, "u8")`). Writes its handle to `*port`;
/// read it with [`nerve_take_seq`] or [`nerve_latest_seq`].
///
/// Call it in `init` only, with the `setup` given to it, from that thread.
/// `element`, `header` and their strings are read during the call, not kept.
///
/// # Safety
/// `setup` is null or the pointer given to `init`; `name` is null or a
/// NUL-terminated string; `element` and `header` are null or valid
/// `nerve_type`s; `port` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_input_seq(
    setup: *mut nerve_setup,
    name: *const c_char,
    element: *const nerve_type,
    header: *const nerve_type,
    port: *mut nerve_port,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract, which is `port_decl`'s and `sequence`'s
        let decl = unsafe { port_decl(setup, name, port, |p| sequence(p, element, header)) }?;
        declare(decl, true)
    })
}

/// Declares output `name` of sequences of `element` structs after a
/// `header` struct (NULL: none), at most `max_len` elements a sample (and
/// at most the 64 MiB every sample is bounded to), as a Rust agent's
/// `setup.output_seq::<T, H>(name, max_len)` does. The types are given as
/// for [`nerve_setup_input_seq`]. Writes its handle to `*port`; send on it
/// with [`nerve_loan_seq`] then `nerve_send`.
///
/// # Safety
/// As for [`nerve_setup_input_seq`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_setup_output_seq(
    setup: *mut nerve_setup,
    name: *const c_char,
    element: *const nerve_type,
    header: *const nerve_type,
    max_len: usize,
    port: *mut nerve_port,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract, which is `port_decl`'s and `sequence`'s
        let decl = unsafe { port_decl(setup, name, port, |p| sequence(p, element, header)) }?;
        let shape = decl.schema.sequence_shape().ok_or(Failure::Invalid("not a sequence".into()))?;
        let bound = shape.count_of_at_most(shm_schemas::schema::MAX_SIZE);
        if max_len > bound {
            return Err(Failure::Invalid(format!(
                "port {:?}: max_len {max_len} elements of {} bytes are more than a sample's 64 MiB; give at most {bound}",
                decl.name, shape.element
            )));
        }
        let index = decl.setup.outputs.len();
        declare(decl, false)?;
        // `declare` refused nothing (an error returns before this): the output is at `index`
        // SAFETY: `setup` was checked not null by `port_decl` above
        let setup = unsafe { &mut *setup };
        setup.seq_max.insert(index, max_len);
        Ok(())
    })
}

/// Splits received sample `sample` of `shape` into `out`, and keeps it until the call returns.
fn hold_seq(
    ctx: &mut nerve_ctx,
    port: nerve_port,
    shape: &SeqShape,
    sample: Received,
    out: &mut nerve_seq,
) -> Result<(), Failure> {
    let bytes = sample.bytes();
    let n = shape.count_of(bytes.len()).ok_or_else(|| {
        Failure::Invalid(format!(
            "input {port}: a sample of {} bytes is not a {}-byte header and whole {}-byte elements (dropped)",
            bytes.len(),
            shape.items_at,
            shape.element
        ))
    })?;
    let at = bytes.as_ptr();
    *out = nerve_seq {
        header: if shape.items_at == 0 { std::ptr::null() } else { at.cast() },
        // SAFETY: `items_at` <= the sample's length (`count_of` checked it holds a header)
        items: if n == 0 { std::ptr::null() } else { unsafe { at.add(shape.items_at) }.cast() },
        len: n,
    };
    // the bytes are in shared memory (or a heap box in a test): they do
    // not move with the `Received`
    ctx.held.push(sample);
    Ok(())
}

/// The live context, the input's shape and `out` set to "no sample".
///
/// # Safety
/// `ctx` is null or a callback's context; `out` is null or writable.
unsafe fn begin_take<'a>(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    out: *mut nerve_seq,
) -> Result<(&'a mut nerve_ctx, &'a mut nerve_seq, SeqShape), Failure> {
    // SAFETY: the caller's contract
    let out = unsafe { out.as_mut() }.ok_or(Failure::Null("seq"))?;
    *out = nerve_seq { header: std::ptr::null(), items: std::ptr::null(), len: 0 };
    // SAFETY: the caller's contract
    let ctx = unsafe { live(ctx) }?;
    let shape = shape_of(ctx.input(port)?.schema(), port)?;
    Ok((ctx, out, shape))
}

/// Takes the next sample waiting on sequence input `port` and writes its
/// header, elements and length to `*seq`, in place in shared memory (zero
/// copy), read-only and valid until the callback that got `ctx` returns.
/// `NERVE_NO_SAMPLE` when none waits (`*seq` is then NULLs and 0);
/// `NERVE_INVALID_ARGUMENT` for an input that is not a sequence.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `seq` is
/// null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_take_seq(ctx: *mut nerve_ctx, port: nerve_port, seq: *mut nerve_seq) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let (ctx, out, shape) = unsafe { begin_take(ctx, port, seq) }?;
        let input = ctx.input(port)?;
        let sample = input.take().map_err(|source| Failure::Port { port, source })?.ok_or(Failure::NoSample(port))?;
        hold_seq(ctx, port, &shape, sample, out)
    })
}

/// As [`nerve_take_seq`], but the newest sample waiting: the older ones
/// are dropped. `NERVE_NO_SAMPLE` when none waits.
///
/// # Safety
/// As for [`nerve_take_seq`].
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_latest_seq(ctx: *mut nerve_ctx, port: nerve_port, seq: *mut nerve_seq) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let (ctx, out, shape) = unsafe { begin_take(ctx, port, seq) }?;
        let input = ctx.input(port)?;
        let mut newest = None;
        while let Some(s) = input.take().map_err(|source| Failure::Port { port, source })? {
            newest = Some(s);
        }
        hold_seq(ctx, port, &shape, newest.ok_or(Failure::NoSample(port))?, out)
    })
}

/// Loans a sample of `n` elements on sequence output `port` to write in
/// place in shared memory: `*loan` gets its header (zeroed) and room for
/// `n` elements (holding what the slot last held: write every one). Send
/// it with `nerve_send` before the callback returns; a loan not sent is
/// given back then. One loan per output at a time (`NERVE_LOAN_PENDING`).
/// Past the output's `max_len`, `NERVE_TOO_LONG` and nothing is loaned.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `loan` is
/// null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_loan_seq(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    n: usize,
    loan: *mut nerve_seq_loan,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let out = unsafe { loan.as_mut() }.ok_or(Failure::Null("loan"))?;
        *out = nerve_seq_loan { header: std::ptr::null_mut(), items: std::ptr::null_mut(), len: 0 };
        // SAFETY: the caller's contract
        let ctx = unsafe { live(ctx) }?;
        let i = ctx.output_index(port)?;
        let output = ctx.outputs.get(i).ok_or(Failure::UnknownPort { port, what: "output" })?;
        let shape = shape_of(output.schema(), port)?;
        let max_len = ctx.seq_max.get(&i).copied().unwrap_or(0);
        if n > max_len {
            return Err(Failure::TooLong { port: output.service().to_owned(), len: n, max_len });
        }
        if ctx.loans.get(i).is_some_and(Option::is_some) {
            return Err(Failure::LoanPending(port));
        }
        let len = shape.len_of(n).ok_or(Failure::TooLong { port: output.service().to_owned(), len: n, max_len })?;
        let mut l = output.loan_len(len, false).map_err(|source| Failure::Port { port, source })?;
        let bytes = l.bytes_mut();
        if bytes.len() != len {
            return Err(Failure::Invalid(format!("a loan of {} bytes for {n} elements ({len} bytes)", bytes.len())));
        }
        // the header zeroed, as a C struct initialised `= {0}` would be
        if let Some(h) = bytes.get_mut(..shape.items_at) {
            h.fill(0);
        }
        let at = bytes.as_mut_ptr();
        *out = nerve_seq_loan {
            header: if shape.items_at == 0 { std::ptr::null_mut() } else { at.cast() },
            // SAFETY: `items_at` <= `len`, the loan's length (`len_of`)
            items: if n == 0 { std::ptr::null_mut() } else { unsafe { at.add(shape.items_at) }.cast() },
            len: n,
        };
        // the bytes are a slot of shared memory (or a heap box in a test):
        // they do not move with the `Loan`
        let slot = ctx.loans.get_mut(i).ok_or(Failure::UnknownPort { port, what: "output" })?;
        *slot = Some(l);
        Ok(())
    })
}
