//! Processes that nerve learned by pid (an agent's registration, a pid file,
//! the router's list of agents) and may signal later, signalled only while
//! they are still the process that was meant.
//!
//! A pid is a number the kernel hands out again once its process is reaped:
//! an agent that exits during `nerve down`'s grace can leave its pid to an
//! unrelated program (reliability review R6). A [`ProcessHandle`] is taken
//! when the pid is learned: it opens a pidfd (`pidfd_open`, Linux 5.3 and
//! later) and records the process's start time (field 22 of
//! `/proc/<pid>/stat`). Before each signal and liveness answer it checks the
//! start time again, and it signals through the pidfd (`pidfd_send_signal`),
//! so a signal never reaches a process that took the pid since. On a kernel
//! without pidfds the start-time check alone remains.
//!
//! [`ProcessHandle::is_nerve`] tells nerve's own programs from others: the
//! executable's file name starts with [`EXECUTABLE_PREFIX`] (`nerve`, the
//! agents `nerve-*`), or the process holds a live iceoryx2 node of the robot
//! (an agent built from the SDK under another name, `exe = "path"` in a
//! launch file). A `tail -f .../logs/t1.log` whose command line names nerve
//! and the robot is neither.

use crate::world::World;
use nix::sys::signal::Signal;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The start of the file name of every nerve executable: the `nerve`
/// program (CLI and router) and the agents `nerve-<kind>`.
pub const EXECUTABLE_PREFIX: &str = "nerve";

/// Why a process could not be taken or signalled.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// The process exited, or its pid now names another process.
    #[error(
        "process {pid} is not running any more (it exited, or its pid now names another process); nothing was signalled"
    )]
    Gone {
        /// the pid as it was learned
        pid: u32,
    },
    /// The kernel refused the signal.
    #[error("cannot send {signal} to process {pid}: {source}")]
    Signal {
        /// the process
        pid: u32,
        /// the signal
        signal: Signal,
        /// what the kernel said
        #[source]
        source: nix::Error,
    },
}

/// A process known by its pid and its start time, with a pidfd where the
/// kernel has them. Cheap to clone (the pidfd is shared).
#[derive(Debug, Clone)]
pub struct ProcessHandle {
    pid: u32,
    start_time: u64,
    pidfd: Option<Arc<OwnedFd>>,
}

/// The fields of `/proc/<pid>/stat` this module needs.
struct Stat {
    /// field 3: R, S, D, Z, X...
    state: char,
    /// field 22: clock ticks after boot when the process started
    start_time: u64,
}

fn read_stat(pid: u32) -> Option<Stat> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // the command name (field 2) is in parentheses and may hold spaces and
    // parentheses itself: the fields that follow start after the last ')'
    let (_, rest) = stat.rsplit_once(')')?;
    let mut fields = rest.split_whitespace();
    let state = fields.next()?.chars().next()?;
    // field 3 was the first after ')': field 22 is 19 further on
    let start_time = fields.nth(18)?.parse().ok()?;
    Some(Stat { state, start_time })
}

/// The start time of process `pid` (field 22 of `/proc/<pid>/stat`), if it exists.
pub fn start_time(pid: u32) -> Option<u64> {
    read_stat(pid).map(|s| s.start_time)
}

/// What a process holds, from `/proc/<pid>`: its resident memory and its
/// open descriptors, as the soak benchmark and the chaos test watch them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Holdings {
    /// resident memory (`VmRSS`), KiB
    pub rss_kib: u64,
    /// open file descriptors
    pub fds: u64,
}

/// What `pid` holds now; zeros for a process that is gone or unreadable.
pub fn holdings(pid: u32) -> Holdings {
    let rss_kib = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines().find_map(|l| l.strip_prefix("VmRSS:")).and_then(|v| v.split_whitespace().next()?.parse().ok())
        })
        .unwrap_or(0);
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count() as u64);
    Holdings { rss_kib, fds }
}

/// Whether `exe` (a path, as `/proc/<pid>/exe` reads) is one of nerve's
/// executables: its file name starts with [`EXECUTABLE_PREFIX`].
pub fn is_nerve_executable(exe: &Path) -> bool {
    exe.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(EXECUTABLE_PREFIX))
}

/// A pidfd of `pid`: `Ok(None)` when the kernel has no pidfds or none can be
/// opened now (the start-time checks remain), `Err` when there is no such process.
fn pidfd_open(pid: u32) -> Result<Option<OwnedFd>, ProcessError> {
    // SAFETY: pidfd_open takes a pid and flags, no pointers.
    let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid as libc::pid_t, 0 as libc::c_uint) };
    if fd >= 0 {
        // SAFETY: the kernel just returned this descriptor to us; nothing else owns it.
        return Ok(Some(unsafe { OwnedFd::from_raw_fd(fd as libc::c_int) }));
    }
    match nix::errno::Errno::last() {
        nix::errno::Errno::ESRCH => Err(ProcessError::Gone { pid }),
        e => {
            tracing::debug!(pid, error = %e, "no pidfd for this process; relying on its start time");
            Ok(None)
        }
    }
}

/// Whether the process of `pidfd` has exited (the pidfd reads as readable then).
fn pidfd_exited(pidfd: &OwnedFd) -> bool {
    pidfd_exited_within(pidfd, 0)
}

/// Whether the process of `pidfd` exits within `ms` milliseconds: asleep in
/// `poll` until then, no wake-up in between (an interrupted poll counts as
/// not yet).
fn pidfd_exited_within(pidfd: &OwnedFd, ms: libc::c_int) -> bool {
    let mut p = libc::pollfd { fd: pidfd.as_raw_fd(), events: libc::POLLIN, revents: 0 };
    // SAFETY: one valid pollfd.
    let rc = unsafe { libc::poll(&mut p, 1, ms) };
    rc > 0 && p.revents & (libc::POLLIN | libc::POLLHUP | libc::POLLERR | libc::POLLNVAL) != 0
}

impl ProcessHandle {
    /// Takes a handle of the process that has pid `pid` now: opens a pidfd
    /// and records its start time. Take it when the pid is learned (a
    /// registration, a pid file read, the router's list), not later.
    pub fn take(pid: u32) -> Result<Self, ProcessError> {
        if pid == 0 || pid > i32::MAX as u32 {
            return Err(ProcessError::Gone { pid });
        }
        let pidfd = pidfd_open(pid)?;
        let stat = read_stat(pid).ok_or(ProcessError::Gone { pid })?;
        let handle = ProcessHandle { pid, start_time: stat.start_time, pidfd: pidfd.map(Arc::new) };
        // the start time read above is the pidfd's process's only if that
        // process is still there now (otherwise the pid may name another)
        if !handle.is_alive() {
            return Err(ProcessError::Gone { pid });
        }
        Ok(handle)
    }

    /// A handle of the process that had pid `pid` and start time
    /// `start_time` when they were recorded (e.g. by another program): it
    /// acts only while the process with that pid has that start time.
    pub fn from_parts(pid: u32, start_time: u64) -> Self {
        ProcessHandle { pid, start_time, pidfd: None }
    }

    /// The pid.
    pub fn pid(&self) -> u32 {
        self.pid
    }

    /// The start time recorded when the handle was taken (clock ticks after boot).
    pub fn start_time(&self) -> u64 {
        self.start_time
    }

    /// Whether the process is alive: it has not exited (a zombie has), and
    /// its pid has not been reused since the handle was taken.
    pub fn is_alive(&self) -> bool {
        // A pidfd names one process, never a later one with the same pid,
        // and polls readable once it exited (a zombie included): it answers
        // alone. The router asks this of every agent before every request,
        // where reading `/proc/<pid>/stat` instead took about a fifth of its
        // CPU for a `nerve ps` of 100 agents.
        if let Some(fd) = &self.pidfd {
            return !pidfd_exited(fd);
        }
        match read_stat(self.pid) {
            Some(s) => s.start_time == self.start_time && !matches!(s.state, 'Z' | 'X' | 'x'),
            None => false,
        }
    }

    /// Waits up to `timeout` for the process to exit (a zombie has); true
    /// when it has. With a pidfd the caller sleeps until the exit, without
    /// waking in between (a benchmark's harness waits this way beside what
    /// it measures); without one, it looks every 5 ms.
    pub fn wait_exit(&self, timeout: Duration) -> bool {
        let t0 = Instant::now();
        loop {
            let left = timeout.saturating_sub(t0.elapsed());
            let exited = match &self.pidfd {
                Some(fd) => {
                    let ms = libc::c_int::try_from(left.as_millis().saturating_add(1)).unwrap_or(libc::c_int::MAX);
                    pidfd_exited_within(fd, ms)
                }
                None => !self.is_alive(),
            };
            if exited {
                return true;
            }
            if left.is_zero() {
                return false;
            }
            if self.pidfd.is_none() {
                std::thread::sleep(left.min(Duration::from_millis(5)));
            }
        }
    }

    /// Sends `signal` to the process, only if it is still the one the handle
    /// was taken of: [`ProcessError::Gone`] otherwise, and nothing is sent.
    pub fn signal(&self, signal: Signal) -> Result<(), ProcessError> {
        if !self.is_alive() {
            return Err(ProcessError::Gone { pid: self.pid });
        }
        let sent = match &self.pidfd {
            Some(fd) => {
                // SAFETY: a valid pidfd, a signal number, no siginfo (null), no flags.
                let rc = unsafe {
                    libc::syscall(
                        libc::SYS_pidfd_send_signal,
                        fd.as_raw_fd(),
                        signal as libc::c_int,
                        std::ptr::null::<libc::siginfo_t>(),
                        0 as libc::c_uint,
                    )
                };
                if rc == 0 { Ok(()) } else { Err(nix::errno::Errno::last()) }
            }
            None => nix::sys::signal::kill(nix::unistd::Pid::from_raw(self.pid as i32), signal),
        };
        match sent {
            Ok(()) => Ok(()),
            Err(nix::errno::Errno::ESRCH) => Err(ProcessError::Gone { pid: self.pid }),
            Err(source) => Err(ProcessError::Signal { pid: self.pid, signal, source }),
        }
    }

    /// A `/proc/<pid>/...` read that is answered only while the process is
    /// still the one the handle was taken of (checked after the read).
    fn read_proc<T>(&self, read: impl FnOnce(&Path) -> Option<T>) -> Option<T> {
        let dir = PathBuf::from(format!("/proc/{}", self.pid));
        let value = read(&dir)?;
        self.is_alive().then_some(value)
    }

    /// The process's executable (`/proc/<pid>/exe`; ends in ` (deleted)`
    /// when the file was replaced since it started).
    pub fn exe(&self) -> Option<PathBuf> {
        self.read_proc(|d| std::fs::read_link(d.join("exe")).ok())
    }

    /// The process's effective uid.
    pub fn uid(&self) -> Option<u32> {
        self.read_proc(|d| {
            let status = std::fs::read_to_string(d.join("status")).ok()?;
            let line = status.lines().find_map(|l| l.strip_prefix("Uid:"))?;
            // real, effective, saved, filesystem
            line.split_whitespace().nth(1)?.parse().ok()
        })
    }

    /// The process's command line.
    pub fn args(&self) -> Option<Vec<String>> {
        self.read_proc(|d| {
            let raw = std::fs::read(d.join("cmdline")).ok()?;
            Some(
                raw.split(|b| *b == 0)
                    .filter(|a| !a.is_empty())
                    .map(|a| String::from_utf8_lossy(a).into_owned())
                    .collect(),
            )
        })
    }

    /// The robot the process works for, as a nerve program reads it: its
    /// `--robot` argument, else its `NERVE_ROBOT`, else the default robot.
    pub fn robot(&self) -> Option<String> {
        let args = self.args()?;
        let named = args
            .windows(2)
            .find(|w| w[0] == "--robot")
            .map(|w| w[1].clone())
            .or_else(|| args.iter().find_map(|a| a.strip_prefix("--robot=").map(str::to_owned)));
        if named.is_some() {
            return named;
        }
        let from_env = self.read_proc(|d| {
            let env = std::fs::read(d.join("environ")).ok()?;
            let key = format!("{}=", crate::world::ROBOT_ENV);
            Some(env.split(|b| *b == 0).find_map(|v| String::from_utf8_lossy(v).strip_prefix(&key).map(str::to_owned)))
        })?;
        Some(from_env.unwrap_or_else(|| crate::world::DEFAULT_ROBOT.to_owned()))
    }

    /// Whether the process runs a nerve executable ([`is_nerve_executable`]).
    pub fn runs_nerve_executable(&self) -> bool {
        self.exe().is_some_and(|e| is_nerve_executable(&e))
    }

    /// Whether the process is one of nerve's in `world`: it runs a nerve
    /// executable, or it holds a live iceoryx2 node of `world` (an agent
    /// built from the SDK under another file name). Reading the nodes lists
    /// the world's node records, so the executable is checked first.
    pub fn is_nerve(&self, world: &World) -> bool {
        self.runs_nerve_executable() || (world.live_node_pids().contains(&self.pid) && self.is_alive())
    }
}

#[cfg(test)]
mod tests {
    use super::{ProcessError, ProcessHandle, is_nerve_executable, start_time};
    use nix::sys::signal::Signal;
    use std::path::Path;
    use std::process::{Child, Command};
    use std::time::{Duration, Instant};

    /// A `sleep` child, killed and reaped when dropped.
    struct Sleeper(Child);

    impl Sleeper {
        fn start() -> Self {
            Sleeper(Command::new("sleep").arg("30").spawn().expect("start sleep"))
        }
        fn pid(&self) -> u32 {
            self.0.id()
        }
        fn running(&mut self) -> bool {
            matches!(self.0.try_wait(), Ok(None))
        }
    }

    impl Drop for Sleeper {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }

    /// `wait_exit` returns at the exit (the child is left to reap), with a
    /// pidfd and without one, and gives up at its timeout.
    #[test]
    fn wait_exit_returns_at_the_exit_or_at_the_timeout() {
        let mut short = Command::new("sleep").arg("0.2").spawn().expect("start sleep");
        let handle = ProcessHandle::take(short.id()).expect("sleep runs");
        let no_pidfd = ProcessHandle::from_parts(short.id(), handle.start_time());
        let t0 = Instant::now();
        assert!(handle.wait_exit(Duration::from_secs(20)), "it exited");
        assert!(t0.elapsed() < Duration::from_secs(15), "at the exit, not at the timeout: {:?}", t0.elapsed());
        assert!(no_pidfd.wait_exit(Duration::from_secs(20)), "a zombie by /proc");
        assert!(short.try_wait().is_ok_and(|s| s.is_some()), "left for the caller to reap");

        let mut sleeper = Sleeper::start();
        let handle = ProcessHandle::take(sleeper.pid()).expect("sleep runs");
        let no_pidfd = ProcessHandle::from_parts(sleeper.pid(), handle.start_time());
        for h in [&handle, &no_pidfd] {
            let t0 = Instant::now();
            assert!(!h.wait_exit(Duration::from_millis(150)), "still running");
            assert!(t0.elapsed() >= Duration::from_millis(150));
        }
        assert!(sleeper.running());
    }

    #[test]
    fn a_handle_of_a_process_that_exited_and_was_reaped_is_dead_and_signals_nothing() {
        let mut sleeper = Sleeper::start();
        let pid = sleeper.pid();
        let handle = ProcessHandle::take(pid).expect("sleep runs");
        sleeper.0.kill().expect("kill sleep");
        let _ = sleeper.0.wait();
        assert!(!handle.is_alive());
        assert!(matches!(handle.signal(Signal::SIGTERM), Err(ProcessError::Gone { .. })));
        assert!(ProcessHandle::take(pid).is_err(), "a reaped pid cannot be taken");
    }

    #[test]
    fn a_handle_signals_the_process_it_was_taken_of() {
        let mut sleeper = Sleeper::start();
        let handle = ProcessHandle::take(sleeper.pid()).expect("sleep runs");
        assert!(handle.is_alive());
        assert_eq!(handle.start_time(), start_time(sleeper.pid()).expect("stat"));
        handle.signal(Signal::SIGKILL).expect("signalled");
        let _ = sleeper.0.wait();
        assert!(!handle.is_alive(), "killed and reaped");
        assert!(!sleeper.running());
    }

    /// A process that exited but was not reaped yet (a zombie) is dead: the
    /// pidfd says so alone, without `/proc` (and so does `/proc` without one).
    #[test]
    fn a_zombie_is_dead() {
        let mut sleeper = Sleeper::start();
        let pid = sleeper.pid();
        let handle = ProcessHandle::take(pid).expect("sleep runs");
        let no_pidfd = ProcessHandle::from_parts(pid, handle.start_time());
        assert!(handle.is_alive() && no_pidfd.is_alive());
        // SIGKILL without a wait: the child stays a zombie until the Sleeper drops
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), Signal::SIGKILL).expect("kill");
        let t0 = std::time::Instant::now();
        while handle.is_alive() && t0.elapsed() < std::time::Duration::from_secs(5) {
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        assert!(!handle.is_alive(), "a zombie by its pidfd");
        assert!(!no_pidfd.is_alive(), "a zombie by /proc");
        assert!(sleeper.0.try_wait().is_ok_and(|s| s.is_some()), "it was a zombie, reaped only now");
    }

    /// A pid reused by another process: simulated by a handle whose start
    /// time is not the live process's. Neither a liveness check nor a signal
    /// may act on the process that has the pid now.
    #[test]
    fn a_reused_pid_is_neither_alive_nor_signalled() {
        let mut sleeper = Sleeper::start();
        let real = start_time(sleeper.pid()).expect("stat");
        let stale = ProcessHandle::from_parts(sleeper.pid(), real.wrapping_sub(1));
        assert!(!stale.is_alive(), "another start time: another process");
        assert!(matches!(stale.signal(Signal::SIGKILL), Err(ProcessError::Gone { .. })));
        assert!(stale.exe().is_none() && stale.args().is_none(), "nothing is read of another process");
        std::thread::sleep(std::time::Duration::from_millis(50));
        assert!(sleeper.running(), "the process that has the pid now was signalled");
        // the recorded start time does act
        let same = ProcessHandle::from_parts(sleeper.pid(), real);
        assert!(same.is_alive());
    }

    #[test]
    fn only_nerve_executables_count_as_nerve() {
        assert!(is_nerve_executable(Path::new("/usr/local/bin/nerve")));
        assert!(is_nerve_executable(Path::new("/opt/nerve/nerve-ticker")));
        assert!(is_nerve_executable(Path::new("/target/debug/nerve-ticker (deleted)")));
        assert!(!is_nerve_executable(Path::new("/usr/bin/tail")));
        assert!(!is_nerve_executable(Path::new("/home/nerve/bin/sleep")), "a folder named nerve does not count");
        // `exec -a nerve-x sleep 30`: calls itself nerve-x, but runs sleep
        let mut child = std::os::unix::process::CommandExt::arg0(&mut Command::new("sleep"), "nerve-x")
            .arg("30")
            .spawn()
            .expect("start sleep");
        let handle = ProcessHandle::take(child.id()).expect("runs");
        let t0 = std::time::Instant::now();
        while handle.args().and_then(|a| a.first().cloned()).as_deref() != Some("nerve-x") {
            assert!(t0.elapsed() < std::time::Duration::from_secs(10), "sleep did not start");
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert!(!handle.runs_nerve_executable(), "{:?}", handle.exe());
        let _ = child.kill();
        let _ = child.wait();
    }
}
