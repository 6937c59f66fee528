//! The router's event log: what happened in the graph (agents registered,
//! left, died; edges made and removed), numbered from 1, the last
//! [`EVENTS_KEPT`] kept. Tools that react to the graph (the black box fires
//! on an agent's death) ask for the events after the last one they saw
//! (`CliRequest::Events`) instead of comparing `ps` listings, which cannot
//! tell a death from a clean stop.

use shm_schemas::control::cli_to_router::{EVENTS_KEPT, EventKind, RouterEvent};
use std::collections::VecDeque;

/// The last [`EVENTS_KEPT`] events.
#[derive(Debug)]
pub struct EventLog {
    next: u64,
    kept: VecDeque<RouterEvent>,
}

impl Default for EventLog {
    fn default() -> Self {
        EventLog { next: 1, kept: VecDeque::with_capacity(EVENTS_KEPT) }
    }
}

impl EventLog {
    /// Records an event, stamped now.
    pub fn push(&mut self, what: EventKind) {
        if self.kept.len() == EVENTS_KEPT {
            self.kept.pop_front();
        }
        self.kept.push_back(RouterEvent { seq: self.next, unix_ns: agent_sdk::clock::unix_now_ns(), what });
        self.next = self.next.saturating_add(1);
    }

    /// The sequence number the next event will get.
    pub fn next(&self) -> u64 {
        self.next
    }

    /// The kept events after `after`, oldest first.
    pub fn after(&self, after: u64) -> Vec<RouterEvent> {
        self.kept.iter().filter(|e| e.seq > after).cloned().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn died(n: u32) -> EventKind {
        EventKind::Died { agent: format!("a{n}"), pid: n }
    }

    #[test]
    fn events_are_numbered_and_the_oldest_forgotten() {
        let mut log = EventLog::default();
        assert!(log.after(0).is_empty());
        for n in 0..(EVENTS_KEPT as u32 + 10) {
            log.push(died(n));
        }
        assert_eq!(log.next(), EVENTS_KEPT as u64 + 11);
        let all = log.after(0);
        assert_eq!(all.len(), EVENTS_KEPT);
        assert_eq!(all[0].seq, 11, "the ten oldest are gone");
        assert_eq!(all[0].what, died(10));
        let tail = log.after(EVENTS_KEPT as u64 + 8);
        assert_eq!(tail.iter().map(|e| e.seq).collect::<Vec<_>>(), [EVENTS_KEPT as u64 + 9, EVENTS_KEPT as u64 + 10]);
        assert!(log.after(u64::MAX).is_empty());
    }
}
