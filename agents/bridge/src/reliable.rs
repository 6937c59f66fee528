//! Delivery of reliable topics across a link that may be cut: the sender's
//! [`Outbox`] and the receiver's [`Inbox`]. Pure bookkeeping, no I/O, so
//! that every case (a cut, an overflow, a restart on either side) is a unit
//! test.
//!
//! The sender numbers each message of a topic (1, 2, ...) and keeps it in a
//! bounded queue until every importer it has ever seen has acknowledged it.
//! Importers are known by name (`ROBOT.BRIDGE`) and remembered across a cut,
//! so what is sent while the link is down stays queued and goes out when the
//! importer is back. A full queue drops its oldest message and counts it as
//! lost; the receiver learns of it from the `oldest` field of later frames
//! and counts it too. Nothing is lost without a count and a log line.
//!
//! The receiver delivers in order: a frame after a gap that the sender still
//! holds is held back (it will be retransmitted), a frame before the next
//! expected one is a duplicate. A sender that restarts starts a new
//! `instance`; the receiver then starts again from that run's oldest frame.
//!
//! An importer is known once it has been seen alive (its liveliness token):
//! acknowledgements from an importer never seen are ignored, at most
//! [`MAX_IMPORTERS`] are known at once, and one gone for longer than the
//! bridge's `importer_ttl` is forgotten ([`Outbox::forget_gone`]), so that a
//! robot decommissioned or renamed does not pin the queue for ever.

use std::collections::{BTreeMap, VecDeque};

/// A queued message of a reliable topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Queued {
    /// sequence number, from 1
    pub seq: u64,
    /// CLOCK_REALTIME ns when the sample was taken
    pub stamp_unix_ns: u64,
    /// the local sender and its sequence number
    pub sender: String,
    /// sequence number on the local port
    pub origin_seq: u64,
    /// the payload
    pub payload: Vec<u8>,
}

/// Most importers one reliable topic keeps track of; more are refused
/// (until some are forgotten).
pub const MAX_IMPORTERS: usize = 64;

#[derive(Debug, Clone)]
struct Importer {
    acked: u64,
    alive: bool,
    /// when it last made progress or was last sent what it lacks (ns);
    /// `None`: it is owed everything after `acked` at once
    last_tx_ns: Option<u64>,
    /// when it was last seen going away (ns), while it is gone
    gone_since_ns: Option<u64>,
}

impl Importer {
    fn new() -> Self {
        Importer { acked: 0, alive: true, last_tx_ns: None, gone_since_ns: None }
    }
}

/// What [`Outbox::set_importer`] and [`Outbox::ack`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seen {
    /// Taken into account.
    Taken,
    /// An importer never seen alive: ignored.
    Unknown,
    /// A new importer while [`MAX_IMPORTERS`] are known: refused.
    Full,
}

/// The sender side of one reliable topic.
#[derive(Debug)]
pub struct Outbox {
    cap: usize,
    next_seq: u64,
    queue: VecDeque<Queued>,
    /// highest sequence number sent at least once
    sent_upto: u64,
    importers: BTreeMap<String, Importer>,
    lost: u64,
    retransmitted: u64,
}

/// What [`Outbox::push`] had to drop to make room.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Overflow {
    /// the sequence number dropped
    pub seq: u64,
}

impl Outbox {
    /// An outbox that keeps at most `cap` (≥ 1) messages.
    pub fn new(cap: usize) -> Self {
        Outbox {
            cap: cap.max(1),
            next_seq: 1,
            queue: VecDeque::new(),
            sent_upto: 0,
            importers: BTreeMap::new(),
            lost: 0,
            retransmitted: 0,
        }
    }

    /// Queues a message; returns its sequence number and what was dropped
    /// to make room, if anything.
    pub fn push(
        &mut self,
        stamp_unix_ns: u64,
        sender: &str,
        origin_seq: u64,
        payload: Vec<u8>,
    ) -> (u64, Option<Overflow>) {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.saturating_add(1);
        let mut overflow = None;
        if self.queue.len() >= self.cap
            && let Some(old) = self.queue.pop_front()
        {
            self.lost = self.lost.saturating_add(1);
            overflow = Some(Overflow { seq: old.seq });
        }
        self.queue.push_back(Queued { seq, stamp_unix_ns, sender: sender.into(), origin_seq, payload });
        (seq, overflow)
    }

    /// The oldest sequence number still held (the next one when empty).
    pub fn oldest(&self) -> u64 {
        self.queue.front().map_or(self.next_seq, |q| q.seq)
    }

    /// The sequence number of the newest message queued (0 before the first).
    pub fn last_seq(&self) -> u64 {
        self.next_seq.saturating_sub(1)
    }

    /// Messages queued now.
    pub fn depth(&self) -> usize {
        self.queue.len()
    }

    /// Messages dropped because the queue was full.
    pub fn lost(&self) -> u64 {
        self.lost
    }

    /// Messages sent again after a cut or a missing acknowledgement.
    pub fn retransmitted(&self) -> u64 {
        self.retransmitted
    }

    /// Importers known (ever seen) and alive now.
    pub fn importers(&self) -> (usize, usize) {
        (self.importers.len(), self.importers.values().filter(|i| i.alive).count())
    }

    /// An importer appeared (`alive`) or went away (at `now_ns`); one that
    /// comes back is owed what it has not acknowledged at the next
    /// [`Outbox::due`]. One never seen alive that goes away is ignored; a
    /// new one beyond [`MAX_IMPORTERS`] is refused.
    pub fn set_importer(&mut self, who: &str, alive: bool, now_ns: u64) -> Seen {
        let known = self.importers.len();
        let Some(imp) = self.importers.get_mut(who) else {
            if !alive {
                return Seen::Unknown;
            }
            if known >= MAX_IMPORTERS {
                return Seen::Full;
            }
            self.importers.insert(who.into(), Importer::new());
            return Seen::Taken;
        };
        if alive && !imp.alive {
            imp.last_tx_ns = None;
        }
        imp.alive = alive;
        imp.gone_since_ns = if alive { None } else { imp.gone_since_ns.or(Some(now_ns)) };
        Seen::Taken
    }

    /// `who` has delivered everything up to `acked` (at `now_ns`). Only an
    /// importer seen alive (and not forgotten) is heard. An acknowledgement
    /// also proves that `who` is reachable: one that was taken for gone (its
    /// liveliness token lost, or its return not yet seen) is alive again
    /// and owed what it lacks.
    pub fn ack(&mut self, who: &str, acked: u64, now_ns: u64) -> Seen {
        let acked = acked.min(self.sent_upto);
        let Some(imp) = self.importers.get_mut(who) else { return Seen::Unknown };
        if !imp.alive {
            imp.alive = true;
            imp.gone_since_ns = None;
            imp.last_tx_ns = None;
        }
        if acked > imp.acked {
            imp.acked = acked;
            imp.last_tx_ns = Some(now_ns);
        }
        self.trim();
        Seen::Taken
    }

    /// Forgets the importers gone for at least `ttl_ns` at `now_ns`, and
    /// returns their names (each is returned once).
    pub fn forget_gone(&mut self, now_ns: u64, ttl_ns: u64) -> Vec<String> {
        let gone: Vec<String> = self
            .importers
            .iter()
            .filter(|(_, i)| i.gone_since_ns.is_some_and(|t| now_ns.saturating_sub(t) >= ttl_ns))
            .map(|(k, _)| k.clone())
            .collect();
        for k in &gone {
            self.importers.remove(k);
        }
        if !gone.is_empty() {
            self.trim();
        }
        gone
    }

    /// Drops what every known importer has acknowledged. With no importer
    /// known yet, everything stays (up to the cap): nobody has it.
    fn trim(&mut self) {
        let Some(min) = self.importers.values().map(|i| i.acked).min() else { return };
        while self.queue.front().is_some_and(|q| q.seq <= min) {
            self.queue.pop_front();
        }
    }

    /// What to send now, in order and each message once: for an alive
    /// importer that is owed messages and made no progress within `rto_ns`,
    /// everything after its acknowledgement again; then messages never sent,
    /// at most `budget` of them (the rate limit).
    pub fn due(&mut self, now_ns: u64, rto_ns: u64, budget: usize) -> Vec<&Queued> {
        let first_new = self.sent_upto + 1;
        let mut from = first_new;
        for imp in self.importers.values_mut() {
            let waited = imp.last_tx_ns.is_none_or(|t| now_ns.saturating_sub(t) >= rto_ns);
            if imp.alive && imp.acked < self.sent_upto && waited {
                from = from.min(imp.acked + 1);
                imp.last_tx_ns = Some(now_ns);
            }
        }
        let mut n_new = 0usize;
        let mut upto = self.sent_upto;
        let mut out = Vec::new();
        for q in self.queue.iter().filter(|q| q.seq >= from) {
            if q.seq >= first_new {
                if n_new >= budget {
                    break;
                }
                n_new += 1;
                upto = q.seq;
            } else {
                self.retransmitted = self.retransmitted.saturating_add(1);
            }
            out.push(q);
        }
        if upto > self.sent_upto {
            self.sent_upto = upto;
            for imp in self.importers.values_mut().filter(|i| i.alive && i.last_tx_ns.is_none()) {
                imp.last_tx_ns = Some(now_ns);
            }
        }
        out
    }
}

/// What the receiver does with a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Deliver it now.
    Deliver,
    /// Seen already (a retransmission): drop it, acknowledge again.
    Duplicate,
    /// A gap the sender can still fill: drop it and wait.
    Early,
}

/// What [`Inbox::accept`] found: the verdict, and how many messages are
/// now known lost for good (the sender's queue overflowed), counted the
/// moment the loss is known, whether or not this frame is delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Judged {
    /// what to do with the frame
    pub verdict: Verdict,
    /// messages found lost by this frame
    pub lost: u64,
}

/// The receiver side of one reliable topic.
#[derive(Debug, Default)]
pub struct Inbox {
    instance: Option<u64>,
    next: u64,
}

impl Inbox {
    /// Judges a frame of run `instance` with sequence number `seq`, sent
    /// while the sender held `oldest..`.
    pub fn accept(&mut self, instance: u64, seq: u64, oldest: u64) -> Judged {
        if self.instance != Some(instance) {
            // a new sender (or a restarted one): start from what it holds
            self.instance = Some(instance);
            self.next = oldest.max(1);
        }
        let mut lost = 0;
        if oldest > self.next {
            lost = oldest - self.next;
            self.next = oldest;
        }
        let verdict = if seq < self.next {
            Verdict::Duplicate
        } else if seq > self.next {
            Verdict::Early
        } else {
            self.next = seq.saturating_add(1);
            Verdict::Deliver
        };
        Judged { verdict, lost }
    }

    /// The highest sequence number delivered in order, or known lost (what
    /// to acknowledge).
    pub fn acked(&self) -> u64 {
        self.next.saturating_sub(1)
    }

    /// The sender's run this inbox follows.
    pub fn instance(&self) -> Option<u64> {
        self.instance
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RTO: u64 = 100;

    fn seqs(v: Vec<&Queued>) -> Vec<u64> {
        v.into_iter().map(|q| q.seq).collect()
    }

    fn push(o: &mut Outbox, n: usize) {
        for _ in 0..n {
            o.push(0, "t1", 0, vec![1]);
        }
    }

    #[test]
    fn a_message_stays_until_every_importer_acknowledged_it() {
        let mut o = Outbox::new(10);
        push(&mut o, 3);
        assert_eq!(seqs(o.due(0, RTO, usize::MAX)), vec![1, 2, 3], "sent while nobody listens");
        o.set_importer("r2.bridge", true, 0);
        o.set_importer("r3.bridge", true, 0);
        assert_eq!(seqs(o.due(1, RTO, usize::MAX)), vec![1, 2, 3], "a new importer gets what it missed");
        o.ack("r2.bridge", 3, 2);
        assert_eq!(o.depth(), 3, "r3 has not acknowledged");
        o.ack("r3.bridge", 2, 2);
        assert_eq!((o.depth(), o.oldest()), (1, 3));
        o.ack("r3.bridge", 3, 2);
        assert_eq!((o.depth(), o.oldest()), (0, 4));
    }

    #[test]
    fn a_cut_keeps_messages_and_the_return_delivers_them_in_order() {
        let mut o = Outbox::new(10);
        o.set_importer("r2.bridge", true, 0);
        push(&mut o, 2);
        assert_eq!(seqs(o.due(0, RTO, usize::MAX)), vec![1, 2]);
        o.ack("r2.bridge", 2, 1);
        o.set_importer("r2.bridge", false, 0); // the link is cut
        push(&mut o, 3);
        assert_eq!(seqs(o.due(10, RTO, usize::MAX)), vec![3, 4, 5], "first try, into the void");
        assert!(o.due(500, RTO, usize::MAX).is_empty(), "no retransmission to a dead importer");
        o.set_importer("r2.bridge", true, 0); // back
        assert_eq!(seqs(o.due(600, RTO, usize::MAX)), vec![3, 4, 5]);
        assert_eq!(o.retransmitted(), 3);
        assert!(o.due(650, RTO, usize::MAX).is_empty(), "not again before the timeout");
        o.ack("r2.bridge", 5, 700);
        assert!(o.due(900, RTO, usize::MAX).is_empty() && o.depth() == 0);

        let mut i = Inbox::default();
        for s in 1..=2 {
            assert_eq!(i.accept(1, s, 1), Judged { verdict: Verdict::Deliver, lost: 0 });
        }
        for s in 3..=5 {
            assert_eq!(i.accept(1, s, 3), Judged { verdict: Verdict::Deliver, lost: 0 });
        }
        assert_eq!(i.acked(), 5);
    }

    #[test]
    fn an_overflow_is_counted_on_both_sides() {
        let mut o = Outbox::new(3);
        o.set_importer("r2.bridge", false, 0);
        let mut dropped = Vec::new();
        for _ in 0..5 {
            if let (_, Some(ov)) = o.push(0, "t1", 0, vec![]) {
                dropped.push(ov.seq);
            }
        }
        assert_eq!((dropped, o.lost(), o.oldest()), (vec![1, 2], 2, 3));
        let mut i = Inbox::default();
        assert_eq!(i.accept(9, 1, 1), Judged { verdict: Verdict::Deliver, lost: 0 }, "it had got 1 before the cut");
        assert_eq!(i.accept(9, 3, 3), Judged { verdict: Verdict::Deliver, lost: 1 }, "2 is gone for good");
        assert_eq!(i.accept(9, 4, 3), Judged { verdict: Verdict::Deliver, lost: 0 });
    }

    #[test]
    fn the_receiver_keeps_order_and_drops_duplicates() {
        let mut i = Inbox::default();
        assert_eq!(i.accept(1, 1, 1), Judged { verdict: Verdict::Deliver, lost: 0 });
        assert_eq!(i.accept(1, 3, 1), Judged { verdict: Verdict::Early, lost: 0 }, "2 is missing but still held");
        assert_eq!(i.accept(1, 2, 1), Judged { verdict: Verdict::Deliver, lost: 0 });
        assert_eq!(i.accept(1, 2, 1), Judged { verdict: Verdict::Duplicate, lost: 0 });
        assert_eq!(i.accept(1, 3, 1), Judged { verdict: Verdict::Deliver, lost: 0 });
        assert_eq!(
            i.accept(1, 6, 5),
            Judged { verdict: Verdict::Early, lost: 1 },
            "4 is lost (counted now, even though 6 waits), 5 still to come"
        );
        assert_eq!(i.acked(), 4, "the loss of 4 is recorded, 5 is expected");
        assert_eq!(i.accept(1, 5, 5), Judged { verdict: Verdict::Deliver, lost: 0 }, "the loss is counted once");
        assert_eq!(i.accept(1, 6, 5), Judged { verdict: Verdict::Deliver, lost: 0 });
    }

    #[test]
    fn a_restarted_sender_starts_a_new_run() {
        let mut i = Inbox::default();
        for s in 1..=4 {
            i.accept(1, s, 1);
        }
        assert_eq!(i.accept(2, 1, 1), Judged { verdict: Verdict::Deliver, lost: 0 }, "new instance, from its start");
        assert_eq!(i.instance(), Some(2));
        assert_eq!(i.acked(), 1);
    }

    #[test]
    fn an_acknowledgement_revives_an_importer_taken_for_gone() {
        let mut o = Outbox::new(5);
        o.set_importer("r2.bridge", true, 0);
        o.push(0, "t1", 0, vec![]);
        assert_eq!(seqs(o.due(0, RTO, usize::MAX)), vec![1]);
        o.set_importer("r2.bridge", false, 0); // its token went with the cut...
        o.push(0, "t1", 0, vec![]);
        assert_eq!(seqs(o.due(10, RTO, usize::MAX)), vec![2]);
        // ...and its return was never seen, but it acknowledges what it got
        o.ack("r2.bridge", 0, 20);
        assert_eq!(o.importers(), (1, 1), "alive again");
        assert_eq!(seqs(o.due(30, RTO, usize::MAX)), vec![1, 2], "owed everything it lacks, at once");
    }

    #[test]
    fn an_importer_gone_past_its_ttl_is_forgotten_and_frees_the_queue() {
        let mut o = Outbox::new(10);
        o.set_importer("r2.bridge", true, 0);
        o.set_importer("r3.bridge", true, 0);
        push(&mut o, 3);
        assert_eq!(seqs(o.due(0, RTO, usize::MAX)), vec![1, 2, 3]);
        o.ack("r2.bridge", 3, 1);
        o.set_importer("r3.bridge", false, 1_000); // decommissioned
        assert_eq!(o.depth(), 3, "r3 may come back: its messages stay");
        assert!(o.forget_gone(1_000 + 499, 500).is_empty(), "not before the ttl");
        assert_eq!(o.forget_gone(1_000 + 500, 500), vec!["r3.bridge".to_string()]);
        assert_eq!((o.depth(), o.importers()), (0, (1, 1)), "nothing is held for it any more");
        assert!(o.forget_gone(10_000, 500).is_empty(), "forgotten once");
        assert_eq!(o.ack("r3.bridge", 3, 10_001), Seen::Unknown, "a forgotten importer's acknowledgement is ignored");
        // it comes back later: a new importer again, owed what is still held
        assert_eq!(o.set_importer("r3.bridge", true, 20_000), Seen::Taken);
        assert_eq!(o.importers(), (2, 2));
    }

    #[test]
    fn a_return_before_the_ttl_keeps_the_importer() {
        let mut o = Outbox::new(10);
        o.set_importer("r2.bridge", true, 0);
        o.set_importer("r2.bridge", false, 100);
        o.set_importer("r2.bridge", true, 200);
        assert!(o.forget_gone(10_000, 500).is_empty(), "alive again: never forgotten");
        o.set_importer("r2.bridge", false, 20_000);
        assert!(o.forget_gone(20_400, 500).is_empty(), "gone counts from the last departure");
    }

    #[test]
    fn acks_count_only_from_importers_seen_alive_and_the_map_is_capped() {
        let mut o = Outbox::new(10);
        push(&mut o, 2);
        assert_eq!(seqs(o.due(0, RTO, usize::MAX)), vec![1, 2]);
        assert_eq!(o.ack("forged.bridge", 2, 1), Seen::Unknown);
        assert_eq!((o.depth(), o.importers()), (2, (0, 0)), "an unknown importer trims nothing and is not kept");
        assert_eq!(o.set_importer("never.seen", false, 1), Seen::Unknown, "a departure of nobody is ignored");
        for n in 0..MAX_IMPORTERS {
            assert_eq!(o.set_importer(&format!("r{n}.bridge"), true, 2), Seen::Taken);
        }
        assert_eq!(o.set_importer("one.more", true, 3), Seen::Full);
        assert_eq!(o.importers().0, MAX_IMPORTERS);
        assert_eq!(o.set_importer("r0.bridge", true, 4), Seen::Taken, "a known one is still heard");
        o.set_importer("r0.bridge", false, 5);
        assert_eq!(o.forget_gone(1_000, 10), vec!["r0.bridge".to_string()]);
        assert_eq!(o.set_importer("one.more", true, 1_001), Seen::Taken, "room again once one is forgotten");
    }

    #[test]
    fn the_budget_paces_new_messages_but_not_retransmissions() {
        let mut o = Outbox::new(100);
        o.set_importer("a", true, 0);
        push(&mut o, 5);
        assert_eq!(seqs(o.due(0, RTO, 2)), vec![1, 2]);
        assert_eq!(seqs(o.due(200, RTO, 1)), vec![1, 2, 3], "1 and 2 unacknowledged: again, plus one new");
        o.ack("a", 3, 205);
        assert_eq!(seqs(o.due(210, RTO, 10)), vec![4, 5]);
    }
}
