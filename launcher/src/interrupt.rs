//! Ctrl-C for the commands that run until told to stop (`nerve logs
//! --follow`, `nerve launch --foreground`, `nerve demo`, `nerve calibrate`):
//! [`catch`] routes SIGINT and SIGTERM to a flag that their loops poll with
//! [`requested`], so that they end cleanly (bring the robot down, write
//! what they recorded) instead of dying.

use std::sync::atomic::{AtomicBool, Ordering};

/// Set by SIGINT/SIGTERM once [`catch`] was called.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Routes SIGINT and SIGTERM to the flag [`requested`] reads.
pub fn catch() {
    use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
    let act = SigAction::new(SigHandler::Handler(on_signal), SaFlags::empty(), SigSet::empty());
    for sig in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        let _ = unsafe { sigaction(sig, &act) };
    }
}

/// Whether SIGINT or SIGTERM came since [`catch`].
pub fn requested() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}
