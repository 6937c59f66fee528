//! The Zenoh side of the bridge: one peer-mode session (no Zenoh router),
//! the publishers and subscribers of the topics, the liveliness tokens that
//! tell who is there, and the acknowledgements of reliable topics.
//!
//! Keys (robot, agent and port names never contain `/`, `*`, `$` or `?`):
//!
//! | key | what |
//! |---|---|
//! | `nerve/<robot>/<agent>/<port>` | the data frames of an exported port |
//! | `nerve-ack/<robot>/<agent>/<port>` | acknowledgements of a reliable topic, to its sender |
//! | `nerve-importer/<robot>/<agent>/<port>/<me>` | liveliness: bridge `<me>` imports that port |
//! | `nerve-bridge/<robot>/<name>` | liveliness: a bridge is up (the peers figure) |
//!
//! Zenoh runs its own threads. They are started from the link thread, which
//! first drops real-time scheduling, so that Zenoh's runtime never competes
//! with the robot's real-time tasks.

use crate::config::Config;
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

/// The Zenoh configuration of a bridge: peer mode, the given endpoints,
/// multicast scouting only when asked, a short lease so that a cut is
/// noticed quickly, and quick re-dialling of `connect` endpoints.
pub fn zenoh_config(cfg: &Config) -> Result<zenoh::Config, LinkError> {
    let mut z = zenoh::Config::default();
    let lease_ms = cfg.lease.as_millis().max(100);
    let settings: Vec<(&'static str, String)> = vec![
        ("mode", "\"peer\"".into()),
        ("listen/endpoints", json_list(&cfg.listen)),
        ("connect/endpoints", json_list(&cfg.connect)),
        ("scouting/multicast/enabled", cfg.multicast_scouting.to_string()),
        ("scouting/gossip/enabled", "true".into()),
        // dial in the background for ever (a peer that is not up yet, or
        // comes back after a cut), retrying every 0.2 s growing to 1 s
        ("connect/timeout_ms", "-1".into()),
        ("connect/exit_on_failure", "false".into()),
        ("connect/retry", "{period_init_ms: 200, period_max_ms: 1000, period_increase_factor: 2}".into()),
        ("listen/exit_on_failure", "true".into()),
        ("transport/link/tx/lease", lease_ms.to_string()),
        ("transport/link/tx/keep_alive", "4".into()),
    ];
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
        let session = zenoh::open(zenoh_config(cfg)?)
            .wait()
            .map_err(|e| LinkError::Open { listen: cfg.listen.clone(), detail: e.to_string() })?;
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
            let sub = session
                .declare_subscriber(ack_key.clone())
                .callback(move |s| {
                    let key = s.key_expr().as_str();
                    let Some(t) = acks.iter().find(|t| ack_key_of(&t.key) == key) else { return };
                    let bytes = s.payload().to_bytes();
                    match wire::decode_ack(&bytes) {
                        Ok(a) => t.ack(&a, now_mono()),
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
                    // nerve-importer/<robot>/<agent>/<port>/<who>
                    let Some(rest) = s.key_expr().as_str().strip_prefix(&prefix) else { return };
                    let parts: Vec<&str> = rest.split('/').collect();
                    let [agent, port, who] = parts[..] else { return };
                    if let Some(t) = by_key.iter().find(|t| t.spec.agent == agent && t.spec.port == port) {
                        t.set_importer(who, s.kind() == SampleKind::Put);
                    }
                })
                .wait()
                .map_err(|e| declare_err("liveliness subscriber", &imp_key, e))?;
            subscribers.push(sub);
        }

        // imports: a subscriber and an importer token each; acknowledgements go back on nerve-ack
        for t in imports {
            let ack_pub = session
                .declare_publisher(ack_key_of(&t.key))
                .congestion_control(CongestionControl::Drop)
                .express(true)
                .wait()
                .map_err(|e| declare_err("publisher", &ack_key_of(&t.key), e))?;
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
                format!("nerve-importer/{}/{}/{}/{}", t.spec.robot, t.spec.agent, t.spec.port, me.importer_id());
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
        tracing::info!(zid = %session.zid(), listen = ?cfg.listen, connect = ?cfg.connect, "zenoh session open (peer mode)");
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

/// The acknowledgement key of a data key: `nerve/R/A/P` → `nerve-ack/R/A/P`.
fn ack_key_of(data_key: &str) -> String {
    format!("nerve-ack/{}", data_key.strip_prefix("nerve/").unwrap_or(data_key))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_and_config() {
        assert_eq!(ack_key_of("nerve/r1/t1/tick"), "nerve-ack/r1/t1/tick");
        let cfg = crate::config::parse(
            "listen = [\"tcp/127.0.0.1:7447\"]\n[[export]]\nport = \"t1/tick\"\ntype = \"nerve::Tick\"\n",
            "b.toml",
            &|_| true,
        )
        .expect("valid");
        let z = zenoh_config(&cfg).expect("zenoh accepts it");
        let json = format!("{z}");
        assert!(json.contains("127.0.0.1:7447"), "{json}");
    }
}
