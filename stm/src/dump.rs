//! Writing a stored image frame as a PNG file, for `nerve mem dump`, or
//! into memory ([`encode_png`], for `nerve ui`: no file that another user
//! could pre-create or read).
//!
//! * `RGB8` is written as an RGB PNG;
//! * `GRAY8` (and masks) as an 8-bit greyscale PNG;
//! * `HSI8` is converted to RGB with the textbook HSI→RGB formulas
//!   (Gonzalez & Woods, sectors of 120°), so that the picture looks as the
//!   scene did: hue byte `h` is `h * 360 / 256` degrees, saturation and
//!   intensity bytes are fractions of 255;
//! * `RAW` frames are not images and are refused.
//!
//! The frame is first copied out of the ring (a validated read), so encoding
//! never races the writer.

use crate::error::ReadError;
use crate::reader::{FrameMeta, RingReader};
use shm_schemas::ring::PixelFormat;
use std::path::{Path, PathBuf};

/// Which frame to dump.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameSelector {
    /// The latest complete frame.
    Latest,
    /// Frame number `seq`.
    Seq(u64),
    /// The frame stamped nearest to this CLOCK_MONOTONIC time (ns).
    Nearest(u64),
}

/// Why no PNG was written.
#[derive(Debug, thiserror::Error)]
pub enum DumpError {
    /// The frame could not be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The frame is not an image this build can show.
    #[error(
        "frame {seq} has pixel format {format}, which is not an image; only rgb8, gray8 and hsi8 frames can be dumped as PNG"
    )]
    NotAnImage {
        /// the frame
        seq: u64,
        /// its format
        format: String,
    },
    /// Width or height is zero, or the frame is shorter than they say.
    #[error("frame {seq} says {width}x{height} {format} ({needed} bytes) but holds {len} bytes")]
    BadSize {
        /// the frame
        seq: u64,
        /// width in pixels
        width: u32,
        /// height in pixels
        height: u32,
        /// the format
        format: &'static str,
        /// bytes needed
        needed: u64,
        /// bytes held
        len: usize,
    },
    /// The PNG file could not be written.
    #[error("cannot write {path}: {source}")]
    Io {
        /// the file
        path: PathBuf,
        /// the error
        #[source]
        source: std::io::Error,
    },
    /// The PNG encoder failed (writing into memory).
    #[error("cannot encode frame {seq} as PNG: {source}")]
    EncodeInMemory {
        /// the frame
        seq: u64,
        /// the error
        #[source]
        source: png::EncodingError,
    },
    /// The PNG encoder failed.
    #[error("cannot encode {path} as PNG: {source}")]
    Encode {
        /// the file
        path: PathBuf,
        /// the error
        #[source]
        source: png::EncodingError,
    },
}

/// Writes the selected image frame of `reader` to `path` as a PNG and returns
/// the frame's description.
pub fn dump_png(reader: &RingReader, which: FrameSelector, path: &Path) -> Result<FrameMeta, DumpError> {
    let (meta, color, bytes) = select_image(reader, which)?;
    let io_err = |source| DumpError::Io { path: path.to_owned(), source };
    let enc_err = |source| DumpError::Encode { path: path.to_owned(), source };
    let file = std::fs::File::create(path).map_err(io_err)?;
    write_png(std::io::BufWriter::new(file), &meta, color, &bytes).map_err(enc_err)?;
    tracing::debug!(ring = %reader.name(), seq = meta.seq, path = %path.display(), "frame dumped as PNG");
    Ok(meta)
}

/// Encodes the selected image frame of `reader` as a PNG in memory; returns
/// the frame's description and the PNG's bytes.
pub fn encode_png(reader: &RingReader, which: FrameSelector) -> Result<(FrameMeta, Vec<u8>), DumpError> {
    let (meta, color, bytes) = select_image(reader, which)?;
    let mut png = Vec::new();
    write_png(&mut png, &meta, color, &bytes).map_err(|source| DumpError::EncodeInMemory { seq: meta.seq, source })?;
    Ok((meta, png))
}

fn write_png<W: std::io::Write>(
    out: W,
    meta: &FrameMeta,
    color: png::ColorType,
    bytes: &[u8],
) -> Result<(), png::EncodingError> {
    let mut enc = png::Encoder::new(out, meta.width, meta.height);
    enc.set_color(color);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header()?;
    w.write_image_data(bytes)?;
    w.finish()
}

/// The selected frame, checked to be an image, as PNG colour type and pixels.
fn select_image(reader: &RingReader, which: FrameSelector) -> Result<(FrameMeta, png::ColorType, Vec<u8>), DumpError> {
    let mut data = Vec::new();
    let meta = match which {
        FrameSelector::Latest => reader.latest_into(&mut data)?,
        FrameSelector::Seq(seq) => reader.read_into(seq, &mut data)?,
        FrameSelector::Nearest(t) => reader.nearest_into(t, &mut data)?,
    };
    let format = meta.format().filter(|f| *f != PixelFormat::Raw).ok_or_else(|| DumpError::NotAnImage {
        seq: meta.seq,
        format: meta.format().map_or_else(|| format!("code {}", meta.format_code), |f| f.to_string()),
    })?;
    let bpp = format.bytes_per_pixel().unwrap_or(1) as u64;
    // the sizes come from the ring's writer: (2^32-1)^2 * 3 overflows u64
    let pixels = u64::from(meta.width) * u64::from(meta.height);
    let needed = pixels.saturating_mul(bpp);
    if pixels == 0 || (data.len() as u64) < needed {
        return Err(DumpError::BadSize {
            seq: meta.seq,
            width: meta.width,
            height: meta.height,
            format: format.as_str(),
            needed,
            len: data.len(),
        });
    }
    data.truncate(needed as usize);
    let (color, bytes) = match format {
        PixelFormat::Rgb8 => (png::ColorType::Rgb, data),
        PixelFormat::Gray8 => (png::ColorType::Grayscale, data),
        PixelFormat::Hsi8 => (png::ColorType::Rgb, hsi8_to_rgb8(&data)),
        PixelFormat::Raw => unreachable!("refused above"),
    };
    Ok((meta, color, bytes))
}

/// Converts packed HSI8 pixels (see the module doc) to packed RGB8.
pub fn hsi8_to_rgb8(hsi: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(hsi.len());
    for px in hsi.chunks_exact(3) {
        let [r, g, b] = hsi_to_rgb(px[0], px[1], px[2]);
        out.extend_from_slice(&[r, g, b]);
    }
    out
}

fn hsi_to_rgb(h: u8, s: u8, i: u8) -> [u8; 3] {
    let h = f64::from(h) * 360.0 / 256.0;
    let s = f64::from(s) / 255.0;
    let i = f64::from(i) / 255.0;
    // in sector [0°, 120°) of hue hh: the "low" channel is i(1-s), the "high"
    // one i(1 + s cos hh / cos(60° - hh)), the third makes the mean i
    let f = |hh: f64| {
        let lo = i * (1.0 - s);
        let hi = i * (1.0 + s * hh.to_radians().cos() / (60.0 - hh).to_radians().cos());
        (lo, hi, 3.0 * i - (lo + hi))
    };
    let (r, g, b) = if h < 120.0 {
        let (lo, hi, mid) = f(h);
        (hi, mid, lo)
    } else if h < 240.0 {
        let (lo, hi, mid) = f(h - 120.0);
        (lo, hi, mid)
    } else {
        let (lo, hi, mid) = f(h - 240.0);
        (mid, lo, hi)
    };
    let q = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    [q(r), q(g), q(b)]
}

#[cfg(test)]
mod tests {
    use super::hsi_to_rgb;

    #[test]
    fn hsi_primaries() {
        // grey: no saturation
        assert_eq!(hsi_to_rgb(0, 0, 128), [128, 128, 128]);
        // pure red: hue 0, full saturation, intensity 1/3
        assert_eq!(hsi_to_rgb(0, 255, 85), [255, 0, 0]);
        // green at 120° (byte 85.33 -> 85 is 119.5°, close to green)
        let [r, g, b] = hsi_to_rgb(85, 255, 85);
        assert!(g > 240 && r < 10 && b < 10, "{r} {g} {b}");
        // blue at 240° (byte 171 is 240.5°)
        let [r, g, b] = hsi_to_rgb(171, 255, 85);
        assert!(b > 240 && r < 10 && g < 10, "{r} {g} {b}");
    }
}
