//! Refused commands counted per sender, for the log: the first refusal of a
//! sender and then every power of two are logged, so that a sender that
//! keeps sending impractical commands does not flood the log.
//!
//! Bounded: a sender not refused for [`FORGET_AFTER`] is forgotten (its next
//! refusal is logged as a first one again), and at most [`MAX_SENDERS`]
//! senders are counted; a new one beyond replaces the one refused longest
//! ago. Before, every distinct sender name ever refused stayed in the map.

use std::collections::BTreeMap;
use std::time::Duration;

/// The most senders counted at once.
pub const MAX_SENDERS: usize = 64;
/// How long a sender's count is kept after its last refusal.
pub const FORGET_AFTER: Duration = Duration::from_secs(60);

/// Refusals per sender: (count, time of the last refusal in ns).
#[derive(Debug, Clone, Default)]
pub struct Refusals {
    by_sender: BTreeMap<String, (u64, u64)>,
}

impl Refusals {
    /// Counts a refusal of `sender` at `now_ns`; returns its count so far.
    pub fn record(&mut self, sender: &str, now_ns: u64) -> u64 {
        let keep = agent_sdk::clock::nanos(FORGET_AFTER);
        self.by_sender.retain(|_, (_, t)| now_ns.saturating_sub(*t) <= keep);
        if !self.by_sender.contains_key(sender)
            && self.by_sender.len() >= MAX_SENDERS
            && let Some(oldest) = self.by_sender.iter().min_by_key(|(_, (_, t))| *t).map(|(n, _)| n.clone())
        {
            self.by_sender.remove(&oldest);
        }
        let e = self.by_sender.entry(sender.to_owned()).or_insert((0, now_ns));
        e.0 += 1;
        e.1 = now_ns;
        e.0
    }

    /// How many senders are counted.
    pub fn senders(&self) -> usize {
        self.by_sender.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn senders_are_capped_and_forgotten_when_quiet() {
        let mut r = Refusals::default();
        assert_eq!(r.record("a", 0), 1);
        assert_eq!(r.record("a", 1), 2);
        for i in 0..1000u64 {
            r.record(&format!("s{i}"), 10 + i);
        }
        assert_eq!(r.senders(), MAX_SENDERS, "distinct names do not grow the map without end");
        // a minute of quiet: everyone is forgotten, a new refusal counts from 1
        let later = 2_000 + agent_sdk::clock::nanos(FORGET_AFTER);
        assert_eq!(r.record("a", later), 1);
        assert_eq!(r.senders(), 1);
    }
}
