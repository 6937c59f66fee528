//! Camera frames in bags ROS 2 reads: a recording keeps each frame of a
//! short-term-memory ring as a `foxglove.RawImage` (protobuf, written by
//! `nerve record`); [`raw_image_to_ros`] reads it and writes the
//! `sensor_msgs/msg/Image` CDR the agent publishes for the same frame
//! ([`crate::convert::image_cdr`]), stamped with the frame's own time.

/// The recorded channel's schema name this module reads.
pub const RAW_IMAGE: &str = "foxglove.RawImage";
/// Its message encoding in a recording.
pub const RAW_IMAGE_ENCODING: &str = "protobuf";
/// What it becomes.
pub const ROS_IMAGE: &str = "sensor_msgs/msg/Image";

/// Why a recorded frame cannot be a `sensor_msgs/Image`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ImageError {
    /// The protobuf ends inside a field, or a field has a wire type
    /// RawImage does not use.
    #[error("a recorded foxglove.RawImage is damaged at byte {at}: {why}")]
    Damaged {
        /// the offset
        at: usize,
        /// what is wrong
        why: &'static str,
    },
    /// An encoding other than rgb8 and mono8, or fewer pixels than
    /// width × height.
    #[error("a recorded frame {width}x{height} {encoding:?} with {len} bytes is not an rgb8 or mono8 picture")]
    Picture {
        /// pixels per row
        width: u32,
        /// rows
        height: u32,
        /// its encoding
        encoding: String,
        /// bytes of data
        len: usize,
    },
    /// The message could not be written as CDR.
    #[error("cannot write the frame as CDR: {0}")]
    Cdr(#[from] crate::cdr::CdrError),
}

/// The fields of a recorded `foxglove.RawImage`.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct RawImage<'a> {
    /// ns since the epoch
    pub unix_ns: u64,
    /// the frame's name
    pub frame_id: &'a str,
    /// pixels per row
    pub width: u32,
    /// rows
    pub height: u32,
    /// `rgb8` or `mono8`
    pub encoding: &'a str,
    /// bytes per row
    pub step: u32,
    /// the pixels
    pub data: &'a [u8],
}

struct Pb<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Pb<'a> {
    fn damaged(&self, why: &'static str) -> ImageError {
        ImageError::Damaged { at: self.at, why }
    }
    fn varint(&mut self) -> Result<u64, ImageError> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let byte = *self.b.get(self.at).ok_or_else(|| self.damaged("ends inside a varint"))?;
            self.at += 1;
            v |= u64::from(byte & 0x7f) << shift;
            if byte & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(self.damaged("a varint longer than 10 bytes"))
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], ImageError> {
        let end =
            self.at.checked_add(n).filter(|e| *e <= self.b.len()).ok_or_else(|| self.damaged("ends inside a field"))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn fixed32(&mut self) -> Result<u32, ImageError> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
    fn len_delimited(&mut self) -> Result<&'a [u8], ImageError> {
        let n = usize::try_from(self.varint()?).map_err(|_| self.damaged("a length past memory"))?;
        self.take(n)
    }
    /// Skips a field of another number.
    fn skip(&mut self, wire: u64) -> Result<(), ImageError> {
        match wire {
            0 => self.varint().map(drop),
            1 => self.take(8).map(drop),
            2 => self.len_delimited().map(drop),
            5 => self.take(4).map(drop),
            _ => Err(self.damaged("a wire type protobuf does not have")),
        }
    }
}

/// Reads a `foxglove.RawImage` protobuf message.
pub fn parse_raw_image(b: &[u8]) -> Result<RawImage<'_>, ImageError> {
    fn text(s: &[u8], at: usize) -> Result<&str, ImageError> {
        std::str::from_utf8(s).map_err(|_| ImageError::Damaged { at, why: "a string that is not UTF-8" })
    }
    let mut img = RawImage::default();
    let mut p = Pb { b, at: 0 };
    while p.at < b.len() {
        let tag = p.varint()?;
        match (tag >> 3, tag & 7) {
            (1, 2) => {
                let ts = p.len_delimited()?;
                let mut q = Pb { b: ts, at: 0 };
                let (mut sec, mut nsec) = (0u64, 0u64);
                while q.at < ts.len() {
                    let t = q.varint()?;
                    match (t >> 3, t & 7) {
                        (1, 0) => sec = q.varint()?,
                        (2, 0) => nsec = q.varint()?,
                        (_, w) => q.skip(w)?,
                    }
                }
                img.unix_ns = sec.saturating_mul(1_000_000_000).saturating_add(nsec);
            }
            (7, 2) => img.frame_id = text(p.len_delimited()?, p.at)?,
            (2, 5) => img.width = p.fixed32()?,
            (3, 5) => img.height = p.fixed32()?,
            (4, 2) => img.encoding = text(p.len_delimited()?, p.at)?,
            (5, 5) => img.step = p.fixed32()?,
            (6, 2) => img.data = p.len_delimited()?,
            (_, w) => p.skip(w)?,
        }
    }
    Ok(img)
}

/// A recorded frame (`foxglove.RawImage` protobuf) as the CDR of a
/// `sensor_msgs/msg/Image`, stamped with the frame's time (the recording's
/// `log_time` if the frame has none).
pub fn raw_image_to_ros(proto: &[u8], log_time: u64) -> Result<Vec<u8>, ImageError> {
    let img = parse_raw_image(proto)?;
    let channels = match img.encoding {
        "rgb8" => 3,
        "mono8" => 1,
        _ => 0,
    };
    let stamp = crate::msgs::Time::from_ns(i128::from(if img.unix_ns > 0 { img.unix_ns } else { log_time }));
    let bad = || ImageError::Picture {
        width: img.width,
        height: img.height,
        encoding: img.encoding.to_owned(),
        len: img.data.len(),
    };
    if channels == 0 || img.step != img.width.saturating_mul(channels) {
        return Err(bad());
    }
    Ok(crate::convert::image_cdr(stamp, img.frame_id, img.width, img.height, img.encoding, channels, img.data)
        .ok_or_else(bad)??)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A RawImage written by hand after protobuf's encoding rules
    /// (tag = field << 3 | wire type; fixed32 little-endian), in the field
    /// order `nerve record` writes, read back and written as an Image.
    #[test]
    fn a_recorded_frame_becomes_an_image() {
        let mut pb = vec![0x0a, 0x05, 0x08, 0x07, 0x10, 0xe8, 0x07]; // timestamp {sec 7, nanos 1000}
        pb.extend([0x3a, 0x03]);
        pb.extend(b"cam"); // frame_id (7)
        pb.extend([0x15, 2, 0, 0, 0]); // width (2) = 2
        pb.extend([0x1d, 1, 0, 0, 0]); // height (3) = 1
        pb.extend([0x22, 4]);
        pb.extend(b"rgb8"); // encoding (4)
        pb.extend([0x2d, 6, 0, 0, 0]); // step (5) = 6
        pb.extend([0x32, 6, 1, 2, 3, 4, 5, 6]); // data (6)
        let img = parse_raw_image(&pb).expect("parses");
        assert_eq!(
            img,
            RawImage {
                unix_ns: 7_000_001_000,
                frame_id: "cam",
                width: 2,
                height: 1,
                encoding: "rgb8",
                step: 6,
                data: &[1, 2, 3, 4, 5, 6]
            }
        );
        let cdr = raw_image_to_ros(&pb, 0).expect("an Image");
        let mut r = crate::cdr::Reader::new(&cdr).expect("header");
        assert_eq!((r.i32(), r.u32(), r.string()), (Ok(7), Ok(1000), Ok("cam")));
        assert_eq!((r.u32(), r.u32(), r.string(), r.u8(), r.u32()), (Ok(1), Ok(2), Ok("rgb8"), Ok(0), Ok(6)));
        assert_eq!(r.bytes(), Ok(&[1u8, 2, 3, 4, 5, 6][..]));
        r.finish().expect("nothing left");
        // cut short, and a picture that is not one
        assert!(matches!(parse_raw_image(&pb[..pb.len() - 2]), Err(ImageError::Damaged { .. })));
        let mut bgr = pb.clone();
        let i = bgr.windows(4).position(|w| w == b"rgb8").expect("encoding");
        bgr[i..i + 4].copy_from_slice(b"bgr8");
        assert!(matches!(raw_image_to_ros(&bgr, 0), Err(ImageError::Picture { .. })));
    }
}
