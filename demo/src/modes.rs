//! The decision maker's mode changes, read from its log.
//!
//! nerve's log lines start with the UTC time of day and the agent's name:
//! `20:41:07.312  INFO [decision] ...`. A mode change is a line that says
//! one of (case-insensitive, quotes optional):
//!
//! * `mode A -> B` / `mode change: A -> B` / `mode A → B` (the decision agent's form)
//! * `mode changed from A to B`
//! * a tracing field `mode=B` (with `from=A` when present)
//!
//! Times of day become simulated seconds through a [`ClockMap`], which the
//! demo measures while it follows the ground truth.

use crate::analysis::ModeChange;

/// Maps the logs' time of day (UTC seconds since midnight) to simulated time.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ClockMap {
    /// Time of day, s, at which simulated time was 0. `None` until measured.
    pub sim_zero_s_of_day: Option<f64>,
}

/// Seconds since midnight UTC, now.
pub fn now_s_of_day() -> f64 {
    let d = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    (d.as_secs() % 86_400) as f64 + f64::from(d.subsec_micros()) * 1e-6
}

impl ClockMap {
    /// Feeds an observation: at time of day `now`, the newest simulated time
    /// read from the truth log was `sim_t`. The log is written before it is
    /// read, so `now − sim_t` is an upper bound of the true offset; the
    /// smallest bound seen is kept.
    pub fn observe(&mut self, now: f64, sim_t: f64) {
        let off = now - sim_t;
        self.sim_zero_s_of_day = Some(match self.sim_zero_s_of_day {
            None => off,
            Some(o) => {
                let d = day_diff(off, o);
                if d < 0.0 { off } else { o }
            }
        });
    }

    /// Simulated time of a time of day.
    pub fn sim_time(&self, s_of_day: f64) -> Option<f64> {
        self.sim_zero_s_of_day.map(|z| day_diff(s_of_day, z))
    }
}

/// `a − b` for times of day, across midnight.
fn day_diff(a: f64, b: f64) -> f64 {
    let mut d = a - b;
    if d < -43_200.0 {
        d += 86_400.0;
    } else if d > 43_200.0 {
        d -= 86_400.0;
    }
    d
}

/// Parses the leading `HH:MM:SS.mmm` of a log line into seconds of day.
pub fn line_clock(line: &str) -> Option<(f64, &str)> {
    let stamp = line.split_whitespace().next()?;
    let mut it = stamp.split(':');
    let h: f64 = it.next()?.parse().ok()?;
    let m: f64 = it.next()?.parse().ok()?;
    let s: f64 = it.next()?.parse().ok()?;
    if it.next().is_some() || !(0.0..24.0).contains(&h) || !(0.0..60.0).contains(&m) || !(0.0..61.0).contains(&s) {
        return None;
    }
    Some((h * 3600.0 + m * 60.0 + s, stamp))
}

fn clean(word: &str) -> String {
    word.trim_matches(|c: char| !(c.is_alphanumeric() || c == '-' || c == '_')).to_owned()
}

fn field(text: &str, key: &str) -> Option<String> {
    text.split_whitespace().find_map(|w| {
        let (k, v) = w.split_once('=')?;
        (k.eq_ignore_ascii_case(key)).then(|| clean(v)).filter(|v| !v.is_empty())
    })
}

/// The (from, to) of a mode change in the message part of a line.
pub fn parse_change(msg: &str) -> Option<(Option<String>, String)> {
    let lower = msg.to_lowercase();
    let words: Vec<&str> = lower.split_whitespace().collect();
    if let Some(i) = words.iter().position(|w| w.trim_end_matches(':') == "mode") {
        let rest = &words[i + 1..];
        // mode A -> B, mode change: A -> B
        if let Some(k) = rest.iter().take(4).position(|w| *w == "->" || *w == "→") {
            if k >= 1 && k + 1 < rest.len() {
                return Some((Some(clean(rest[k - 1])), clean(rest[k + 1])));
            }
        }
        // mode changed from A to B
        if rest.len() >= 5 && rest[0] == "changed" && rest[1] == "from" && rest[3] == "to" {
            return Some((Some(clean(rest[2])), clean(rest[4])));
        }
    }
    let to = field(&lower, "mode")?;
    Some((field(&lower, "from"), to))
}

/// Every mode change in a decision maker's log, with simulated times from `clock`.
pub fn parse_log(text: &str, clock: &ClockMap) -> Vec<ModeChange> {
    let mut out: Vec<ModeChange> = Vec::new();
    for line in text.lines() {
        let Some((s, stamp)) = line_clock(line) else { continue };
        let msg = line.split_once(']').map_or(line, |(_, m)| m);
        let Some((from, mode)) = parse_change(msg) else { continue };
        if mode.is_empty() || out.last().is_some_and(|l| l.mode == mode) {
            continue;
        }
        out.push(ModeChange { t_s: clock.sim_time(s), clock: stamp.to_owned(), mode, from, line: line.to_owned() });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recognises_the_usual_phrasings() {
        assert_eq!(parse_change(" mode wander -> track (red area 800)"), Some((Some("wander".into()), "track".into())));
        assert_eq!(parse_change("Mode: avoid → wall-follow"), Some((Some("avoid".into()), "wall-follow".into())));
        assert_eq!(
            parse_change("mode change: explore -> track (target seen, danger low, load normal)"),
            Some((Some("explore".into()), "track".into()))
        );
        assert_eq!(parse_change("mode changed from a to b"), Some((Some("a".into()), "b".into())));
        assert_eq!(
            parse_change("switching mode=\"track\" from=avoid danger=0.2"),
            Some((Some("avoid".into()), "track".into()))
        );
        assert_eq!(parse_change("started: kind decision"), None);
    }

    #[test]
    fn maps_clock_to_sim_time() {
        let mut c = ClockMap::default();
        c.observe(100.5, 10.0);
        c.observe(101.2, 11.0);
        assert_eq!(c.sim_zero_s_of_day, Some(90.2));
        let log = "00:01:45.200  INFO [decision] mode wall-follow -> track\n\
                   00:01:46.000  INFO [decision] mode=track\n\
                   garbage\n00:01:50.200  INFO [decision] mode track -> avoid\n";
        let m = parse_log(log, &c);
        assert_eq!(m.len(), 2);
        assert!((m[0].t_s.expect("timed") - 15.0).abs() < 1e-6);
        assert_eq!(m[1].mode, "avoid");
        assert_eq!(m[1].from.as_deref(), Some("track"));
    }
}
