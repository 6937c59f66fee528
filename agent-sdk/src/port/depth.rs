//! Per-input depth and policy (issue 46): how many samples an input holds
//! per source, and whether it overwrites the oldest (`keep = "latest"`, the
//! default) or keeps them all up to its depth (`keep = "all"`).
//!
//! An output port's iceoryx2 service is made by the output, with one
//! setting for every reader: [`SUBSCRIBER_BUFFER`] samples per subscriber,
//! the oldest overwritten (safe overflow). Raising that for every output
//! would cost shared memory on every port (16 readers × N × a 1 MB image),
//! so an input's depth is kept on the reader's side:
//!
//! * `depth <= 16` and `keep = "latest"`: the subscriber's own iceoryx2
//!   buffer of `depth` samples, zero copy; the common case (16, latest)
//!   costs exactly what it did.
//! * a larger depth, or `keep = "all"`: the input moves waiting samples out
//!   of iceoryx2 into its own queue of copies ([`Held`]) each time it is
//!   read or its agent wakes, up to `depth` per source. A `keep = "all"`
//!   queue never overwrites: when it is full the samples stay in iceoryx2's
//!   buffer (16 more) and each such refill is counted as back-pressure;
//!   a `latest` queue overwrites its oldest and counts it as dropped.
//!
//! The depth is bounded by [`MAX_DEPTH`]: the queue is copies in the
//! reader's memory (256 × a 1 MB image is 256 MB per source), and a
//! deeper queue of commands is a late robot, not a safe one.
//! docs/inputs.md has the design and its limits.

use super::bytes::{ByteSubscriber, InputInner, payload_bytes};
use super::memory::SampleBuf;
use super::service::{SUBSCRIBER_BUFFER, lock};
use shm_schemas::SampleHeader;
use std::collections::VecDeque;
use std::sync::Mutex;

/// The deepest an input may be, samples per source.
pub const MAX_DEPTH: usize = 256;

/// What an input does when samples arrive faster than it reads them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Keep {
    /// overwrite the oldest waiting sample (counted as dropped): sensors
    #[default]
    Latest,
    /// keep every sample up to the depth; past it, the sender's samples
    /// wait in iceoryx2 and the wait is counted as back-pressure: commands
    All,
}

impl Keep {
    /// The word a launch file and `nerve graph` use: `latest` or `all`.
    pub fn as_str(self) -> &'static str {
        match self {
            Keep::Latest => "latest",
            Keep::All => "all",
        }
    }

    /// `latest` or `all`.
    pub fn parse(word: &str) -> Result<Self, OptionsError> {
        match word {
            "latest" => Ok(Keep::Latest),
            "all" => Ok(Keep::All),
            other => Err(OptionsError::Keep { given: other.into() }),
        }
    }
}

/// How an input buffers: its depth per source and its [`Keep`] policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputOptions {
    /// samples held per source, 1..=[`MAX_DEPTH`]
    pub depth: usize,
    /// what happens past the depth
    pub keep: Keep,
}

impl Default for InputOptions {
    fn default() -> Self {
        InputOptions { depth: SUBSCRIBER_BUFFER, keep: Keep::Latest }
    }
}

/// A depth or policy an input cannot have.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OptionsError {
    /// depth 0 or past [`MAX_DEPTH`]
    #[error("depth {given} is out of range: give 1 to {MAX_DEPTH} samples per source")]
    Depth {
        /// what was given
        given: i64,
    },
    /// a policy that is not `latest` or `all`
    #[error("keep {given:?} is not a policy: give \"latest\" (overwrite the oldest) or \"all\" (lose nothing)")]
    Keep {
        /// what was given
        given: String,
    },
    /// a setting for an input the agent does not declare
    #[error("the agent has no such input (its inputs: {known}): check the input's name in the launch file")]
    NoSuchInput {
        /// the inputs it has
        known: String,
    },
    /// text that is not `depth=N,keep=WORD`
    #[error("{given:?} is not an input setting: write depth=N and/or keep=latest|all, separated by commas")]
    Text {
        /// what was given
        given: String,
    },
}

impl InputOptions {
    /// Depth `depth` with policy `keep`, checked.
    pub fn new(depth: i64, keep: Keep) -> Result<Self, OptionsError> {
        let options = InputOptions { depth: usize::try_from(depth).unwrap_or(0), keep };
        if options.depth == 0 || options.depth > MAX_DEPTH {
            return Err(OptionsError::Depth { given: depth });
        }
        Ok(options)
    }

    /// Refuses a depth out of 1..=[`MAX_DEPTH`].
    pub fn check(self) -> Result<Self, OptionsError> {
        Self::new(i64::try_from(self.depth).unwrap_or(i64::MAX), self.keep)
    }

    /// Whether the input keeps its own queue of copies ([`Held`]) rather
    /// than only iceoryx2's buffer.
    pub fn holds_copies(self) -> bool {
        self.keep == Keep::All || self.depth > SUBSCRIBER_BUFFER
    }

    /// The iceoryx2 subscriber's buffer for this input: its depth when
    /// iceoryx2 holds it all, else the service's whole buffer.
    pub fn buffer_size(self) -> usize {
        self.depth.clamp(1, SUBSCRIBER_BUFFER)
    }

    /// The text form (`depth=64,keep=all`), as the launcher passes it to
    /// an agent (`--input NAME:TEXT`) and `nerve graph` shows it.
    pub fn to_text(self) -> String {
        format!("depth={},keep={}", self.depth, self.keep.as_str())
    }

    /// Reads the text form: `depth=N` and/or `keep=WORD`, comma separated;
    /// what is not given stays at the default.
    pub fn parse(text: &str) -> Result<Self, OptionsError> {
        let mut options = InputOptions::default();
        for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            match part.split_once('=').map(|(k, v)| (k.trim(), v.trim())) {
                Some(("depth", n)) => {
                    let n: i64 = n.parse().map_err(|_| OptionsError::Text { given: text.into() })?;
                    options = InputOptions::new(n, options.keep)?;
                }
                Some(("keep", word)) => options.keep = Keep::parse(word)?,
                _ => return Err(OptionsError::Text { given: text.into() }),
            }
        }
        Ok(options)
    }
}

/// What an input's own queue counts, for `nerve ps`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HeldCounts {
    /// samples overwritten in a `latest` queue
    pub overwritten: u64,
    /// refills of a full `all` queue that left samples waiting in iceoryx2
    /// (the sender's samples waited: back-pressure)
    pub back_pressure: u64,
    /// the most samples the queue held at once
    pub high_water: usize,
}

/// An input source's own queue of copies, up to the input's depth.
#[derive(Debug)]
pub(crate) struct Held {
    options: InputOptions,
    /// the payload's alignment, for the copies
    align: usize,
    queue: VecDeque<(SampleHeader, SampleBuf)>,
    counts: HeldCounts,
}

impl Held {
    /// The queue of an input with `options`; `None` when iceoryx2's own
    /// buffer holds the input's depth.
    pub(crate) fn of(options: InputOptions, align: usize) -> Option<Self> {
        options.holds_copies().then(|| Held { options, align, queue: VecDeque::new(), counts: HeldCounts::default() })
    }

    /// Moves the samples waiting in `subscriber` into the queue, as copies,
    /// until none waits or an `all` queue is full (then, if samples still
    /// wait, counts the back-pressure). Bounded: at most the depth and
    /// iceoryx2's buffer are taken, however fast the sender goes.
    pub(crate) fn refill(&mut self, subscriber: &ByteSubscriber, input: &str) {
        for _ in 0..self.options.depth.saturating_add(SUBSCRIBER_BUFFER) {
            if !self.has_room() {
                if subscriber.has_samples().unwrap_or(false) {
                    self.count_back_pressure();
                    tracing::debug!(input, depth = self.options.depth, "input queue full: the sender's samples wait");
                }
                return;
            }
            match subscriber.receive() {
                Ok(Some(sample)) => match SampleBuf::copy_of(input, payload_bytes(sample.payload()), self.align) {
                    Ok(copy) => self.push(*sample.user_header(), copy),
                    Err(e) => tracing::warn!(input, error = %e, "a sample could not be copied into the input's queue"),
                },
                Ok(None) => return,
                Err(e) => {
                    tracing::warn!(input, error = ?e, "receive failed while filling the input's queue");
                    return;
                }
            }
        }
    }

    /// Whether the queue takes another sample now: always for `latest`
    /// (it overwrites), until the depth for `all`.
    pub(crate) fn has_room(&self) -> bool {
        self.options.keep == Keep::Latest || self.queue.len() < self.options.depth
    }

    /// Counts one refill that stopped at a full `all` queue with samples
    /// still waiting in iceoryx2.
    pub(crate) fn count_back_pressure(&mut self) {
        self.counts.back_pressure = self.counts.back_pressure.saturating_add(1);
    }

    /// Keeps a copy of one sample; a `latest` queue at its depth drops its
    /// oldest first. The caller checks [`Held::has_room`] for `all`.
    pub(crate) fn push(&mut self, header: SampleHeader, sample: SampleBuf) {
        if self.queue.len() >= self.options.depth {
            self.queue.pop_front();
            self.counts.overwritten = self.counts.overwritten.saturating_add(1);
        }
        self.queue.push_back((header, sample));
        self.counts.high_water = self.counts.high_water.max(self.queue.len());
    }

    /// Refills from `subscriber`, then hands out the oldest sample held.
    pub(crate) fn take(&mut self, subscriber: &ByteSubscriber, input: &str) -> Option<(SampleHeader, SampleBuf)> {
        self.refill(subscriber, input);
        self.pop()
    }

    /// The oldest sample held.
    pub(crate) fn pop(&mut self) -> Option<(SampleHeader, SampleBuf)> {
        self.queue.pop_front()
    }

    /// The sequence number of the newest sample held.
    pub(crate) fn last_seq(&self) -> Option<u64> {
        self.queue.back().map(|(h, _)| h.seq)
    }

    /// What it counted.
    pub(crate) fn counts(&self) -> HeldCounts {
        self.counts
    }
}

/// An input's options, set by `setup.input_with` or the launch file
/// before it is connected, and what its queues counted.
#[derive(Debug, Default)]
pub(crate) struct InputDepth {
    options: Mutex<InputOptions>,
}

impl InputDepth {
    pub(crate) fn options(&self) -> InputOptions {
        *lock(&self.options)
    }

    pub(crate) fn set(&self, options: InputOptions) {
        *lock(&self.options) = options;
    }
}

impl InputInner {
    /// Moves what waits in iceoryx2 into each source's own queue (when the
    /// agent wakes, so a deep input holds what arrives between reads).
    pub(crate) fn refill_held(&self) {
        // borrowed, not copied: this runs for every input at every wake-up
        let name = self.name();
        self.each_held(|subscriber, held| held.refill(subscriber, name));
    }

    /// What the own queues counted, summed over the sources.
    pub(crate) fn held_counts(&self) -> HeldCounts {
        let mut sum = HeldCounts::default();
        self.each_held(|_, held| {
            let c = held.counts();
            sum.overwritten = sum.overwritten.saturating_add(c.overwritten);
            sum.back_pressure = sum.back_pressure.saturating_add(c.back_pressure);
            sum.high_water = sum.high_water.max(c.high_water);
        });
        sum
    }
}

impl<T: shm_schemas::Payload> super::typed::Input<T> {
    /// What this input's own queues counted ([`InputOptions::holds_copies`]):
    /// samples overwritten, back-pressure, the most held at once. All zero
    /// for an input that only iceoryx2 buffers.
    pub fn queue_counts(&self) -> HeldCounts {
        self.inner().held_counts()
    }
}

impl super::bytes::SchemaInput {
    /// What this input's own queues counted (see [`super::typed::Input::queue_counts`]).
    pub fn queue_counts(&self) -> HeldCounts {
        self.inner().held_counts()
    }
}

/// Applies the launcher's settings (`--input NAME:depth=N,keep=WORD`, from
/// a launch file's `[agent.inputs]`) to the declared `inputs`, before any
/// is connected; they win over the agent's own `input_with`.
pub(crate) fn apply_settings(
    inputs: &[std::sync::Arc<dyn super::bytes::DynInput>],
    settings: &[String],
) -> Result<(), crate::agent::AgentError> {
    use crate::agent::AgentError;
    for setting in settings {
        let (name, text) = setting.split_once(':').unwrap_or((setting.as_str(), ""));
        let err = |source| AgentError::InputOptions { input: name.into(), source };
        let Some(depth) = inputs.iter().filter(|i| i.name() == name).find_map(|i| i.depth()) else {
            let known: Vec<&str> = inputs.iter().filter(|i| i.depth().is_some()).map(|i| i.name()).collect();
            return Err(err(OptionsError::NoSuchInput { known: known.join(", ") }));
        };
        let options = InputOptions::parse(text).map_err(err)?;
        tracing::info!(input = name, depth = options.depth, keep = options.keep.as_str(), "input depth and policy set");
        depth.set(options);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(seq: u64) -> (SampleHeader, SampleBuf) {
        let h = SampleHeader { seq, ..SampleHeader::default() };
        (h, SampleBuf::copy_of("test", &seq.to_le_bytes(), 8).expect("a copy"))
    }

    /// Real iceoryx2, one process: `sends` Ticks into an input of
    /// `options`, the input's queues filled every 8 samples as the task's
    /// wake-ups do; returns the seqs read afterwards and the counts.
    fn burst(tag: &str, options: InputOptions, sends: u64) -> (Vec<u64>, HeldCounts) {
        use crate::port::bytes::DynInput as _;
        use crate::world::World;
        use crate::world::test_support::Cleanup;
        use shm_schemas::payloads::Tick;
        let world = World::new(&format!("depth{tag}{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = world.node("test").expect("node");
        let robot = world.robot().clone();
        let out = crate::port::Output::<Tick>::create(&node, &robot.port_service("src", "out"), "src").expect("output");
        let (input, inner) = crate::port::Input::<Tick>::new("in").expect("input");
        inner.depth.set(options);
        assert!(inner.connect(&node, &robot, "src", "out").expect("subscribes"));
        for k in 1..=sends {
            out.send(Tick { seq: k, stamp_ns: k }).expect("send");
            if k % 8 == 0 {
                inner.refill();
            }
        }
        let seqs: Vec<u64> = std::iter::from_fn(|| input.recv()).take(1000).map(|(_, t)| t.seq).collect();
        (seqs, input.queue_counts())
    }

    #[test]
    fn a_depth_64_input_holds_the_last_64_and_counts_the_rest_overwritten() {
        let (seqs, counts) = burst("d64", InputOptions::new(64, Keep::Latest).expect("depth 64"), 100);
        assert_eq!(seqs, (37..=100).collect::<Vec<u64>>());
        assert_eq!((counts.overwritten, counts.back_pressure, counts.high_water), (36, 0, 64));
        // the default holds iceoryx2's 16
        let (seqs, counts) = burst("d16", InputOptions::default(), 100);
        assert_eq!(seqs, (85..=100).collect::<Vec<u64>>());
        assert_eq!(counts, HeldCounts::default());
    }

    #[test]
    fn a_keep_all_input_loses_nothing_of_a_burst_past_its_depth_and_counts_back_pressure() {
        // 48 = its depth 32 and iceoryx2's 16 behind it
        let (seqs, counts) = burst("all", InputOptions::new(32, Keep::All).expect("depth 32"), 48);
        assert_eq!(seqs, (1..=48).collect::<Vec<u64>>(), "every sample, in order");
        assert_eq!(counts.overwritten, 0);
        assert!(counts.back_pressure > 0, "the full queue was counted: {counts:?}");
        assert_eq!(counts.high_water, 32);
    }

    #[test]
    fn the_default_is_iceoryx2s_buffer_of_16_latest_without_copies() {
        let o = InputOptions::default();
        assert_eq!((o.depth, o.keep), (SUBSCRIBER_BUFFER, Keep::Latest));
        assert!(!o.holds_copies());
        assert_eq!(o.buffer_size(), SUBSCRIBER_BUFFER);
        assert!(Held::of(o, 8).is_none());
        let shallow = InputOptions::new(4, Keep::Latest).expect("depth 4");
        assert_eq!(shallow.buffer_size(), 4);
        assert!(!shallow.holds_copies());
    }

    #[test]
    fn deep_or_keep_all_inputs_hold_copies() {
        let deep = InputOptions::new(64, Keep::Latest).expect("depth 64");
        assert!(deep.holds_copies());
        assert_eq!(deep.buffer_size(), SUBSCRIBER_BUFFER);
        assert!(InputOptions::new(2, Keep::All).expect("depth 2").holds_copies());
    }

    #[test]
    fn depths_out_of_range_and_unknown_words_are_refused() {
        assert_eq!(InputOptions::new(0, Keep::Latest), Err(OptionsError::Depth { given: 0 }));
        assert_eq!(InputOptions::new(-3, Keep::All), Err(OptionsError::Depth { given: -3 }));
        assert_eq!(InputOptions::new(257, Keep::All), Err(OptionsError::Depth { given: 257 }));
        assert!(InputOptions::new(256, Keep::All).is_ok());
        assert!(InputOptions { depth: 1000, keep: Keep::All }.check().is_err());
        assert_eq!(Keep::parse("everything"), Err(OptionsError::Keep { given: "everything".into() }));
        assert!(InputOptions::parse("depth=ten").is_err());
        assert!(InputOptions::parse("deep=10").is_err());
        assert!(InputOptions::parse("depth=300").is_err());
        let msg = InputOptions::new(0, Keep::Latest).expect_err("refused").to_string();
        assert!(msg.contains("1 to 256"), "{msg}");
    }

    #[test]
    fn the_text_form_reads_back() {
        let o = InputOptions::new(64, Keep::All).expect("depth 64");
        assert_eq!(o.to_text(), "depth=64,keep=all");
        assert_eq!(InputOptions::parse(&o.to_text()), Ok(o));
        assert_eq!(InputOptions::parse("keep=all"), Ok(InputOptions { depth: 16, keep: Keep::All }));
        assert_eq!(InputOptions::parse(" depth = 3 "), Ok(InputOptions { depth: 3, keep: Keep::Latest }));
        assert_eq!(InputOptions::parse(""), Ok(InputOptions::default()));
    }

    #[test]
    fn a_latest_queue_overwrites_its_oldest_and_counts_it() {
        let mut held = Held::of(InputOptions::new(32, Keep::Latest).expect("depth 32"), 8).expect("copies");
        for seq in 1..=40 {
            assert!(held.has_room());
            let (h, b) = sample(seq);
            held.push(h, b);
        }
        assert_eq!(held.counts().high_water, 32);
        assert_eq!(held.counts().overwritten, 8);
        assert_eq!(held.pop().map(|(h, _)| h.seq), Some(9));
    }

    #[test]
    fn an_all_queue_stops_at_its_depth_and_keeps_every_sample_in_order() {
        let mut held = Held::of(InputOptions::new(3, Keep::All).expect("depth 3"), 8).expect("copies");
        for seq in 1..=3 {
            assert!(held.has_room());
            let (h, b) = sample(seq);
            held.push(h, b);
        }
        assert!(!held.has_room());
        held.count_back_pressure();
        assert_eq!(held.counts(), HeldCounts { overwritten: 0, back_pressure: 1, high_water: 3 });
        let order: Vec<u64> = std::iter::from_fn(|| held.pop()).map(|(h, _)| h.seq).collect();
        assert_eq!(order, vec![1, 2, 3]);
    }
}
