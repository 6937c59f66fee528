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

use nerve_stm::PixelFormat;

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

#[cfg(test)]
mod tests {
    use super::*;

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
        let px = [1u8, 2, 3, 4, 5, 6];
        let mut buf = Vec::new();
        encode_raw_image(
            &mut buf,
            &RawImage {
                unix_ns: 1_500_000_001,
                frame_id: "cam",
                width: 2,
                height: 1,
                encoding: "rgb8",
                step: 6,
                data: &px,
            },
        );
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
