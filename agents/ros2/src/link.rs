//! The Zenoh side of the `ros2` agent: one session (client of a router, as
//! rmw_zenoh's nodes are by default, or a peer with explicit endpoints), the
//! node's liveliness token, a publisher and a token per published topic, a
//! subscriber and a token per subscribed topic ([`crate::wire`] spells them).
//!
//! It runs in a thread of its own that first drops real-time scheduling, so
//! that Zenoh's runtime (started by the session) never competes with the
//! robot's real-time tasks. The task puts the messages of its small topics
//! itself, with the publishers this thread lends it once the session is
//! open ([`crate::route`]), and hands the rest (Images) to this thread as
//! CDR bytes through a bounded channel ([`Outgoing`]); the subscribers'
//! callbacks leave what arrives in a
//! bounded [`Inbox`] per topic and wake the event-driven task through the
//! agent's waker ([`agent_sdk::Waker`]); the task empties the inboxes in the
//! step that wake makes.
//!
//! A transient-local topic (`durability = "transient_local"`, and
//! /tf_static) keeps its last `depth` messages, attachments included, and
//! serves them to subscriptions that join later, as zenoh-ext's
//! `AdvancedPublisher` with a cache and publisher detection does for
//! rmw_zenoh: a queryable and a liveliness token on
//! [`wire::cache_key`].

use crate::config::{Config, Mode};
use crate::msgs::{RosMessage, Twist};
use crate::route::{Route, TaskPublishers};
use crate::wire::{self, Attachment, EntityKind, NodeId};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;
use zenoh::Wait;
use zenoh::qos::CongestionControl;

/// How many received messages per topic wait for the task at most (the
/// oldest is dropped beyond).
const INBOX: usize = 64;

/// Why the session or a declaration failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// Zenoh refused a configuration value.
    #[error("zenoh configuration {key} = {value}: {source}")]
    Config {
        /// the key
        key: &'static str,
        /// the value
        value: String,
        /// what zenoh said
        #[source]
        source: zenoh::Error,
    },
    /// The session could not be opened.
    #[error(
        "cannot open the zenoh session ({mode:?}, connect {connect:?}, listen {listen:?}): {source}; is a router (rmw_zenohd, or nerve-ros2-router) running there?"
    )]
    Open {
        /// client or peer
        mode: Mode,
        /// the endpoints
        connect: Vec<String>,
        /// the endpoints listened on
        listen: Vec<String>,
        /// what zenoh said
        #[source]
        source: zenoh::Error,
    },
    /// A publisher, subscriber or token could not be declared.
    #[error("zenoh refused to declare the {what} {key}: {source}")]
    Declare {
        /// publisher, subscriber, token
        what: &'static str,
        /// its key
        key: String,
        /// what zenoh said
        #[source]
        source: zenoh::Error,
    },
    /// A message could not be written as CDR.
    #[error("the message for {topic} could not be written as CDR: {source}")]
    Encode {
        /// the topic
        topic: String,
        /// why
        #[source]
        source: crate::cdr::CdrError,
    },
    /// A topic's type has no hash (not vendored).
    #[error("{ros_type} is not among the vendored messages (agents/ros2/msg): no type hash for its key")]
    UnknownType {
        /// the type
        ros_type: String,
    },
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// CDR bytes of published topic number `topic`, for the link thread.
#[derive(Debug)]
pub struct Outgoing {
    /// index into the configuration's `publish`
    pub topic: usize,
    /// the message, header first
    pub bytes: Vec<u8>,
}

/// A message one subscription received, decoded as its mapping says.
#[derive(Debug, Clone, PartialEq)]
pub enum Arrived {
    /// a `geometry_msgs/msg/Twist` (`SubMap::TwistToVelocity`)
    Twist(Twist),
    /// a sample of the subscription's nerve layout (`SubMap::User`)
    Sample(Vec<u8>),
}

/// What one subscription received, for the task; and its counters. Each
/// message put wakes the task through the agent's waker, so that it steps
/// at once (the wakes coalesce: one step takes all that waits).
#[derive(Debug, Default)]
pub struct Inbox {
    queue: Mutex<VecDeque<Arrived>>,
    /// wakes the agent's event-driven task (`None`: nothing to wake)
    waker: Option<agent_sdk::Waker>,
    received: AtomicU64,
    refused: AtomicU64,
    overflow: AtomicU64,
    last_refusal: Mutex<String>,
}

impl Inbox {
    /// An inbox whose messages wake the task through `waker`.
    pub fn waking(waker: agent_sdk::Waker) -> Self {
        Inbox { waker: Some(waker), ..Inbox::default() }
    }

    /// Keeps a decoded message (dropping the oldest when full), then wakes
    /// the task.
    pub fn put(&self, t: Arrived) {
        self.received.fetch_add(1, Ordering::Relaxed);
        {
            let mut q = lock(&self.queue);
            if q.len() >= INBOX {
                q.pop_front();
                self.overflow.fetch_add(1, Ordering::Relaxed);
            }
            q.push_back(t);
        }
        if let Some(w) = &self.waker {
            w.wake();
        }
    }

    /// Everything waiting, oldest first.
    pub fn take(&self) -> Vec<Arrived> {
        lock(&self.queue).drain(..).collect()
    }

    /// Counts a message that was not delivered, and logs why at counts 1,
    /// 2, 4, 8, ...
    pub fn refuse(&self, why: &str) {
        let n = self.refused.fetch_add(1, Ordering::Relaxed) + 1;
        if n.is_power_of_two() {
            tracing::warn!(refused = n, reason = why, "a ROS message was refused");
        }
        *lock(&self.last_refusal) = why.to_owned();
    }

    /// The figures of topic `topic`.
    pub fn figures(&self, topic: &str) -> Vec<(String, String)> {
        vec![
            (format!("received{topic}"), self.received.load(Ordering::Relaxed).to_string()),
            (format!("refused{topic}"), self.refused.load(Ordering::Relaxed).to_string()),
            (format!("overflow{topic}"), self.overflow.load(Ordering::Relaxed).to_string()),
        ]
    }
}

/// Counters of the published topics, and the session id.
#[derive(Debug)]
pub struct Stats {
    published: Vec<AtomicU64>,
    dropped: Vec<AtomicU64>,
    refused_frames: AtomicU64,
    session: Mutex<String>,
}

impl Stats {
    /// Counters for `n` published topics.
    pub fn new(n: usize) -> Self {
        Stats {
            published: (0..n).map(|_| AtomicU64::new(0)).collect(),
            dropped: (0..n).map(|_| AtomicU64::new(0)).collect(),
            refused_frames: AtomicU64::new(0),
            session: Mutex::new(String::new()),
        }
    }

    /// A message of topic `i` went out (to Zenoh's queue).
    pub fn published(&self, i: usize) {
        if let Some(c) = self.published.get(i) {
            c.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// A message of topic `i` found the link thread's queue full, no
    /// session, or a put that failed.
    pub fn dropped(&self, i: usize) {
        if let Some(d) = self.dropped.get(i) {
            d.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// A frame of topic `i` that could not be an Image (a pixel format ROS
    /// has no name for, or sizes that do not fit its slot).
    pub fn refused_frame(&self, i: usize) {
        let n = self.refused_frames.fetch_add(1, Ordering::Relaxed) + 1;
        if n.is_power_of_two() {
            tracing::warn!(topic = i, refused = n, "a frame is not rgb8 or gray8, or its sizes do not fit its slot");
        }
    }

    /// The figures, `published/odom` etc. for the topics named.
    pub fn figures(&self, topics: &[String]) -> Vec<(String, String)> {
        let mut v = vec![
            ("session".to_string(), lock(&self.session).clone()),
            ("refused_frames".to_string(), self.refused_frames.load(Ordering::Relaxed).to_string()),
        ];
        for (i, t) in topics.iter().enumerate() {
            let get = |c: &Vec<AtomicU64>| c.get(i).map_or(0, |a| a.load(Ordering::Relaxed)).to_string();
            v.push((format!("published{t}"), get(&self.published)));
            v.push((format!("dropped{t}"), get(&self.dropped)));
        }
        v
    }
}

/// The last messages of a transient-local publisher, for late joiners.
#[derive(Debug)]
struct Cache {
    depth: usize,
    /// (CDR bytes, attachment), oldest first
    items: Mutex<VecDeque<(Vec<u8>, Vec<u8>)>>,
}

impl Cache {
    fn keep(&self, bytes: &[u8], attachment: &[u8]) {
        let mut q = lock(&self.items);
        while q.len() >= self.depth {
            q.pop_front();
        }
        q.push_back((bytes.to_vec(), attachment.to_vec()));
    }
}

/// A topic's publisher, with its attachment's state: its GID and its last
/// sequence number. One thread puts with it ([`Route`]).
pub struct Publisher {
    publisher: zenoh::pubsub::Publisher<'static>,
    gid: [u8; 16],
    /// transient local: the cache, its queryable and its detection token
    cache: Option<(Arc<Cache>, zenoh::query::Queryable<()>, zenoh::liveliness::LivelinessToken)>,
    /// the last sequence number sent
    seq: i64,
}

impl std::fmt::Debug for Publisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Publisher").field("key", &self.publisher.key_expr().as_str()).field("seq", &self.seq).finish()
    }
}

impl Publisher {
    /// Declares the publisher of `key` (and, when `qos` is transient local,
    /// its cache) and its graph token; pushes the token onto `tokens`.
    fn declare(
        session: &zenoh::Session,
        node: &NodeId,
        entity: u32,
        topic: &str,
        ros_type: (&str, &str),
        (qos, route): (&wire::Qos, Route),
        tokens: &mut Vec<zenoh::liveliness::LivelinessToken>,
    ) -> Result<Publisher, LinkError> {
        let (dds, hash) = ros_type;
        let key = wire::topic_key(node.domain, topic, dds, hash);
        let publisher = session
            .declare_publisher(key.clone())
            .congestion_control(CongestionControl::Drop)
            .priority(route.priority())
            .wait()
            .map_err(declare_err("publisher", &key))?;
        let cache = if qos.transient_local {
            let cache = Arc::new(Cache {
                depth: usize::try_from(qos.depth.max(1)).unwrap_or(1),
                items: Mutex::new(VecDeque::new()),
            });
            let adv = wire::cache_key(&key, &node.session, entity);
            let queryable = session
                .declare_queryable(adv.clone())
                .callback({
                    let (cache, key) = (cache.clone(), key.clone());
                    move |query| {
                        // the replies carry the topic's own key, as the
                        // advanced publisher's cache does (the querier
                        // accepts any key)
                        let items: Vec<(Vec<u8>, Vec<u8>)> = lock(&cache.items).iter().cloned().collect();
                        for (bytes, att) in items {
                            if let Err(e) = query.reply(key.clone(), bytes).attachment(att).wait() {
                                tracing::debug!(key = %key, error = %e, "a late joiner's query was not answered");
                            }
                        }
                    }
                })
                .wait()
                .map_err(declare_err("queryable", &adv))?;
            let token = session
                .liveliness()
                .declare_token(adv.clone())
                .wait()
                .map_err(declare_err("liveliness token", &adv))?;
            Some((cache, queryable, token))
        } else {
            None
        };
        let tok = node.entity_token(EntityKind::Publisher, entity, topic, dds, hash, qos);
        let gid = wire::gid_of(&tok);
        tokens.push(
            session.liveliness().declare_token(tok.clone()).wait().map_err(declare_err("liveliness token", &tok))?,
        );
        Ok(Publisher { publisher, gid, cache, seq: 0 })
    }

    /// Sends `bytes` with the next attachment (and keeps them for late
    /// joiners when transient local).
    pub fn put(&mut self, bytes: Vec<u8>) -> Result<(), zenoh::Error> {
        self.seq = self.seq.saturating_add(1);
        let att = Attachment {
            sequence_number: self.seq,
            source_timestamp: i64::try_from(crate::convert::epoch_now_ns()).unwrap_or(i64::MAX),
            gid: self.gid,
        }
        .encode();
        if let Some((cache, _, _)) = &self.cache {
            cache.keep(&bytes, &att);
        }
        self.publisher.put(bytes).attachment(att.to_vec()).wait()
    }
}

/// An open session with everything declared; dropping it undeclares all.
pub struct Link {
    session: zenoh::Session,
    /// the link thread's publishers, by topic (`None`: the task's)
    publishers: Vec<Option<Publisher>>,
    /// the task's publishers, lent to it while the session is open
    task: Arc<TaskPublishers>,
    /// /tf_static, when the configuration has static transforms
    _tf_static: Option<Publisher>,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    _tokens: Vec<zenoh::liveliness::LivelinessToken>,
}

impl std::fmt::Debug for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Link").field("zid", &self.session.zid()).finish()
    }
}

fn json_list(v: &[String]) -> String {
    let items: Vec<String> = v.iter().map(|s| format!("{s:?}")).collect();
    format!("[{}]", items.join(","))
}

/// The Zenoh configuration: the mode and endpoints of `cfg`, multicast
/// scouting off (rmw_zenoh's default: discovery goes through the router),
/// and an open that gives up after 2 s when no router answers
/// ([`Link::open_retrying`] tries again).
pub fn zenoh_config(cfg: &Config) -> Result<zenoh::Config, LinkError> {
    let mut z = zenoh::Config::default();
    let mode = match cfg.mode {
        Mode::Client => "\"client\"",
        Mode::Peer => "\"peer\"",
    };
    let settings: Vec<(&'static str, String)> = vec![
        ("mode", mode.into()),
        ("connect/endpoints", json_list(&cfg.connect)),
        ("listen/endpoints", json_list(&cfg.listen)),
        ("scouting/multicast/enabled", "false".into()),
        ("connect/timeout_ms", "2000".into()),
        ("connect/retry", "{period_init_ms: 200, period_max_ms: 2000, period_increase_factor: 2}".into()),
    ];
    for (key, value) in settings {
        z.insert_json5(key, &value).map_err(|source| LinkError::Config { key, value: value.clone(), source })?;
    }
    Ok(z)
}

fn declare_err(what: &'static str, key: &str) -> impl FnOnce(zenoh::Error) -> LinkError {
    let key = key.to_owned();
    move |source| LinkError::Declare { what, key, source }
}

impl Link {
    /// Opens the session, declares the node, its publishers and
    /// subscriptions with their tokens. `inboxes` are the subscriptions'
    /// (in the order of `cfg.subscribe`); the publishers of the task's
    /// topics ([`Route::Task`]) are lent to `task`.
    pub fn open(cfg: &Config, inboxes: Vec<Arc<Inbox>>, task: Arc<TaskPublishers>) -> Result<Link, LinkError> {
        let session = zenoh::open(zenoh_config(cfg)?).wait().map_err(|source| LinkError::Open {
            mode: cfg.mode,
            connect: cfg.connect.clone(),
            listen: cfg.listen.clone(),
            source,
        })?;
        let node = NodeId {
            domain: cfg.domain,
            session: session.zid().to_string(),
            node: 0,
            enclave: String::new(),
            namespace: cfg.namespace.clone(),
            name: cfg.node.clone(),
        };
        let mut tokens = Vec::new();
        let token = |key: String| -> Result<zenoh::liveliness::LivelinessToken, LinkError> {
            session.liveliness().declare_token(key.clone()).wait().map_err(declare_err("liveliness token", &key))
        };
        tokens.push(token(node.node_token())?);
        let mut entity = 0u32;
        let (mut publishers, mut lent) = (Vec::new(), Vec::new());
        for p in &cfg.publish {
            entity += 1;
            let (dds, hash) = type_of(cfg, &p.ros_type)?;
            let route = Route::of(p);
            let publisher =
                Publisher::declare(&session, &node, entity, &p.topic, (&dds, hash), (&p.qos, route), &mut tokens)?;
            tracing::info!(topic = %p.topic, key = %publisher.publisher.key_expr(), ?route, "publishing {} as {}", p.input, p.ros_type);
            match route {
                Route::Task => {
                    publishers.push(None);
                    lent.push(Some(publisher));
                }
                Route::Link => {
                    publishers.push(Some(publisher));
                    lent.push(None);
                }
            }
        }
        let tf_static = if cfg.static_transforms.is_empty() {
            None
        } else {
            entity += 1;
            let topic = wire::qualified_topic(&cfg.namespace, crate::config::TF_STATIC_TOPIC);
            let (dds, hash) = type_of(cfg, "tf2_msgs/msg/TFMessage")?;
            let mut p = Publisher::declare(
                &session,
                &node,
                entity,
                &topic,
                (&dds, hash),
                (&Config::tf_static_qos(), Route::Task),
                &mut tokens,
            )?;
            let stamp = crate::msgs::Time::from_ns(crate::convert::epoch_now_ns());
            let bytes = crate::convert::static_tf(&cfg.static_transforms, stamp)
                .to_cdr()
                .map_err(|source| LinkError::Encode { topic: topic.clone(), source })?;
            // once: the cache serves it to whoever subscribes later
            if let Err(e) = p.put(bytes) {
                tracing::warn!(topic = %topic, error = %e, "the static transforms were not sent now; late joiners still get them");
            }
            tracing::info!(topic = %topic, transforms = cfg.static_transforms.len(), "static transforms published (transient local)");
            Some(p)
        };
        let mut subscribers = Vec::new();
        for (s, inbox) in cfg.subscribe.iter().zip(inboxes) {
            entity += 1;
            let (dds, hash) = type_of(cfg, &s.ros_type)?;
            let key = wire::topic_key(cfg.domain, &s.topic, &dds, hash);
            let topic = s.topic.clone();
            let user = s.user.clone();
            let sub = session
                .declare_subscriber(key.clone())
                .callback(move |sample| {
                    if let Some(a) = sample.attachment()
                        && let Err(e) = Attachment::decode(&a.to_bytes())
                    {
                        tracing::debug!(topic = %topic, error = %e, "a message with a malformed attachment (taken all the same)");
                    }
                    let bytes = sample.payload().to_bytes();
                    match &user {
                        Some(m) => match m.decode(&bytes) {
                            Ok(b) => inbox.put(Arrived::Sample(b)),
                            Err(e) => inbox.refuse(&format!("{topic}: {e}")),
                        },
                        None => match Twist::from_cdr(&bytes) {
                            Ok(t) => inbox.put(Arrived::Twist(t)),
                            Err(e) => inbox.refuse(&format!("{topic}: {e}")),
                        },
                    }
                })
                .wait()
                .map_err(declare_err("subscriber", &key))?;
            tokens.push(token(node.entity_token(EntityKind::Subscription, entity, &s.topic, &dds, hash, &s.qos))?);
            tracing::info!(topic = %s.topic, key = %key, "subscribed as {} for output {}", s.ros_type, s.output);
            subscribers.push(sub);
        }
        tracing::info!(
            zid = %session.zid(),
            node = %node.node_token(),
            mode = ?cfg.mode,
            connect = ?cfg.connect,
            "zenoh session open: ROS 2 node {} in domain {}",
            cfg.node,
            cfg.domain
        );
        task.fill(lent);
        Ok(Link { session, publishers, task, _tf_static: tf_static, _subscribers: subscribers, _tokens: tokens })
    }

    /// Opens the link, trying again (every 0.2 s, growing to 2 s) while no
    /// router answers, until `stop` is set (then `None`). Meanwhile what the
    /// task hands over is dropped and counted: nobody could receive it.
    pub fn open_retrying(
        cfg: &Config,
        inboxes: &[Arc<Inbox>],
        task: &Arc<TaskPublishers>,
        rx: &Receiver<Outgoing>,
        stats: &Stats,
        stop: &AtomicBool,
    ) -> Option<Link> {
        let mut wait = Duration::from_millis(200);
        let mut attempts = 0u64;
        loop {
            if stop.load(Ordering::Acquire) {
                return None;
            }
            match Link::open(cfg, inboxes.to_vec(), task.clone()) {
                Ok(l) => {
                    if attempts > 0 {
                        tracing::info!(attempts, "zenoh session open after {attempts} failed attempt(s)");
                    }
                    return Some(l);
                }
                Err(e) => {
                    attempts += 1;
                    if attempts.is_power_of_two() {
                        tracing::warn!(attempts, error = %e, "no zenoh session yet; trying again");
                    }
                }
            }
            let until = std::time::Instant::now() + wait;
            while std::time::Instant::now() < until && !stop.load(Ordering::Acquire) {
                while let Ok(out) = rx.try_recv() {
                    stats.dropped(out.topic);
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            wait = (wait * 2).min(Duration::from_secs(2));
        }
    }

    /// Publishes what the task hands over until `stop` is set or the task
    /// drops its end of the channel.
    pub fn run(&mut self, rx: &Receiver<Outgoing>, stats: &Stats, stop: &AtomicBool) {
        *lock(&stats.session) = self.session.zid().to_string();
        while !stop.load(Ordering::Acquire) {
            let out = match rx.recv_timeout(Duration::from_millis(100)) {
                Ok(o) => o,
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => break,
            };
            let Some(p) = self.publishers.get_mut(out.topic).and_then(Option::as_mut) else { continue };
            match p.put(out.bytes) {
                Ok(()) => stats.published(out.topic),
                Err(e) => {
                    stats.dropped(out.topic);
                    tracing::debug!(key = %p.publisher.key_expr(), error = %e, "put failed");
                }
            }
        }
    }

    /// Undeclares everything and closes the session.
    pub fn close(self) {
        let Link { session, publishers, task, _tf_static, _subscribers, _tokens } = self;
        // the task's publishers back first: none is put with after the close
        let lent = task.take();
        drop((lent, publishers, _tf_static, _subscribers, _tokens));
        if let Err(e) = session.close().wait() {
            tracing::debug!(error = %e, "zenoh session close");
        }
    }
}

fn type_of(cfg: &Config, ros_type: &str) -> Result<(String, &'static str), LinkError> {
    let unknown = || LinkError::UnknownType { ros_type: ros_type.to_owned() };
    let dds = wire::dds_type_name(ros_type).ok_or_else(unknown)?;
    let hash = cfg.distro.type_hash(ros_type).ok_or_else(unknown)?;
    Ok((dds, hash))
}
