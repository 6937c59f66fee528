//! Real-time scheduling and locked memory, asked for where the system
//! permits and reported plainly where it does not.

/// Locks current and future pages of the process in RAM as they are touched
/// (`MCL_ONFAULT`, so large sparse shared-memory mappings are not faulted in).
pub fn lock_memory() -> Result<(), String> {
    // SAFETY: mlockall has no memory-safety preconditions.
    let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE | libc::MCL_ONFAULT) };
    if rc == 0 { Ok(()) } else { Err(std::io::Error::last_os_error().to_string()) }
}

/// Puts the calling thread under SCHED_FIFO at `priority` (1-99).
pub fn set_thread_fifo(priority: i32) -> Result<(), String> {
    let param = libc::sched_param { sched_priority: priority };
    // SAFETY: pthread_self is always valid; param is a valid sched_param.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc == 0 { Ok(()) } else { Err(std::io::Error::from_raw_os_error(rc).to_string()) }
}

/// Blocks SIGINT and SIGTERM in the calling thread, so that they are
/// delivered to the message checker, which stops the agent cleanly.
pub fn block_termination_signals() {
    use nix::sys::signal::{SigSet, SigmaskHow, Signal, pthread_sigmask};
    let mut set = SigSet::empty();
    set.add(Signal::SIGINT);
    set.add(Signal::SIGTERM);
    let _ = pthread_sigmask(SigmaskHow::SIG_BLOCK, Some(&set), None);
}

/// Makes the calling thread's timed sleeps wake on time (a timer slack of
/// 1 ns). Linux lets the wake-up of a normal-priority thread slip by up to
/// 50 µs so that timers can be batched; SCHED_FIFO threads have no slack,
/// but a task running without real-time privileges would otherwise wake
/// that much late every cycle (measured: a 100 kHz polling agent pair's
/// round trip was 95-100 µs, where event-driven agents take 36-55 µs).
pub fn tight_timer_slack() {
    // SAFETY: PR_SET_TIMERSLACK takes a plain integer argument.
    let _ = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
}

/// Puts the calling thread back under the normal scheduler (SCHED_OTHER).
/// Threads inherit their creator's policy: an agent that starts a library's
/// own thread pool (a network stack, say) from a real-time thread calls
/// this first in a thread of its own, so the pool never competes with the
/// robot's real-time tasks.
pub fn drop_realtime() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: pthread_self is always valid; param is a valid sched_param.
    let _ = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_OTHER, &param) };
}
