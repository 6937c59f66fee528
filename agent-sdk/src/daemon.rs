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
        if let Some(p) = &self.pid_file {
            let _ = std::fs::remove_file(p);
        }
    }
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
    let devnull = std::fs::File::open("/dev/null")?;
    let logf = std::fs::OpenOptions::new().create(true).append(true).open(log)?;
    nix::unistd::dup2_stdin(&devnull)?;
    nix::unistd::dup2_stdout(&logf)?;
    nix::unistd::dup2_stderr(&logf)?;
    let _ = logf.as_raw_fd();
    std::fs::write(pid_file, format!("{}\n", std::process::id()))?;
    Ok(Readiness { pipe: Some(std::fs::File::from(wr)), pid_file: Some(pid_file.to_path_buf()) })
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
