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

pub mod foxglove;

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
    /// Starts a file (uncompressed: recording must cost the robot next to nothing).
    pub fn new(out: W) -> Result<Self, RecordingError> {
        let mcap = mcap::WriteOptions::new().compression(None).profile("").create(out)?;
        Ok(RecordingWriter { mcap, image_schema: None })
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
