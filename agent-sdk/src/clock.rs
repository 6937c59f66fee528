//! The monotonic clock of the thesis' Fig. 2-1: one time base for every
//! agent (CLOCK_MONOTONIC, shared by all processes on the host) and sleeping
//! to absolute deadlines, so that periodic tasks do not drift. On simulated
//! time the same functions read the simulator's clock ([`crate::simclock`]).

use std::time::Duration;

/// Nanoseconds of the robot's clock: CLOCK_MONOTONIC (comparable across
/// processes on one host), or the simulated clock when the robot runs on
/// simulated time ([`crate::simclock`], decided once per process). Every
/// agent's `ctx.now_ns()`, deadline and sample stamp is read from here.
#[inline]
pub fn now_ns() -> u64 {
    match crate::simclock::active() {
        None => wall_now_ns(),
        Some(c) => c.now_ns(),
    }
}

/// Nanoseconds of CLOCK_MONOTONIC, whatever clock the robot runs on: for
/// what is measured against the machine (CPU use, the simulated clock itself).
#[inline]
pub fn wall_now_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Robot-clock nanoseconds since `at` (an [`std::time::Instant`] taken
/// earlier, e.g. when a device's frame arrived): the wall time scaled when
/// the robot runs on simulated time.
pub fn elapsed_ns(at: std::time::Instant) -> u64 {
    let wall = nanos(at.elapsed());
    match crate::simclock::active() {
        None => wall,
        Some(c) => c.scaled(wall),
    }
}

/// CLOCK_REALTIME in ns since 1970: the stamp that means something on
/// another machine or in a file (the bridge's one-way latency, a
/// recording's log time), as good as the clock's synchronisation. Real
/// time also on simulated time (see `docs/time.md`).
pub fn unix_now_ns() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

/// Sleeps until the robot's clock ([`now_ns`]) reaches `deadline_ns`
/// (absolute), restarting after signals. Returns at once if the deadline
/// has passed. On simulated time it sleeps the scaled wall time and looks
/// again, until the simulator has got there.
pub fn sleep_until_ns(deadline_ns: u64) {
    match crate::simclock::active() {
        None => sleep_until_wall_ns(deadline_ns),
        Some(c) => c.sleep_until(deadline_ns),
    }
}

/// Sleeps toward `deadline_ns` on the robot's clock for at most about
/// `max_wall_ns` of wall time: returns at the deadline, or earlier when a
/// simulator holds the clock short of it (the caller looks at what it
/// watches, and sleeps again). `now_ns` is the caller's last [`now_ns`]: on
/// the wall clock this sleeps to the nearer of the deadline and `now_ns +
/// max_wall_ns`, reading no clock.
pub fn sleep_toward_ns(deadline_ns: u64, now_ns: u64, max_wall_ns: u64) {
    match crate::simclock::active() {
        None => sleep_until_wall_ns(deadline_ns.min(now_ns.saturating_add(max_wall_ns))),
        Some(c) => c.sleep_until_within(deadline_ns, max_wall_ns),
    }
}

/// Sleeps until CLOCK_MONOTONIC reaches `deadline_ns` (absolute),
/// restarting after signals.
pub fn sleep_until_wall_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; the remainder pointer may be null with TIMER_ABSTIME.
        let rc =
            unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) };
        if rc != libc::EINTR {
            return;
        }
    }
}

/// Formats a duration the way users write periods: `10ms`, `1.5s`, `250us`.
pub fn format_duration(d: Duration) -> String {
    let ns = d.as_nanos();
    if ns.is_multiple_of(1_000_000_000) {
        format!("{}s", ns / 1_000_000_000)
    } else if ns.is_multiple_of(1_000_000) {
        format!("{}ms", ns / 1_000_000)
    } else if ns.is_multiple_of(1_000) {
        format!("{}us", ns / 1_000)
    } else {
        format!("{ns}ns")
    }
}

/// The longest duration nerve takes anywhere (periods, back-offs, windows,
/// leases): one day. Longer values are typos or attacks, and their
/// nanoseconds would come close to overflowing deadline arithmetic.
pub const MAX_DURATION: Duration = Duration::from_secs(86_400);

/// Nanoseconds of `d`, saturating at `u64::MAX` (never wrapping).
pub fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// Seconds given on a command line (`--grace 2`, `--timeout 0.5`): finite,
/// not negative, at most [`MAX_DURATION`]; a clap value parser.
pub fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if !v.is_finite() || v < 0.0 {
        return Err(format!("{s:?}: give a number of seconds from 0 to {}", MAX_DURATION.as_secs()));
    }
    if v > MAX_DURATION.as_secs_f64() {
        return Err(format!("{s:?} is longer than nerve accepts ({} s, one day)", MAX_DURATION.as_secs()));
    }
    Ok(v)
}

/// Parses a period such as `10ms`, `1s`, `250us`, `100hz`, `2.5ms` or a bare
/// number of milliseconds; from 10 µs to [`MAX_DURATION`].
pub fn parse_duration(s: &str) -> Result<Duration, String> {
    let t = s.trim().to_ascii_lowercase();
    let split = t.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let value: f64 =
        num.parse().map_err(|_| format!("{s:?} is not a duration; write e.g. 10ms, 1s, 250us or 100hz"))?;
    if !(value.is_finite() && value > 0.0) {
        return Err(format!("{s:?}: a period must be greater than zero"));
    }
    let secs = match unit {
        "" | "ms" => value / 1e3,
        "s" => value,
        "us" | "µs" => value / 1e6,
        "ns" => value / 1e9,
        "hz" => 1.0 / value,
        "min" => value * 60.0,
        _ => return Err(format!("{s:?}: unknown unit {unit:?}; use ns, us, ms, s, min or hz")),
    };
    let d = Duration::try_from_secs_f64(secs)
        .ok()
        .filter(|d| *d <= MAX_DURATION)
        .ok_or_else(|| format!("{s:?} is longer than the longest duration nerve accepts (1 day); check the unit"))?;
    if d < Duration::from_micros(10) {
        return Err(format!("{s:?} is shorter than the shortest period nerve runs (10us)"));
    }
    Ok(d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_durations_are_refused_not_wrapped() {
        for bad in ["18446744074s", "18446744073s", "99999999999999999999ms", "2days", "1e400s", "inf", "nan"] {
            assert!(parse_duration(bad).is_err(), "{bad} was accepted");
        }
        assert_eq!(parse_duration("86400s"), Ok(MAX_DURATION));
        assert!(parse_duration("86401s").expect_err("too long").contains("1 day"));
        assert_eq!(nanos(Duration::MAX), u64::MAX);
        for bad in ["inf", "-1", "nan", "1e9", "x"] {
            assert!(parse_seconds(bad).is_err(), "{bad} was accepted");
        }
        assert_eq!(parse_seconds("2.5"), Ok(2.5));
    }

    #[test]
    fn parses_periods() {
        assert_eq!(parse_duration("10ms"), Ok(Duration::from_millis(10)));
        assert_eq!(parse_duration("1s"), Ok(Duration::from_secs(1)));
        assert_eq!(parse_duration("100hz"), Ok(Duration::from_millis(10)));
        assert_eq!(parse_duration("250us"), Ok(Duration::from_micros(250)));
        assert_eq!(parse_duration("5"), Ok(Duration::from_millis(5)));
        assert!(parse_duration("0ms").is_err());
        assert!(parse_duration("fast").is_err());
        assert!(parse_duration("3parsecs").is_err());
        assert!(parse_duration("1ns").is_err());
        assert_eq!(format_duration(Duration::from_millis(10)), "10ms");
    }

    #[test]
    fn sleeps_to_absolute_deadline() {
        let start = now_ns();
        sleep_until_ns(start + 2_000_000);
        assert!(now_ns() >= start + 2_000_000);
        // a past deadline returns at once
        sleep_until_ns(start);
    }
}
