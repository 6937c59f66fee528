//! The Zenoh side of the bridge: one session, in peer mode (no Zenoh router)
//! or as a client of the fleet's routers (`mode = "client"`),
//! the publishers and subscribers of the topics, the liveliness tokens that
//! tell who is there, and the acknowledgements of reliable topics.
//!
//! Keys (robot, agent and port names never contain `/`, `*`, `$` or `?`):
//!
//! | key | what |
//! |---|---|
//! | `nerve/<robot>/<agent>/<port>` | the data frames of an exported port |
//! | `nerve-ack/<robot>/<agent>/<port>/<me-robot>/<me-name>` | acknowledgements of a reliable topic, to its sender |
//! | `nerve-importer/<robot>/<agent>/<port>/<me-robot>/<me-name>` | liveliness: bridge `<me>` imports that port |
//! | `nerve-bridge/<robot>/<name>` | liveliness: a bridge is up (the peers figure) |
//!
//! Every key a robot writes carries its own name, so that access control
//! can tie it to the robot's certificate. With `[tls]` the session speaks
//! mutual TLS only, and Zenoh's access control lets each peer robot (known
//! by its certificate's common name) put only its own data frames that this
//! robot imports, and its own acknowledgements and importer tokens of this
//! robot's exports; anything else, and any other peer, is denied (see
//! [`acl_json`]). Frames larger than the largest carried sample (a
//! sequence's: its header and `max_len` elements) are refused at the link
//! (`transport/link/rx/max_message_size`).
//!
//! Zenoh runs its own threads. They are started from the link thread, which
//! first drops real-time scheduling, so that Zenoh's runtime never competes
//! with the robot's real-time tasks.

use crate::config::{Config, Mode, TlsFiles};
use crate::topics::{ExportTopic, ImportTopic, Reply, Transmit};
use crate::wire;
use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use zenoh::Wait;
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;

/// Why the link could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// Zenoh refused the configuration.
    #[error("zenoh configuration {key}: {detail}")]
    Config {
        /// the configuration key
        key: &'static str,
        /// what zenoh said
        detail: String,
    },
    /// The session could not be opened (a listen endpoint in use, say).
    #[error("cannot open the zenoh session (listen {listen:?}): {detail}; is another bridge listening there?")]
    Open {
        /// the listen endpoints
        listen: Vec<String>,
        /// what zenoh said
        detail: String,
    },
    /// A client's session reached none of its routers.
    #[error(
        "no Zenoh router answered at {routers:?} within 10 s: {detail}; start the fleet's router there first (e.g. `nerve-ros2-router --listen ENDPOINT`)"
    )]
    NoRouter {
        /// the `connect` endpoints
        routers: Vec<String>,
        /// what zenoh said
        detail: String,
    },
    /// A publisher, subscriber or token could not be declared.
    #[error("zenoh refused to declare {what} {key}: {detail}")]
    Declare {
        /// publisher, subscriber, token
        what: &'static str,
        /// its key
        key: String,
        /// what zenoh said
        detail: String,
    },
}

fn json_list(v: &[String]) -> String {
    let items: Vec<String> = v.iter().map(|s| format!("{s:?}")).collect();
    format!("[{}]", items.join(","))
}

/// The largest frame header (`wire::encode_frame`: magic, version, flags,
/// name length, a type name of at most 256 bytes, the payload length, six
/// u64 fields, the sender's name of at most 255 bytes).
pub const MAX_FRAME_HEADER: usize = 4 + 1 + 1 + 2 + crate::wire::MAX_TYPE_NAME + 4 + 6 * 8 + 1 + 255;
/// Room for Zenoh's own message header on top of a frame.
const ZENOH_SLACK: usize = 4096;

/// The largest message the link accepts for payloads of at most
/// `max_payload` bytes: one frame, plus Zenoh's header.
pub fn max_message_size(max_payload: usize) -> usize {
    max_payload.saturating_add(MAX_FRAME_HEADER).saturating_add(ZENOH_SLACK)
}

/// Zenoh's access control for `robot` (a JSON5 value for `access_control`):
/// default deny; for each peer robot `P` (its certificate's common name),
/// allowed in: puts of `nerve/P/..` for each port imported from `P`, and of
/// `nerve-ack/<robot>/<export>/P/*`; subscriptions to this robot's exports
/// and to `P`'s own acknowledgements; `P`'s importer tokens of this robot's
/// exports and its presence token; liveliness subscriptions and queries of
/// its own importers and of presences. Out to a peer: anything.
pub fn acl_json(cfg: &Config, robot: &str) -> String {
    let list = |v: Vec<String>| json_list(&v);
    let mut rules = vec![format!(
        "{{id: \"out\", messages: [\"put\", \"delete\", \"declare_subscriber\", \"query\", \"reply\", \"declare_queryable\", \"liveliness_token\", \"declare_liveliness_subscriber\", \"liveliness_query\"], flows: [\"egress\"], permission: \"allow\", key_exprs: [\"**\"]}}"
    )];
    let mut subjects = Vec::new();
    let mut policies = Vec::new();
    let exports: Vec<String> = cfg.exports.iter().map(|e| format!("{}/{}", e.agent, e.port)).collect();
    for (n, p) in cfg.peers.iter().enumerate() {
        let mut ids = Vec::new();
        let mut rule = |what: &str, messages: &[&str], keys: Vec<String>| {
            if keys.is_empty() {
                return;
            }
            let id = format!("p{n}-{what}");
            let messages: Vec<String> = messages.iter().map(|m| (*m).to_string()).collect();
            rules.push(format!(
                "{{id: {id:?}, messages: {}, flows: [\"ingress\"], permission: \"allow\", key_exprs: {}}}",
                json_list(&messages),
                list(keys)
            ));
            ids.push(id);
        };
        let mut puts: Vec<String> = cfg
            .imports
            .iter()
            .filter(|i| &i.robot == p)
            .map(|i| format!("nerve/{}/{}/{}", i.robot, i.agent, i.port))
            .collect();
        puts.extend(exports.iter().map(|e| format!("nerve-ack/{robot}/{e}/{p}/*")));
        rule("put", &["put"], puts);
        let mut subs: Vec<String> = exports.iter().map(|e| format!("nerve/{robot}/{e}")).collect();
        subs.push(format!("nerve-ack/{p}/**"));
        rule("sub", &["declare_subscriber"], subs);
        let mut tokens: Vec<String> = exports.iter().map(|e| format!("nerve-importer/{robot}/{e}/{p}/*")).collect();
        tokens.push(format!("nerve-bridge/{p}/*"));
        rule("token", &["liveliness_token", "reply"], tokens);
        rule(
            "live",
            &["declare_liveliness_subscriber", "liveliness_query"],
            vec![format!("nerve-importer/{p}/**"), "nerve-bridge/**".into()],
        );
        ids.push("out".into());
        subjects.push(format!("{{id: \"robot-{n}\", cert_common_names: [{p:?}]}}"));
        policies.push(format!("{{rules: {}, subjects: [\"robot-{n}\"]}}", json_list(&ids)));
    }
    format!(
        "{{enabled: true, default_permission: \"deny\", rules: [{}], subjects: [{}], policies: [{}]}}",
        rules.join(", "),
        subjects.join(", "),
        policies.join(", ")
    )
}

/// The bridge's Zenoh configuration without TLS, access control or a
/// message limit (for a plain Zenoh peer beside a bridge: the raw Zenoh
/// benchmark); a bridge itself uses [`session_config`].
pub fn zenoh_config(cfg: &Config) -> Result<zenoh::Config, LinkError> {
    let mut z = session_config(cfg, "", None, 0)?;
    z.insert_json5("transport/link/rx/max_message_size", "1073741824")
        .map_err(|e| LinkError::Config { key: "transport/link/rx/max_message_size", detail: e.to_string() })?;
    Ok(z)
}

fn path_json(p: &std::path::Path) -> String {
    format!("{:?}", p.display().to_string())
}

/// The link lease Zenoh is given, in real milliseconds, for a configured
/// `lease` on a robot whose clock runs `scale` times as fast as real time
/// (1 on the wall clock): the configured lease is in the robot's seconds,
/// simulated ones on simulated time (issue 46), so that a cut link is
/// noticed after the same simulated time at any scale. Zenoh's keep-alive
/// runs on the machine's clock: a simulator that holds its clock while the
/// machine is slow does not hold the lease. Never under 100 ms, Zenoh's
/// floor for a lease that still lets its keep-alives through.
pub fn link_lease_ms(lease: std::time::Duration, scale: f64) -> u64 {
    let scale = if scale.is_finite() && scale > 0.0 { scale } else { 1.0 };
    let ms = lease.as_secs_f64() * 1000.0 / scale;
    (ms as u64).max(100)
}

/// The Zenoh configuration of a bridge: peer mode, the given endpoints,
/// multicast scouting only when asked, a short lease so that a cut is
/// noticed quickly, and quick re-dialling of `connect` endpoints. With
/// `tls` (the files of this robot): TLS links only, mutual authentication
/// against the fleet CA, and [`acl_json`]. Messages above
/// [`max_message_size`]`(max_payload)` are refused at the link.
pub fn session_config(
    cfg: &Config,
    robot: &str,
    tls: Option<&TlsFiles>,
    max_payload: usize,
) -> Result<zenoh::Config, LinkError> {
    let mut z = zenoh::Config::default();
    let lease_ms = link_lease_ms(cfg.lease, agent_sdk::simclock::scale());
    let mut settings: Vec<(&'static str, String)> = vec![
        ("mode", format!("{:?}", cfg.mode.as_str())),
        ("listen/endpoints", json_list(&cfg.listen)),
        ("connect/endpoints", json_list(&cfg.connect)),
        ("scouting/multicast/enabled", cfg.multicast_scouting.to_string()),
        ("scouting/gossip/enabled", "true".into()),
        // a peer dials in the background for ever (a peer that is not up
        // yet, or comes back after a cut), retrying every 0.2 s growing to 1 s
        ("connect/retry", "{period_init_ms: 200, period_max_ms: 1000, period_increase_factor: 2}".into()),
        ("listen/exit_on_failure", "true".into()),
        // a client's session opens once it reaches a router: give up after
        // 10 s with an error that names the routers (the agent's start
        // fails loudly); once up, it re-dials a lost router by itself
        ("connect/timeout_ms", if cfg.mode == Mode::Client { "10000" } else { "-1" }.into()),
        ("connect/exit_on_failure", (cfg.mode == Mode::Client).to_string()),
        ("transport/link/tx/lease", lease_ms.to_string()),
        ("transport/link/tx/keep_alive", "4".into()),
        ("transport/link/rx/max_message_size", max_message_size(max_payload).to_string()),
    ];
    if let Some(t) = tls {
        settings.extend([
            ("transport/link/protocols", "[\"tls\"]".to_string()),
            ("transport/link/tls/root_ca_certificate", path_json(&t.ca)),
            ("transport/link/tls/listen_certificate", path_json(&t.cert)),
            ("transport/link/tls/listen_private_key", path_json(&t.key)),
            ("transport/link/tls/connect_certificate", path_json(&t.cert)),
            ("transport/link/tls/connect_private_key", path_json(&t.key)),
            ("transport/link/tls/enable_mtls", "true".into()),
            // a robot is known by its certificate's common name (checked by
            // the access control), not by the address it is reached at
            ("transport/link/tls/verify_name_on_connect", "false".into()),
            ("transport/link/tls/close_link_on_expiration", "true".into()),
            ("access_control", acl_json(cfg, robot)),
        ]);
    }
    for (key, value) in settings {
        z.insert_json5(key, &value).map_err(|e| LinkError::Config { key, detail: e.to_string() })?;
    }
    Ok(z)
}

struct Put {
    publisher: zenoh::pubsub::Publisher<'static>,
}

impl Transmit for Put {
    fn send(&self, bytes: &[u8]) -> bool {
        self.publisher.put(bytes.to_vec()).wait().is_ok()
    }
}

/// The peers this bridge sees: other bridges' liveliness, `ROBOT/NAME`.
#[derive(Debug, Default)]
pub struct Peers {
    names: Mutex<BTreeSet<String>>,
}

impl Peers {
    /// The peers seen now, sorted.
    pub fn names(&self) -> Vec<String> {
        self.names.lock().unwrap_or_else(|p| p.into_inner()).iter().cloned().collect()
    }

    fn set(&self, name: &str, up: bool) {
        let mut n = self.names.lock().unwrap_or_else(|p| p.into_inner());
        let changed = if up { n.insert(name.into()) } else { n.remove(name) };
        if changed {
            tracing::info!(peer = name, "peer bridge {}", if up { "connected" } else { "lost" });
        }
    }
}

/// An open link: dropping it undeclares everything and closes the session.
pub struct Link {
    session: zenoh::Session,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    _tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link").field("zid", &self.session.zid()).finish()
    }
}

/// Who this bridge is: its robot and agent name.
#[derive(Debug, Clone)]
pub struct Me {
    /// the robot
    pub robot: String,
    /// the bridge agent's name
    pub name: String,
}

impl Me {
    /// `ROBOT.NAME`, how importers are known to senders.
    pub fn importer_id(&self) -> String {
        format!("{}.{}", self.robot, self.name)
    }
}

fn declare_err(what: &'static str, key: &str, e: impl std::fmt::Display) -> LinkError {
    LinkError::Declare { what, key: key.into(), detail: e.to_string() }
}

impl Link {
    /// Opens the session and declares every topic. Call from a thread that
    /// is not real-time (Zenoh's threads inherit its scheduling).
    pub fn open(
        cfg: &Config,
        me: &Me,
        exports: &[Arc<ExportTopic>],
        imports: &[Arc<ImportTopic>],
        peers: &Arc<Peers>,
        now_mono: fn() -> u64,
    ) -> Result<Link, LinkError> {
        let tls = cfg.tls.as_ref().map(|t| t.files(&me.robot));
        if tls.is_some() {
            // before Zenoh builds its rustls configs on the process's provider
            crate::cipher::prefer_aes_128();
        }
        let max_payload = exports
            .iter()
            .map(|t| t.info.max_payload())
            .chain(imports.iter().map(|t| t.info.max_payload()))
            .max()
            .unwrap_or(0);
        let session = zenoh::open(session_config(cfg, &me.robot, tls.as_ref(), max_payload)?).wait().map_err(|e| {
            match cfg.mode {
                Mode::Peer => LinkError::Open { listen: cfg.listen.clone(), detail: e.to_string() },
                Mode::Client => LinkError::NoRouter { routers: cfg.connect.clone(), detail: e.to_string() },
            }
        })?;
        let mut subscribers = Vec::new();
        let mut tokens = Vec::new();

        // exports: a publisher each; acknowledgements and importers' tokens for all of them
        for t in exports {
            let publisher = session
                .declare_publisher(t.key.clone())
                .congestion_control(CongestionControl::Drop)
                .express(true)
                .wait()
                .map_err(|e| declare_err("publisher", &t.key, e))?;
            t.attach(Box::new(Put { publisher }));
        }
        if !exports.is_empty() {
            let by_key = exports.to_vec();
            let ack_key = format!("nerve-ack/{}/**", me.robot);
            let acks = by_key.clone();
            let ack_prefix = format!("nerve-ack/{}/", me.robot);
            let sub = session
                .declare_subscriber(ack_key.clone())
                .callback(move |s| {
                    // nerve-ack/<robot>/<agent>/<port>/<importer robot>/<importer name>
                    let key = s.key_expr().as_str();
                    let Some(rest) = key.strip_prefix(&ack_prefix) else { return };
                    let parts: Vec<&str> = rest.split('/').collect();
                    let [agent, port, robot, name] = parts[..] else { return };
                    let Some(t) = acks.iter().find(|t| t.spec.agent == agent && t.spec.port == port) else { return };
                    let bytes = s.payload().to_bytes();
                    match wire::decode_ack(&bytes) {
                        // the key (which the access control ties to the
                        // importer's certificate) must name the importer the frame names
                        Ok(a) if a.importer.split_once('.') == Some((robot, name)) => t.ack(&a, now_mono()),
                        Ok(a) => t.refuse_ack(key, a.importer),
                        Err(e) => tracing::warn!(key, "an acknowledgement was refused: {e}"),
                    }
                })
                .wait()
                .map_err(|e| declare_err("subscriber", &ack_key, e))?;
            subscribers.push(sub);
            let imp_key = format!("nerve-importer/{}/**", me.robot);
            let prefix = format!("nerve-importer/{}/", me.robot);
            let sub = session
                .liveliness()
                .declare_subscriber(imp_key.clone())
                .history(true)
                .callback(move |s| {
                    // nerve-importer/<robot>/<agent>/<port>/<importer robot>/<importer name>
                    let Some(rest) = s.key_expr().as_str().strip_prefix(&prefix) else { return };
                    let parts: Vec<&str> = rest.split('/').collect();
                    let [agent, port, robot, name] = parts[..] else { return };
                    if let Some(t) = by_key.iter().find(|t| t.spec.agent == agent && t.spec.port == port) {
                        t.set_importer(&format!("{robot}.{name}"), s.kind() == SampleKind::Put, now_mono());
                    }
                })
                .wait()
                .map_err(|e| declare_err("liveliness subscriber", &imp_key, e))?;
            subscribers.push(sub);
        }

        // imports: a subscriber and an importer token each; acknowledgements go back on nerve-ack
        for t in imports {
            let ack_key = ack_key_of(&t.key, me);
            let ack_pub = session
                .declare_publisher(ack_key.clone())
                .congestion_control(CongestionControl::Drop)
                .express(true)
                .wait()
                .map_err(|e| declare_err("publisher", &ack_key, e))?;
            let topic = t.clone();
            let who = me.importer_id();
            let sub = session
                .declare_subscriber(t.key.clone())
                .callback(move |s| {
                    let bytes = s.payload().to_bytes();
                    if let Reply::Ack { instance, acked } = topic.receive(&bytes, now_mono()) {
                        let ack = wire::encode_ack(&wire::Ack { instance, acked, importer: &who });
                        if let Err(e) = ack_pub.put(ack).wait() {
                            tracing::debug!(topic = %topic.spec.origin(), "acknowledgement not sent: {e}");
                        }
                    }
                })
                .wait()
                .map_err(|e| declare_err("subscriber", &t.key, e))?;
            subscribers.push(sub);
            let token_key =
                format!("nerve-importer/{}/{}/{}/{}/{}", t.spec.robot, t.spec.agent, t.spec.port, me.robot, me.name);
            let token = session
                .liveliness()
                .declare_token(token_key.clone())
                .wait()
                .map_err(|e| declare_err("token", &token_key, e))?;
            tokens.push(token);
        }

        // presence: who else is there
        let mine = format!("{}/{}", me.robot, me.name);
        let key = format!("nerve-bridge/{mine}");
        tokens.push(session.liveliness().declare_token(key.clone()).wait().map_err(|e| declare_err("token", &key, e))?);
        let peers = peers.clone();
        let sub = session
            .liveliness()
            .declare_subscriber("nerve-bridge/**")
            .history(true)
            .callback(move |s| {
                let Some(who) = s.key_expr().as_str().strip_prefix("nerve-bridge/") else { return };
                if who != mine {
                    peers.set(who, s.kind() == SampleKind::Put);
                }
            })
            .wait()
            .map_err(|e| declare_err("liveliness subscriber", "nerve-bridge/**", e))?;
        subscribers.push(sub);
        tracing::info!(zid = %session.zid(), listen = ?cfg.listen, connect = ?cfg.connect, mode = cfg.mode.as_str(), "zenoh session open");
        Ok(Link { session, _subscribers: subscribers, _tokens: tokens })
    }

    /// Closes the session (peers see this bridge's tokens go at once).
    pub fn close(self) {
        let Link { session, _subscribers, _tokens } = self;
        drop(_subscribers);
        drop(_tokens);
        if let Err(e) = session.close().wait() {
            tracing::debug!("zenoh session close: {e}");
        }
    }
}

/// The key on which importer `me` acknowledges a data key:
/// `nerve/R/A/P` → `nerve-ack/R/A/P/<me robot>/<me name>`.
fn ack_key_of(data_key: &str, me: &Me) -> String {
    format!("nerve-ack/{}/{}/{}", data_key.strip_prefix("nerve/").unwrap_or(data_key), me.robot, me.name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lease_is_in_the_robots_seconds_with_a_floor() {
        let s = std::time::Duration::from_secs;
        assert_eq!(link_lease_ms(s(3), 1.0), 3000);
        assert_eq!(link_lease_ms(s(3), 4.0), 750, "3 simulated seconds at 4x are 0.75 real ones");
        assert_eq!(link_lease_ms(s(3), 0.5), 6000, "slower than real time: longer");
        assert_eq!(link_lease_ms(s(1), 100.0), 100, "never under Zenoh's floor");
        assert_eq!(link_lease_ms(s(3), f64::NAN), 3000, "a broken scale is taken as real time");
        assert_eq!(link_lease_ms(s(3), 0.0), 3000);
    }

    #[test]
    fn keys_and_config() {
        let me = Me { robot: "r2".into(), name: "bridge".into() };
        assert_eq!(ack_key_of("nerve/r1/t1/tick", &me), "nerve-ack/r1/t1/tick/r2/bridge");
        let cfg = crate::config::parse(
            "listen = [\"tcp/127.0.0.1:7447\"]\n[[export]]\nport = \"t1/tick\"\ntype = \"nerve::Tick\"\n",
            "b.toml",
            &|_| true,
        )
        .expect("valid");
        let z = session_config(&cfg, "r1", None, 8).expect("zenoh accepts it");
        let json = format!("{z}");
        assert!(json.contains("127.0.0.1:7447"), "{json}");
        assert!(json.contains(&format!("\"max_message_size\":{}", max_message_size(8))), "{json}");
    }

    #[test]
    fn tls_and_access_control_are_accepted_by_zenoh() {
        let cfg = crate::config::parse(
            "listen = [\"tls/10.0.0.1:7447\"]\npeers = [\"r3\"]\n[[export]]\nport = \"t1/tick\"\ntype = \"nerve::Tick\"\n\
             [[import]]\nport = \"r2/m/report\"\ntype = \"nerve::Tick\"\n[tls]\nkeys = \"/k\"\n",
            "b.toml",
            &|_| true,
        )
        .expect("valid");
        let files = cfg.tls.as_ref().expect("tls").files("r1");
        let z = session_config(&cfg, "r1", Some(&files), 1 << 20).expect("zenoh accepts TLS and the ACL");
        let json = format!("{z}");
        assert!(json.contains("\"enable_mtls\":true") && json.contains("/k/r1.key"), "{json}");
        let acl = acl_json(&cfg, "r1");
        for k in
            ["nerve/r2/m/report", "nerve-ack/r1/t1/tick/r2/*", "nerve-importer/r1/t1/tick/r3/*", "nerve-bridge/r3/*"]
        {
            assert!(acl.contains(k), "{k} missing from {acl}");
        }
        assert!(!acl.contains("nerve/r3/"), "r3 is imported from by nobody: it may put no data: {acl}");
    }
}
