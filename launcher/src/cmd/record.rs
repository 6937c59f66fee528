//! `nerve record`: output ports to an MCAP file.
//!
//! The recorder is a subscriber like any other: it reads each port by its
//! bytes ([`RawPort`]), zero copy, and publishers never wait for it. What it
//! could not keep up with (a port's buffer overwritten before it read it)
//! shows as a gap in the sender's sequence numbers: counted per port, shown
//! on the progress line and reported at the end.
//!
//! The file is in nerve's recording format ([`nerve_recording`]): each
//! sample's bytes as they were in shared memory, with the nerve schema of
//! its type. A port that carries ring notices (`nerve::RingNotice`) gets a
//! second channel, `AGENT/PORT/image`, with each noticed frame read from the
//! short-term-memory ring as a `foxglove.RawImage`; a frame the writer
//! overwrote before the recorder read it is counted as a dropped image.
//!
//! What a crash loses is bounded. The open chunk is closed every
//! [`FLUSH_PERIOD`] (and at [`nerve_recording::CHUNK_SIZE`]), so that a
//! `kill -9` or an OOM kill leaves every message older than that in closed
//! chunks that any MCAP reader takes; nerve's own reader
//! ([`nerve_recording::read`]) also reads the unclosed chunk, so it loses
//! only what was still in the recorder's buffer ([`WRITE_BUFFER`] bytes at
//! most). The file's data is synced to the disk every [`SYNC_PERIOD`], so
//! a power loss costs at most that much. A write that fails (a full disk,
//! a file over its size limit) stops the recorder with an error that names
//! the file, what is on disk and what to do; what was written stays readable.

use crate::client::{RouterSession, cli_node};
use agent_sdk::World;
use agent_sdk::ports::port_event;
use agent_sdk::raw_port::RawPort;
use agent_sdk::router_events::{EventFollower, Look};
use agent_sdk::world::Ipc;
use anyhow::{Context as _, Result, anyhow, bail};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use nerve_recording::{FrameOutcome, PortChannel, RecordingError, RecordingWriter, RingFrames, Sample, foxglove};
use shm_schemas::control::cli_to_router::{CliRequest, EventKind, RouterReply};
use shm_schemas::ring::RingNotice;
use shm_schemas::{Payload, PortRef, RobotName, Schema};
use std::io::{BufWriter, IsTerminal as _, Write as _};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::rc::Rc;
use std::time::{Duration, Instant};

/// The file being written.
type Out = RecordingWriter<BufWriter<std::fs::File>>;

/// How often the open chunk is closed (and the buffer written out).
pub const FLUSH_PERIOD: Duration = Duration::from_secs(1);
/// How often the file's data is synced to the disk (`fdatasync`).
pub const SYNC_PERIOD: Duration = Duration::from_secs(5);
/// The recorder's write buffer, bytes.
pub const WRITE_BUFFER: usize = 64 * 1024;

/// The error of a failed write to `path`: what failed, how much is on disk,
/// that it stays readable, and what to do.
fn write_failed(path: &Path, e: RecordingError) -> anyhow::Error {
    let on_disk = std::fs::metadata(path).map_or(0, |m| m.len());
    let what = match e.io().map(std::io::Error::kind) {
        Some(std::io::ErrorKind::StorageFull) => "the disk is full",
        Some(std::io::ErrorKind::FileTooLarge) => {
            "the file reached the size limit of its file system or of the process (ulimit -f)"
        }
        Some(std::io::ErrorKind::QuotaExceeded) => "the disk quota is used up",
        _ => "the write failed",
    };
    let advice = match e.io().map(std::io::Error::kind) {
        Some(std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded) => {
            "free space, or record to another disk (-o)"
        }
        Some(std::io::ErrorKind::FileTooLarge) => "record shorter files (--duration) or raise the limit",
        _ => "check the disk (dmesg) and record again",
    };
    anyhow::Error::new(e).context(format!(
        "cannot write {}: {what}; recording stopped with {:.1} MB on disk. What was written is readable: \
         nerve replay and nerve export read it up to its last whole message (other MCAP readers up to its \
         last closed chunk). To record on: {advice}",
        path.display(),
        on_disk as f64 / 1e6
    ))
}

/// `nerve record`
#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// Output ports to record, AGENT/PORT.
    pub ports: Vec<String>,
    /// Every output port of the robot, and those of agents started while it records.
    #[arg(long)]
    pub all: bool,
    /// The MCAP file to write (default: `nerve-ROBOT-YYYYmmdd-HHMMSS.mcap` here).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// Stop after this many seconds (default: at Ctrl-C).
    #[arg(long, value_parser = agent_sdk::clock::parse_seconds)]
    pub duration: Option<f64>,
    /// No progress line.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// An output port the router knows, with what is needed to record it.
#[derive(Debug, Clone)]
pub struct Known {
    /// AGENT/PORT
    pub port: PortRef,
    /// its type name
    pub type_name: String,
    /// its layout fingerprint
    pub fingerprint: u64,
    /// its schema, when the agent registered one (or the type is built in)
    pub schema: Option<Schema>,
}

/// Every output port of the robot's live agents, from the router.
pub fn known_ports(world: &World) -> Result<Vec<Known>> {
    let session = RouterSession::open(world).context(
        "recording needs the router (it holds each port's schema): start it with `nerve router --daemon` or `nerve launch`",
    )?;
    let RouterReply::Agents(agents) = session.call(CliRequest::Ps)? else {
        bail!("the router did not answer `ps` with its agents");
    };
    let mut out = Vec::new();
    for a in agents.iter().filter(|a| a.pid != 0) {
        for o in &a.outputs {
            let Ok(port) = PortRef::new(&a.name, &o.name) else { continue };
            let schema = a.schema_for(o.fingerprint);
            out.push(Known { port, type_name: o.type_name.clone(), fingerprint: o.fingerprint, schema });
        }
    }
    Ok(out)
}

/// A port being recorded.
struct Recording {
    known: Known,
    raw: RawPort,
    listener: Rc<Listener<Ipc>>,
    channel: u16,
    messages: u64,
    bytes: u64,
    dropped: u64,
    last_seq: Option<u64>,
    /// the frames of the ring its notices name, when it carries notices
    images: Option<Images>,
}

/// The image channel of a port that carries ring notices.
pub struct Images {
    channel: u16,
    frames_of: RingFrames,
    /// the encoded message, reused
    buf: Vec<u8>,
    /// frames written
    pub frames: u64,
    /// frames overwritten before they were read, or unreadable
    pub dropped: u64,
    /// bytes of messages written
    pub bytes: u64,
}

impl Images {
    /// Adds the image channel of `AGENT/PORT`'s ring to `out`.
    fn add(out: &mut Out, robot: &RobotName, port: &PortRef) -> Result<Images, RecordingError> {
        let channel = out.add_images(robot.as_str(), port.agent.as_str(), &port.port)?;
        let frames_of = RingFrames::new(robot, port.agent.as_str());
        Ok(Images { channel, frames_of, buf: Vec::new(), frames: 0, dropped: 0, bytes: 0 })
    }

    /// Writes the frame `notice_bytes` announces (log time `log_ns`).
    fn write(&mut self, out: &mut Out, notice_bytes: &[u8], log_ns: u64) -> Result<(), RecordingError> {
        match self.frames_of.encode(notice_bytes, log_ns, &mut self.buf) {
            FrameOutcome::Encoded(seq) => {
                out.write_image(self.channel, seq, log_ns, &self.buf)?;
                self.frames += 1;
                self.bytes = self.bytes.saturating_add(self.buf.len() as u64);
            }
            FrameOutcome::NotImage => {}
            FrameOutcome::Lost => self.dropped += 1,
        }
        Ok(())
    }
}

/// The figures of a recording, for the progress line and the summary.
#[derive(Debug, Default, Clone, Copy)]
struct Totals {
    messages: u64,
    bytes: u64,
    dropped: u64,
}

/// `PREFIX-ROBOT-YYYYmmdd-HHMMSS.mcap` in the current folder.
pub fn dated_file(prefix: &str, world: &World) -> PathBuf {
    let stamp = nerve_recording::file_stamp(agent_sdk::clock::unix_now_ns());
    PathBuf::from(format!("{prefix}-{}-{stamp}.mcap", world.robot()))
}

pub fn record(world: &World, a: RecordArgs) -> Result<ExitCode> {
    if a.ports.is_empty() && !a.all {
        bail!("name the ports to record (AGENT/PORT ...) or give --all");
    }
    if let Some(d) = a.duration
        && !(d.is_finite() && d > 0.0)
    {
        bail!("--duration must be a positive number of seconds");
    }
    let wanted: Vec<PortRef> =
        a.ports.iter().map(|p| p.parse::<PortRef>().with_context(|| format!("port {p:?}"))).collect::<Result<_>>()?;
    let node = cli_node(world)?;
    let known = known_ports(world)?;
    for w in &wanted {
        if !known.iter().any(|k| &k.port == w) {
            bail!(
                "no output port {w} on robot {}; its output ports: {}",
                world.robot(),
                known.iter().map(|k| k.port.to_string()).collect::<Vec<_>>().join(", ")
            );
        }
    }
    let path = a.output.clone().unwrap_or_else(|| dated_file("nerve", world));
    let file = std::fs::File::create(&path).with_context(|| format!("cannot create {}", path.display()))?;
    let data = file.try_clone().with_context(|| format!("cannot open {} twice (to sync it)", path.display()))?;
    let mut writer =
        RecordingWriter::new(BufWriter::with_capacity(WRITE_BUFFER, file)).map_err(|e| write_failed(&path, e))?;

    let mut ports = Ports { world, node: &node, path: &path, recordings: Vec::new(), skipped: Vec::new() };
    for k in known.iter().filter(|k| a.all || wanted.contains(&k.port)) {
        ports.add(k, &mut writer)?;
    }
    if ports.recordings.is_empty() && !a.all {
        bail!("nothing to record");
    }

    let start = Instant::now();
    let tty = std::io::stderr().is_terminal();
    let events_node =
        world.node(&format!("cli-{}-events", std::process::id())).context("cannot join the robot's shared memory")?;
    let mut events = EventFollower::new(world, events_node);
    let _ = events.look();
    // what was recorded is told whether the recording ended well or on a
    // failed write (a full disk)
    let outcome = record_until(&mut ports, writer, &data, &mut events, &a, start);
    let recordings = ports.recordings;
    let totals = sum(&recordings);
    if !a.quiet && tty {
        eprintln!();
    }
    println!(
        "recorded {} ports to {}{}: {} messages, {:.1} MB in {:.1} s, {} dropped",
        recordings.len(),
        path.display(),
        if outcome.is_err() { " until the failure below" } else { "" },
        totals.messages,
        totals.bytes as f64 / 1e6,
        start.elapsed().as_secs_f64(),
        totals.dropped
    );
    for r in &recordings {
        println!(
            "  {:<32} {:<24} {:>8} messages{}",
            r.known.port.to_string(),
            r.known.type_name,
            r.messages,
            if r.dropped > 0 { format!(", {} dropped (the recorder fell behind)", r.dropped) } else { String::new() }
        );
        if let Some(i) = &r.images {
            println!(
                "  {:<32} {:<24} {:>8} frames, {:.1} MB{}",
                format!("{}{}", r.known.port, nerve_recording::IMAGE_TOPIC_SUFFIX),
                foxglove::RAW_IMAGE,
                i.frames,
                i.bytes as f64 / 1e6,
                if i.dropped > 0 {
                    format!(", {} dropped (overwritten in the ring before the recorder read them)", i.dropped)
                } else {
                    String::new()
                }
            );
        }
    }
    outcome?;
    Ok(ExitCode::SUCCESS)
}

/// The ports being recorded, and what adding one needs.
struct Ports<'a> {
    world: &'a World,
    node: &'a Node<Ipc>,
    /// the file, for the errors of a failed write
    path: &'a Path,
    recordings: Vec<Recording>,
    /// ports that could not be recorded (said once, not tried again)
    skipped: Vec<PortRef>,
}

impl Ports<'_> {
    /// Starts recording `k` into `writer`: its channel (and its image
    /// channel, for ring notices) and a listener on its port. A port without
    /// a schema, or one that cannot be opened, is said once and skipped from
    /// then on. Returns whether `k` is recorded.
    fn add(&mut self, k: &Known, writer: &mut Out) -> Result<bool> {
        let Some(schema) = &k.schema else {
            eprintln!(
                "skipping {}: its type {} has no schema (the agent registered none and it is not built in)",
                k.port, k.type_name
            );
            self.skipped.push(k.port.clone());
            return Ok(false);
        };
        let robot = self.world.robot();
        let service = robot.port_service(k.port.agent.as_str(), &k.port.port);
        let raw = match RawPort::open(self.node, &service) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("skipping {}: {e}", k.port);
                self.skipped.push(k.port.clone());
                return Ok(false);
            }
        };
        let listener =
            Rc::new(port_event(self.node, &service)?.listener_builder().create().map_err(|e| anyhow!("{e:?}"))?);
        let channel = writer
            .add_port(&PortChannel {
                robot: robot.as_str(),
                agent: k.port.agent.as_str(),
                port: &k.port.port,
                type_name: &k.type_name,
                fingerprint: k.fingerprint,
                schema,
            })
            .map_err(|e| write_failed(self.path, e))?;
        let images = if k.type_name == <RingNotice as Payload>::stable_type_name() {
            Some(Images::add(writer, robot, &k.port).map_err(|e| write_failed(self.path, e))?)
        } else {
            None
        };
        self.recordings.push(Recording {
            known: k.clone(),
            raw,
            listener,
            channel,
            messages: 0,
            bytes: 0,
            dropped: 0,
            last_seq: None,
            images,
        });
        Ok(true)
    }

    /// With `--all`: the ports of agents registered since the last look
    /// (the router's `events`) join the recording. Returns whether one did.
    fn add_new(&mut self, events: &mut EventFollower, writer: &mut Out, tty: bool) -> Result<bool> {
        let registered = match events.look() {
            Look::Events(ev) => ev.iter().any(|e| matches!(e.what, EventKind::Registered { .. })),
            Look::Fresh | Look::NoRouter => true,
        };
        let Some(known) = registered.then(|| known_ports(self.world).ok()).flatten() else { return Ok(false) };
        let mut added = false;
        for k in &known {
            let tried = self.skipped.contains(&k.port) || self.recordings.iter().any(|r| r.known.port == k.port);
            if !tried && self.add(k, writer)? {
                eprintln!("{}recording {} too", if tty { "\n" } else { "" }, k.port);
                added = true;
            }
        }
        Ok(added)
    }
}

/// The recording: every port's samples into `writer` until `--duration`
/// ends or Ctrl-C, with the chunk closed every [`FLUSH_PERIOD`] and `data`
/// synced every [`SYNC_PERIOD`], the progress line, and with `--all` the
/// ports of agents started meanwhile; then the file's end. A failed write
/// stops it with the error of [`write_failed`].
fn record_until(
    ports: &mut Ports,
    mut writer: Out,
    data: &std::fs::File,
    events: &mut EventFollower,
    a: &RecordArgs,
    start: Instant,
) -> Result<()> {
    let path = ports.path;
    let until = a.duration.map(|d| start + Duration::from_secs_f64(d));
    let tty = std::io::stderr().is_terminal();
    let mut next_progress = start + Duration::from_secs(1);
    let mut next_look = start + Duration::from_millis(500);
    let (mut next_flush, mut next_sync) = (start + FLUSH_PERIOD, start + SYNC_PERIOD);
    let mut interrupted = false;
    crate::interrupt::catch();
    loop {
        // a fresh wait set each round: --all adds ports as agents appear
        let ws = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Ipc>()
            .map_err(|e| anyhow!("{e:?}"))?;
        let listeners: Vec<Rc<Listener<Ipc>>> = ports.recordings.iter().map(|r| r.listener.clone()).collect();
        let mut guards = Vec::new();
        for l in &listeners {
            guards.push(ws.attach_notification(l.as_ref()).map_err(|e| anyhow!("{e:?}"))?);
        }
        let _tick = ws.attach_interval(Duration::from_millis(100)).map_err(|e| anyhow!("{e:?}"))?;
        let mut round_done = false;
        while !round_done {
            match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
                Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => {
                    interrupted = true;
                    break;
                }
                Ok(_) if crate::interrupt::requested() => {
                    interrupted = true;
                    break;
                }
                Ok(_) => {}
                Err(e) => bail!("wait failed: {e:?}"),
            }
            for r in &mut ports.recordings {
                let _ = r.listener.try_wait(|_| {});
                drain(r, &mut writer, path)?;
            }
            let now = Instant::now();
            if now >= next_flush {
                next_flush = now + FLUSH_PERIOD;
                writer.flush().map_err(|e| write_failed(path, e))?;
                if now >= next_sync {
                    next_sync = now + SYNC_PERIOD;
                    data.sync_data().map_err(|e| write_failed(path, mcap::McapError::Io(e).into()))?;
                }
            }
            if until.is_some_and(|u| now >= u) {
                break;
            }
            if now >= next_progress && !a.quiet {
                next_progress = now + Duration::from_secs(1);
                progress(&ports.recordings, start.elapsed(), tty);
            }
            if a.all && now >= next_look {
                next_look = now + Duration::from_millis(500);
                // a new port needs a new wait set
                round_done = ports.add_new(events, &mut writer, tty)?;
            }
        }
        if interrupted || until.is_some_and(|u| Instant::now() >= u) {
            break;
        }
    }
    // what arrived until the end
    for r in &mut ports.recordings {
        drain(r, &mut writer, path)?;
    }
    writer.finish().map_err(|e| write_failed(path, e))?;
    data.sync_data().map_err(|e| write_failed(path, mcap::McapError::Io(e).into()))?;
    Ok(())
}

/// Writes every waiting sample of `r` (and the frames its notices name) to
/// `path`.
fn drain(r: &mut Recording, writer: &mut Out, path: &Path) -> Result<()> {
    let mut failed = None;
    r.raw.receive(|h, bytes| {
        if let Some(last) = r.last_seq {
            r.dropped = r.dropped.saturating_add(h.seq.saturating_sub(last).saturating_sub(1));
        }
        r.last_seq = Some(h.seq);
        let log_ns = agent_sdk::clock::unix_now_ns();
        let sample = Sample { seq: h.seq, log_time_ns: log_ns, stamp_ns: h.stamp_ns, bytes };
        if let Err(e) = writer.write_sample(r.channel, &sample) {
            failed = Some(e);
            return false;
        }
        r.messages += 1;
        r.bytes = r.bytes.saturating_add(bytes.len() as u64);
        if let Some(images) = &mut r.images
            && let Err(e) = images.write(writer, bytes, log_ns)
        {
            failed = Some(e);
            return false;
        }
        true
    })?;
    match failed {
        Some(e) => Err(write_failed(path, e)),
        None => Ok(()),
    }
}

fn sum(recordings: &[Recording]) -> Totals {
    recordings.iter().fold(Totals::default(), |t, r| {
        let (frames, image_bytes, image_drops) =
            r.images.as_ref().map_or((0, 0, 0), |i| (i.frames, i.bytes, i.dropped));
        Totals {
            messages: t.messages + r.messages + frames,
            bytes: t.bytes + r.bytes + image_bytes,
            dropped: t.dropped + r.dropped + image_drops,
        }
    })
}

fn progress(recordings: &[Recording], elapsed: Duration, tty: bool) {
    let t = sum(recordings);
    let line = format!(
        "recording {} ports: {} messages, {:.1} MB, {} dropped ({:.0} s)",
        recordings.len(),
        t.messages,
        t.bytes as f64 / 1e6,
        t.dropped,
        elapsed.as_secs_f64()
    );
    let mut err = std::io::stderr().lock();
    let _ = if tty { write!(err, "\r{line}   ") } else { writeln!(err, "{line}") };
    let _ = err.flush();
}
