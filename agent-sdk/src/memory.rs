//! Short-term memory ports: "a link and a signal" for large data.
//!
//! The thesis mails small messages and keeps large data (camera images) in a
//! short-term memory, sending readers only a link and a signal. This module
//! joins the two halves nerve has for that:
//!
//! * a ring of the robot's short-term memory (`nerve-stm`: one file
//!   `/dev/shm/nerve_<uid>_<robot>_stm_<ring>`, one writer, any number of readers
//!   reading in place), and
//! * an ordinary output port carrying a [`RingNotice`] (ring, slot, sequence,
//!   stamp, size, image geometry) after every stored frame, so that readers
//!   are event-driven: they wake on the notice, like on any other input.
//!
//! [`RingOutput`] is the writer side: `write` / `write_with` store a frame in
//! the ring (in place: a camera renders straight into shared memory) and
//! then announce it. [`RingInput`] is the reader side: an input port of
//! notices plus a cache of opened ring readers, one per ring, mapped once;
//! `latest_with` / `read_notice_with` hand the frame's bytes in shared
//! memory to a closure. Nothing is copied per reader and readers keep no
//! state in shared memory, so the cost of a frame for the writer does not
//! grow with the number of readers.
//!
//! Both are declared in [`crate::Agent::new`] through [`MemorySetup`], an
//! extension of [`Setup`]:
//!
//! ```no_run
//! use agent_sdk::memory::{FrameDesc, MemorySetup, PixelFormat, RingInput, RingOutput, RingSpec};
//! use agent_sdk::{AgentError, Setup};
//! fn declare(setup: &mut Setup) -> Result<(RingOutput, RingInput), AgentError> {
//!     // output port `frames`, ring `cam`: 8 slots of one 320x240 RGB image
//!     let out = setup.ring_output("frames", RingSpec::new(8, 320 * 240 * 3).named("cam"))?;
//!     let input = setup.ring_input("frames_in")?;
//!     Ok((out, input))
//! }
//! # fn use_them(mut out: RingOutput, mut input: RingInput) -> Result<(), AgentError> {
//! out.write_with(FrameDesc::image(320, 240, PixelFormat::Rgb8), 320 * 240 * 3, |buf| buf.fill(0))?;
//! let mean = input.latest_with(|_meta, px| px.iter().map(|&b| u64::from(b)).sum::<u64>())?;
//! # let _ = mean; Ok(()) }
//! ```
//!
//! **The ring is created lazily**, at the first write or at an explicit
//! [`RingOutput::open`] (call it from [`crate::Agent::start`] to fail
//! early): `Agent::new` also runs for `--describe`, in a throw-away world,
//! where no ring file should be left behind. At declaration, a ring that
//! another live process already writes is refused at once, with the pid and
//! what to do, so that `nerve start` reports the clash.

use crate::agent::{AgentError, Setup};
use crate::ports::{Input, Meta, Output, PortError};
use nerve_stm::{CreateError, OpenError, ReadError, RingNameError, RingReader, RingWriter, WriteError};
use shm_schemas::RobotName;
use std::collections::HashMap;

pub use nerve_stm as stm;
pub use nerve_stm::{FrameDesc, FrameMeta, PixelFormat, RingName, RingNotice, RingOptions};

/// Slots of a ring when the agent does not say: about half a second of video
/// at 15 fps, enough for readers that wake late.
pub const DEFAULT_SLOTS: u32 = 8;

/// Why a short-term-memory port could not be made or used.
#[derive(Debug, thiserror::Error)]
pub enum MemoryError {
    /// The ring name is not allowed.
    #[error("ring name for port {port:?}: {source}")]
    Name {
        /// the port
        port: String,
        /// what is wrong with the name
        #[source]
        source: RingNameError,
    },
    /// Another live process writes the ring already.
    #[error(
        "ring {ring} is already written by another process (pid {pid}); each ring has one writer: stop that agent, or give this one another ring name (a ring option of the agent)"
    )]
    Taken {
        /// the ring
        ring: String,
        /// the writer's pid
        pid: u32,
    },
    /// The ring could not be created.
    #[error(transparent)]
    Create(#[from] CreateError),
    /// A ring named by a notice could not be opened.
    #[error(transparent)]
    Open(#[from] OpenError),
    /// A frame could not be stored.
    #[error(transparent)]
    Write(#[from] WriteError),
    /// A frame could not be read (overwritten, not yet stored, ...).
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The notice port failed.
    #[error(transparent)]
    Port(#[from] PortError),
    /// A notice names no valid ring (a misbehaving sender).
    #[error("a notice names ring {ring:?}, which is not a ring name ({source}); is the sender a nerve ring writer?")]
    BadNotice {
        /// the text in the notice
        ring: String,
        /// why it is not a ring name
        #[source]
        source: RingNameError,
    },
}

impl From<MemoryError> for AgentError {
    fn from(e: MemoryError) -> Self {
        match e {
            MemoryError::Port(p) => AgentError::Port(p),
            e @ (MemoryError::Name { .. } | MemoryError::Taken { .. }) => AgentError::Config(e.to_string()),
            e => AgentError::Other(e.to_string()),
        }
    }
}

/// How a [`RingOutput`]'s ring is made.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RingSpec {
    /// The ring's name (`cam`, `id-42`); `None` names it after the port,
    /// which then must be a valid ring name (1 to 6 of `a-z0-9_`).
    pub ring: Option<String>,
    /// Number of slots (frames kept), at least 2.
    pub slots: u32,
    /// Largest frame, in bytes.
    pub slot_capacity: usize,
    /// Where rings live and who may read them.
    pub options: RingOptions,
}

impl RingSpec {
    /// A ring named after its port, with `slots` slots of `slot_capacity` bytes.
    pub fn new(slots: u32, slot_capacity: usize) -> Self {
        RingSpec { ring: None, slots, slot_capacity, options: RingOptions::default() }
    }

    /// Names the ring (`cam`, `id-42`).
    pub fn named(mut self, ring: &str) -> Self {
        self.ring = Some(ring.to_owned());
        self
    }

    /// Creates the ring readable by the owner's group (0640).
    pub fn group_readable(mut self) -> Self {
        self.options.group_readable = true;
        self
    }
}

/// The ring a port writes: the name given, else the port's name.
pub fn ring_name_for(port: &str, ring: Option<&str>) -> Result<RingName, MemoryError> {
    let text = ring.unwrap_or(port);
    RingName::parse(text).map_err(|source| MemoryError::Name { port: port.to_owned(), source })
}

/// Declaring short-term-memory ports on a [`Setup`] (in [`crate::Agent::new`]).
pub trait MemorySetup {
    /// Declares output port `port` (type `nerve::RingNotice`) announcing the
    /// frames of a ring this agent writes.
    fn ring_output(&mut self, port: &str, spec: RingSpec) -> Result<RingOutput, AgentError>;

    /// Declares input port `port` (type `nerve::RingNotice`) whose notices
    /// name frames to read in place.
    fn ring_input(&mut self, port: &str) -> Result<RingInput, AgentError>;
}

impl MemorySetup for Setup {
    fn ring_output(&mut self, port: &str, spec: RingSpec) -> Result<RingOutput, AgentError> {
        RingOutput::declare(self, port, spec)
    }

    fn ring_input(&mut self, port: &str) -> Result<RingInput, AgentError> {
        RingInput::declare(self, port)
    }
}

/// A ring this agent writes, and the port that announces its frames.
#[derive(Debug)]
pub struct RingOutput {
    port_name: String,
    port: Output<RingNotice>,
    robot: RobotName,
    ring: RingName,
    spec: RingSpec,
    writer: Option<RingWriter>,
}

impl RingOutput {
    /// Declares output port `port` of `setup` for the ring of `spec`. The
    /// ring itself is created at the first write (or [`RingOutput::open`]).
    pub fn declare(setup: &mut Setup, port: &str, spec: RingSpec) -> Result<Self, AgentError> {
        let ring = ring_name_for(port, spec.ring.as_deref())?;
        let robot = setup.world().robot().clone();
        // refuse a ring someone else writes now, while `nerve start` still
        // reports startup errors (best effort: the writer lock decides)
        if let Ok(r) = RingReader::open_with(&spec.options, &robot, &ring)
            && let Some(pid) = r.writer_pid().filter(|p| *p != std::process::id())
            && r.writer_alive()
        {
            return Err(MemoryError::Taken { ring: ring.to_string(), pid }.into());
        }
        let out = setup.output::<RingNotice>(port)?;
        Ok(RingOutput { port_name: port.to_owned(), port: out, robot, ring, spec, writer: None })
    }

    /// Creates (or, after a restart, re-opens) the ring now, if not done yet.
    ///
    /// A ring left by an earlier writer with another geometry (say, another
    /// image size) is removed and created anew: readers that mapped the old
    /// file keep it until they notice (see [`RingInput`]), nobody is cut off.
    pub fn open(&mut self) -> Result<&mut RingWriter, MemoryError> {
        if self.writer.is_none() {
            let s = &self.spec;
            let w = match RingWriter::create_with(&s.options, &self.robot, &self.ring, s.slots, s.slot_capacity) {
                Err(CreateError::GeometryMismatch { path, existing_slots, existing_capacity, .. }) => {
                    // the writer lock was free (else WriterExists): nobody
                    // writes this old ring any more; replace its file
                    tracing::warn!(
                        ring = %self.ring,
                        "ring {} exists with {existing_slots} slots of {existing_capacity} bytes; replacing it by {} slots of {} bytes",
                        path.display(), s.slots, s.slot_capacity
                    );
                    let _ = std::fs::remove_file(&path);
                    RingWriter::create_with(&s.options, &self.robot, &self.ring, s.slots, s.slot_capacity)?
                }
                Err(CreateError::WriterExists { pid, .. }) => {
                    return Err(MemoryError::Taken { ring: self.ring.to_string(), pid });
                }
                other => other?,
            };
            self.writer = Some(w);
        }
        match self.writer.as_mut() {
            Some(w) => Ok(w),
            None => unreachable!("set just above"),
        }
    }

    /// Makes sure a slot holds `len` bytes. Before the ring is open this only
    /// raises the capacity it will be created with; once it is open and too
    /// small, the ring is replaced by a larger one (new file, sequence from
    /// 1; readers map the new file when they notice, see [`RingInput`]).
    /// Agents whose frame size is known only from their input (an image
    /// filter) call this before each write; it costs a comparison.
    pub fn reserve(&mut self, len: usize) -> Result<(), MemoryError> {
        if len <= self.spec.slot_capacity {
            return Ok(());
        }
        tracing::info!(ring = %self.ring, "frames of {len} bytes: slots grow from {} bytes", self.spec.slot_capacity);
        self.spec.slot_capacity = len;
        if let Some(w) = self.writer.take() {
            // we are the writer: nobody else can be using the file for writing
            let path = w.path().to_owned();
            w.remove().map_err(|source| {
                MemoryError::Create(CreateError::Os { what: "cannot remove the outgrown ring", path, source })
            })?;
            self.open()?;
        }
        Ok(())
    }

    /// Stores a copy of `data` as the next frame, then announces it.
    pub fn write(&mut self, desc: FrameDesc, data: &[u8]) -> Result<RingNotice, MemoryError> {
        self.write_with(desc, data.len(), |buf| buf.copy_from_slice(data))
    }

    /// Stores the next frame of `len` bytes, written in place by `fill`
    /// straight into shared memory, then announces it on the port. `fill`
    /// gets exactly `len` bytes holding an older frame: it must write every
    /// byte it means to publish.
    pub fn write_with(
        &mut self,
        desc: FrameDesc,
        len: usize,
        fill: impl FnOnce(&mut [u8]),
    ) -> Result<RingNotice, MemoryError> {
        let notice = self.open()?.write_with(desc, len, fill)?;
        self.port.send(notice)?;
        Ok(notice)
    }

    /// Announces a frame again (or a frame stored by [`RingOutput::writer_mut`]).
    pub fn announce(&self, notice: RingNotice) -> Result<(), MemoryError> {
        Ok(self.port.send(notice)?)
    }

    /// The ring's name.
    pub fn ring(&self) -> &RingName {
        &self.ring
    }

    /// The output port's name.
    pub fn port_name(&self) -> &str {
        &self.port_name
    }

    /// The ring's geometry and options.
    pub fn spec(&self) -> &RingSpec {
        &self.spec
    }

    /// The writer, once the ring is open.
    pub fn writer(&self) -> Option<&RingWriter> {
        self.writer.as_ref()
    }

    /// The writer, once the ring is open (to store without announcing).
    pub fn writer_mut(&mut self) -> Option<&mut RingWriter> {
        self.writer.as_mut()
    }
}

/// An input of ring notices, and the rings they name, each mapped once.
#[derive(Debug)]
pub struct RingInput {
    input: Input<RingNotice>,
    robot: RobotName,
    options: RingOptions,
    readers: HashMap<RingName, RingReader>,
}

impl RingInput {
    /// Declares input port `port` of `setup`.
    pub fn declare(setup: &mut Setup, port: &str) -> Result<Self, AgentError> {
        let input = setup.input::<RingNotice>(port)?;
        Ok(RingInput {
            input,
            robot: setup.world().robot().clone(),
            options: RingOptions::default(),
            readers: HashMap::new(),
        })
    }

    /// The same, reading rings under `options.base_dir`.
    pub fn with_options(mut self, options: RingOptions) -> Self {
        self.options = options;
        self.readers.clear();
        self
    }

    /// The input port itself (sources, raw notices).
    pub fn input(&self) -> &Input<RingNotice> {
        &self.input
    }

    /// Takes the next waiting notice.
    pub fn recv(&self) -> Option<(Meta, RingNotice)> {
        self.input.recv()
    }

    /// Takes every waiting notice and returns the newest (by stamp), if any.
    pub fn latest_notice(&self) -> Option<(Meta, RingNotice)> {
        self.input.latest()
    }

    /// The reader of `ring`, opened (mapped) at its first use and kept.
    pub fn reader(&mut self, ring: &RingName) -> Result<&RingReader, MemoryError> {
        if !self.readers.contains_key(ring) {
            let r = RingReader::open_with(&self.options, &self.robot, ring)?;
            self.readers.insert(*ring, r);
        }
        match self.readers.get(ring) {
            Some(r) => Ok(r),
            None => unreachable!("inserted just above"),
        }
    }

    /// How many rings this input has mapped.
    pub fn open_rings(&self) -> usize {
        self.readers.len()
    }

    /// The reader of the ring file `notice` names. A notice carries the
    /// creation id of the file its frame is in; when the cached mapping is
    /// of another file (the ring was replaced since it was mapped), the
    /// ring is mapped again. A notice of a file that is gone (sent before
    /// the ring was replaced) is refused with `ReadError::OtherRing`: its
    /// sequence number would name another frame in the current file.
    pub fn reader_for(&mut self, notice: &RingNotice) -> Result<&RingReader, MemoryError> {
        let ring = ring_of(notice)?;
        if self.reader(&ring)?.check_notice(notice).is_err() && self.refresh_if_stale(&ring) {
            tracing::debug!(ring = %ring, seq = notice.seq, "a notice of another ring file; mapped the ring again");
        }
        let r = self.reader(&ring)?;
        r.check_notice(notice)?;
        Ok(r)
    }

    /// Reads the frame `notice` names, in place: `f` gets its description
    /// and its bytes in shared memory.
    ///
    /// As with [`RingReader::read_with`], the bytes are speculative while
    /// `f` runs: compute (into your own buffers), don't act; only an `Ok`
    /// result proves `f` saw the frame intact. The frame is read from the
    /// ring file the notice names (see [`RingInput::reader_for`]): a notice
    /// of a ring replaced since (another geometry) is refused, never
    /// resolved in another file.
    pub fn read_notice_with<R>(
        &mut self,
        notice: &RingNotice,
        f: impl FnOnce(&FrameMeta, &[u8]) -> R,
    ) -> Result<R, MemoryError> {
        Ok(self.reader_for(notice)?.read_with(notice.seq, f)?)
    }

    /// Copies the frame `notice` names into `buf` (validated) and returns
    /// its description; the same checks as [`RingInput::read_notice_with`].
    pub fn read_notice_into(&mut self, notice: &RingNotice, buf: &mut Vec<u8>) -> Result<FrameMeta, MemoryError> {
        Ok(self.reader_for(notice)?.read_into(notice.seq, buf)?)
    }

    /// Takes every waiting notice and reads the newest frame in place:
    /// `Ok(None)` when no notice was waiting. If that frame was overwritten
    /// before it could be read (this agent is slower than the writer), or
    /// its ring was replaced since (the notice names a file that is gone),
    /// the newest frame of the ring's current file is read instead. Same
    /// rules for `f` as [`RingInput::read_notice_with`].
    pub fn latest_with<R>(&mut self, mut f: impl FnMut(&FrameMeta, &[u8]) -> R) -> Result<Option<R>, MemoryError> {
        let Some((_, notice)) = self.latest_notice() else { return Ok(None) };
        match self.read_notice_with(&notice, &mut f) {
            Ok(r) => Ok(Some(r)),
            Err(MemoryError::Read(ReadError::Overwritten { .. } | ReadError::OtherRing { .. })) => {
                let ring = ring_of(&notice)?;
                Ok(Some(self.reader(&ring)?.latest_with(f)?))
            }
            Err(e) => Err(e),
        }
    }

    /// Drops the reader of `ring` if its file was removed or replaced;
    /// returns whether it did (the next use maps the new file).
    fn refresh_if_stale(&mut self, ring: &RingName) -> bool {
        if self.readers.get(ring).is_some_and(RingReader::is_stale) {
            tracing::info!(ring = %ring, "ring file was replaced; mapping it again");
            self.readers.remove(ring);
            true
        } else {
            false
        }
    }
}

fn ring_of(notice: &RingNotice) -> Result<RingName, MemoryError> {
    RingName::from_notice(notice)
        .map_err(|source| MemoryError::BadNotice { ring: notice.ring.as_str().to_owned(), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_named_after_port_or_given() {
        assert_eq!(ring_name_for("cam", None).expect("cam").to_string(), "cam");
        assert_eq!(ring_name_for("frames", Some("cam")).expect("given").to_string(), "cam");
        assert_eq!(ring_name_for("frames", Some("id-7")).expect("id").as_id(), Some(7));
        let e = ring_name_for("camera_left", None).expect_err("too long");
        assert!(e.to_string().contains("camera_left") && e.to_string().contains("6"), "{e}");
        assert!(ring_name_for("x", Some("Cam")).is_err());
    }

    /// Review R18: a ring replaced for another geometry starts its sequence
    /// at 1 again. A reader that still maps the old file must not resolve a
    /// notice of the new ring there (the old frame would come back as the
    /// new one), nor a notice of the old ring in the new file.
    #[test]
    fn notices_resolve_only_in_the_ring_file_that_announced_them() {
        use crate::world::World;
        use crate::world::test_support::Cleanup;
        use shm_schemas::AgentName;
        use std::sync::Arc;

        let world = World::new(&format!("r18m{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let node = Arc::new(world.node("t").expect("node"));
        let mut setup =
            Setup::new(world.clone(), AgentName::new("t").expect("name"), crate::agent::Binding::Shm(node), Vec::new());
        let mut out = setup.ring_output("frames", RingSpec::new(4, 64).named("r18")).expect("ring output");
        let mut input = setup.ring_input("in").expect("ring input");
        let old: Vec<RingNotice> =
            (1..=3u8).map(|k| out.write(FrameDesc::raw(), &[k; 64]).expect("old frame")).collect();
        // the reader maps the old ring
        assert_eq!(input.read_notice_with(&old[2], |m, b| (m.seq, b[0])).expect("old frame 3"), (3, 3));

        // the writer outgrows it: a new file, sequence from 1 again
        out.reserve(200).expect("replace the ring");
        let new1 = out.write(FrameDesc::raw(), &[101; 200]).expect("new frame 1");
        assert_eq!(new1.seq, 1);
        assert_ne!(new1.creation_id, old[0].creation_id, "a new ring file has a new creation id");
        let got = input.read_notice_with(&new1, |m, b| (m.len, b[0])).expect("the new frame 1");
        assert_eq!(got, (200, 101), "notice 1 of the new ring resolved in the old file");
        let mut buf = Vec::new();
        assert_eq!(input.read_notice_into(&new1, &mut buf).expect("copy").len, 200);
        assert_eq!(buf[0], 101);

        // a notice of the old ring, read late, names a frame that is gone;
        // the new file has a frame 2 too, which is another frame
        let new2 = out.write(FrameDesc::raw(), &[102; 200]).expect("new frame 2");
        let stale = input.read_notice_with(&old[1], |_, b| b[0]);
        assert!(
            matches!(stale, Err(MemoryError::Read(ReadError::OtherRing { seq: 2, .. }))),
            "an old notice must be refused, not resolved in the new file: {stale:?}"
        );
        let msg = stale.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(msg.contains("replaced") && msg.contains("r18"), "{msg}");
        assert!(input.read_notice_into(&old[0], &mut buf).is_err());
        assert_eq!(input.read_notice_with(&new2, |_, b| b[0]).expect("new frame 2"), 102);
        assert_eq!(input.open_rings(), 1);
    }

    #[test]
    fn errors_map_to_agent_errors() {
        let e: AgentError = MemoryError::Taken { ring: "cam".into(), pid: 42 }.into();
        assert!(matches!(e, AgentError::Config(ref m) if m.contains("pid 42")), "{e}");
        let e: AgentError = MemoryError::Read(ReadError::ZeroSeq).into();
        assert!(matches!(e, AgentError::Other(_)), "{e}");
    }
}
