//! Bounded waits: every wait ends after the time it is given, and says
//! whether what it waited for came.

use crate::{ChildGuard, Error};
use std::path::Path;
use std::time::{Duration, Instant};

/// Polls `cond` every 20 ms until it holds or `timeout` passes; returns whether it held.
pub fn wait_until(timeout: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let t0 = Instant::now();
    loop {
        if cond() {
            return true;
        }
        if t0.elapsed() > timeout {
            return false;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits up to `timeout` for a file to appear (polling every 2 ms), watching
/// `children` for early exits (an error); returns whether it appeared.
pub fn wait_file(path: &Path, timeout: Duration, children: &mut [&mut ChildGuard]) -> Result<bool, Error> {
    let t0 = Instant::now();
    while t0.elapsed() < timeout {
        if path.exists() {
            return Ok(true);
        }
        for c in children.iter_mut() {
            c.check_alive()?;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    Ok(false)
}

/// Waits for a file to appear as [`wait_file`] does, after sleeping through
/// `quiet` (at most `timeout`) without a wake-up: for a batch known to take
/// about that long, so that this process's polling does not run on the
/// CPUs beside the batch it measures (every 2 ms at SCHED_FIFO 20, which a
/// woken agent would have to wait for).
pub fn wait_file_after(
    path: &Path,
    quiet: Duration,
    timeout: Duration,
    children: &mut [&mut ChildGuard],
) -> Result<bool, Error> {
    let quiet = quiet.min(timeout);
    std::thread::sleep(quiet);
    wait_file(path, timeout.saturating_sub(quiet), children)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wait_file_after_sleeps_through_the_quiet_time_then_finds_the_file() {
        let dir = std::env::temp_dir().join(format!("nerve-testkit-wait-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a folder");
        let path = dir.join("batch-1.txt");
        std::fs::write(&path, "1\n").expect("a batch file");
        let t0 = Instant::now();
        let found = wait_file_after(&path, Duration::from_millis(100), Duration::from_secs(5), &mut []);
        assert!(found.expect("no child to fail"));
        assert!(t0.elapsed() >= Duration::from_millis(100), "it looked before its quiet time was over");
        // a file that never comes: false once the whole timeout has passed
        let t0 = Instant::now();
        let none = dir.join("batch-2.txt");
        let found = wait_file_after(&none, Duration::from_millis(50), Duration::from_millis(120), &mut []);
        let _ = std::fs::remove_dir_all(&dir);
        assert!(!found.expect("no child to fail"));
        assert!(t0.elapsed() >= Duration::from_millis(120));
    }

    #[test]
    fn wait_until_says_whether_the_condition_came() {
        let mut n = 0;
        assert!(wait_until(Duration::from_secs(5), || {
            n += 1;
            n == 3
        }));
        assert!(!wait_until(Duration::from_millis(50), || false));
    }
}
