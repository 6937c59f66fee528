//! nerve's recording format, written by `nerve record` and the black box
//! (`nerve snapshot`), read by `nerve replay` and `nerve plot`.
//!
//! An MCAP file with one channel per output port, topic `AGENT/PORT`:
//! each message is a sample's bytes exactly as they were in shared memory
//! (message encoding [`MESSAGE_ENCODING`]), its schema the nerve
//! [`Schema`] as JSON ([`SCHEMA_ENCODING`]), the channel's metadata naming
//! the robot, agent, port, type and layout fingerprint. A message's log
//! time is when it was taken (CLOCK_REALTIME), its publish time the
//! sample's own stamp (CLOCK_MONOTONIC), its sequence the sender's
//! sequence number (low 32 bits). `docs/payloads.md` says why raw bytes.
//!
//! Frames of short-term-memory rings go on a channel of their own, topic
//! `AGENT/PORT/image` beside the port that carried the ring notices, as
//! `foxglove.RawImage` in protobuf ([`foxglove`]), which Foxglove and
//! Lichtblick show as images.
//!
//! The file is written in chunks of at most [`CHUNK_SIZE`] bytes (a larger
//! message makes a chunk of its own); [`RecordingWriter::flush`] closes the
//! open chunk. A file whose writer was stopped before [`RecordingWriter::finish`]
//! (killed, out of memory or disk) is read by [`read`] up to its last whole
//! message, and by other MCAP readers up to its last closed chunk.

pub mod foxglove;
pub mod json;
pub mod read;

use shm_schemas::Schema;
use shm_schemas::services::port_attributes::fingerprint_text;
use std::collections::BTreeMap;
use std::io::{Seek, Write};

/// The message encoding of a port's samples: the `#[repr(C)]` payload's
/// bytes (little-endian).
pub const MESSAGE_ENCODING: &str = "nerve.raw";
/// The schema encoding of a port's channel: a [`Schema`] as JSON.
pub const SCHEMA_ENCODING: &str = "nerve.schema+json";
/// Topic suffix of a ring's images, after the notice port's `AGENT/PORT`.
pub const IMAGE_TOPIC_SUFFIX: &str = "/image";

/// The size at which a chunk is closed and the next begun (uncompressed
/// bytes). Smaller than mcap's default (1 MiB), so that readers that take
/// only closed chunks lose less of a file cut short.
pub const CHUNK_SIZE: u64 = 256 * 1024;

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The MCAP writer failed (the disk is full, the file went away).
    #[error("cannot write the MCAP file: {0}")]
    Mcap(#[from] mcap::McapError),
    /// A schema did not serialize.
    #[error("cannot write the schema of {type_name}: {source}")]
    Schema {
        /// the type
        type_name: String,
        /// why
        source: serde_json::Error,
    },
}

impl RecordingError {
    /// The I/O error under it, when the output failed (a full disk, a
    /// file over its size limit).
    pub fn io(&self) -> Option<&std::io::Error> {
        match self {
            RecordingError::Mcap(mcap::McapError::Io(e)) => Some(e),
            _ => None,
        }
    }
}

/// What identifies a recorded port.
#[derive(Debug, Clone)]
pub struct PortChannel<'a> {
    /// the robot
    pub robot: &'a str,
    /// the agent that owns the port
    pub agent: &'a str,
    /// the output port
    pub port: &'a str,
    /// its type name
    pub type_name: &'a str,
    /// its layout fingerprint
    pub fingerprint: u64,
    /// its schema
    pub schema: &'a Schema,
}

/// A sample to write.
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a> {
    /// the sender's sequence number
    pub seq: u64,
    /// when it was taken, CLOCK_REALTIME ns
    pub log_time_ns: u64,
    /// the sample's stamp, CLOCK_MONOTONIC ns
    pub stamp_ns: u64,
    /// its bytes
    pub bytes: &'a [u8],
}

/// An MCAP file being written in nerve's format.
pub struct RecordingWriter<W: Write + Seek> {
    mcap: mcap::Writer<W>,
    image_schema: Option<u16>,
}

impl<W: Write + Seek> std::fmt::Debug for RecordingWriter<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordingWriter").finish_non_exhaustive()
    }
}

impl<W: Write + Seek> RecordingWriter<W> {
    /// Starts a file (uncompressed: recording must cost the robot next to
    /// nothing), in chunks of [`CHUNK_SIZE`].
    pub fn new(out: W) -> Result<Self, RecordingError> {
        Self::with_chunk_size(out, CHUNK_SIZE)
    }

    /// Starts a file in chunks of `chunk_size` bytes.
    pub fn with_chunk_size(out: W, chunk_size: u64) -> Result<Self, RecordingError> {
        let mcap = mcap::WriteOptions::new().compression(None).profile("").chunk_size(Some(chunk_size)).create(out)?;
        Ok(RecordingWriter { mcap, image_schema: None })
    }

    /// Closes the open chunk and flushes the output: what was written so
    /// far is then readable by any MCAP reader, should the writer die.
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        Ok(self.mcap.flush()?)
    }

    /// Adds a port's channel; returns its id.
    pub fn add_port(&mut self, p: &PortChannel<'_>) -> Result<u16, RecordingError> {
        let schema = serde_json::to_vec(p.schema)
            .map_err(|source| RecordingError::Schema { type_name: p.type_name.to_string(), source })?;
        let schema_id = self.mcap.add_schema(p.type_name, SCHEMA_ENCODING, &schema)?;
        let metadata = BTreeMap::from([
            ("robot".to_string(), p.robot.to_string()),
            ("agent".to_string(), p.agent.to_string()),
            ("port".to_string(), p.port.to_string()),
            ("type".to_string(), p.type_name.to_string()),
            ("fingerprint".to_string(), fingerprint_text(p.fingerprint)),
        ]);
        Ok(self.mcap.add_channel(schema_id, &format!("{}/{}", p.agent, p.port), MESSAGE_ENCODING, &metadata)?)
    }

    /// Adds the image channel of the ring whose notices `AGENT/PORT` carries.
    pub fn add_images(&mut self, robot: &str, agent: &str, port: &str) -> Result<u16, RecordingError> {
        let schema_id = match self.image_schema {
            Some(id) => id,
            None => {
                let id = self.mcap.add_schema(
                    foxglove::RAW_IMAGE,
                    foxglove::SCHEMA_ENCODING,
                    &foxglove::raw_image_descriptor_set(),
                )?;
                self.image_schema = Some(id);
                id
            }
        };
        let metadata = BTreeMap::from([
            ("robot".to_string(), robot.to_string()),
            ("agent".to_string(), agent.to_string()),
            ("port".to_string(), port.to_string()),
        ]);
        let topic = format!("{agent}/{port}{IMAGE_TOPIC_SUFFIX}");
        Ok(self.mcap.add_channel(schema_id, &topic, foxglove::MESSAGE_ENCODING, &metadata)?)
    }

    /// Writes a port's sample.
    pub fn write_sample(&mut self, channel: u16, s: &Sample<'_>) -> Result<(), RecordingError> {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: s.seq as u32,
            log_time: s.log_time_ns,
            publish_time: s.stamp_ns,
        };
        Ok(self.mcap.write_to_known_channel(&header, s.bytes)?)
    }

    /// Writes an encoded image (see [`foxglove::encode_raw_image`]).
    pub fn write_image(
        &mut self,
        channel: u16,
        seq: u64,
        log_time_ns: u64,
        encoded: &[u8],
    ) -> Result<(), RecordingError> {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: seq as u32,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        Ok(self.mcap.write_to_known_channel(&header, encoded)?)
    }

    /// Ends the file: its summary and index, then the footer.
    pub fn finish(mut self) -> Result<(), RecordingError> {
        self.mcap.finish()?;
        Ok(())
    }
}

/// What became of a noticed frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameOutcome {
    /// Encoded as a `foxglove.RawImage`; the frame's sequence number in its ring.
    Encoded(u64),
    /// The ring holds raw data, not an image: nothing to show.
    NotImage,
    /// The frame could not be read: overwritten before it was read, or the
    /// ring is gone or not a ring.
    Lost,
}

/// Reads the frames that ring notices name, and encodes them as
/// `foxglove.RawImage`: the recorder and the black box keep a port's
/// images this way. Opens the ring at the first notice, and again when a
/// notice names another ring or a newer file of it.
#[derive(Debug)]
pub struct RingFrames {
    robot: shm_schemas::RobotName,
    agent: String,
    reader: Option<nerve_stm::RingReader>,
    rgb: Vec<u8>,
}

impl RingFrames {
    /// For the notices that `agent` publishes on robot `robot`.
    pub fn new(robot: &shm_schemas::RobotName, agent: &str) -> RingFrames {
        RingFrames { robot: robot.clone(), agent: agent.to_string(), reader: None, rgb: Vec::new() }
    }

    /// Encodes into `buf` the frame that the notice in `notice_bytes`
    /// names; its time is the frame's stamp on the wall clock, found from
    /// `log_ns` (CLOCK_REALTIME, now).
    pub fn encode(&mut self, notice_bytes: &[u8], log_ns: u64, buf: &mut Vec<u8>) -> FrameOutcome {
        use nerve_stm::{PixelFormat, RingName, RingReader};
        let Some(notice) = shm_schemas::ring::RingNotice::from_bytes(notice_bytes) else { return FrameOutcome::Lost };
        let Ok(name) = RingName::from_notice(&notice) else { return FrameOutcome::Lost };
        if self.reader.as_ref().is_none_or(|r| r.name() != &name || r.check_notice(&notice).is_err()) {
            self.reader = RingReader::open(&self.robot, &name).ok();
        }
        let Some(reader) = &self.reader else { return FrameOutcome::Lost };
        let rgb = &mut self.rgb;
        let frame_id = format!("{}/{}", self.agent, name);
        let read = reader.read_with(notice.seq, |meta, px| {
            let Some((encoding, bpp)) = meta.format().and_then(foxglove::encoding_of) else { return false };
            let data: &[u8] = if meta.format() == Some(PixelFormat::Hsi8) {
                *rgb = nerve_stm::hsi8_to_rgb8(px);
                rgb
            } else {
                px
            };
            let age = nerve_stm::monotonic_ns().saturating_sub(meta.stamp_ns);
            foxglove::encode_raw_image(
                buf,
                &foxglove::RawImage {
                    unix_ns: log_ns.saturating_sub(age),
                    frame_id: &frame_id,
                    width: meta.width,
                    height: meta.height,
                    encoding,
                    step: meta.width.saturating_mul(bpp),
                    data,
                },
            );
            true
        });
        match read {
            Ok(true) => FrameOutcome::Encoded(notice.seq),
            Ok(false) => FrameOutcome::NotImage,
            Err(_) => FrameOutcome::Lost,
        }
    }
}

/// `YYYYmmdd-HHMMSS` (UTC) of CLOCK_REALTIME nanoseconds: the stamp in
/// the names of recordings and snapshots, which sort by it.
pub fn file_stamp(unix_ns: u64) -> String {
    let secs = unix_ns / 1_000_000_000;
    let (days, s) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days as i64);
    format!("{y:04}{m:02}{d:02}-{:02}{:02}{:02}", s / 3600, s / 60 % 60, s % 60)
}

/// Year, month, day of a count of days since 1970-01-01 (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn days_become_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(20_416), (2025, 11, 24));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(file_stamp(1_764_000_000_123_000_000), "20251124-160000");
    }
}
