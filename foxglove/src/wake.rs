//! Waiting without polling: the serving thread sleeps until a port has a
//! sample, a client asked something or a client connects, and a client's
//! thread until its socket has a request, its queue has something to send
//! or its socket takes more; neither looks at anything on a timer but the
//! refresh, the pings and the stall timeout.
//!
//! A [`Wake`] is a socket pair: the side that queued something writes a
//! byte ([`Wake::wake`]), the sleeper waits for its other end to be
//! readable with [`wait_fds`] (`poll(2)`) and empties it
//! ([`Wake::drain`]) before it looks at what was queued, so a wake-up
//! that comes after the look is never lost.

use std::io::{ErrorKind, Read as _, Write as _};
use std::os::fd::{AsRawFd as _, RawFd};
use std::os::unix::net::UnixStream;
use std::time::Duration;

/// One end to wake a sleeper, the other to sleep on.
#[derive(Debug)]
pub(crate) struct Wake {
    tx: UnixStream,
    rx: UnixStream,
}

impl Wake {
    /// A new pair, both ends non-blocking (a full pair already wakes its sleeper).
    pub(crate) fn new() -> std::io::Result<Wake> {
        let (tx, rx) = UnixStream::pair()?;
        tx.set_nonblocking(true)?;
        rx.set_nonblocking(true)?;
        Ok(Wake { tx, rx })
    }

    /// Wakes the sleeper (from any thread; never blocks).
    pub(crate) fn wake(&self) {
        // WouldBlock: bytes wait already, the sleeper wakes anyway
        let _ = (&self.tx).write(&[1]);
    }

    /// The descriptor to sleep on.
    pub(crate) fn fd(&self) -> RawFd {
        self.rx.as_raw_fd()
    }

    /// Takes every byte written so far.
    pub(crate) fn drain(&self) {
        let mut buf = [0u8; 256];
        loop {
            match (&self.rx).read(&mut buf) {
                Ok(n) if n == buf.len() => {}
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                _ => return,
            }
        }
    }
}

/// What to wait for on a descriptor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interest {
    /// something to read (or the peer hung up)
    Read,
    /// something to read, or room to write
    ReadWrite,
}

/// Waits until one of `fds` is ready as asked, or `timeout` passed, or a
/// signal came; whether each is ready (all false after a timeout). A
/// descriptor that is closed or in error counts as ready, so that its
/// reader finds out why.
pub fn wait_fds(fds: &[(RawFd, Interest)], timeout: Duration) -> std::io::Result<Vec<bool>> {
    let mut polled: Vec<libc::pollfd> = fds
        .iter()
        .map(|&(fd, interest)| libc::pollfd {
            fd,
            events: match interest {
                Interest::Read => libc::POLLIN,
                Interest::ReadWrite => libc::POLLIN | libc::POLLOUT,
            },
            revents: 0,
        })
        .collect();
    // rounded up, so that a wait for 0.4 ms does not spin until it is due
    let ms = timeout.as_micros().div_ceil(1000);
    let ms = libc::c_int::try_from(ms).unwrap_or(libc::c_int::MAX);
    let n = libc::nfds_t::try_from(polled.len()).map_err(|_| std::io::Error::from(ErrorKind::InvalidInput))?;
    // SAFETY: `polled` is a live, exclusively borrowed array of `n` pollfd
    // structs for the whole call; poll only reads `fd`/`events` and writes
    // `revents` of those entries. A descriptor that is closed meanwhile is
    // reported as POLLNVAL, never dereferenced.
    let r = unsafe { libc::poll(polled.as_mut_ptr(), n, ms) };
    if r < 0 {
        let e = std::io::Error::last_os_error();
        if e.kind() == ErrorKind::Interrupted {
            return Ok(vec![false; fds.len()]);
        }
        return Err(e);
    }
    Ok(polled.iter().map(|p| p.revents != 0).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wake_ends_a_wait_and_a_drained_pair_sleeps_again() {
        let w = Wake::new().expect("pair");
        let ready = wait_fds(&[(w.fd(), Interest::Read)], Duration::ZERO).expect("poll");
        assert_eq!(ready, [false], "nothing written: not ready");
        for _ in 0..1000 {
            w.wake();
        }
        let ready = wait_fds(&[(w.fd(), Interest::Read)], Duration::from_secs(5)).expect("poll");
        assert_eq!(ready, [true]);
        w.drain();
        let ready = wait_fds(&[(w.fd(), Interest::Read)], Duration::ZERO).expect("poll");
        assert_eq!(ready, [false], "drained: not ready");
    }

    #[test]
    fn a_wake_from_another_thread_ends_a_long_wait() {
        let w = std::sync::Arc::new(Wake::new().expect("pair"));
        let w2 = std::sync::Arc::clone(&w);
        let t = std::thread::spawn(move || w2.wake());
        // bounded: the test fails (all false) instead of hanging if the wake is lost
        let ready = wait_fds(&[(w.fd(), Interest::Read)], Duration::from_secs(30)).expect("poll");
        t.join().expect("thread");
        assert_eq!(ready, [true]);
    }
}
