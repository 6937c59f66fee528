//! What an input counts of each of its sources ([`Tally`]): samples
//! received, samples lost (gaps in the sender's sequence numbers, [`gap`]),
//! the rate and the age of the last one, as `nerve ps` shows them.

use crate::meters::RateMeter;
use shm_schemas::SampleHeader;
use shm_schemas::stats::InputStats;

/// What an input counts about one source.
#[derive(Default)]
pub(crate) struct Tally {
    received: u64,
    dropped: u64,
    last_seq: u64,
    last_ns: Option<u64>,
    rate: RateMeter,
}

/// Samples lost between `last_seq` and `seq` on one sender's port. A sender
/// is another process: its numbers are not trusted, so nothing here can
/// overflow, and a number going backwards (a restarted sender) loses nothing.
pub(crate) fn gap(last_seq: u64, seq: u64) -> u64 {
    if last_seq == 0 { 0 } else { seq.saturating_sub(last_seq.saturating_add(1)) }
}

impl Tally {
    /// The sequence number of the last sample handed out, if any was.
    pub(crate) fn last_delivered(&self) -> Option<u64> {
        (self.received > 0).then_some(self.last_seq)
    }

    pub(crate) fn account(&mut self, h: &SampleHeader, now: u64) {
        self.received = self.received.saturating_add(1);
        self.dropped = self.dropped.saturating_add(gap(self.last_seq, h.seq));
        self.last_seq = h.seq;
        self.last_ns = Some(now);
        self.rate.record(now);
    }

    /// What `nerve ps` shows of input `input`'s source `from_agent/from_port`.
    pub(crate) fn stats(&self, input: &str, from_agent: &str, from_port: &str, now: u64) -> InputStats {
        InputStats {
            input: input.into(),
            from_agent: from_agent.into(),
            from_port: from_port.into(),
            received: self.received,
            rate_hz: self.rate.rate(now),
            last_age_ns: self.last_ns.map(|t| now.saturating_sub(t)),
            dropped: self.dropped,
        }
    }
}
