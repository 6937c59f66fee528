//! The V4L2 backend: a webcam through the `v4l` crate, memory-mapped
//! streaming (4 buffers), frames converted to RGB8 straight into the ring.
//!
//! Format choice, in order: YUYV (every UVC webcam has it at 320x240), RGB3,
//! MJPEG. The driver may adjust the size; frames of another size than asked
//! are refused with the size to ask for instead. The frame rate is asked with
//! `VIDIOC_S_PARM` (best effort: some drivers ignore it). Frames carry the
//! driver's capture time when it is CLOCK_MONOTONIC (the norm for UVC),
//! else the time they are stored.
//!
//! Every failure is a [`SourceError`] whose message names the device and
//! says what to do; the agent drops the device and tries again later.

use crate::convert::{self, ConvertError};
use crate::{Grab, Source, SourceError};
use agent_sdk::memory::{FrameDesc, PixelFormat, RingOutput};
use std::io;
use std::path::{Path, PathBuf};
use std::time::Duration;
use v4l::buffer::{Flags, Type};
use v4l::capability::Flags as CapFlags;
use v4l::io::mmap::Stream;
use v4l::io::traits::{CaptureStream, Stream as _};
use v4l::video::Capture;
use v4l::video::capture::Parameters;
use v4l::{Device, Format, FourCC};

/// How long to wait for one frame before declaring the camera stalled.
const FRAME_TIMEOUT: Duration = Duration::from_secs(2);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Yuyv,
    Rgb3,
    Mjpeg,
}

impl Encoding {
    fn fourcc(self) -> FourCC {
        FourCC::new(match self {
            Encoding::Yuyv => b"YUYV",
            Encoding::Rgb3 => b"RGB3",
            Encoding::Mjpeg => b"MJPG",
        })
    }
}

/// An open V4L2 capture device.
pub struct V4lSource {
    path: PathBuf,
    width: u32,
    height: u32,
    stride: usize,
    encoding: Encoding,
    // field order: the stream (its buffers) goes before the device
    stream: Option<Stream<'static>>,
    _dev: Device,
    jpeg: Vec<u8>,
}

impl std::fmt::Debug for V4lSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("V4lSource")
            .field("path", &self.path)
            .field("size", &(self.width, self.height))
            .field("encoding", &self.encoding)
            .finish()
    }
}

/// A device error with the device path and what to do.
fn dev_err(path: &Path, what: &str, e: &io::Error) -> SourceError {
    let p = path.display();
    let hint = match e.raw_os_error() {
        Some(libc::ENOENT | libc::ENODEV | libc::ENXIO) => format!(
            "no camera at {p} (no such device); plug the camera in and check `ls /dev/video*` or `v4l2-ctl --list-devices`, pass --device PATH, or run without hardware with --source test-pattern"
        ),
        Some(libc::EBUSY) => format!(
            "camera {p} is busy: another program is capturing from it; stop that program (`fuser -v {p}` names it) or use another camera with --device"
        ),
        Some(libc::EACCES | libc::EPERM) => format!(
            "permission denied opening {p}; add this user to the `video` group (then log in again) or run the agent as a user that may use the camera"
        ),
        Some(libc::ENOTTY) => format!(
            "{p} is not a V4L2 video device (the driver does not answer V4L2 requests); pass the right --device"
        ),
        _ => format!("camera {p}: {what} failed: {e}"),
    };
    SourceError::Device(hint)
}

impl V4lSource {
    /// Opens `path` and sets it up for `width` x `height` RGB frames at about `fps`.
    pub fn open(path: &Path, width: u32, height: u32, fps: f64) -> Result<Self, SourceError> {
        // refuse anything but a character device before opening it read-write
        match std::fs::metadata(path) {
            Ok(m) if !std::os::unix::fs::FileTypeExt::is_char_device(&m.file_type()) => {
                return Err(SourceError::Device(format!(
                    "{} is not a device file (a V4L2 camera is a character device such as /dev/video0); pass the right --device",
                    path.display()
                )));
            }
            Ok(_) => {}
            Err(e) => return Err(dev_err(path, "open", &e)),
        }
        let dev = Device::with_path(path).map_err(|e| dev_err(path, "open", &e))?;
        let caps = dev.query_caps().map_err(|e| dev_err(path, "VIDIOC_QUERYCAP", &e))?;
        if !caps.capabilities.contains(CapFlags::VIDEO_CAPTURE) {
            return Err(SourceError::Device(format!(
                "{} ({}, driver {}) cannot capture video (capabilities: {}); a webcam often has a second node for metadata: try the next /dev/videoN with --device",
                path.display(),
                caps.card,
                caps.driver,
                caps.capabilities
            )));
        }
        if !caps.capabilities.contains(CapFlags::STREAMING) {
            return Err(SourceError::Device(format!(
                "{} ({}) does not support streaming I/O, which this agent needs",
                path.display(),
                caps.card
            )));
        }
        let offered: Vec<FourCC> = dev
            .enum_formats()
            .map_err(|e| dev_err(path, "VIDIOC_ENUM_FMT", &e))?
            .into_iter()
            .map(|d| d.fourcc)
            .collect();
        let encoding = [Encoding::Yuyv, Encoding::Rgb3, Encoding::Mjpeg]
            .into_iter()
            .find(|e| offered.contains(&e.fourcc()))
            .ok_or_else(|| {
                SourceError::Device(format!(
                    "{} offers none of the formats this agent converts (YUYV, RGB3, MJPG); it offers {}",
                    path.display(),
                    offered.iter().map(|f| f.to_string()).collect::<Vec<_>>().join(", ")
                ))
            })?;
        let fmt = dev
            .set_format(&Format::new(width, height, encoding.fourcc()))
            .map_err(|e| dev_err(path, "VIDIOC_S_FMT", &e))?;
        if (fmt.width, fmt.height) != (width, height) {
            return Err(SourceError::Device(format!(
                "{} cannot deliver {width}x{height} {}; the driver offers {}x{}: start the camera with --width {} --height {}",
                path.display(),
                encoding.fourcc(),
                fmt.width,
                fmt.height,
                fmt.width,
                fmt.height
            )));
        }
        if fmt.fourcc != encoding.fourcc() {
            return Err(SourceError::Device(format!(
                "{} switched the format to {} instead of {}",
                path.display(),
                fmt.fourcc,
                encoding.fourcc()
            )));
        }
        if fps > 0.0 {
            let params = Parameters::with_fps(fps.round().max(1.0) as u32);
            if let Err(e) = dev.set_params(&params) {
                tracing::info!(device = %path.display(), "the driver does not take a frame rate ({e}); it runs at its own");
            }
        }
        let mut stream =
            Stream::with_buffers(&dev, Type::VideoCapture, 4).map_err(|e| dev_err(path, "VIDIOC_REQBUFS", &e))?;
        stream.set_timeout(FRAME_TIMEOUT);
        tracing::info!(
            device = %path.display(), card = %caps.card, driver = %caps.driver,
            "camera open: {width}x{height} {} (stride {})", encoding.fourcc(), fmt.stride
        );
        Ok(V4lSource {
            path: path.to_owned(),
            width,
            height,
            stride: fmt.stride as usize,
            encoding,
            stream: Some(stream),
            _dev: dev,
            jpeg: Vec::new(),
        })
    }
}

fn convert_err(path: &Path, e: ConvertError) -> SourceError {
    SourceError::Device(format!("camera {}: {e}", path.display()))
}

impl Source for V4lSource {
    fn describe(&self) -> String {
        format!("V4L2 camera {} ({}x{} {})", self.path.display(), self.width, self.height, self.encoding.fourcc())
    }

    fn grab(&mut self, out: &mut RingOutput, _n: u64) -> Result<Grab, SourceError> {
        let (w, h, stride, enc) = (self.width, self.height, self.stride, self.encoding);
        let stream = self.stream.as_mut().ok_or_else(|| SourceError::Device("stream closed".into()))?;
        let (buf, meta) = match stream.next() {
            Ok(x) => x,
            Err(e) if e.kind() == io::ErrorKind::TimedOut => {
                return Err(SourceError::Device(format!(
                    "camera {} delivered no frame within {} s (unplugged, or stalled); it will be reopened",
                    self.path.display(),
                    FRAME_TIMEOUT.as_secs()
                )));
            }
            Err(e) => return Err(dev_err(&self.path, "VIDIOC_DQBUF", &e)),
        };
        if meta.flags.contains(Flags::ERROR) {
            tracing::debug!(device = %self.path.display(), "the driver marked a frame corrupt; skipped");
            return Ok(Grab::Nothing);
        }
        let used = (meta.bytesused as usize).min(buf.len());
        let buf = &buf[..used];
        let monotonic = meta.flags.bits() & Flags::TIMESTAMP_MASK.bits() == Flags::TIMESTAMP_MONOTONIC.bits();
        let stamp = v4l2_stamp_ns(meta.timestamp.sec, meta.timestamp.usec).filter(|_| monotonic);
        let mut desc = FrameDesc::image(w, h, PixelFormat::Rgb8);
        if let Some(s) = stamp {
            desc = desc.stamped(s);
        }
        let len = w as usize * h as usize * 3;
        // convert first where it can fail half-way, so that no half frame is published
        match enc {
            Encoding::Mjpeg => {
                convert::mjpeg_to_rgb(buf, w, h, &mut self.jpeg).map_err(|e| convert_err(&self.path, e))?;
                out.write(desc, &self.jpeg[..len])?;
            }
            Encoding::Yuyv | Encoding::Rgb3 => {
                // the length check comes first: after it the in-place
                // conversion cannot fail, so no half-converted frame is published
                let row = w as usize * if enc == Encoding::Yuyv { 2 } else { 3 };
                let stride = if stride == 0 { row } else { stride };
                let needed = stride * (h as usize).saturating_sub(1) + row;
                if buf.len() < needed || stride < row {
                    return Err(convert_err(
                        &self.path,
                        ConvertError::Short {
                            format: if enc == Encoding::Yuyv { "YUYV" } else { "RGB3" },
                            width: w,
                            height: h,
                            needed,
                            got: buf.len(),
                        },
                    ));
                }
                out.write_with(desc, len, |dst| {
                    let r = if enc == Encoding::Yuyv {
                        convert::yuyv_to_rgb(buf, w, h, stride, dst)
                    } else {
                        convert::rgb24_to_rgb(buf, w, h, stride, dst)
                    };
                    if r.is_err() {
                        dst.fill(0); // unreachable after the check above
                    }
                })?;
            }
        }
        Ok(Grab::Frame)
    }
}

impl Drop for V4lSource {
    fn drop(&mut self) {
        if let Some(mut s) = self.stream.take() {
            // stop explicitly to log a failure: the v4l crate's own drop
            // panics on a failing VIDIOC_STREAMOFF other than ENODEV
            if let Err(e) = s.stop() {
                tracing::warn!(device = %self.path.display(), "stopping the stream failed: {e}");
            }
        }
    }
}

/// A V4L2 buffer timestamp in nanoseconds, `None` when there is none (zero)
/// or it is implausible. The driver, or a v4l2loopback producer, chooses
/// these numbers: a negative second or microsecond, or a microsecond of a
/// million or more, is refused rather than wrapped or overflowed.
pub(crate) fn v4l2_stamp_ns(sec: i64, usec: i64) -> Option<u64> {
    let sec = u64::try_from(sec).ok()?;
    let usec = u64::try_from(usec).ok().filter(|u| *u < 1_000_000)?;
    sec.checked_mul(1_000_000_000)?.checked_add(usec * 1_000).filter(|s| *s > 0)
}

#[cfg(test)]
mod tests {
    use super::v4l2_stamp_ns;

    #[test]
    fn v4l2_timestamps_from_the_driver_are_checked() {
        assert_eq!(v4l2_stamp_ns(12, 345_678), Some(12_345_678_000));
        assert_eq!(v4l2_stamp_ns(0, 0), None, "no timestamp");
        // a negative usec (e.g. from a v4l2loopback producer) overflowed `usec as u64 * 1000`
        assert_eq!(v4l2_stamp_ns(5, -1), None);
        assert_eq!(v4l2_stamp_ns(-1, 0), None);
        assert_eq!(v4l2_stamp_ns(1, 1_000_000), None, "usec is below a million");
        assert_eq!(v4l2_stamp_ns(i64::MAX, 0), None, "seconds beyond u64 nanoseconds");
        assert_eq!(v4l2_stamp_ns(18_446_744_073, 999_999), None, "the sum overflows");
    }
}
