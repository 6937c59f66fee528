//! The step's clock: the time the running step of this thread began, so
//! that what a step takes is counted at one clock read a step instead of
//! one a sample (an input's tally, `port::tally`: the rate and the age of
//! the last sample, as `nerve ps` shows them).
//!
//! A polling task's hop is about a microsecond (issue 42), and a clock read
//! is a few percent of it on each side. The step's start is when the task
//! found what it takes (the event loop's wake-up, the poller's look), so a
//! sample counted then is counted at its arrival as the task saw it; a long
//! step that takes its input late counts it at its start, not later. A take
//! outside a step (the test harness, another thread) reads the clock.

use crate::clock::now_ns;
use std::cell::Cell;

thread_local! {
    /// the running step's start (ns, the task's clock); 0 between steps
    static STEP_NOW_NS: Cell<u64> = const { Cell::new(0) };
}

/// Runs `step` with `now_ns` as the step's clock on this thread.
pub(crate) fn during_step<R>(now_ns: u64, step: impl FnOnce() -> R) -> R {
    /// ends the step's clock even when the step unwinds
    struct Ended;
    impl Drop for Ended {
        fn drop(&mut self) {
            STEP_NOW_NS.set(0);
        }
    }
    STEP_NOW_NS.set(now_ns.max(1));
    let _ended = Ended;
    step()
}

/// The time a sample taken now is counted at: the running step's start, or
/// the clock outside a step.
pub(crate) fn counted_at() -> u64 {
    match STEP_NOW_NS.get() {
        0 => now_ns(),
        t => t,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_counts_at_its_start_and_outside_a_step_the_clock_is_read() {
        let before = counted_at();
        assert!(before > 0);
        assert_eq!(during_step(42, || (counted_at(), counted_at())), (42, 42));
        let after = counted_at();
        assert!(after >= before && after != 42, "outside the step the clock is read again");
        // a step that unwinds leaves no clock behind
        let _ = std::panic::catch_unwind(|| during_step(7, || panic!("a failing step")));
        assert_ne!(counted_at(), 7);
    }
}
