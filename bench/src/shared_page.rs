//! A small file mapped shared by two processes, and futex waits and wakes
//! on its 32-bit words: the futex floor of `hop` ([`crate::futex`]) and the
//! closed-loop acknowledgements of `images` (`images::frame::Acks`).

use anyhow::{Context as _, Result, bail};
use std::os::fd::AsRawFd as _;
use std::path::Path;
use std::sync::atomic::AtomicU32;
use std::time::Duration;

/// The first `len` bytes of a file, mapped shared, read and written as
/// 32-bit atomic words.
#[derive(Debug)]
pub struct SharedPage {
    ptr: *mut AtomicU32,
    len: usize,
}

// SAFETY: the mapping is process-wide and only accessed through atomics.
unsafe impl Send for SharedPage {}

impl SharedPage {
    /// Maps the first `len` bytes of the file at `path` (at least that long).
    pub fn map(path: &Path, len: usize) -> Result<Self> {
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .with_context(|| format!("cannot open {}", path.display()))?;
        // SAFETY: a fresh shared mapping of a file we opened read-write; checked below.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                f.as_raw_fd(),
                0,
            )
        };
        if p == libc::MAP_FAILED {
            bail!("cannot map {}: {}", path.display(), std::io::Error::last_os_error());
        }
        Ok(SharedPage { ptr: p.cast(), len })
    }

    /// The `index`-th 32-bit word of the mapping.
    pub fn word(&self, index: usize) -> &AtomicU32 {
        assert!((index + 1) * 4 <= self.len, "word {index} lies beyond the {} mapped bytes", self.len);
        // SAFETY: within the mapping (checked above), which is page aligned and
        // alive as long as self; AtomicU32 may be shared across processes.
        unsafe { &*self.ptr.add(index) }
    }
}

impl Drop for SharedPage {
    fn drop(&mut self) {
        // SAFETY: unmapping our own mapping once; no reference outlives self.
        unsafe { libc::munmap(self.ptr.cast(), self.len) };
    }
}

/// Waits while `word` still holds `expected`, at most `timeout` (a shared,
/// not process-private, futex: the waker is another process).
pub fn futex_wait(word: &AtomicU32, expected: u32, timeout: Duration) {
    let ts = libc::timespec {
        tv_sec: timeout.as_secs() as libc::time_t,
        tv_nsec: libc::c_long::from(timeout.subsec_nanos() as i32),
    };
    // SAFETY: FUTEX_WAIT reads the word through a valid pointer; ts is valid; a relative timeout.
    unsafe { libc::syscall(libc::SYS_futex, word.as_ptr(), libc::FUTEX_WAIT, expected, &ts as *const libc::timespec) };
}

/// Wakes up to `n` waiters on `word`.
pub fn futex_wake(word: &AtomicU32, n: i32) {
    // SAFETY: FUTEX_WAKE only uses the address as a key.
    unsafe { libc::syscall(libc::SYS_futex, word.as_ptr(), libc::FUTEX_WAKE, n) };
}
