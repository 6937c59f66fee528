//! Cyclone DDS as a peer of the hop benchmark: `ddsperf` (Debian package
//! `cyclonedds-tools`), the transport under ROS 2's default middleware, in
//! its own ping-pong mode with waitsets (blocking, like the others).
//!
//! `ddsperf pong waitset` runs for the whole scenario in a DDS domain of the
//! run's own (so that no other DDS program on the machine answers); each
//! batch is `ddsperf -D SECS ping size S waitset`, which sends the next ping
//! when the pong came back and prints, once a second, the mean, min, median,
//! 90%, 99% and max of the interval and how many round trips it made.
//!
//! **ddsperf prints half the round trip**: with sequential ping-pong, the
//! number of round trips per second times the printed mean is 0.5 (checked:
//! 22,231 round trips in a second at a printed mean of 22.4 µs; 2,186 at
//! 228.6 µs). The values here are doubled, so that they are round trips
//! like every other row of the hop table. ddsperf gives no raw samples:
//! a batch's median is the median of its per-second medians, its p99 and
//! max the largest per-second p99 and max, and the first second (discovery,
//! warm-up) is dropped. Its smallest payload is 12 bytes.
//!
//! Both processes run at SCHED_FIFO priority 20 like the other peers.

use crate::procs::ChildGuard;
use crate::stats::Summary;
use anyhow::{Context as _, Result, bail};
use std::io::BufRead as _;
use std::os::unix::process::CommandExt as _;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The program.
pub const DDSPERF: &str = "ddsperf";
/// ddsperf's smallest payload (its KS topic's own fields).
pub const MIN_SIZE: usize = 12;

/// One second of a ddsperf ping run, as round trips (ns).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    /// median round trip
    pub p50_ns: u64,
    /// 99th percentile
    pub p99_ns: u64,
    /// maximum
    pub max_ns: u64,
    /// minimum
    pub min_ns: u64,
    /// round trips in the interval
    pub count: u64,
}

/// Whether `ddsperf` can be run (`ddsperf help` exits with status 3: only
/// starting it counts).
pub fn available() -> bool {
    Command::new(DDSPERF).arg("help").stdout(Stdio::null()).stderr(Stdio::null()).status().is_ok()
}

/// The size ddsperf sends for a payload of `size` bytes.
pub fn dds_size(size: usize) -> usize {
    size.max(MIN_SIZE)
}

fn realtime(cmd: &mut Command) {
    // SAFETY: sched_setscheduler is async-signal-safe; failure is ignored (no privilege).
    unsafe {
        cmd.pre_exec(|| {
            let param = libc::sched_param { sched_priority: 20 };
            let _ = libc::sched_setscheduler(0, libc::SCHED_FIFO, &param);
            Ok(())
        });
    }
}

/// The pong side, running until dropped.
#[derive(Debug)]
pub struct DdsPeer {
    _pong: ChildGuard,
    domain: u32,
    verbose: bool,
}

impl DdsPeer {
    /// Starts `ddsperf pong waitset` in a domain of this run's own.
    pub fn start(verbose: bool) -> Result<Self> {
        let domain = 20 + std::process::id() % 200;
        let mut cmd = Command::new(DDSPERF);
        cmd.args(["-i", &domain.to_string(), "pong", "waitset"]).stdin(Stdio::null());
        if !verbose {
            cmd.stdout(Stdio::null()).stderr(Stdio::null());
        }
        realtime(&mut cmd);
        let pong = ChildGuard::spawn("ddsperf pong", cmd)?;
        Ok(DdsPeer { _pong: pong, domain, verbose })
    }

    /// One ping run of `seconds` at `size` (plus the first second, dropped, and
    /// one more: ddsperf does not print the interval it ends in).
    pub fn batch(&self, size: usize, seconds: u64) -> Result<Vec<Interval>> {
        let s = dds_size(size);
        let mut cmd = Command::new(DDSPERF);
        cmd.args(["-i", &self.domain.to_string(), "-D", &(seconds + 2).to_string(), "ping", "size", &s.to_string()])
            .arg("waitset")
            .stdin(Stdio::null())
            .stdout(Stdio::piped());
        if !self.verbose {
            cmd.stderr(Stdio::null());
        }
        realtime(&mut cmd);
        let mut ping = ChildGuard::spawn("ddsperf ping", cmd)?;
        let out = ping.stdout().context("ddsperf ping: no stdout")?;
        let t0 = Instant::now();
        let mut intervals = Vec::new();
        for line in std::io::BufReader::new(out).lines() {
            let line = line.context("reading ddsperf's output")?;
            if let Some(i) = parse_line(&line, s) {
                intervals.push(i);
            }
            if t0.elapsed() > Duration::from_secs(seconds + 20) {
                break;
            }
        }
        ping.stop(Duration::from_secs(2));
        if intervals.len() < 2 {
            bail!(
                "ddsperf ping at {s} B printed {} interval(s) in {:.0} s; is the pong running (domain {})?",
                intervals.len(),
                t0.elapsed().as_secs_f64(),
                self.domain
            );
        }
        Ok(intervals.split_off(1))
    }
}

fn micros_after(line: &str, key: &str) -> Option<u64> {
    let rest = &line[line.find(key)? + key.len()..];
    let v = rest.split_whitespace().next()?.strip_suffix("us")?;
    let us: f64 = v.parse().ok()?;
    // ddsperf prints half the round trip
    Some((2.0 * us * 1000.0).round() as u64)
}

/// Parses a ping line of ddsperf for payload size `size`, e.g.
/// `[9095] 5.000  vm:9078 size 12 mean 22.437us min 10.335us 50% 18.868us 90% 22.879us 99% 75.473us max 4002.439us cnt 22231`.
pub fn parse_line(line: &str, size: usize) -> Option<Interval> {
    if !line.contains(&format!(" size {size} mean ")) {
        return None;
    }
    let count = line.split_whitespace().skip_while(|w| *w != "cnt").nth(1)?.parse().ok()?;
    Some(Interval {
        p50_ns: micros_after(line, " 50% ")?,
        p99_ns: micros_after(line, " 99% ")?,
        max_ns: micros_after(line, " max ")?,
        min_ns: micros_after(line, " min ")?,
        count,
    })
}

/// Pools intervals into a summary (see the module doc for what each field means).
pub fn summarise(intervals: &[Interval]) -> Summary {
    let p50s: Vec<u64> = intervals.iter().map(|i| i.p50_ns).collect();
    Summary {
        n: intervals.iter().map(|i| i.count as usize).sum(),
        min_ns: intervals.iter().map(|i| i.min_ns).min().unwrap_or(0),
        p50_ns: Summary::of(&p50s).p50_ns,
        p99_ns: intervals.iter().map(|i| i.p99_ns).max().unwrap_or(0),
        max_ns: intervals.iter().map(|i| i.max_ns).max().unwrap_or(0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LINE: &str = "[9095] 5.000  vm:9078 size 12 mean 22.437us min 10.335us 50% 18.868us 90% 22.879us 99% 75.473us max 4002.439us cnt 22231";

    #[test]
    fn parses_a_ping_line_as_round_trips() {
        let i = parse_line(LINE, 12).expect("a ping line");
        assert_eq!(i.p50_ns, 37_736);
        assert_eq!(i.p99_ns, 150_946);
        assert_eq!(i.max_ns, 8_004_878);
        assert_eq!(i.min_ns, 20_670);
        assert_eq!(i.count, 22231);
    }

    #[test]
    fn ignores_other_sizes_and_other_lines() {
        assert!(parse_line(LINE, 16).is_none());
        assert!(parse_line("[9095] 5.000  rss:50.4MB vcsw:4112 ivcsw:1835", 12).is_none());
        assert!(parse_line("size 8 invalid: too small to allow for overhead", 8).is_none());
    }

    #[test]
    fn summary_pools_intervals() {
        let a = Interval { p50_ns: 10, p99_ns: 50, max_ns: 90, min_ns: 5, count: 3 };
        let b = Interval { p50_ns: 30, p99_ns: 40, max_ns: 100, min_ns: 7, count: 4 };
        let c = Interval { p50_ns: 20, p99_ns: 60, max_ns: 80, min_ns: 6, count: 5 };
        let s = summarise(&[a, b, c]);
        assert_eq!((s.n, s.min_ns, s.p50_ns, s.p99_ns, s.max_ns), (12, 5, 20, 60, 100));
    }
}
