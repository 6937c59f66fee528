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
