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
//!
//! `--ros2` writes a rosbag2 MCAP instead (`FILE-ros2.mcap`): profile
//! `ros2`, the ports whose types map to standard ROS 2 messages
//! ([`nerve_ros2::bag`]: odometry, ground truth, velocity commands, the
//! sonar ring; camera frames as `sensor_msgs/Image`,
//! [`nerve_ros2::bag_image`]) as CDR messages with `ros2msg` schemas, each channel's
//! `offered_qos_profiles`, and the `rosbag2` metadata record rosbag2
//! writes; `ros2 bag info/play` and the `rosbags` library read it. Ports of
//! other types are left out, and named.

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
    /// The file to write (default: FILE's name with `-json.mcap`, or
    /// `-ros2.mcap` with --ros2).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// Write a ROS 2 bag (rosbag2 MCAP: CDR messages of the standard types
    /// nerve's odometry, velocity and sonar map to) instead of JSON.
    #[arg(long)]
    pub ros2: bool,
}

/// What a channel of the input becomes.
enum Out {
    /// decoded through its schema into this channel
    Json { channel: u16, schema: Schema },
    /// copied into this channel
    Copy { channel: u16 },
}

fn default_output(file: &Path, suffix: &str) -> PathBuf {
    let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or("recording");
    file.with_file_name(format!("{stem}-{suffix}.mcap"))
}

pub fn export(a: ExportArgs) -> Result<ExitCode> {
    if a.ros2 {
        return export_ros2(a);
    }
    let file = a.file.display().to_string();
    let mut reader = RecordingReader::open(&a.file)?;
    let output = a.output.clone().unwrap_or_else(|| default_output(&a.file, "json"));
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

/// A channel of the recording that goes into the bag.
struct RosChannel {
    channel: u16,
    /// a sample's layout and conversion; `None`: a camera frame
    /// (`foxglove.RawImage`) to `sensor_msgs/Image` (`nerve_ros2::bag_image`)
    sample: Option<(Schema, nerve_ros2::bag::BagMap)>,
    topic: nerve_ros2::bag::TopicCount,
}

/// `nerve export --ros2`: the recording as a rosbag2 MCAP file.
fn export_ros2(a: ExportArgs) -> Result<ExitCode> {
    use nerve_ros2::bag;
    let file = a.file.display().to_string();
    let mut reader = RecordingReader::open(&a.file)?;
    let output = a.output.clone().unwrap_or_else(|| default_output(&a.file, "ros2"));
    if output == a.file {
        bail!("-o names the recording itself; give another file");
    }
    let out_file = std::fs::File::create(&output).with_context(|| format!("cannot create {}", output.display()))?;
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .profile(bag::PROFILE)
        .library(format!("nerve-{}", env!("CARGO_PKG_VERSION")))
        .chunk_size(Some(nerve_recording::CHUNK_SIZE))
        .create(BufWriter::new(out_file))?;
    let mut channels: BTreeMap<u16, RosChannel> = BTreeMap::new();
    let mut schemas: BTreeMap<&'static str, u16> = BTreeMap::new();
    let mut left_out: Vec<String> = Vec::new();
    let (mut start, mut end) = (u64::MAX, 0u64);
    while let Some(event) = reader.next_event()? {
        let m = match event {
            Event::Channel(ch) => {
                let nerve_type = ch.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default();
                let image = nerve_type == nerve_ros2::bag_image::RAW_IMAGE
                    && ch.message_encoding == nerve_ros2::bag_image::RAW_IMAGE_ENCODING;
                let mapped = ch
                    .schema
                    .as_ref()
                    .filter(|s| ch.message_encoding == MESSAGE_ENCODING && s.encoding == SCHEMA_ENCODING)
                    .and_then(|_| bag::mapping_of(&nerve_type))
                    .map(|(r, m)| (r, Some(m)))
                    .or(image.then_some((nerve_ros2::bag_image::ROS_IMAGE, None)));
                let Some((ros_type, map)) = mapped else {
                    left_out.push(format!(
                        "{} ({})",
                        ch.topic,
                        if nerve_type.is_empty() { "no schema" } else { &nerve_type }
                    ));
                    continue;
                };
                let sample = match map {
                    Some(map) => Some((nerve_schema(&file, &ch)?, map)),
                    None => None,
                };
                let schema_id = match schemas.get(ros_type) {
                    Some(id) => *id,
                    None => {
                        let def = bag::msg_definition(ros_type).ok_or_else(|| {
                            anyhow!("{ros_type} is not among the vendored messages (agents/ros2/msg)")
                        })?;
                        let id = w.add_schema(ros_type, bag::SCHEMA_ENCODING, def.as_bytes())?;
                        schemas.insert(ros_type, id);
                        id
                    }
                };
                let topic = bag::ros_topic(&ch.topic);
                let qos = bag::offered_qos(10, false);
                let metadata = BTreeMap::from([("offered_qos_profiles".to_string(), qos.clone())]);
                let channel = w.add_channel(schema_id, &topic, bag::MESSAGE_ENCODING, &metadata)?;
                let topic = bag::TopicCount { topic, ros_type: ros_type.to_string(), qos, count: 0 };
                channels.insert(ch.id, RosChannel { channel, sample, topic });
                continue;
            }
            Event::Message(m) => m,
        };
        let Some(c) = channels.get_mut(&m.channel.id) else { continue };
        let cdr = match &c.sample {
            Some((schema, map)) => {
                let value = schema.decode(m.data).map_err(|e| {
                    anyhow!("{file}: a message of {} does not decode ({e}); the file is damaged", m.channel.topic)
                })?;
                bag::encode(*map, &serde_json::to_value(&value)?, m.log_time).with_context(|| {
                    format!("{file}: a message of {} cannot be a {}", m.channel.topic, c.topic.ros_type)
                })?
            }
            None => nerve_ros2::bag_image::raw_image_to_ros(m.data, m.log_time)
                .with_context(|| format!("{file}: a frame of {} cannot be a {}", m.channel.topic, c.topic.ros_type))?,
        };
        let header = mcap::records::MessageHeader {
            channel_id: c.channel,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        w.write_to_known_channel(&header, &cdr)?;
        c.topic.count += 1;
        start = start.min(m.log_time);
        end = end.max(m.log_time);
    }
    if channels.is_empty() {
        drop(w);
        let _ = std::fs::remove_file(&output);
        bail!(
            "{file} has no port whose type a ROS 2 bag can carry (it has {}); the types that map: {}",
            if left_out.is_empty() { "no ports".to_string() } else { left_out.join(", ") },
            bag::BAG_MAPS.iter().map(|(n, r, _)| format!("{n} -> {r}")).collect::<Vec<_>>().join(", ")
        );
    }
    if start > end {
        start = end;
    }
    let name = output.file_name().and_then(|n| n.to_str()).unwrap_or("bag.mcap");
    let topics: Vec<bag::TopicCount> = channels.values().map(|c| c.topic.clone()).collect();
    let yaml = bag::metadata_yaml(name, start, end, &topics);
    w.write_metadata(&mcap::records::Metadata {
        name: "rosbag2".into(),
        metadata: BTreeMap::from([
            ("serialized_metadata".to_string(), yaml),
            ("ROS_DISTRO".to_string(), "jazzy".to_string()),
        ]),
    })?;
    w.finish().with_context(|| format!("cannot finish {}", output.display()))?;
    if let Some(cut) = reader.cut() {
        eprintln!("warning: {cut}");
    }
    let total: u64 = topics.iter().map(|t| t.count).sum();
    println!(
        "exported {} to {} (a ROS 2 bag): {total} messages on {} topics ({}){}",
        a.file.display(),
        output.display(),
        topics.len(),
        topics.iter().map(|t| format!("{} {} x{}", t.topic, t.ros_type, t.count)).collect::<Vec<_>>().join(", "),
        if left_out.is_empty() { String::new() } else { format!("; left out, no ROS 2 type: {}", left_out.join(", ")) }
    );
    Ok(ExitCode::SUCCESS)
}
