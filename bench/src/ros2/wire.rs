//! The ROS 2 side of the `ros2` scenario, in the benchmark's own process:
//! plain Zenoh sessions opened with the `ros2` agent's own configuration
//! ([`nerve_ros2::link::zenoh_config`] of the agent's configuration file:
//! a client of the same router), as a ROS 2 node on rmw_zenoh would be.
//!
//! * [`Collector`]: one session, a subscriber on each key ([`Keys`]: the
//!   agent's Image, clock Image and Twist, the raw Image and Twist). Each
//!   callback reads the epoch clock first, then keeps what the measure
//!   needs: the attachment's source timestamp, an Image's header stamp,
//!   event number and geometry (read from the first bytes of the message,
//!   the rest untouched), a Twist's `linear.x` (the event number).
//! * [`raw_puts`]: a second session, so that its puts cross the router as
//!   the agent's do (a put to a subscriber of the same session would not
//!   leave the process), declaring its publishers as the agent declares its
//!   own (`CongestionControl::Drop`) and putting, in turn, the very CDR
//!   bytes the agent writes for a frame (encoded before the clock is read)
//!   and for a Twist, each with an rmw_zenoh attachment.

use super::source::{Gaps, epoch_ns};
use anyhow::{Context as _, Result, anyhow};
use nerve_ros2::cdr;
use nerve_ros2::msgs::{RosMessage as _, Twist, Vector3};
use nerve_ros2::wire::Attachment;
use std::io::Read as _;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait as _;
use zenoh::qos::CongestionControl;

/// One received message: when, and what it said.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Received {
    /// event number (the Twist's `linear.x`, the frame's first 8 bytes)
    pub seq: u64,
    /// epoch ns when the callback began
    pub t_recv: i64,
    /// the attachment's source timestamp (the put), epoch ns
    pub t_put: i64,
    /// the Image's header stamp, epoch ns (0 for a Twist)
    pub t_stamp: i64,
    /// an Image of the expected geometry and size (always true for a Twist)
    pub ok: bool,
}

/// What each subscriber received.
#[derive(Debug, Default)]
pub struct Received3 {
    /// the agent's 640x480 Images
    pub image: Vec<Received>,
    /// the agent's clock Images (the steps of the Twist events)
    pub clock: Vec<Received>,
    /// the agent's Twists
    pub twist: Vec<Received>,
    /// the raw Image puts
    pub raw_image: Vec<Received>,
    /// the raw Twist puts
    pub raw: Vec<Received>,
}

/// The data keys the collector subscribes to.
#[derive(Debug, Clone)]
pub struct Keys {
    /// the agent's Image
    pub image: String,
    /// the agent's clock Image
    pub clock: String,
    /// the agent's Twist
    pub twist: String,
    /// the raw Image
    pub raw_image: String,
    /// the raw Twist
    pub raw_twist: String,
}

/// The geometry an Image must have: width, height, encoding.
type Geometry = (u32, u32, &'static str);
/// A 640x480 frame.
pub const FRAME: Geometry = (super::source::WIDTH, super::source::HEIGHT, "rgb8");
/// A clock frame.
pub const CLOCK: Geometry = (super::source::CLOCK_WIDTH, 1, "mono8");

/// The bench's subscribing session.
pub struct Collector {
    session: zenoh::Session,
    subs: Vec<zenoh::pubsub::Subscriber<()>>,
    got: Arc<Mutex<Received3>>,
}

fn lock(m: &Mutex<Received3>) -> std::sync::MutexGuard<'_, Received3> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn source_timestamp(sample: &zenoh::sample::Sample) -> i64 {
    sample.attachment().and_then(|a| Attachment::decode(&a.to_bytes()).ok()).map_or(0, |a| a.source_timestamp)
}

/// Reads an Image's header stamp, event number (its first 8 data bytes)
/// and whether it has geometry `g` from the start of its CDR (`prefix`),
/// given the message's whole length.
pub fn image_head(prefix: &[u8], total: usize, g: Geometry) -> Result<(i64, u64, bool), cdr::CdrError> {
    let mut r = cdr::Reader::new(prefix)?;
    let (sec, nanosec) = (r.i32()?, r.u32()?);
    let _frame = r.string()?;
    let (height, width) = (r.u32()?, r.u32()?);
    let encoding = r.string()? == g.2;
    let _bigendian = r.u8()?;
    let step = r.u32()?;
    let n = r.u32()?;
    let mut seq = [0u8; 8];
    for b in &mut seq {
        *b = r.u8()?;
    }
    let channels = if g.2 == "rgb8" { 3 } else { 1 };
    let ok = encoding
        && (width, height) == (g.0, g.1)
        && step == width * channels
        && u64::from(n) == u64::from(step) * u64::from(height)
        && total >= n as usize;
    Ok((i64::from(sec) * 1_000_000_000 + i64::from(nanosec), u64::from_le_bytes(seq), ok))
}

/// Which list of [`Received3`] a subscriber fills.
#[derive(Debug, Clone, Copy)]
enum Slot {
    Image(Geometry),
    Clock,
    Twist,
    RawImage,
    RawTwist,
}

fn record(sample: &zenoh::sample::Sample, slot: Slot, t_recv: i64) -> Received {
    let t_put = source_timestamp(sample);
    let payload = sample.payload();
    let image = |g: Geometry| {
        let mut prefix = [0u8; 128];
        let mut n = 0;
        let mut rd = payload.reader();
        while n < prefix.len() {
            match rd.read(&mut prefix[n..]) {
                Ok(0) | Err(_) => break,
                Ok(k) => n += k,
            }
        }
        let (t_stamp, seq, ok) = image_head(&prefix[..n], payload.len(), g).unwrap_or((0, u64::MAX, false));
        Received { seq, t_recv, t_put, t_stamp, ok }
    };
    match slot {
        Slot::Image(g) => image(g),
        Slot::RawImage => image(FRAME),
        Slot::Clock => image(CLOCK),
        Slot::Twist | Slot::RawTwist => {
            let t = Twist::from_cdr(&payload.to_bytes()).ok();
            Received { seq: t.map_or(u64::MAX, |t| t.linear.x as u64), t_recv, t_put, t_stamp: 0, ok: t.is_some() }
        }
    }
}

/// Opens a session of the agent's configuration `cfg`.
pub fn open(cfg: &nerve_ros2::config::Config) -> Result<zenoh::Session> {
    let z = nerve_ros2::link::zenoh_config(cfg).map_err(|e| anyhow!("{e}"))?;
    zenoh::open(z).wait().map_err(|e| anyhow!("cannot open the benchmark's zenoh session: {e}"))
}

impl Collector {
    /// Subscribes to the keys.
    pub fn new(cfg: &nerve_ros2::config::Config, keys: &Keys) -> Result<Self> {
        let session = open(cfg)?;
        let got = Arc::new(Mutex::new(Received3::default()));
        let mut subs = Vec::new();
        let slots = [
            (&keys.image, Slot::Image(FRAME)),
            (&keys.clock, Slot::Clock),
            (&keys.twist, Slot::Twist),
            (&keys.raw_image, Slot::RawImage),
            (&keys.raw_twist, Slot::RawTwist),
        ];
        for (key, slot) in slots {
            let got = got.clone();
            subs.push(
                session
                    .declare_subscriber(key.clone())
                    .callback(move |sample| {
                        let t_recv = epoch_ns();
                        let rec = record(&sample, slot, t_recv);
                        let mut g = lock(&got);
                        match slot {
                            Slot::Image(_) => g.image.push(rec),
                            Slot::Clock => g.clock.push(rec),
                            Slot::Twist => g.twist.push(rec),
                            Slot::RawImage => g.raw_image.push(rec),
                            Slot::RawTwist => g.raw.push(rec),
                        }
                    })
                    .wait()
                    .map_err(|e| anyhow!("cannot subscribe to {key}: {e}"))?,
            );
        }
        Ok(Collector { session, subs, got })
    }

    /// Waits until the router knows the agent's publishers of `topics`
    /// (their liveliness tokens), at most `timeout`.
    pub fn wait_publishers(&self, topics: &[&str], timeout: Duration) -> Result<()> {
        let t0 = Instant::now();
        loop {
            let replies = self
                .session
                .liveliness()
                .get("@ros2_lv/**")
                .timeout(Duration::from_millis(500))
                .wait()
                .map_err(|e| anyhow!("liveliness query: {e}"))?;
            let mut tokens = Vec::new();
            while let Ok(r) = replies.recv() {
                if let Ok(s) = r.result() {
                    tokens.push(s.key_expr().to_string());
                }
            }
            let found =
                |t: &&str| tokens.iter().any(|k| k.contains("/MP/") && k.contains(&nerve_ros2::wire::mangle(t)));
            if topics.iter().all(found) {
                return Ok(());
            }
            if t0.elapsed() > timeout {
                anyhow::bail!(
                    "the ros2 agent's publishers of {topics:?} did not appear within {timeout:?} (tokens: {tokens:?})"
                );
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Everything received so far; the subscribers and the session closed.
    pub fn finish(self) -> Received3 {
        let Collector { session, subs, got } = self;
        drop(subs);
        let _ = session.close().wait();
        std::mem::take(&mut *lock(&got))
    }
}

/// The CDR of the Twist the agent writes for event `i`
/// (`VelocityCommand { v: i, omega: 0 }`).
pub fn twist_cdr(i: u64) -> Result<Vec<u8>> {
    let zero = Vector3 { x: 0.0, y: 0.0, z: 0.0 };
    Twist { linear: Vector3 { x: i as f64, ..zero }, angular: zero }.to_cdr().context("a Twist as CDR")
}

/// Puts `count` Images and `count` Twists (event numbers 0..count), in
/// turn, from a session of its own, one after each gap of `gaps`. The
/// attachment carries each put's epoch time.
pub fn raw_puts(cfg: &nerve_ros2::config::Config, keys: &Keys, count: usize, mut gaps: Gaps) -> Result<()> {
    let session = open(cfg)?;
    let declare = |key: &str| {
        session
            .declare_publisher(key.to_owned())
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(|e| anyhow!("cannot declare the raw publisher {key}: {e}"))
    };
    let (image, twist) = (declare(&keys.raw_image)?, declare(&keys.raw_twist)?);
    let gid = nerve_ros2::wire::gid_of(&keys.raw_twist);
    let mut px = vec![0u8; super::source::FRAME_BYTES];
    let mut next = agent_sdk::clock::now_ns();
    for e in 0..2 * count {
        next = next.saturating_add(gaps.next_ns());
        agent_sdk::clock::sleep_until_ns(next);
        let i = e / 2;
        let (publisher, bytes) = if e % 2 == 0 {
            px[..8].copy_from_slice(&(i as u64).to_le_bytes());
            let stamp = nerve_ros2::msgs::Time::from_ns(i128::from(epoch_ns()));
            let (w, h, enc) = FRAME;
            let bytes = nerve_ros2::convert::image_cdr(stamp, "camera", w, h, enc, 3, &px)
                .context("a frame fits")?
                .context("a frame as CDR")?;
            (&image, bytes)
        } else {
            (&twist, twist_cdr(i as u64)?)
        };
        // as the agent's publishers: the attachment's stamp, then the put
        let t_put = epoch_ns();
        let att = Attachment { sequence_number: e as i64 + 1, source_timestamp: t_put, gid }.encode();
        publisher.put(bytes).attachment(att.to_vec()).wait().map_err(|e| anyhow!("raw put: {e}"))?;
    }
    drop((image, twist));
    let _ = session.close().wait();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An Image written by the agent's own encoder reads back: stamp,
    /// event number, geometry; a prefix too short is an error.
    #[test]
    fn image_head_reads_what_the_agent_writes() {
        let mut px = vec![0u8; super::super::source::FRAME_BYTES];
        px[..8].copy_from_slice(&42u64.to_le_bytes());
        let stamp = nerve_ros2::msgs::Time { sec: 3, nanosec: 7 };
        let b = nerve_ros2::convert::image_cdr(stamp, "camera", 640, 480, "rgb8", 3, &px).expect("fits").expect("cdr");
        assert_eq!(image_head(&b[..128], b.len(), FRAME).expect("reads"), (3_000_000_007, 42, true));
        assert!(!image_head(&b[..128], b.len(), CLOCK).expect("reads").2, "another geometry");
        assert!(image_head(&b[..20], b.len(), FRAME).is_err());
        let t = Twist::from_cdr(&twist_cdr(9).expect("cdr")).expect("reads");
        assert_eq!(t.linear.x, 9.0);
    }
}
