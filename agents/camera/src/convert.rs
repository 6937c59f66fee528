//! Pixel conversions from what cameras deliver to packed RGB8 (3 bytes per
//! pixel, rows top to bottom, no padding: the `rgb8` format of the rings).
//!
//! * **YUYV** (YUV 4:2:2, `Y0 U Y1 V` per two pixels), the format nearly every
//!   UVC webcam offers at 320x240: BT.601 limited range ("studio swing",
//!   Y 16-235, U/V 16-240) in integer arithmetic, as the kernel's vivid
//!   driver and libv4lconvert do;
//! * **RGB3** (packed RGB24): copied row by row (rows may be padded);
//! * **MJPEG**: decoded with `jpeg-decoder` (handles the Huffman-table-less
//!   frames many webcams send).

/// Why a camera buffer could not be converted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConvertError {
    /// The buffer is shorter than the format says.
    #[error("the camera delivered {got} bytes for a {width}x{height} {format} frame, which needs {needed}")]
    Short {
        /// the camera format
        format: &'static str,
        /// width in pixels
        width: u32,
        /// height in pixels
        height: u32,
        /// bytes needed
        needed: usize,
        /// bytes delivered
        got: usize,
    },
    /// A JPEG frame could not be decoded.
    #[error("the camera delivered an MJPEG frame that cannot be decoded: {0}")]
    Jpeg(String),
    /// A JPEG frame of another size than negotiated.
    #[error("the camera delivered a {got_w}x{got_h} MJPEG frame, not {width}x{height}")]
    JpegSize {
        /// negotiated width
        width: u32,
        /// negotiated height
        height: u32,
        /// decoded width
        got_w: u32,
        /// decoded height
        got_h: u32,
    },
}

fn clip(v: i32) -> u8 {
    v.clamp(0, 255) as u8
}

/// One BT.601 limited-range YUV pixel as RGB.
pub fn yuv_to_rgb(y: u8, u: u8, v: u8) -> [u8; 3] {
    let c = 298 * (i32::from(y) - 16);
    let d = i32::from(u) - 128;
    let e = i32::from(v) - 128;
    [clip((c + 409 * e + 128) >> 8), clip((c - 100 * d - 208 * e + 128) >> 8), clip((c + 516 * d + 128) >> 8)]
}

/// Checks that a buffer of `got` bytes holds `height` rows of `stride` bytes
/// (the last row needs only `row` bytes).
fn check(
    format: &'static str,
    width: u32,
    height: u32,
    row: usize,
    stride: usize,
    got: usize,
) -> Result<(), ConvertError> {
    let needed = if height == 0 { 0 } else { stride * (height as usize - 1) + row };
    if got < needed || stride < row {
        return Err(ConvertError::Short { format, width, height, needed: needed.max(row * height as usize), got });
    }
    Ok(())
}

/// Converts a YUYV frame of `width` x `height` with rows `stride` bytes apart
/// (0: packed) into packed RGB8 in `out` (`width * height * 3` bytes).
pub fn yuyv_to_rgb(src: &[u8], width: u32, height: u32, stride: usize, out: &mut [u8]) -> Result<(), ConvertError> {
    let (w, h) = (width as usize, height as usize);
    let row = w * 2;
    let stride = if stride == 0 { row } else { stride };
    check("YUYV", width, height, row, stride, src.len())?;
    for (y, dst) in out.chunks_exact_mut(w * 3).take(h).enumerate() {
        let line = &src[y * stride..y * stride + row];
        for (pair, px) in line.chunks_exact(4).zip(dst.chunks_exact_mut(6)) {
            let (y0, u, y1, v) = (pair[0], pair[1], pair[2], pair[3]);
            px[..3].copy_from_slice(&yuv_to_rgb(y0, u, v));
            px[3..].copy_from_slice(&yuv_to_rgb(y1, u, v));
        }
        if w % 2 == 1 {
            // odd width: the last pixel shares its pair with a padding pixel
            let i = (w - 1) * 2;
            let (y0, u, v) = (line[i], line.get(i + 1).copied().unwrap_or(128), 128);
            dst[(w - 1) * 3..].copy_from_slice(&yuv_to_rgb(y0, u, v));
        }
    }
    Ok(())
}

/// Copies an RGB24 frame with rows `stride` bytes apart into packed RGB8.
pub fn rgb24_to_rgb(src: &[u8], width: u32, height: u32, stride: usize, out: &mut [u8]) -> Result<(), ConvertError> {
    let row = width as usize * 3;
    let stride = if stride == 0 { row } else { stride };
    check("RGB3", width, height, row, stride, src.len())?;
    for (y, dst) in out.chunks_exact_mut(row).take(height as usize).enumerate() {
        dst.copy_from_slice(&src[y * stride..y * stride + row]);
    }
    Ok(())
}

/// Decodes an MJPEG frame into packed RGB8 (`out` is cleared and filled).
pub fn mjpeg_to_rgb(src: &[u8], width: u32, height: u32, out: &mut Vec<u8>) -> Result<(), ConvertError> {
    let mut dec = jpeg_decoder::Decoder::new(src);
    let px = dec.decode().map_err(|e| ConvertError::Jpeg(e.to_string()))?;
    let info = dec.info().ok_or_else(|| ConvertError::Jpeg("no image header".into()))?;
    if (u32::from(info.width), u32::from(info.height)) != (width, height) {
        return Err(ConvertError::JpegSize { width, height, got_w: info.width.into(), got_h: info.height.into() });
    }
    out.clear();
    match info.pixel_format {
        jpeg_decoder::PixelFormat::RGB24 => out.extend_from_slice(&px),
        jpeg_decoder::PixelFormat::L8 => out.extend(px.iter().flat_map(|&l| [l, l, l])),
        jpeg_decoder::PixelFormat::L16 => out.extend(px.chunks_exact(2).flat_map(|l| [l[0], l[0], l[0]])),
        jpeg_decoder::PixelFormat::CMYK32 => out.extend(px.chunks_exact(4).flat_map(|p| {
            // Adobe CMYK JPEGs store inverted values
            let k = u16::from(p[3]);
            let f = |c: u8| ((u16::from(c) * k) / 255) as u8;
            [f(p[0]), f(p[1]), f(p[2])]
        })),
    }
    let needed = width as usize * height as usize * 3;
    if out.len() < needed {
        return Err(ConvertError::Short { format: "MJPEG", width, height, needed, got: out.len() });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yuv_reference_colours() {
        assert_eq!(yuv_to_rgb(16, 128, 128), [0, 0, 0]);
        assert_eq!(yuv_to_rgb(235, 128, 128), [255, 255, 255]);
        assert_eq!(yuv_to_rgb(126, 128, 128), [128, 128, 128]);
        // BT.601 75% colour bars, limited range: red is Y 65, Cb 100, Cr 212
        let [r, g, b] = yuv_to_rgb(65, 100, 212);
        assert!(r > 185 && r < 195 && g < 5 && b < 5, "{r} {g} {b}");
        // full red (Y 81, Cb 90, Cr 240)
        let [r, g, b] = yuv_to_rgb(81, 90, 240);
        assert!(r >= 253 && g <= 2 && b <= 2, "{r} {g} {b}");
        // full blue (Y 41, Cb 240, Cr 110)
        let [r, g, b] = yuv_to_rgb(41, 240, 110);
        assert!(b >= 253 && r <= 2 && g <= 2, "{r} {g} {b}");
    }

    #[test]
    fn yuyv_frame_with_padding_and_shared_chroma() {
        // 2x2 image, rows padded to 6 bytes: white|black on top, red|red below
        let src = [235, 128, 16, 128, 0, 0, /* row 2 */ 81, 90, 81, 240, 0, 0];
        let mut out = [0u8; 12];
        yuyv_to_rgb(&src, 2, 2, 6, &mut out).expect("convert");
        assert_eq!(&out[..6], &[255, 255, 255, 0, 0, 0]);
        assert!(out[6] >= 253 && out[7] <= 2 && out[9] >= 253 && out[11] <= 2, "{out:?}");
    }

    #[test]
    fn short_buffers_are_refused() {
        let mut out = [0u8; 12];
        let e = yuyv_to_rgb(&[0u8; 7], 2, 2, 0, &mut out).expect_err("short");
        assert!(e.to_string().contains("needs 8"), "{e}");
        assert!(rgb24_to_rgb(&[0u8; 11], 2, 2, 0, &mut out).is_err());
        assert!(mjpeg_to_rgb(b"not a jpeg", 2, 2, &mut Vec::new()).is_err());
    }

    #[test]
    fn rgb24_rows_are_unpadded() {
        let src = [1, 2, 3, 9, /* row 2 */ 4, 5, 6, 9];
        let mut out = [0u8; 6];
        rgb24_to_rgb(&src, 1, 2, 4, &mut out).expect("copy");
        assert_eq!(out, [1, 2, 3, 4, 5, 6]);
    }
}
