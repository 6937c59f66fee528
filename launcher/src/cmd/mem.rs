//! `nerve mem`: look into the robot's short-term memory.
//!
//! * `nerve mem list [--json]` — every ring of the robot
//!   (`/dev/shm/nerve_<uid>_<robot>_stm_*`): name, slots, slot size, last sequence
//!   number, frame rate (from the stamps of the frames it holds), age of the
//!   newest frame, the newest frame's geometry and format, and the writer
//!   (pid, alive or gone). Files that cannot be read as rings are listed
//!   with the reason.
//! * `nerve mem dump RING [--seq N | --at TIME] --out FILE.png` — writes one
//!   image frame as a viewable PNG (`rgb8` as RGB, `gray8` and masks as
//!   grey, `hsi8` converted back to RGB). Without `--seq`/`--at`, the newest
//!   frame. `TIME` is a CLOCK_MONOTONIC time in nanoseconds (as in notices
//!   and `--json` outputs), or relative to now: `-2s`, `-150ms`; the frame
//!   stamped nearest to it is taken.
//!
//! Both only read: a reader maps the ring read-only and never disturbs its
//! writer.

use agent_sdk::World;
use agent_sdk::clock::parse_duration;
use anyhow::{Context as _, Result};
use nerve_stm::{FrameSelector, ListedRing, RingName, RingReader, dump_png, list_rings, monotonic_ns};
use serde_json::{Value, json};
use std::path::PathBuf;
use std::process::ExitCode;

/// `nerve mem ...`
#[derive(Debug, clap::Subcommand)]
pub enum MemCmd {
    /// List the robot's short-term-memory rings.
    List {
        /// Print JSON (one array of rings) instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Write one image frame of a ring as a PNG file.
    Dump {
        /// The ring: its name (cam) or number (id-42).
        ring: String,
        /// The frame with this sequence number (default: the newest).
        #[arg(long, conflicts_with = "at")]
        seq: Option<u64>,
        /// The frame stamped nearest to TIME: CLOCK_MONOTONIC ns, or relative to now (-2s, -150ms).
        #[arg(long, allow_hyphen_values = true)]
        at: Option<String>,
        /// The PNG file to write.
        #[arg(long)]
        out: PathBuf,
    },
}

/// Runs `nerve mem`.
pub fn mem(world: &World, cmd: MemCmd) -> Result<ExitCode> {
    match cmd {
        MemCmd::List { json } => list(world, json),
        MemCmd::Dump { ring, seq, at, out } => dump(world, &ring, seq, at.as_deref(), &out),
    }
}

/// Parses `--at`: absolute monotonic ns, or `-DURATION` before now.
fn parse_time(text: &str, now_ns: u64) -> Result<u64> {
    let t = text.trim();
    if let Some(rel) = t.strip_prefix('-') {
        let d = parse_duration(rel)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--at {text}: a relative time is a duration before now, like -2s or -150ms"))?;
        return Ok(now_ns.saturating_sub(d.as_nanos() as u64));
    }
    t.parse::<u64>().with_context(|| {
        format!(
            "--at {text}: give a CLOCK_MONOTONIC time in nanoseconds (as shown by `nerve mem list --json`) or a time before now like -2s"
        )
    })
}

fn dump(world: &World, ring: &str, seq: Option<u64>, at: Option<&str>, out: &std::path::Path) -> Result<ExitCode> {
    let name = RingName::parse(ring).with_context(|| format!("ring {ring:?}"))?;
    let reader = RingReader::open(world.robot(), &name).with_context(|| {
        format!("cannot read ring {name} of robot {} (`nerve mem list` shows its rings)", world.robot())
    })?;
    let now = monotonic_ns();
    let which = match (seq, at) {
        (Some(s), _) => FrameSelector::Seq(s),
        (None, Some(t)) => FrameSelector::Nearest(parse_time(t, now)?),
        (None, None) => FrameSelector::Latest,
    };
    let meta = dump_png(&reader, which, out).with_context(|| match reader.seq_range() {
        Some((lo, hi)) => format!("ring {name} holds frames {lo} to {hi}; no PNG written"),
        None => format!("ring {name} holds no frame yet; no PNG written"),
    })?;
    println!(
        "wrote {}: ring {name} frame {} ({}x{} {}, stamped {} ago)",
        out.display(),
        meta.seq,
        meta.width,
        meta.height,
        meta.format().map_or_else(|| format!("code {}", meta.format_code), |f| f.to_string()),
        age(now.saturating_sub(meta.stamp_ns))
    );
    Ok(ExitCode::SUCCESS)
}

/// The newest frame's geometry, format and stamp, if it can be read.
fn newest(path: &std::path::Path) -> Option<nerve_stm::FrameMeta> {
    let r = RingReader::open_path(path).ok()?;
    let last = r.last_seq()?;
    r.meta(last).ok()
}

fn to_json(e: &ListedRing) -> Value {
    match &e.info {
        Ok(info) => {
            let mut v = serde_json::to_value(info).unwrap_or(Value::Null);
            if let (Value::Object(m), Some(f)) = (&mut v, newest(&e.path)) {
                m.insert("width".into(), json!(f.width));
                m.insert("height".into(), json!(f.height));
                m.insert("format".into(), json!(f.format().map(|x| x.as_str())));
                m.insert("last_len".into(), json!(f.len));
            }
            v
        }
        Err(err) => json!({ "path": e.path, "error": err.to_string() }),
    }
}

/// A duration for people: `850us`, `42ms`, `1.5s`, `12s`.
fn age(ns: u64) -> String {
    match ns {
        n if n < 1_000_000 => format!("{}us", n / 1_000),
        n if n < 1_000_000_000 => format!("{}ms", n / 1_000_000),
        n if n < 10_000_000_000 => format!("{:.1}s", n as f64 / 1e9),
        n => format!("{}s", n / 1_000_000_000),
    }
}

fn bytes(n: u64) -> String {
    match n {
        n if n >= 10 << 20 => format!("{}MiB", n >> 20),
        n if n >= 10 << 10 => format!("{}KiB", n >> 10),
        n => format!("{n}B"),
    }
}

fn list(world: &World, as_json: bool) -> Result<ExitCode> {
    let rings = list_rings(world.robot()).context("cannot list /dev/shm")?;
    if as_json {
        let v: Vec<Value> = rings.iter().map(to_json).collect();
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(ExitCode::SUCCESS);
    }
    if rings.is_empty() {
        println!("robot {}: no rings (a camera agent creates ring cam when it starts)", world.robot());
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "{:<8} {:>6} {:>9} {:>10} {:>8} {:>9}  {:<18} WRITER",
        "RING", "SLOTS", "SLOT", "LAST_SEQ", "RATE", "AGE", "FRAME"
    );
    for e in &rings {
        match &e.info {
            Ok(i) => {
                let frame = newest(&e.path).map_or_else(
                    || "-".to_owned(),
                    |f| match f.format() {
                        Some(nerve_stm::PixelFormat::Raw) | None => format!("{} B raw", f.len),
                        Some(fmt) => format!("{}x{} {fmt}", f.width, f.height),
                    },
                );
                println!(
                    "{:<8} {:>6} {:>9} {:>10} {:>8} {:>9}  {:<18} {}",
                    i.name.to_string(),
                    i.slots,
                    bytes(i.slot_capacity),
                    i.last_seq,
                    i.rate_hz.map_or_else(|| "-".into(), |r| format!("{r:.1}Hz")),
                    i.last_age_ns.map_or_else(|| "-".into(), age),
                    frame,
                    match (i.writer_pid, i.writer_alive) {
                        (Some(p), true) => format!("pid {p}"),
                        (Some(p), false) => format!("pid {p} (gone)"),
                        (None, _) => "closed".into(),
                    }
                );
            }
            Err(err) => println!("{:<8} {err}", e.path.display()),
        }
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times() {
        assert_eq!(parse_time("123456789", 10).expect("abs"), 123_456_789);
        assert_eq!(parse_time("-2s", 5_000_000_000).expect("rel"), 3_000_000_000);
        assert_eq!(parse_time("-150ms", 1_000_000_000).expect("rel"), 850_000_000);
        assert_eq!(parse_time("-2s", 1).expect("saturates"), 0);
        assert!(parse_time("yesterday", 1).is_err());
        assert!(parse_time("-soon", 1).is_err());
    }

    #[test]
    fn sizes() {
        assert_eq!(bytes(230_400), "225KiB");
        assert_eq!(bytes(64), "64B");
        assert_eq!(age(42_000_000), "42ms");
        assert_eq!(age(1_500_000_000), "1.5s");
    }
}
