//! Short-term memory rings: stamped circular buffers of large data (camera
//! frames, masks, maps) in shared memory.
//!
//! The thesis' short-term memory is "a large piece of memory \[that\] stores
//! the recent variables" as circular buffers, each "identified with an
//! unsigned long integer, or a six characters name"; large data travels as
//! "a link and a signal". In nerve:
//!
//! * a ring is a file `/dev/shm/nerve_<uid>_<robot>_stm_<name>` ([`RingName`]:
//!   `cam` or `id-42`) of fixed-size slots, created by its single
//!   [`RingWriter`] (an exclusive `flock` keeps it single);
//! * each frame gets a sequence number (from 1) and a CLOCK_MONOTONIC stamp;
//!   the writer overwrites the oldest slot;
//! * the writer then publishes the returned [`RingNotice`] (the link and
//!   the signal) on an ordinary nerve port;
//! * any number of [`RingReader`]s map the ring once and read frames in place
//!   ([`RingReader::read_with`]) or by copy, by sequence number, latest,
//!   nearest to a time, or the last k. A per-slot seqlock guarantees that a
//!   reader never gets a torn frame: it gets [`ReadError::Overwritten`] or
//!   [`ReadError::Incomplete`] instead. Readers never block the writer and
//!   keep no state in shared memory.
//!
//! The layout lives in [`shm_schemas::ring`]; the protocol is described in
//! `docs/short-term-memory.md` and in the docs of `writer` and `reader`.
//!
//! ```no_run
//! use nerve_stm::{FrameDesc, RingName, RingReader, RingWriter};
//! use shm_schemas::{RobotName, ring::PixelFormat};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let robot = RobotName::new("h1")?;
//! let cam = RingName::parse("cam")?;
//! let mut w = RingWriter::create(&robot, &cam, 8, 320 * 240 * 3)?;
//! let notice = w.write_with(FrameDesc::image(320, 240, PixelFormat::Rgb8), 320 * 240 * 3, |buf| {
//!     buf.fill(0x80); // render the frame here, in shared memory
//! })?;
//! // ... publish `notice` on a port; a reader elsewhere:
//! let r = RingReader::open(&robot, &cam)?;
//! let mean = r.read_with(notice.seq, |_meta, px| px.iter().map(|&b| u64::from(b)).sum::<u64>())?;
//! # let _ = mean; Ok(()) }
//! ```

mod dump;
mod error;
mod list;
mod name;
mod reader;
mod sys;
mod writer;

pub use dump::{DumpError, FrameSelector, dump_png, encode_png, hsi8_to_rgb8};
pub use error::{CreateError, OpenError, ReadError, WriteError};
pub use list::{ListedRing, RingInfo, list_rings, list_rings_with};
pub use name::{RING_ID_PREFIX, RING_NAME_MAX_LEN, RingName, RingNameError};
pub use reader::{Frame, FrameMeta, RingReader};
pub use shm_schemas::ring::{PixelFormat, RingNotice};
pub use sys::monotonic_ns;
pub use writer::{MAX_SLOT_CAPACITY, MAX_SLOTS, MIN_SLOTS, RingWriter};

use std::path::PathBuf;

/// The directory where rings live by default.
pub const DEFAULT_BASE_DIR: &str = "/dev/shm";

/// Where rings live and who may read them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RingOptions {
    /// Directory of the ring files; `/dev/shm` by default (tests use their own).
    pub base_dir: PathBuf,
    /// Create ring files readable by the owner's group (mode 0640) instead
    /// of by the owner only (0600, the default). Only the writer ever writes.
    pub group_readable: bool,
}

impl Default for RingOptions {
    fn default() -> Self {
        RingOptions { base_dir: PathBuf::from(DEFAULT_BASE_DIR), group_readable: false }
    }
}

impl RingOptions {
    /// The file mode rings are created with.
    pub fn mode(&self) -> u32 {
        if self.group_readable { 0o640 } else { 0o600 }
    }
}

/// How the writer describes a frame it stores.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameDesc {
    /// Image width in pixels (0 for raw data).
    pub width: u32,
    /// Image height in pixels (0 for raw data).
    pub height: u32,
    /// Pixel format; [`PixelFormat::Raw`] for anything that is not an image.
    pub format: PixelFormat,
    /// The stamp to store; `None` stamps the frame with the CLOCK_MONOTONIC
    /// time at which it is stored (when it becomes visible).
    pub stamp_ns: Option<u64>,
}

impl FrameDesc {
    /// Opaque bytes, stamped when stored.
    pub fn raw() -> Self {
        FrameDesc { width: 0, height: 0, format: PixelFormat::Raw, stamp_ns: None }
    }

    /// An image, stamped when stored.
    pub fn image(width: u32, height: u32, format: PixelFormat) -> Self {
        FrameDesc { width, height, format, stamp_ns: None }
    }

    /// The same frame with an explicit stamp (e.g. the camera's capture time).
    pub fn stamped(self, stamp_ns: u64) -> Self {
        FrameDesc { stamp_ns: Some(stamp_ns), ..self }
    }
}
