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
        if self.len == 0 {
            return (0, 0, 0);
        }
        let mut v = self.recent[..self.len].to_vec();
        v.sort_unstable();
        (percentile(&v, 0.50), percentile(&v, 0.99), self.max)
    }

    /// Forgets the recent values and the maximum (after a period change).
    pub fn reset(&mut self) {
        self.len = 0;
        self.next = 0;
        self.max = 0;
    }
}

/// The `q` quantile (0..=1) of sorted values, nearest rank.
pub fn percentile(sorted: &[u64], q: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

/// CPU use of this process, from `/proc/self/stat`.
#[derive(Debug, Default)]
pub struct CpuMeter {
    last: Option<(u64, u64)>,
    percent: f64,
}

impl CpuMeter {
    /// Samples the CPU time; returns the percent of one core used since the last sample.
    pub fn sample(&mut self, now_ns: u64) -> f64 {
        if let Some(ticks) = process_cpu_ticks() {
            if let Some((t0, c0)) = self.last {
                let dt = now_ns.saturating_sub(t0) as f64 / 1e9;
                if dt > 0.05 {
                    let hz = clock_ticks_per_sec();
                    self.percent = (ticks.saturating_sub(c0)) as f64 / hz / dt * 100.0;
                    self.last = Some((now_ns, ticks));
                }
            } else {
                self.last = Some((now_ns, ticks));
            }
        }
        self.percent
    }

    /// The last computed percentage.
    pub fn percent(&self) -> f64 {
        self.percent
    }
}

fn clock_ticks_per_sec() -> f64 {
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if hz > 0 { hz as f64 } else { 100.0 }
}

/// utime + stime of a process in clock ticks.
pub fn cpu_ticks_of(pid: &str) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    // after the command: state is field 3, utime 14, stime 15 (1-based in proc(5))
    let utime: u64 = f.get(11)?.parse().ok()?;
    let stime: u64 = f.get(12)?.parse().ok()?;
    Some(utime + stime)
}

fn process_cpu_ticks() -> Option<u64> {
    cpu_ticks_of("self")
}

/// Resident memory of this process in bytes.
pub fn rss_bytes() -> u64 {
    let statm = std::fs::read_to_string("/proc/self/statm").unwrap_or_default();
    let pages: u64 = statm.split_whitespace().nth(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    // SAFETY: sysconf has no preconditions.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) }.max(4096) as u64;
    pages * page
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
    fn percentiles() {
        let mut l = LatenessRecorder::default();
        for i in 1..=100u64 {
            l.record(i);
        }
        assert_eq!(l.summary(), (50, 99, 100));
    }
}
