//! SIGTERM and SIGINT, kept until they are acted on.
//!
//! iceoryx2's signal handler records the last signal it caught in a single
//! slot: any later signal it catches overwrites it (SIGCONT, SIGURG,
//! SIGUSR1, ...), and its set-up of zeroed shared memory clears it. systemd
//! stops a unit with SIGTERM followed at once by SIGCONT, so a process that
//! waited on a WaitSet with `HandleTerminationRequests` could find SIGCONT in
//! the slot, never see the SIGTERM and run on until SIGKILL: here one agent
//! in 20 (`kill -TERM; kill -CONT`), and the router every time when it was
//! stopped (SIGSTOP) as the two came.
//!
//! [`install`] lets iceoryx2 put its handlers in first (they are installed
//! once, on its first use of signals, and would otherwise replace ours),
//! then takes SIGTERM and SIGINT itself: a flag that nothing clears
//! ([`requested`]) and a byte written to a pipe. The read end
//! ([`Termination`]) is attached to the waiting thread's WaitSet, so the
//! request wakes it whichever thread the kernel delivered the signal to.
//! The other signals iceoryx2 catches (job control, SIGQUIT, SIGUSR1, ...)
//! get back the actions they had before it, which it would otherwise
//! swallow: Ctrl-Z still suspends a command, SIGQUIT still quits.

use iceoryx2::prelude::{FileDescriptor, FileDescriptorBased, SynchronousMultiplexing};
use std::os::fd::{AsRawFd, IntoRawFd, OwnedFd};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

/// Set by SIGTERM or SIGINT once [`install`] ran; never cleared.
static REQUESTED: AtomicBool = AtomicBool::new(false);
/// The pipe's write end, for the handler (-1 before [`install`]).
static WAKE_FD: AtomicI32 = AtomicI32::new(-1);
/// The one installation of the process.
static INSTALLED: OnceLock<Result<Termination, String>> = OnceLock::new();

/// The read end of the pipe a termination signal writes to: attach it to a
/// WaitSet. It is never emptied: once woken, the waiting loop sees
/// [`requested`] before it would wait again, and ends.
#[derive(Debug)]
pub struct Termination {
    read: FileDescriptor,
}

impl FileDescriptorBased for Termination {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.read
    }
}

impl SynchronousMultiplexing for Termination {}

extern "C" fn on_signal(_: libc::c_int) {
    REQUESTED.store(true, Ordering::SeqCst);
    let fd = WAKE_FD.load(Ordering::SeqCst);
    if fd >= 0 {
        // SAFETY: errno is thread-local; saved and restored around write,
        // which is async-signal-safe. A full pipe already wakes its reader.
        unsafe {
            let errno = *libc::__errno_location();
            let byte = 1u8;
            let _ = libc::write(fd, (&byte as *const u8).cast(), 1);
            *libc::__errno_location() = errno;
        }
    }
}

/// Takes SIGTERM and SIGINT for this process (once; later calls return the
/// same). Call it after any fork that should not inherit it (a daemon's)
/// and before the process waits for work.
pub fn install() -> Result<&'static Termination, &'static str> {
    INSTALLED.get_or_init(make).as_ref().map_err(String::as_str)
}

/// The installation, where [`install`] succeeded.
pub fn installed() -> Option<&'static Termination> {
    INSTALLED.get().and_then(|r| r.as_ref().ok())
}

/// Whether SIGTERM or SIGINT came since [`install`].
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}

/// The signals iceoryx2's handler catches besides SIGTERM and SIGINT
/// (`iceoryx2_bb_posix::signal::NonFatalFetchableSignal`).
const ALSO_CAUGHT_BY_ICEORYX2: [libc::c_int; 11] = [
    libc::SIGCONT,
    libc::SIGABRT,
    libc::SIGQUIT,
    libc::SIGTSTP,
    libc::SIGTTIN,
    libc::SIGTTOU,
    libc::SIGUSR1,
    libc::SIGUSR2,
    libc::SIGPROF,
    libc::SIGURG,
    libc::SIGVTALRM,
];

fn make() -> Result<Termination, String> {
    use iceoryx2_bb_posix::signal::{NonFatalFetchableSignal, SignalHandler};
    use nix::fcntl::OFlag;
    use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
    // iceoryx2 installs its handlers on its first use of signals, over
    // whatever was there: have it done now, so that ours stay. A request
    // its handler caught before is taken over (the call empties its record).
    // It also catches job control and others (SIGTSTP, SIGQUIT, SIGUSR1,
    // ...), which it would then swallow: Ctrl-Z would no longer suspend
    // `nerve logs --follow`. Those get back what they had before.
    let before: Vec<(libc::c_int, libc::sigaction)> = ALSO_CAUGHT_BY_ICEORYX2
        .iter()
        .filter_map(|&sig| {
            // SAFETY: an all-zero sigaction is a valid value (no handler, empty mask)
            let mut old: libc::sigaction = unsafe { std::mem::zeroed() };
            // SAFETY: a null new action only reads the current one into `old`.
            (unsafe { libc::sigaction(sig, std::ptr::null(), &mut old) } == 0).then_some((sig, old))
        })
        .collect();
    if matches!(
        SignalHandler::last_signal(),
        Some(NonFatalFetchableSignal::Terminate | NonFatalFetchableSignal::Interrupt)
    ) {
        REQUESTED.store(true, Ordering::SeqCst);
    }
    for (sig, old) in &before {
        // SAFETY: puts back an action read above, unchanged.
        unsafe { libc::sigaction(*sig, old, std::ptr::null_mut()) };
    }
    let (read, write): (OwnedFd, OwnedFd) = nix::unistd::pipe2(OFlag::O_NONBLOCK | OFlag::O_CLOEXEC)
        .map_err(|e| format!("cannot make the pipe for termination signals: {e}"))?;
    let read = FileDescriptor::new(read.into_raw_fd())
        .ok_or_else(|| "the pipe for termination signals has no valid descriptor".to_owned())?;
    WAKE_FD.store(write.as_raw_fd(), Ordering::SeqCst);
    // the write end lives as long as the process
    let _ = write.into_raw_fd();
    // SA_RESTART: a read or write the signal interrupts in other code goes
    // on; waits (epoll) still return, and the pipe wakes the one that matters
    let act = SigAction::new(SigHandler::Handler(on_signal), SaFlags::SA_RESTART, SigSet::empty());
    for sig in [Signal::SIGTERM, Signal::SIGINT] {
        // SAFETY: the handler only stores to an atomic and writes to a pipe,
        // both async-signal-safe.
        unsafe { sigaction(sig, &act) }.map_err(|e| format!("cannot take {sig}: {e}"))?;
    }
    Ok(Termination { read })
}
