//! Daemon plumbing: detach from the terminal, send stdout and stderr to the
//! agent's log file, write a pid file, and tell the starting process when the
//! agent is ready (or why it failed), so `nerve start` can report it.
//!
//! Also the logging set-up shared by every nerve process, and sd_notify for
//! systemd (`READY=1`, `WATCHDOG=1`) when `NOTIFY_SOCKET` is set.
//!
//! Logs are rotated by size: a log larger than [`LOG_ROTATE_BYTES`] (8 MiB)
//! when it is opened ([`open_log`]: daemon start-up, the router's restart of
//! an agent), or found so while a daemon writes to it (checked every
//! [`LOG_CHECK_EVERY`] bytes of `tracing` output), is renamed `NAME.log.1`;
//! older generations shift to `.2` and `.3`, and the fourth is dropped
//! ([`LOG_GENERATIONS`]). A robot's logs so take at most about 32 MiB per
//! process name.

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
        if let Some(p) = &self.pid_file
            && read_pid(p) == Some(std::process::id())
        {
            let _ = std::fs::remove_file(p);
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
    // the daemon (our grandchild) is re-parented to us, not to init, while
    // we wait: if it dies before it is ready we can say how (a signal's
    // name is most of the diagnosis of a crash that logged nothing)
    // SAFETY: PR_SET_CHILD_SUBREAPER takes a plain integer argument.
    let _ = unsafe { libc::prctl(libc::PR_SET_CHILD_SUBREAPER, 1 as libc::c_ulong, 0, 0, 0) };
    // SAFETY: no other thread runs yet (documented precondition).
    match unsafe { fork() }? {
        ForkResult::Parent { child } => {
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
                let how = daemon_end(child).map(|h| format!(" ({h})")).unwrap_or_default();
                eprintln!("error: the agent exited during start-up{how}; see its log {}", log.display());
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
    let logf = open_log(log)?;
    if let Ok(mut current) = DAEMON_LOG.lock() {
        *current = Some(log.to_path_buf());
    }
    nix::unistd::dup2_stdin(&devnull)?;
    nix::unistd::dup2_stdout(&logf)?;
    nix::unistd::dup2_stderr(&logf)?;
    let _ = logf.as_raw_fd();
    Ok(Readiness { pipe: Some(pipe), pid_file: Some(pid_file.to_path_buf()) })
}

/// How the daemon that closed the start-up pipe without a word ended, as
/// its subreaper sees it: "killed by SIGSEGV", "exit status 3". Reaps the
/// intermediate child `first` too. Waits at most a second for the daemon's
/// status (its pipe closes a moment before it becomes a zombie); `None`
/// when it is still running or the status could not be had.
fn daemon_end(first: nix::unistd::Pid) -> Option<String> {
    use nix::sys::wait::{WaitPidFlag, WaitStatus, waitpid};
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(1);
    while std::time::Instant::now() < deadline {
        match waitpid(None, Some(WaitPidFlag::WNOHANG)) {
            Ok(WaitStatus::Exited(pid, _)) if pid == first => continue,
            Ok(WaitStatus::Exited(_, code)) => return Some(format!("exit status {code}")),
            Ok(WaitStatus::Signaled(pid, _, _)) if pid == first => continue,
            Ok(WaitStatus::Signaled(_, sig, core)) => {
                let core = if core { ", core dumped" } else { "" };
                return Some(format!("killed by {}{core}", sig.as_str()));
            }
            Ok(WaitStatus::StillAlive) => std::thread::sleep(std::time::Duration::from_millis(5)),
            Ok(_) => continue,
            Err(_) => return None,
        }
    }
    None
}

/// Size above which a log is rotated (see the module documentation).
pub const LOG_ROTATE_BYTES: u64 = 8 << 20;

/// Rotated generations kept: `NAME.log.1` (the newest) to `NAME.log.3`.
pub const LOG_GENERATIONS: u32 = 3;

/// A daemon checks the size of its log after this many bytes of `tracing`
/// output (one `fstat`, not one per line).
pub const LOG_CHECK_EVERY: u64 = 64 << 10;

/// The log a daemon's stdout and stderr go to (set by [`daemonize`]); `None`
/// in a foreground process, whose stderr is not ours to rotate.
static DAEMON_LOG: std::sync::Mutex<Option<PathBuf>> = std::sync::Mutex::new(None);

/// `tracing` output since the last size check of the daemon's log.
static LOG_WRITTEN: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Opens the log `path` for appending, readable by its owner only and never
/// through a symlink, first rotating it if it is larger than
/// [`LOG_ROTATE_BYTES`].
pub fn open_log(path: &Path) -> std::io::Result<std::fs::File> {
    open_log_with(path, LOG_ROTATE_BYTES, LOG_GENERATIONS)
}

fn open_log_with(path: &Path, max_bytes: u64, keep: u32) -> std::io::Result<std::fs::File> {
    match std::fs::symlink_metadata(path) {
        // a link or other non-file is left for the open to refuse
        Ok(m) if m.file_type().is_file() && m.len() > max_bytes => rotate_log(path, keep)?,
        _ => {}
    }
    open_append(path)
}

fn open_append(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot open log {}: {e}", path.display())))
}

/// `path` with `.i` appended (`agent.log` → `agent.log.1`).
pub fn rotated_log(path: &Path, i: u32) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(format!(".{i}"));
    PathBuf::from(s)
}

/// Shifts `path.1`..`path.{keep-1}` up by one (dropping `path.{keep}`) and
/// renames `path` to `path.1`. A generation missing, or already moved by
/// another process rotating the same log, is skipped.
fn rotate_log(path: &Path, keep: u32) -> std::io::Result<()> {
    let ignore_missing = |r: std::io::Result<()>| match r {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            Err(std::io::Error::new(e.kind(), format!("cannot rotate log {}: {e}", path.display())))
        }
        _ => Ok(()),
    };
    if keep == 0 {
        return ignore_missing(std::fs::remove_file(path));
    }
    for i in (1..keep).rev() {
        ignore_missing(std::fs::rename(rotated_log(path, i), rotated_log(path, i + 1)))?;
    }
    ignore_missing(std::fs::rename(path, rotated_log(path, 1)))
}

/// Whether the log open as `fd` has to be replaced by a fresh `path`: if it
/// grew past `max_bytes` it is rotated; if `path` is no longer the file open
/// (rotated by another process) the current `path` is opened. Returns the
/// file to write to from now on, `None` to keep `fd`.
fn rotate_open_log(
    fd: std::os::fd::BorrowedFd<'_>,
    path: &Path,
    max_bytes: u64,
    keep: u32,
) -> std::io::Result<Option<std::fs::File>> {
    use std::os::unix::fs::MetadataExt;
    let open = nix::sys::stat::fstat(fd).map_err(std::io::Error::from)?;
    let same =
        std::fs::symlink_metadata(path).is_ok_and(|m| m.dev() == open.st_dev as u64 && m.ino() == open.st_ino as u64);
    if same && (open.st_size as u64) <= max_bytes {
        return Ok(None);
    }
    if same {
        rotate_log(path, keep)?;
    }
    open_append(path).map(Some)
}

/// After a daemon wrote [`LOG_CHECK_EVERY`] bytes of log, rotates its log if
/// it grew too large, pointing stdout and stderr at the fresh file.
fn check_daemon_log(written: u64) {
    use std::sync::atomic::Ordering;
    if LOG_WRITTEN.fetch_add(written, Ordering::Relaxed) + written < LOG_CHECK_EVERY {
        return;
    }
    // one thread checks; the others keep writing to the current file
    let Ok(current) = DAEMON_LOG.try_lock() else { return };
    LOG_WRITTEN.store(0, Ordering::Relaxed);
    let Some(path) = current.as_deref() else { return };
    // SAFETY: fd 2 is open for the life of the process.
    let stderr = unsafe { std::os::fd::BorrowedFd::borrow_raw(2) };
    match rotate_open_log(stderr, path, LOG_ROTATE_BYTES, LOG_GENERATIONS) {
        Ok(Some(fresh)) => {
            let _ = nix::unistd::dup2_stdout(&fresh);
            let _ = nix::unistd::dup2_stderr(&fresh);
        }
        Ok(None) => {}
        // keep writing to the file open now; say why once per check
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "warning: {e}; the log keeps growing until it can be rotated");
        }
    }
}

/// `tracing`'s writer: stderr, with the daemon's log rotation checked once
/// the event is written (so an event never straddles two files).
struct LogWriter {
    written: u64,
}

impl Write for LogWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = std::io::stderr().write(buf)?;
        self.written += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

impl Drop for LogWriter {
    fn drop(&mut self) {
        if self.written > 0 {
            check_daemon_log(self.written);
        }
    }
}

/// Checks a `--log-level` value (`error`, `warn`, `info`, `debug`, `trace`
/// or a `tracing` filter such as `info,nerve_router=debug`) for clap's
/// `value_parser`: a typo is refused with what is accepted instead of
/// falling back to `info` without a word.
pub fn parse_log_level(s: &str) -> Result<String, String> {
    const LEVELS: [&str; 6] = ["error", "warn", "info", "debug", "trace", "off"];
    const WHAT: &str = "give error, warn, info, debug, trace, off or a tracing filter such as info,nerve_router=debug";
    // A lone word is a target name to `tracing` ("debgu" would enable a
    // target of that name and hide everything else): only a level is taken.
    let lone_word = !s.contains([',', '=', '[', ':']);
    if lone_word && !LEVELS.contains(&s.to_ascii_lowercase().as_str()) {
        return Err(format!("unknown log level {s:?}; {WHAT}"));
    }
    tracing_subscriber::EnvFilter::try_new(s).map(|_| s.to_owned()).map_err(|e| format!("{e}; {WHAT}"))
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
        .with_writer(|| LogWriter { written: 0 })
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
        // the spans the event happened in, outermost first, with their
        // fields: `connect{input=in peer=t2/tick}: ...`
        if let Some(scope) = ctx.event_scope() {
            for span in scope.from_root() {
                write!(writer, "{}", span.name())?;
                let ext = span.extensions();
                if let Some(fields) = ext.get::<tracing_subscriber::fmt::FormattedFields<N>>()
                    && !fields.is_empty()
                {
                    write!(writer, "{{{fields}}}")?;
                }
                write!(writer, ": ")?;
            }
        }
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
    if let Ok(pid) = std::env::var("WATCHDOG_PID")
        && pid.parse::<u32>().ok()? != std::process::id()
    {
        return None;
    }
    (usec > 0).then(|| std::time::Duration::from_micros(usec))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_log_level_is_refused_with_what_is_accepted() {
        assert_eq!(parse_log_level("debug").as_deref(), Ok("debug"));
        assert!(parse_log_level("info,nerve_router=trace").is_ok());
        let e = parse_log_level("debgu").expect_err("a typo of a level");
        assert!(e.contains("unknown log level \"debgu\"") && e.contains("give error, warn, info"), "{e}");
    }

    #[test]
    fn logs_are_rotated_by_size_keeping_three_generations() {
        let dir = std::env::temp_dir().join(format!("nerve-log-rotate-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let log = dir.join("agent.log");
        // five runs, each writing more than the limit: the log is rotated
        // at each open and only the three newest generations stay
        for run in 0..5u8 {
            let mut f = open_log_with(&log, 100, 3).unwrap();
            f.write_all(&[b'a' + run; 150]).unwrap();
        }
        let generation = |i| std::fs::read(rotated_log(&log, i)).unwrap();
        assert_eq!(std::fs::read(&log).unwrap(), [b'e'; 150]);
        assert_eq!(generation(1), [b'd'; 150]);
        assert_eq!(generation(2), [b'c'; 150]);
        assert_eq!(generation(3), [b'b'; 150]);
        assert!(!rotated_log(&log, 4).exists());
        use std::os::unix::fs::PermissionsExt;
        assert_eq!(std::fs::metadata(&log).unwrap().permissions().mode() & 0o777, 0o600);
        // a small log is appended to, not rotated
        let mut f = open_log_with(&log, 1000, 3).unwrap();
        f.write_all(b"more").unwrap();
        assert_eq!(std::fs::read(&log).unwrap().len(), 154);
        assert_eq!(generation(1), [b'd'; 150]);

        // while appending: the open log grew past the limit, so it is
        // rotated and a fresh file handed back
        use std::os::fd::AsFd;
        assert!(rotate_open_log(f.as_fd(), &log, 1000, 3).unwrap().is_none());
        let mut fresh = rotate_open_log(f.as_fd(), &log, 100, 3).unwrap().expect("rotated");
        assert_eq!(generation(1).len(), 154);
        fresh.write_all(b"new").unwrap();
        assert_eq!(std::fs::read(&log).unwrap(), b"new");
        // another process rotated the log under us: reopen the current one
        std::fs::rename(&log, rotated_log(&log, 1)).unwrap();
        std::fs::write(&log, b"").unwrap();
        assert!(rotate_open_log(fresh.as_fd(), &log, 100, 3).unwrap().is_some());

        // never through a symlink, and 0600
        let link = dir.join("link.log");
        std::os::unix::fs::symlink(dir.join("elsewhere"), &link).unwrap();
        assert!(open_log_with(&link, 100, 3).is_err());
        assert!(!dir.join("elsewhere").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

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
