//! `nerve ui`: the robot's live graph in a browser (the `nerve-ui` crate
//! serves the page; this module is its robot side).
//!
//! Every action goes through the router with the requests the matching
//! command sends (`connect`, `rate`, `param set`...), and hot add runs
//! `nerve start` itself, so the command line and the page always agree. The
//! page's port inspector subscribes to the port like `nerve echo` does
//! (zero copy, the publisher undisturbed) and lets go of the subscription
//! when nobody has asked for it for [`TAP_IDLE`].
//!
//! The tokens (review findings B3, B4) never come from the command line,
//! which every local user can read in `/proc/PID/cmdline`: they come from
//! `NERVE_UI_TOKEN` / `NERVE_UI_READ_TOKEN`, or from a file only its owner
//! can read (`--token-file`), or are made at random and printed once, on a
//! terminal only (never into a file or a log). Hot add starts only kinds
//! installed next to `nerve`, never a path.

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
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply};
use shm_schemas::ring::RingNotice;
use shm_schemas::schema::Kind;
use shm_schemas::{PortRef, Schema};
use std::collections::{BTreeMap, VecDeque};
use std::io::{IsTerminal as _, Write as _};
use std::net::SocketAddr;
use std::path::PathBuf;
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
    /// A file (mode 0600) holding the edit token on its first line and, optionally, the read token on
    /// its second (default: NERVE_UI_TOKEN and NERVE_UI_READ_TOKEN, else random ones printed at start).
    #[arg(long, value_name = "PATH")]
    pub token_file: Option<PathBuf>,
    /// Another name the page may be opened by (its `Host`), besides the bound address and localhost.
    #[arg(long, value_name = "NAME")]
    pub allow_host: Vec<String>,
    /// Seconds a connection may take to send its request (slow or idle clients are cut off).
    #[arg(long, default_value_t = 10.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub idle_timeout: f64,
    /// Refused: a token on the command line is readable by every local user.
    #[arg(long, hide = true)]
    pub token: Option<String>,
}

/// The environment variable of the edit token.
const TOKEN_ENV: &str = "NERVE_UI_TOKEN";
/// The environment variable of the read token.
const READ_TOKEN_ENV: &str = "NERVE_UI_READ_TOKEN";

/// The two tokens, and whether none was given (so that they must be shown).
struct Tokens {
    edit: String,
    read: String,
    made: bool,
}

/// A given token, checked.
fn checked(token: String, from: &str) -> Result<String> {
    match nerve_ui::token_problem(&token) {
        None => Ok(token),
        Some(why) => anyhow::bail!(
            "the token from {from} is not usable: {why}; give 16 to 256 characters of A-Z, a-z, 0-9, '-', '.', '_', \
             '~' (or leave it out for a random one)"
        ),
    }
}

/// The tokens from `--token-file`, else the environment, else random.
fn tokens(a: &UiArgs) -> Result<Tokens> {
    if a.token.is_some() {
        anyhow::bail!(
            "--token is no longer accepted: a token on the command line is readable by every local user \
             (ps, /proc/PID/cmdline), so consider this one known to others. Give the token in {TOKEN_ENV} \
             (and the read token in {READ_TOKEN_ENV}), or in a file only you can read with --token-file PATH, \
             or leave it out for a random one"
        );
    }
    let (mut edit, mut read) = (None, None);
    if let Some(path) = &a.token_file {
        let (e, r) = token_file(path)?;
        let from = format!("--token-file {}", path.display());
        edit = Some(checked(e, &from)?);
        read = r.map(|r| checked(r, &from)).transpose()?;
    } else {
        if let Ok(t) = std::env::var(TOKEN_ENV) {
            edit = Some(checked(t, TOKEN_ENV)?);
        }
        if let Ok(t) = std::env::var(READ_TOKEN_ENV) {
            read = Some(checked(t, READ_TOKEN_ENV)?);
        }
    }
    // a token made here is of use only if it can be shown; with none given, one must be
    let made = edit.is_none() && read.is_none();
    let new = || nerve_ui::new_token().context("cannot make a token from /dev/urandom");
    let edit = match edit {
        Some(t) => t,
        None => new()?,
    };
    let read = match read {
        Some(t) => t,
        None => new()?,
    };
    if edit == read {
        anyhow::bail!("the edit token and the read token are the same: give two different tokens");
    }
    Ok(Tokens { edit, read, made })
}

/// Reads `--token-file`: refused unless only its owner (this user) can read it.
fn token_file(path: &std::path::Path) -> Result<(String, Option<String>)> {
    use std::io::Read as _;
    use std::os::unix::fs::MetadataExt as _;
    let file = std::fs::File::open(path).with_context(|| format!("cannot open the token file {}", path.display()))?;
    let meta = file.metadata().with_context(|| format!("cannot read the token file {}", path.display()))?;
    if meta.mode() & 0o077 != 0 {
        anyhow::bail!(
            "the token file {} can be read by other users (mode {:o}): make it yours alone with `chmod 600 {}`, \
             and consider the tokens in it known",
            path.display(),
            meta.mode() & 0o777,
            path.display()
        );
    }
    let me = nix::unistd::geteuid().as_raw();
    if meta.uid() != me {
        anyhow::bail!(
            "the token file {} belongs to uid {}, not to this user (uid {me}): use a file of your own",
            path.display(),
            meta.uid()
        );
    }
    let mut text = String::new();
    file.take(4096)
        .read_to_string(&mut text)
        .with_context(|| format!("cannot read the token file {} (is it text?)", path.display()))?;
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let edit = lines.next().map(str::to_owned).with_context(|| {
        format!("the token file {} is empty: write the edit token on its first line", path.display())
    })?;
    Ok((edit, lines.next().map(str::to_owned)))
}

/// Whether the address keeps the page to this machine.
fn is_loopback(addr: &SocketAddr) -> bool {
    addr.ip().is_loopback()
}

/// A port subscription unused this long is dropped.
const TAP_IDLE: Duration = Duration::from_secs(10);
/// Samples kept per inspected port.
const KEPT: usize = 100;
/// Elements of a sequence sample kept and sent to the page, at most: its
/// first ones (and its last, for `items[-1].x`). A 40,000-cell map stays a
/// table a browser draws at once, and one `/api/samples` answer holds at
/// most [`KEPT`] × (this + 1) elements.
const SEQ_ROWS: usize = 50;

pub fn ui(world: &World, a: UiArgs) -> Result<ExitCode> {
    if !(0.05..=10.0).contains(&a.interval) {
        anyhow::bail!("--interval {} is out of range: give 0.05 to 10 seconds", a.interval);
    }
    if !(0.1..=600.0).contains(&a.idle_timeout) {
        anyhow::bail!("--idle-timeout {} is out of range: give 0.1 to 600 seconds", a.idle_timeout);
    }
    let tokens = tokens(&a)?;
    let terminal = std::io::stdout().is_terminal();
    if tokens.made && !terminal {
        anyhow::bail!(
            "nerve ui's output is not a terminal, so a token made here would be written into a file or a log: \
             give the tokens in {TOKEN_ENV} and {READ_TOKEN_ENV}, or in a file with --token-file PATH (mode 0600)"
        );
    }
    if !is_loopback(&a.bind) {
        let warning = format!(
            "WARNING: --bind {} serves the robot over plain HTTP (no TLS): the tokens, the camera and every action \
             cross the network unencrypted, readable and replayable by anyone on the way. Prefer the default \
             127.0.0.1 and an SSH tunnel (ssh -L 8080:127.0.0.1:8080 ROBOT); remote browsers also need \
             --allow-host with the name or address they use",
            a.bind
        );
        tracing::warn!(bind = %a.bind, "nerve ui serves a non-loopback address over plain HTTP");
        eprintln!("{warning}");
    }
    let opts = Options {
        bind: a.bind,
        read_only: a.read_only,
        interval: Duration::from_secs_f64(a.interval),
        token: tokens.edit.clone(),
        read_token: tokens.read.clone(),
        robot: world.robot().as_str().to_owned(),
        max_clients: 16,
        max_connections: 32,
        idle_timeout: Duration::from_secs_f64(a.idle_timeout),
        write_timeout: nerve_ui::WRITE_TIMEOUT,
        allowed_hosts: a.allow_host.clone(),
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
        let mode = if a.read_only { " (read-only)" } else { "" };
        if terminal {
            // the tokens go to the terminal only, once
            let (first, what) = if a.read_only {
                (&tokens.read, "(the address carries the read token: it lets the page watch)")
            } else {
                (&tokens.edit, "(the address carries the edit token: it lets the page change the robot)")
            };
            say(format!("nerve ui of robot {robot_name}{mode}: http://{addr}/?token={first}"));
            say(what.into());
            if !a.read_only {
                say(format!("to watch only: http://{addr}/?token={}", tokens.read));
            }
        } else {
            say(format!("nerve ui of robot {robot_name}{mode}: http://{addr}/"));
            say(format!("(open it with ?token= and the token given in {TOKEN_ENV}, {READ_TOKEN_ENV} or --token-file)"));
        }
        say("press Ctrl-C to stop".into());
    };
    nerve_ui::serve(&opts, &mut robot, &mut listening, &interrupt::requested)?;
    say("nerve ui stopped".into());
    Ok(ExitCode::SUCCESS)
}

/// Why the page may not start `kind`, if it may not: only kinds installed
/// next to `nerve`, never a path (the server checks the same first).
fn kind_refused(kind: &str) -> Option<String> {
    if kind.contains('/') {
        return Some(format!(
            "the page starts only agent kinds installed next to nerve, not paths ({kind:?}); start a program \
             by its path with `nerve start PATH` on the robot"
        ));
    }
    let known = crate::kinds::known_kinds();
    if !known.iter().any(|k| k == kind) {
        return Some(format!("unknown agent kind {kind:?}: the kinds this robot knows are {}", known.join(", ")));
    }
    None
}

/// An inspected output port.
struct Tap {
    raw: RawPort,
    type_name: String,
    schema: Option<Schema>,
    kept: VecDeque<Value>,
    /// the most elements a sample of this (sequence) port had since the page looked
    longest: usize,
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
        crate::client::call_kept(&mut self.session, &self.world, req)
    }

    fn ok(&mut self, req: CliRequest) -> Result<Value, String> {
        match self.call(req)? {
            RouterReply::Ok => Ok(json!({ "ok": true })),
            other => Err(format!("unexpected reply from the router: {other:?}")),
        }
    }

    /// `nerve start KIND --name NAME`, run as a command so that it is the same start-up.
    fn start(&self, kind: &str, name: &str) -> Result<Value, String> {
        if let Some(why) = kind_refused(kind) {
            return Err(why);
        }
        let exe = std::env::current_exe().map_err(|e| format!("cannot find the nerve program: {e}"))?;
        let out = Command::new(exe)
            .args(["--robot", self.world.robot().as_str(), "start", kind, "--name", name])
            // the agent has no use for the page's tokens
            .env_remove(TOKEN_ENV)
            .env_remove(READ_TOKEN_ENV)
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
        if let Some(why) = kind_refused(&kind) {
            return Err(format!("{name} cannot be restarted from the page: {why}"));
        }
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
                longest: 0,
                latest: Vec::new(),
                asked: Instant::now(),
            };
            self.taps.insert(port.to_owned(), tap);
        }
        let tap = self.taps.get_mut(port).ok_or("the subscription is gone")?;
        tap.asked = Instant::now();
        let (kept, latest, longest, schema) = (&mut tap.kept, &mut tap.latest, &mut tap.longest, &tap.schema);
        tap.raw
            .receive(|h, bytes| {
                let mut sample = json!({ "seq": h.seq, "stamp_ns": h.stamp_ns });
                match schema.as_ref() {
                    Some(s) => {
                        let shown = page_sample(s, bytes, &mut sample);
                        *longest = (*longest).max(shown.unwrap_or(0));
                    }
                    None => sample["value"] = json!({ "bytes": bytes.len() }),
                }
                kept.push_back(sample);
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

/// Fills `sample` with what the page shows of a sample's `bytes`, decoded
/// with the port's schema as `nerve echo` does: its `value`; for a sequence
/// also its `len` (elements) and `last` element (`null` when empty), with
/// `value.items` cut to the first [`SEQ_ROWS`]. Returns the sequence's length.
fn page_sample(schema: &Schema, bytes: &[u8], sample: &mut Value) -> Option<usize> {
    let Some(shape) = schema.sequence_shape() else {
        sample["value"] = match schema.decode(bytes) {
            Ok(v) => serde_json::to_value(v).unwrap_or(Value::Null),
            Err(e) => json!({ "undecodable": e.to_string() }),
        };
        return None;
    };
    let Some(len) = shape.count_of(bytes.len()) else {
        sample["value"] = json!({ "undecodable": format!(
            "a {}-byte sample is not a {}-byte header and whole {}-byte elements of {}",
            bytes.len(), shape.items_at, shape.element, schema.type_name
        ) });
        return None;
    };
    // the decoder of echo, over the header and the first elements only
    let first = shape.len_of(len.min(SEQ_ROWS)).and_then(|end| bytes.get(..end)).unwrap_or_default();
    sample["value"] = match schema.decode(first) {
        Ok(v) => serde_json::to_value(v).unwrap_or(Value::Null),
        Err(e) => json!({ "undecodable": e.to_string() }),
    };
    let last = len.checked_sub(1).and_then(|i| schema.decode_path(&format!("items[{i}]"), bytes));
    sample["len"] = json!(len);
    sample["last"] = serde_json::to_value(last).unwrap_or(Value::Null);
    Some(len)
}

/// The most columns of a sequence's element table.
const SEQ_COLUMNS: usize = 20;

/// The paths of `schema`'s numbers, bools and strings in declaration order,
/// named as the page flattens a decoded value (`pose.x`, `ranges.3`), at
/// most [`SEQ_COLUMNS`]; `""` for an element that is one number.
fn leaf_paths(schema: &Schema, prefix: &str, out: &mut Vec<String>) {
    let join = |name: &str| if prefix.is_empty() { name.to_owned() } else { format!("{prefix}.{name}") };
    match &schema.kind {
        Kind::Struct { fields } => fields.iter().for_each(|f| leaf_paths(&f.schema, &join(&f.name), out)),
        Kind::Array { len, element } => {
            (0..*len).take(SEQ_COLUMNS).for_each(|i| leaf_paths(element, &join(&i.to_string()), out));
        }
        Kind::Sequence { .. } => {}
        Kind::Primitive { .. } | Kind::String { .. } => out.push(prefix.to_owned()),
    }
    out.truncate(SEQ_COLUMNS);
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
        // a sequence port: how many of its elements a sample shows, its longest yet, and
        // its element's fields in declaration order (a JSON object's keys lose it)
        let sequence = match tap.schema.as_ref().map(|s| &s.kind) {
            Some(Kind::Sequence { element, .. }) => {
                let mut columns = Vec::new();
                leaf_paths(element, "", &mut columns);
                Some(json!({ "rows": SEQ_ROWS, "longest": tap.longest, "columns": columns }))
            }
            _ => None,
        };
        Ok(json!({
            "port": port,
            "type_name": tap.type_name,
            "image": tap.type_name == <RingNotice as shm_schemas::Payload>::stable_type_name(),
            "sequence": sequence,
            "samples": samples,
        }))
    }

    fn image(&mut self, port: &str) -> Result<Vec<u8>, String> {
        let tap = self.tap(port)?;
        let notice = RingNotice::from_bytes(&tap.latest)
            .ok_or_else(|| format!("{port} carries {}, not ring notices, or sent none yet", tap.type_name))?;
        let name = nerve_stm::RingName::from_notice(&notice).map_err(|e| e.to_string())?;
        let reader = nerve_stm::RingReader::open(self.world.robot(), &name).map_err(|e| e.to_string())?;
        // in memory: no file another user could pre-create or read (B11)
        let (_, png) = nerve_stm::encode_png(&reader, nerve_stm::FrameSelector::Latest).map_err(|e| e.to_string())?;
        Ok(png)
    }

    fn kinds(&mut self) -> Vec<String> {
        crate::kinds::known_kinds()
    }

    fn tick(&mut self) {
        self.taps.retain(|_, t| t.asked.elapsed() < TAP_IDLE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::payloads::Tick;
    use shm_schemas::{Described as _, Seq};

    /// A `Seq<Tick, Tick>` sample: header `{seq: 7}`, element `i` `{seq: i, stamp_ns: 2i}`.
    fn ticks(n: u64) -> Vec<u8> {
        let mut b = [7u64, 0].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>();
        for i in 0..n {
            b.extend(i.to_le_bytes());
            b.extend((2 * i).to_le_bytes());
        }
        b
    }

    #[test]
    fn a_sequence_sample_is_its_header_length_first_rows_and_last() {
        let s = Seq::<Tick, Tick>::schema();
        for n in [0u64, 1, 50, 51, 40_000] {
            let mut sample = json!({});
            assert_eq!(page_sample(&s, &ticks(n), &mut sample), Some(n as usize));
            assert_eq!(sample["len"], json!(n));
            assert_eq!(sample["value"]["header"]["seq"], json!(7), "{sample}");
            let items = sample["value"]["items"].as_array().expect("items");
            assert_eq!(items.len(), (n as usize).min(SEQ_ROWS), "{n}");
            match n.checked_sub(1) {
                Some(i) => assert_eq!(sample["last"], json!({ "seq": i, "stamp_ns": 2 * i })),
                None => assert_eq!(sample["last"], Value::Null),
            }
        }
        // bytes that are not a header and whole elements: said, not shown
        let mut sample = json!({});
        let mut odd = ticks(2);
        odd.pop();
        assert_eq!(page_sample(&s, &odd, &mut sample), None);
        assert!(sample["value"]["undecodable"].as_str().is_some_and(|e| e.contains("whole 16-byte elements")));
        // a fixed type: decoded whole, no length
        let mut sample = json!({});
        assert_eq!(page_sample(&Tick::schema(), &ticks(0), &mut sample), None);
        assert_eq!(sample["value"], json!({ "seq": 7, "stamp_ns": 0 }));
        assert!(sample.get("len").is_none());
    }

    #[test]
    fn an_elements_columns_are_its_fields_in_order_and_bounded() {
        let mut cols = Vec::new();
        leaf_paths(&Tick::schema(), "", &mut cols);
        assert_eq!(cols, ["seq", "stamp_ns"]);
        let mut cols = Vec::new();
        leaf_paths(&f32::schema(), "", &mut cols);
        assert_eq!(cols, [""]);
        let mut cols = Vec::new();
        leaf_paths(&<[u8; 100]>::schema(), "", &mut cols);
        assert_eq!(cols.len(), SEQ_COLUMNS);
        assert_eq!((cols[0].as_str(), cols[19].as_str()), ("0", "19"));
    }
}
