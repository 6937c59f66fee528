//! Simulated time: the robot's clock when the simulator owns it (`nerve
//! launch --sim-time`, `nerve demo ... --sim-time --time-scale 4`).
//!
//! The clock is a small shared page (a file of 40 bytes, mapped by every
//! process of the robot) that the launcher creates before anything starts
//! and names in the environment ([`SIM_CLOCK_ENV`]), so that every process
//! it starts, and every one the router restarts, reads the same clock:
//!
//! * `epoch_mono_ns`, `epoch_sim_ns`, `scale`: written once. Simulated time
//!   is `epoch_sim + (CLOCK_MONOTONIC - epoch_mono) × scale`: at scale 4 a
//!   simulated second lasts 250 ms.
//! * `horizon_ns`: how far the simulator has got. The simulator (the clock's
//!   owner, [`own`]) publishes, at each of its steps, the end of the step it
//!   runs; every other process's clock stops there. A simulator that falls
//!   behind (a busy machine at 4×) or stops holds the robot's time: no agent
//!   runs ahead of the world it senses. Before a simulator has started, time
//!   runs at the scale from the launch (`horizon_ns = u64::MAX`).
//!
//! Whether a process is simulated is decided once, at the first reading of
//! the clock ([`crate::clock::now_ns`]), from [`SIM_CLOCK_ENV`]; the wall
//! clock's path costs one branch on that value. Sleeping to a simulated
//! deadline sleeps the wall time the scale gives and looks again on waking
//! (the simulator may have fallen behind meanwhile).
//!
//! Unix-time stamps ([`crate::clock::unix_now_ns`]: a recording's log time,
//! the bridge's one-way latency) stay on the real clock: they say when
//! something happened in the world outside, and a file or a peer on another
//! machine reads them so. Everything an agent measures a robot's behaviour
//! with (`ctx.now_ns()`, deadlines, sample stamps, timeouts, the bridge's
//! lease) follows the simulated clock. See `docs/time.md`.

use std::os::fd::AsRawFd as _;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The environment variable naming the clock's page; set by the launcher
/// for every process of a robot on simulated time.
pub const SIM_CLOCK_ENV: &str = "NERVE_SIM_CLOCK";

/// The page's file name in the robot's state folder.
pub const PAGE_FILE: &str = "sim-clock";

/// The fastest and slowest simulated time nerve runs: 1/100 to 100 × real time.
pub const SCALE_RANGE: (f64, f64) = (0.01, 100.0);

/// `--sim-time [--time-scale K]`, as `nerve launch` and `nerve-demo` take
/// them (flatten it into a command's clap arguments).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SimTimeArgs {
    /// Run on simulated time: the simulator owns the robot's clock, and every
    /// agent's time, deadlines, stamps and timeouts follow it (docs/time.md).
    #[arg(long)]
    pub sim_time: bool,
    /// With --sim-time: how many times as fast as real time the robot runs
    /// [default: the world's `time_scale`, else 1].
    #[arg(long, requires = "sim_time", value_parser = parse_scale)]
    pub time_scale: Option<f64>,
}

impl SimTimeArgs {
    /// The scale to run at: `None` on the wall clock; with `--sim-time` the
    /// flag's, else the world's (`world_scale`), else 1.
    pub fn scale(&self, world_scale: Option<f64>) -> Option<f64> {
        self.sim_time.then(|| self.time_scale.or(world_scale).unwrap_or(1.0))
    }
}

/// A time scale on the command line or in a launch file: a number in
/// [`SCALE_RANGE`], or a message saying what to give instead.
pub fn parse_scale(s: &str) -> Result<f64, String> {
    let v: f64 =
        s.trim().parse().map_err(|_| format!("{s:?} is not a number; give e.g. 4 for four times real time"))?;
    let (lo, hi) = SCALE_RANGE;
    if !(v.is_finite() && (lo..=hi).contains(&v)) {
        return Err(format!("{s:?}: give a time scale from {lo} (slower than real time) to {hi} (faster)"));
    }
    Ok(v)
}

/// `nrvclk01`: a page of this layout.
const MAGIC: u64 = u64::from_le_bytes(*b"nrvclk01");

/// The shared page, as it lies in the file.
#[repr(C)]
struct Page {
    magic: AtomicU64,
    epoch_mono_ns: AtomicU64,
    epoch_sim_ns: AtomicU64,
    scale_bits: AtomicU64,
    horizon_ns: AtomicU64,
}

const PAGE_LEN: usize = std::mem::size_of::<Page>();

/// Why the simulated clock cannot be made or used.
#[derive(Debug, thiserror::Error)]
pub enum SimClockError {
    /// The scale is not a number nerve runs at.
    #[error(
        "time scale {scale} is out of range: give a number from {} (slower than real time) to {} (faster)",
        SCALE_RANGE.0,
        SCALE_RANGE.1
    )]
    Scale {
        /// The scale asked for.
        scale: f64,
    },
    /// The page could not be written.
    #[error("cannot create the simulated clock {path}: {source}; check that the robot's state folder is writable")]
    Create {
        /// The page's path.
        path: PathBuf,
        /// What the OS said.
        #[source]
        source: std::io::Error,
    },
    /// The page named by the environment could not be opened or mapped.
    #[error(
        "cannot use the simulated clock {path} named by {SIM_CLOCK_ENV}: {source}; start the robot again with \
         `nerve launch --sim-time`, or unset {SIM_CLOCK_ENV} to run on the wall clock"
    )]
    Open {
        /// The page's path.
        path: PathBuf,
        /// What the OS said.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a clock page.
    #[error(
        "{path} (named by {SIM_CLOCK_ENV}) is not a simulated clock of this nerve version; start the robot again \
         with `nerve launch --sim-time`"
    )]
    NotAClock {
        /// The page's path.
        path: PathBuf,
    },
    /// A device that is not the simulator's is to be used on simulated time.
    #[error(
        "device {path} is real hardware ({target}), but robot runs on simulated time ({SIM_CLOCK_ENV}={page}): a \
         real device cannot follow a simulated clock. Run this agent on a robot without --sim-time, or point it at \
         the simulator's device (the links in the robot's dev folder)"
    )]
    RealDevice {
        /// The device asked for.
        path: PathBuf,
        /// What it resolves to.
        target: String,
        /// The clock's page.
        page: String,
    },
}

/// The simulated clock of this process, mapped.
#[derive(Debug)]
pub struct SimClock {
    page: &'static Page,
    epoch_mono_ns: u64,
    epoch_sim_ns: u64,
    scale: f64,
    path: PathBuf,
}

impl std::fmt::Debug for Page {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Page").field("horizon_ns", &self.horizon_ns.load(Ordering::Relaxed)).finish_non_exhaustive()
    }
}

/// Set once by the simulator: its clock does not stop at the horizon (it
/// makes it).
static OWNER: AtomicBool = AtomicBool::new(false);

/// The process's clock: `None` on the wall clock.
static CLOCK: OnceLock<Option<SimClock>> = OnceLock::new();

/// The simulated clock if this process runs on one (decided at the first
/// call, from [`SIM_CLOCK_ENV`]). A page that cannot be used is logged and
/// the process runs on the wall clock; an agent's start-up refuses it first
/// ([`check`]).
#[inline]
pub fn active() -> Option<&'static SimClock> {
    CLOCK
        .get_or_init(|| match from_env() {
            Ok(c) => c,
            Err(e) => {
                tracing::error!("{e}");
                None
            }
        })
        .as_ref()
}

/// Whether this process may run: `Ok(Some(scale))` on simulated time,
/// `Ok(None)` on the wall clock, an error for a page named but unusable.
pub fn check() -> Result<Option<f64>, SimClockError> {
    match std::env::var_os(SIM_CLOCK_ENV) {
        Some(p) if !p.is_empty() => match active() {
            Some(c) => Ok(Some(c.scale)),
            None => {
                let path = PathBuf::from(p);
                Err(map(&path).err().unwrap_or(SimClockError::NotAClock { path }))
            }
        },
        _ => Ok(None),
    }
}

fn from_env() -> Result<Option<SimClock>, SimClockError> {
    match std::env::var_os(SIM_CLOCK_ENV) {
        Some(p) if !p.is_empty() => map(Path::new(&p)).map(Some),
        _ => Ok(None),
    }
}

/// Creates (or replaces) the page at `path`: simulated time starts at the
/// wall's monotonic time now and runs `scale` times as fast; no simulator
/// yet. Written to a new file then renamed, so that no process maps half a
/// page.
pub fn create(path: &Path, scale: f64) -> Result<(), SimClockError> {
    if !(scale.is_finite() && (SCALE_RANGE.0..=SCALE_RANGE.1).contains(&scale)) {
        return Err(SimClockError::Scale { scale });
    }
    let now = crate::clock::wall_now_ns();
    let mut bytes = Vec::with_capacity(PAGE_LEN);
    for v in [MAGIC, now, now, scale.to_bits(), u64::MAX] {
        bytes.extend_from_slice(&v.to_ne_bytes());
    }
    let tmp = path.with_extension(format!("new-{}", std::process::id()));
    let err = |source| SimClockError::Create { path: path.to_path_buf(), source };
    std::fs::write(&tmp, &bytes).map_err(err)?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        err(e)
    })
}

/// Maps the page at `path` for the life of the process.
fn map(path: &Path) -> Result<SimClock, SimClockError> {
    let open_err = |source| SimClockError::Open { path: path.to_path_buf(), source };
    let file = std::fs::OpenOptions::new().read(true).write(true).open(path).map_err(open_err)?;
    let len = file.metadata().map_err(open_err)?.len();
    if len != PAGE_LEN as u64 {
        return Err(SimClockError::NotAClock { path: path.to_path_buf() });
    }
    // SAFETY: a shared, read-write mapping of PAGE_LEN bytes of a file of
    // exactly that length, opened read-write; the mapping outlives the
    // descriptor (closed when `file` drops) as mmap(2) allows.
    let ptr = unsafe {
        libc::mmap(
            std::ptr::null_mut(),
            PAGE_LEN,
            libc::PROT_READ | libc::PROT_WRITE,
            libc::MAP_SHARED,
            file.as_raw_fd(),
            0,
        )
    };
    if ptr == libc::MAP_FAILED {
        return Err(open_err(std::io::Error::last_os_error()));
    }
    // SAFETY: the mapping is page-aligned (so aligned for AtomicU64), holds
    // PAGE_LEN bytes, is never unmapped (it lives as long as the process),
    // and every field is an atomic, so that the other processes writing
    // it concurrently are no data race.
    let page: &'static Page = unsafe { &*(ptr as *const Page) };
    if page.magic.load(Ordering::Acquire) != MAGIC {
        return Err(SimClockError::NotAClock { path: path.to_path_buf() });
    }
    let scale = f64::from_bits(page.scale_bits.load(Ordering::Acquire));
    if !(scale.is_finite() && (SCALE_RANGE.0..=SCALE_RANGE.1).contains(&scale)) {
        return Err(SimClockError::Scale { scale });
    }
    Ok(SimClock {
        page,
        epoch_mono_ns: page.epoch_mono_ns.load(Ordering::Acquire),
        epoch_sim_ns: page.epoch_sim_ns.load(Ordering::Acquire),
        scale,
        path: path.to_path_buf(),
    })
}

/// Shortest wall sleep while waiting for a simulator that is behind: a
/// look every 200 µs, not a spin.
const MIN_WAIT_NS: u64 = 200_000;

impl SimClock {
    /// Simulated ns now: the scaled wall clock, stopped at the simulator's
    /// horizon unless this process is the simulator.
    #[inline]
    pub fn now_ns(&self) -> u64 {
        let t = self.at_wall(crate::clock::wall_now_ns());
        if OWNER.load(Ordering::Relaxed) { t } else { t.min(self.page.horizon_ns.load(Ordering::Acquire)) }
    }

    /// Simulated ns at wall (monotonic) ns `wall`, without the horizon.
    fn at_wall(&self, wall: u64) -> u64 {
        let d = wall.saturating_sub(self.epoch_mono_ns) as f64 * self.scale;
        self.epoch_sim_ns.saturating_add(d as u64)
    }

    /// How many times as fast as real time the clock runs.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// The page's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Simulated ns in `wall_ns` of real time.
    pub fn scaled(&self, wall_ns: u64) -> u64 {
        (wall_ns as f64 * self.scale) as u64
    }

    /// Sleeps until the simulated clock reaches `deadline_ns`: the wall time
    /// the scale gives, then a look, again until it is reached.
    pub fn sleep_until(&self, deadline_ns: u64) {
        self.sleep_until_within(deadline_ns, u64::MAX);
    }

    /// [`SimClock::sleep_until`], but back after at most about `max_wall_ns`
    /// of wall time even when the simulator holds the clock short of the
    /// deadline (stopped, suspended, behind): a task that must see a stop
    /// request sleeps so, and loops.
    pub fn sleep_until_within(&self, deadline_ns: u64, max_wall_ns: u64) {
        let until_wall = crate::clock::wall_now_ns().saturating_add(max_wall_ns);
        loop {
            let now = self.now_ns();
            let wall_now = crate::clock::wall_now_ns();
            if now >= deadline_ns || wall_now >= until_wall {
                return;
            }
            let wall = ((deadline_ns - now) as f64 / self.scale) as u64;
            crate::clock::sleep_until_wall_ns(wall_now.saturating_add(wall.max(MIN_WAIT_NS)).min(until_wall));
        }
    }

    /// The simulator's step that ends at `end_ns` has begun: every other
    /// process's clock may run to there.
    pub fn publish_horizon(&self, end_ns: u64) {
        let h = &self.page.horizon_ns;
        let cur = h.load(Ordering::Acquire);
        if cur == u64::MAX || end_ns > cur {
            h.store(end_ns, Ordering::Release);
        }
    }
}

/// Makes this process the clock's owner (the simulator): its clock runs
/// unstopped and its periodic task publishes the horizon at every step. A
/// no-op on the wall clock. Until its first step, the others wait at the
/// time it took ownership.
pub fn own() {
    if let Some(c) = active() {
        OWNER.store(true, Ordering::Release);
        let now = c.now_ns();
        let h = &c.page.horizon_ns;
        let cur = h.load(Ordering::Acquire);
        if cur == u64::MAX || now > cur {
            h.store(now, Ordering::Release);
        }
        tracing::info!(scale = c.scale, page = %c.path.display(), "the simulator owns the robot's clock");
    }
}

/// How many times as fast as real time the robot's clock runs: 1 on the
/// wall clock. A rate measured against the machine's time (a process's CPU
/// share) divided by it is the rate per simulated second.
pub fn scale() -> f64 {
    active().map_or(1.0, |c| c.scale)
}

/// Whether this process owns the simulated clock.
pub fn is_owner() -> bool {
    OWNER.load(Ordering::Relaxed)
}

/// Refuses a device that is not a pseudo-terminal (the simulator's) while
/// the process runs on simulated time: a real board cannot follow it. A
/// path that does not exist yet counts as the simulator's link (it appears
/// when the simulator starts) unless it names something in `/dev`.
pub fn refuse_real_device(path: &Path) -> Result<(), SimClockError> {
    let Some(c) = active() else { return Ok(()) };
    if is_simulated_device(path) {
        return Ok(());
    }
    let target = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    Err(SimClockError::RealDevice {
        path: path.to_path_buf(),
        target: target.display().to_string(),
        page: c.path.display().to_string(),
    })
}

/// Whether `path` is (or will be) a simulator's pseudo-terminal rather
/// than a real device.
fn is_simulated_device(path: &Path) -> bool {
    match std::fs::canonicalize(path) {
        Ok(target) => target.starts_with("/dev/pts"),
        Err(_) => !path.starts_with("/dev"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_are_checked_and_default_to_the_worlds() {
        assert_eq!(parse_scale("4"), Ok(4.0));
        assert_eq!(parse_scale(" 0.5 "), Ok(0.5));
        for bad in ["0", "-1", "nan", "inf", "1000", "fast", ""] {
            assert!(parse_scale(bad).is_err(), "{bad} accepted");
        }
        let wall = SimTimeArgs::default();
        assert_eq!(wall.scale(Some(4.0)), None, "a world's scale alone does not make time simulated");
        let sim = SimTimeArgs { sim_time: true, time_scale: None };
        assert_eq!(sim.scale(Some(4.0)), Some(4.0));
        assert_eq!(sim.scale(None), Some(1.0));
        let given = SimTimeArgs { sim_time: true, time_scale: Some(2.0) };
        assert_eq!(given.scale(Some(4.0)), Some(2.0));
    }

    fn temp_page(scale: f64) -> (PathBuf, SimClock) {
        let dir = std::env::temp_dir().join(format!("nerve-simclock-{}-{scale}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join(PAGE_FILE);
        create(&path, scale).expect("create");
        let c = map(&path).expect("map");
        (dir, c)
    }

    #[test]
    fn runs_at_the_scale_and_stops_at_the_horizon() {
        let (dir, c) = temp_page(4.0);
        let wa = crate::clock::wall_now_ns();
        let s0 = c.now_ns();
        let wb = crate::clock::wall_now_ns();
        crate::clock::sleep_until_wall_ns(wb + 20_000_000);
        let s1 = c.now_ns();
        let w1 = crate::clock::wall_now_ns();
        // 4 × the wall time between the readings: at least the 20 ms slept,
        // at most the wall time around both readings (±1 ns of rounding each)
        assert!(s1 - s0 >= 4 * 20_000_000 - 2, "simulated {} ns in 20 ms of wall time", s1 - s0);
        assert!(s1 - s0 <= 4 * (w1 - wa) + 2, "simulated {} ns in {} ns", s1 - s0, w1 - wa);
        // a simulator that published a horizon holds the others there
        c.publish_horizon(s1 + 1_000_000);
        crate::clock::sleep_until_wall_ns(crate::clock::wall_now_ns() + 5_000_000);
        assert_eq!(c.now_ns(), s1 + 1_000_000);
        // and the horizon only moves forward
        c.publish_horizon(s1);
        assert_eq!(c.now_ns(), s1 + 1_000_000);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn sleeping_to_a_simulated_deadline_waits_for_the_simulator() {
        let (dir, c) = temp_page(2.0);
        let start = c.now_ns();
        c.sleep_until(start + 10_000_000);
        assert!(c.now_ns() >= start + 10_000_000);
        // held at the horizon: a deadline past it is reached only when it moves
        let h = c.now_ns() + 1_000_000;
        c.publish_horizon(h);
        let page = c.page;
        let mover = std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(30));
            let cur = page.horizon_ns.load(Ordering::Acquire);
            page.horizon_ns.store(cur + 100_000_000, Ordering::Release);
        });
        c.sleep_until(h + 5_000_000);
        assert!(c.now_ns() >= h + 5_000_000);
        mover.join().expect("mover");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn real_devices_are_told_from_the_simulators() {
        assert!(!is_simulated_device(Path::new("/dev/null")), "a character device outside /dev/pts");
        assert!(!is_simulated_device(Path::new("/dev/ttyUSB-nerve-none")), "a board not plugged in");
        assert!(is_simulated_device(Path::new("/nonexistent/nerve/h1/dev/sonar")), "a link yet to appear");
        // a pseudo-terminal, as the simulator's links resolve to
        // SAFETY: posix_openpt returns a new descriptor or -1; ptsname reads it.
        let fd = unsafe { libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY) };
        assert!(fd >= 0, "posix_openpt");
        let mut buf = [0 as libc::c_char; 128];
        // SAFETY: `buf` is writable for its length; `fd` is the master opened above.
        let rc = unsafe { libc::ptsname_r(fd, buf.as_mut_ptr(), buf.len()) };
        assert_eq!(rc, 0, "ptsname_r");
        // SAFETY: ptsname_r wrote a NUL-terminated name into `buf`.
        let name = unsafe { std::ffi::CStr::from_ptr(buf.as_ptr()) }.to_string_lossy().into_owned();
        assert!(is_simulated_device(Path::new(&name)), "{name}");
        // SAFETY: `fd` is ours and closed once.
        unsafe { libc::close(fd) };
    }

    #[test]
    fn bad_pages_and_scales_are_refused() {
        let dir = std::env::temp_dir().join(format!("nerve-simclock-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 1000.0] {
            assert!(matches!(create(&dir.join("x"), bad), Err(SimClockError::Scale { .. })), "{bad} accepted");
        }
        let junk = dir.join("junk");
        std::fs::write(&junk, b"not a clock").expect("write");
        assert!(matches!(map(&junk), Err(SimClockError::NotAClock { .. })));
        std::fs::write(&junk, [0u8; PAGE_LEN]).expect("write");
        let e = map(&junk).expect_err("zeroes are no clock");
        assert!(e.to_string().contains("--sim-time"), "{e}");
        assert!(matches!(map(&dir.join("missing")), Err(SimClockError::Open { .. })));
        let _ = std::fs::remove_dir_all(dir);
    }
}
