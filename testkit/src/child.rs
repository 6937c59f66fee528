//! Children that never outlive their test or benchmark: a [`ChildGuard`]
//! stops its child when dropped (SIGTERM, a short grace, then SIGKILL),
//! and the kernel sends the child SIGTERM should this process die first.

use crate::Error;
use std::os::unix::process::CommandExt as _;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

/// How long a child may take to say it is ready.
pub const READY_WITHIN: Duration = Duration::from_secs(60);

/// A child process that is stopped when dropped.
#[derive(Debug)]
pub struct ChildGuard {
    name: String,
    child: Child,
}

/// Spawns `cmd` so that the child gets SIGTERM if this process dies
/// (`PR_SET_PDEATHSIG`): a run killed half-way leaves no process behind.
pub fn spawn_dying_with_us(cmd: &mut Command) -> std::io::Result<Child> {
    // SAFETY: the closure runs in the child between fork and exec; prctl is
    // async-signal-safe, allocates nothing and touches no memory of the parent.
    unsafe {
        cmd.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM as libc::c_ulong, 0, 0, 0) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    cmd.spawn()
}

impl ChildGuard {
    /// Spawns `cmd` as `name` (used in messages); the child gets SIGTERM if this process dies.
    pub fn spawn(name: &str, mut cmd: Command) -> Result<Self, Error> {
        let child = spawn_dying_with_us(&mut cmd).map_err(|source| Error::Spawn {
            name: name.into(),
            command: format!("{cmd:?}"),
            source,
        })?;
        Ok(ChildGuard { name: name.into(), child })
    }

    /// The child's pid.
    pub fn id(&self) -> u32 {
        self.child.id()
    }

    /// The child's stdin, when piped.
    pub fn stdin(&mut self) -> Option<std::process::ChildStdin> {
        self.child.stdin.take()
    }

    /// The child's stdout, when piped.
    pub fn stdout(&mut self) -> Option<std::process::ChildStdout> {
        self.child.stdout.take()
    }

    /// Reads the child's `ready` line (its stdout must be piped); its exit,
    /// any other line, or no line within [`READY_WITHIN`] is an error (a
    /// child stuck in its start would otherwise hold the run forever).
    pub fn await_ready(&mut self, what: &str) -> Result<(), Error> {
        use std::io::BufRead as _;
        let out = self.stdout().ok_or_else(|| Error::NoStdout { what: what.into() })?;
        let (tx, rx) = std::sync::mpsc::channel();
        // the reader ends with the child's stdout: at its line, its exit, or
        // when the guard stops the child after a timeout
        std::thread::spawn(move || {
            let mut line = String::new();
            let r = std::io::BufReader::new(out).read_line(&mut line).map(|_| line);
            let _ = tx.send(r);
        });
        let line = match rx.recv_timeout(READY_WITHIN) {
            Ok(r) => r.map_err(|source| Error::ReadReady { what: what.into(), source })?,
            Err(_) => {
                self.check_alive()?;
                return Err(Error::ReadyTimeout { what: what.into(), within: READY_WITHIN });
            }
        };
        if line.trim() != "ready" {
            self.check_alive()?;
            return Err(Error::NotReady { what: what.into(), said: line });
        }
        Ok(())
    }

    /// Fails when the child has exited already.
    pub fn check_alive(&mut self) -> Result<(), Error> {
        let status = self.child.try_wait().map_err(|source| Error::Wait { name: self.name.clone(), source })?;
        match status {
            Some(status) => Err(Error::ExitedEarly { name: self.name.clone(), status }),
            None => Ok(()),
        }
    }

    /// Stops the child: SIGTERM, up to `grace`, then SIGKILL.
    pub fn stop(&mut self, grace: Duration) {
        if matches!(self.child.try_wait(), Ok(Some(_))) {
            return;
        }
        if let Ok(pid) = libc::pid_t::try_from(self.child.id()) {
            // SAFETY: kill has no memory-safety preconditions; the pid is our
            // child's, not yet waited for, so it cannot have been reused.
            unsafe { libc::kill(pid, libc::SIGTERM) };
        }
        let t0 = Instant::now();
        while t0.elapsed() < grace {
            if matches!(self.child.try_wait(), Ok(Some(_))) {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        self.stop(Duration::from_secs(2));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_guard_stops_its_child_when_dropped_and_reports_an_early_exit() {
        let mut cmd = Command::new("sleep");
        cmd.arg("30");
        let guard = ChildGuard::spawn("sleep", cmd).expect("spawn sleep");
        let pid = guard.id();
        assert!(crate::alive(pid));
        drop(guard);
        assert!(!crate::exists(pid), "the child of a dropped guard is still there");

        let mut quick = ChildGuard::spawn("true", Command::new("true")).expect("spawn true");
        assert!(crate::wait_until(Duration::from_secs(5), || quick.check_alive().is_err()));
        let err = quick.check_alive().expect_err("true has exited");
        assert!(err.to_string().contains("true exited early"), "{err}");
    }
}
