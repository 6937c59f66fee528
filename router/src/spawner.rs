//! The router's hands on processes: it starts every agent of its robot,
//! those `nerve launch` and `nerve start` ask for ([`CliRequest::Start`],
//! reported back) and those supervision restarts (logged), and reaps every
//! start-up process it made.
//!
//! An agent starts as a daemon (`--daemon`): its start-up process forks the
//! agent into a session of its own and exits once the agent has registered
//! and its `start` worked, printing `NAME started (pid N, robot R)`, or
//! with an error and the agent's message. The agent itself is then nobody's
//! child (its start-up process made itself the subreaper of the middle
//! process only, see `agent_sdk::daemon`): it outlives the router, as an
//! agent started by `nerve launch` always did, and the next router finds it
//! when it re-registers. `nerve down` stops it through the router and the
//! pid files, as before.
//!
//! * **Asked starts** ([`Spawner::start`]): stdout and stderr are piped; a
//!   thread per start waits for the start-up process (reading both pipes
//!   together, so an agent that writes more than a pipe holds before it is
//!   ready does not block), sends its [`StartEnd`] and wakes the serving
//!   loop through [`Wake`]. The loop never waits for a start.
//! * **Restarts** ([`Spawner::spawn`]): the start-up process writes its
//!   errors into the agent's log; it is reaped by the liveness tick
//!   ([`Spawner::reap`]), and a failure counts as a death for supervision.
//!
//! [`CliRequest::Start`]: shm_schemas::control::cli_to_router::CliRequest::Start

use crate::calls::Ticket;
use iceoryx2::prelude::{FileDescriptor, FileDescriptorBased, SynchronousMultiplexing};
use shm_schemas::control::cli_to_router::StartResult;
use std::os::fd::{AsRawFd, OwnedFd};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, channel};

/// Why the router cannot wake itself for ended starts.
#[derive(Debug, thiserror::Error)]
#[error("cannot make the pipe that tells the router a start has ended: {source}")]
pub struct WakeError {
    #[source]
    source: nix::Error,
}

/// The read end of the pipe a start's thread writes a byte to when its
/// start-up process has ended: attach it to the serving loop's WaitSet and
/// [`Wake::drain`] it after every wake-up.
#[derive(Debug)]
pub struct Wake {
    read: OwnedFd,
    /// `read` as the WaitSet takes it (not owned: `read` closes it)
    fd: FileDescriptor,
}

impl FileDescriptorBased for Wake {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.fd
    }
}

impl SynchronousMultiplexing for Wake {}

impl Wake {
    /// Empties the pipe (it never blocks), so that the next wait sleeps.
    pub fn drain(&self) {
        let mut buf = [0u8; 64];
        // a read of a non-blocking pipe: at most a few bytes wait in it
        while nix::unistd::read(&self.read, &mut buf).is_ok_and(|n| n > 0) {}
    }
}

/// The write end of [`Wake`]'s pipe, shared by the threads of starts.
#[derive(Debug, Clone)]
struct Waker(Arc<OwnedFd>);

impl Waker {
    fn wake(&self) {
        // a full pipe wakes its reader already
        let _ = nix::unistd::write(&*self.0, &[1u8]);
    }
}

/// The pipe between the threads of starts and the serving loop.
pub fn wake_pipe() -> Result<(Wake, WakeHandle), WakeError> {
    use nix::fcntl::OFlag;
    let (read, write) =
        nix::unistd::pipe2(OFlag::O_NONBLOCK | OFlag::O_CLOEXEC).map_err(|source| WakeError { source })?;
    let fd = FileDescriptor::non_owning_new(read.as_raw_fd()).ok_or(WakeError { source: nix::Error::EBADF })?;
    Ok((Wake { read, fd }, WakeHandle(Waker(Arc::new(write)))))
}

/// What [`Spawner::with_wake`] takes: the write end of the pipe.
#[derive(Debug)]
pub struct WakeHandle(Waker);

/// An asked start that is over: its ticket, agent and outcome.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StartEnd {
    /// the start's ticket ([`crate::serving::Effect::Spawn`])
    pub ticket: Ticket,
    /// agent
    pub name: String,
    /// how it went
    pub result: StartResult,
}

/// Starts agents and reaps their start-up processes.
#[derive(Debug)]
pub struct Spawner {
    /// start-up processes of restarted agents (with the agent's name),
    /// reaped as they exit
    children: Vec<(String, Child)>,
    /// asked starts whose thread has not reported yet
    in_flight: usize,
    ended_tx: Sender<StartEnd>,
    ended_rx: Receiver<StartEnd>,
    waker: Option<Waker>,
}

impl Default for Spawner {
    fn default() -> Self {
        let (ended_tx, ended_rx) = channel();
        Spawner { children: Vec::new(), in_flight: 0, ended_tx, ended_rx, waker: None }
    }
}

/// The command that runs `argv` in `cwd` (where the agent was launched, so
/// that relative paths in its arguments hold: a router started elsewhere
/// restarted the decision maker without its knowledge base, found by the
/// chaos test) with `env` (else the router's), under the normal scheduling
/// policy.
fn command(argv: &[String], cwd: Option<&str>, env: Option<&[(String, String)]>) -> Option<Command> {
    let (program, args) = argv.split_first()?;
    let mut cmd = Command::new(program);
    cmd.args(args).stdin(Stdio::null());
    if let Some(cwd) = cwd {
        cmd.current_dir(cwd);
    }
    if let Some(env) = env {
        cmd.env_clear().envs(env.iter().map(|(k, v)| (k, v)));
    }
    // whatever policy the router runs under (SCHED_RESET_ON_FORK covers
    // a real-time one; SCHED_BATCH or IDLE would pass on), the agent
    // starts under the normal one and asks for its own (R13)
    // SAFETY: the closure runs in the child between fork and exec and
    // only makes one system call, which is async-signal-safe.
    unsafe {
        std::os::unix::process::CommandExt::pre_exec(&mut cmd, || {
            let normal = libc::sched_param { sched_priority: 0 };
            libc::sched_setscheduler(0, libc::SCHED_OTHER, &normal);
            Ok(())
        });
    }
    Some(cmd)
}

/// How a process ended, as a person reads it: `exit status 1`, `killed by SIGSEGV`.
pub fn describe_exit(status: std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exit status {code}"),
        (None, Some(sig)) => {
            let name = nix::sys::signal::Signal::try_from(sig).map(|s| s.as_str().to_owned());
            let core = if status.core_dumped() { ", core dumped" } else { "" };
            format!("killed by {}{core}", name.unwrap_or_else(|_| format!("signal {sig}")))
        }
        (None, None) => status.to_string(),
    }
}

/// The outcome of a start-up process that ended with `output`.
fn outcome(output: &std::process::Output) -> StartResult {
    let said = |b: &[u8]| String::from_utf8_lossy(b).trim().to_owned();
    if output.status.success() {
        StartResult::Started { said: said(&output.stdout) }
    } else {
        StartResult::Failed { status: describe_exit(output.status), said: said(&output.stderr) }
    }
}

impl Spawner {
    /// A spawner whose ended starts wake the serving loop through `wake`.
    pub fn with_wake(wake: WakeHandle) -> Self {
        Spawner { waker: Some(wake.0), ..Spawner::default() }
    }

    /// Starts `argv` for the agent `name` as asked by a request: its
    /// [`StartEnd`] comes from [`Spawner::ended`] once the start-up process
    /// has exited, or is returned at once when it could not be run.
    pub fn start(
        &mut self,
        ticket: Ticket,
        name: &str,
        argv: &[String],
        cwd: Option<&str>,
        env: Option<&[(String, String)]>,
    ) -> Option<StartEnd> {
        let failed = |status: &str, said: String| {
            tracing::warn!(agent = name, "cannot start {name}: {said}");
            Some(StartEnd {
                ticket,
                name: name.to_owned(),
                result: StartResult::Failed { status: status.to_owned(), said },
            })
        };
        let Some(mut cmd) = command(argv, cwd, env) else {
            return failed("not run", "no command line to start it with".to_owned());
        };
        cmd.stdout(Stdio::piped()).stderr(Stdio::piped());
        // the thread first: a start-up process made is always waited for
        let (child_tx, child_rx) = channel::<Child>();
        let (ended, waker) = (self.ended_tx.clone(), self.waker.clone());
        let agent = name.to_owned();
        let watcher = std::thread::Builder::new().name(format!("start-{name}")).spawn(move || {
            let Ok(child) = child_rx.recv() else { return };
            let result = match child.wait_with_output() {
                Ok(output) => outcome(&output),
                Err(e) => StartResult::Failed {
                    status: "unknown".into(),
                    said: format!("the router lost its start-up process: {e}"),
                },
            };
            let _ = ended.send(StartEnd { ticket, name: agent, result });
            if let Some(w) = waker {
                w.wake();
            }
        });
        if let Err(e) = watcher {
            return failed("not run", format!("the router cannot make a thread to watch its start: {e}"));
        }
        let program = argv.first().map(String::as_str).unwrap_or_default();
        match cmd.spawn() {
            Ok(child) => {
                tracing::info!(agent = name, pid = child.id(), "starting {name} (start-up process {})", child.id());
                self.in_flight += 1;
                // the thread waits for it: it cannot have gone
                let _ = child_tx.send(child);
                None
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                failed("not run", format!("cannot run {program}: no such program (is it built and on the PATH?)"))
            }
            Err(e) => failed("not run", format!("cannot run {program}: {e}")),
        }
    }

    /// The asked starts that have ended since the last call.
    pub fn ended(&mut self) -> Vec<StartEnd> {
        let ended: Vec<StartEnd> = self.ended_rx.try_iter().collect();
        self.in_flight = self.in_flight.saturating_sub(ended.len());
        ended
    }

    /// Whether asked starts are still under way.
    pub fn starting(&self) -> bool {
        self.in_flight > 0
    }

    /// Whether a thread's end can go unnoticed (no wake pipe): the serving
    /// loop must look by itself.
    pub fn needs_polling(&self) -> bool {
        self.waker.is_none() && self.in_flight > 0
    }

    /// Starts `argv` again for the agent `name` (a restart) in `cwd` with
    /// `env` (else the router's), its start-up errors into `log`.
    pub fn spawn(
        &mut self,
        name: &str,
        argv: &[String],
        cwd: Option<&str>,
        env: Option<&[(String, String)]>,
        log: &Path,
        restart: u32,
    ) {
        let program = argv.first().map(String::as_str).unwrap_or_default();
        let Some(mut cmd) = command(argv, cwd, env) else { return };
        cmd.stdout(Stdio::null());
        // rotated by size, 0600, never through a symlink (see agent_sdk::daemon)
        match agent_sdk::daemon::open_log(log) {
            Ok(f) => {
                cmd.stderr(f);
            }
            Err(e) => tracing::warn!(agent = name, "{e}; its start-up errors go to the router's log"),
        }
        match cmd.spawn() {
            Ok(child) => {
                tracing::info!(agent = name, restart, "restarted {name} (restart {restart})");
                self.children.push((name.to_owned(), child));
            }
            Err(e) => tracing::error!(agent = name, program = %program, "cannot restart {name}: {e}"),
        }
    }

    /// Reaps the start-up processes of restarts that have exited; returns
    /// the names of the agents whose start failed (the start-up process
    /// exits with an error when the agent could not start): no agent
    /// registered, so no death would be noticed, and the restart must
    /// count as failed.
    pub fn reap(&mut self) -> Vec<String> {
        let mut failed = Vec::new();
        self.children.retain_mut(|(name, c)| match c.try_wait() {
            Ok(Some(status)) => {
                if !status.success() {
                    failed.push(name.clone());
                }
                false
            }
            Ok(None) => true,
            Err(_) => false,
        });
        failed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;
    use std::time::{Duration, Instant};

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("nerve-spawn-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn argv(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| (*s).to_owned()).collect()
    }

    /// Waits (bounded) until `n` asked starts have ended, woken by the pipe.
    fn ends(s: &mut Spawner, wake: &Wake, n: usize) -> Vec<StartEnd> {
        let t0 = Instant::now();
        let mut out = Vec::new();
        while out.len() < n {
            assert!(t0.elapsed() < Duration::from_secs(20), "starts did not end: {out:?}");
            std::thread::sleep(Duration::from_millis(5));
            wake.drain();
            out.extend(s.ended());
        }
        out.sort_by_key(|e| e.ticket);
        out
    }

    #[test]
    fn asked_starts_report_what_the_start_up_process_said_and_how_it_ended() {
        let (wake, handle) = wake_pipe().expect("pipe");
        let mut s = Spawner::with_wake(handle);
        let ok = argv(&["sh", "-c", "echo 'a1 started (pid 7, robot r)'"]);
        let bad = argv(&["sh", "-c", "echo 'error: no device' >&2; exit 3"]);
        let crash = argv(&["sh", "-c", "kill -SEGV $$"]);
        assert_eq!(s.start(1, "a1", &ok, None, None), None);
        assert_eq!(s.start(2, "a2", &bad, None, None), None);
        assert_eq!(s.start(3, "a3", &crash, None, None), None);
        assert!(s.starting());
        let ended = ends(&mut s, &wake, 3);
        assert_eq!(ended[0].result, StartResult::Started { said: "a1 started (pid 7, robot r)".into() });
        assert_eq!(
            ended[1].result,
            StartResult::Failed { status: "exit status 3".into(), said: "error: no device".into() }
        );
        assert!(
            matches!(&ended[2].result, StartResult::Failed { status, .. } if status.starts_with("killed by SIGSEGV")),
            "{:?}",
            ended[2]
        );
        assert!(!s.starting());
    }

    #[test]
    fn a_program_that_does_not_exist_fails_at_once_and_plainly() {
        let (_wake, handle) = wake_pipe().expect("pipe");
        let mut s = Spawner::with_wake(handle);
        let end = s.start(9, "ghost", &argv(&["/nonexistent/nerve-ghost"]), None, None).expect("at once");
        match end.result {
            StartResult::Failed { status, said } => {
                assert_eq!(status, "not run");
                assert!(said.contains("/nonexistent/nerve-ghost") && said.contains("no such program"), "{said}");
            }
            other => panic!("{other:?}"),
        }
        assert!(!s.starting());
    }

    #[test]
    fn an_asked_start_gets_the_callers_environment_and_folder() {
        let d = dir("env");
        std::fs::create_dir_all(&d).expect("dir");
        let (wake, handle) = wake_pipe().expect("pipe");
        let mut s = Spawner::with_wake(handle);
        let env = vec![("PATH".to_owned(), std::env::var("PATH").unwrap_or_default()), ("NERVE_X".into(), "42".into())];
        let cmd = argv(&["sh", "-c", "echo \"$NERVE_X $(pwd) ${HOME:-nohome}\""]);
        assert_eq!(s.start(1, "e", &cmd, Some(&d.display().to_string()), Some(&env)), None);
        let ended = ends(&mut s, &wake, 1);
        assert_eq!(
            ended[0].result,
            StartResult::Started { said: format!("42 {} nohome", d.display()) },
            "only the caller's variables, in the caller's folder"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_restart_whose_start_up_fails_is_reported_so_that_it_counts() {
        let d = dir("startfail");
        std::fs::create_dir_all(&d).expect("dir");
        let mut s = Spawner::default();
        s.spawn("bad", &["false".to_owned()], None, None, &d.join("bad.log"), 1);
        s.spawn("good", &["true".to_owned()], None, None, &d.join("good.log"), 1);
        let mut failed = Vec::new();
        for _ in 0..200 {
            failed.extend(s.reap());
            if s.children.is_empty() {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        assert_eq!(failed, vec!["bad".to_owned()]);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_restart_starts_where_the_agent_was_launched() {
        let d = dir("cwd");
        let launched = d.join("robot-folder");
        std::fs::create_dir_all(&launched).expect("dir");
        let mut s = Spawner::default();
        // a relative path in its arguments, as `--kb kb/explore.toml`
        let argv = argv(&["sh", "-c", "echo here > relative.txt"]);
        s.spawn("kb-user", &argv, Some(&launched.display().to_string()), None, &d.join("kb-user.log"), 1);
        for _ in 0..200 {
            s.reap();
            if s.children.is_empty() {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        assert!(launched.join("relative.txt").is_file(), "not started in the launch folder");
        let _ = std::fs::remove_dir_all(&d);
    }
}
