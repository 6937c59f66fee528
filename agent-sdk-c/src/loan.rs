//! Loans of an output's shared memory to write in place: zeroed
//! ([`crate::nerve_loan`]) or as the slot is ([`nerve_loan_uninit`]).
//!
//! A zeroed loan writes the whole payload before the C program writes
//! anything: at 1080p (6.2 MB) that memset was most of a C pong's round
//! trip in `nerve bench c` and grew with the size, where the Rust pong
//! (`Output::send_uninit`) writes only what it writes. The uninitialised
//! loan is the C counterpart of `send_uninit` and of the Python
//! `loan(zeroed=False)`: for plain C structs any bytes are valid values.

use crate::error::{Failure, guard, nerve_status};
use crate::{live, nerve_ctx, nerve_port};
use std::ffi::c_void;

/// Loans a slot of output `port` to `*data`, zeroed or not.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `data` is
/// null or writable.
pub(crate) unsafe fn loan_on(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    data: *mut *mut c_void,
    zeroed: bool,
) -> Result<(), Failure> {
    // SAFETY: the caller's contract
    let data = unsafe { data.as_mut() }.ok_or(Failure::Null("data"))?;
    *data = std::ptr::null_mut();
    // SAFETY: the caller's contract
    let ctx = unsafe { live(ctx) }?;
    let i = ctx.output_index(port)?;
    let slot = ctx.loans.get_mut(i).ok_or(Failure::UnknownPort { port, what: "output" })?;
    if slot.is_some() {
        return Err(Failure::LoanPending(port));
    }
    let output = ctx.outputs.get(i).ok_or(Failure::UnknownPort { port, what: "output" })?;
    let mut loan = output.loan(zeroed).map_err(|source| Failure::Port { port, source })?;
    // the bytes are a slot of shared memory (or a heap box in a test):
    // they do not move with the `Loan`
    *data = loan.bytes_mut().as_mut_ptr().cast();
    *slot = Some(loan);
    Ok(())
}

/// As `nerve_loan`, but the slot is not zeroed: `*data` points
/// at whatever bytes an earlier sample of this output left in it (zeros
/// in a slot never used). Write every byte your readers read. Nothing is
/// written for you, so a large payload of which only a part changes (a
/// frame's header, a sequence number) costs what is written, not its size.
/// Send it with `nerve_send`; one loan per output at a time.
///
/// # Safety
/// `ctx` is null or the pointer given to the running callback; `data` is
/// null or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn nerve_loan_uninit(
    ctx: *mut nerve_ctx,
    port: nerve_port,
    data: *mut *mut c_void,
) -> nerve_status {
    // SAFETY: the caller's contract, which is `loan_on`'s
    guard(|| unsafe { loan_on(ctx, port, data, false) })
}

#[cfg(test)]
mod tests {
    //! `nerve_loan_uninit` called as a C agent calls it, in the C test
    //! harness: a relay that answers each tick through it, and its misuse.

    use super::nerve_loan_uninit;
    use crate::harness::{
        nerve_harness_free, nerve_harness_new, nerve_harness_output, nerve_harness_send, nerve_harness_step,
    };
    use crate::*;
    use shm_schemas::payloads::Tick;
    use std::ffi::CStr;
    use std::sync::Mutex;

    /// What the step found wrong (a panic must not unwind into C).
    static WRONG: Mutex<Vec<String>> = Mutex::new(Vec::new());

    fn expect(what: &str, got: nerve_status, want: nerve_status) {
        if got != want {
            WRONG.lock().expect("lock").push(format!("{what}: {got:?}, not {want:?}"));
        }
    }

    const TICK: &CStr = c"nerve::Tick";
    const SIZE: usize = std::mem::size_of::<Tick>();
    const ALIGN: usize = std::mem::align_of::<Tick>();

    /// Ports: the input's handle at 0, the output's at 1.
    unsafe extern "C" fn init(setup: *mut nerve_setup, user: *mut c_void) -> c_int {
        // SAFETY: `user` is the test's two handles; the strings are C literals
        unsafe {
            let ports = user.cast::<[nerve_port; 2]>();
            let a = nerve_setup_input(setup, c"in".as_ptr(), TICK.as_ptr(), SIZE, ALIGN, 0, &mut (*ports)[0]);
            let b = nerve_setup_output(setup, c"out".as_ptr(), TICK.as_ptr(), SIZE, ALIGN, 0, &mut (*ports)[1]);
            c_int::from(a != nerve_status::NERVE_OK || b != nerve_status::NERVE_OK)
        }
    }

    /// Answers each tick with `seq + 1` in an uninitialised loan, checking its misuse on the way.
    unsafe extern "C" fn step(ctx: *mut nerve_ctx, user: *mut c_void) -> c_int {
        use nerve_status::*;
        // SAFETY: `user` is the test's handles, `ctx` this step's context; out-pointers are locals
        unsafe {
            let [input, output] = *user.cast::<[nerve_port; 2]>();
            let (mut data, mut len) = (std::ptr::null::<c_void>(), 0usize);
            while nerve_take(ctx, input, &mut data, &mut len) == NERVE_OK {
                let seq = data.cast::<Tick>().read_unaligned().seq;
                let mut slot = std::ptr::null_mut::<c_void>();
                expect("null data", nerve_loan_uninit(ctx, output, std::ptr::null_mut()), NERVE_NULL_POINTER);
                expect("an input's handle", nerve_loan_uninit(ctx, input, &mut slot), NERVE_UNKNOWN_PORT);
                expect("loan", nerve_loan_uninit(ctx, output, &mut slot), NERVE_OK);
                let mut again = slot;
                expect("second loan", nerve_loan_uninit(ctx, output, &mut again), NERVE_LOAN_PENDING);
                if !again.is_null() {
                    WRONG.lock().expect("lock").push("a refused loan left its pointer set".into());
                }
                // only the sequence number is written: the stamp is what the slot held (zero here)
                slot.cast::<u64>().write(seq + 1);
                expect("send", nerve_send(ctx, output), NERVE_OK);
            }
            0
        }
    }

    #[test]
    fn an_uninitialised_loan_is_written_in_place_and_sent() {
        let mut ports: [nerve_port; 2] = [0, 0];
        let vt = nerve_agent_vtable {
            kind: c"uninit-relay".as_ptr(),
            period_ns: 0,
            init: Some(init),
            start: None,
            step: Some(step),
            stop: None,
        };
        let mut h = std::ptr::null_mut();
        let user = (&raw mut ports).cast::<c_void>();
        // SAFETY: a valid vtable, no parameters, `h` writable; `ports` outlives the harness
        unsafe {
            assert_eq!(nerve_harness_new(&vt, user, std::ptr::null(), 0, &mut h), nerve_status::NERVE_OK);
            let tick = Tick { seq: 41, stamp_ns: 7 };
            let sent = nerve_harness_send(h, c"in".as_ptr(), (&raw const tick).cast(), SIZE);
            assert_eq!(sent, nerve_status::NERVE_OK);
            assert_eq!(nerve_harness_step(h), nerve_status::NERVE_OK);
            let mut out = Tick { seq: 0, stamp_ns: 99 };
            let mut len = 0;
            let got = nerve_harness_output(h, c"out".as_ptr(), (&raw mut out).cast(), SIZE, &mut len);
            assert_eq!(got, nerve_status::NERVE_OK);
            assert_eq!((out.seq, out.stamp_ns, len), (42, 0, SIZE), "the seq written, the rest as the slot held");
            assert_eq!(nerve_harness_free(h), nerve_status::NERVE_OK);
        }
        let wrong = WRONG.lock().expect("lock");
        assert!(wrong.is_empty(), "{wrong:?}");
    }
}
