//! The bridge's configuration file (`--config FILE`, TOML, strict like launch
//! files): the Zenoh endpoints and the two lists of what crosses.
//!
//! ```toml
//! mode = "peer"                        # "peer" (default): robots link directly;
//!                                      # "client": through Zenoh routers (a fleet)
//! listen = ["tls/10.0.0.1:7447"]       # endpoints this bridge accepts peers on (peer mode only)
//! connect = ["tls/10.0.0.2:7447"]      # peers it dials (and re-dials after a cut); the routers in client mode
//! multicast_scouting = false           # find peers on the LAN by multicast (off by default)
//! queue = 256                          # default queue of a reliable export, messages
//! lease = "2s"                         # a silent link is declared lost after this
//! peers = ["r3"]                       # robots that may import our exports (besides those we import from)
//! importer_ttl = "10min"               # an importer gone this long is forgotten
//! insecure = false                     # allow tcp/ on a non-loopback address (no authentication)
//!
//! [tls]                                # mutual TLS with the fleet's certificates
//! keys = "/path/to/bridge-keys"        # `nerve bridge keys` directory (default: $NERVE_HOME/bridge-keys)
//! # ca = "...", cert = "...", key = "..." name the files one by one instead
//! #   (default KEYS/ca.crt, KEYS/<robot>.crt, KEYS/<robot>.key)
//!
//! [[export]]                           # a local output port sent to the peers
//! port = "t1/tick"                     # AGENT/PORT on this robot
//! type = "nerve::Tick"                 # its payload type
//! max_hz = 20.0                        # at most 20 messages a second (optional)
//!
//! [[export]]
//! port = "cmd/out"
//! type = "nerve::Scalar"
//! reliable = true                      # in order, kept while the link is down
//! queue = 64                           # overrides the default queue
//!
//! [[import]]                           # a remote port published here as a local output
//! port = "r1/t1/tick"                  # ROBOT/AGENT/PORT on the remote robot
//! type = "nerve::Tick"
//! as = "r1.t1.tick"                    # the local port name (this is the default)
//! ```
//!
//! Every problem is reported as `FILE:LINE: what, and what to do`, all of
//! them at once, before anything starts.
//!
//! Security (issue 40): an endpoint on a non-loopback address must be
//! `tls/` (mutual TLS, each robot known by its certificate's common name)
//! unless `insecure = true` says otherwise. With `[tls]`, every endpoint is
//! `tls/`. Relative paths are relative to the configuration file.

use serde::Deserialize;
use shm_schemas::names::validate_port_name;
use shm_schemas::{AgentName, RobotName};
use std::path::{Path, PathBuf};
use std::time::Duration;
use toml::Spanned;

mod security;
use security::check_endpoint;
pub use security::{KEYS_DIR_NAME, Tls, TlsFiles, default_keys_dir, is_loopback_endpoint};

/// Largest queue a reliable export may keep (messages).
pub const MAX_QUEUE: usize = 100_000;
/// Default queue of a reliable export (messages).
pub const DEFAULT_QUEUE: usize = 256;
/// Largest rate limit accepted (messages per second).
pub const MAX_HZ: f64 = 100_000.0;
/// The most elements of a sequence sample a topic carries when its entry
/// gives no `max_len`.
pub const DEFAULT_MAX_LEN: usize = 1024;
/// Default lease: a link silent for this long is declared lost.
pub const DEFAULT_LEASE: Duration = Duration::from_secs(2);
/// Default time after which an importer that left is forgotten.
pub const DEFAULT_IMPORTER_TTL: Duration = Duration::from_secs(600);

/// A configuration that could not be used; the message lists every problem.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read bridge config {path}: {source}")]
    Read {
        /// the file
        path: String,
        /// why
        #[source]
        source: std::io::Error,
    },
    /// The file has problems, each `FILE:LINE: what`.
    #[error("{}\n{} problem(s) in {path}; the bridge did not start", problems.join("\n"), problems.len())]
    Invalid {
        /// the file
        path: String,
        /// one line per problem
        problems: Vec<String>,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    #[serde(default)]
    mode: Option<Spanned<String>>,
    #[serde(default)]
    listen: Vec<Spanned<String>>,
    #[serde(default)]
    connect: Vec<Spanned<String>>,
    #[serde(default)]
    multicast_scouting: bool,
    #[serde(default)]
    queue: Option<Spanned<i64>>,
    #[serde(default)]
    lease: Option<Spanned<String>>,
    #[serde(default)]
    export: Vec<RawExport>,
    #[serde(default)]
    import: Vec<RawImport>,
    #[serde(default)]
    peers: Vec<Spanned<String>>,
    #[serde(default)]
    importer_ttl: Option<Spanned<String>>,
    #[serde(default)]
    insecure: bool,
    #[serde(default)]
    tls: Option<RawTls>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTls {
    #[serde(default)]
    keys: Option<String>,
    #[serde(default)]
    ca: Option<String>,
    #[serde(default)]
    cert: Option<String>,
    #[serde(default)]
    key: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExport {
    port: Spanned<String>,
    #[serde(rename = "type")]
    type_name: Spanned<String>,
    #[serde(default)]
    reliable: bool,
    #[serde(default)]
    max_hz: Option<Spanned<f64>>,
    #[serde(default)]
    queue: Option<Spanned<i64>>,
    #[serde(default)]
    max_len: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawImport {
    port: Spanned<String>,
    #[serde(rename = "type")]
    type_name: Spanned<String>,
    #[serde(default, rename = "as")]
    local: Option<Spanned<String>>,
    #[serde(default)]
    max_len: Option<Spanned<i64>>,
}

/// A local output port sent to the peers.
#[derive(Debug, Clone, PartialEq)]
pub struct Export {
    /// the exporting agent
    pub agent: String,
    /// its output port
    pub port: String,
    /// the payload type name
    pub type_name: String,
    /// delivered in order or reported lost (else best effort, newest wins)
    pub reliable: bool,
    /// rate limit, messages per second
    pub max_hz: Option<f64>,
    /// messages a reliable export keeps while no peer has acknowledged them
    pub queue: usize,
    /// a sequence type's most elements a sample sent may hold (`max_len`;
    /// `None`: [`DEFAULT_MAX_LEN`]); a longer sample is not sent, and counted
    pub max_len: Option<usize>,
}

impl Export {
    /// `AGENT/PORT`.
    pub fn origin(&self) -> String {
        format!("{}/{}", self.agent, self.port)
    }

    /// The bridge's input port that reads it: `AGENT.PORT`.
    pub fn input_name(&self) -> String {
        format!("{}.{}", self.agent, self.port)
    }
}

/// A remote port published as one of this bridge's output ports.
#[derive(Debug, Clone, PartialEq)]
pub struct Import {
    /// the remote robot
    pub robot: String,
    /// the remote agent
    pub agent: String,
    /// the remote output port
    pub port: String,
    /// the payload type name this bridge expects
    pub type_name: String,
    /// the local output port name
    pub local: String,
    /// a sequence type's most elements a sample received may hold
    /// (`max_len`; `None`: [`DEFAULT_MAX_LEN`]); a longer one is refused
    pub max_len: Option<usize>,
}

impl Import {
    /// `ROBOT/AGENT/PORT`.
    pub fn origin(&self) -> String {
        format!("{}/{}/{}", self.robot, self.agent, self.port)
    }
}

/// How the bridge's Zenoh session meets the others (`mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Robots link to each other directly (`listen` and `connect` name peers).
    #[default]
    Peer,
    /// Robots meet through one or more Zenoh routers (`connect` names them),
    /// so that a fleet is a star instead of a full mesh.
    Client,
}

impl Mode {
    /// Zenoh's name of the mode.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Peer => "peer",
            Mode::Client => "client",
        }
    }
}

/// A checked bridge configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// peer-to-peer or through routers
    pub mode: Mode,
    /// endpoints to listen on
    pub listen: Vec<String>,
    /// endpoints to connect to
    pub connect: Vec<String>,
    /// multicast scouting on the LAN
    pub multicast_scouting: bool,
    /// link lease
    pub lease: Duration,
    /// what leaves
    pub exports: Vec<Export>,
    /// what arrives
    pub imports: Vec<Import>,
    /// robots allowed to talk to this one: those named in `peers` and those imported from
    pub peers: Vec<String>,
    /// an importer gone this long is forgotten
    pub importer_ttl: Duration,
    /// plain TCP on a non-loopback address was allowed (`insecure = true`)
    pub insecure: bool,
    /// mutual TLS (`[tls]`)
    pub tls: Option<Tls>,
}

impl Config {
    /// Whether the link is open to unauthenticated peers beyond this host:
    /// `insecure = true` and a plain TCP endpoint on a non-loopback address.
    pub fn runs_insecure(&self) -> bool {
        self.tls.is_none() && self.listen.iter().chain(&self.connect).any(|e| !is_loopback_endpoint(e))
    }
}

fn line_of(src: &str, offset: usize) -> usize {
    src.as_bytes().iter().take(offset).filter(|&&b| b == b'\n').count() + 1
}

/// Reads and checks a configuration file. `known_type` says whether this
/// build of the bridge can carry a payload type.
pub fn load(path: &Path, known_type: &dyn Fn(&str) -> bool) -> Result<Config, ConfigError> {
    let src = std::fs::read_to_string(path)
        .map_err(|source| ConfigError::Read { path: path.display().to_string(), source })?;
    let mut cfg = parse(&src, &path.display().to_string(), known_type)?;
    // relative paths of [tls] are relative to the configuration file
    if let (Some(tls), Some(dir)) = (cfg.tls.as_mut(), path.parent()) {
        for p in [Some(&mut tls.keys), tls.ca.as_mut(), tls.cert.as_mut(), tls.key.as_mut()].into_iter().flatten() {
            if p.is_relative() {
                *p = dir.join(&*p);
            }
        }
    }
    Ok(cfg)
}

/// Checks a configuration given as text; `file` names it in messages.
pub fn parse(src: &str, file: &str, known_type: &dyn Fn(&str) -> bool) -> Result<Config, ConfigError> {
    let invalid = |problems: Vec<String>| ConfigError::Invalid { path: file.into(), problems };
    let raw: RawConfig = toml::from_str(src).map_err(|e| {
        let line = e.span().map(|s| line_of(src, s.start)).unwrap_or(1);
        invalid(vec![format!("{file}:{line}: {}", e.message())])
    })?;
    let mut problems = Vec::new();
    let mut at = |span: std::ops::Range<usize>, msg: String| {
        problems.push(format!("{file}:{}: {msg}", line_of(src, span.start)))
    };

    for ep in raw.listen.iter().chain(&raw.connect) {
        if let Err(e) = check_endpoint(ep.get_ref()) {
            at(ep.span(), e);
        } else if raw.tls.is_some() && !ep.get_ref().starts_with("tls/") {
            at(
                ep.span(),
                format!(
                    "endpoint {:?}: with [tls] every endpoint is tls/ (write tls/{})",
                    ep.get_ref(),
                    ep.get_ref().split_once('/').map_or("", |(_, a)| a)
                ),
            );
        } else if ep.get_ref().starts_with("tls/") && raw.tls.is_none() {
            at(
                ep.span(),
                format!(
                    "endpoint {:?} is tls/ but the config has no [tls] section; add [tls] (keys made by `nerve bridge keys init`)",
                    ep.get_ref()
                ),
            );
        } else if !raw.insecure && ep.get_ref().starts_with("tcp/") && !is_loopback_endpoint(ep.get_ref()) {
            at(
                ep.span(),
                format!(
                    "endpoint {:?} is plain TCP on a non-loopback address: any host that reaches it could read and forge this robot's topics; use tls/ with a [tls] section (see `nerve bridge keys`), or write `insecure = true` if the network itself is protected (WireGuard, a VLAN)",
                    ep.get_ref()
                ),
            );
        }
    }
    let mode = match raw.mode.as_ref().map(|m| (m.get_ref().as_str(), m.span())) {
        None | Some(("peer", _)) => Mode::Peer,
        Some(("client", span)) => {
            if raw.connect.is_empty() {
                at(
                    span.clone(),
                    "mode = \"client\" meets the fleet through Zenoh routers: name them in connect = [\"tcp/HOST:7447\"]".into(),
                );
            }
            if let Some(l) = raw.listen.first() {
                at(
                    l.span(),
                    "a bridge in client mode listens on nothing (the router does); remove listen, or use mode = \"peer\""
                        .into(),
                );
            }
            if raw.tls.is_some() {
                at(
                    span,
                    "mode = \"client\" with [tls] is not supported yet: through a router every message arrives on the router's TLS link, so this bridge cannot tell robots apart by certificate (access control would have to be the router's); use mode = \"peer\" for mutual TLS, or a protected network (WireGuard, a VLAN) with insecure = true".into(),
                );
            }
            Mode::Client
        }
        Some((other, span)) => {
            at(span, format!("mode {other:?}: write \"peer\" (robots link directly) or \"client\" (through routers)"));
            Mode::Peer
        }
    };
    let mut peers: Vec<String> = Vec::new();
    for p in &raw.peers {
        match RobotName::new(p.get_ref()) {
            Ok(_) if !peers.contains(p.get_ref()) => peers.push(p.get_ref().clone()),
            Ok(_) => {}
            Err(e) => at(p.span(), format!("peers: {e}")),
        }
    }
    let importer_ttl = match &raw.importer_ttl {
        Some(l) => match agent_sdk::clock::parse_duration(l.get_ref()) {
            Ok(d) if (Duration::from_secs(1)..=Duration::from_secs(7 * 24 * 3600)).contains(&d) => d,
            Ok(_) => {
                at(l.span(), "importer_ttl must be between 1s and 7 days (e.g. \"10min\")".into());
                DEFAULT_IMPORTER_TTL
            }
            Err(e) => {
                at(l.span(), format!("importer_ttl: {e}"));
                DEFAULT_IMPORTER_TTL
            }
        },
        None => DEFAULT_IMPORTER_TTL,
    };
    let tls = raw.tls.as_ref().map(|t| Tls {
        keys: t.keys.as_ref().map_or_else(default_keys_dir, PathBuf::from),
        ca: t.ca.as_ref().map(PathBuf::from),
        cert: t.cert.as_ref().map(PathBuf::from),
        key: t.key.as_ref().map(PathBuf::from),
    });
    let default_queue = match &raw.queue {
        Some(q) => match check_queue(*q.get_ref()) {
            Ok(n) => n,
            Err(e) => {
                at(q.span(), e);
                DEFAULT_QUEUE
            }
        },
        None => DEFAULT_QUEUE,
    };
    let lease = match &raw.lease {
        Some(l) => match agent_sdk::clock::parse_duration(l.get_ref()) {
            Ok(d) if (Duration::from_millis(100)..=Duration::from_secs(600)).contains(&d) => d,
            Ok(_) => {
                at(l.span(), "lease must be between 100ms and 600s".into());
                DEFAULT_LEASE
            }
            Err(e) => {
                at(l.span(), format!("lease: {e}"));
                DEFAULT_LEASE
            }
        },
        None => DEFAULT_LEASE,
    };

    let mut exports: Vec<Export> = Vec::new();
    for e in &raw.export {
        let Some((agent, port)) = e.port.get_ref().split_once('/').filter(|(_, p)| !p.contains('/')) else {
            at(
                e.port.span(),
                format!("export port {:?} must be written AGENT/PORT (a port of this robot)", e.port.get_ref()),
            );
            continue;
        };
        if let Err(err) = AgentName::new(agent) {
            at(e.port.span(), format!("export {}: {err}", e.port.get_ref()));
            continue;
        }
        if let Err(err) = validate_port_name(port) {
            at(e.port.span(), format!("export {}: {err}", e.port.get_ref()));
            continue;
        }
        if !known_type(e.type_name.get_ref()) {
            at(
                e.type_name.span(),
                format!(
                    "type {:?} is unknown to this bridge; check the spelling (e.g. nerve::Tick) or build a bridge that carries it",
                    e.type_name.get_ref()
                ),
            );
        }
        let max_hz = match &e.max_hz {
            Some(h) if !(h.get_ref().is_finite() && *h.get_ref() > 0.0 && *h.get_ref() <= MAX_HZ) => {
                at(h.span(), format!("max_hz must be a number above 0 and at most {MAX_HZ}"));
                None
            }
            Some(h) => Some(*h.get_ref()),
            None => None,
        };
        let queue = match &e.queue {
            Some(q) if !e.reliable => {
                at(q.span(), "queue applies to reliable exports only; add `reliable = true` or remove it".into());
                default_queue
            }
            Some(q) => check_queue(*q.get_ref()).unwrap_or_else(|msg| {
                at(q.span(), msg);
                default_queue
            }),
            None => default_queue,
        };
        let export = Export {
            agent: agent.into(),
            port: port.into(),
            type_name: e.type_name.get_ref().clone(),
            reliable: e.reliable,
            max_hz,
            queue,
            max_len: check_max_len(&e.max_len, e.type_name.get_ref(), &mut at),
        };
        if let Err(err) = validate_port_name(&export.input_name()) {
            at(
                e.port.span(),
                format!("export {}: the bridge's input for it would be {err}; use shorter names", e.port.get_ref()),
            );
            continue;
        }
        if exports.iter().any(|x| x.origin() == export.origin()) {
            at(e.port.span(), format!("export {} is listed twice", e.port.get_ref()));
            continue;
        }
        exports.push(export);
    }

    let mut imports: Vec<Import> = Vec::new();
    for i in &raw.import {
        let parts: Vec<&str> = i.port.get_ref().split('/').collect();
        let [robot, agent, port] = parts[..] else {
            at(
                i.port.span(),
                format!(
                    "import port {:?} must be written ROBOT/AGENT/PORT (a port of a remote robot)",
                    i.port.get_ref()
                ),
            );
            continue;
        };
        if let Err(err) = RobotName::new(robot) {
            at(i.port.span(), format!("import {}: {err}", i.port.get_ref()));
            continue;
        }
        if let Err(err) = AgentName::new(agent) {
            at(i.port.span(), format!("import {}: {err}", i.port.get_ref()));
            continue;
        }
        if let Err(err) = validate_port_name(port) {
            at(i.port.span(), format!("import {}: {err}", i.port.get_ref()));
            continue;
        }
        if !known_type(i.type_name.get_ref()) {
            at(
                i.type_name.span(),
                format!(
                    "type {:?} is unknown to this bridge; check the spelling (e.g. nerve::Tick) or build a bridge that carries it",
                    i.type_name.get_ref()
                ),
            );
        }
        let (local, span) = match &i.local {
            Some(l) => (l.get_ref().clone(), l.span()),
            None => (format!("{robot}.{agent}.{port}"), i.port.span()),
        };
        if let Err(err) = validate_port_name(&local) {
            at(span, format!("import {}: local port {err}; name it with `as = \"...\"`", i.port.get_ref()));
            continue;
        }
        let import = Import {
            robot: robot.into(),
            agent: agent.into(),
            port: port.into(),
            type_name: i.type_name.get_ref().clone(),
            local,
            max_len: check_max_len(&i.max_len, i.type_name.get_ref(), &mut at),
        };
        if imports.iter().any(|x| x.origin() == import.origin()) {
            at(i.port.span(), format!("import {} is listed twice", i.port.get_ref()));
            continue;
        }
        if imports.iter().any(|x| x.local == import.local) {
            at(
                span,
                format!(
                    "two imports would publish on the same local port {:?}; name one with `as = \"...\"`",
                    import.local
                ),
            );
            continue;
        }
        imports.push(import);
    }
    if exports.is_empty() && imports.is_empty() {
        at(0..0, "nothing crosses: list at least one [[export]] or [[import]]".into());
    }
    if !problems.is_empty() {
        return Err(invalid(problems));
    }
    for i in &imports {
        if !peers.contains(&i.robot) {
            peers.push(i.robot.clone());
        }
    }
    Ok(Config {
        mode,
        peers,
        importer_ttl,
        insecure: raw.insecure,
        tls,
        listen: raw.listen.into_iter().map(Spanned::into_inner).collect(),
        connect: raw.connect.into_iter().map(Spanned::into_inner).collect(),
        multicast_scouting: raw.multicast_scouting,
        lease,
        exports,
        imports,
    })
}

/// An entry's `max_len`: for a sequence type only, at least 1.
fn check_max_len(
    raw: &Option<Spanned<i64>>,
    type_name: &str,
    at: &mut impl FnMut(std::ops::Range<usize>, String),
) -> Option<usize> {
    let m = raw.as_ref()?;
    if !type_name.starts_with(SEQ_PREFIX) {
        at(
            m.span(),
            format!(
                "max_len applies to sequence types ({SEQ_PREFIX}...) only; {type_name} has a fixed size: remove it"
            ),
        );
        return None;
    }
    let n = usize::try_from(*m.get_ref()).ok().filter(|n| *n >= 1);
    if n.is_none() {
        at(m.span(), "max_len must be a number of elements of at least 1".into());
    }
    n
}

/// How the name of every sequence type starts (`shm_schemas::Schema::sequence`).
pub const SEQ_PREFIX: &str = "nerve::Seq<";

fn check_queue(q: i64) -> Result<usize, String> {
    usize::try_from(q)
        .ok()
        .filter(|n| (1..=MAX_QUEUE).contains(n))
        .ok_or_else(|| format!("queue must be between 1 and {MAX_QUEUE} messages"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn known(t: &str) -> bool {
        matches!(t, "nerve::Tick" | "nerve::Scalar")
    }

    fn problems(src: &str) -> Vec<String> {
        match parse(src, "b.toml", &known) {
            Err(ConfigError::Invalid { problems, .. }) => problems,
            other => panic!("expected problems, got {other:?}"),
        }
    }

    #[test]
    fn a_full_config_is_read() {
        let c = parse(
            r#"
listen = ["tcp/127.0.0.1:7447"]
connect = ["tcp/127.0.0.1:7448"]
queue = 32
lease = "3s"

[[export]]
port = "t1/tick"
type = "nerve::Tick"
max_hz = 20.0

[[export]]
port = "cmd/out"
type = "nerve::Scalar"
reliable = true
queue = 8

[[import]]
port = "r1/t1/tick"
type = "nerve::Tick"

[[import]]
port = "r1/cmd/out"
type = "nerve::Scalar"
as = "cmd"
"#,
            "b.toml",
            &known,
        )
        .expect("valid");
        assert_eq!(c.listen, vec!["tcp/127.0.0.1:7447"]);
        assert_eq!(c.mode, Mode::Peer, "peer mode unless asked for");
        assert!(!c.multicast_scouting, "scouting is off unless asked for");
        assert_eq!(c.lease, Duration::from_secs(3));
        assert_eq!(c.exports[0].input_name(), "t1.tick");
        assert_eq!((c.exports[0].reliable, c.exports[0].max_hz, c.exports[0].queue), (false, Some(20.0), 32));
        assert_eq!((c.exports[1].reliable, c.exports[1].queue), (true, 8));
        assert_eq!(c.imports[0].local, "r1.t1.tick");
        assert_eq!(c.imports[0].origin(), "r1/t1/tick");
        assert_eq!(c.imports[1].local, "cmd");
    }

    #[test]
    fn every_problem_is_reported_with_its_line() {
        let p = problems(
            r#"listen = ["udp/1.2.3.4:5"]
[[export]]
port = "t1"
type = "nerve::Tick"
[[export]]
port = "t1/tick"
type = "nerve::Tock"
max_hz = -1.0
[[import]]
port = "r1/t1/tick"
type = "nerve::Tick"
[[import]]
port = "r2/t1/tick"
type = "nerve::Tick"
as = "r1.t1.tick"
"#,
        );
        assert!(p[0].starts_with("b.toml:1: ") && p[0].contains("TCP and TLS only"), "{p:?}");
        assert!(p.iter().any(|l| l.starts_with("b.toml:3: ") && l.contains("AGENT/PORT")), "{p:?}");
        assert!(p.iter().any(|l| l.starts_with("b.toml:7: ") && l.contains("nerve::Tock")), "{p:?}");
        assert!(p.iter().any(|l| l.starts_with("b.toml:8: ") && l.contains("max_hz")), "{p:?}");
        assert!(p.iter().any(|l| l.starts_with("b.toml:15: ") && l.contains("same local port")), "{p:?}");
        assert_eq!(p.len(), 5, "{p:?}");
    }

    #[test]
    fn max_len_is_for_sequences_only() {
        let seq = "nerve::Seq<nerve::MapCell, nerve::MapHeader>";
        let src = format!(
            "[[export]]\nport = \"a/map\"\ntype = \"{seq}\"\nmax_len = 5000\n\
             [[import]]\nport = \"r1/a/map\"\ntype = \"{seq}\"\n"
        );
        let cfg = parse(&src, "b.toml", &|_| true).expect("valid");
        assert_eq!((cfg.exports[0].max_len, cfg.imports[0].max_len), (Some(5000), None));
        let src = format!(
            "[[export]]\nport = \"a/t\"\ntype = \"nerve::Tick\"\nmax_len = 3\n\
             [[import]]\nport = \"r1/a/map\"\ntype = \"{seq}\"\nmax_len = 0\n"
        );
        let Err(ConfigError::Invalid { problems: p, .. }) = parse(&src, "b.toml", &|_| true) else {
            panic!("max_len on a fixed type accepted")
        };
        assert!(p[0].contains("b.toml:4") && p[0].contains("nerve::Tick has a fixed size"), "{p:?}");
        assert!(p[1].contains("b.toml:8") && p[1].contains("at least 1"), "{p:?}");
    }

    #[test]
    fn unknown_keys_and_bad_queues_are_refused() {
        let p = problems("[[export]]\nport = \"a/b\"\ntype = \"nerve::Tick\"\nreliabel = true\n");
        assert!(p[0].starts_with("b.toml:4: ") && p[0].contains("reliabel"), "{p:?}");
        let p = problems("[[export]]\nport = \"a/b\"\ntype = \"nerve::Tick\"\nqueue = 3\n");
        assert!(p[0].contains("reliable exports only"), "{p:?}");
        let p = problems("queue = 0\n[[export]]\nport = \"a/b\"\ntype = \"nerve::Tick\"\n");
        assert!(p[0].starts_with("b.toml:1: ") && p[0].contains("between 1 and"), "{p:?}");
        let p = problems("listen = []\n");
        assert!(p[0].contains("nothing crosses"), "{p:?}");
    }

    const ONE: &str = "[[export]]\nport = \"t1/tick\"\ntype = \"nerve::Tick\"\n";

    #[test]
    fn plain_tcp_beyond_the_host_needs_insecure() {
        let p = problems(&format!("listen = [\"tcp/10.0.0.1:7447\"]\n{ONE}"));
        assert!(
            p[0].starts_with("b.toml:1: ") && p[0].contains("tcp/10.0.0.1:7447") && p[0].contains("insecure = true"),
            "{p:?}"
        );
        let p = problems(&format!("connect = [\"tcp/0.0.0.0:7447\"]\n{ONE}"));
        assert!(p[0].contains("use tls/"), "{p:?}");
        let c = parse(&format!("insecure = true\nlisten = [\"tcp/10.0.0.1:7447\"]\n{ONE}"), "b.toml", &known)
            .expect("insecure is allowed when written");
        assert!(c.insecure && c.runs_insecure());
        let c = parse(&format!("listen = [\"tcp/127.0.0.1:7447\"]\n{ONE}"), "b.toml", &known).expect("loopback");
        assert!(!c.runs_insecure() && c.tls.is_none());
    }

    #[test]
    fn tls_names_its_files_and_every_endpoint_is_tls() {
        let c = parse(
            &format!(
                "listen = [\"tls/10.0.0.1:7447\"]\npeers = [\"r3\"]\nimporter_ttl = \"1min\"\n{ONE}\
                 [[import]]\nport = \"r2/t1/tick\"\ntype = \"nerve::Tick\"\n[tls]\nkeys = \"/k\"\ncert = \"/c/me.crt\"\n"
            ),
            "b.toml",
            &known,
        )
        .expect("valid");
        assert_eq!(c.peers, vec!["r3", "r2"], "named peers, then the robots imported from");
        assert_eq!(c.importer_ttl, Duration::from_secs(60));
        let f = c.tls.as_ref().expect("tls").files("r1");
        assert_eq!(f.ca, PathBuf::from("/k/ca.crt"));
        assert_eq!(f.cert, PathBuf::from("/c/me.crt"));
        assert_eq!(f.key, PathBuf::from("/k/r1.key"));
        let e = f.check(None, c.tls.as_ref().expect("tls")).expect_err("no such files");
        assert!(e.contains("/k/ca.crt") && e.contains("nerve bridge keys init"), "{e}");
        let p = problems(&format!("listen = [\"tcp/127.0.0.1:7447\"]\n{ONE}[tls]\n"));
        assert!(p[0].starts_with("b.toml:1: ") && p[0].contains("every endpoint is tls/"), "{p:?}");
        let p = problems(&format!("listen = [\"tls/127.0.0.1:7447\"]\n{ONE}"));
        assert!(p[0].contains("no [tls] section"), "{p:?}");
        let p = problems(&format!("importer_ttl = \"0s\"\npeers = [\"a/b\"]\n{ONE}"));
        assert_eq!(p.len(), 2, "{p:?}");
    }

    #[test]
    fn client_mode_needs_a_router_and_listens_on_nothing() {
        let c = parse(&format!("mode = \"client\"\nconnect = [\"tcp/127.0.0.1:7447\"]\n{ONE}"), "b.toml", &known)
            .expect("client");
        assert_eq!(c.mode, Mode::Client);
        let p = problems(&format!("mode = \"client\"\n{ONE}"));
        assert!(p.len() == 1 && p[0].starts_with("b.toml:1:") && p[0].contains("connect"), "{p:?}");
        let p = problems(&format!(
            "mode = \"client\"\nconnect = [\"tcp/127.0.0.1:7447\"]\nlisten = [\"tcp/127.0.0.1:7448\"]\n{ONE}"
        ));
        assert!(p.len() == 1 && p[0].starts_with("b.toml:3:") && p[0].contains("listens on nothing"), "{p:?}");
        let p = problems(&format!("mode = \"client\"\nconnect = [\"tls/127.0.0.1:7447\"]\n{ONE}[tls]\n"));
        assert!(p.iter().any(|l| l.starts_with("b.toml:1:") && l.contains("not supported yet")), "{p:?}");
        let p = problems(&format!("mode = \"router\"\n{ONE}"));
        assert!(p.len() == 1 && p[0].contains("\"peer\"") && p[0].contains("\"client\""), "{p:?}");
    }
}
