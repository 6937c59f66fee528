//! `blackbox`: keeps the last seconds of chosen ports in memory and writes
//! them as MCAP when asked (`nerve snapshot`) or by itself when an agent
//! dies or a watched field changes. See the library (`nerve_blackbox`) for
//! the configuration file.
//!
//! ```text
//! nerve start blackbox --name blackbox -- --config blackbox.toml
//! nerve snapshot -o crash.mcap
//! ```
//!
//! The black box is a subscriber like any other: it reads each kept port by
//! its bytes, publishers never wait for it. It learns of deaths and of new
//! agents from the router's event log (`agent_sdk::router_events`), which
//! tells a death from a clean stop. Snapshots are written on their own
//! threads, so the black box keeps taking samples meanwhile; a file appears
//! whole (renamed into place).
//!
//! Parameter `snapshot`: an absolute path ending in `.mcap`; setting it
//! writes the kept seconds there (`nerve snapshot` sets it). Figures:
//! `snapshots` (written so far), `last_snapshot`, `kept_mb`, `ports`,
//! `refused` (snapshots not written: the disk was below `min_free_mb`, or
//! the write failed), `deleted` (old fired snapshots deleted to keep
//! `max_files` and `max_total_mb`).

use agent_sdk::control::{ControlClient, router_client};
use agent_sdk::raw_port::RawPort;
use agent_sdk::router_events::{EventFollower, Look};
use agent_sdk::world::Ipc;
use agent_sdk::{Agent, AgentError, Context, Param, Setup, Task, World};
use clap::Parser;
use iceoryx2::prelude::Node;
use nerve_blackbox::{
    Config, Folder, Kept, KeptImage, Memory, PortHistory, check_room, snapshot_bytes, write_snapshot,
};
use nerve_recording::{FrameOutcome, RingFrames};
use shm_schemas::control::cli_to_router::{CliRequest, EventKind, RouterReply, RouterRequest};
use shm_schemas::ring::RingNotice;
use shm_schemas::{Payload, PortRef};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

type RouterClient = ControlClient<RouterRequest, RouterReply>;

/// How long a call to the router may take (it answers these at once).
const ROUTER_TIMEOUT: Duration = Duration::from_secs(2);
/// How often the robot's ports are looked at while the router does not
/// answer for its events (else only when an agent registered).
const LOOK_PERIOD: Duration = Duration::from_secs(1);
/// How often the router's events are read.
const EVENTS_PERIOD: Duration = Duration::from_millis(200);

/// The black box's options (after `--`).
#[derive(Debug, Clone, Parser)]
#[command(name = "nerve-blackbox --", about = "black box options")]
struct Args {
    /// The configuration file (TOML; see the nerve_blackbox docs).
    #[arg(long)]
    config: PathBuf,
}

/// A kept port with its subscription.
struct Watched {
    raw: RawPort,
    /// its index in the memory
    index: usize,
    /// ring frames, for a port of ring notices
    frames: Option<RingFrames>,
    /// watched fields: (path, last value)
    fields: Vec<(String, Option<String>)>,
}

/// A snapshot to write when its time comes.
struct Pending {
    at: Instant,
    from_ns: u64,
    to_ns: u64,
    path: PathBuf,
    why: String,
    /// fired (into the folder, within its caps), not asked
    fired: bool,
}

/// Figures the message checker reads.
#[derive(Default)]
struct Figures {
    snapshots: AtomicU64,
    kept_bytes: AtomicU64,
    ports: AtomicU64,
    refused: AtomicU64,
    deleted: AtomicU64,
    last: Mutex<String>,
}

struct Blackbox {
    /// its own name (its ports are not kept)
    name: String,
    config: Config,
    world: World,
    node: Node<Ipc>,
    router: Option<RouterClient>,
    memory: Memory,
    watched: Vec<Watched>,
    /// ports that could not be kept, said once
    refused: Vec<PortRef>,
    snapshot: Param<String>,
    figures: Arc<Figures>,
    pending: Vec<Pending>,
    writing: Vec<JoinHandle<()>>,
    /// the router's event log
    events: EventFollower,
    last_look: Option<Instant>,
    /// a port could not be opened: look again at the next events
    look_again: bool,
    last_events: Option<Instant>,
    last_fired: Option<Instant>,
    buf: Vec<u8>,
    /// the folder of fired snapshots
    folder: Folder,
    /// a refusal for lack of space was logged (again only after a snapshot
    /// was written)
    low_space_said: bool,
}

/// The check of `snapshot`: empty, or an absolute `.mcap` path in an existing folder.
fn check_snapshot(v: &String) -> Result<(), String> {
    if v.is_empty() {
        return Ok(());
    }
    let p = Path::new(v);
    if !p.is_absolute() || p.extension().is_none_or(|e| e != "mcap") {
        return Err(format!("snapshot {v:?}: give an absolute path ending in .mcap (`nerve snapshot -o FILE` does)"));
    }
    match p.parent() {
        Some(d) if d.is_dir() => Ok(()),
        _ => Err(format!("snapshot {v:?}: its folder does not exist")),
    }
}

impl Blackbox {
    fn call(&mut self, req: CliRequest) -> Option<RouterReply> {
        if self.router.is_none() {
            self.router = router_client(&self.world, &self.node).ok();
        }
        let client = self.router.as_ref()?;
        match client.call(&RouterRequest::Cli(req), ROUTER_TIMEOUT) {
            Ok(RouterReply::Error(e)) => {
                tracing::debug!("the router refused: {e}");
                None
            }
            Ok(r) => Some(r),
            Err(e) => {
                tracing::debug!("the router did not answer: {e}");
                self.router = None;
                None
            }
        }
    }

    /// Subscribes to the kept ports that appeared.
    fn look(&mut self) {
        self.look_again = false;
        let Some(RouterReply::Agents(agents)) = self.call(CliRequest::Ps) else { return };
        for a in agents.iter().filter(|a| a.pid != 0 && a.name != self.name) {
            for o in &a.outputs {
                let Ok(port) = PortRef::new(&a.name, &o.name) else { continue };
                if !self.config.keeps(&port)
                    || self.refused.contains(&port)
                    || self.memory.ports.iter().any(|h| h.port == port)
                {
                    continue;
                }
                let Some(schema) = a.schema_for(o.fingerprint) else {
                    tracing::warn!(port = %port, "not keeping {port}: its type {} has no schema", o.type_name);
                    self.refused.push(port);
                    continue;
                };
                let service = self.world.robot().port_service(&a.name, &o.name);
                let raw = match RawPort::open(&self.node, &service) {
                    Ok(r) => r,
                    Err(e) => {
                        // a port being made or remade: tried again at the next events
                        tracing::debug!(port = %port, "cannot keep {port} yet: {e}");
                        self.look_again = true;
                        continue;
                    }
                };
                let name = port.to_string();
                let fields: Vec<(String, Option<String>)> = self
                    .config
                    .fire
                    .on_change
                    .iter()
                    .filter(|w| w.port == name)
                    .filter_map(|w| {
                        if schema.field(&w.field).is_some() {
                            Some((w.field.clone(), None))
                        } else {
                            tracing::warn!(port = %port, "{port} has no field {:?}: not watched", w.field);
                            None
                        }
                    })
                    .collect();
                let frames = (o.type_name == <RingNotice as Payload>::stable_type_name())
                    .then(|| RingFrames::new(self.world.robot(), &a.name));
                tracing::info!(port = %port, "keeping {port} ({})", o.type_name);
                self.memory.ports.push(PortHistory::new(port, o.type_name.clone(), o.fingerprint, schema));
                self.watched.push(Watched { raw, index: self.memory.ports.len() - 1, frames, fields });
            }
        }
        self.figures.ports.store(self.watched.len() as u64, Ordering::Relaxed);
    }

    /// Takes every waiting sample; returns the watched fields that changed.
    fn take(&mut self) -> Vec<String> {
        let mut changed = Vec::new();
        for w in &mut self.watched {
            let h = &self.memory.ports[w.index];
            let (schema, port) = (&h.schema, &h.port);
            let mut got: Vec<Kept> = Vec::new();
            let mut images: Vec<KeptImage> = Vec::new();
            let buf = &mut self.buf;
            let frames = &mut w.frames;
            let fields = &mut w.fields;
            let r = w.raw.receive(|hdr, bytes| {
                let log_ns = agent_sdk::clock::unix_now_ns();
                if let Some(f) = frames
                    && let FrameOutcome::Encoded(seq) = f.encode(bytes, log_ns, buf)
                {
                    images.push(KeptImage { seq, log_ns, encoded: buf.as_slice().into() });
                }
                if !fields.is_empty() {
                    for (path, last) in fields.iter_mut() {
                        let now = schema.decode_field(path, bytes).map(|x| x.to_string());
                        if last.is_some() && now != *last {
                            changed.push(format!(
                                "{port} {path} {} -> {}",
                                last.as_deref().unwrap_or("?"),
                                now.as_deref().unwrap_or("?")
                            ));
                        }
                        *last = now;
                    }
                }
                got.push(Kept { seq: hdr.seq, log_ns, stamp_ns: hdr.stamp_ns, bytes: bytes.into() });
                true
            });
            if let Err(e) = r {
                tracing::debug!(port = %port, "receive: {e}");
            }
            for k in got {
                self.memory.push(w.index, k);
            }
            for i in images {
                self.memory.push_image(w.index, i);
            }
        }
        changed
    }

    /// What the router saw since the last look: the deaths (why, agent),
    /// and whether to look for new ports (an agent registered, or the
    /// router cannot say).
    fn events(&mut self, now: Instant) -> (Vec<(String, String)>, bool) {
        match self.events.look() {
            // what happened before the black box (or this router) started is
            // not its business; the agents there are found by a look
            Look::Fresh => (vec![], true),
            Look::NoRouter => (vec![], self.last_look.is_none_or(|t| now.duration_since(t) >= LOOK_PERIOD)),
            Look::Events(events) => {
                let registered = events.iter().any(|e| matches!(e.what, EventKind::Registered { .. }));
                let deaths = events
                    .into_iter()
                    .filter_map(|e| match e.what {
                        EventKind::Died { agent, pid } => Some((format!("{agent} (pid {pid}) died"), agent)),
                        _ => None,
                    })
                    .collect();
                (deaths, registered)
            }
        }
    }

    fn fire(&mut self, why: &str, slug: &str) {
        let now = Instant::now();
        if self.last_fired.is_some_and(|t| now.duration_since(t).as_secs_f64() < self.config.fire.min_gap) {
            tracing::info!("{why}: within fire.min_gap of the last snapshot, not written again");
            return;
        }
        self.last_fired = Some(now);
        let unix = agent_sdk::clock::unix_now_ns();
        let after = Duration::from_secs_f64(self.config.after);
        let name = format!("blackbox-{}-{}.mcap", stamp(unix), slug);
        let path = self.config.dir.join(name);
        tracing::warn!(file = %path.display(), "{why}: writing the black box to {} in {after:?}", path.display());
        self.pending.push(Pending {
            at: now + after,
            from_ns: unix.saturating_sub((self.config.seconds * 1e9) as u64),
            to_ns: unix.saturating_add(after.as_nanos() as u64),
            path,
            why: why.to_string(),
            fired: true,
        });
    }

    /// Starts writing the snapshots whose time has come.
    fn write_due(&mut self, now: Instant) {
        let (due, later): (Vec<Pending>, Vec<Pending>) = self.pending.drain(..).partition(|p| p.at <= now);
        self.pending = later;
        for p in due {
            let ports = self.memory.window(p.from_ns, p.to_ns);
            let need = snapshot_bytes(&ports);
            if p.fired {
                // the oldest fired snapshots make room for this one
                match self.folder.make_room(need) {
                    Ok(gone) if !gone.files.is_empty() => {
                        self.figures.deleted.fetch_add(gone.files.len() as u64, Ordering::Relaxed);
                        tracing::info!(
                            dir = %self.folder.dir.display(),
                            files = gone.files.len(),
                            bytes = gone.bytes,
                            "deleted the {} oldest snapshots ({:.1} MB) to keep max_files = {} and max_total_mb",
                            gone.files.len(),
                            gone.bytes as f64 / 1e6,
                            self.folder.max_files
                        );
                    }
                    Ok(_) => {}
                    Err(e) => {
                        tracing::warn!(dir = %self.folder.dir.display(), "cannot keep the snapshot folder within its caps: {e}")
                    }
                }
            }
            let dir = p.path.parent().unwrap_or(Path::new(".")).to_path_buf();
            if let Err(e) = check_room(&dir, need, self.config.min_free_mb) {
                self.figures.refused.fetch_add(1, Ordering::Relaxed);
                if !self.low_space_said {
                    self.low_space_said = true;
                    tracing::error!(file = %p.path.display(), need, "{e} (said once; the figure `refused` counts them)");
                }
                continue;
            }
            self.low_space_said = false;
            let robot = self.world.robot().to_string();
            let figures = self.figures.clone();
            self.writing.push(std::thread::spawn(move || match write_snapshot(&p.path, &robot, &ports) {
                Ok(w) => {
                    tracing::info!(
                        file = %p.path.display(),
                        messages = w.messages,
                        images = w.images,
                        "black box written ({}): {} messages, {} images, {:.1} MB to {}",
                        p.why,
                        w.messages,
                        w.images,
                        w.bytes as f64 / 1e6,
                        p.path.display()
                    );
                    figures.snapshots.fetch_add(1, Ordering::Relaxed);
                    *figures.last.lock().unwrap_or_else(|e| e.into_inner()) = p.path.display().to_string();
                }
                Err(e) => {
                    figures.refused.fetch_add(1, Ordering::Relaxed);
                    tracing::error!(
                        file = %p.path.display(),
                        "cannot write the black box to {} (its .part is removed): {e}",
                        p.path.display()
                    )
                }
            }));
        }
        self.writing.retain(|h| !h.is_finished());
    }
}

/// `YYYYmmdd-HHMMSS.mmm` of CLOCK_REALTIME ns (UTC).
fn stamp(unix_ns: u64) -> String {
    format!("{}.{:03}", nerve_recording::file_stamp(unix_ns), unix_ns / 1_000_000 % 1000)
}

/// A file-name-safe form of `text`.
fn slug(text: &str) -> String {
    text.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '-' }).collect()
}

impl Agent for Blackbox {
    const KIND: &'static str = "blackbox";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(10))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let config = Config::load(&args.config).map_err(|e| AgentError::Config(e.to_string()))?;
        std::fs::create_dir_all(&config.dir).map_err(|e| {
            AgentError::Config(format!(
                "cannot make the snapshot folder {} (dir in {}): {e}",
                config.dir.display(),
                args.config.display()
            ))
        })?;
        let world = setup.world().clone();
        let node = world
            .node(&format!("{}-ports", setup.name()))
            .map_err(|e| AgentError::Config(format!("cannot join the robot's shared memory: {e}")))?;
        let events_node = world
            .node(&format!("{}-events", setup.name()))
            .map_err(|e| AgentError::Config(format!("cannot join the robot's shared memory: {e}")))?;
        let events = EventFollower::new(&world, events_node);
        let snapshot = setup.param_checked("snapshot", String::new(), check_snapshot);
        let figures = Arc::new(Figures::default());
        let f = figures.clone();
        setup.figures(move || {
            vec![
                ("snapshots".into(), f.snapshots.load(Ordering::Relaxed).to_string()),
                ("last_snapshot".into(), f.last.lock().map(|s| s.clone()).unwrap_or_default()),
                ("kept_mb".into(), format!("{:.1}", f.kept_bytes.load(Ordering::Relaxed) as f64 / 1e6)),
                ("ports".into(), f.ports.load(Ordering::Relaxed).to_string()),
                ("refused".into(), f.refused.load(Ordering::Relaxed).to_string()),
                ("deleted".into(), f.deleted.load(Ordering::Relaxed).to_string()),
            ]
        });
        let memory = Memory::new(config.seconds, config.max_mb);
        let folder = Folder::of(&config);
        // what a black box that died while writing left
        match folder.sweep() {
            Ok(gone) if !gone.files.is_empty() => tracing::info!(
                dir = %folder.dir.display(),
                files = gone.files.len(),
                bytes = gone.bytes,
                "removed {} unfinished snapshots (.part) of an earlier run",
                gone.files.len()
            ),
            Ok(_) => {}
            Err(e) => {
                tracing::warn!(dir = %folder.dir.display(), "cannot sweep the .part files of {}: {e}", folder.dir.display())
            }
        }
        Ok(Blackbox {
            name: setup.name().to_string(),
            config,
            world,
            node,
            router: None,
            memory,
            watched: Vec::new(),
            refused: Vec::new(),
            snapshot,
            figures,
            pending: Vec::new(),
            writing: Vec::new(),
            events,
            last_look: None,
            look_again: false,
            last_events: None,
            last_fired: None,
            buf: Vec::new(),
            folder,
            low_space_said: false,
        })
    }

    fn step(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        let now = Instant::now();
        // the router's events say when to look for new ports (an agent
        // registered) and who died; a look every LOOK_PERIOD catches up
        // with a router that did not answer
        if self.last_events.is_none_or(|t| now.duration_since(t) >= EVENTS_PERIOD) {
            self.last_events = Some(now);
            let (deaths, registered) = self.events(now);
            if registered || self.look_again {
                self.last_look = Some(now);
                self.look();
            }
            if self.config.fire.on_death {
                for (why, agent) in deaths {
                    self.fire(&why, &format!("died-{}", slug(&agent)));
                }
            }
        }
        for why in self.take() {
            self.fire(&why, "change");
        }
        let asked = self.snapshot.get();
        if !asked.is_empty() {
            self.snapshot.set(String::new());
            let unix = agent_sdk::clock::unix_now_ns();
            self.pending.push(Pending {
                at: now,
                from_ns: unix.saturating_sub((self.config.seconds * 1e9) as u64),
                to_ns: unix,
                path: PathBuf::from(&asked),
                why: "asked".into(),
                fired: false,
            });
        }
        self.memory.trim(agent_sdk::clock::unix_now_ns());
        self.figures.kept_bytes.store(self.memory.bytes() as u64, Ordering::Relaxed);
        self.write_due(now);
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) {
        // what is due is written before the black box leaves
        let now = Instant::now() + Duration::from_secs(3600);
        self.write_due(now);
        for h in self.writing.drain(..) {
            let _ = h.join();
        }
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Blackbox>()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn snapshot_paths_are_checked() {
        assert!(check_snapshot(&String::new()).is_ok());
        assert!(check_snapshot(&"rel.mcap".to_string()).is_err());
        assert!(check_snapshot(&"/tmp/x.txt".to_string()).is_err());
        assert!(check_snapshot(&"/no/such/folder/x.mcap".to_string()).is_err());
        assert!(check_snapshot(&"/tmp/x.mcap".to_string()).is_ok());
    }

    #[test]
    fn stamps_and_slugs_make_file_names() {
        assert_eq!(stamp(0), "19700101-000000.000");
        assert_eq!(stamp(1_764_000_000_123_000_000), "20251124-160000.123");
        assert_eq!(slug("t1 (pid 4)"), "t1--pid-4-");
    }
}
