//! The C test harness (`nerve_harness_*`, issue 43): a C agent's own
//! `init`, `start`, `step` and `stop` run in the test's process and thread,
//! with no router and no shared memory, on the SDK's
//! [`Harness`](agent_sdk::testing::Harness) as a Rust agent's test runs.
//! The test queues samples on inputs, steps the agent or moves its clock,
//! reads what the outputs sent and sets parameters; the agent sees what it
//! sees when it runs (the same `nerve_take`, `nerve_loan`, `nerve_cycle`).
//!
//! Samples go in and out as copies of the test's structs, checked against
//! the port's size, so no pointer of the harness outlives a call. The
//! samples an agent's step takes are heap copies freed when the step
//! returns: a pointer it keeps past its step is a use after free that
//! AddressSanitizer reports.

use crate::error::{Failure, guard};
use crate::{CAgent, STARTING, nerve_agent_vtable, spec_of, text};
use agent_sdk::testing::Harness;
use shm_schemas::Schema;
use std::collections::{HashMap, VecDeque};
use std::ffi::{c_char, c_void};
use std::time::Duration;

use crate::error::nerve_status;

/// A C agent running in a test, made by [`nerve_harness_new`] and freed by
/// [`nerve_harness_free`]. Opaque: use it through the `nerve_harness_*`
/// functions only.
#[allow(non_camel_case_types)]
pub struct nerve_harness {
    pub(crate) h: Harness<CAgent>,
    /// what each output sent that the test has not read yet, oldest first
    unread: HashMap<String, VecDeque<Vec<u8>>>,
    /// each service's answers to the test's calls not taken yet, oldest first
    pub(crate) answers: HashMap<String, VecDeque<crate::harness_call::Answered>>,
}

impl std::fmt::Debug for nerve_harness {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("nerve_harness").field("harness", &self.h).finish()
    }
}

impl nerve_harness {
    /// The layout of the agent's input (`input`) or output `port`, or the
    /// failure naming the ports it has.
    fn schema(&self, port: &str, input: bool) -> Result<&Schema, Failure> {
        let ctx = &self.h.agent().ctx;
        let (names, direction) = if input { (&ctx.names.inputs, "input") } else { (&ctx.names.outputs, "output") };
        let at = names.iter().position(|n| n == port).ok_or_else(|| Failure::NoPortNamed {
            direction,
            port: port.to_owned(),
            known: names.clone(),
        })?;
        let schema =
            if input { ctx.inputs.get(at).map(|i| i.schema()) } else { ctx.outputs.get(at).map(|o| o.schema()) };
        schema.ok_or_else(|| Failure::NoPortNamed { direction, port: port.to_owned(), known: names.clone() })
    }

    /// Refuses `given` bytes for `port` unless they are its payload's size.
    fn check_size(&self, port: &str, input: bool, given: usize) -> Result<(), Failure> {
        let schema = self.schema(port, input)?;
        if schema.sequence_shape().is_none() && schema.size != given {
            return Err(Failure::Size {
                direction: if input { "input" } else { "output" },
                port: port.to_owned(),
                type_name: schema.type_name.to_string(),
                want: schema.size,
                given,
            });
        }
        Ok(())
    }
}

/// Clears the thread's starting agent when dropped, even on a panic.
struct Starting;

impl Drop for Starting {
    fn drop(&mut self) {
        STARTING.with(|s| s.set(None));
    }
}

/// The harness behind `h`, or why not.
///
/// # Safety
/// `h` is null or a harness from [`nerve_harness_new`] not yet freed.
pub(crate) unsafe fn harness<'a>(h: *mut nerve_harness) -> Result<&'a mut nerve_harness, Failure> {
    // SAFETY: the caller's contract
    unsafe { h.as_mut() }.ok_or(Failure::Null("harness"))
}

/// Starts C agent `agent` in a test harness: runs its `init` (its ports
/// bound to in-memory queues, no router, no shared memory), applies the
/// `n_params` settings of `params` (`"KEY=VALUE"`, as `--param` is), runs
/// its `start`, and writes the harness to `*harness` (NULL on a failure).
/// The agent's name is its kind, its period `agent->period_ns` (0:
/// event-driven); its clock starts at 1 s and moves only when the test
/// moves it ([`nerve_harness_step`], [`nerve_harness_advance`]).
///
/// Ownership: `agent` and `params` are read during the call and not kept;
/// `user` is handed to every callback and never read by nerve; the
/// harness is the caller's, to free with [`nerve_harness_free`].
///
/// Threads: the callbacks run in the thread calling the `nerve_harness_*`
/// function that runs them; a harness may move between threads but is
/// used by one at a time. Several harnesses, of one or several agents, may
/// live at once. `NERVE_AGENT_FAILED` when `init` or `start` failed, with
/// the agent's message; `NERVE_INVALID_ARGUMENT` for a setting refused.
///
/// # Safety
/// `agent` is null or a vtable as [`crate::nerve_run`] takes; `params` is
/// null or holds `n_params` pointers, each null or a NUL-terminated
/// string; `harness` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_new(
    agent: *const nerve_agent_vtable,
    user: *mut c_void,
    params: *const *const c_char,
    n_params: usize,
    harness: *mut *mut nerve_harness,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let out = unsafe { harness.as_mut() }.ok_or(Failure::Null("harness"))?;
        *out = std::ptr::null_mut();
        // SAFETY: the caller's contract
        let spec = unsafe { spec_of(agent, user) }?;
        if n_params > 0 && params.is_null() {
            return Err(Failure::Null("params"));
        }
        let mut builder = Harness::<CAgent>::builder();
        for i in 0..n_params {
            // SAFETY: `params` holds `n_params` pointers by the caller's contract
            let kv = unsafe { text(*params.add(i), "params[i]") }?;
            let (k, v) = kv.split_once('=').ok_or_else(|| {
                Failure::Invalid(format!("params[{i}] is {kv:?}: give a setting as \"KEY=VALUE\", e.g. \"gain=2\""))
            })?;
            builder = builder.param(k, v);
        }
        STARTING.with(|s| s.set(Some(spec)));
        let started = {
            let _clear = Starting;
            builder.start()
        };
        let h = started.map_err(|source| Failure::Harness { source })?;
        *out = Box::into_raw(Box::new(nerve_harness { h, unread: HashMap::new(), answers: HashMap::new() }));
        Ok(())
    })
}

/// Runs the agent's `stop` and frees the harness; NULL does nothing.
/// The harness must not be used after.
///
/// # Safety
/// `h` is null or a harness from [`nerve_harness_new`] not yet freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_free(h: *mut nerve_harness) -> nerve_status {
    guard(|| {
        if !h.is_null() {
            // SAFETY: made by Box::into_raw in nerve_harness_new, freed once by the caller's contract
            drop(unsafe { Box::from_raw(h) });
        }
        Ok(())
    })
}

/// Queues a copy of the `len` bytes at `data` on input `input`, as a
/// sample from agent `test` stamped with the harness's clock. `len` must be
/// the input's payload size (`sizeof` its struct): another is refused with
/// `NERVE_LAYOUT_MISMATCH`. Past 16 waiting samples the oldest is
/// overwritten, as on a running agent's input.
///
/// # Safety
/// `h` is null or a live harness; `input` is null or a NUL-terminated
/// string; `data` is null or readable for `len` bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_send(
    h: *mut nerve_harness,
    input: *const c_char,
    data: *const c_void,
    len: usize,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let h = unsafe { harness(h) }?;
        // SAFETY: the caller's contract
        let input = unsafe { text(input, "input") }?;
        if data.is_null() {
            return Err(Failure::Null("data"));
        }
        h.check_size(input, true, len)?;
        // SAFETY: `data` is readable for `len` bytes by the caller's contract
        let bytes = unsafe { std::slice::from_raw_parts(data.cast::<u8>(), len) };
        h.h.send_bytes_from(input, "test", bytes).map_err(|source| Failure::Harness { source })
    })
}

/// Runs one cycle: an event-driven agent steps now (woken by the inputs
/// that have samples); a periodic agent's clock moves to its next deadline
/// and it steps there. `NERVE_AGENT_FAILED` when the step returned an
/// error, with its message.
///
/// # Safety
/// `h` is null or a live harness.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_step(h: *mut nerve_harness) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let h = unsafe { harness(h) }?;
        h.h.step().map_err(|source| Failure::Agent { what: "step", source })
    })
}

/// Moves the clock on by `ns` nanoseconds; a periodic agent steps at every
/// deadline passed. Writes how many steps ran to `*steps` (may be NULL).
/// The first failed step ends the advance (`NERVE_AGENT_FAILED`).
///
/// # Safety
/// `h` is null or a live harness; `steps` is null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_advance(h: *mut nerve_harness, ns: u64, steps: *mut u64) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let h = unsafe { harness(h) }?;
        let ran = h.h.advance(Duration::from_nanos(ns)).map_err(|source| Failure::Agent { what: "step", source })?;
        // SAFETY: the caller's contract
        if let Some(s) = unsafe { steps.as_mut() } {
            *s = ran;
        }
        Ok(())
    })
}

/// Copies the oldest sample output `output` sent that the test has not
/// read yet into `dst` (`size` bytes: the port's payload size, else
/// `NERVE_LAYOUT_MISMATCH`) and writes its size to `*len`.
/// `NERVE_NO_SAMPLE` when none is left (`*len` is then 0).
///
/// # Safety
/// `h` is null or a live harness; `output` is null or a NUL-terminated
/// string; `dst` is null or writable for `size` bytes; `len` is null or
/// writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_output(
    h: *mut nerve_harness,
    output: *const c_char,
    dst: *mut c_void,
    size: usize,
    len: *mut usize,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let len = unsafe { len.as_mut() }.ok_or(Failure::Null("len"))?;
        *len = 0;
        // SAFETY: the caller's contract
        let h = unsafe { harness(h) }?;
        // SAFETY: the caller's contract
        let output = unsafe { text(output, "output") }?;
        if dst.is_null() {
            return Err(Failure::Null("dst"));
        }
        h.check_size(output, false, size)?;
        let sent = h.h.output_bytes(output).map_err(|source| Failure::Harness { source })?;
        let unread = h.unread.entry(output.to_owned()).or_default();
        unread.extend(sent.into_iter().map(|(_, bytes)| bytes));
        let Some(sample) = unread.front() else {
            return Err(Failure::NoOutput(output.to_owned()));
        };
        if sample.len() > size {
            return Err(Failure::Size {
                direction: "output",
                port: output.to_owned(),
                type_name: "a sequence".into(),
                want: sample.len(),
                given: size,
            });
        }
        // SAFETY: `dst` is writable for `size` >= `sample.len()` bytes by the
        // caller's contract, and cannot overlap the harness's own copy
        unsafe { std::ptr::copy_nonoverlapping(sample.as_ptr(), dst.cast::<u8>(), sample.len()) };
        *len = sample.len();
        unread.pop_front();
        Ok(())
    })
}

/// Sets parameter `key` to `value` (text, as `nerve param set KEY VALUE`
/// gives it); a value the agent's bounds refuse is `NERVE_INVALID_ARGUMENT`
/// with the refusal `nerve` would print.
///
/// # Safety
/// `h` is null or a live harness; `key` and `value` are null or
/// NUL-terminated strings.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_set_param(
    h: *mut nerve_harness,
    key: *const c_char,
    value: *const c_char,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let h = unsafe { harness(h) }?;
        // SAFETY: the caller's contract
        let (key, value) = unsafe { (text(key, "key")?, text(value, "value")?) };
        h.h.set_param(key, value).map_err(|reason| Failure::Invalid(format!("parameter {key}={value}: {reason}")))
    })
}

/// Changes a periodic agent's period to `period_ns`, as `nerve rate` does:
/// the next step comes one new period after the last. Ignored for an
/// event-driven agent; 0 is refused.
///
/// # Safety
/// `h` is null or a live harness.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_set_period(h: *mut nerve_harness, period_ns: u64) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let h = unsafe { harness(h) }?;
        if period_ns == 0 {
            return Err(Failure::Invalid("period_ns 0: give a period in nanoseconds".into()));
        }
        h.h.set_period(Duration::from_nanos(period_ns));
        Ok(())
    })
}

/// Writes the harness's clock (what the agent reads as now, in ns; it
/// starts at 1 s) to `*now_ns` and how many steps ran to `*cycles`
/// (either may be NULL).
///
/// # Safety
/// `h` is null or a live harness; `now_ns` and `cycles` are null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_harness_clock(
    h: *mut nerve_harness,
    now_ns: *mut u64,
    cycles: *mut u64,
) -> nerve_status {
    guard(|| {
        // SAFETY: the caller's contract
        let h = unsafe { harness(h) }?;
        // SAFETY: the caller's contract
        let (now, n) = unsafe { (now_ns.as_mut(), cycles.as_mut()) };
        if let Some(now) = now {
            *now = h.h.now_ns();
        }
        if let Some(n) = n {
            *n = h.h.cycles();
        }
        Ok(())
    })
}
