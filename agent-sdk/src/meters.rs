//! Measurement helpers: rate over a sliding window, lateness percentiles,
//! CPU and memory of this process.

/// Estimates an event rate from the most recent event times.
#[derive(Debug, Clone)]
pub struct RateMeter {
    stamps: Vec<u64>,
    next: usize,
    len: usize,
    window_ns: u64,
}

impl Default for RateMeter {
    fn default() -> Self {
        Self::new(256, 2_000_000_000)
    }
}

impl RateMeter {
    /// Keeps up to `capacity` event times and looks back at most `window_ns`.
    pub fn new(capacity: usize, window_ns: u64) -> Self {
        RateMeter { stamps: vec![0; capacity.max(2)], next: 0, len: 0, window_ns }
    }

    /// Records an event at `t_ns`.
    pub fn record(&mut self, t_ns: u64) {
        self.stamps[self.next] = t_ns;
        self.next = (self.next + 1) % self.stamps.len();
        self.len = (self.len + 1).min(self.stamps.len());
    }

    /// Events per second around `now_ns`; 0 when nothing arrived within the window.
    pub fn rate(&self, now_ns: u64) -> f64 {
        let cap = self.stamps.len();
        let newest_idx = (self.next + cap - 1) % cap;
        if self.len == 0 || now_ns.saturating_sub(self.stamps[newest_idx]) > self.window_ns {
            return 0.0;
        }
        // the oldest stamp still inside the window
        let mut count = 0usize;
        let mut oldest = self.stamps[newest_idx];
        for i in 0..self.len {
            let t = self.stamps[(newest_idx + cap - i) % cap];
            if now_ns.saturating_sub(t) > self.window_ns {
                break;
            }
            oldest = t;
            count += 1;
        }
        if count < 2 {
            return 0.0;
        }
        let span = self.stamps[newest_idx].saturating_sub(oldest);
        if span == 0 { 0.0 } else { (count - 1) as f64 * 1e9 / span as f64 }
    }
}

/// Lateness of wake-ups: recent values for percentiles and the all-time maximum.
#[derive(Debug, Clone)]
pub struct LatenessRecorder {
    recent: Vec<u64>,
    next: usize,
    len: usize,
    max: u64,
}

impl Default for LatenessRecorder {
    fn default() -> Self {
        LatenessRecorder { recent: vec![0; 2048], next: 0, len: 0, max: 0 }
    }
}

impl LatenessRecorder {
    /// Records one lateness value.
    pub fn record(&mut self, ns: u64) {
        self.recent[self.next] = ns;
        self.next = (self.next + 1) % self.recent.len();
        self.len = (self.len + 1).min(self.recent.len());
        self.max = self.max.max(ns);
    }

    /// (p50, p99, max since start) in nanoseconds.
    pub fn summary(&self) -> (u64, u64, u64) {
        let mut v = Vec::new();
        let max = self.copy_recent_into(&mut v);
        summary_of(&mut v, max)
    }

    /// Copies the recent values into `out` (replacing what it held, reusing
    /// its memory) and returns the all-time maximum: taken under the lock
    /// the task records into, so that [`summary_of`] can work outside it.
    pub fn copy_recent_into(&self, out: &mut Vec<u64>) -> u64 {
        out.clear();
        out.extend_from_slice(&self.recent[..self.len]);
        self.max
    }

    /// Forgets the recent values and the maximum (after a period change).
    pub fn reset(&mut self) {
        self.len = 0;
        self.next = 0;
        self.max = 0;
    }
}

/// (p50, p99, max) of lateness values (reordered in place), given their
/// maximum; zeros when there are none.
pub fn summary_of(values: &mut [u64], max: u64) -> (u64, u64, u64) {
    if values.is_empty() {
        return (0, 0, 0);
    }
    // two selections instead of a sort: every `nerve ps` asks for this,
    // and sorting 2048 values was the largest part of an agent's answer
    let n = values.len();
    let mut nth = |q: f64| *values.select_nth_unstable(nearest_rank(n, q)).1;
    (nth(0.50), nth(0.99), max)
}

/// The `q` quantile (0..=1) of sorted values, nearest rank.
pub fn percentile(sorted: &[u64], q: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    sorted[nearest_rank(sorted.len(), q)]
}

/// The index of the `q` quantile (0..=1) among `len` sorted values, by
/// nearest rank; `len` is at least 1.
fn nearest_rank(len: usize, q: f64) -> usize {
    ((q * len as f64).ceil() as usize).clamp(1, len) - 1
}

/// CPU use and memory of this process, for its statistics.
///
/// Both are read often (every `nerve ps` asks every agent), so neither
/// opens a file per reading: the CPU time comes from
/// `clock_gettime(CLOCK_PROCESS_CPUTIME_ID)`, and the resident memory from
/// `/proc/self/statm` opened once and read again at offset 0. Opening it
/// each time (the path walk through `/proc/self`) was a fifth of an agent's
/// CPU while it answered `ps` (BENCHMARKS.md §6).
#[derive(Debug)]
pub struct CpuMeter {
    last: Option<(u64, u64)>,
    percent: f64,
    statm: Option<std::fs::File>,
}

impl Default for CpuMeter {
    fn default() -> Self {
        CpuMeter { last: None, percent: 0.0, statm: std::fs::File::open("/proc/self/statm").ok() }
    }
}

impl CpuMeter {
    /// Samples the CPU time; returns the percent of one core used since the last sample.
    pub fn sample(&mut self, now_ns: u64) -> f64 {
        if let Some(cpu_ns) = process_cpu_ns() {
            if let Some((t0, c0)) = self.last {
                let dt = now_ns.saturating_sub(t0);
                if dt > 50_000_000 {
                    self.percent = cpu_ns.saturating_sub(c0) as f64 / dt as f64 * 100.0;
                    self.last = Some((now_ns, cpu_ns));
                }
            } else {
                self.last = Some((now_ns, cpu_ns));
            }
        }
        self.percent
    }

    /// The last computed percentage.
    pub fn percent(&self) -> f64 {
        self.percent
    }

    /// Resident memory of this process now, bytes (0 where `/proc` cannot
    /// be read).
    pub fn rss_bytes(&self) -> u64 {
        use std::os::unix::fs::FileExt;
        let Some(f) = &self.statm else { return rss_bytes() };
        let mut buf = [0u8; 128];
        match f.read_at(&mut buf, 0) {
            Ok(n) => rss_of_statm(std::str::from_utf8(&buf[..n]).unwrap_or("")),
            Err(_) => rss_bytes(),
        }
    }
}

/// CPU time of this whole process, ns.
fn process_cpu_ns() -> Option<u64> {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes into the timespec we pass.
    let r = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    if r != 0 {
        return None;
    }
    u64::try_from(ts.tv_sec).ok()?.checked_mul(1_000_000_000)?.checked_add(u64::try_from(ts.tv_nsec).ok()?)
}

/// Resident memory of this process, bytes, from `/proc/self/statm`.
pub fn rss_bytes() -> u64 {
    rss_of_statm(&std::fs::read_to_string("/proc/self/statm").unwrap_or_default())
}

/// Resident bytes from the text of a `statm` file (pages, second field).
fn rss_of_statm(statm: &str) -> u64 {
    let pages: u64 = statm.split_whitespace().nth(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    // SAFETY: sysconf has no preconditions.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) }.max(4096) as u64;
    pages.saturating_mul(page)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rate_of_regular_events() {
        let mut m = RateMeter::default();
        for i in 0..100u64 {
            m.record(1_000_000_000 + i * 10_000_000); // 100 Hz
        }
        let r = m.rate(1_000_000_000 + 99 * 10_000_000);
        assert!((r - 100.0).abs() < 0.5, "{r}");
        // silence for longer than the window gives 0
        assert_eq!(m.rate(10_000_000_000), 0.0);
    }

    #[test]
    fn memory_and_cpu_of_this_process() {
        let mut m = CpuMeter::default();
        let rss = m.rss_bytes();
        assert!(rss > 1 << 20, "a test process has more than 1 MiB resident: {rss}");
        // read again from the same open file: still there, about the same
        assert!(m.rss_bytes().abs_diff(rss) < 64 << 20);
        assert_eq!(rss_of_statm("100 25 3 1 0 20 0\n") % 4096, 0);
        assert_eq!(rss_of_statm(""), 0);
        // a busy loop of 200 ms shows as CPU
        let t0 = crate::clock::now_ns();
        m.sample(t0);
        let start = std::time::Instant::now();
        let mut x = 0u64;
        while start.elapsed() < std::time::Duration::from_millis(200) {
            x = x.wrapping_add(std::hint::black_box(1));
        }
        let pct = m.sample(crate::clock::now_ns());
        assert!(pct > 20.0 && pct < 250.0, "{pct}% ({x})");
    }

    #[test]
    fn percentiles() {
        let mut l = LatenessRecorder::default();
        for i in 1..=100u64 {
            l.record(i);
        }
        assert_eq!(l.summary(), (50, 99, 100));
        // out of order, and wrapped round the buffer: the same as sorting
        let mut l = LatenessRecorder::default();
        let mut x = 12345u64;
        for _ in 0..5000 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            l.record(x >> 40);
        }
        let mut v = l.recent.clone();
        v.sort_unstable();
        let (p50, p99, _) = l.summary();
        assert_eq!((p50, p99), (percentile(&v, 0.50), percentile(&v, 0.99)));
    }
}
