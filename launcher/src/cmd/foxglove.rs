//! `nerve foxglove`: the robot, live, in Foxglove and Lichtblick (the
//! `nerve-foxglove` crate serves the Foxglove WebSocket protocol; this
//! module is its robot side).
//!
//! Channels are the output ports the router lists, each with a JSON Schema
//! made from the schema its agent registered (`nerve_recording::json`, the
//! one `nerve export --json` writes), so a user's own types are readable. A
//! subscribed port is read like `nerve echo` reads it ([`RawPort`]: zero
//! copy, the publisher undisturbed) and let go when nobody subscribes.
//! Parameters, the connection graph and publishing go through the router
//! with the requests `nerve param`, `nerve graph` and `nerve pub` send, so
//! its bounds and refusals are the same.
//!
//! Services agents offer are Foxglove services, found and called in
//! [`services`] as `nerve call` calls them.
//!
//! The edit token (parameter changes, publishing, calls) never comes from the
//! command line: from `NERVE_FOXGLOVE_TOKEN`, or made at random and printed
//! on a terminal only; with neither, nobody may change the robot.

use crate::client::{RouterSession, cli_node};
use crate::interrupt;
use agent_sdk::World;
use agent_sdk::clock::{now_ns, unix_now_ns};
use agent_sdk::ports::port_event;
use agent_sdk::raw_port::{RawOutput, RawPort};
use agent_sdk::world::Ipc;
use anyhow::{Context as _, Result};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::FileDescriptorBased as _;
use iceoryx2::prelude::Node;
use nerve_foxglove::protocol::Parameter;
use nerve_foxglove::{CallDone, ChannelSpec, GraphSpec, Interest, Options, Robot, ServiceSpec, wait_fds};
use nerve_recording::foxglove::{
    IMAGE_SUFFIX, RAW_IMAGE, RawImage, encoding_of, mapping_of, raw_image_json, raw_image_json_schema,
    velocity_from_twist,
};
use serde_json::{Value, json};
use shm_schemas::control::cli_to_router::{AgentView, CliRequest, RouterReply};
use shm_schemas::encode::encode_json;
use shm_schemas::ring::RingNotice;
use shm_schemas::{PortRef, Schema};
use std::collections::{BTreeMap, BTreeSet};
use std::io::{IsTerminal as _, Write as _};
use std::net::SocketAddr;
use std::os::fd::RawFd;
use std::process::ExitCode;
use std::time::Duration;

mod services;

/// `nerve foxglove`
#[derive(Debug, clap::Args)]
pub struct FoxgloveArgs {
    /// Address to serve on; 127.0.0.1 keeps the robot to this machine (port 0: any free port).
    #[arg(long, default_value = "127.0.0.1:8765")]
    pub bind: SocketAddr,
    /// Watch only: no client may set parameters or publish, token or not.
    #[arg(long)]
    pub read_only: bool,
    /// Let clients with the edit token publish into input ports (Foxglove's Teleop and Publish panels).
    #[arg(long, conflicts_with = "read_only")]
    pub publish: bool,
    /// A web origin besides loopback ones whose pages may connect (e.g. https://app.foxglove.dev).
    #[arg(long, value_name = "ORIGIN")]
    pub allow_origin: Vec<String>,
    /// Messages queued per client before the oldest are dropped (a slow client loses them, the robot never waits).
    #[arg(long, default_value_t = 1024)]
    pub queue: usize,
    /// Seconds a client may take nothing while messages wait before it is disconnected.
    #[arg(long, default_value_t = 10.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub stall_timeout: f64,
    /// Seconds a service call a client makes waits for its answer.
    #[arg(long, default_value_t = 2.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub call_timeout: f64,
}

/// How long the first message into an input waits for the agent to take the new port.
const FIRST_DELIVERY: Duration = Duration::from_secs(1);

/// The environment variable of the edit token.
const TOKEN_ENV: &str = "NERVE_FOXGLOVE_TOKEN";

/// The edit token, and whether it was made here (so that it must be shown).
fn token(read_only: bool) -> Result<Option<(String, bool)>> {
    if read_only {
        return Ok(None);
    }
    if let Ok(t) = std::env::var(TOKEN_ENV) {
        if let Some(why) = nerve_ui::token_problem(&t) {
            anyhow::bail!(
                "the token in {TOKEN_ENV} is not usable: {why}; give 16 to 256 characters of A-Z, a-z, 0-9, '-', \
                 '.', '_', '~' (or leave it out for a random one)"
            );
        }
        return Ok(Some((t, false)));
    }
    if !std::io::stdout().is_terminal() {
        // a token made here would land in a file or a log: none, so nobody may change the robot
        return Ok(None);
    }
    Ok(Some((nerve_ui::new_token().context("cannot make a token from /dev/urandom")?, true)))
}

pub fn foxglove(world: &World, a: FoxgloveArgs) -> Result<ExitCode> {
    if a.queue == 0 || a.queue > 1_000_000 {
        anyhow::bail!("--queue {} is out of range: give 1 to 1000000 messages", a.queue);
    }
    if !(0.1..=3600.0).contains(&a.stall_timeout) {
        anyhow::bail!("--stall-timeout {} is out of range: give 0.1 to 3600 seconds", a.stall_timeout);
    }
    if !(0.01..=600.0).contains(&a.call_timeout) {
        anyhow::bail!("--call-timeout {} is out of range: give 0.01 to 600 seconds", a.call_timeout);
    }
    let token = token(a.read_only)?;
    if !a.bind.ip().is_loopback() {
        tracing::warn!(bind = %a.bind, "nerve foxglove serves a non-loopback address without TLS");
        eprintln!(
            "WARNING: --bind {} serves the robot over plain WebSocket (no TLS): the token, the samples and every \
             change cross the network unencrypted. Prefer the default 127.0.0.1 and an SSH tunnel \
             (ssh -L 8765:127.0.0.1:8765 ROBOT)",
            a.bind
        );
    }
    let mut opts = Options::new(a.bind, world.robot().as_str());
    opts.read_only = a.read_only;
    opts.publish = a.publish;
    opts.token = token.as_ref().map(|(t, _)| t.clone());
    opts.allowed_origins = a.allow_origin.clone();
    opts.queue = a.queue;
    opts.stall_timeout = Duration::from_secs_f64(a.stall_timeout);
    opts.call_timeout = Duration::from_secs_f64(a.call_timeout);
    let node = cli_node(world)?;
    let mut robot = FoxRobot {
        world: world.clone(),
        node,
        session: None,
        taps: BTreeMap::new(),
        outputs: BTreeMap::new(),
        warned: BTreeSet::new(),
        rings: BTreeMap::new(),
        services: services::Services::new(world),
        agents_seen: None,
    };
    interrupt::catch();
    let say = |text: String| {
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "{text}").and_then(|()| out.flush());
    };
    let robot_name = world.robot().as_str().to_owned();
    let mut listening = |addr: SocketAddr| {
        let mode = if a.read_only { " (read-only)" } else { "" };
        say(format!("nerve foxglove of robot {robot_name}{mode}: ws://{addr} (open it in Foxglove or Lichtblick)"));
        match &token {
            Some((t, true)) => say(format!(
                "to set parameters, call services{}: ws://{addr}/?token={t}",
                if a.publish { " and publish" } else { "" }
            )),
            Some((_, false)) => {
                say(format!("to set parameters and call services: ws://{addr}/?token= and the token in {TOKEN_ENV}"))
            }
            None if !a.read_only => say(format!("no token: nobody may change the robot (give one in {TOKEN_ENV})")),
            None => {}
        }
        say("press Ctrl-C to stop".into());
    };
    let stats = nerve_foxglove::serve(&opts, &mut robot, &mut listening, &interrupt::requested)?;
    robot.detach_all();
    say(format!(
        "nerve foxglove stopped: {} client(s) served, {} refused, {} message(s) dropped for slow clients, {} \
         client(s) disconnected for not reading",
        stats.clients, stats.refused, stats.dropped_messages, stats.dropped_clients
    ));
    Ok(ExitCode::SUCCESS)
}

/// A subscribed output port.
struct Tap {
    raw: RawPort,
    /// the port's event, notified on every sample: the serving thread sleeps on it
    listener: Listener<Ipc>,
    schema: Schema,
}

/// An input port a client publishes into, through a port of this process
/// attached to it.
struct Output {
    from: PortRef,
    to: PortRef,
    raw: RawOutput,
    schema: Schema,
    /// the offset of a top-level `stamp_ns` the JSON may leave out
    stamp_at: Option<usize>,
    /// a message reached the input
    delivered: bool,
}

/// The robot as Foxglove sees it.
struct FoxRobot {
    world: World,
    node: Node<Ipc>,
    /// opened on first use, and again after the router did not answer
    session: Option<RouterSession>,
    taps: BTreeMap<String, Tap>,
    outputs: BTreeMap<String, Output>,
    /// ports already reported as unreadable
    warned: BTreeSet<String>,
    /// the short-term-memory rings of image channels, by name
    rings: BTreeMap<String, nerve_stm::RingReader>,
    services: services::Services,
    /// the agents [`Robot::channels`] was told, for the [`Robot::services`] that follows it
    agents_seen: Option<Vec<AgentView>>,
}

/// The frame a ring notice announces, as a `foxglove.RawImage` in JSON;
/// `None` for a ring of raw data or one that cannot be read (logged).
fn image_of(
    robot: &shm_schemas::RobotName,
    rings: &mut BTreeMap<String, nerve_stm::RingReader>,
    notice: &[u8],
    unix_ns: u64,
) -> Option<Vec<u8>> {
    let notice = RingNotice::from_bytes(notice)?;
    let name = nerve_stm::RingName::from_notice(&notice).ok()?;
    let key = name.to_string();
    if !rings.contains_key(&key) {
        match nerve_stm::RingReader::open(robot, &name) {
            Ok(r) => {
                rings.insert(key.clone(), r);
            }
            Err(e) => {
                tracing::debug!(ring = %key, "cannot open the ring: {e}");
                return None;
            }
        }
    }
    let reader = rings.get(&key)?;
    let r = reader.read_with(notice.seq, |meta, data| {
        let format = meta.format()?;
        let (encoding, bpp) = encoding_of(format)?;
        let converted;
        let data = if format == nerve_stm::PixelFormat::Hsi8 {
            converted = nerve_stm::hsi8_to_rgb8(data);
            &converted[..]
        } else {
            data
        };
        let step = meta.width.checked_mul(bpp)?;
        let len = usize::try_from(u64::from(step) * u64::from(meta.height)).ok()?;
        let img = RawImage {
            unix_ns,
            frame_id: &key,
            width: meta.width,
            height: meta.height,
            encoding,
            step,
            data: data.get(..len)?,
        };
        serde_json::to_vec(&raw_image_json(&img)).ok()
    });
    match r {
        Ok(v) => v,
        Err(e) => {
            // overwritten before it was read (a slow reader), or the ring was made anew
            tracing::debug!(ring = %key, seq = notice.seq, "frame not read: {e}");
            rings.remove(&key);
            None
        }
    }
}

/// `/<agent>/<port>` as a port reference.
fn port_of(topic: &str) -> Result<PortRef, String> {
    let path = topic.strip_prefix('/').ok_or_else(|| format!("{topic:?} is not /AGENT/PORT"))?;
    path.parse::<PortRef>().map_err(|e| format!("{topic:?} is not /AGENT/PORT: {e}"))
}

/// A channel's topic as the port it reads (`/<agent>/<port>`) and the
/// suffix of a mapping (`/<agent>/<port>/tf`), if it is one.
fn split_mapped(topic: &str) -> (&str, Option<&str>) {
    match topic.rsplit_once('/') {
        Some((base, suffix)) if base.matches('/').count() == 2 => (base, Some(suffix)),
        _ => (topic, None),
    }
}

/// A parameter's text as the JSON value of its type.
fn typed(type_name: &str, text: &str) -> Value {
    let number =
        matches!(type_name, "f32" | "f64" | "u8" | "u16" | "u32" | "u64" | "usize" | "i8" | "i16" | "i32" | "i64");
    match (type_name, text.parse::<f64>(), text.parse::<bool>()) {
        ("bool", _, Ok(b)) => json!(b),
        (_, Ok(x), _) if number && x.is_finite() => {
            if let Ok(i) = text.parse::<i64>() {
                json!(i)
            } else {
                json!(x)
            }
        }
        _ => json!(text),
    }
}

/// A parameter's JSON value as the text `nerve param set` takes.
fn text_of(value: &Value) -> Result<String, String> {
    match value {
        Value::String(s) => Ok(s.clone()),
        Value::Number(n) => Ok(n.to_string()),
        Value::Bool(b) => Ok(b.to_string()),
        other => Err(format!("nerve's parameters are numbers, booleans or text, not {other}")),
    }
}

impl FoxRobot {
    fn call(&mut self, req: CliRequest) -> Result<RouterReply, String> {
        crate::client::call_kept(&mut self.session, &self.world, req)
    }

    fn agents(&mut self) -> Result<Vec<AgentView>, String> {
        match self.call(CliRequest::Ps)? {
            RouterReply::Agents(a) => Ok(a),
            other => Err(format!("unexpected reply from the router: {other:?}")),
        }
    }

    fn open_tap(&mut self, topic: &str, agents: &[AgentView]) -> Result<Tap, String> {
        let port = port_of(topic)?;
        let agent = agents.iter().find(|a| a.name == port.agent.as_str()).ok_or("its agent is gone")?;
        let spec = agent.outputs.iter().find(|o| o.name == port.port).ok_or("the agent has no such output")?;
        let schema = agent.schema_for(spec.fingerprint).ok_or("its agent registered no schema for it")?;
        let service = self.world.robot().port_service(port.agent.as_str(), &port.port);
        let raw = RawPort::open(&self.node, &service).map_err(|e| format!("cannot subscribe: {e}"))?;
        let listener = port_event(&self.node, &service)
            .map_err(|e| format!("cannot wait for its samples: {e}"))?
            .listener_builder()
            .create()
            .map_err(|e| format!("cannot wait for its samples: {e:?}"))?;
        Ok(Tap { raw, listener, schema })
    }

    /// Sends `bytes` again until the input takes it, at most [`FIRST_DELIVERY`].
    fn first_delivery(&mut self, topic: &str, bytes: &[u8], stamp_at: Option<usize>) -> Result<(), String> {
        let o = self.outputs.get_mut(topic).ok_or("the channel was not advertised")?;
        let t0 = std::time::Instant::now();
        while t0.elapsed() < FIRST_DELIVERY {
            std::thread::sleep(Duration::from_millis(5));
            let mut loan = o.raw.loan(false).map_err(|e| e.to_string())?;
            loan.bytes_mut().copy_from_slice(bytes);
            if let Some(at) = stamp_at
                && let Some(slot) = loan.bytes_mut().get_mut(at..at.saturating_add(8))
            {
                slot.copy_from_slice(&now_ns().to_le_bytes());
            }
            if o.raw.send_loan_counted(loan).map_err(|e| e.to_string())? > 0 {
                return Ok(());
            }
        }
        Err(format!("{} did not subscribe within {FIRST_DELIVERY:?}; is it running (`nerve ps`)?", o.to))
    }

    fn detach_all(&mut self) {
        let outputs = std::mem::take(&mut self.outputs);
        for o in outputs.values() {
            if let Err(e) = self.call(CliRequest::Detach { from: o.from.clone(), to: o.to.clone() }) {
                tracing::warn!(from = %o.from, to = %o.to, "could not detach: {e}; the router removes it when this process has exited");
            }
        }
    }
}

impl Robot for FoxRobot {
    fn channels(&mut self) -> Result<Vec<ChannelSpec>, String> {
        let agents = self.agents()?;
        let agents = &*self.agents_seen.insert(agents);
        let mut out = Vec::new();
        for a in agents {
            for o in &a.outputs {
                let topic = format!("/{}/{}", a.name, o.name);
                match a.schema_for(o.fingerprint) {
                    Some(s) => {
                        // a pose or a scan also as Foxglove's own schema, for the 3D panel
                        if o.type_name == <RingNotice as shm_schemas::Payload>::stable_type_name() {
                            out.push(ChannelSpec {
                                topic: format!("{topic}/{IMAGE_SUFFIX}"),
                                schema_name: RAW_IMAGE.to_owned(),
                                schema: raw_image_json_schema().to_string(),
                            });
                        }
                        if let Some(m) = mapping_of(&o.type_name) {
                            out.push(ChannelSpec {
                                topic: format!("{topic}/{}", m.suffix),
                                schema_name: m.schema_name.to_owned(),
                                schema: m.json_schema().to_string(),
                            });
                        }
                        out.push(ChannelSpec {
                            topic,
                            schema_name: o.type_name.clone(),
                            schema: nerve_recording::json::json_schema(&s).to_string(),
                        });
                    }
                    None => {
                        if self.warned.insert(topic.clone()) {
                            tracing::warn!(%topic, type_name = %o.type_name, "not advertised: its agent registered no schema for it");
                        }
                    }
                }
            }
        }
        Ok(out)
    }

    fn wait(&mut self, also: &[RawFd], timeout: Duration) {
        let mut fds: Vec<(RawFd, Interest)> = also.iter().map(|&fd| (fd, Interest::Read)).collect();
        for tap in self.taps.values() {
            // SAFETY: the descriptor is only handed to poll(2) below, while `tap` (and so its
            // listener, which owns the descriptor) is borrowed; it is neither kept nor closed
            fds.push((unsafe { tap.listener.file_descriptor().native_handle() }, Interest::Read));
        }
        if let Err(e) = wait_fds(&fds, timeout) {
            tracing::warn!(error = %e, "cannot wait for the ports' events: sleeping instead");
            std::thread::sleep(timeout.min(Duration::from_millis(5)));
        }
        // the events are taken before the samples are read, so that one sent after the read wakes the next wait
        for tap in self.taps.values() {
            let _ = tap.listener.try_wait(|_| {});
        }
    }

    fn read(&mut self, topics: &[&str], sink: &mut dyn FnMut(&str, u64, Vec<u8>)) {
        // each port read, and the channels of it asked for: its own (no suffix) or a mapping's
        let mut wanted: BTreeMap<String, Vec<(&str, Option<&str>)>> = BTreeMap::new();
        for t in topics {
            let (base, suffix) = split_mapped(t);
            wanted.entry(base.to_owned()).or_default().push((t, suffix));
        }
        self.taps.retain(|t, _| wanted.contains_key(t));
        let missing: Vec<String> = wanted.keys().filter(|t| !self.taps.contains_key(*t)).cloned().collect();
        if !missing.is_empty() {
            let agents = self.agents().unwrap_or_default();
            for topic in missing {
                match self.open_tap(&topic, &agents) {
                    Ok(tap) => {
                        self.warned.remove(&topic);
                        self.taps.insert(topic, tap);
                    }
                    Err(e) => {
                        if self.warned.insert(topic.clone()) {
                            tracing::warn!(%topic, "cannot read: {e}");
                        }
                    }
                }
            }
        }
        // the robot's clock to the wall clock, as Foxglove's timestamps are
        let offset = i128::from(unix_now_ns()) - i128::from(now_ns());
        let robot = self.world.robot().clone();
        let rings = &mut self.rings;
        for (topic, tap) in &self.taps {
            let Some(channels) = wanted.get(topic) else { continue };
            let mapping = mapping_of(&tap.schema.type_name);
            let r = tap.raw.receive(|h, bytes| {
                let value = match tap.schema.decode(bytes) {
                    Ok(v) => serde_json::to_value(&v).unwrap_or(Value::Null),
                    Err(e) => json!({ "undecodable": e.to_string() }),
                };
                let unix = u64::try_from(i128::from(h.stamp_ns).saturating_add(offset)).unwrap_or(0);
                for (channel, suffix) in channels {
                    let out = match suffix {
                        None => serde_json::to_vec(&value).ok(),
                        Some(IMAGE_SUFFIX) => image_of(&robot, rings, bytes, unix),
                        Some(sx) => mapping
                            .filter(|m| m.suffix == *sx)
                            .and_then(|m| m.convert(&value, unix))
                            .and_then(|v| serde_json::to_vec(&v).ok()),
                    };
                    if let Some(out) = out {
                        sink(channel, unix, out);
                    }
                }
                true
            });
            if let Err(e) = r {
                tracing::debug!(%topic, "cannot read: {e}");
            }
        }
    }

    fn graph(&mut self) -> Result<GraphSpec, String> {
        let view = match self.call(CliRequest::Graph)? {
            RouterReply::Graph(g) => g,
            other => return Err(format!("unexpected reply from the router: {other:?}")),
        };
        let mut g = GraphSpec::default();
        for a in &view.agents {
            for o in &a.outputs {
                g.published.push((format!("/{}/{}", a.name, o.name), vec![a.name.clone()]));
            }
        }
        let mut fed: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for c in &view.connections {
            let agent = c.to.split('/').next().unwrap_or(&c.to).to_owned();
            fed.entry(format!("/{}", c.from)).or_default().insert(agent);
        }
        g.subscribed = fed.into_iter().map(|(t, s)| (t, s.into_iter().collect())).collect();
        Ok(g)
    }

    fn parameters(&mut self) -> Result<Vec<Parameter>, String> {
        let names: Vec<String> = self.agents()?.into_iter().map(|a| a.name).collect();
        let mut out = Vec::new();
        for name in names {
            // an agent that left between the two questions has no parameters
            if let Ok(RouterReply::Params(list)) = self.call(CliRequest::ParamList { name: name.clone() }) {
                for p in list {
                    out.push(Parameter { name: format!("/{name}/{}", p.key), value: typed(&p.type_name, &p.value) });
                }
            }
        }
        Ok(out)
    }

    fn set_parameter(&mut self, name: &str, value: &Value) -> Result<(), String> {
        let (agent, key) = name
            .strip_prefix('/')
            .and_then(|n| n.split_once('/'))
            .ok_or_else(|| format!("{name:?} is not /AGENT/KEY"))?;
        let value = text_of(value)?;
        match self.call(CliRequest::ParamSet { name: agent.to_owned(), key: key.to_owned(), value })? {
            RouterReply::Ok => Ok(()),
            other => Err(format!("unexpected reply from the router: {other:?}")),
        }
    }

    fn input(&mut self, topic: &str) -> Result<String, String> {
        if let Some(o) = self.outputs.get(topic) {
            return Ok(o.schema.type_name.clone());
        }
        let to = port_of(topic)?;
        let session = crate::client::kept_session(&mut self.session, &self.world)?;
        let (schema, fingerprint) = super::publish::input_schema(session, &to).map_err(|e| format!("{e:#}"))?;
        let from = PortRef::new(&format!("foxglove-{}", std::process::id()), &to.port).map_err(|e| e.to_string())?;
        let service = self.world.robot().port_service(from.agent.as_str(), &to.port);
        let raw = RawOutput::create(&self.node, &service, &schema, fingerprint, "foxglove")
            .map_err(|e| format!("cannot make a port to publish on: {e}"))?;
        let attach = CliRequest::Attach {
            from: from.clone(),
            pid: std::process::id(),
            type_name: schema.type_name.clone(),
            fingerprint,
            to: to.clone(),
        };
        match self.call(attach)? {
            RouterReply::Ok => {}
            other => return Err(format!("unexpected reply from the router: {other:?}")),
        }
        let stamp_at = super::publish::auto_stamp(&schema, &json!({}));
        let type_name = schema.type_name.clone();
        self.outputs.insert(topic.to_owned(), Output { from, to, raw, schema, stamp_at, delivered: false });
        Ok(type_name)
    }

    fn publish(&mut self, topic: &str, payload: &[u8]) -> Result<(), String> {
        let o = self.outputs.get_mut(topic).ok_or("the channel was not advertised")?;
        let mut value: Value = serde_json::from_slice(payload).map_err(|e| format!("not JSON: {e}"))?;
        // Foxglove's Teleop panel sends a geometry_msgs/Twist: a velocity command's speed and turn rate
        if o.schema.type_name == "nerve::VelocityCommand"
            && let Some(v) = velocity_from_twist(&value)
        {
            value = v;
        }
        let stamp_at = o.stamp_at.filter(|_| value.get("stamp_ns").is_none());
        let bytes = encode_json(&o.schema, &value, &|p| p == "stamp_ns" && stamp_at.is_some())
            .map_err(|e| format!("{} takes {}: {e}", o.to, o.schema.type_name))?;
        let mut loan = o.raw.loan(false).map_err(|e| e.to_string())?;
        let b = loan.bytes_mut();
        if b.len() != bytes.len() {
            return Err(format!("{} bytes encoded for a {}-byte port", bytes.len(), b.len()));
        }
        b.copy_from_slice(&bytes);
        if let Some(at) = stamp_at
            && let Some(slot) = b.get_mut(at..at.saturating_add(8))
        {
            slot.copy_from_slice(&now_ns().to_le_bytes());
        }
        let receivers = o.raw.send_loan_counted(loan).map_err(|e| e.to_string())?;
        if receivers == 0 && !o.delivered {
            // the agent subscribes to a new port a moment after the router attached it: the first
            // message waits for it (bounded), so that it is not lost
            self.first_delivery(topic, &bytes, stamp_at)?;
        }
        if let Some(o) = self.outputs.get_mut(topic) {
            o.delivered = true;
        }
        Ok(())
    }

    fn services(&mut self) -> Result<Vec<ServiceSpec>, String> {
        // the server asks for the services right after the channels: the same answer of the router
        let agents = match self.agents_seen.take() {
            Some(a) => a,
            None => self.agents()?,
        };
        Ok(self.services.specs(&self.node, &agents))
    }

    fn call_service(&mut self, name: &str, request: &[u8], timeout: Duration, done: CallDone) {
        self.services.call(name, request, timeout, done);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameters_are_typed_by_their_declared_type() {
        assert_eq!(typed("f64", "0.5"), json!(0.5));
        assert_eq!(typed("u32", "20"), json!(20));
        assert_eq!(typed("bool", "true"), json!(true));
        assert_eq!(typed("String", "12"), json!("12"));
        assert_eq!(typed("figure", "3 of 4"), json!("3 of 4"));
        assert_eq!(text_of(&json!(2.5)).as_deref(), Ok("2.5"));
        assert_eq!(text_of(&json!(false)).as_deref(), Ok("false"));
        assert!(text_of(&json!([1])).is_err());
    }

    #[test]
    fn topics_are_agent_and_port() {
        let p = port_of("/ticker/tick").expect("topic");
        assert_eq!((p.agent.as_str(), p.port.as_str()), ("ticker", "tick"));
        assert!(port_of("ticker/tick").is_err());
        assert_eq!(split_mapped("/odometry/pose"), ("/odometry/pose", None));
        assert_eq!(split_mapped("/odometry/pose/tf"), ("/odometry/pose", Some("tf")));
    }
}
