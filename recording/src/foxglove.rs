//! Ring frames as `foxglove.RawImage`, the image message Foxglove and
//! Lichtblick show, in protobuf: the schema is the `FileDescriptorSet` of
//! `foxglove/RawImage.proto` (with `google/protobuf/timestamp.proto`), built
//! here field by field, and each message is encoded by hand: seven fields,
//! no protobuf library needed. The field numbers and types are those of
//! Foxglove's published schema.
//!
//! ```text
//! message RawImage {
//!   google.protobuf.Timestamp timestamp = 1;
//!   string frame_id = 7;
//!   fixed32 width = 2;
//!   fixed32 height = 3;
//!   string encoding = 4;   // rgb8, mono8
//!   fixed32 step = 5;      // bytes per row
//!   bytes data = 6;
//! }
//! ```
//!
//! And the mapping of nerve's pose and sonar types to Foxglove's
//! `FrameTransform` and `LaserScan` in JSON ([`mapping_of`]), and of the
//! map builder's map to a `Grid` ([`grid`]), which `nerve foxglove` offers
//! beside each such port's own JSON.

use nerve_stm::PixelFormat;

pub mod grid;

/// The schema name Foxglove knows.
pub const RAW_IMAGE: &str = "foxglove.RawImage";
/// MCAP schema encoding of a protobuf `FileDescriptorSet`.
pub const SCHEMA_ENCODING: &str = "protobuf";
/// MCAP message encoding of protobuf messages.
pub const MESSAGE_ENCODING: &str = "protobuf";

/// Protobuf wire types.
const VARINT: u8 = 0;
const LEN: u8 = 2;
const I32: u8 = 5;

fn varint(buf: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        buf.push((v as u8) | 0x80);
        v >>= 7;
    }
    buf.push(v as u8);
}

fn key(buf: &mut Vec<u8>, field: u32, wire: u8) {
    varint(buf, u64::from(field) << 3 | u64::from(wire));
}

fn bytes(buf: &mut Vec<u8>, field: u32, b: &[u8]) {
    key(buf, field, LEN);
    varint(buf, b.len() as u64);
    buf.extend_from_slice(b);
}

fn uint(buf: &mut Vec<u8>, field: u32, v: u64) {
    key(buf, field, VARINT);
    varint(buf, v);
}

fn fixed32(buf: &mut Vec<u8>, field: u32, v: u32) {
    key(buf, field, I32);
    buf.extend_from_slice(&v.to_le_bytes());
}

/// `FieldDescriptorProto.Type` values used here.
#[derive(Clone, Copy)]
enum FieldType {
    Int64 = 3,
    Int32 = 5,
    Fixed32 = 7,
    String = 9,
    Message = 11,
    Bytes = 12,
}

/// A `FieldDescriptorProto` (optional label).
fn field(name: &str, number: u32, ty: FieldType, type_name: Option<&str>) -> Vec<u8> {
    let mut f = Vec::new();
    bytes(&mut f, 1, name.as_bytes());
    uint(&mut f, 3, u64::from(number));
    uint(&mut f, 4, 1); // LABEL_OPTIONAL
    uint(&mut f, 5, ty as u64);
    if let Some(t) = type_name {
        bytes(&mut f, 6, t.as_bytes());
    }
    f
}

/// A `FileDescriptorProto` with one message.
fn file(name: &str, package: &str, deps: &[&str], message: &str, fields: &[Vec<u8>]) -> Vec<u8> {
    let mut m = Vec::new();
    bytes(&mut m, 1, message.as_bytes());
    for f in fields {
        bytes(&mut m, 2, f);
    }
    let mut out = Vec::new();
    bytes(&mut out, 1, name.as_bytes());
    bytes(&mut out, 2, package.as_bytes());
    for d in deps {
        bytes(&mut out, 3, d.as_bytes());
    }
    bytes(&mut out, 4, &m);
    bytes(&mut out, 12, b"proto3");
    out
}

/// The schema of [`RAW_IMAGE`]: a `FileDescriptorSet` holding
/// `google/protobuf/timestamp.proto` and `foxglove/RawImage.proto`.
pub fn raw_image_descriptor_set() -> Vec<u8> {
    use FieldType::*;
    let timestamp = file(
        "google/protobuf/timestamp.proto",
        "google.protobuf",
        &[],
        "Timestamp",
        &[field("seconds", 1, Int64, None), field("nanos", 2, Int32, None)],
    );
    let image = file(
        "foxglove/RawImage.proto",
        "foxglove",
        &["google/protobuf/timestamp.proto"],
        "RawImage",
        &[
            field("timestamp", 1, Message, Some(".google.protobuf.Timestamp")),
            field("frame_id", 7, String, None),
            field("width", 2, Fixed32, None),
            field("height", 3, Fixed32, None),
            field("encoding", 4, String, None),
            field("step", 5, Fixed32, None),
            field("data", 6, Bytes, None),
        ],
    );
    let mut set = Vec::new();
    bytes(&mut set, 1, &timestamp);
    bytes(&mut set, 1, &image);
    set
}

/// Foxglove's name of a pixel format and its bytes per pixel; `None` for a
/// ring of raw data (not an image). `hsi8` is shown as `rgb8` (converted).
pub fn encoding_of(format: PixelFormat) -> Option<(&'static str, u32)> {
    match format {
        PixelFormat::Rgb8 | PixelFormat::Hsi8 => Some(("rgb8", 3)),
        PixelFormat::Gray8 => Some(("mono8", 1)),
        PixelFormat::Raw => None,
    }
}

/// An image to encode.
#[derive(Debug, Clone, Copy)]
pub struct RawImage<'a> {
    /// CLOCK_REALTIME ns of the frame
    pub unix_ns: u64,
    /// the frame's name (the ring)
    pub frame_id: &'a str,
    /// pixels per row
    pub width: u32,
    /// rows
    pub height: u32,
    /// `rgb8` or `mono8`
    pub encoding: &'a str,
    /// bytes per row
    pub step: u32,
    /// `step * height` bytes
    pub data: &'a [u8],
}

/// Encodes `img` as a `foxglove.RawImage` message into `buf` (cleared first).
pub fn encode_raw_image(buf: &mut Vec<u8>, img: &RawImage<'_>) {
    buf.clear();
    buf.reserve(img.data.len() + 64 + img.frame_id.len());
    let mut ts = Vec::with_capacity(16);
    uint(&mut ts, 1, img.unix_ns / 1_000_000_000);
    uint(&mut ts, 2, img.unix_ns % 1_000_000_000);
    bytes(buf, 1, &ts);
    bytes(buf, 7, img.frame_id.as_bytes());
    fixed32(buf, 2, img.width);
    fixed32(buf, 3, img.height);
    bytes(buf, 4, img.encoding.as_bytes());
    fixed32(buf, 5, img.step);
    bytes(buf, 6, img.data);
}

/// The suffix of a ring notice port's image channel in `nerve foxglove`.
pub const IMAGE_SUFFIX: &str = "image";

/// The JSON Schema of [`RAW_IMAGE`] in JSON (bytes as base64, as
/// Foxglove's JSON encoding has them).
pub fn raw_image_json_schema() -> serde_json::Value {
    serde_json::json!({
        "title": RAW_IMAGE,
        "type": "object",
        "properties": {
            "timestamp": time_schema(),
            "frame_id": { "type": "string" },
            "width": { "type": "integer" },
            "height": { "type": "integer" },
            "encoding": { "type": "string" },
            "step": { "type": "integer" },
            "data": { "type": "string", "contentEncoding": "base64" },
        },
    })
}

/// `img` as a [`RAW_IMAGE`] message in JSON.
pub fn raw_image_json(img: &RawImage<'_>) -> serde_json::Value {
    serde_json::json!({
        "timestamp": time_of(img.unix_ns),
        "frame_id": img.frame_id,
        "width": img.width,
        "height": img.height,
        "encoding": img.encoding,
        "step": img.step,
        "data": base64(img.data),
    })
}

/// Standard base64 with padding (RFC 4648).
fn base64(data: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let b = [chunk[0], chunk.get(1).copied().unwrap_or(0), chunk.get(2).copied().unwrap_or(0)];
        let n = u32::from(b[0]) << 16 | u32::from(b[1]) << 8 | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(char::from(ALPHABET[(n >> (18 - 6 * i) & 63) as usize]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A `geometry_msgs/Twist` in JSON (`{"linear": {"x": ..}, "angular":
/// {"z": ..}}`, what Foxglove's Teleop panel publishes) as the JSON of a
/// `nerve::VelocityCommand` (`{"v": .., "omega": ..}`: forward speed and
/// turn rate of a planar base); `None` for anything else.
pub fn velocity_from_twist(value: &serde_json::Value) -> Option<serde_json::Value> {
    let x = value.get("linear")?.get("x")?.as_f64()?;
    let z = value.get("angular")?.get("z")?.as_f64()?;
    Some(serde_json::json!({ "v": x, "omega": z }))
}

/// A nerve type also shown as one of Foxglove's own schemas (the 3D
/// panel's), in JSON: the live server (`nerve foxglove`) offers it as a
/// second channel of the port, `/<agent>/<port>/<suffix>`.
#[derive(Debug, Clone, Copy)]
pub struct Mapping {
    /// Foxglove's schema name (`foxglove.FrameTransform`)
    pub schema_name: &'static str,
    /// the channel's suffix (`tf`)
    pub suffix: &'static str,
    /// the parent frame of a transform (`world`), or the frame of a scan
    parent: &'static str,
    /// the child frame of a transform (`base_link`)
    child: &'static str,
    kind: MappingKind,
}

#[derive(Debug, Clone, Copy)]
enum MappingKind {
    /// `x`, `y`, `theta` as a planar transform
    Transform,
    /// H1's sonar ring (`ranges_m`, `valid`) as a laser scan
    SonarScan,
    /// the map builder's map as a dense grid ([`grid`])
    Grid,
}

/// The robot's frame, which the pose moves and the sonar is fixed to.
pub const ROBOT_FRAME: &str = "base_link";

const MAPPINGS: [(&str, Mapping); 5] = [
    (
        "nerve::PoseEstimate",
        Mapping {
            schema_name: "foxglove.FrameTransform",
            suffix: "tf",
            parent: "world",
            child: ROBOT_FRAME,
            kind: MappingKind::Transform,
        },
    ),
    (
        "nerve::GroundTruth",
        Mapping {
            schema_name: "foxglove.FrameTransform",
            suffix: "tf",
            parent: "world",
            child: "truth",
            kind: MappingKind::Transform,
        },
    ),
    (
        "nerve::Odometry",
        Mapping {
            schema_name: "foxglove.FrameTransform",
            suffix: "tf",
            parent: "odom",
            child: "odom_base_link",
            kind: MappingKind::Transform,
        },
    ),
    (
        "nerve::SonarScan",
        Mapping {
            schema_name: "foxglove.LaserScan",
            suffix: "scan",
            parent: ROBOT_FRAME,
            child: ROBOT_FRAME,
            kind: MappingKind::SonarScan,
        },
    ),
    (
        grid::MAP_TYPE,
        Mapping {
            schema_name: grid::GRID,
            suffix: "grid",
            parent: grid::MAP_FRAME,
            child: grid::MAP_FRAME,
            kind: MappingKind::Grid,
        },
    ),
];

/// The Foxglove schema nerve's type `type_name` is also shown as, if any.
pub fn mapping_of(type_name: &str) -> Option<Mapping> {
    MAPPINGS.iter().find(|(t, _)| *t == type_name).map(|(_, m)| *m)
}

fn time_schema() -> serde_json::Value {
    serde_json::json!({
        "type": "object",
        "properties": { "sec": { "type": "integer" }, "nsec": { "type": "integer" } },
    })
}

fn vector_schema(fields: &[&str]) -> serde_json::Value {
    let props: serde_json::Map<String, serde_json::Value> =
        fields.iter().map(|f| ((*f).to_owned(), serde_json::json!({ "type": "number" }))).collect();
    serde_json::json!({ "type": "object", "properties": props })
}

fn time_of(unix_ns: u64) -> serde_json::Value {
    serde_json::json!({ "sec": unix_ns / 1_000_000_000, "nsec": unix_ns % 1_000_000_000 })
}

/// A rotation by `theta` about z as a quaternion.
fn yaw(theta: f64) -> serde_json::Value {
    serde_json::json!({ "x": 0.0, "y": 0.0, "z": (theta / 2.0).sin(), "w": (theta / 2.0).cos() })
}

impl Mapping {
    /// The JSON Schema of the Foxglove message (schema encoding `jsonschema`).
    pub fn json_schema(&self) -> serde_json::Value {
        let mut s = match self.kind {
            MappingKind::Grid => grid::grid_json_schema(),
            MappingKind::Transform => serde_json::json!({
                "type": "object",
                "properties": {
                    "timestamp": time_schema(),
                    "parent_frame_id": { "type": "string" },
                    "child_frame_id": { "type": "string" },
                    "translation": vector_schema(&["x", "y", "z"]),
                    "rotation": vector_schema(&["x", "y", "z", "w"]),
                },
            }),
            MappingKind::SonarScan => serde_json::json!({
                "type": "object",
                "properties": {
                    "timestamp": time_schema(),
                    "frame_id": { "type": "string" },
                    "pose": {
                        "type": "object",
                        "properties": {
                            "position": vector_schema(&["x", "y", "z"]),
                            "orientation": vector_schema(&["x", "y", "z", "w"]),
                        },
                    },
                    "start_angle": { "type": "number" },
                    "end_angle": { "type": "number" },
                    "ranges": { "type": "array", "items": { "type": "number" } },
                    "intensities": { "type": "array", "items": { "type": "number" } },
                },
            }),
        };
        if let Some(o) = s.as_object_mut() {
            o.insert("title".into(), serde_json::json!(self.schema_name));
        }
        s
    }

    /// The Foxglove message of a sample, from its JSON (as
    /// [`shm_schemas::schema::Value`] prints it) and its time; `None` when
    /// the sample lacks a field the mapping needs.
    pub fn convert(&self, sample: &serde_json::Value, unix_ns: u64) -> Option<serde_json::Value> {
        let num = |k: &str| sample.get(k).and_then(serde_json::Value::as_f64);
        match self.kind {
            MappingKind::Grid => grid::map_to_grid(sample, unix_ns),
            MappingKind::Transform => Some(serde_json::json!({
                "timestamp": time_of(unix_ns),
                "parent_frame_id": self.parent,
                "child_frame_id": self.child,
                "translation": { "x": num("x")?, "y": num("y")?, "z": 0.0 },
                "rotation": yaw(num("theta")?),
            })),
            MappingKind::SonarScan => {
                let ranges = sample.get("ranges_m")?.as_array()?;
                let valid = sample.get("valid")?.as_array()?;
                let n = ranges.len();
                // a direction that heard no echo has no range: 0, which the 3D panel leaves out
                let ranges: Vec<f64> = ranges
                    .iter()
                    .zip(valid)
                    .map(|(r, v)| if v.as_u64() == Some(1) { r.as_f64().unwrap_or(0.0) } else { 0.0 })
                    .collect();
                let step = std::f64::consts::TAU / n.max(1) as f64;
                Some(serde_json::json!({
                    "timestamp": time_of(unix_ns),
                    "frame_id": self.parent,
                    "pose": {
                        "position": { "x": 0.0, "y": 0.0, "z": 0.0 },
                        "orientation": { "x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0 },
                    },
                    "start_angle": 0.0,
                    "end_angle": step * n.saturating_sub(1) as f64,
                    "ranges": ranges,
                    "intensities": [],
                }))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_is_a_frame_transform_of_the_robot_in_the_world() {
        let m = mapping_of("nerve::PoseEstimate").expect("pose mapped");
        assert_eq!((m.schema_name, m.suffix), ("foxglove.FrameTransform", "tf"));
        let pose = serde_json::json!({ "x": 1.5, "y": -2.0, "theta": std::f64::consts::FRAC_PI_2, "stamp_ns": 5 });
        let t = m.convert(&pose, 3_000_000_007).expect("converted");
        assert_eq!(t["timestamp"], serde_json::json!({ "sec": 3, "nsec": 7 }));
        assert_eq!((t["parent_frame_id"].as_str(), t["child_frame_id"].as_str()), (Some("world"), Some(ROBOT_FRAME)));
        assert_eq!(t["translation"], serde_json::json!({ "x": 1.5, "y": -2.0, "z": 0.0 }));
        let (z, w) = (t["rotation"]["z"].as_f64().expect("z"), t["rotation"]["w"].as_f64().expect("w"));
        assert!((z - w).abs() < 1e-12 && (z * z + w * w - 1.0).abs() < 1e-12, "a quarter turn: {t}");
        assert!(m.convert(&serde_json::json!({ "x": 1 }), 0).is_none(), "a sample without theta");
        assert_eq!(m.json_schema()["title"], "foxglove.FrameTransform");
        assert!(mapping_of("nerve::Tick").is_none());
    }

    #[test]
    fn a_teleop_twist_is_a_velocity_command() {
        let twist =
            serde_json::json!({ "linear": { "x": 0.3, "y": 0, "z": 0 }, "angular": { "x": 0, "y": 0, "z": -0.5 } });
        assert_eq!(velocity_from_twist(&twist), Some(serde_json::json!({ "v": 0.3, "omega": -0.5 })));
        assert_eq!(velocity_from_twist(&serde_json::json!({ "v": 0.3, "omega": 0 })), None);
        assert_eq!(velocity_from_twist(&serde_json::json!({ "linear": { "x": "fast" }, "angular": { "z": 0 } })), None);
    }

    #[test]
    fn base64_is_rfc_4648s() {
        assert_eq!(base64(b""), "");
        assert_eq!(base64(b"f"), "Zg==");
        assert_eq!(base64(b"fo"), "Zm8=");
        assert_eq!(base64(b"foo"), "Zm9v");
        assert_eq!(base64(b"foobar"), "Zm9vYmFy");
        assert_eq!(base64(&[0xff, 0xfe]), "//4=");
    }

    /// An image of two rgb8 pixels (bytes 1 to 6) at 1.500000001 s.
    fn two_pixels() -> RawImage<'static> {
        RawImage {
            unix_ns: 1_500_000_001,
            frame_id: "cam",
            width: 2,
            height: 1,
            encoding: "rgb8",
            step: 6,
            data: &[1, 2, 3, 4, 5, 6],
        }
    }

    #[test]
    fn an_image_in_json_carries_its_pixels_in_base64() {
        let v = raw_image_json(&two_pixels());
        assert_eq!(v["timestamp"], serde_json::json!({ "sec": 1, "nsec": 500_000_001 }));
        assert_eq!((v["width"].as_u64(), v["step"].as_u64()), (Some(2), Some(6)));
        assert_eq!(v["data"], "AQIDBAUG");
        assert_eq!(raw_image_json_schema()["title"], RAW_IMAGE);
    }

    #[test]
    fn the_sonar_ring_is_a_laser_scan_without_its_silent_directions() {
        let m = mapping_of("nerve::SonarScan").expect("sonar mapped");
        let mut ranges = vec![1.0; 12];
        ranges[3] = 0.5;
        let mut valid = vec![1; 12];
        valid[6] = 0;
        let scan = serde_json::json!({ "seq": 1, "stamp_ns": 2, "ranges_m": ranges, "valid": valid });
        let l = m.convert(&scan, 0).expect("converted");
        assert_eq!(l["frame_id"], ROBOT_FRAME);
        assert_eq!(l["ranges"][3], 0.5);
        assert_eq!(l["ranges"][6], 0.0, "no echo, no range");
        let end = l["end_angle"].as_f64().expect("end");
        assert!((end - 11.0 * std::f64::consts::TAU / 12.0).abs() < 1e-12);
    }

    #[test]
    fn varints_are_protobufs() {
        let mut b = Vec::new();
        varint(&mut b, 1);
        varint(&mut b, 300);
        varint(&mut b, u64::MAX);
        assert_eq!(&b[..3], &[0x01, 0xac, 0x02]);
        assert_eq!(b.len(), 3 + 10);
    }

    #[test]
    fn an_image_message_has_its_fields_in_order() {
        let mut buf = Vec::new();
        encode_raw_image(&mut buf, &two_pixels());
        // timestamp { seconds: 1, nanos: 500000001 (a 5-byte varint) }
        assert_eq!(&buf[..2], &[0x0a, 8]);
        assert_eq!(&buf[2..5], &[0x08, 1, 0x10]);
        // frame_id = 7
        assert_eq!(&buf[10..15], &[0x3a, 3, b'c', b'a', b'm']);
        // width = 2 (fixed32)
        assert_eq!(&buf[15..20], &[0x15, 2, 0, 0, 0]);
        assert!(buf.ends_with(&[0x32, 6, 1, 2, 3, 4, 5, 6]), "data last: {buf:?}");
    }
}
