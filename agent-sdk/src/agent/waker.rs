//! The waker: a thread of the agent wakes its event-driven task.
//!
//! An event-driven task sleeps until one of its inputs gets a sample. An
//! agent that also has a thread of its own (a network session's callbacks,
//! a device thread, a library's worker) needs the task to run when *that*
//! thread has something for it, without a clock that polls. It asks
//! [`Setup::waker`](crate::Setup::waker) for a [`Waker`], hands a clone to
//! the thread, and the thread calls [`Waker::wake`] after leaving its data
//! where the step finds it (a queue, a mutex, an atomic). The task then
//! steps, with [`Context::woken_by_waker`](crate::Context::woken_by_waker)
//! true.
//!
//! ```
//! use agent_sdk::testing::Harness;
//! use agent_sdk::{Agent, AgentError, Context, Output, Setup, Task, Waker};
//! use shm_schemas::payloads::Tick;
//! use std::sync::{Arc, Mutex};
//!
//! /// Sends on `out` what its own thread (here: the test) leaves in `inbox`.
//! struct Forward { out: Output<Tick>, inbox: Arc<Mutex<Vec<Tick>>>, waker: Waker }
//!
//! impl Agent for Forward {
//!     const KIND: &'static str = "forward";
//!     fn task() -> Task { Task::EventDriven }
//!     fn new(setup: &mut Setup) -> Result<Self, AgentError> {
//!         Ok(Forward { out: setup.output("out")?, inbox: Arc::default(), waker: setup.waker()? })
//!     }
//!     // in `start`, a real agent gives `self.waker.clone()` and
//!     // `self.inbox.clone()` to the thread it starts
//!     fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
//!         if ctx.woken_by_waker() {
//!             let arrived = std::mem::take(&mut *self.inbox.lock().unwrap());
//!             for t in arrived {
//!                 self.out.send(t)?;
//!             }
//!         }
//!         Ok(())
//!     }
//! }
//!
//! let mut h = Harness::<Forward>::new().unwrap();
//! let (inbox, waker) = (h.agent().inbox.clone(), h.agent().waker.clone());
//! std::thread::spawn(move || {
//!     inbox.lock().unwrap().push(Tick { seq: 7, stamp_ns: 0 });
//!     waker.wake();
//!     waker.wake(); // coalesces with the first: one step
//! })
//! .join()
//! .unwrap();
//! assert!(h.wake_pending());
//! assert_eq!(h.step_if_woken().unwrap(), true);
//! assert_eq!(h.output::<Tick>("out").unwrap()[0].seq, 7);
//! assert_eq!(h.step_if_woken().unwrap(), false, "the two wakes made one step");
//! ```
//!
//! **What it promises.**
//! * No wake is lost: a wake that comes before a step began is seen by
//!   that step, or makes the next one; one that comes while a step runs
//!   makes one more step after it.
//! * Wakes coalesce: any number before the task looks make one step.
//!   Only the first since the last step costs a system call (a write to
//!   an eventfd, under a microsecond); the others are one atomic
//!   operation each.
//! * It is cheap to clone and to keep: `Send + Sync`, one `Arc`. Waking an
//!   agent that has stopped, or is stopping, does nothing (the wake is
//!   dropped with the waker), so a thread may go on waking until it is
//!   joined in [`Agent::stop`](crate::Agent::stop).
//! * A suspended agent is not stepped: the wake counts for the first step
//!   after it resumes, as inputs' samples do.
//! * A periodic task is not woken early: it steps on its clock, and
//!   `woken_by_waker()` says whether a wake came since its last step.
//!   Polling (`--poll`) sees a wake without a system call.
//!
//! **How.** An eventfd attached to the task's WaitSet beside its inputs'
//! listeners (the same WaitSet: a wake and a sample that come together make
//! one step), and a flag that makes the wakes after the first free until
//! the task takes them. In the test harness ([`crate::testing::Harness`])
//! nothing steps on its own: [`Harness::wake_pending`](crate::testing::Harness::wake_pending)
//! says whether a wake waits, [`Harness::step`](crate::testing::Harness::step)
//! takes it, and [`Harness::step_if_woken`](crate::testing::Harness::step_if_woken)
//! steps only when one waits.

use iceoryx2::prelude::{FileDescriptor, FileDescriptorBased, SynchronousMultiplexing};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Why the agent's waker could not be made.
#[derive(Debug, thiserror::Error)]
#[error(
    "cannot make the agent's waker (an eventfd): {source}; the process may have run out of file descriptors (raise `ulimit -n`)"
)]
pub struct WakerError {
    /// what the kernel said
    #[source]
    source: std::io::Error,
}

/// Wakes the agent's event-driven task from another thread of the agent;
/// see the [module](self). Clone it for every thread that needs it.
#[derive(Clone)]
pub struct Waker {
    inner: Arc<Inner>,
}

struct Inner {
    /// the eventfd, non-blocking; counts the wakes the task has not read
    fd: OwnedFd,
    /// the same descriptor, not owned, as iceoryx2's WaitSet takes it
    attach: FileDescriptor,
    /// a wake came that the task has not taken ([`Waker::take`])
    pending: AtomicBool,
}

impl std::fmt::Debug for Waker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Waker").field("pending", &self.inner.pending.load(Ordering::Relaxed)).finish()
    }
}

impl Waker {
    /// A waker with no wake pending.
    pub(crate) fn new() -> Result<Waker, WakerError> {
        // SAFETY: eventfd takes no pointer; it returns a new descriptor or -1.
        let raw = unsafe { libc::eventfd(0, libc::EFD_NONBLOCK | libc::EFD_CLOEXEC) };
        if raw < 0 {
            return Err(WakerError { source: std::io::Error::last_os_error() });
        }
        // SAFETY: `raw` is a descriptor eventfd just opened, owned by no one else.
        let fd = unsafe { OwnedFd::from_raw_fd(raw) };
        let attach = FileDescriptor::non_owning_new(fd.as_raw_fd())
            .ok_or_else(|| WakerError { source: std::io::Error::other("the eventfd has no valid descriptor") })?;
        Ok(Waker { inner: Arc::new(Inner { fd, attach, pending: AtomicBool::new(false) }) })
    }

    /// Wakes the task: it steps soon, with
    /// [`Context::woken_by_waker`](crate::Context::woken_by_waker) true.
    /// Call it after leaving the data where the step finds it. Never
    /// blocks; any thread, any number of times (see the [module](self)).
    pub fn wake(&self) {
        // the first wake since the task last took them writes; the others
        // find the flag set and leave (an RMW: it reads the newest value,
        // so a wake after the task's take always writes)
        if !self.inner.pending.swap(true, Ordering::AcqRel) {
            let one: u64 = 1;
            // SAFETY: writes 8 bytes from a live u64 to the eventfd this
            // waker owns. It fails only when the counter would overflow
            // (EAGAIN: the task already has a wake to read), never blocks.
            let _ = unsafe { libc::write(self.inner.fd.as_raw_fd(), (&one as *const u64).cast(), 8) };
        }
    }

    /// Whether a wake came that the task has not taken (a hint: one atomic
    /// load, no system call).
    pub(crate) fn pending(&self) -> bool {
        self.inner.pending.load(Ordering::Acquire)
    }

    /// Takes the wakes that came: empties the eventfd, then clears the
    /// flag; true when there was one. In this order no wake is lost: a
    /// wake before the clear is the caller's (it steps after), a wake
    /// after it finds the flag clear and writes again.
    pub(crate) fn take(&self) -> bool {
        let mut count: u64 = 0;
        // SAFETY: reads at most 8 bytes into a live u64 from the eventfd
        // this waker owns; non-blocking, so EAGAIN when it is empty.
        let _ = unsafe { libc::read(self.inner.fd.as_raw_fd(), (&mut count as *mut u64).cast(), 8) };
        self.inner.pending.swap(false, Ordering::AcqRel)
    }

    /// What the task's WaitSet attaches (the eventfd).
    pub(crate) fn listener(&self) -> WakerFd<'_> {
        WakerFd(&self.inner.attach)
    }
}

/// The waker's eventfd as iceoryx2's WaitSet takes it
/// (`attach_notification`).
#[derive(Debug)]
pub(crate) struct WakerFd<'a>(&'a FileDescriptor);

impl FileDescriptorBased for WakerFd<'_> {
    fn file_descriptor(&self) -> &FileDescriptor {
        self.0
    }
}

impl SynchronousMultiplexing for WakerFd<'_> {}

#[cfg(test)]
mod tests {
    use super::*;
    use iceoryx2::prelude::*;
    use std::time::Duration;

    #[test]
    fn wakes_coalesce_until_taken_and_a_wake_after_the_take_counts_again() {
        let w = Waker::new().expect("waker");
        assert!(!w.pending() && !w.take(), "nothing pending at first");
        for _ in 0..100 {
            w.wake();
        }
        assert!(w.pending());
        assert!(w.take(), "the hundred wakes are one");
        assert!(!w.pending() && !w.take(), "and taken once");
        w.clone().wake();
        assert!(w.take(), "a clone wakes the same task");
    }

    /// The eventfd in a WaitSet: a wake from another thread ends the wait;
    /// after the take, the WaitSet sleeps again (its timeout, not a wake).
    #[test]
    fn a_wake_from_another_thread_ends_the_waitsets_wait() {
        let w = Waker::new().expect("waker");
        let ws = WaitSetBuilder::new().signal_handling_mode(SignalHandlingMode::Disabled).create::<crate::world::Ipc>();
        let ws = ws.expect("waitset");
        let fd = w.listener();
        let guard = ws.attach_notification(&fd).expect("attach");
        let other = w.clone();
        let t = std::thread::spawn(move || other.wake());
        let mut woke = false;
        // bounded: a lost wake ends here as a failure, not a hang
        for _ in 0..100 {
            ws.wait_and_process_once_with_timeout(
                |id| {
                    woke |= id.has_event_from(&guard);
                    CallbackProgression::Continue
                },
                Duration::from_millis(200),
            )
            .expect("wait");
            if woke {
                break;
            }
        }
        t.join().expect("waker thread");
        assert!(woke, "the wake did not end the wait");
        assert!(w.take());
        let mut again = false;
        ws.wait_and_process_once_with_timeout(
            |id| {
                again |= id.has_event_from(&guard);
                CallbackProgression::Continue
            },
            Duration::from_millis(20),
        )
        .expect("wait");
        assert!(!again, "a taken wake wakes no more");
    }

    /// Counts the steps its waker woke; sends one tick per such step.
    struct Woken {
        waker: Waker,
        out: crate::Output<shm_schemas::payloads::Tick>,
    }

    impl crate::Agent for Woken {
        const KIND: &'static str = "woken";
        fn task() -> crate::Task {
            crate::Task::EventDriven
        }
        fn new(setup: &mut crate::Setup) -> Result<Self, crate::AgentError> {
            let waker = setup.waker()?;
            assert!(Arc::ptr_eq(&waker.inner, &setup.waker()?.inner), "one waker per agent");
            Ok(Woken { waker, out: setup.output("out")? })
        }
        fn step(&mut self, ctx: &mut crate::Context) -> Result<(), crate::AgentError> {
            if ctx.woken_by_waker() {
                self.out.send(shm_schemas::payloads::Tick { seq: ctx.cycle(), stamp_ns: ctx.now_ns() })?;
            }
            Ok(())
        }
    }

    /// In a Wiring, `settle` steps an agent whose waker was woken (once for
    /// many wakes), and a suspended one only after it resumes.
    #[test]
    fn a_wiring_steps_an_agent_its_waker_woke() {
        use crate::testing::Wiring;
        use shm_schemas::payloads::Tick;
        let mut w = Wiring::new();
        w.add::<Woken>("w").expect("add");
        assert_eq!(w.settle().expect("settle"), 0, "nothing woke it");
        let waker = w.agent::<Woken>("w").expect("agent").waker.clone();
        waker.wake();
        waker.wake();
        assert_eq!(w.settle().expect("settle"), 1, "two wakes, one step");
        assert_eq!(w.output::<Tick>("w/out").expect("out").len(), 1);
        w.suspend("w").expect("suspend");
        waker.wake();
        assert_eq!(w.settle().expect("settle"), 0, "no step while suspended");
        assert_eq!(w.resume("w").expect("resume"), 1, "the wake counts after resuming");
        assert_eq!(w.output::<Tick>("w/out").expect("out").len(), 1);
    }
}
