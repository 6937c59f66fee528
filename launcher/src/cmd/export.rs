//! `nerve export`: a recording for viewers that read JSON.
//!
//! `nerve record` keeps each sample's bytes (`nerve.raw`), which replay
//! gives back bit-exact but Foxglove and Lichtblick cannot plot. This
//! writes a second file where every port's channel has a JSON Schema
//! (`jsonschema`) and every message is the sample as JSON (`json`),
//! decoded through the nerve schema in the recording, with the same times
//! and sequence numbers; image channels (`foxglove.RawImage`) are copied
//! as they are. The original stays the record.
//!
//! The recording is streamed ([`nerve_recording::read`]), a message at a
//! time, so a file of any size exports in the memory of one message; a file
//! cut short (the recorder was killed, the disk filled) is exported up to
//! its last whole message, with a warning that says what was lost, and the
//! export itself is whole.

use anyhow::{Context as _, Result, anyhow, bail};
use nerve_recording::read::{Event, RecordingReader, nerve_schema};
use nerve_recording::{MESSAGE_ENCODING, SCHEMA_ENCODING, json};
use shm_schemas::Schema;
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `nerve export`
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// A recording written by `nerve record` or `nerve snapshot`.
    pub file: PathBuf,
    /// The file to write (default: FILE's name with `-json.mcap`).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
}

/// What a channel of the input becomes.
enum Out {
    /// decoded through its schema into this channel
    Json { channel: u16, schema: Schema },
    /// copied into this channel
    Copy { channel: u16 },
}

fn default_output(file: &Path) -> PathBuf {
    let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or("recording");
    file.with_file_name(format!("{stem}-json.mcap"))
}

pub fn export(a: ExportArgs) -> Result<ExitCode> {
    let file = a.file.display().to_string();
    let mut reader = RecordingReader::open(&a.file)?;
    let output = a.output.clone().unwrap_or_else(|| default_output(&a.file));
    if output == a.file {
        bail!("-o names the recording itself; give another file");
    }
    let out_file = std::fs::File::create(&output).with_context(|| format!("cannot create {}", output.display()))?;
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .profile("")
        .chunk_size(Some(nerve_recording::CHUNK_SIZE))
        .create(BufWriter::new(out_file))?;
    let mut channels: BTreeMap<u16, Out> = BTreeMap::new();
    let (mut messages, mut copied) = (0u64, 0u64);
    let mut text = Vec::new();
    while let Some(event) = reader.next_event()? {
        let m = match event {
            Event::Channel(ch) => {
                let metadata: BTreeMap<String, String> = ch.metadata.clone();
                let out = match ch.schema.as_ref() {
                    Some(s) if ch.message_encoding == MESSAGE_ENCODING && s.encoding == SCHEMA_ENCODING => {
                        let schema = nerve_schema(&file, &ch)?;
                        let js = serde_json::to_vec(&json::json_schema(&schema))?;
                        let id = w.add_schema(&s.name, json::SCHEMA_ENCODING, &js)?;
                        Out::Json { channel: w.add_channel(id, &ch.topic, json::MESSAGE_ENCODING, &metadata)?, schema }
                    }
                    Some(s) => {
                        let id = w.add_schema(&s.name, &s.encoding, &s.data)?;
                        Out::Copy { channel: w.add_channel(id, &ch.topic, &ch.message_encoding, &metadata)? }
                    }
                    None => Out::Copy { channel: w.add_channel(0, &ch.topic, &ch.message_encoding, &metadata)? },
                };
                channels.insert(ch.id, out);
                continue;
            }
            Event::Message(m) => m,
        };
        let header = |channel_id: u16| mcap::records::MessageHeader {
            channel_id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        match channels.get(&m.channel.id) {
            Some(Out::Json { channel, schema }) => {
                let value = schema.decode(m.data).map_err(|e| {
                    anyhow!("{file}: a message of {} does not decode ({e}); the file is damaged", m.channel.topic)
                })?;
                text.clear();
                serde_json::to_writer(&mut text, &value)?;
                w.write_to_known_channel(&header(*channel), &text)?;
                messages += 1;
            }
            Some(Out::Copy { channel }) => {
                w.write_to_known_channel(&header(*channel), m.data)?;
                copied += 1;
            }
            None => {}
        }
    }
    w.finish().with_context(|| format!("cannot finish {}", output.display()))?;
    if let Some(cut) = reader.cut() {
        eprintln!("warning: {cut}");
    }
    println!(
        "exported {} to {}: {messages} messages as JSON, {copied} copied as they were ({} channels)",
        a.file.display(),
        output.display(),
        channels.len()
    );
    Ok(ExitCode::SUCCESS)
}
