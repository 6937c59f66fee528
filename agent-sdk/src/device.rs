//! The device thread of nerve's sensor and actuator agents (thesis Fig. 2-3:
//! the "receiver" that listens to the hardware), part of the SDK as DESIGN
//! puts it (it was the `nerve-devlink` crate in an agent's folder).
//!
//! [`DeviceLink::spawn`] starts a thread that owns one serial device (a
//! board's `/dev/ttyUSB*` or a simulator's pseudo-terminal), decodes its
//! frames with [`nerve_devices::SerialLink`] and hands every message to the
//! agent's task through a bounded channel ([`DeviceLink::try_recv`]); the task
//! sends commands back with [`DeviceLink::send`].
//!
//! **Failures.** When the device cannot be opened, or vanishes while open
//! (the pty closed: `BrokenPipe`, EIO, end of file), the thread logs it once
//! at `warn` level, then retries with **exponential backoff** ([`Backoff`]:
//! 100 ms doubling up to 5 s, by default), sleeping between attempts — never
//! a busy loop. Further failed attempts are logged at `debug` level only,
//! with a `warn` line again at attempts 8, 16, 32, ... so that a log does
//! not fill up. When the device reappears it is reopened, logged at `info`
//! level ("device recovered"), and the backoff starts over. Decoder
//! counters ([`LinkStats`]) are cumulative over reopenings.
//!
//! **Stale input.** Whatever the line holds at the moment it is opened was
//! sent before: while the line was cut, or before the agent started (the
//! kernel, a USB adapter or a pty keeps it for the next reader). Handed on,
//! it would arrive as a burst of old readings stamped "now" (review fault
//! 4c: 12 sonar scans in one burst after a reconnect). So every open first
//! discards it unread; the frames discarded are counted
//! ([`LinkStats::stale`], the agents' `stale_frames`) and logged.

use nerve_devices::{DecodeStats, Message, SerialLink};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How often the thread looks for outgoing commands while waiting for input.
const POLL: Duration = Duration::from_millis(20);
/// Messages buffered for the task before the oldest are dropped (counted).
const CHANNEL_DEPTH: usize = 256;

/// Why the device thread could not start.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The OS refused a thread.
    #[error("cannot start the device thread for {path}: {source}")]
    Thread {
        /// device path
        path: PathBuf,
        /// OS error
        source: std::io::Error,
    },
}

/// Exponential backoff between reconnection attempts.
#[derive(Debug, Clone)]
pub struct Backoff {
    initial: Duration,
    max: Duration,
    next: Duration,
    attempts: u64,
}

impl Backoff {
    /// Starts at `initial`, doubles after each failure, never exceeds `max`.
    pub fn new(initial: Duration, max: Duration) -> Self {
        Backoff { initial, max: max.max(initial), next: initial, attempts: 0 }
    }

    /// The delay before the next attempt; doubles the one after.
    pub fn next_delay(&mut self) -> Duration {
        let d = self.next;
        self.next = (self.next * 2).min(self.max);
        self.attempts += 1;
        d
    }

    /// Failed attempts since the last success.
    pub fn attempts(&self) -> u64 {
        self.attempts
    }

    /// After a success: start over.
    pub fn reset(&mut self) {
        self.next = self.initial;
        self.attempts = 0;
    }
}

impl Default for Backoff {
    fn default() -> Self {
        Backoff::new(Duration::from_millis(100), Duration::from_secs(5))
    }
}

/// Counters of a device link, cumulative over reopenings.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Decoder counters (frames, garbage bytes, bad checksums, truncated...).
    pub decode: DecodeStats,
    /// Whether the device is open now.
    pub connected: bool,
    /// Successful opens.
    pub opens: u64,
    /// Times the open device vanished (closed, I/O error).
    pub losses: u64,
    /// Failed open attempts.
    pub failed_opens: u64,
    /// Messages dropped because the task did not take them in time.
    pub overflow: u64,
    /// Commands that could not be written (device absent or failing).
    pub unsent: u64,
    /// Frames that were waiting on the line when it was opened (sent while
    /// it was cut, or before the agent started), discarded unread.
    pub stale: u64,
}

fn add(a: DecodeStats, b: DecodeStats) -> DecodeStats {
    DecodeStats {
        frames: a.frames + b.frames,
        garbage_bytes: a.garbage_bytes + b.garbage_bytes,
        bad_headers: a.bad_headers + b.bad_headers,
        bad_checksums: a.bad_checksums + b.bad_checksums,
        truncated: a.truncated + b.truncated,
        invalid_payloads: a.invalid_payloads + b.invalid_payloads,
    }
}

/// What the device thread tells the task.
#[derive(Debug, Clone, PartialEq)]
pub enum DeviceEvent {
    /// A decoded message and the CLOCK_MONOTONIC-like instant it was read.
    Message(Message, Instant),
    /// The device was opened (first time or after a loss).
    Connected,
    /// The device vanished; the thread is retrying.
    Lost,
}

/// A serial device kept open by its own thread; see the module documentation.
#[derive(Debug)]
pub struct DeviceLink {
    events: Receiver<DeviceEvent>,
    commands: SyncSender<Message>,
    stats: Arc<Mutex<LinkStats>>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
    path: PathBuf,
}

/// Options of a [`DeviceLink`].
#[derive(Debug, Clone)]
pub struct LinkOptions {
    /// Backoff between reconnection attempts.
    pub backoff: Backoff,
    /// Name used in log lines (`sonar`, `motor`...).
    pub label: String,
}

impl DeviceLink {
    /// Starts the device thread for `path`. It opens the device itself (and
    /// keeps retrying), so this succeeds even when the device is absent.
    pub fn spawn(path: &Path, opts: LinkOptions) -> Result<Self, LinkError> {
        let (ev_tx, ev_rx) = sync_channel(CHANNEL_DEPTH);
        let (cmd_tx, cmd_rx) = sync_channel(16);
        let stats = Arc::new(Mutex::new(LinkStats::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let worker = Worker {
            path: path.to_path_buf(),
            opts,
            events: ev_tx,
            commands: cmd_rx,
            stats: stats.clone(),
            stop: stop.clone(),
            base: DecodeStats::default(),
        };
        let handle = std::thread::Builder::new()
            .name("device".into())
            .spawn(move || worker.run())
            .map_err(|source| LinkError::Thread { path: path.to_path_buf(), source })?;
        Ok(DeviceLink { events: ev_rx, commands: cmd_tx, stats, stop, handle: Some(handle), path: path.to_path_buf() })
    }

    /// The device path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The next event, if one is waiting.
    pub fn try_recv(&self) -> Option<DeviceEvent> {
        self.events.try_recv().ok()
    }

    /// The next event, waiting at most `timeout`.
    pub fn recv_timeout(&self, timeout: Duration) -> Option<DeviceEvent> {
        self.events.recv_timeout(timeout).ok()
    }

    /// Queues a command for the device; `false` (and counted) when the queue
    /// is full. Commands queued while the device is absent are discarded.
    pub fn send(&self, msg: Message) -> bool {
        match self.commands.try_send(msg) {
            Ok(()) => true,
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                lock(&self.stats).unsent += 1;
                false
            }
        }
    }

    /// The counters now.
    pub fn stats(&self) -> LinkStats {
        *lock(&self.stats)
    }
}

impl Drop for DeviceLink {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

struct Worker {
    path: PathBuf,
    opts: LinkOptions,
    events: SyncSender<DeviceEvent>,
    commands: Receiver<Message>,
    stats: Arc<Mutex<LinkStats>>,
    stop: Arc<AtomicBool>,
    /// decoder counters of the links closed so far
    base: DecodeStats,
}

impl Worker {
    fn stopping(&self) -> bool {
        self.stop.load(Ordering::Acquire)
    }

    /// Sleeps `d` in short slices, returning early on stop.
    fn sleep(&self, d: Duration) {
        let end = Instant::now() + d;
        while !self.stopping() {
            let now = Instant::now();
            if now >= end {
                return;
            }
            std::thread::sleep((end - now).min(Duration::from_millis(50)));
        }
    }

    fn emit(&self, ev: DeviceEvent) {
        match self.events.try_send(ev) {
            Ok(()) | Err(TrySendError::Disconnected(_)) => {}
            Err(TrySendError::Full(_)) => lock(&self.stats).overflow += 1,
        }
    }

    fn run(mut self) {
        let label = self.opts.label.clone();
        let mut backoff = self.opts.backoff.clone();
        let mut ever_open = false;
        while !self.stopping() {
            match SerialLink::open(&self.path) {
                Ok(mut link) => {
                    // what the line holds now was sent before we listened
                    match link.discard_waiting() {
                        Ok(0) => {}
                        Ok(n) => {
                            let mut s = lock(&self.stats);
                            s.stale = s.stale.saturating_add(n);
                            drop(s);
                            tracing::info!(
                                device = %label, path = %self.path.display(), stale_frames = n,
                                "discarded {n} frame(s) the device sent before the line was opened"
                            );
                        }
                        // serving the link finds out whether it still works
                        Err(e) => tracing::debug!(device = %label, "cannot discard stale input: {e}"),
                    }
                    if ever_open {
                        tracing::info!(
                            device = %label, path = %self.path.display(),
                            "device recovered after {} attempt(s)", backoff.attempts()
                        );
                    } else {
                        tracing::info!(device = %label, path = %self.path.display(), "device opened");
                    }
                    ever_open = true;
                    backoff.reset();
                    // commands queued while the device was away are stale
                    while self.commands.try_recv().is_ok() {}
                    {
                        let mut s = lock(&self.stats);
                        s.opens += 1;
                        s.connected = true;
                    }
                    self.emit(DeviceEvent::Connected);
                    let why = self.serve(link);
                    if self.stopping() {
                        break;
                    }
                    lock(&self.stats).losses += 1;
                    self.emit(DeviceEvent::Lost);
                    tracing::warn!(
                        device = %label, path = %self.path.display(),
                        "device lost ({why}); reconnecting with backoff"
                    );
                }
                Err(e) => {
                    lock(&self.stats).failed_opens += 1;
                    let delay = backoff.next_delay();
                    let n = backoff.attempts();
                    if n == 1 || n.is_power_of_two() && n >= 8 {
                        tracing::warn!(
                            device = %label, attempt = n,
                            "{e}; retrying in {} ms (backoff doubles up to {} ms)",
                            delay.as_millis(), self.opts.backoff.max.as_millis()
                        );
                    } else {
                        tracing::debug!(device = %label, attempt = n, "{e}; retrying in {} ms", delay.as_millis());
                    }
                    self.sleep(delay);
                }
            }
        }
    }

    /// Serves an open link until it fails or the thread stops; returns why it ended.
    fn serve(&mut self, mut link: SerialLink) -> String {
        let why = loop {
            if self.stopping() {
                break "stopping".to_owned();
            }
            let mut failed = None;
            while let Ok(cmd) = self.commands.try_recv() {
                if let Err(e) = link.send(&cmd) {
                    lock(&self.stats).unsent += 1;
                    failed = Some(format!("write failed: {e}"));
                    break;
                }
            }
            if let Some(f) = failed {
                break f;
            }
            let result = link.recv(POLL);
            lock(&self.stats).decode = add(self.base, link.stats());
            match result {
                Ok(Some(m)) => {
                    self.emit(DeviceEvent::Message(m, Instant::now()));
                    // more frames may be buffered: take them without waiting
                    while let Ok(Some(m)) = link.recv(Duration::ZERO) {
                        self.emit(DeviceEvent::Message(m, Instant::now()));
                    }
                }
                Ok(None) => {}
                Err(e) => break format!("read failed: {e}"),
            }
        };
        self.base = add(self.base, link.stats());
        let mut s = lock(&self.stats);
        s.decode = self.base;
        s.connected = false;
        why
    }
}

/// A pseudo-terminal in raw mode, standing in for a board's serial line:
/// `(master, slave, path of the slave)`. A device agent is given the path;
/// whoever plays the board reads and writes the master. Keeping the slave
/// open keeps what the master writes queued for whoever opens the path next.
pub fn raw_pty() -> nix::Result<(std::os::fd::OwnedFd, std::os::fd::OwnedFd, PathBuf)> {
    use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
    let pair = nix::pty::openpty(None, None)?;
    let mut t = tcgetattr(&pair.slave)?;
    cfmakeraw(&mut t);
    tcsetattr(&pair.slave, SetArg::TCSANOW, &t)?;
    let tty = nix::unistd::ttyname(&pair.slave)?;
    Ok((pair.master, pair.slave, tty))
}

/// Starts the device thread on `device`, in `Agent::start` (never in `new`,
/// which `--describe` and test harnesses run without a device); `label`
/// names the device in logs, `missing` tells the user what to give when no
/// `--device` was (`nerve start` prints it).
pub fn open_link(device: &Option<PathBuf>, label: &str, missing: &str) -> Result<DeviceLink, crate::AgentError> {
    let Some(path) = device else {
        return Err(crate::AgentError::Config(missing.into()));
    };
    // a real board beside a simulated robot's clock is refused with what to do
    crate::simclock::refuse_real_device(path).map_err(|e| crate::AgentError::Config(e.to_string()))?;
    DeviceLink::spawn(path, LinkOptions { backoff: Default::default(), label: label.into() })
        .map_err(|e| crate::AgentError::Device(e.to_string()))
}

/// Reports the counters of a device link as the agent's read-only figures
/// (`nerve param get`, `nerve param list`, `nerve ps --json`), followed by
/// what `more` reports (the agent's own figures; `Vec::new` for none): an
/// agent has one figure source. Returns the handle the task copies
/// [`LinkStats`] into, at each step.
pub fn counter_figures(
    setup: &mut crate::Setup,
    more: impl Fn() -> Vec<(String, String)> + Send + Sync + 'static,
) -> CounterFigures {
    let shown = Arc::new(Mutex::new(LinkStats::default()));
    let read = shown.clone();
    setup.figures(move || {
        let s = *read.lock().unwrap_or_else(|p| p.into_inner());
        let mut v = link_figures(&s);
        v.extend(more());
        v
    });
    CounterFigures { shown, last_logged: DecodeStats::default(), last_log: None }
}

/// The figures of a device link's counters: `frames`, `garbage_bytes`,
/// `bad_headers`, `bad_checksums`, `truncated`, `invalid_payloads`,
/// `device_opens`, `device_losses`, `device_failed_opens`, `stale_frames`.
pub fn link_figures(s: &LinkStats) -> Vec<(String, String)> {
    let d = s.decode;
    [
        ("frames", d.frames),
        ("garbage_bytes", d.garbage_bytes),
        ("bad_headers", d.bad_headers),
        ("bad_checksums", d.bad_checksums),
        ("truncated", d.truncated),
        ("invalid_payloads", d.invalid_payloads),
        ("device_opens", s.opens),
        ("device_losses", s.losses),
        ("device_failed_opens", s.failed_opens),
        ("stale_frames", s.stale),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v.to_string()))
    .collect()
}

/// A counter an agent keeps itself and reports among its figures (see
/// [`counter_figures`]'s `more`): the task adds, the message checker reads.
#[derive(Debug, Clone, Default)]
pub struct Count(Arc<AtomicU64>);

impl Count {
    /// Adds `n` (wrapping at `u64::MAX`, which no counter reaches).
    pub fn add(&self, n: u64) {
        self.0.fetch_add(n, Ordering::Relaxed);
    }

    /// Sets the value (a count the agent keeps elsewhere, copied each step).
    pub fn set(&self, v: u64) {
        self.0.store(v, Ordering::Relaxed);
    }

    /// The value now.
    pub fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }

    /// The figure `key` with this count.
    pub fn figure(&self, key: &str) -> (String, String) {
        (key.to_owned(), self.get().to_string())
    }
}

/// The counters of a device link as figures (see [`counter_figures`]).
#[derive(Debug)]
pub struct CounterFigures {
    /// what the figures show, read by the message checker
    shown: Arc<Mutex<LinkStats>>,
    last_logged: DecodeStats,
    last_log: Option<Instant>,
}

impl CounterFigures {
    /// Copies the counters into the figures; logs (at most every 5 s)
    /// when the decoder dropped anything since the last log line.
    pub fn update(&mut self, s: &LinkStats, label: &str) {
        let d = s.decode;
        *self.shown.lock().unwrap_or_else(|p| p.into_inner()) = *s;
        let dirty = d.garbage_bytes != self.last_logged.garbage_bytes
            || d.rejected_frames() != self.last_logged.rejected_frames();
        if dirty && self.last_log.is_none_or(|t| t.elapsed() >= Duration::from_secs(5)) {
            tracing::warn!(
                device = %label,
                "line noise: {} garbage bytes, {} bad headers, {} bad checksums, {} truncated, {} invalid payloads dropped so far ({} good frames); parsing resynchronised",
                d.garbage_bytes, d.bad_headers, d.bad_checksums, d.truncated, d.invalid_payloads, d.frames
            );
            self.last_logged = d;
            self.last_log = Some(Instant::now());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_to_the_cap_and_resets() {
        let mut b = Backoff::new(Duration::from_millis(100), Duration::from_millis(700));
        let d: Vec<u128> = (0..5).map(|_| b.next_delay().as_millis()).collect();
        assert_eq!(d, vec![100, 200, 400, 700, 700]);
        assert_eq!(b.attempts(), 5);
        b.reset();
        assert_eq!(b.next_delay(), Duration::from_millis(100));
    }

    /// A pseudo-terminal standing in for a board: the test writes to the
    /// master; the link opens the slave through a symlink, once it exists.
    struct Line {
        master: std::fs::File,
        // held open, so that what the master writes stays queued for
        // whoever opens the slave next
        _slave: std::os::fd::OwnedFd,
        tty: PathBuf,
    }

    impl Line {
        fn new() -> Line {
            let (master, slave, tty) = raw_pty().expect("a pseudo-terminal in raw mode");
            Line { master: std::fs::File::from(master), _slave: slave, tty }
        }

        fn scan(&mut self, seq: u16) {
            use std::io::Write;
            let msg =
                Message::SonarScan(nerve_devices::SonarScan { seq, ranges_mm: [1000; nerve_devices::SONAR_COUNT] });
            self.master.write_all(&msg.encode()).expect("write to the pty master");
        }
    }

    /// The next sonar scan's seq, skipping connection events; `None` if no
    /// scan comes within `wait`.
    fn next_scan(link: &DeviceLink, wait: Duration) -> Option<u16> {
        let end = Instant::now() + wait;
        while let Some(left) = end.checked_duration_since(Instant::now()) {
            match link.recv_timeout(left) {
                Some(DeviceEvent::Message(Message::SonarScan(s), _)) => return Some(s.seq),
                Some(_) => {}
                None => return None,
            }
        }
        None
    }

    /// Review fault 4c: after a cut line came back, a burst of 12 scans
    /// the device had sent during the outage reached the agent, all stamped
    /// at the reconnect. Frames waiting when the line is opened are
    /// discarded unread and counted; the first frame handed on is the first
    /// one sent after the reopen.
    #[test]
    fn frames_sent_while_the_line_was_cut_are_discarded_and_counted() {
        let dir = std::env::temp_dir().join(format!("nerve-devlink-cut-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let link_path = dir.join("sonar");
        let _ = std::fs::remove_file(&link_path);
        let mut line = Line::new();
        std::os::unix::fs::symlink(&line.tty, &link_path).expect("symlink");
        let link = DeviceLink::spawn(
            &link_path,
            LinkOptions {
                backoff: Backoff::new(Duration::from_millis(20), Duration::from_millis(100)),
                label: "sonar".into(),
            },
        )
        .expect("spawn");
        assert!(wait_for(|| link.stats().opens == 1), "the line opens: {:?}", link.stats());
        line.scan(1);
        assert_eq!(next_scan(&link, Duration::from_secs(5)), Some(1));

        // the cut: the line goes away, the link notices and retries
        std::fs::remove_file(&link_path).expect("remove link");
        drop(line);
        assert!(wait_for(|| link.stats().losses == 1), "the cut is noticed: {:?}", link.stats());

        // the line comes back holding 12 scans sent during the outage
        let mut line = Line::new();
        for seq in 2..=13 {
            line.scan(seq);
        }
        std::os::unix::fs::symlink(&line.tty, &link_path).expect("symlink");
        assert!(wait_for(|| link.stats().opens == 2), "the line reopens: {:?}", link.stats());
        // then the device goes on talking
        line.scan(14);
        assert_eq!(next_scan(&link, Duration::from_secs(5)), Some(14), "a stale scan was handed on");
        let s = link.stats();
        assert_eq!(s.stale, 12, "{s:?}");
        assert_eq!(s.decode.garbage_bytes, 0, "{s:?}");
        drop(link);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Polls `cond` for up to 10 s (a bound against hangs, not a timing assertion).
    fn wait_for(mut cond: impl FnMut() -> bool) -> bool {
        let end = Instant::now() + Duration::from_secs(10);
        while Instant::now() < end {
            if cond() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        cond()
    }

    #[test]
    fn absent_device_is_retried_not_spun() {
        let dir = std::env::temp_dir().join(format!("nerve-devlink-{}", std::process::id()));
        let link = DeviceLink::spawn(
            &dir.join("nope"),
            LinkOptions {
                backoff: Backoff::new(Duration::from_millis(20), Duration::from_millis(80)),
                label: "t".into(),
            },
        )
        .expect("spawn");
        std::thread::sleep(Duration::from_millis(500));
        let s = link.stats();
        // 20 + 40 + 80 + 80 + ... ms: about 7 attempts in 500 ms, never hundreds
        assert!((3..=12).contains(&s.failed_opens), "{s:?}");
        assert!(!s.connected);
    }
}
