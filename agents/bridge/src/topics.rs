//! One topic crossing the bridge, in each direction, with its figures.
//!
//! An [`ExportTopic`] reads a local output port (through the bridge's input
//! `AGENT.PORT`) and sends it to the peers under `nerve/<robot>/<agent>/<port>`:
//! best effort (newest wins, paced by `max_hz`) or reliable (numbered,
//! queued until acknowledged, see [`crate::reliable`]). An [`ImportTopic`]
//! receives a remote port, checks its type, keeps order for a reliable
//! topic, and publishes it on the bridge's output port.

use crate::config::{Export, Import};
use crate::reliable::{Inbox, MAX_IMPORTERS, Outbox, Seen, Verdict};
use crate::types::{ExportTap, ImportSink, TypeInfo};
use crate::wire::{self, Frame};
use std::collections::{BTreeSet, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

/// How long a reliable message waits for its acknowledgement before it is sent again.
pub const RETRANSMIT_AFTER_NS: u64 = 300_000_000;
/// One-way latencies kept for the median figure.
const LATENCY_WINDOW: usize = 256;
/// At most one line per this interval for a repeated warning (with a count).
pub const WARN_EVERY_NS: u64 = 10_000_000_000;

/// A warning that repeats: the first is written at once, later ones at
/// most once per [`WARN_EVERY_NS`], with how many happened meanwhile.
#[derive(Debug, Default)]
pub struct RateLimited {
    last_ns: Option<u64>,
    pending: u64,
}

impl RateLimited {
    /// Counts one event at `now_ns`; returns how many events the line to
    /// write now stands for (0: write nothing now).
    pub fn hit(&mut self, now_ns: u64) -> u64 {
        self.pending = self.pending.saturating_add(1);
        if self.last_ns.is_some_and(|t| now_ns.saturating_sub(t) < WARN_EVERY_NS) {
            return 0;
        }
        self.last_ns = Some(now_ns);
        std::mem::take(&mut self.pending)
    }
}

/// CLOCK_REALTIME in ns: the stamp that crosses machines (one-way latency
/// across hosts is only as good as their clock synchronisation).
pub use agent_sdk::clock::unix_now_ns;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Sends a frame to the peers; implemented by the Zenoh link (and by tests).
pub trait Transmit: Send + Sync {
    /// Puts `bytes` on the topic's key; false when the link refused it.
    fn send(&self, bytes: &[u8]) -> bool;
}

#[derive(Debug, Default)]
struct Counter(AtomicU64);

impl Counter {
    fn add(&self, n: u64) {
        self.0.fetch_add(n, Relaxed);
    }
    fn get(&self) -> u64 {
        self.0.load(Relaxed)
    }
}

struct Pending {
    stamp: u64,
    sender: String,
    origin_seq: u64,
    payload: Vec<u8>,
}

struct ExportState {
    outbox: Option<Outbox>,
    overflow_warn: RateLimited,
    refused_warn: RateLimited,
    too_long_warn: RateLimited,
    pending: Option<Pending>,
    last_sent_ns: u64,
    seq: u64,
    buf: Vec<u8>,
}

/// A local port sent to the peers.
pub struct ExportTopic {
    /// what the configuration says
    pub spec: Export,
    /// the payload's layout
    pub info: TypeInfo,
    /// the Zenoh key: `nerve/<robot>/<agent>/<port>`
    pub key: String,
    instance: u64,
    tap: Box<dyn ExportTap>,
    link: OnceLock<Box<dyn Transmit>>,
    state: Mutex<ExportState>,
    importers: Mutex<BTreeSet<String>>,
    msgs: Counter,
    bytes: Counter,
    dropped: Counter,
    failed: Counter,
    wired: std::sync::atomic::AtomicBool,
    importer_ttl_ns: u64,
}

impl std::fmt::Debug for ExportTopic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ExportTopic").field("key", &self.key).finish()
    }
}

impl ExportTopic {
    /// A topic for `spec`, read through `tap`, in the bridge run `instance`.
    pub fn new(spec: Export, info: TypeInfo, robot: &str, instance: u64, tap: Box<dyn ExportTap>) -> Self {
        let key = format!("nerve/{robot}/{}/{}", spec.agent, spec.port);
        let outbox = spec.reliable.then(|| Outbox::new(spec.queue));
        ExportTopic {
            spec,
            info,
            key,
            instance,
            tap,
            link: OnceLock::new(),
            state: Mutex::new(ExportState {
                outbox,
                overflow_warn: RateLimited::default(),
                refused_warn: RateLimited::default(),
                too_long_warn: RateLimited::default(),
                pending: None,
                last_sent_ns: 0,
                seq: 0,
                buf: Vec::new(),
            }),
            importer_ttl_ns: u64::try_from(crate::config::DEFAULT_IMPORTER_TTL.as_nanos()).unwrap_or(u64::MAX),
            importers: Mutex::new(BTreeSet::new()),
            msgs: Counter::default(),
            bytes: Counter::default(),
            dropped: Counter::default(),
            failed: Counter::default(),
            wired: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// Forgets an importer gone for this long (default
    /// [`crate::config::DEFAULT_IMPORTER_TTL`]).
    pub fn with_importer_ttl(mut self, ttl: std::time::Duration) -> Self {
        self.importer_ttl_ns = u64::try_from(ttl.as_nanos()).unwrap_or(u64::MAX);
        self
    }

    /// Attaches the link once it is up; until then samples are queued
    /// (reliable) or kept as the newest (best effort).
    pub fn attach(&self, link: Box<dyn Transmit>) {
        let _ = self.link.set(link);
    }

    /// Whether the router has wired the local port to the bridge.
    pub fn wired(&self) -> bool {
        self.wired.load(Relaxed)
    }

    /// Records that the router wired the local port to the bridge.
    pub fn set_wired(&self) {
        self.wired.store(true, Relaxed);
    }

    /// Reads every waiting local sample and sends what is due (the task's step).
    pub fn pump(&self, now_mono_ns: u64) -> usize {
        let mut st = lock(&self.state);
        let st = &mut *st;
        let n = self.tap.drain(&mut |sender, origin_seq, payload| {
            if let Err(e) = self.info.check_len(payload.len()) {
                // a sequence longer than this topic carries: never sent (the
                // peer's link would refuse the frame), counted as dropped
                self.dropped.add(1);
                let n = st.too_long_warn.hit(now_mono_ns);
                if n > 0 {
                    tracing::warn!(topic = %self.spec.origin(), sender, origin_seq, dropped = n, "{n} sample(s) not sent: {e}");
                }
                return;
            }
            let stamp = unix_now_ns();
            match st.outbox.as_mut() {
                Some(outbox) => {
                    let (_, overflow) = outbox.push(stamp, sender, origin_seq, payload.to_vec());
                    if let Some(o) = overflow {
                        let lost = st.overflow_warn.hit(now_mono_ns);
                        if lost > 0 {
                            tracing::warn!(
                                topic = %self.spec.origin(),
                                seq = o.seq,
                                lost,
                                queue = self.spec.queue,
                                "reliable queue full: {lost} oldest message(s) lost since the last such line (no peer acknowledged them); raise `queue` or check the link"
                            );
                        }
                    }
                }
                None => {
                    if st.pending.replace(Pending { stamp, sender: sender.into(), origin_seq, payload: payload.to_vec() }).is_some() {
                        // newest wins: the one it replaces was never sent
                        self.dropped.add(1);
                    }
                }
            }
        });
        self.flush_locked(st, now_mono_ns);
        n
    }

    /// Sends what is due now: paced best-effort samples, reliable messages
    /// never sent, and retransmissions (the link thread's tick).
    pub fn flush(&self, now_mono_ns: u64) {
        let mut st = lock(&self.state);
        self.flush_locked(&mut st, now_mono_ns);
    }

    fn budget(&self, st: &ExportState, now: u64) -> usize {
        match self.spec.max_hz {
            None => usize::MAX,
            Some(hz) => {
                let interval = (1e9 / hz) as u64;
                if st.last_sent_ns == 0 {
                    1
                } else {
                    usize::try_from(now.saturating_sub(st.last_sent_ns) / interval.max(1)).unwrap_or(usize::MAX)
                }
            }
        }
    }

    fn flush_locked(&self, st: &mut ExportState, now: u64) {
        if let Some(outbox) = st.outbox.as_mut() {
            for who in outbox.forget_gone(now, self.importer_ttl_ns) {
                tracing::info!(
                    topic = %self.spec.origin(),
                    importer = %who,
                    ttl_s = self.importer_ttl_ns / 1_000_000_000,
                    "importer forgotten: gone for longer than importer_ttl; nothing is kept for it any more"
                );
            }
        }
        let Some(link) = self.link.get() else { return };
        let budget = self.budget(st, now);
        let st = &mut *st;
        if let Some(outbox) = st.outbox.as_mut() {
            let oldest = outbox.oldest();
            let due: Vec<_> = outbox.due(now, RETRANSMIT_AFTER_NS, budget).into_iter().cloned().collect();
            let mut new = 0;
            for q in &due {
                let frame = Frame {
                    reliable: true,
                    type_name: &self.info.name,
                    fingerprint: self.info.fingerprint,
                    instance: self.instance,
                    seq: q.seq,
                    oldest: oldest.min(q.seq),
                    stamp_unix_ns: q.stamp_unix_ns,
                    origin_seq: q.origin_seq,
                    sender: &q.sender,
                    payload: &q.payload,
                };
                wire::encode_frame(&mut st.buf, &frame);
                if link.send(&st.buf) {
                    self.msgs.add(1);
                    self.bytes.add(q.payload.len() as u64);
                } else {
                    self.failed.add(1);
                }
                new += 1;
            }
            if new > 0 && self.spec.max_hz.is_some() {
                st.last_sent_ns = now;
            }
            return;
        }
        if budget == 0 {
            return;
        }
        let Some(p) = st.pending.take() else { return };
        st.seq += 1;
        let frame = Frame {
            reliable: false,
            type_name: &self.info.name,
            fingerprint: self.info.fingerprint,
            instance: self.instance,
            seq: st.seq,
            oldest: st.seq,
            stamp_unix_ns: p.stamp,
            origin_seq: p.origin_seq,
            sender: &p.sender,
            payload: &p.payload,
        };
        wire::encode_frame(&mut st.buf, &frame);
        if link.send(&st.buf) {
            self.msgs.add(1);
            self.bytes.add(p.payload.len() as u64);
        } else {
            self.failed.add(1);
        }
        st.last_sent_ns = now;
    }

    /// An importer appeared or went away (from its liveliness token), at `now_mono_ns`.
    pub fn set_importer(&self, who: &str, alive: bool, now_mono_ns: u64) {
        let mut st = lock(&self.state);
        let seen = {
            let mut set = lock(&self.importers);
            let seen = match st.outbox.as_mut() {
                Some(outbox) => outbox.set_importer(who, alive, now_mono_ns),
                None if alive && !set.contains(who) && set.len() >= MAX_IMPORTERS => Seen::Full,
                None => Seen::Taken,
            };
            if seen == Seen::Taken {
                if alive {
                    set.insert(who.into());
                } else {
                    set.remove(who);
                }
            }
            seen
        };
        match seen {
            Seen::Taken => tracing::info!(
                topic = %self.spec.origin(),
                importer = who,
                alive,
                "importer {}",
                if alive { "joined" } else { "left" }
            ),
            Seen::Unknown => {}
            Seen::Full => {
                let n = st.refused_warn.hit(now_mono_ns);
                if n > 0 {
                    tracing::warn!(
                        topic = %self.spec.origin(),
                        importer = who,
                        refused = n,
                        "{n} new importer(s) refused: {MAX_IMPORTERS} are known already; those gone are forgotten after importer_ttl"
                    );
                }
            }
        }
    }

    /// An acknowledgement arrived; one from an importer never seen alive is ignored.
    pub fn ack(&self, ack: &wire::Ack<'_>, now_mono_ns: u64) {
        if ack.instance != self.instance {
            return; // for an earlier run of this bridge
        }
        let mut st = lock(&self.state);
        let st = &mut *st;
        if let Some(outbox) = st.outbox.as_mut()
            && outbox.ack(ack.importer, ack.acked, now_mono_ns) == Seen::Unknown
        {
            let n = st.refused_warn.hit(now_mono_ns);
            if n > 0 {
                tracing::warn!(
                    topic = %self.spec.origin(),
                    importer = ack.importer,
                    refused = n,
                    "{n} acknowledgement(s) from importers never seen alive ignored"
                );
            }
        }
    }

    /// An acknowledgement whose key names another importer than its frame:
    /// refused (the key is what access control ties to a certificate).
    pub fn refuse_ack(&self, key: &str, importer: &str) {
        let mut st = lock(&self.state);
        let n = st.refused_warn.hit(agent_sdk::clock::now_ns());
        if n > 0 {
            tracing::warn!(
                topic = %self.spec.origin(),
                key,
                importer,
                refused = n,
                "{n} acknowledgement(s) refused: the key does not name the importer the frame names"
            );
        }
    }

    /// The figures of this topic, prefixed `export.AGENT/PORT.`.
    pub fn figures(&self, out: &mut Vec<(String, String)>) {
        let p = format!("export.{}", self.spec.origin());
        let st = lock(&self.state);
        let (depth, lost, retx, last) =
            st.outbox.as_ref().map_or((0, 0, 0, 0), |o| (o.depth(), o.lost(), o.retransmitted(), o.last_seq()));
        let importers = lock(&self.importers).len();
        out.extend([
            (format!("{p}.type"), self.info.name.to_string()),
            (format!("{p}.reliable"), self.spec.reliable.to_string()),
            (format!("{p}.wired"), self.wired().to_string()),
            (format!("{p}.importers"), importers.to_string()),
            (format!("{p}.msgs_out"), self.msgs.get().to_string()),
            (format!("{p}.bytes_out"), self.bytes.get().to_string()),
            (format!("{p}.dropped"), (self.dropped.get() + self.failed.get()).to_string()),
            (format!("{p}.lost"), lost.to_string()),
            (format!("{p}.queue"), depth.to_string()),
            (format!("{p}.retransmitted"), retx.to_string()),
            (format!("{p}.last_seq"), last.to_string()),
        ]);
    }
}

struct ImportState {
    inbox: Inbox,
    /// best effort: the sender's run and last sequence number seen
    last: Option<(u64, u64)>,
    latencies: VecDeque<u64>,
    last_rx_mono_ns: Option<u64>,
    last_error: Option<String>,
}

/// A remote port published on the bridge's output port.
pub struct ImportTopic {
    /// what the configuration says
    pub spec: Import,
    /// the local payload's layout
    pub info: TypeInfo,
    /// the Zenoh key: `nerve/<robot>/<agent>/<port>`
    pub key: String,
    sink: Arc<dyn ImportSink>,
    state: Mutex<ImportState>,
    msgs: Counter,
    bytes: Counter,
    lost: Counter,
    dropped: Counter,
    refused: Counter,
    duplicates: Counter,
}

impl std::fmt::Debug for ImportTopic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImportTopic").field("key", &self.key).finish()
    }
}

/// What the link must do after a frame was received.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply {
    /// Nothing.
    None,
    /// Acknowledge `acked` of run `instance`.
    Ack {
        /// the sender's run
        instance: u64,
        /// delivered up to
        acked: u64,
    },
}

impl ImportTopic {
    /// A topic for `spec`, published through `sink`.
    pub fn new(spec: Import, info: TypeInfo, sink: Arc<dyn ImportSink>) -> Self {
        let key = format!("nerve/{}/{}/{}", spec.robot, spec.agent, spec.port);
        ImportTopic {
            spec,
            info,
            key,
            sink,
            state: Mutex::new(ImportState {
                inbox: Inbox::default(),
                last: None,
                latencies: VecDeque::new(),
                last_rx_mono_ns: None,
                last_error: None,
            }),
            msgs: Counter::default(),
            bytes: Counter::default(),
            lost: Counter::default(),
            dropped: Counter::default(),
            refused: Counter::default(),
            duplicates: Counter::default(),
        }
    }

    fn refuse(&self, st: &mut ImportState, msg: String) {
        self.refused.add(1);
        if st.last_error.as_deref() != Some(msg.as_str()) {
            tracing::error!(topic = %self.spec.origin(), local = %self.spec.local, "{msg}");
            st.last_error = Some(msg);
        }
    }

    /// Handles one frame from the link.
    pub fn receive(&self, bytes: &[u8], now_mono_ns: u64) -> Reply {
        let mut st = lock(&self.state);
        let f = match wire::decode_frame(bytes) {
            Ok(f) => f,
            Err(e) => {
                self.refuse(&mut st, format!("a frame for {} was refused: {e}", self.spec.origin()));
                return Reply::None;
            }
        };
        if f.type_name != self.info.name {
            self.refuse(
                &mut st,
                format!(
                    "type mismatch: {} sends {} but this bridge imports it as {} (port {}); fix `type` in one of the two bridge configs",
                    self.spec.origin(),
                    f.type_name,
                    self.info.name,
                    self.spec.local
                ),
            );
            return Reply::None;
        }
        let fixed_size_differs = self.info.seq.is_none() && f.payload.len() != self.info.size;
        if f.fingerprint != self.info.fingerprint || fixed_size_differs {
            self.refuse(
                &mut st,
                format!(
                    "layout mismatch for {}: {} has fingerprint {:016x} ({} bytes) on the sending robot and {:016x} ({} bytes) here; rebuild the bridge and agents of the robot with the older nerve",
                    self.spec.origin(),
                    self.info.name,
                    f.fingerprint,
                    f.payload.len(),
                    self.info.fingerprint,
                    self.info.size
                ),
            );
            return Reply::None;
        }
        if f.reliable {
            let judged = st.inbox.accept(f.instance, f.seq, f.oldest);
            if judged.lost > 0 {
                self.lost.add(judged.lost);
                tracing::warn!(topic = %self.spec.origin(), lost = judged.lost, "reliable messages lost: the sender's queue overflowed while the link was down");
            }
            match judged.verdict {
                Verdict::Deliver => self.deliver(&mut st, &f, now_mono_ns),
                Verdict::Duplicate => self.duplicates.add(1),
                Verdict::Early => {}
            }
            Reply::Ack { instance: f.instance, acked: st.inbox.acked() }
        } else {
            match st.last {
                Some((inst, last)) if inst == f.instance && f.seq <= last => {
                    self.duplicates.add(1);
                    return Reply::None;
                }
                Some((inst, last)) if inst == f.instance && f.seq > last + 1 => self.dropped.add(f.seq - last - 1),
                _ => {}
            }
            st.last = Some((f.instance, f.seq));
            self.deliver(&mut st, &f, now_mono_ns);
            Reply::None
        }
    }

    fn deliver(&self, st: &mut ImportState, f: &Frame<'_>, now_mono_ns: u64) {
        if let Err(e) = self.info.check_len(f.payload.len()) {
            // a sequence sample this port cannot hold: refused whole, never
            // cut (a reliable one counts as delivered: it is refused for good)
            self.refuse(st, format!("a sample of {} was refused: {e}", self.spec.origin()));
            return;
        }
        if let Err(e) = self.sink.publish(f.payload) {
            self.refuse(st, format!("cannot publish {} on {}: {e}", self.spec.origin(), self.spec.local));
            return;
        }
        self.msgs.add(1);
        self.bytes.add(f.payload.len() as u64);
        st.last_rx_mono_ns = Some(now_mono_ns);
        let now = unix_now_ns();
        if f.stamp_unix_ns <= now {
            if st.latencies.len() == LATENCY_WINDOW {
                st.latencies.pop_front();
            }
            st.latencies.push_back(now - f.stamp_unix_ns);
        }
    }

    /// The figures of this topic, prefixed `import.ROBOT/AGENT/PORT.`.
    pub fn figures(&self, now_mono_ns: u64, out: &mut Vec<(String, String)>) {
        let p = format!("import.{}", self.spec.origin());
        let st = lock(&self.state);
        let mut lat: Vec<u64> = st.latencies.iter().copied().collect();
        lat.sort_unstable();
        let median = lat.get(lat.len() / 2).map_or("-".to_string(), |ns| format!("{}", ns / 1000));
        let age =
            st.last_rx_mono_ns.map_or("-".to_string(), |t| format!("{}", now_mono_ns.saturating_sub(t) / 1_000_000));
        out.extend([
            (format!("{p}.type"), self.info.name.to_string()),
            (format!("{p}.port"), self.spec.local.clone()),
            (format!("{p}.msgs_in"), self.msgs.get().to_string()),
            (format!("{p}.bytes_in"), self.bytes.get().to_string()),
            (format!("{p}.dropped"), self.dropped.get().to_string()),
            (format!("{p}.lost"), self.lost.get().to_string()),
            (format!("{p}.refused"), self.refused.get().to_string()),
            (format!("{p}.duplicates"), self.duplicates.get().to_string()),
            (format!("{p}.acked"), st.inbox.acked().to_string()),
            (format!("{p}.age_ms"), age),
            (format!("{p}.latency_us"), median),
            (format!("{p}.error"), st.last_error.clone().unwrap_or_default()),
        ]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::PortError;

    struct Wire(Arc<Mutex<Vec<Vec<u8>>>>);
    impl Transmit for Wire {
        fn send(&self, bytes: &[u8]) -> bool {
            lock(&self.0).push(bytes.to_vec());
            true
        }
    }

    type Samples = Arc<Mutex<Vec<(String, u64, Vec<u8>)>>>;
    struct Script(Samples);
    impl ExportTap for Script {
        fn drain(&self, f: &mut dyn FnMut(&str, u64, &[u8])) -> usize {
            let v: Vec<_> = lock(&self.0).drain(..).collect();
            for (s, q, b) in &v {
                f(s, *q, b);
            }
            v.len()
        }
    }

    struct Collect(Mutex<Vec<Vec<u8>>>);
    impl ImportSink for Collect {
        fn publish(&self, bytes: &[u8]) -> Result<(), PortError> {
            lock(&self.0).push(bytes.to_vec());
            Ok(())
        }
    }

    fn info() -> TypeInfo {
        TypeInfo { name: "nerve::Tick".into(), size: 8, fingerprint: 5, seq: None }
    }

    fn export(reliable: bool, max_hz: Option<f64>, queue: usize) -> (ExportTopic, Samples, Arc<Mutex<Vec<Vec<u8>>>>) {
        let spec = Export {
            agent: "t1".into(),
            port: "tick".into(),
            type_name: "nerve::Tick".into(),
            reliable,
            max_hz,
            queue,
            max_len: None,
        };
        let samples = Samples::default();
        let t = ExportTopic::new(spec, info(), "r1", 77, Box::new(Script(samples.clone())));
        let sent = Arc::new(Mutex::new(Vec::new()));
        t.attach(Box::new(Wire(sent.clone())));
        (t, samples, sent)
    }

    fn feed(samples: &Samples, n: u64) {
        for i in 0..n {
            lock(samples).push(("t1".into(), i + 1, (i + 1).to_le_bytes().to_vec()));
        }
    }

    fn import() -> (ImportTopic, Arc<Collect>) {
        import_of(info())
    }

    fn import_of(info: TypeInfo) -> (ImportTopic, Arc<Collect>) {
        let spec = Import {
            robot: "r1".into(),
            agent: "t1".into(),
            port: "tick".into(),
            type_name: info.name.clone(),
            local: "r1.t1.tick".into(),
            max_len: None,
        };
        let sink = Arc::new(Collect(Mutex::new(Vec::new())));
        (ImportTopic::new(spec, info, sink.clone()), sink)
    }

    fn figure(v: &[(String, String)], key: &str) -> String {
        v.iter().find(|(k, _)| k.ends_with(key)).map(|(_, v)| v.clone()).unwrap_or_default()
    }

    #[test]
    fn best_effort_keeps_the_newest_and_counts_the_rest() {
        let (t, samples, sent) = export(false, Some(10.0), 0);
        feed(&samples, 5);
        t.pump(1_000_000_000);
        assert_eq!(lock(&sent).len(), 1, "one sample per slot");
        let f = wire::decode_frame(&lock(&sent)[0]).map(|f| f.payload.to_vec()).expect("frame");
        assert_eq!(f, 5u64.to_le_bytes(), "the newest won");
        feed(&samples, 2);
        t.pump(1_050_000_000);
        assert_eq!(lock(&sent).len(), 1, "too early for the next slot");
        t.flush(1_100_000_000);
        assert_eq!(lock(&sent).len(), 2, "the held sample leaves at its slot");
        let mut v = Vec::new();
        t.figures(&mut v);
        assert_eq!(figure(&v, ".dropped"), "5", "4 then 1 were replaced before they could leave");
    }

    #[test]
    fn reliable_frames_cross_in_order_across_a_lossy_link() {
        let (t, samples, sent) = export(true, None, 16);
        let (imp, got) = import();
        feed(&samples, 4);
        t.pump(0); // nobody listens: sent into the void
        lock(&sent).clear();
        t.set_importer("r2.bridge", true, 0);
        t.flush(1);
        let frames: Vec<Vec<u8>> = lock(&sent).drain(..).collect();
        assert_eq!(frames.len(), 4, "the importer that appeared is sent what it missed");
        // the link loses frame 2 once
        for (i, fr) in frames.iter().enumerate() {
            if i == 1 {
                continue;
            }
            if let Reply::Ack { instance, acked } = imp.receive(fr, 10) {
                t.ack(&wire::Ack { instance, acked, importer: "r2.bridge" }, 10);
            }
        }
        assert_eq!(lock(&got.0).len(), 1, "3 and 4 wait for 2");
        t.flush(10 + RETRANSMIT_AFTER_NS);
        for fr in lock(&sent).drain(..) {
            if let Reply::Ack { instance, acked } = imp.receive(&fr, 20) {
                t.ack(&wire::Ack { instance, acked, importer: "r2.bridge" }, 20);
            }
        }
        let got: Vec<u64> =
            lock(&got.0).iter().map(|b| u64::from_le_bytes(b.as_slice().try_into().expect("8 bytes"))).collect();
        assert_eq!(got, vec![1, 2, 3, 4]);
        let mut v = Vec::new();
        t.figures(&mut v);
        assert_eq!(figure(&v, ".queue"), "0", "everything acknowledged");
    }

    #[test]
    fn a_mismatched_type_is_refused_with_both_names() {
        let (imp, got) = import();
        let mut buf = Vec::new();
        let payload = [0u8; 8];
        let frame = Frame {
            reliable: false,
            type_name: "nerve::Scalar",
            fingerprint: 5,
            instance: 1,
            seq: 1,
            oldest: 1,
            stamp_unix_ns: 0,
            origin_seq: 1,
            sender: "t1",
            payload: &payload,
        };
        wire::encode_frame(&mut buf, &frame);
        assert_eq!(imp.receive(&buf, 0), Reply::None);
        let mut v = Vec::new();
        imp.figures(0, &mut v);
        let err = figure(&v, ".error");
        assert!(err.contains("nerve::Scalar") && err.contains("nerve::Tick"), "{err}");
        let stale = Frame { type_name: "nerve::Tick", fingerprint: 6, ..frame };
        wire::encode_frame(&mut buf, &stale);
        imp.receive(&buf, 0);
        assert!(lock(&got.0).is_empty());
        let mut v = Vec::new();
        imp.figures(0, &mut v);
        assert_eq!(figure(&v, ".refused"), "2");
        let err = figure(&v, ".error");
        assert!(err.contains("fingerprint") && err.contains("0000000000000006"), "{err}");
    }

    /// A sequence topic (a 16-byte header, 12-byte elements, at most 3):
    /// samples of 0, 1 and 3 elements cross at their own length; 4
    /// elements, or bytes that are not whole elements, are refused and
    /// counted on the import, and never sent by the export.
    #[test]
    fn sequence_frames_cross_at_their_length_and_longer_ones_are_refused() {
        let shape = shm_schemas::SeqShape { items_at: 16, element: 12, align: 8 };
        let seq = TypeInfo {
            name: "nerve::Seq<test::Det, nerve::Tick>".into(),
            size: 16,
            fingerprint: 9,
            seq: Some(crate::types::SeqLimit { shape, max_len: 3 }),
        };
        assert_eq!(seq.max_payload(), 16 + 3 * 12, "the link's bound accounts for max_len");
        let (imp, got) = import_of(seq.clone());
        let frame_of = |n: u64, len: usize, buf: &mut Vec<u8>| {
            let payload = vec![n as u8; len];
            let f = Frame {
                reliable: false,
                type_name: "nerve::Seq<test::Det, nerve::Tick>",
                fingerprint: 9,
                instance: 1,
                seq: n,
                oldest: n,
                stamp_unix_ns: 0,
                origin_seq: n,
                sender: "t1",
                payload: &payload,
            };
            wire::encode_frame(buf, &f);
        };
        let mut buf = Vec::new();
        for (n, len) in [(1, 16), (2, 28), (3, 52), (4, 64), (5, 17), (6, 8)] {
            frame_of(n, len, &mut buf);
            imp.receive(&buf, 0);
        }
        let lens: Vec<usize> = lock(&got.0).iter().map(Vec::len).collect();
        assert_eq!(lens, [16, 28, 52], "0, 1 and 3 elements, each at its length");
        let mut v = Vec::new();
        imp.figures(0, &mut v);
        assert_eq!(figure(&v, ".refused"), "3", "4 elements, 17 bytes, 8 bytes");
        assert_eq!(figure(&v, ".msgs_in"), "3");
        // the export side: a sample longer than its max_len is not sent
        let spec = Export {
            agent: "t1".into(),
            port: "dets".into(),
            type_name: seq.name.clone(),
            reliable: false,
            max_hz: None,
            queue: 0,
            max_len: Some(3),
        };
        let samples = Samples::default();
        let t = ExportTopic::new(spec, seq, "r1", 77, Box::new(Script(samples.clone())));
        let sent = Arc::new(Mutex::new(Vec::new()));
        t.attach(Box::new(Wire(sent.clone())));
        lock(&samples).push(("t1".into(), 1, vec![0; 64]));
        t.pump(0);
        assert!(lock(&sent).is_empty(), "4 elements are not sent");
        lock(&samples).push(("t1".into(), 2, vec![0; 40]));
        t.pump(1);
        let frames = lock(&sent).clone();
        assert_eq!(frames.len(), 1);
        assert_eq!(wire::decode_frame(&frames[0]).expect("frame").payload.len(), 40, "2 elements, not max_len");
        let mut v = Vec::new();
        t.figures(&mut v);
        assert_eq!(figure(&v, ".dropped"), "1");
    }
}
