//! `image`: turns camera frames into HSI and a red mask.
//!
//! Event-driven on its input `frames` (`nerve::RingNotice`, connect it to a
//! camera's `frames`). For the newest announced RGB8 frame (older waiting
//! notices are skipped: the agent always works on the freshest picture) it
//! reads the pixels in place from the camera's ring and writes
//!
//! * an `hsi8` image into its ring `hsi`, announced on output `hsi`;
//! * a `gray8` red mask (255 red, 0 not) into its ring `red`, announced on
//!   output `red`;
//! * the area in pixels of the largest red blob (4-connected) on output
//!   `red_area` (`nerve::Scalar`, stamped with the frame's stamp; 0 when
//!   nothing is red).
//!
//! Both rings are created at the first frame, with the frame's size, and
//! follow it if the camera changes resolution. Ring names are options, so
//! that two image agents can run side by side:
//!
//! ```text
//! nerve start image --name img -- [--hsi-ring hsi] [--red-ring red] [--slots 8]
//! nerve connect cam/frames img/frames
//! ```
//!
//! Parameters (`nerve param set img KEY VALUE`): `hue_lo` (degrees, 350),
//! `hue_hi` (degrees, 10; below `hue_lo` means the range wraps through 0°),
//! `sat_min` (0-1, 0.35), `int_min` (0-1, 0.08). See `hsi` for the formulas.

mod hsi;

use agent_sdk::memory::{FrameDesc, MemoryError, MemorySetup, PixelFormat, RingInput, RingOutput, RingSpec};
use agent_sdk::{Agent, AgentError, Context, Output, Param, Setup, Task};
use clap::Parser;
use shm_schemas::payloads::Scalar;

/// The image agent's own options (after `--`).
#[derive(Debug, Clone, Parser)]
#[command(name = "nerve-image --", about = "image agent options")]
struct ImageArgs {
    /// Ring of the HSI images.
    #[arg(long, default_value = "hsi")]
    hsi_ring: String,
    /// Ring of the red masks.
    #[arg(long, default_value = "red")]
    red_ring: String,
    /// Slots of each ring.
    #[arg(long, default_value_t = agent_sdk::memory::DEFAULT_SLOTS, value_parser = clap::value_parser!(u32).range(2..=1024))]
    slots: u32,
}

/// Slot size the rings start with (one 320x240 HSI image); they grow with the frames.
const START_CAPACITY: usize = 320 * 240 * 3;

struct ImageAgent {
    frames: RingInput,
    hsi_out: RingOutput,
    red_out: RingOutput,
    area_out: Output<Scalar>,
    hue_lo: Param<f64>,
    hue_hi: Param<f64>,
    sat_min: Param<f64>,
    int_min: Param<f64>,
    hsi: Vec<u8>,
    mask: Vec<u8>,
    processed: u64,
    refused: u64,
}

fn in_range(lo: f64, hi: f64) -> impl Fn(&f64) -> Result<(), String> + Send + Sync + 'static {
    move |v| {
        if (lo..=hi).contains(v) { Ok(()) } else { Err(format!("{v} is outside {lo} to {hi}")) }
    }
}

/// The number of pixels of a `width` x `height` RGB8 frame of `len` bytes,
/// or why the frame cannot be one. The sizes come from another process's
/// ring, so they are multiplied with checks (0xFFFF_FFFF squared, times 3,
/// overflows u64) and must fit in the bytes the frame holds (at most a slot).
fn rgb8_pixels(width: u32, height: u32, len: usize) -> Result<usize, String> {
    let pixels = u64::from(width) * u64::from(height); // at most (2^32-1)^2 < 2^64
    pixels
        .checked_mul(3)
        .filter(|bytes| *bytes <= len as u64)
        .and_then(|_| usize::try_from(pixels).ok())
        .ok_or_else(|| format!("it says {width}x{height} rgb8 (3 bytes a pixel) but holds {len} bytes"))
}

/// Why a frame was not processed.
enum Refusal {
    /// Not RGB8: the pixel format code.
    Format(u32),
    /// Sizes that do not fit the frame.
    Size(String),
}

impl ImageAgent {
    fn thresholds(&self) -> hsi::RedThresholds {
        hsi::RedThresholds {
            hue_lo: self.hue_lo.get() as f32,
            hue_hi: self.hue_hi.get() as f32,
            sat_min: self.sat_min.get() as f32,
            int_min: self.int_min.get() as f32,
        }
    }
}

impl Agent for ImageAgent {
    const KIND: &'static str = "image";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: ImageArgs = setup.args()?;
        let hint = |e: AgentError| match e {
            AgentError::Config(m) => {
                AgentError::Config(format!("{m}; this agent's rings are set with -- --hsi-ring NAME --red-ring NAME"))
            }
            e => e,
        };
        Ok(ImageAgent {
            frames: setup.ring_input("frames")?,
            hsi_out: setup
                .ring_output("hsi", RingSpec::new(args.slots, START_CAPACITY).named(&args.hsi_ring))
                .map_err(hint)?,
            red_out: setup
                .ring_output("red", RingSpec::new(args.slots, START_CAPACITY / 3).named(&args.red_ring))
                .map_err(hint)?,
            area_out: setup.output("red_area")?,
            hue_lo: setup.param_checked("hue_lo", 350.0, in_range(0.0, 360.0)),
            hue_hi: setup.param_checked("hue_hi", 10.0, in_range(0.0, 360.0)),
            sat_min: setup.param_checked("sat_min", 0.35, in_range(0.0, 1.0)),
            int_min: setup.param_checked("int_min", 0.08, in_range(0.0, 1.0)),
            hsi: Vec::new(),
            mask: Vec::new(),
            processed: 0,
            refused: 0,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        // create the rings now: a ring another agent writes stops this one here
        self.hsi_out.open()?;
        self.red_out.open()?;
        Ok(())
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let thr = self.thresholds();
        let (hsi, mask) = (&mut self.hsi, &mut self.mask);
        // read in place from the camera's ring, computing into our own
        // buffers; only an Ok result proves the pixels were intact
        let read = self.frames.latest_with(|meta, px| {
            if meta.format() != Some(PixelFormat::Rgb8) {
                return Err(Refusal::Format(meta.format_code));
            }
            let n = rgb8_pixels(meta.width, meta.height, px.len()).map_err(Refusal::Size)?;
            let red = hsi::convert(&px[..n * 3], &thr, hsi, mask);
            Ok((*meta, red))
        });
        let (meta, _red) = match read {
            Ok(None) => return Ok(()),
            Ok(Some(Ok(x))) => x,
            Ok(Some(Err(Refusal::Size(why)))) => {
                return Err(AgentError::Other(format!("the camera ring is inconsistent: a frame {why}")));
            }
            Ok(Some(Err(Refusal::Format(code)))) => {
                self.refused += 1;
                if self.refused.is_power_of_two() {
                    tracing::warn!(
                        "frames of pixel format code {code} are not rgb8; connect this input to a camera ({} refused)",
                        self.refused
                    );
                }
                return Ok(());
            }
            // a frame overwritten before we got to it: the next notice brings a newer one
            Err(MemoryError::Read(e)) => {
                tracing::debug!("frame skipped: {e}");
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        };
        let (w, h) = (meta.width, meta.height);
        let n = w as usize * h as usize;
        if self.hsi.len() < n * 3 || self.mask.len() < n {
            return Err(AgentError::Other(format!(
                "frame {} says {w}x{h} but holds {} bytes; the camera ring is inconsistent",
                meta.seq, meta.len
            )));
        }
        self.hsi_out.reserve(n * 3)?;
        self.red_out.reserve(n)?;
        let desc = |f| FrameDesc::image(w, h, f).stamped(meta.stamp_ns);
        self.hsi_out.write(desc(PixelFormat::Hsi8), &self.hsi[..n * 3])?;
        self.red_out.write(desc(PixelFormat::Gray8), &self.mask[..n])?;
        let area = hsi::largest_blob(&self.mask, w as usize, h as usize).map_or(0, |(a, _, _)| a);
        self.area_out.send(Scalar { value: area as f64, stamp_ns: meta.stamp_ns })?;
        self.processed += 1;
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) {
        tracing::info!("{} frames processed", self.processed);
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<ImageAgent>()
}

#[cfg(test)]
mod tests {
    use super::rgb8_pixels;

    #[test]
    fn frame_sizes_from_the_ring_are_checked_not_overflowed() {
        assert_eq!(rgb8_pixels(320, 240, 320 * 240 * 3), Ok(320 * 240));
        assert_eq!(rgb8_pixels(0, 0, 0), Ok(0));
        // 0xFFFF_FFFF squared times 3 overflows u64: refused, no panic
        let e = rgb8_pixels(u32::MAX, u32::MAX, 1 << 20).expect_err("absurd geometry");
        assert!(e.contains("4294967295x4294967295") && e.contains("1048576 bytes"), "{e}");
        // larger than the frame (and its slot) holds
        assert!(rgb8_pixels(320, 240, 320 * 240 * 3 - 1).is_err());
        assert!(rgb8_pixels(1 << 20, 1 << 20, usize::MAX / 2).is_ok());
        assert!(rgb8_pixels(u32::MAX, u32::MAX, usize::MAX).is_err(), "3 * (2^32-1)^2 bytes overflow u64");
    }
}
