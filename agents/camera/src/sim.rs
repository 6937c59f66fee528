//! The simulator backend: forwards the frames the simulator renders.
//!
//! Decision: the simulator (`nerve-sim`) renders its 320x240 RGB8 camera
//! frames into a short-term-memory ring of the same robot, named by
//! `--sim-ring` (default `simcam`). It does not announce them on a nerve
//! port. The camera agent with `--source sim` reads that ring (mapped once)
//! and, each period, copies the newest frame it has not forwarded yet into
//! its own ring (`cam`) and announces it on `frames` — exactly as with a
//! real webcam. So every downstream agent is the same against the simulator
//! and the robot, the camera agent keeps its rate, ring and port, and the
//! simulator needs no nerve port at all. The copy costs one 230 kB memcpy
//! per frame (about 20 µs).
//!
//! A missing simulator ring is a device error like a missing camera: the
//! agent says which ring it waits for and retries with backoff. A simulator
//! restart (a new ring file) is noticed and the ring is mapped again.

use crate::{Grab, Source, SourceError};
use agent_sdk::memory::stm::{OpenError, ReadError, RingReader};
use agent_sdk::memory::{FrameDesc, PixelFormat, RingName, RingOutput};
use shm_schemas::RobotName;

/// Reads the simulator's camera ring.
#[derive(Debug)]
pub struct SimSource {
    reader: RingReader,
    ring: RingName,
    forwarded: u64,
    generation: u64,
    buf: Vec<u8>,
}

impl SimSource {
    /// Opens ring `ring` of `robot`, written by the simulator.
    pub fn open(robot: &RobotName, ring: &RingName) -> Result<Self, SourceError> {
        let reader = RingReader::open(robot, ring).map_err(|e| match e {
            OpenError::NotFound { path, .. } => SourceError::Device(format!(
                "no simulator camera: ring {ring} ({}) does not exist; start the simulator for robot {robot} with its camera ring named {ring} (or pass --sim-ring NAME), or run with --source test-pattern",
                path.display()
            )),
            e => SourceError::Device(format!("simulator camera ring {ring}: {e}")),
        })?;
        tracing::info!(ring = %ring, "reading the simulator's camera frames from ring {ring}");
        let generation = reader.writer_generation();
        Ok(SimSource { reader, ring: *ring, forwarded: 0, generation, buf: Vec::new() })
    }
}

impl Source for SimSource {
    fn describe(&self) -> String {
        format!("simulator camera ring {}", self.ring)
    }

    fn grab(&mut self, out: &mut RingOutput, _n: u64) -> Result<Grab, SourceError> {
        let Some(last) = self.reader.last_seq() else { return Ok(Grab::Nothing) };
        let generation = self.reader.writer_generation();
        if generation != self.generation {
            // the simulator restarted on the same file: its sequence may go on or restart
            self.generation = generation;
            self.forwarded = self.forwarded.min(last.saturating_sub(1));
        }
        if last <= self.forwarded {
            if self.reader.is_stale() {
                return Err(SourceError::Device(format!(
                    "the simulator's camera ring {} was replaced (simulator restarted); mapping it again",
                    self.ring
                )));
            }
            return Ok(Grab::Nothing);
        }
        let meta = match self.reader.latest_into(&mut self.buf) {
            Ok(m) => m,
            Err(ReadError::Empty { .. } | ReadError::InProgress { .. } | ReadError::Overwritten { .. }) => {
                return Ok(Grab::Nothing);
            }
            Err(e) => return Err(SourceError::Device(format!("simulator camera ring {}: {e}", self.ring))),
        };
        if meta.format() != Some(PixelFormat::Rgb8) {
            return Err(SourceError::Device(format!(
                "the simulator's ring {} holds {:?} frames; the camera agent forwards rgb8 only",
                self.ring,
                meta.format()
            )));
        }
        let desc = FrameDesc::image(meta.width, meta.height, PixelFormat::Rgb8).stamped(meta.stamp_ns);
        if meta.len > out.spec().slot_capacity {
            return Err(SourceError::Device(format!(
                "the simulator renders {}x{} frames, larger than this camera's {} byte slots; start the camera with --width {} --height {}",
                meta.width,
                meta.height,
                out.spec().slot_capacity,
                meta.width,
                meta.height
            )));
        }
        out.write(desc, &self.buf)?;
        self.forwarded = meta.seq;
        Ok(Grab::Frame)
    }
}
