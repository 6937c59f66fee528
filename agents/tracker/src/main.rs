//! `tracker`: the image tracker (thesis section 4.2.2.3). Event-driven on
//! input `mask` (`nerve::RingNotice`; connect it to the image agent's `red`
//! output): for the newest announced mask it reads the `gray8` frame in
//! place from short-term memory, finds the largest red blob and its centre
//! (library `nerve_tracker`), and sends
//!
//! * output `head_cmd` (`nerve::HeadCommand`): the head turns to centre the target;
//! * output `cmd` (`nerve::VelocityCommand`): the foot turns toward it, comes
//!   closer while it is small, stops once it is close (and stays stopped
//!   until the target steps back: `release`); nothing is sent
//!   while no target is seen, so that the other sources lead;
//! * output `situation` (`nerve::Situation`): target none / seen / close,
//!   its size and bearing, for the decision maker.
//!
//! Optional input `head` (`nerve::HeadState`): the measured head position;
//! without it the tracker trusts its own last set-point.
//!
//! Silent input: with no mask the tracker does not run, so it sends
//! nothing; the motor's staleness check drops its last command within
//! 0.5 s, and the decision maker sees its report go stale (target
//! `unknown`). After `lost_frames` frames without a target the head looks
//! ahead again.

use agent_sdk::memory::{MemorySetup, PixelFormat, RingInput};
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use nerve_tracker::{Blob, BlobFinder, MaskError, Settings, steer};
use shm_schemas::payloads::{HeadCommand, HeadState, Situation, TargetState, VelocityCommand};

/// Speed changes sent are limited to this, m/s² (the motor refuses jumps over 5).
const ACCEL: f32 = 3.0;
/// Turn-rate changes are limited to this, rad/s² (the motor refuses jumps over 20).
const ALPHA: f32 = 12.0;
/// A head state older than this is not trusted, ns.
const HEAD_FRESH_NS: u64 = 500_000_000;

struct Tracker {
    mask: RingInput,
    head: Input<HeadState>,
    head_cmd: Output<HeadCommand>,
    cmd: Output<VelocityCommand>,
    situation: Output<Situation>,
    min_area: Param<u64>,
    close_size: Param<f32>,
    release: Param<f32>,
    v_max: Param<f32>,
    lost_frames: Param<u64>,
    finder: BlobFinder,
    pan_tilt: (f32, f32),
    head_seen_ns: Option<u64>,
    sent: Option<(f32, f32, u64)>,
    lost: u64,
    state: TargetState,
}

fn slew(from: f32, to: f32, rate: f32, dt: f32) -> f32 {
    let d = rate * dt.max(0.0);
    to.clamp(from - d, from + d)
}

impl Agent for Tracker {
    const KIND: &'static str = "tracker";

    fn task() -> agent_sdk::Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let d = Settings::default();
        Ok(Tracker {
            mask: setup.ring_input("mask")?,
            head: setup.input("head")?,
            head_cmd: setup.output("head_cmd")?,
            cmd: setup.output("cmd")?,
            situation: setup.output("situation")?,
            min_area: setup.param_checked("min_area", d.min_area as u64, |v| {
                if *v >= 1 { Ok(()) } else { Err("min_area is at least 1 pixel".into()) }
            }),
            close_size: setup.param_checked("close_size", d.close_size, |v| {
                if *v > 0.0 && *v <= 1.0 { Ok(()) } else { Err("close_size is a fraction in (0, 1]".into()) }
            }),
            release: setup.param_checked("release", d.release, |v| {
                if *v > 0.0 && *v <= 1.0 { Ok(()) } else { Err("release is a fraction of close_size in (0, 1]".into()) }
            }),
            v_max: setup.param_checked("v_max", d.v_max, |v| {
                if v.is_finite() && *v >= 0.0 && *v <= 0.8 { Ok(()) } else { Err("v_max is in [0, 0.8] m/s".into()) }
            }),
            lost_frames: setup.param("lost_frames", 15u64),
            finder: BlobFinder::default(),
            pan_tilt: (0.0, 0.0),
            head_seen_ns: None,
            sent: None,
            lost: 0,
            state: TargetState::None,
        })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        if let Some((_, h)) = self.head.latest()
            && h.pan_rad.is_finite()
            && h.tilt_rad.is_finite()
        {
            self.pan_tilt = (h.pan_rad as f32, h.tilt_rad as f32);
            self.head_seen_ns = Some(now);
        }
        let finder = &mut self.finder;
        let found = self.mask.latest_with(|meta, px| -> Result<(Option<Blob>, usize, usize), String> {
            if meta.format() != Some(PixelFormat::Gray8) {
                return Err(format!(
                    "frames of pixel format code {} are not gray8 masks; connect `mask` to the image agent's `red` output",
                    meta.format_code
                ));
            }
            let (w, h) = (meta.width as usize, meta.height as usize);
            finder.largest_blob(px, w, h).map(|b| (b, w, h)).map_err(|e: MaskError| e.to_string())
        });
        let (blob, w, h) = match found {
            Ok(None) => return Ok(()), // woken without a new notice
            Ok(Some(Ok(x))) => x,
            Ok(Some(Err(e))) => return Err(AgentError::Other(e)),
            Err(e) => return Err(e.into()),
        };
        let s = Settings {
            min_area: self.min_area.get() as usize,
            close_size: self.close_size.get(),
            release: self.release.get(),
            v_max: self.v_max.get(),
            ..Settings::default()
        };
        let (pan, tilt) = self.pan_tilt;
        let st = steer(blob.as_ref(), w, h, pan, tilt, self.state == TargetState::Close, &s);
        if st.state != self.state {
            tracing::info!("target {} (size {:.3}, bearing {:.2} rad)", st.state.name(), st.size, st.bearing);
            self.state = st.state;
        }
        self.situation.send(Situation::target(st.state, st.size, st.bearing, now))?;
        if st.state == TargetState::None {
            self.lost += 1;
            self.sent = None;
            if self.lost == self.lost_frames.get() {
                self.pan_tilt = (0.0, 0.0);
                self.head_cmd.send(HeadCommand { pan_rad: 0.0, tilt_rad: 0.0, stamp_ns: now })?;
            }
            return Ok(());
        }
        self.lost = 0;
        // without a fresh measured head position, trust our own set-point
        if self.head_seen_ns.is_none_or(|t| now.saturating_sub(t) > HEAD_FRESH_NS) {
            self.pan_tilt = (st.pan, st.tilt);
        }
        self.head_cmd.send(HeadCommand { pan_rad: f64::from(st.pan), tilt_rad: f64::from(st.tilt), stamp_ns: now })?;
        let (v0, w0, t0) = self.sent.unwrap_or((0.0, 0.0, now.saturating_sub(66_000_000)));
        let dt = now.saturating_sub(t0) as f32 / 1e9;
        let (v, omega) = (slew(v0, st.v, ACCEL, dt), slew(w0, st.omega, ALPHA, dt));
        self.sent = Some((v, omega, now));
        self.cmd.send(VelocityCommand { v: f64::from(v), omega: f64::from(omega), stamp_ns: now })?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Tracker>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::memory::stm::RingWriter;
    use agent_sdk::memory::{FrameDesc, RingName, RingOptions};
    use agent_sdk::testing::Harness;
    use std::time::Duration;

    const W: usize = 320;
    const H: usize = 240;

    /// A gray8 mask with a filled square of side `side` centred at column `cx`.
    fn mask(cx: usize, side: usize) -> Vec<u8> {
        let mut px = vec![0u8; W * H];
        let (x0, y0) = (cx.saturating_sub(side / 2), (H - side) / 2);
        for y in y0..y0 + side {
            for x in x0..(x0 + side).min(W) {
                px[y * W + x] = 255;
            }
        }
        px
    }

    /// The tracker as it runs, reading masks from a real ring of the
    /// harness's robot (the image agent's `red` output stood in by a ring
    /// writer): a target to the right turns the head and the foot right, a large one stops the robot, and losing it for
    /// `lost_frames` frames brings the head home.
    #[test]
    fn the_tracker_follows_a_target_in_the_masks_and_brings_the_head_home_when_it_is_lost() {
        let mut h = Harness::<Tracker>::builder().param("lost_frames", "3").start().expect("start");
        let ring = RingName::text("mask").expect("ring name");
        let mut writer =
            RingWriter::create_with(&RingOptions::default(), h.world().robot(), &ring, 4, W * H).expect("ring");
        let mut show = |h: &mut Harness<Tracker>, px: &[u8]| {
            let notice = writer
                .write_with(FrameDesc::image(W as u32, H as u32, PixelFormat::Gray8), px.len(), |b| {
                    b.copy_from_slice(px)
                })
                .expect("write");
            h.send("mask", notice).expect("notice");
            h.advance(Duration::from_millis(66)).expect("time");
            h.step().expect("step");
        };

        // a small target right of centre: seen; head and foot turn right, the foot drives on
        for _ in 0..5 {
            show(&mut h, &mask(280, 20));
        }
        let sit = h.output::<Situation>("situation").expect("situation");
        assert_eq!(sit.len(), 5);
        assert!(sit.iter().all(|s| s.target_state() == Some(TargetState::Seen)), "{sit:?}");
        assert!(sit[4].target_bearing_rad < 0.0, "to the right: {:?}", sit[4]);
        let head = h.output::<HeadCommand>("head_cmd").expect("head");
        assert!(head.last().is_some_and(|c| c.pan_rad < 0.0), "{head:?}");
        // (the head keeps turning toward it, so the bearing grows and the foot
        // slows to turn on the spot)
        let cmd = h.output::<VelocityCommand>("cmd").expect("cmd");
        assert!(cmd[0].v > 0.0 && cmd.iter().all(|c| c.omega < 0.0), "{cmd:?}");

        // large and straight ahead: close, the foot stops (ramping down)
        for _ in 0..10 {
            show(&mut h, &mask(W / 2, 140));
        }
        let sit = h.output::<Situation>("situation").expect("situation");
        assert_eq!(sit.last().and_then(|s| s.target_state()), Some(TargetState::Close));
        assert_eq!(h.output::<VelocityCommand>("cmd").expect("cmd").last().map(|c| c.v), Some(0.0));

        // gone: after 3 empty masks the head is sent home, once
        h.output::<HeadCommand>("head_cmd").expect("head");
        for _ in 0..5 {
            show(&mut h, &mask(0, 0));
        }
        let head = h.output::<HeadCommand>("head_cmd").expect("head");
        assert_eq!(head.len(), 1, "{head:?}");
        assert_eq!((head[0].pan_rad, head[0].tilt_rad), (0.0, 0.0));

        // a wake-up without a notice (the head's state) changes nothing
        h.send("head", HeadState::default()).expect("head state");
        h.step().expect("step");
        assert!(h.output::<Situation>("situation").expect("situation").len() == 5);
        writer.remove().expect("remove the ring");
    }

    /// Frames that are not gray8 masks fail the step with what to connect.
    #[test]
    fn a_frame_that_is_not_a_mask_is_refused_with_what_to_connect() {
        let mut h = Harness::<Tracker>::new().expect("start");
        let ring = RingName::text("rgb").expect("ring name");
        let mut writer =
            RingWriter::create_with(&RingOptions::default(), h.world().robot(), &ring, 2, W * H * 3).expect("ring");
        let notice = writer
            .write_with(FrameDesc::image(W as u32, H as u32, PixelFormat::Rgb8), W * H * 3, |b| b.fill(0))
            .expect("write");
        h.send("mask", notice).expect("notice");
        let e = h.step().expect_err("an rgb frame").to_string();
        assert!(e.contains("red"), "{e}");
        writer.remove().expect("remove the ring");
    }
}
