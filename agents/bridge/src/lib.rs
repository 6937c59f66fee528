//! `bridge`: carries chosen ports between robots over Zenoh, in peer mode
//! with no server (thesis 2.2.3, 2.3.3.2: "the transmitter and receiver are
//! treated as sensors and actuators"), or, for a fleet, as a client of
//! Zenoh routers (`mode = "client"`: the robots meet through the routers
//! instead of a full mesh). Each robot keeps its own router and
//! real-time system; only the ports named in the bridge's configuration
//! cross, and Zenoh stays inside this agent.
//!
//! * **export** `AGENT/PORT`: the bridge declares an input `AGENT.PORT`,
//!   asks the router to wire the local port to it, and sends every sample to
//!   the peers under `nerve/<robot>/<agent>/<port>`.
//! * **import** `ROBOT/AGENT/PORT`: the bridge publishes what arrives on its
//!   own output port (`ROBOT.AGENT.PORT` unless renamed), which local agents
//!   are wired to with `nerve connect` like any port.
//!
//! A link cut is normal: both robots run on, Zenoh re-dials, reliable topics
//! keep what was sent meanwhile in a bounded queue (see [`reliable`]).
//! Figures (peers, per-topic messages, bytes, drops, losses, queue depth,
//! age, one-way latency) are read-only figures of the agent: `nerve param
//! get`, `nerve ps --json`, `nerve bridge status`.
//!
//! The task is event-driven on the export inputs; a link thread (not
//! real-time) owns the Zenoh session, paces and retransmits, and wires the
//! exports through the router.

pub mod cipher;
pub mod config;
pub mod link;
pub mod reliable;
pub mod topics;
pub mod types;
pub mod wire;

use agent_sdk::control::router_client;
use agent_sdk::world::World;
use agent_sdk::{Agent, AgentError, Context, Setup, Task};
use config::Config;
use link::{Link, Me, Peers};
use shm_schemas::PortRef;
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply, RouterRequest};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::thread::JoinHandle;
use std::time::Duration;
use topics::{ExportTopic, ImportTopic};
pub use types::Types;

/// How often the link thread paces, retransmits and retries wiring.
const TICK: Duration = Duration::from_millis(20);
/// How often an export not yet wired is asked of the router again.
const WIRE_RETRY: Duration = Duration::from_millis(500);

static TYPES: OnceLock<Types> = OnceLock::new();

/// Runs a bridge that carries `types` (for a team's own payload types);
/// `nerve-bridge` itself is `main_with(Types::builtin())`.
pub fn main_with(types: Types) -> std::process::ExitCode {
    let _ = TYPES.set(types);
    agent_sdk::run::<Bridge>()
}

/// Like [`main_with`], with the agent's command line already parsed (for a
/// program that runs a bridge behind a subcommand of its own).
pub fn run_with_args(types: Types, args: agent_sdk::CommonArgs) -> std::process::ExitCode {
    let _ = TYPES.set(types);
    agent_sdk::run_with_args::<Bridge>(args)
}

fn types() -> &'static Types {
    TYPES.get_or_init(Types::builtin)
}

/// The bridge's own arguments (after `--`).
#[derive(Debug, clap::Parser)]
#[command(name = "nerve-bridge")]
struct BridgeArgs {
    /// The bridge's configuration (TOML; see agents/bridge/README.md).
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

impl BridgeArgs {
    /// `--config FILE`, which the bridge cannot do without.
    fn config_path(self) -> Result<PathBuf, AgentError> {
        self.config.ok_or_else(|| {
            AgentError::Config(
                "the bridge needs its configuration: nerve start bridge --name NAME -- --config FILE (see agents/bridge/README.md)"
                    .into(),
            )
        })
    }
}

fn instance_id() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u64(topics::unix_now_ns());
    h.write_u32(std::process::id());
    h.finish().max(1)
}

/// The bridge agent.
pub struct Bridge {
    cfg: Config,
    me: Me,
    world: World,
    exports: Vec<Arc<ExportTopic>>,
    imports: Vec<Arc<ImportTopic>>,
    peers: Arc<Peers>,
    stop: Arc<AtomicBool>,
    link_thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bridge").field("me", &self.me).field("exports", &self.exports.len()).finish()
    }
}

impl Agent for Bridge {
    const KIND: &'static str = "bridge";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let path = setup.args::<BridgeArgs>()?.config_path()?;
        let types = types();
        let cfg = config::load(&path, &|t| types.knows(t)).map_err(|e| AgentError::Config(e.to_string()))?;
        let robot = setup.world().robot().to_string();
        let me = Me { robot: robot.clone(), name: setup.name().to_owned() };
        // the files named by the robot's name are checked at the start (a
        // description for `nerve launch`'s check runs under another name)
        if let Some(tls) = &cfg.tls {
            tls.files(&robot).check(None, tls).map_err(|e| AgentError::Config(format!("{}: {e}", path.display())))?;
        }
        let instance = instance_id();
        let mut exports = Vec::new();
        for e in &cfg.exports {
            let c = types
                .carrier(&e.type_name, e.max_len)
                .ok_or_else(|| AgentError::Config(format!("unknown type {}", e.type_name)))?;
            let tap = c.export(setup, &e.input_name())?;
            exports.push(Arc::new(
                ExportTopic::new(e.clone(), c.info, &robot, instance, tap).with_importer_ttl(cfg.importer_ttl),
            ));
        }
        let mut imports = Vec::new();
        for i in &cfg.imports {
            if i.robot == robot {
                return Err(AgentError::Config(format!(
                    "import {} names this robot ({robot}); import ports of another robot",
                    i.origin()
                )));
            }
            let c = types
                .carrier(&i.type_name, i.max_len)
                .ok_or_else(|| AgentError::Config(format!("unknown type {}", i.type_name)))?;
            let sink = c.import(setup, &i.local)?;
            imports.push(Arc::new(ImportTopic::new(i.clone(), c.info, sink)));
        }
        let peers = Arc::new(Peers::default());
        let security = if cfg.tls.is_some() {
            "tls"
        } else if cfg.runs_insecure() {
            "insecure"
        } else {
            "loopback"
        };
        let mode = cfg.mode.as_str();
        {
            let (exports, imports, peers) = (exports.clone(), imports.clone(), peers.clone());
            setup.figures(move || {
                let now = agent_sdk::clock::now_ns();
                let names = peers.names();
                let mut v = vec![
                    ("peers".to_string(), names.len().to_string()),
                    ("peer_names".to_string(), names.join(",")),
                    ("security".to_string(), security.to_string()),
                    ("mode".to_string(), mode.to_string()),
                ];
                for t in &exports {
                    t.figures(&mut v);
                }
                for t in &imports {
                    t.figures(now, &mut v);
                }
                v
            });
        }
        Ok(Bridge {
            cfg,
            me,
            world: setup.world().clone(),
            exports,
            imports,
            peers,
            stop: Arc::new(AtomicBool::new(false)),
            link_thread: None,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        if let Some(tls) = &self.cfg.tls {
            tls.files(&self.me.robot).check(Some(&self.me.robot), tls).map_err(AgentError::Config)?;
        }
        if self.cfg.runs_insecure() {
            tracing::warn!(
                listen = ?self.cfg.listen,
                connect = ?self.cfg.connect,
                "insecure = true: plain TCP beyond this host; any host that reaches these endpoints can read and forge this robot's topics (use [tls], see `nerve bridge keys`)"
            );
        }
        if self.cfg.tls.is_some() && self.cfg.peers.is_empty() {
            tracing::warn!("[tls] with no peers: no robot may import from this bridge; list them in `peers = [...]`");
        }
        // The session is opened by the link thread, which is not real-time;
        // wait for it here so that a bad endpoint fails the start loudly.
        let (tx, rx) = std::sync::mpsc::channel::<Result<(), String>>();
        let cfg = self.cfg.clone();
        let me = self.me.clone();
        let world = self.world.clone();
        let (exports, imports, peers, stop) =
            (self.exports.clone(), self.imports.clone(), self.peers.clone(), self.stop.clone());
        let handle = std::thread::Builder::new()
            .name("bridge-link".into())
            .spawn(move || {
                agent_sdk::rt::drop_realtime();
                let link = match Link::open(&cfg, &me, &exports, &imports, &peers, agent_sdk::clock::now_ns) {
                    Ok(l) => {
                        let _ = tx.send(Ok(()));
                        l
                    }
                    Err(e) => {
                        let _ = tx.send(Err(e.to_string()));
                        return;
                    }
                };
                link_loop(&world, &me, &exports, &stop);
                link.close();
            })
            .map_err(|e| AgentError::Other(format!("cannot start the link thread: {e}")))?;
        self.link_thread = Some(handle);
        match rx.recv_timeout(Duration::from_secs(20)) {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(AgentError::Other(e)),
            Err(_) => Err(AgentError::Other("the zenoh session did not open within 20 s".into())),
        }
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        for t in &self.exports {
            t.pump(ctx.now_ns());
        }
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = self.link_thread.take() {
            let _ = h.join();
        }
    }
}

/// The link thread's loop: pace and retransmit every export, pick up what
/// the task left queued (it takes a bounded batch per wake-up), and ask the
/// router to wire the exports that are not wired yet.
fn link_loop(world: &World, me: &Me, exports: &[Arc<ExportTopic>], stop: &AtomicBool) {
    let mut next_wire = std::time::Instant::now();
    let mut router = None;
    while !stop.load(Ordering::Acquire) {
        let now = agent_sdk::clock::now_ns();
        for t in exports {
            t.pump(now);
        }
        if std::time::Instant::now() >= next_wire && exports.iter().any(|t| !t.wired()) {
            next_wire = std::time::Instant::now() + WIRE_RETRY;
            wire_exports(world, me, exports, &mut router);
        }
        std::thread::sleep(TICK);
    }
}

type RouterLink =
    (iceoryx2::prelude::Node<agent_sdk::Ipc>, agent_sdk::control::ControlClient<RouterRequest, RouterReply>);

/// Asks the router to connect each export's local port to the bridge's
/// input; the router keeps the connection (and restores it when either
/// agent restarts), so each is asked until it succeeds once.
fn wire_exports(world: &World, me: &Me, exports: &[Arc<ExportTopic>], router: &mut Option<RouterLink>) {
    if router.is_none() {
        let Ok(node) = world.node(&format!("{}-wiring", me.name)) else { return };
        match router_client(world, &node) {
            Ok(client) => *router = Some((node, client)),
            Err(e) => {
                tracing::debug!("no router yet to wire the exports: {e}");
                return;
            }
        }
    }
    let Some((_, client)) = router.as_ref() else { return };
    for t in exports.iter().filter(|t| !t.wired()) {
        let (Ok(from), Ok(to)) =
            (PortRef::new(&t.spec.agent, &t.spec.port), PortRef::new(&me.name, &t.spec.input_name()))
        else {
            continue;
        };
        match client.call(
            &RouterRequest::Cli(CliRequest::Connect { from: from.clone(), to: to.clone(), allow_cycle: false }),
            Duration::from_secs(5),
        ) {
            Ok(RouterReply::Ok) => {
                t.set_wired();
                tracing::info!(export = %from, input = %to, "export wired: {from} -> {to}");
            }
            Ok(RouterReply::Error(e)) => tracing::debug!(export = %from, "not wired yet: {e}"),
            Ok(other) => tracing::warn!(export = %from, "unexpected reply from the router: {other:?}"),
            Err(e) => {
                tracing::debug!(export = %from, "router unreachable: {e}");
                *router = None;
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config_path(args: &[&str]) -> Result<PathBuf, AgentError> {
        let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        agent_sdk::agent::args::parse::<BridgeArgs>("bridge", &args)
            .map_err(|e| AgentError::Config(e.to_string()))?
            .config_path()
    }

    #[test]
    fn the_config_flag_is_required() {
        assert_eq!(config_path(&["--config", "b.toml"]).ok(), Some(PathBuf::from("b.toml")));
        assert_eq!(config_path(&["--config=b.toml"]).ok(), Some(PathBuf::from("b.toml")));
        let e = config_path(&[]).expect_err("missing").to_string();
        assert!(e.contains("--config FILE"), "{e}");
        let e = config_path(&["--confg", "b.toml"]).expect_err("misspelt").to_string();
        assert!(e.contains("--confg") && e.contains("nerve-bridge -- --help"), "{e}");
    }
}
