//! Lossless delivery to `keep = "all"` inputs (issue 46): the sender waits,
//! for a bounded time, rather than overwrite what a keep-all reader has not
//! read yet.
//!
//! An output port's own service has safe overflow on (the oldest sample is
//! overwritten) for every reader: that is right for sensors, and it is a
//! property of the service. So an output with keep-all readers publishes
//! each sample a second time, into a **keep-all service** beside its own
//! (`<port service>/keep-all`, safe overflow off, a subscriber buffer up to
//! [`MAX_DEPTH`]):
//!
//! * the reader makes it: a keep-all input opens (or creates) the service
//!   and subscribes to it with a buffer of its depth *before* it subscribes
//!   to the port's own service ([`KeepAllFeed::subscribe`]);
//! * the output finds it: each send compares the port's subscriber count
//!   (one atomic load in shared memory) with the last one it saw; when it
//!   changed, it looks for the keep-all service and, if there is one with
//!   readers, makes a publisher on it ([`KeepAllSender::before_send`]). No
//!   message of the control protocol is needed, and tools that publish
//!   (`nerve pub`) keep their old path: a keep-all input reads the port's
//!   own service (its own queue of copies, `port::depth`) for as long as
//!   no publisher is on its keep-all service;
//! * a send then copies the sample into the keep-all service *before* it
//!   sends it on the port's own service and wakes the readers, so the
//!   wake-up finds it. iceoryx2's back-pressure handler waits while a
//!   keep-all reader's buffer is full, at most [`KEEP_ALL_WAIT`] per
//!   sample; each wait is counted as back-pressure, and a sample given up
//!   after the bound as lost ([`KeepAllFigures`]). After one such timeout
//!   the output does not wait again until a send goes through without a
//!   full reader: a stuck reader costs the sender one bound, not one per
//!   sample.
//!
//! The default path (no keep-all reader) costs one atomic load and one
//! comparison per send: no lock, no allocation, no copy.

use super::bytes::ByteSubscriber;
use super::depth::MAX_DEPTH;
use super::error::{PortError, port_err};
use super::input::{Feed, Received, Source};
use super::service::{Carried, OutputFactory, SourceFactory, keep_all_output_service, keep_all_source_service, lock};
use crate::world::Ipc;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::service::marker::{CustomHeaderMarker, CustomPayloadMarker};
use shm_schemas::SampleHeader;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How long one send waits for a keep-all reader whose buffer is full
/// before it gives the sample up for that reader (counted as lost).
pub const KEEP_ALL_WAIT: Duration = Duration::from_secs(1);

/// The keep-all service beside output port `service`.
pub(crate) fn keep_all_name(service: &str) -> String {
    format!("{service}/keep-all")
}

/// What an output counts of its keep-all readers, shared with the
/// back-pressure handler and read for `nerve ps` and `nerve graph`.
#[derive(Debug, Default)]
pub struct KeepAllFigures {
    readers: AtomicU64,
    back_pressure: AtomicU64,
    lost: AtomicU64,
    /// a reader timed out: give samples up at once until a send finds no full reader
    stalled: AtomicBool,
    /// the handler was called during the current send
    touched: AtomicBool,
}

/// A snapshot of [`KeepAllFigures`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct KeepAllCounts {
    /// keep-all readers at the last look
    pub readers: u64,
    /// samples whose send waited for a full keep-all reader
    pub back_pressure: u64,
    /// samples given up for a keep-all reader after [`KEEP_ALL_WAIT`] (or
    /// at once while that reader was stuck)
    pub lost: u64,
}

impl KeepAllFigures {
    /// What was counted so far.
    pub fn counts(&self) -> KeepAllCounts {
        KeepAllCounts {
            readers: self.readers.load(Ordering::Relaxed),
            back_pressure: self.back_pressure.load(Ordering::Relaxed),
            lost: self.lost.load(Ordering::Relaxed),
        }
    }

    /// iceoryx2's back-pressure handler: a keep-all reader's buffer is full.
    /// Waits (retries) up to [`KEEP_ALL_WAIT`], then gives the sample up for
    /// that reader; while stalled, gives up at once.
    fn on_full(&self, info: &BackpressureInfo) -> BackpressureAction {
        self.touched.store(true, Ordering::Relaxed);
        if self.stalled.load(Ordering::Relaxed) {
            self.lost.fetch_add(1, Ordering::Relaxed);
            return BackpressureAction::DiscardData;
        }
        if info.retries == 0 {
            self.back_pressure.fetch_add(1, Ordering::Relaxed);
        }
        if info.elapsed_time < KEEP_ALL_WAIT {
            return BackpressureAction::Retry;
        }
        self.stalled.store(true, Ordering::Relaxed);
        self.lost.fetch_add(1, Ordering::Relaxed);
        tracing::warn!(
            wait_ms = KEEP_ALL_WAIT.as_millis() as u64,
            "a keep-all reader did not take a sample within the bound: the sample is lost for it, and the output \
             sends on without waiting until the reader reads again (make the reader faster or its depth larger)"
        );
        BackpressureAction::DiscardData
    }
}

/// The keep-all figures of this process's outputs, by port name, for the
/// agent's statistics (an agent's outputs are made by its own code, which
/// the runtime does not see): entries go with their outputs.
static OUTPUTS: Mutex<Vec<(String, std::sync::Weak<KeepAllFigures>)>> = Mutex::new(Vec::new());

/// What this process's outputs counted of their keep-all readers: those
/// that have had one (`nerve ps --json`, `nerve graph`).
pub(crate) fn output_stats() -> Vec<shm_schemas::stats::OutputStats> {
    let mut outputs = lock(&OUTPUTS);
    outputs.retain(|(_, f)| f.strong_count() > 0);
    outputs
        .iter()
        .filter_map(|(port, f)| Some((port, f.upgrade()?.counts())))
        .filter(|(_, c)| *c != KeepAllCounts::default())
        .map(|(port, c)| shm_schemas::stats::OutputStats {
            output: port.clone(),
            keep_all_readers: c.readers,
            back_pressure: c.back_pressure,
            lost: c.lost,
        })
        .collect()
}

type KeepAllPublisher = Publisher<Ipc, [CustomPayloadMarker], CustomHeaderMarker>;

/// An output's side: finds its keep-all readers and copies each sample to them.
pub(crate) struct KeepAllSender {
    node: Arc<Node<Ipc>>,
    /// the keep-all service's name
    service: String,
    carried: Carried,
    /// a sequence port's first slice length (its memory then grows)
    seq_initial: Option<usize>,
    figures: Arc<KeepAllFigures>,
    /// the port's subscriber count at the last look; `usize::MAX` before the first
    seen: AtomicUsize,
    /// a publisher is on the keep-all service
    active: AtomicBool,
    port: Mutex<Option<(OutputFactory, KeepAllPublisher)>>,
}

impl std::fmt::Debug for KeepAllSender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KeepAllSender").field("service", &self.service).field("figures", &self.figures).finish()
    }
}

impl KeepAllSender {
    /// The keep-all side of output port `service` carrying `carried`, made
    /// through `node` when a reader appears.
    pub(crate) fn new(node: Arc<Node<Ipc>>, service: &str, carried: Carried, seq_initial: Option<usize>) -> Self {
        let figures = Arc::default();
        let port = service.rsplit('/').next().unwrap_or(service);
        lock(&OUTPUTS).push((port.to_string(), Arc::downgrade(&figures)));
        KeepAllSender {
            node,
            service: keep_all_name(service),
            carried,
            seq_initial,
            figures,
            seen: AtomicUsize::new(usize::MAX),
            active: AtomicBool::new(false),
            port: Mutex::new(None),
        }
    }

    /// What it counted, shared (the agent's statistics read it).
    pub(crate) fn figures(&self) -> &Arc<KeepAllFigures> {
        &self.figures
    }

    /// Before each send, with the port's subscriber count: looks for
    /// keep-all readers when the count changed since the last look.
    #[inline]
    pub(crate) fn before_send(&self, subscribers: usize) {
        if subscribers != self.seen.load(Ordering::Relaxed) {
            self.look(subscribers);
        }
    }

    #[cold]
    fn look(&self, subscribers: usize) {
        self.seen.store(subscribers, Ordering::Relaxed);
        let mut port = lock(&self.port);
        if port.is_none() {
            match keep_all_output_service(&self.node, &self.service, &self.carried) {
                Ok(Some(factory)) => match self.publisher(&factory) {
                    Ok(publisher) => *port = Some((factory, publisher)),
                    Err(e) => tracing::warn!(service = %self.service, error = %e, "cannot publish to keep-all readers"),
                },
                Ok(None) => {}
                Err(e) => tracing::warn!(service = %self.service, error = %e, "cannot open the keep-all service"),
            }
        }
        let readers = port.as_ref().map_or(0, |(f, _)| f.dynamic_config().number_of_subscribers());
        if readers == 0 && port.take().is_some() {
            tracing::info!(service = %self.service, "no keep-all reader left: sending on the port's own service only");
        } else if readers > 0 && self.figures.readers.load(Ordering::Relaxed) == 0 {
            tracing::info!(service = %self.service, readers, "keep-all readers: each sample waits for them (bounded)");
        }
        self.figures.readers.store(readers as u64, Ordering::Relaxed);
        self.active.store(port.is_some(), Ordering::Release);
    }

    fn publisher(&self, factory: &OutputFactory) -> Result<KeepAllPublisher, PortError> {
        let figures = self.figures.clone();
        let builder = factory
            .publisher_builder()
            .backpressure_strategy(iceoryx2::port::backpressure_strategy::BackpressureStrategy::DiscardData)
            .set_backpressure_handler(move |info: &BackpressureInfo| figures.on_full(info));
        let builder = match self.seq_initial {
            Some(len) => builder.initial_max_slice_len(len).allocation_strategy(AllocationStrategy::PowerOfTwo),
            None => builder,
        };
        builder.create().map_err(port_err!(Publisher, &self.service))
    }

    /// Copies a sample being sent (`header`, `bytes`) to the keep-all
    /// readers, waiting for a full one at most [`KEEP_ALL_WAIT`]. Called
    /// before the sample goes on the port's own service, so that the
    /// wake-up after it finds the copy.
    /// A copy that cannot be made (no memory left in the service) is lost
    /// for the keep-all readers, counted and logged; the sample still goes
    /// on the port's own service.
    pub(crate) fn send(&self, header: &SampleHeader, bytes: &[u8]) {
        if !self.active.load(Ordering::Acquire) {
            return;
        }
        if let Err(e) = self.copy(header, bytes) {
            self.figures.lost.fetch_add(1, Ordering::Relaxed);
            tracing::warn!(service = %self.service, seq = header.seq, error = %e, "a sample did not reach the keep-all readers");
        }
    }

    /// One copy to every keep-all reader. iceoryx2 waits for a full reader
    /// (the handler, [`KeepAllFigures::on_full`]) once that reader is
    /// connected; a reader that has not read since the publisher appeared
    /// is not connected yet, and a full buffer then refuses the sample at
    /// once: it is sent again (the reader drops the adjacent duplicate,
    /// [`KeepAllFeed::receive`]) until it arrives or the bound passes.
    fn copy(&self, header: &SampleHeader, bytes: &[u8]) -> Result<(), PortError> {
        let port = lock(&self.port);
        let Some((factory, publisher)) = port.as_ref() else { return Ok(()) };
        let readers = factory.dynamic_config().number_of_subscribers();
        let start = std::time::Instant::now();
        for attempt in 0u64.. {
            self.figures.touched.store(false, Ordering::Relaxed);
            let reached = self.copy_once(publisher, header, bytes)?;
            let touched = self.figures.touched.load(Ordering::Relaxed);
            if reached >= readers {
                if !touched {
                    // no reader was full: a stuck one has read again
                    self.figures.stalled.store(false, Ordering::Relaxed);
                }
                return Ok(());
            }
            if attempt == 0 && !self.figures.stalled.load(Ordering::Relaxed) {
                self.figures.back_pressure.fetch_add(1, Ordering::Relaxed);
            }
            if self.figures.stalled.load(Ordering::Relaxed) || start.elapsed() >= KEEP_ALL_WAIT {
                let missed = (readers - reached) as u64;
                if !touched {
                    // (the handler counted those it gave up itself)
                    self.figures.lost.fetch_add(missed, Ordering::Relaxed);
                }
                self.figures.stalled.store(true, Ordering::Relaxed);
                return Ok(());
            }
            if attempt < 16 {
                std::thread::yield_now();
            } else {
                std::thread::sleep(Duration::from_micros(100));
            }
        }
        Ok(())
    }

    /// Loans, fills and sends one copy; how many readers it reached.
    fn copy_once(&self, publisher: &KeepAllPublisher, header: &SampleHeader, bytes: &[u8]) -> Result<usize, PortError> {
        let units = if self.carried.is_sequence() { bytes.len() } else { 1 };
        // SAFETY: as `SchemaOutput::loan_len`: one element of a FixedSize
        // type, or `len` one-byte elements of a Dynamic one
        let mut sample = unsafe { publisher.loan_custom_payload(units) }.map_err(port_err!(Loan, &self.service))?;
        let payload = sample.payload_mut();
        if payload.len() != bytes.len() {
            return Err(PortError::Ipc {
                service: self.service.clone(),
                detail: format!("loaned {} bytes for a {}-byte sample", payload.len(), bytes.len()),
            });
        }
        // SAFETY: `payload` is `bytes.len()` writable one-byte elements of
        // this loan; `bytes` is another sample's memory, so they do not overlap
        unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), payload.as_mut_ptr().cast::<u8>(), bytes.len()) };
        // SAFETY: the service's user header is a SampleHeader (as in
        // `SchemaOutput::publish_as`), the marker stands at its aligned address
        unsafe { (sample.user_header_mut() as *mut CustomHeaderMarker).cast::<SampleHeader>().write(*header) };
        // SAFETY: every payload byte was written just above
        let sample = unsafe { sample.assume_init() };
        sample.send().map_err(port_err!(Send, &self.service))
    }
}

/// A keep-all input's lossless subscription to one source.
pub(crate) struct KeepAllFeed {
    factory: SourceFactory,
    subscriber: ByteSubscriber,
    /// samples up to this sequence number were read from the port's own
    /// service before the source published here: skipped once here
    skip_through: Option<u64>,
    /// it was read from last time (the source publishes here)
    live: bool,
    /// the header of the last sample handed out: a copy sent again to a
    /// reader that was not yet connected is the same header, skipped
    last: Option<SampleHeader>,
}

impl KeepAllFeed {
    /// Opens (or makes) the keep-all service of output port `service` and
    /// subscribes to it with a buffer of `depth` samples.
    pub(crate) fn subscribe(
        node: &Node<Ipc>,
        service: &str,
        carried: &Carried,
        depth: usize,
    ) -> Result<Self, PortError> {
        let name = keep_all_name(service);
        let factory = keep_all_source_service(node, &name, carried)?;
        let subscriber = factory
            .subscriber_builder()
            .buffer_size(depth.clamp(1, MAX_DEPTH))
            .create()
            .map_err(port_err!(Subscriber, &name))?;
        Ok(KeepAllFeed { factory, subscriber, skip_through: None, live: false, last: None })
    }

    /// Whether the source publishes here now (its output found this
    /// reader); `last_seq`: the last sequence number read from the port's
    /// own service, skipped here when the source has just started to.
    pub(crate) fn is_live(&mut self, last_seq: Option<u64>) -> bool {
        let live = self.factory.dynamic_config().number_of_publishers() > 0;
        if live && !self.live {
            self.skip_through = last_seq;
            tracing::debug!(?last_seq, "the source publishes to this keep-all input: reading losslessly");
        }
        self.live = live;
        live
    }

    /// The next sample, in place, past those already read from the port's
    /// own service.
    pub(crate) fn receive(
        &mut self,
    ) -> Result<Option<Sample<Ipc, [CustomPayloadMarker], SampleHeader>>, iceoryx2::port::ReceiveError> {
        // bounded: at most the buffer of samples already read are skipped
        for _ in 0..=MAX_DEPTH {
            let Some(sample) = self.subscriber.receive()? else { return Ok(None) };
            let h = *sample.user_header();
            let again = self.last.is_some_and(|l| (l.sender, l.seq, l.stamp_ns) == (h.sender, h.seq, h.stamp_ns));
            match self.skip_through {
                _ if again => continue,
                Some(last) if h.seq <= last => continue,
                _ => {
                    self.skip_through = None;
                    self.last = Some(h);
                    return Ok(Some(sample));
                }
            }
        }
        Ok(None)
    }

    /// Whether the source published here at the last look.
    pub(crate) fn was_live(&self) -> bool {
        self.live
    }

    /// Whether a sample waits here.
    pub(crate) fn has_samples(&self) -> bool {
        self.subscriber.has_samples().unwrap_or(false)
    }
}

/// Drops what waits on the port's own service of a source that publishes
/// to its keep-all reader: every such sample is also in the keep-all
/// buffer. Bounded by the subscription's buffer.
pub(crate) fn discard(subscriber: &ByteSubscriber) {
    for _ in 0..=MAX_DEPTH {
        match subscriber.receive() {
            Ok(Some(_)) => {}
            _ => return,
        }
    }
}

// ---------------------------------------------------------------- the reader's side of an input

/// A keep-all input's source ([`super::input`]), read from its keep-all
/// service while its output publishes there.
impl Source {
    /// Whether this keep-all source's output publishes to its keep-all
    /// service now (then the port's own service holds only duplicates).
    pub(super) fn lossless(&mut self) -> bool {
        let Some(feed) = self.keep_all.as_mut() else { return false };
        let delivered = self.tally.last_delivered();
        feed.is_live(self.held.as_ref().and_then(|h| h.last_seq()).max(delivered))
    }

    /// A keep-all source read losslessly: what is left in its own queue,
    /// then the next sample of the keep-all service, in place; the port's
    /// own service emptied. `None` when the source is not read so.
    pub(super) fn take_lossless(&mut self, input: &str) -> Option<Result<Option<(SampleHeader, Received)>, PortError>> {
        if !self.lossless() {
            return None;
        }
        if let Feed::Shm { subscriber, .. } = &self.feed {
            discard(subscriber);
        }
        if let Some((h, b)) = self.held.as_mut().and_then(|held| held.pop()) {
            return Some(Ok(Some((h, Received::copied(h, b)))));
        }
        let got = self.keep_all.as_mut()?.receive();
        Some(match got {
            Ok(sample) => Ok(sample.map(|s| (*s.user_header(), Received::in_place(s)))),
            Err(e) => Err(self.receive_error(input, e)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::port::bytes::{Binding, DynInput as _};
    use crate::port::depth::{InputOptions, Keep};
    use crate::port::{Input, Output};
    use crate::world::World;
    use crate::world::test_support::Cleanup;
    use shm_schemas::payloads::Tick;

    /// A world, its node (shared, as an agent's), an output `src/out` of
    /// Ticks that publishes to keep-all readers, and an input of `options`
    /// reading it.
    struct Bench {
        world: World,
        node: Arc<Node<Ipc>>,
        out: Output<Tick>,
    }

    impl Bench {
        fn new(tag: &str) -> Self {
            let world = World::new(&format!("keepall{tag}{}", std::process::id())).expect("world");
            let node = Arc::new(world.node("test").expect("node"));
            let service = world.robot().port_service("src", "out");
            let out = Output::<Tick>::bind(&Binding::Shm(node.clone()), "out", &service, "src").expect("output");
            Bench { world, node, out }
        }

        fn input(&self, name: &str, options: InputOptions) -> (Input<Tick>, Arc<crate::port::bytes::InputInner>) {
            let (input, inner) = Input::<Tick>::new(name).expect("input");
            inner.depth.set(options);
            assert!(inner.connect(&self.node, self.world.robot(), "src", "out").expect("subscribes"));
            (input, inner)
        }

        fn send(&self, seq: u64) {
            self.out.send(Tick { seq, stamp_ns: seq }).expect("send");
        }

        fn counts(&self) -> KeepAllCounts {
            self.out.keep_all_counts()
        }
    }

    /// 1,000 samples sent at once into a keep-all input of depth 32 (far
    /// past depth + 16) all arrive, in order, while the reader takes them at
    /// its own pace: the sender waited for it (back-pressure counted),
    /// nothing was lost; a `latest` input on the same output still holds the
    /// newest 16, as before.
    #[test]
    fn a_burst_of_1000_reaches_a_keep_all_input_of_depth_32_whole_and_in_order() {
        let b = Bench::new("burst");
        let _cleanup = Cleanup(b.world.clone());
        let (all, all_inner) = b.input("all", InputOptions::new(32, Keep::All).expect("depth 32"));
        let (latest, _latest_inner) = b.input("latest", InputOptions::default());
        let reader = std::thread::spawn(move || {
            let mut seqs = Vec::new();
            let deadline = std::time::Instant::now() + Duration::from_secs(60);
            while seqs.len() < 1000 && std::time::Instant::now() < deadline {
                match all.recv() {
                    Some((_, t)) => seqs.push(t.seq),
                    // slower than the sender: it has to wait
                    None => std::thread::sleep(Duration::from_millis(2)),
                }
            }
            seqs
        });
        for seq in 1..=1000 {
            b.send(seq);
        }
        let seqs = reader.join().expect("the reader");
        assert_eq!(seqs, (1..=1000).collect::<Vec<u64>>(), "every sample, in order");
        let c = b.counts();
        assert_eq!((c.readers, c.lost), (1, 0), "{c:?}");
        assert!(c.back_pressure > 0, "the sender waited for the reader: {c:?}");
        let q = all_inner.queue_stats();
        assert!(q[0].keep_all && q[0].lossless && q[0].depth == 32, "{q:?}");
        let newest: Vec<u64> = std::iter::from_fn(|| latest.recv()).take(100).map(|(_, t)| t.seq).collect();
        assert_eq!(newest, (985..=1000).collect::<Vec<u64>>(), "the latest input holds the newest 16");
    }

    /// A keep-all reader that does not read costs the sender one bounded
    /// wait, not one per sample: the rest are given up for it at once and
    /// counted as lost. What it holds is the oldest, in order; once it
    /// reads again, the next sample reaches it.
    #[test]
    fn a_stuck_keep_all_reader_costs_the_sender_one_bounded_wait_and_counts_what_it_lost() {
        let b = Bench::new("stuck");
        let _cleanup = Cleanup(b.world.clone());
        let (all, _inner) = b.input("all", InputOptions::new(4, Keep::All).expect("depth 4"));
        for seq in 1..=100 {
            b.send(seq);
        }
        let c = b.counts();
        assert_eq!((c.back_pressure, c.lost), (1, 96), "one wait, then the rest given up: {c:?}");
        let held: Vec<u64> = std::iter::from_fn(|| all.recv()).take(100).map(|(_, t)| t.seq).collect();
        assert_eq!(held, vec![1, 2, 3, 4]);
        b.send(101);
        assert_eq!(all.recv().map(|(_, t)| t.seq), Some(101), "read again: delivered again");
        assert_eq!(b.counts().lost, 96);
    }

    /// An output with no keep-all reader makes no keep-all publisher, and
    /// a keep-all input of a tool's output (no keep-all side) reads copies
    /// of the port's own service, as before.
    #[test]
    fn without_a_keep_all_side_the_input_reads_the_ports_own_service() {
        let world = World::new(&format!("keepalltool{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let out = Output::<Tick>::create(&node, &robot.port_service("tool", "out"), "tool").expect("output");
        let (input, inner) = Input::<Tick>::new("in").expect("input");
        inner.depth.set(InputOptions::new(32, Keep::All).expect("depth 32"));
        assert!(inner.connect(&node, &robot, "tool", "out").expect("subscribes"));
        for seq in 1..=40 {
            out.send(Tick { seq, stamp_ns: seq }).expect("send");
            if seq % 8 == 0 {
                inner.refill();
            }
        }
        let seqs: Vec<u64> = std::iter::from_fn(|| input.recv()).take(100).map(|(_, t)| t.seq).collect();
        assert_eq!(seqs, (1..=40).collect::<Vec<u64>>());
        assert!(!inner.queue_stats()[0].lossless);
    }
}
