//! Enumerating a robot's rings, for `nerve mem list`.

use crate::RingOptions;
use crate::error::OpenError;
use crate::name::{RingName, STM_INFIX};
use crate::reader::RingReader;
use crate::sys::monotonic_ns;
use serde::Serialize;
use shm_schemas::RobotName;
use std::path::PathBuf;

/// What `nerve mem list` shows about one ring.
#[derive(Debug, Clone, Serialize)]
pub struct RingInfo {
    /// The ring's name.
    pub name: RingName,
    /// Its file.
    pub path: PathBuf,
    /// Number of slots.
    pub slots: u32,
    /// Largest frame, in bytes.
    pub slot_capacity: u64,
    /// Size of the file, in bytes.
    pub file_bytes: u64,
    /// The last complete frame (0 while empty).
    pub last_seq: u64,
    /// Stamp of the newest frame in the ring.
    pub last_stamp_ns: Option<u64>,
    /// How long ago the newest frame was stored, in nanoseconds.
    pub last_age_ns: Option<u64>,
    /// Frames per second over the frames the ring holds (from their stamps);
    /// `None` with fewer than two frames.
    pub rate_hz: Option<f64>,
    /// The writer's pid, `None` if it closed the ring.
    pub writer_pid: Option<u32>,
    /// Whether that writer is alive.
    pub writer_alive: bool,
}

impl RingInfo {
    /// Summarises an open ring.
    pub fn of(reader: &RingReader) -> RingInfo {
        let mut stamps = reader.stamps();
        stamps.sort_unstable();
        let last_stamp_ns = stamps.last().map(|(_, st)| *st);
        let rate_hz = rate(&stamps);
        RingInfo {
            name: *reader.name(),
            path: reader.path().to_owned(),
            slots: reader.slot_count(),
            slot_capacity: reader.slot_capacity() as u64,
            file_bytes: std::fs::metadata(reader.path()).map(|m| m.len()).unwrap_or(0),
            last_seq: reader.last_seq().unwrap_or(0),
            last_stamp_ns,
            last_age_ns: last_stamp_ns.map(|st| monotonic_ns().saturating_sub(st)),
            rate_hz,
            writer_pid: reader.writer_pid(),
            writer_alive: reader.writer_alive(),
        }
    }
}

/// Frames per second from `(seq, stamp)` pairs sorted by seq: the frames
/// between the oldest and newest one, over the time between their stamps.
/// Counting by sequence number makes frames skipped while sampling harmless.
fn rate(sorted: &[(u64, u64)]) -> Option<f64> {
    let (first, last) = (sorted.first()?, sorted.last()?);
    let frames = last.0.checked_sub(first.0).filter(|n| *n > 0)?;
    let dt = last.1.checked_sub(first.1).filter(|d| *d > 0)?;
    Some(frames as f64 * 1e9 / dt as f64)
}

/// One entry of [`list_rings`]: a ring, or a file with the ring prefix that
/// could not be read (with why).
#[derive(Debug)]
pub struct ListedRing {
    /// The file.
    pub path: PathBuf,
    /// The ring's summary, or why it could not be opened.
    pub info: Result<RingInfo, OpenError>,
}

/// The rings of `robot` in `/dev/shm`, sorted by file name.
pub fn list_rings(robot: &RobotName) -> std::io::Result<Vec<ListedRing>> {
    list_rings_with(&RingOptions::default(), robot)
}

/// [`list_rings`] in `opts.base_dir`.
pub fn list_rings_with(opts: &RingOptions, robot: &RobotName) -> std::io::Result<Vec<ListedRing>> {
    let prefix = format!("{}{}", robot.shm_prefix(), STM_INFIX);
    let mut out = Vec::new();
    for entry in std::fs::read_dir(&opts.base_dir)? {
        let entry = entry?;
        let file_name = entry.file_name();
        let Some(rest) = file_name.to_str().and_then(|n| n.strip_prefix(&prefix)) else { continue };
        if RingName::parse(rest).is_err() {
            continue; // not a ring file name (e.g. a stray temporary)
        }
        let path = entry.path();
        let info = RingReader::open_path(&path).map(|r| RingInfo::of(&r));
        out.push(ListedRing { path, info });
    }
    out.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::rate;

    #[test]
    fn rate_from_stamps() {
        assert_eq!(rate(&[]), None);
        assert_eq!(rate(&[(1, 10)]), None);
        let r = rate(&[(1, 0), (2, 100_000_000), (4, 300_000_000)]).expect("rate");
        assert!((r - 10.0).abs() < 1e-9, "{r}");
    }
}
