//! `nerve ui`: the robot's live graph in a browser (the `nerve-ui` crate
//! serves the page; this module is its robot side).
//!
//! Every action goes through the router with the requests the matching
//! command sends (`connect`, `rate`, `param set`...), and hot add runs
//! `nerve start` itself, so the command line and the page always agree. The
//! page's port inspector subscribes to the port like `nerve echo` does
//! (zero copy, the publisher undisturbed) and lets go of the subscription
//! when nobody has asked for it for [`TAP_IDLE`].

use super::echo::port_info;
use crate::client::{RouterSession, cli_node};
use crate::interrupt;
use agent_sdk::World;
use agent_sdk::raw_port::RawPort;
use agent_sdk::world::Ipc;
use anyhow::{Context as _, Result};
use iceoryx2::prelude::Node;
use nerve_ui::{Action, Options, Robot};
use serde_json::{Value, json};
use shm_schemas::control::cli_to_router::{CliRequest, RouterError, RouterReply};
use shm_schemas::ring::RingNotice;
use shm_schemas::{PortRef, Schema};
use std::collections::{BTreeMap, VecDeque};
use std::io::Write as _;
use std::net::SocketAddr;
use std::process::{Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

/// `nerve ui`
#[derive(Debug, clap::Args)]
pub struct UiArgs {
    /// Address to serve on; 127.0.0.1 keeps the page to this machine (port 0: any free port).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub bind: SocketAddr,
    /// Watch only: the page offers no action and the server refuses every one.
    #[arg(long)]
    pub read_only: bool,
    /// Seconds between two updates of the page.
    #[arg(long, default_value_t = 0.5, value_parser = agent_sdk::clock::parse_seconds)]
    pub interval: f64,
    /// The editing token (default: a fresh random one, printed at start).
    #[arg(long, env = "NERVE_UI_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
}

/// A port subscription unused this long is dropped.
const TAP_IDLE: Duration = Duration::from_secs(10);
/// Samples kept per inspected port.
const KEPT: usize = 100;

pub fn ui(world: &World, a: UiArgs) -> Result<ExitCode> {
    if !(0.05..=10.0).contains(&a.interval) {
        anyhow::bail!("--interval {} is out of range: give 0.05 to 10 seconds", a.interval);
    }
    let token = match a.token {
        Some(t) if t.len() >= 16 => t,
        Some(_) => {
            anyhow::bail!("--token is too short: give at least 16 characters (or leave it out for a random one)")
        }
        None => nerve_ui::new_token().context("cannot make a token from /dev/urandom")?,
    };
    let opts = Options {
        bind: a.bind,
        read_only: a.read_only,
        interval: Duration::from_secs_f64(a.interval),
        token: token.clone(),
        robot: world.robot().as_str().to_owned(),
        max_clients: 16,
    };
    let node = cli_node(world)?;
    let mut robot = UiRobot { world: world.clone(), node, session: None, taps: BTreeMap::new() };
    interrupt::catch();
    let robot_name = world.robot().as_str().to_owned();
    // what it says goes to whoever reads stdout; one that stopped reading does not stop the server
    let say = |text: String| {
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "{text}").and_then(|()| out.flush());
    };
    let mut listening = |addr: SocketAddr| {
        if a.read_only {
            say(format!("nerve ui of robot {robot_name} (read-only): http://{addr}/"));
        } else {
            say(format!("nerve ui of robot {robot_name}: http://{addr}/?token={token}"));
            say("(the token lets the page change the robot; open the address without it to watch only)".into());
        }
        say("press Ctrl-C to stop".into());
    };
    nerve_ui::serve(&opts, &mut robot, &mut listening, &interrupt::requested)?;
    say("nerve ui stopped".into());
    Ok(ExitCode::SUCCESS)
}

/// An inspected output port.
struct Tap {
    raw: RawPort,
    type_name: String,
    schema: Option<Schema>,
    kept: VecDeque<Value>,
    /// the bytes of the latest sample (a ring notice's, for the image)
    latest: Vec<u8>,
    asked: Instant,
}

/// The robot as the page sees it.
struct UiRobot {
    world: World,
    node: Node<Ipc>,
    /// opened on first use, and again after the router did not answer
    session: Option<RouterSession>,
    taps: BTreeMap<String, Tap>,
}

impl UiRobot {
    fn call(&mut self, req: CliRequest) -> Result<RouterReply, String> {
        let session = match &self.session {
            Some(s) => s,
            None => self.session.insert(RouterSession::open(&self.world).map_err(|e| format!("{e:#}"))?),
        };
        let reply = session.call(req);
        // a refusal is the router's answer; any other failure means no router (or a new
        // one): the next call opens a fresh session
        if reply.as_ref().is_err_and(|e| e.downcast_ref::<RouterError>().is_none()) {
            self.session = None;
        }
        reply.map_err(|e| format!("{e:#}"))
    }

    fn ok(&mut self, req: CliRequest) -> Result<Value, String> {
        match self.call(req)? {
            RouterReply::Ok => Ok(json!({ "ok": true })),
            other => Err(format!("unexpected reply from the router: {other:?}")),
        }
    }

    /// `nerve start KIND --name NAME`, run as a command so that it is the same start-up.
    fn start(&self, kind: &str, name: &str) -> Result<Value, String> {
        let exe = std::env::current_exe().map_err(|e| format!("cannot find the nerve program: {e}"))?;
        let out = Command::new(exe)
            .args(["--robot", self.world.robot().as_str(), "start", kind, "--name", name])
            .stdin(Stdio::null())
            .output()
            .map_err(|e| format!("cannot run nerve start: {e}"))?;
        if out.status.success() {
            Ok(json!({ "ok": true, "said": String::from_utf8_lossy(&out.stdout).trim() }))
        } else {
            let said = String::from_utf8_lossy(&out.stderr);
            Err(said.trim().trim_start_matches("error: ").to_owned())
        }
    }

    /// A supervised agent is killed (its supervisor restarts it with its own
    /// command line); another is stopped and started again by kind and name.
    fn restart(&mut self, name: &str) -> Result<Value, String> {
        let RouterReply::Agents(agents) = self.call(CliRequest::Ps)? else {
            return Err("unexpected reply from the router to ps".into());
        };
        let agent = agents
            .iter()
            .find(|a| a.name == name)
            .ok_or_else(|| format!("no agent named {name:?} is running; see `nerve ps`"))?;
        if agent.importance.is_some() {
            return self.ok(CliRequest::Kill { name: name.into() });
        }
        let kind = agent.kind.clone();
        self.ok(CliRequest::Stop { name: name.into() })?;
        let t0 = Instant::now();
        loop {
            match self.start(&kind, name) {
                Ok(v) => return Ok(v),
                // the name is free once the router saw it leave
                Err(e) if e.contains("already running") && t0.elapsed() < Duration::from_secs(5) => {
                    std::thread::sleep(Duration::from_millis(50));
                }
                Err(e) => return Err(e),
            }
        }
    }

    fn tap(&mut self, port: &str) -> Result<&mut Tap, String> {
        if !self.taps.contains_key(port) {
            let r: PortRef = port.parse().map_err(|e| format!("{e}"))?;
            let info = port_info(&self.world, &self.node, &r).map_err(|e| format!("{e:#}"))?;
            let service = self.world.robot().port_service(r.agent.as_str(), &r.port);
            let raw = RawPort::open(&self.node, &service).map_err(|e| format!("cannot subscribe to {port}: {e}"))?;
            let tap = Tap {
                raw,
                type_name: info.type_name,
                schema: info.schema,
                kept: VecDeque::new(),
                latest: Vec::new(),
                asked: Instant::now(),
            };
            self.taps.insert(port.to_owned(), tap);
        }
        let tap = self.taps.get_mut(port).ok_or("the subscription is gone")?;
        tap.asked = Instant::now();
        let (kept, latest, schema) = (&mut tap.kept, &mut tap.latest, &tap.schema);
        tap.raw
            .receive(|h, bytes| {
                let value = match schema.as_ref().map(|s| s.decode(bytes)) {
                    Some(Ok(v)) => serde_json::to_value(v).unwrap_or(Value::Null),
                    Some(Err(e)) => json!({ "undecodable": e.to_string() }),
                    None => json!({ "bytes": bytes.len() }),
                };
                kept.push_back(json!({ "seq": h.seq, "stamp_ns": h.stamp_ns, "value": value }));
                if kept.len() > KEPT {
                    kept.pop_front();
                }
                latest.clear();
                latest.extend_from_slice(bytes);
                true
            })
            .map_err(|e| format!("cannot read {port}: {e}"))?;
        Ok(tap)
    }
}

impl Robot for UiRobot {
    fn graph(&mut self) -> Result<Value, String> {
        match self.call(CliRequest::Graph)? {
            RouterReply::Graph(g) => {
                let mut v = serde_json::to_value(&g).map_err(|e| e.to_string())?;
                // the page needs the ports' types, not their schemas (sent with each sample instead)
                if let Some(agents) = v.get_mut("agents").and_then(Value::as_array_mut) {
                    for a in agents.iter_mut().filter_map(Value::as_object_mut) {
                        a.remove("schemas");
                    }
                }
                Ok(v)
            }
            other => Err(format!("unexpected reply from the router: {other:?}")),
        }
    }

    fn act(&mut self, action: Action) -> Result<Value, String> {
        let port = |p: &str| p.parse::<PortRef>().map_err(|e| format!("{e}"));
        match action {
            Action::Connect { from, to } => {
                self.ok(CliRequest::Connect { from: port(&from)?, to: port(&to)?, allow_cycle: false })
            }
            Action::Disconnect { from, to } => self.ok(CliRequest::Disconnect { from: port(&from)?, to: port(&to)? }),
            Action::Rate { name, period } => {
                let d = agent_sdk::clock::parse_duration(&period)?;
                self.ok(CliRequest::Rate { name, period_ns: agent_sdk::clock::nanos(d) })
            }
            Action::Suspend { name } => self.ok(CliRequest::Suspend { name }),
            Action::Resume { name } => self.ok(CliRequest::Resume { name }),
            Action::Stop { name } => self.ok(CliRequest::Stop { name }),
            Action::Kill { name } => self.ok(CliRequest::Kill { name }),
            Action::Restart { name } => self.restart(&name),
            Action::Params { name } => match self.call(CliRequest::ParamList { name })? {
                RouterReply::Params(list) => serde_json::to_value(list).map_err(|e| e.to_string()),
                other => Err(format!("unexpected reply from the router: {other:?}")),
            },
            Action::ParamGet { name, key } => match self.call(CliRequest::ParamGet { name, key })? {
                RouterReply::Param(v) => Ok(json!({ "value": v })),
                other => Err(format!("unexpected reply from the router: {other:?}")),
            },
            Action::ParamSet { name, key, value } => self.ok(CliRequest::ParamSet { name, key, value }),
            Action::Start { kind, name } => self.start(&kind, &name),
        }
    }

    fn samples(&mut self, port: &str, after: u64) -> Result<Value, String> {
        let tap = self.tap(port)?;
        let samples: Vec<&Value> =
            tap.kept.iter().filter(|s| s["seq"].as_u64().is_some_and(|seq| seq > after)).collect();
        Ok(json!({
            "port": port,
            "type_name": tap.type_name,
            "image": tap.type_name == <RingNotice as shm_schemas::Payload>::stable_type_name(),
            "samples": samples,
        }))
    }

    fn image(&mut self, port: &str) -> Result<Vec<u8>, String> {
        let tap = self.tap(port)?;
        let notice = RingNotice::from_bytes(&tap.latest)
            .ok_or_else(|| format!("{port} carries {}, not ring notices, or sent none yet", tap.type_name))?;
        let name = nerve_stm::RingName::from_notice(&notice).map_err(|e| e.to_string())?;
        let reader = nerve_stm::RingReader::open(self.world.robot(), &name).map_err(|e| e.to_string())?;
        let path = std::env::temp_dir().join(format!("nerve-ui-{}.png", std::process::id()));
        let dumped = nerve_stm::dump_png(&reader, nerve_stm::FrameSelector::Latest, &path).map_err(|e| e.to_string());
        let png = dumped.and_then(|_| std::fs::read(&path).map_err(|e| e.to_string()));
        let _ = std::fs::remove_file(&path);
        png
    }

    fn kinds(&mut self) -> Vec<String> {
        crate::kinds::known_kinds()
    }

    fn tick(&mut self) {
        self.taps.retain(|_, t| t.asked.elapsed() < TAP_IDLE);
    }
}
