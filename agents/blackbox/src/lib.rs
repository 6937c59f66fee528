//! The black box: the thesis' short-term memory put to work after a fault.
//!
//! A `blackbox` agent keeps the last seconds of chosen output ports in
//! memory (each sample's bytes, and for a port that carries ring notices
//! the frames they name, encoded as images), and writes them to an MCAP
//! file in nerve's recording format (`nerve_recording`) when asked
//! (`nerve snapshot`) or by itself when something goes wrong: an agent
//! died, or a watched field changed (the safety stop, the mode). A fired
//! snapshot waits [`Config::after`] seconds, so that the moment itself and
//! what followed are in the file too.
//!
//! This library holds what needs no robot: the configuration file
//! ([`Config`]), the memory ([`Memory`]), the writing of a snapshot
//! ([`write_snapshot`]) and the keeping of its folder ([`Folder`]);
//! `main.rs` is the agent.
//!
//! The black box must never fill the disk it shares with the robot's
//! state: the snapshots it fires are capped by count ([`Config::max_files`])
//! and total size ([`Config::max_total_mb`]), the oldest deleted first; it
//! writes none while the disk's free space is below
//! [`Config::min_free_mb`] (said once, counted); a snapshot that fails is
//! removed, and `.part` files left by a crash are swept at start.

use nerve_recording::{PortChannel, RecordingError, RecordingWriter, Sample};
use serde::Deserialize;
use shm_schemas::{PortRef, Schema};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Why the configuration file was refused.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// It could not be read.
    #[error("cannot read the black box's configuration {path}: {source}")]
    Read {
        /// the file
        path: PathBuf,
        /// why
        source: std::io::Error,
    },
    /// It is not valid TOML for a black box (the message names the line).
    #[error("{path}: {message}")]
    Parse {
        /// the file
        path: PathBuf,
        /// what is wrong, and where
        message: String,
    },
    /// A value is out of range or names something malformed.
    #[error("{path}: {message}")]
    Invalid {
        /// the file
        path: PathBuf,
        /// what is wrong and what to write instead
        message: String,
    },
}

/// The black box's configuration file (TOML).
///
/// ```toml
/// seconds = 10                      # keep the last 10 s
/// ports = ["t1/tick", "cam/frames"] # AGENT/PORT, or "*" for every output port
/// dir = "snapshots"                 # fired snapshots go here (relative to this file)
/// max_mb = 512                      # memory budget: the oldest samples go first
/// after = 1.0                       # seconds kept after an event before writing
/// max_files = 20                    # fired snapshots kept in dir: the oldest go first
/// max_total_mb = 4096               # and their total size
/// min_free_mb = 1024                # no snapshot while the disk has less free
///
/// [fire]
/// on_death = true                   # an agent died (not a clean stop)
/// min_gap = 5.0                     # at most one fired snapshot per 5 s
/// [[fire.on_change]]
/// port = "safety/stop"
/// field = "active"
/// ```
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Seconds of history kept.
    #[serde(default = "default_seconds")]
    pub seconds: f64,
    /// The ports kept: `AGENT/PORT`, or `*` for every output port of the robot.
    pub ports: Vec<String>,
    /// Where fired snapshots are written; relative to the file's folder.
    #[serde(default = "default_dir")]
    pub dir: PathBuf,
    /// Memory budget, MB.
    #[serde(default = "default_max_mb")]
    pub max_mb: u64,
    /// Seconds after an event included in its snapshot.
    #[serde(default = "default_after")]
    pub after: f64,
    /// The most fired snapshots kept in `dir` (the oldest are deleted).
    #[serde(default = "default_max_files")]
    pub max_files: usize,
    /// The most MB the fired snapshots in `dir` take together (the oldest
    /// are deleted); at least `max_mb`, the size of one.
    #[serde(default = "default_max_total_mb")]
    pub max_total_mb: u64,
    /// MB that must stay free on the disk of `dir` (and of a path `nerve
    /// snapshot` names) after a snapshot; below it none is written.
    #[serde(default = "default_min_free_mb")]
    pub min_free_mb: u64,
    /// What fires a snapshot by itself.
    #[serde(default)]
    pub fire: Fire,
}

/// What fires a snapshot by itself.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fire {
    /// An agent of the robot died (the router saw its process end without
    /// unregistering); a clean `nerve stop` does not fire.
    #[serde(default)]
    pub on_death: bool,
    /// A field of a kept port changed value.
    #[serde(default)]
    pub on_change: Vec<Change>,
    /// Seconds between two fired snapshots at least (an event storm
    /// writes one file, not hundreds).
    #[serde(default = "default_min_gap")]
    pub min_gap: f64,
}

/// A watched field.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Change {
    /// `AGENT/PORT` (kept too, whether or not `ports` names it)
    pub port: String,
    /// a field path as `nerve echo --field` takes it (`active`, `pose.x`)
    pub field: String,
}

fn default_seconds() -> f64 {
    10.0
}
fn default_dir() -> PathBuf {
    PathBuf::from("blackbox")
}
fn default_max_mb() -> u64 {
    512
}
fn default_after() -> f64 {
    1.0
}
fn default_min_gap() -> f64 {
    5.0
}
fn default_max_files() -> usize {
    20
}
fn default_max_total_mb() -> u64 {
    4096
}
fn default_min_free_mb() -> u64 {
    1024
}

/// The most fired snapshots a black box may keep.
pub const MAX_FILES: usize = 10_000;

/// The most history a black box keeps (an hour).
pub const MAX_SECONDS: f64 = 3600.0;
/// The largest memory budget, MB (16 GiB).
pub const MAX_MB: u64 = 16 * 1024;

impl Config {
    /// Reads and checks `path`; `dir` becomes relative to its folder.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.into(), source })?;
        let mut c = Config::parse(&text).map_err(|e| match e {
            ConfigError::Parse { message, .. } => ConfigError::Parse { path: path.into(), message },
            ConfigError::Invalid { message, .. } => ConfigError::Invalid { path: path.into(), message },
            e => e,
        })?;
        if c.dir.is_relative() {
            let base = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
            c.dir = base.join(&c.dir);
        }
        Ok(c)
    }

    /// Parses and checks a configuration's text.
    pub fn parse(text: &str) -> Result<Config, ConfigError> {
        let invalid = |message: String| ConfigError::Invalid { path: PathBuf::new(), message };
        let c: Config =
            toml::from_str(text).map_err(|e| ConfigError::Parse { path: PathBuf::new(), message: e.to_string() })?;
        if !(c.seconds.is_finite() && c.seconds > 0.0 && c.seconds <= MAX_SECONDS) {
            return Err(invalid(format!("seconds = {}: give a number of seconds in (0, {MAX_SECONDS}]", c.seconds)));
        }
        if !(c.after.is_finite() && (0.0..=60.0).contains(&c.after)) {
            return Err(invalid(format!("after = {}: give a number of seconds in [0, 60]", c.after)));
        }
        if !(c.fire.min_gap.is_finite() && (0.0..=3600.0).contains(&c.fire.min_gap)) {
            return Err(invalid(format!("fire.min_gap = {}: give a number of seconds in [0, 3600]", c.fire.min_gap)));
        }
        if !(1..=MAX_MB).contains(&c.max_mb) {
            return Err(invalid(format!("max_mb = {}: give a budget in [1, {MAX_MB}] MB", c.max_mb)));
        }
        if !(1..=MAX_FILES).contains(&c.max_files) {
            return Err(invalid(format!("max_files = {}: give a count in [1, {MAX_FILES}]", c.max_files)));
        }
        if c.max_total_mb < c.max_mb {
            return Err(invalid(format!(
                "max_total_mb = {}: give at least max_mb ({}), the size one snapshot can reach",
                c.max_total_mb, c.max_mb
            )));
        }
        if c.ports.is_empty() && c.fire.on_change.is_empty() {
            return Err(invalid("ports = []: name the ports to keep (AGENT/PORT), or \"*\" for every one".into()));
        }
        for p in c.ports.iter().filter(|p| *p != "*").chain(c.fire.on_change.iter().map(|w| &w.port)) {
            p.parse::<PortRef>().map_err(|e| invalid(format!("port {p:?}: {e}; write AGENT/PORT")))?;
        }
        Ok(c)
    }

    /// Whether every output port is kept.
    pub fn all_ports(&self) -> bool {
        self.ports.iter().any(|p| p == "*")
    }

    /// Whether `port` is kept.
    pub fn keeps(&self, port: &PortRef) -> bool {
        let name = port.to_string();
        self.all_ports() || self.ports.contains(&name) || self.fire.on_change.iter().any(|w| w.port == name)
    }
}

/// A kept sample.
#[derive(Debug, Clone)]
pub struct Kept {
    /// the sender's sequence number
    pub seq: u64,
    /// CLOCK_REALTIME ns when the black box took it
    pub log_ns: u64,
    /// the sample's stamp (CLOCK_MONOTONIC ns)
    pub stamp_ns: u64,
    /// its bytes
    pub bytes: Arc<[u8]>,
}

/// A kept image: a `foxglove.RawImage` message.
#[derive(Debug, Clone)]
pub struct KeptImage {
    /// the frame's sequence number in its ring
    pub seq: u64,
    /// CLOCK_REALTIME ns when the black box took it
    pub log_ns: u64,
    /// the encoded message
    pub encoded: Arc<[u8]>,
}

/// One port's history.
#[derive(Debug, Clone)]
pub struct PortHistory {
    /// AGENT/PORT
    pub port: PortRef,
    /// its type
    pub type_name: String,
    /// its layout fingerprint
    pub fingerprint: u64,
    /// its schema
    pub schema: Schema,
    /// its samples, oldest first
    pub samples: VecDeque<Kept>,
    /// the images its notices named, oldest first (ports of ring notices)
    pub images: VecDeque<KeptImage>,
    /// samples missed (gaps in the sender's sequence numbers)
    pub missed: u64,
}

impl PortHistory {
    /// An empty history of a port.
    pub fn new(port: PortRef, type_name: String, fingerprint: u64, schema: Schema) -> PortHistory {
        PortHistory {
            port,
            type_name,
            fingerprint,
            schema,
            samples: VecDeque::new(),
            images: VecDeque::new(),
            missed: 0,
        }
    }

    /// Bytes held (the memory keeps a running count; tests compare it with this).
    #[cfg(test)]
    fn bytes(&self) -> usize {
        self.samples.iter().map(|k| k.bytes.len()).sum::<usize>()
            + self.images.iter().map(|i| i.encoded.len()).sum::<usize>()
    }
}

/// Everything kept, bounded by time and by a memory budget.
#[derive(Debug)]
pub struct Memory {
    /// the ports
    pub ports: Vec<PortHistory>,
    keep_ns: u64,
    max_bytes: usize,
    bytes: usize,
}

impl Memory {
    /// Keeps `seconds` of history within `max_mb` MB.
    pub fn new(seconds: f64, max_mb: u64) -> Memory {
        Memory {
            ports: Vec::new(),
            keep_ns: (seconds * 1e9) as u64,
            max_bytes: usize::try_from(max_mb.saturating_mul(1 << 20)).unwrap_or(usize::MAX),
            bytes: 0,
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// Adds a sample to port `i`.
    pub fn push(&mut self, i: usize, k: Kept) {
        let Some(h) = self.ports.get_mut(i) else { return };
        if let Some(last) = h.samples.back() {
            h.missed = h.missed.saturating_add(k.seq.saturating_sub(last.seq).saturating_sub(1));
        }
        self.bytes = self.bytes.saturating_add(k.bytes.len());
        h.samples.push_back(k);
    }

    /// Adds an image to port `i`.
    pub fn push_image(&mut self, i: usize, img: KeptImage) {
        let Some(h) = self.ports.get_mut(i) else { return };
        self.bytes = self.bytes.saturating_add(img.encoded.len());
        h.images.push_back(img);
    }

    /// Forgets what is older than the kept seconds before `now_ns`, then
    /// the oldest of all until the budget holds.
    pub fn trim(&mut self, now_ns: u64) {
        let cut = now_ns.saturating_sub(self.keep_ns);
        for h in &mut self.ports {
            while h.samples.front().is_some_and(|k| k.log_ns < cut) {
                if let Some(k) = h.samples.pop_front() {
                    self.bytes = self.bytes.saturating_sub(k.bytes.len());
                }
            }
            while h.images.front().is_some_and(|k| k.log_ns < cut) {
                if let Some(k) = h.images.pop_front() {
                    self.bytes = self.bytes.saturating_sub(k.encoded.len());
                }
            }
        }
        while self.bytes > self.max_bytes {
            // the port whose oldest entry is oldest gives it up
            let oldest = self
                .ports
                .iter()
                .enumerate()
                .flat_map(|(i, h)| {
                    let s = h.samples.front().map(|k| (k.log_ns, i, false));
                    let m = h.images.front().map(|k| (k.log_ns, i, true));
                    s.into_iter().chain(m)
                })
                .min();
            let Some((_, i, image)) = oldest else { break };
            let h = &mut self.ports[i];
            let freed = if image {
                h.images.pop_front().map_or(0, |k| k.encoded.len())
            } else {
                h.samples.pop_front().map_or(0, |k| k.bytes.len())
            };
            self.bytes = self.bytes.saturating_sub(freed);
        }
    }

    /// What was kept between `from_ns` and `to_ns` (CLOCK_REALTIME), cheap
    /// to take: the bytes are shared, not copied.
    pub fn window(&self, from_ns: u64, to_ns: u64) -> Vec<PortHistory> {
        self.ports
            .iter()
            .map(|h| PortHistory {
                port: h.port.clone(),
                type_name: h.type_name.clone(),
                fingerprint: h.fingerprint,
                schema: h.schema.clone(),
                samples: h.samples.iter().filter(|k| (from_ns..=to_ns).contains(&k.log_ns)).cloned().collect(),
                images: h.images.iter().filter(|k| (from_ns..=to_ns).contains(&k.log_ns)).cloned().collect(),
                missed: h.missed,
            })
            .collect()
    }
}

/// What a snapshot holds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Written {
    /// port samples
    pub messages: u64,
    /// images
    pub images: u64,
    /// bytes of both
    pub bytes: u64,
}

/// Writes `ports` to `path` in nerve's recording format: first to
/// `path.part`, renamed into place when complete, so that whoever waits
/// for `path` never reads half a file. On an error the `.part` is removed:
/// a full disk is not left fuller.
pub fn write_snapshot(path: &Path, robot: &str, ports: &[PortHistory]) -> Result<Written, RecordingError> {
    let part = part_of(path);
    let written = write_part(&part, robot, ports).and_then(|w| {
        std::fs::rename(&part, path).map_err(mcap::McapError::Io)?;
        Ok(w)
    });
    if written.is_err() {
        let _ = std::fs::remove_file(&part);
    }
    written
}

/// Where a snapshot to `path` is written before it is whole.
pub fn part_of(path: &Path) -> PathBuf {
    path.with_extension("mcap.part")
}

fn write_part(part: &Path, robot: &str, ports: &[PortHistory]) -> Result<Written, RecordingError> {
    let file = std::fs::File::create(part).map_err(mcap::McapError::Io)?;
    let mut out = RecordingWriter::new(std::io::BufWriter::new(file))?;
    let mut w = Written::default();
    // messages in time order across ports, as a recording has them
    let mut all: Vec<(u64, u16, bool, usize, usize)> = Vec::new();
    for (pi, h) in ports.iter().enumerate() {
        let channel = out.add_port(&PortChannel {
            robot,
            agent: h.port.agent.as_str(),
            port: &h.port.port,
            type_name: &h.type_name,
            fingerprint: h.fingerprint,
            schema: &h.schema,
        })?;
        all.extend(h.samples.iter().enumerate().map(|(i, k)| (k.log_ns, channel, false, pi, i)));
        if !h.images.is_empty() {
            let images = out.add_images(robot, h.port.agent.as_str(), &h.port.port)?;
            all.extend(h.images.iter().enumerate().map(|(i, k)| (k.log_ns, images, true, pi, i)));
        }
    }
    all.sort_by_key(|&(t, ..)| t);
    for (_, channel, image, pi, i) in all {
        let h = &ports[pi];
        if image {
            let k = &h.images[i];
            out.write_image(channel, k.seq, k.log_ns, &k.encoded)?;
            w.images += 1;
            w.bytes += k.encoded.len() as u64;
        } else {
            let k = &h.samples[i];
            out.write_sample(
                channel,
                &Sample { seq: k.seq, log_time_ns: k.log_ns, stamp_ns: k.stamp_ns, bytes: &k.bytes },
            )?;
            w.messages += 1;
            w.bytes += k.bytes.len() as u64;
        }
    }
    out.finish()?;
    Ok(w)
}

/// The bytes a snapshot of `ports` will take, about (its messages' bytes).
pub fn snapshot_bytes(ports: &[PortHistory]) -> u64 {
    ports
        .iter()
        .flat_map(|h| h.samples.iter().map(|k| k.bytes.len()).chain(h.images.iter().map(|i| i.encoded.len())))
        .map(|n| n as u64 + 64)
        .sum()
}

/// Why a snapshot was not written.
#[derive(Debug, thiserror::Error)]
pub enum RoomError {
    /// The disk is nearer full than the configuration allows.
    #[error(
        "not writing a snapshot of {need_mb:.1} MB to {dir}: its disk has {free_mb:.1} MB free and min_free_mb = {min_free_mb} must stay free; free space on it, or lower min_free_mb"
    )]
    LowSpace {
        /// the folder
        dir: PathBuf,
        /// MB the snapshot needs
        need_mb: f64,
        /// MB free on the disk
        free_mb: f64,
        /// MB that must stay free
        min_free_mb: u64,
    },
    /// The free space could not be learnt.
    #[error("cannot learn the free space of {dir}: {source}")]
    Statvfs {
        /// the folder
        dir: PathBuf,
        /// why
        #[source]
        source: nix::errno::Errno,
    },
}

/// Bytes free on the disk of `dir` for this user.
pub fn free_bytes(dir: &Path) -> Result<u64, RoomError> {
    let st = nix::sys::statvfs::statvfs(dir).map_err(|source| RoomError::Statvfs { dir: dir.into(), source })?;
    // fsblkcnt_t is u64 on 64-bit Linux, u32 on some targets
    #[allow(clippy::useless_conversion)]
    let blocks = u64::from(st.blocks_available());
    Ok(blocks.saturating_mul(st.fragment_size()))
}

/// Whether a snapshot of `need` bytes may be written to `dir`, leaving
/// `min_free_mb` free.
pub fn check_room(dir: &Path, need: u64, min_free_mb: u64) -> Result<(), RoomError> {
    let free = free_bytes(dir)?;
    if free.checked_sub(need).is_none_or(|left| left < min_free_mb.saturating_mul(1 << 20)) {
        return Err(RoomError::LowSpace {
            dir: dir.into(),
            need_mb: need as f64 / 1e6,
            free_mb: free as f64 / 1e6,
            min_free_mb,
        });
    }
    Ok(())
}

/// The folder of fired snapshots, kept within its caps.
#[derive(Debug, Clone)]
pub struct Folder {
    /// the folder
    pub dir: PathBuf,
    /// the most snapshots kept
    pub max_files: usize,
    /// the most bytes they take together
    pub max_bytes: u64,
}

/// What [`Folder::make_room`] or [`Folder::sweep`] deleted.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Deleted {
    /// the files
    pub files: Vec<PathBuf>,
    /// their bytes
    pub bytes: u64,
}

impl Folder {
    /// The folder of `config`.
    pub fn of(config: &Config) -> Folder {
        Folder {
            dir: config.dir.clone(),
            max_files: config.max_files,
            max_bytes: config.max_total_mb.saturating_mul(1 << 20),
        }
    }

    /// Whether `name` is a snapshot the black box fired (only those are
    /// counted and deleted: nothing else in the folder is touched).
    pub fn is_fired(name: &str) -> bool {
        name.starts_with("blackbox-") && name.ends_with(".mcap")
    }

    /// The fired snapshots in the folder, oldest first, with their sizes.
    pub fn snapshots(&self) -> std::io::Result<Vec<(PathBuf, u64)>> {
        let mut out: Vec<(std::time::SystemTime, PathBuf, u64)> = Vec::new();
        for e in std::fs::read_dir(&self.dir)? {
            let e = e?;
            let name = e.file_name();
            if !name.to_str().is_some_and(Folder::is_fired) {
                continue;
            }
            let Ok(meta) = e.metadata() else { continue };
            if meta.is_file() {
                out.push((meta.modified().unwrap_or(std::time::UNIX_EPOCH), e.path(), meta.len()));
            }
        }
        // by time, then by name (whose stamp sorts): the oldest first
        out.sort();
        Ok(out.into_iter().map(|(_, p, n)| (p, n)).collect())
    }

    /// Deletes the oldest fired snapshots until one more of `need` bytes
    /// fits within the caps.
    pub fn make_room(&self, need: u64) -> std::io::Result<Deleted> {
        let files = self.snapshots()?;
        let mut total: u64 = files.iter().map(|(_, n)| n).sum();
        let mut count = files.len();
        let mut deleted = Deleted::default();
        for (path, len) in files {
            if count < self.max_files && total.saturating_add(need) <= self.max_bytes {
                break;
            }
            std::fs::remove_file(&path)?;
            count -= 1;
            total = total.saturating_sub(len);
            deleted.bytes += len;
            deleted.files.push(path);
        }
        Ok(deleted)
    }

    /// Removes the `.part` files a black box that died while writing left.
    pub fn sweep(&self) -> std::io::Result<Deleted> {
        let mut deleted = Deleted::default();
        for e in std::fs::read_dir(&self.dir)? {
            let e = e?;
            if e.file_name().to_str().is_some_and(|n| n.ends_with(".mcap.part")) && e.file_type()?.is_file() {
                let len = e.metadata().map_or(0, |m| m.len());
                std::fs::remove_file(e.path())?;
                deleted.bytes += len;
                deleted.files.push(e.path());
            }
        }
        Ok(deleted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::Described;
    use shm_schemas::payloads::Tick;
    use std::time::Duration;

    fn history(port: &str) -> PortHistory {
        PortHistory::new(port.parse().expect("port"), "nerve::Tick".into(), 1, Tick::schema())
    }

    fn kept(seq: u64, log_ns: u64, len: usize) -> Kept {
        Kept { seq, log_ns, stamp_ns: log_ns, bytes: vec![seq as u8; len].into() }
    }

    #[test]
    fn a_configuration_reads_with_its_defaults_and_refusals_name_the_line() {
        let c = Config::parse("ports = [\"t1/tick\"]\n[fire]\non_death = true\n").expect("config");
        assert_eq!((c.seconds, c.max_mb, c.after, c.fire.min_gap), (10.0, 512, 1.0, 5.0));
        assert_eq!((c.max_files, c.max_total_mb, c.min_free_mb), (20, 4096, 1024));
        assert!(c.fire.on_death && c.keeps(&"t1/tick".parse().expect("port")));
        assert!(!c.keeps(&"t2/tick".parse().expect("port")));
        let e = Config::parse("ports = [\"t1/tick\"]\nsecnds = 3\n").expect_err("a typo");
        assert!(e.to_string().contains("secnds") && e.to_string().contains("line 2"), "{e}");
        let e = Config::parse("ports = [\"t1\"]\n").expect_err("no port name");
        assert!(e.to_string().contains("AGENT/PORT"), "{e}");
        for bad in ["seconds = 0", "seconds = 1e9", "max_mb = 0", "after = -1", "max_files = 0", "max_total_mb = 100"] {
            assert!(Config::parse(&format!("ports = [\"*\"]\n{bad}\n")).is_err(), "{bad} must be refused");
        }
        let c = Config::parse("ports = [\"*\"]\n[[fire.on_change]]\nport = \"s/stop\"\nfield = \"active\"\n")
            .expect("config");
        assert!(c.all_ports() && c.fire.on_change[0].field == "active");
    }

    #[test]
    fn the_example_configuration_reads() {
        let c = Config::parse(include_str!("../../../launch/blackbox.toml")).expect("launch/blackbox.toml");
        assert!(c.all_ports() && c.fire.on_death);
    }

    #[test]
    fn memory_keeps_the_last_seconds_within_its_budget() {
        let s = 1_000_000_000u64;
        let mut m = Memory::new(2.0, 1);
        m.ports.push(history("a/x"));
        m.ports.push(history("b/y"));
        for t in 0..10u64 {
            m.push(0, kept(t + 1, t * s / 2, 100));
        }
        m.trim(5 * s);
        let seqs: Vec<u64> = m.ports[0].samples.iter().map(|k| k.seq).collect();
        assert_eq!(seqs, [7, 8, 9, 10], "3.0 s .. 4.5 s: the last two seconds");
        assert_eq!(m.bytes(), 400);
        // a gap in the sender's numbers is counted
        m.push(0, kept(13, 5 * s, 100));
        assert_eq!(m.ports[0].missed, 2);
        // over budget (1 MB): the oldest go first, across ports
        m.push(1, kept(1, 5 * s, 700_000));
        m.push(1, kept(2, 5 * s + 1, 700_000));
        m.trim(5 * s + 2);
        assert!(m.bytes() <= 1 << 20, "{}", m.bytes());
        assert_eq!(m.bytes(), m.ports.iter().map(PortHistory::bytes).sum::<usize>(), "the count follows the contents");
        assert!(m.ports[0].samples.is_empty(), "port a's older samples went first");
        assert_eq!(m.ports[1].samples.iter().map(|k| k.seq).collect::<Vec<_>>(), [2]);
        let w = m.window(0, u64::MAX);
        assert_eq!(w[1].samples.len(), 1);
        assert!(m.window(0, 5 * s).iter().all(|h| h.samples.is_empty()));
    }

    #[test]
    fn a_snapshot_is_a_recording_in_time_order() {
        let dir = std::env::temp_dir().join(format!("nerve-blackbox-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("snap.mcap");
        let mut a = history("a/x");
        let mut b = history("b/y");
        let len = std::mem::size_of::<Tick>();
        a.samples.extend([kept(1, 10, len), kept(2, 30, len)]);
        b.samples.extend([kept(1, 20, len)]);
        let w = write_snapshot(&path, "r", &[a, b]).expect("written");
        assert_eq!((w.messages, w.images), (3, 0));
        assert!(!path.with_extension("mcap.part").exists());
        let bytes = std::fs::read(&path).expect("file");
        let order: Vec<(String, u64)> = mcap::MessageStream::new(&bytes)
            .expect("mcap")
            .map(|m| m.map(|m| (m.channel.topic.clone(), m.log_time)).expect("message"))
            .collect();
        assert_eq!(order, [("a/x".into(), 10), ("b/y".into(), 20), ("a/x".into(), 30)]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A fresh folder under the temp folder, removed by the guard.
    struct TempDir(PathBuf);
    impl TempDir {
        fn new(what: &str) -> TempDir {
            let d = std::env::temp_dir().join(format!("nerve-blackbox-{what}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&d);
            std::fs::create_dir_all(&d).expect("dir");
            TempDir(d)
        }
    }
    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn names(files: &[(PathBuf, u64)]) -> Vec<String> {
        files.iter().map(|(p, _)| p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()).collect()
    }

    #[test]
    fn the_folder_keeps_its_caps_by_deleting_the_oldest() {
        let d = TempDir::new("caps");
        let folder = Folder { dir: d.0.clone(), max_files: 3, max_bytes: 10_000 };
        for i in 0..5u8 {
            // names whose stamps sort, and times that follow them
            let p = d.0.join(format!("blackbox-2026112{i}-000000.000-died-g.mcap"));
            std::fs::write(&p, vec![i; 1000]).expect("file");
            let t = std::time::UNIX_EPOCH + Duration::from_secs(1_000_000 + u64::from(i));
            std::fs::File::options().write(true).open(&p).and_then(|f| f.set_modified(t)).expect("mtime");
        }
        std::fs::write(d.0.join("notes.txt"), "not a snapshot").expect("file");
        std::fs::write(d.0.join("mine.mcap"), "not fired").expect("file");
        // by count: room for one more leaves 2 of the 5, the newest
        let gone = folder.make_room(1000).expect("room");
        assert_eq!(gone.files.len(), 3);
        assert_eq!(gone.bytes, 3000);
        let left = folder.snapshots().expect("list");
        assert_eq!(
            names(&left),
            ["blackbox-20261123-000000.000-died-g.mcap", "blackbox-20261124-000000.000-died-g.mcap"]
        );
        // by size: 9,500 more bytes leave none
        let gone = folder.make_room(9_500).expect("room");
        assert_eq!(gone.files.len(), 2);
        assert!(folder.snapshots().expect("list").is_empty());
        assert!(d.0.join("notes.txt").exists() && d.0.join("mine.mcap").exists(), "only fired snapshots go");
    }

    #[test]
    fn stale_parts_are_swept_and_a_failed_snapshot_leaves_none() {
        let d = TempDir::new("parts");
        std::fs::write(d.0.join("blackbox-x.mcap.part"), vec![0u8; 500]).expect("part");
        let folder = Folder { dir: d.0.clone(), max_files: 3, max_bytes: 10_000 };
        let swept = folder.sweep().expect("sweep");
        assert_eq!((swept.files.len(), swept.bytes), (1, 500));
        // the rename into place fails (a folder holds the name): no .part stays
        let path = d.0.join("blackbox-y.mcap");
        std::fs::create_dir_all(path.join("in-the-way")).expect("dir");
        let mut h = history("a/x");
        h.samples.push_back(kept(1, 10, std::mem::size_of::<Tick>()));
        let e = write_snapshot(&path, "r", &[h]).expect_err("the name is a folder");
        assert!(!part_of(&path).exists(), "the .part of a failed snapshot stays: {e}");
    }

    #[test]
    fn a_snapshot_is_refused_below_the_free_space_margin() {
        let d = TempDir::new("room");
        let free = free_bytes(&d.0).expect("statvfs");
        assert!(check_room(&d.0, 1000, 0).is_ok());
        let e = check_room(&d.0, 1000, free / (1 << 20) + 1024).expect_err("more free space than the disk has");
        assert!(e.to_string().contains("min_free_mb") && e.to_string().contains(&d.0.display().to_string()), "{e}");
        let e = check_room(&d.0, free.saturating_add(1 << 30), 0).expect_err("a snapshot larger than the free space");
        assert!(matches!(e, RoomError::LowSpace { .. }), "{e}");
    }
}
