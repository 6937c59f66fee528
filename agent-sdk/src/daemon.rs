//! Daemon plumbing: detach from the terminal, send stdout and stderr to the
//! agent's log file, write a pid file, and tell the starting process when the
//! agent is ready (or why it failed), so `nerve start` can report it.
//!
//! Also the logging set-up shared by every nerve process, and sd_notify for
//! systemd (`READY=1`, `WATCHDOG=1`) when `NOTIFY_SOCKET` is set.

use nix::unistd::{ForkResult, fork, setsid};
use std::io::{Read, Write};
use std::os::fd::{AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};

/// The daemon's end of the start-up pipe: say once whether start-up worked.
#[derive(Debug, Default)]
pub struct Readiness {
    pipe: Option<std::fs::File>,
    pid_file: Option<PathBuf>,
}

impl Readiness {
    /// A readiness handle for a foreground process (does nothing).
    pub fn foreground() -> Self {
        Readiness::default()
    }

    /// Start-up worked; `msg` is printed by the starting process.
    pub fn ready(&mut self, msg: &str) {
        if let Some(mut p) = self.pipe.take() {
            let _ = write!(p, "R{msg}");
        }
    }

    /// Start-up failed; `msg` is printed by the starting process.
    pub fn fail(&mut self, msg: &str) {
        if let Some(mut p) = self.pipe.take() {
            let _ = write!(p, "E{msg}");
        }
    }

    /// The pid file written by [`daemonize`], removed at exit.
    pub fn pid_file(&self) -> Option<&Path> {
        self.pid_file.as_deref()
    }
}

impl Drop for Readiness {
    fn drop(&mut self) {
        // remove the pid file only while it still names this process: a
        // file that another process wrote since is not ours to delete
        if let Some(p) = &self.pid_file {
            if read_pid(p) == Some(std::process::id()) {
                let _ = std::fs::remove_file(p);
            }
        }
    }
}

/// The pid recorded in a pid file.
pub fn read_pid(path: &Path) -> Option<u32> {
    std::fs::read_to_string(path).ok()?.trim().parse().ok()
}

/// Whether `pid` is a live (not zombie) nerve process: its command name
/// starts with `nerve`, so a pid reused by an unrelated program since does
/// not count.
pub fn nerve_process_alive(pid: u32) -> bool {
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else { return false };
    let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else { return false };
    let comm = &stat[open + 1..close];
    let state = stat[close + 1..].split_whitespace().next().unwrap_or("Z");
    comm.starts_with("nerve") && state != "Z"
}

/// Creates `path` for this process, exclusively, without following a
/// symlink, readable by its owner only. A pid file left by a dead process is
/// replaced; one of a live nerve process is an error naming it.
pub fn create_pid_file(path: &Path) -> Result<(), String> {
    use std::os::unix::fs::OpenOptionsExt;
    for _ in 0..2 {
        let open = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW)
            .open(path);
        match open {
            Ok(mut f) => {
                return f
                    .write_all(format!("{}\n", std::process::id()).as_bytes())
                    .map_err(|e| format!("cannot write pid file {}: {e}", path.display()));
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => match read_pid(path) {
                Some(pid) if nerve_process_alive(pid) => {
                    return Err(format!(
                        "already running as pid {pid} (pid file {}); stop it first, or choose another --name",
                        path.display()
                    ));
                }
                _ => {
                    // a dead process's file (or not a pid file at all): replace it
                    std::fs::remove_file(path)
                        .map_err(|e| format!("cannot replace stale pid file {}: {e}", path.display()))?;
                }
            },
            Err(e) => return Err(format!("cannot create pid file {}: {e}", path.display())),
        }
    }
    Err(format!("pid file {} keeps reappearing; another process is starting under this name", path.display()))
}

/// Detaches the process: double fork, new session, stdin from /dev/null,
/// stdout and stderr appended to `log`. Returns in the daemon only; the
/// original process waits for [`Readiness::ready`] or [`Readiness::fail`]
/// and exits with 0 or 1. Must be called before any thread is started.
pub fn daemonize(log: &Path, pid_file: &Path) -> std::io::Result<Readiness> {
    let (rd, wr): (OwnedFd, OwnedFd) = nix::unistd::pipe()?;
    // SAFETY: no other thread runs yet (documented precondition).
    match unsafe { fork() }? {
        ForkResult::Parent { .. } => {
            drop(wr);
            let mut s = String::new();
            let _ = std::fs::File::from(rd).read_to_string(&mut s);
            if let Some(msg) = s.strip_prefix('R') {
                if !msg.is_empty() {
                    println!("{msg}");
                }
                std::process::exit(0);
            }
            let msg = s.strip_prefix('E').unwrap_or("");
            if msg.is_empty() {
                eprintln!("error: the agent exited during start-up; see its log {}", log.display());
            } else {
                eprintln!("error: {msg}");
            }
            std::process::exit(1);
        }
        ForkResult::Child => {}
    }
    drop(rd);
    setsid()?;
    // SAFETY: still single-threaded.
    match unsafe { fork() }? {
        ForkResult::Parent { .. } => std::process::exit(0),
        ForkResult::Child => {}
    }
    let mut pipe = std::fs::File::from(wr);
    if let Err(msg) = create_pid_file(pid_file) {
        let _ = write!(pipe, "E{msg}");
        std::process::exit(1);
    }
    let devnull = std::fs::File::open("/dev/null")?;
    let logf = {
        use std::os::unix::fs::OpenOptionsExt;
        std::fs::OpenOptions::new().create(true).append(true).mode(0o600).custom_flags(libc::O_NOFOLLOW).open(log)?
    };
    nix::unistd::dup2_stdin(&devnull)?;
    nix::unistd::dup2_stdout(&logf)?;
    nix::unistd::dup2_stderr(&logf)?;
    let _ = logf.as_raw_fd();
    Ok(Readiness { pipe: Some(pipe), pid_file: Some(pid_file.to_path_buf()) })
}

/// Sets up `tracing` for a nerve process: `--log-level` when given, else
/// `RUST_LOG`, else `info`; every line carries `who` (the agent's name).
pub fn init_logging(who: &str, level: Option<&str>) {
    use tracing_subscriber::EnvFilter;
    let filter = match level {
        Some(l) => EnvFilter::try_new(l).unwrap_or_else(|_| EnvFilter::new("info")),
        None => EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
    };
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(nix::unistd::isatty(std::io::stderr()).unwrap_or(false))
        .with_target(false)
        .with_thread_names(false)
        .fmt_fields(tracing_subscriber::fmt::format::DefaultFields::new())
        .event_format(NamedFormat { who: who.to_owned() })
        .try_init();
}

struct NamedFormat {
    who: String,
}

impl<S, N> tracing_subscriber::fmt::FormatEvent<S, N> for NamedFormat
where
    S: tracing::Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
    N: for<'a> tracing_subscriber::fmt::FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        ctx: &tracing_subscriber::fmt::FmtContext<'_, S, N>,
        mut writer: tracing_subscriber::fmt::format::Writer<'_>,
        event: &tracing::Event<'_>,
    ) -> std::fmt::Result {
        let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        let secs = now.as_secs();
        let (h, m, s) = ((secs / 3600) % 24, (secs / 60) % 60, secs % 60);
        write!(
            writer,
            "{h:02}:{m:02}:{s:02}.{:03} {:>5} [{}] ",
            now.subsec_millis(),
            event.metadata().level(),
            self.who
        )?;
        ctx.field_format().format_fields(writer.by_ref(), event)?;
        writeln!(writer)
    }
}

/// Sends `state` (e.g. `READY=1`, `WATCHDOG=1`) to systemd's `NOTIFY_SOCKET`;
/// does nothing when the variable is not set.
pub fn sd_notify(state: &str) -> std::io::Result<()> {
    let Some(path) = std::env::var_os("NOTIFY_SOCKET") else { return Ok(()) };
    let sock = std::os::unix::net::UnixDatagram::unbound()?;
    let path = path.to_string_lossy().into_owned();
    if let Some(abstract_name) = path.strip_prefix('@') {
        use std::os::linux::net::SocketAddrExt;
        let addr = std::os::unix::net::SocketAddr::from_abstract_name(abstract_name.as_bytes())?;
        sock.send_to_addr(state.as_bytes(), &addr)?;
    } else {
        sock.send_to(state.as_bytes(), &path)?;
    }
    Ok(())
}

/// The watchdog interval systemd asked for (`WATCHDOG_USEC`), if any and meant for us.
pub fn watchdog_interval() -> Option<std::time::Duration> {
    let usec: u64 = std::env::var("WATCHDOG_USEC").ok()?.parse().ok()?;
    if let Ok(pid) = std::env::var("WATCHDOG_PID") {
        if pid.parse::<u32>().ok()? != std::process::id() {
            return None;
        }
    }
    (usec > 0).then(|| std::time::Duration::from_micros(usec))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pid_file_is_exclusive_and_removed_only_by_its_owner() {
        let dir = std::env::temp_dir().join(format!("nerve-pid-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        let p = dir.join("t1.pid");
        // a stale file of a dead process is replaced
        std::fs::write(&p, "999999999\n").expect("stale");
        create_pid_file(&p).expect("replaces a stale pid file");
        assert_eq!(read_pid(&p), Some(std::process::id()));
        // the file now names another process: dropping our handle leaves it (review R15)
        let ours = Readiness { pipe: None, pid_file: Some(p.clone()) };
        std::fs::write(&p, "1\n").expect("another process's file");
        drop(ours);
        assert_eq!(read_pid(&p), Some(1), "a pid file naming another process was deleted");
        // while it names us, it is ours to remove
        std::fs::write(&p, format!("{}\n", std::process::id())).expect("ours");
        drop(Readiness { pipe: None, pid_file: Some(p.clone()) });
        assert!(!p.exists());
        // a symlink is never followed
        let target = dir.join("target");
        std::fs::write(&target, "keep").expect("target");
        let link = dir.join("l.pid");
        std::os::unix::fs::symlink(&target, &link).expect("symlink");
        create_pid_file(&link).expect("the link is replaced by a file");
        assert_eq!(std::fs::read_to_string(&target).ok().as_deref(), Some("keep"), "wrote through a symlink");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
