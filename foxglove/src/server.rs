//! The server: a listener, a thread per client, and the serving thread
//! (the caller of [`serve`]) that owns the [`Robot`].
//!
//! - The handshake refuses, with an HTTP status and a reason: a
//!   subprotocol other than [`SUBPROTOCOLS`] (400), an `Origin` that is
//!   neither loopback nor given with `--allow-origin` (403), a wrong token
//!   (401), more clients than allowed (503).
//! - A client's thread reads its requests and writes what the serving
//!   thread queued for it: control messages (never dropped) and message
//!   data (at most [`Options::queue`]; when full the oldest is dropped and
//!   counted). It writes a new batch only once the last one has left, so a
//!   client that stops reading holds at most one batch and its queue, and
//!   is disconnected when nothing left for [`Options::stall_timeout`].
//! - The serving thread refreshes the channels (advertise/unadvertise) and
//!   what clients watch (parameters, the graph: [`watched`]),
//!   reads the subscribed ports only, fans samples out to the queues,
//!   answers parameter, graph and publish requests, hands service calls to
//!   the robot ([`services`]), and never blocks on a client or a server.

use crate::Robot;
use crate::protocol::{self, Channel, ClientMessage, Level, Parameter, SUBPROTOCOLS};
use crate::wake::{Interest, Wake, wait_fds};
use nerve_ui::token_matches;
use serde_json::json;
use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::io::ErrorKind;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::os::fd::AsRawFd as _;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tungstenite::handshake::server::{ErrorResponse, Request as HttpRequest, Response};
use tungstenite::protocol::WebSocketConfig;
use tungstenite::{Message, WebSocket};
use watched::{Graph, GraphState, ParamState, graph_update};

mod services;
mod watched;

/// How `nerve foxglove` serves.
#[derive(Debug, Clone)]
pub struct Options {
    /// address to listen on (127.0.0.1:8765 by default)
    pub bind: SocketAddr,
    /// the robot's name (shown in `serverInfo`)
    pub robot: String,
    /// refuse every change: parameter sets and publishing
    pub read_only: bool,
    /// the edit token: a client that connects with `?token=` and it may
    /// set parameters (and publish, with [`Options::publish`]); `None`:
    /// nobody may
    pub token: Option<String>,
    /// offer `clientPublish` into input ports (to clients with the token)
    pub publish: bool,
    /// origins (`https://app.foxglove.dev`) allowed besides loopback ones
    pub allowed_origins: Vec<String>,
    /// clients served at once
    pub max_clients: usize,
    /// message data queued per client before the oldest is dropped
    pub queue: usize,
    /// a client that takes nothing for this long while data waits is disconnected
    pub stall_timeout: Duration,
    /// how often channels and the graph are refreshed from the router
    pub refresh: Duration,
    /// how long a service call a client makes waits for its answer
    pub call_timeout: Duration,
}

impl Options {
    /// The defaults of `nerve foxglove` on `bind`.
    pub fn new(bind: SocketAddr, robot: &str) -> Options {
        Options {
            bind,
            robot: robot.to_owned(),
            read_only: false,
            token: None,
            publish: false,
            allowed_origins: Vec::new(),
            max_clients: 16,
            queue: 1024,
            stall_timeout: Duration::from_secs(10),
            refresh: Duration::from_millis(500),
            call_timeout: Duration::from_secs(2),
        }
    }
}

/// What a server did, told when it stops.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// clients served
    pub clients: u64,
    /// connections refused at the handshake
    pub refused: u64,
    /// messages dropped because a client read too slowly
    pub dropped_messages: u64,
    /// clients disconnected because they stopped reading
    pub dropped_clients: u64,
}

/// Why the server could not run.
#[derive(Debug, thiserror::Error)]
pub enum FoxgloveError {
    /// the address is taken or not ours
    #[error(
        "cannot listen on {addr}: {source}; is another Foxglove server (foxglove_bridge, another nerve foxglove) \
         on that port? give another one with --bind ADDR (port 0: any free port)"
    )]
    Bind {
        /// the address
        addr: SocketAddr,
        /// the system's reason
        #[source]
        source: std::io::Error,
    },
    /// the listener failed
    #[error("the listener on {addr} failed: {source}")]
    Listener {
        /// the address
        addr: SocketAddr,
        /// the system's reason
        #[source]
        source: std::io::Error,
    },
}

/// How long a handshake may take.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(3);
/// Requests read from a client in a row before its queue is looked at.
const READS_IN_A_ROW: usize = 64;
/// Messages written per batch.
const BATCH: usize = 64;
/// Control messages a client may have waiting before it is disconnected.
const CONTROL_MAX: usize = 4096;
/// Largest message a client may send.
const MAX_CLIENT_MESSAGE: usize = 1 << 20;
/// Seconds between two drop reports to a client.
const DROP_REPORT: Duration = Duration::from_secs(2);
/// How often a client is pinged: one that does not answer within the
/// stall timeout has stopped reading (WebSocket clients answer pings
/// themselves, browsers included).
const PING_EVERY: Duration = Duration::from_millis(500);

/// What a client's thread sends to the serving thread.
enum Request {
    Get {
        client: Arc<Client>,
        names: Vec<String>,
        id: Option<String>,
    },
    Set {
        client: Arc<Client>,
        parameters: Vec<Parameter>,
        id: Option<String>,
    },
    Advertise {
        client: Arc<Client>,
        channels: Vec<protocol::ClientChannel>,
    },
    Publish {
        client: Arc<Client>,
        topic: String,
        payload: Vec<u8>,
    },
    Graph {
        client: Arc<Client>,
    },
    /// a service call
    Call(services::Call),
    /// a client subscribed to parameter updates: the values it is measured against are taken now,
    /// before any later request of it (the channel keeps their order)
    WatchParams,
}

/// A queued message data frame.
struct Data {
    subscription: u32,
    unix_ns: u64,
    payload: Arc<Vec<u8>>,
}

#[derive(Default)]
struct Outbox {
    /// text frames, and the binary answers of service calls
    control: VecDeque<Message>,
    data: VecDeque<Data>,
    dropped: u64,
}

impl Outbox {
    /// Queues `d`; when `queue` messages already wait, the oldest is
    /// dropped (and counted) instead of the robot waiting. Whether one was.
    fn push_data(&mut self, d: Data, queue: usize) -> bool {
        let full = self.data.len() >= queue.max(1);
        if full {
            self.data.pop_front();
            self.dropped = self.dropped.saturating_add(1);
        }
        self.data.push_back(d);
        full
    }
}

/// A connected client, shared by its thread and the serving thread.
struct Client {
    id: u64,
    peer: SocketAddr,
    /// may set parameters and publish
    edit: bool,
    out: Mutex<Outbox>,
    /// subscription id -> channel id
    subs: Mutex<HashMap<u32, u32>>,
    /// client channel id -> input port topic
    publishing: Mutex<HashMap<u32, String>>,
    graph: AtomicBool,
    /// the parameters whose changes it is sent
    params: Mutex<BTreeSet<String>>,
    /// its service calls in flight
    calls: AtomicUsize,
    gone: AtomicBool,
    /// wakes its thread: something was queued for it, or the server stops
    wake: Wake,
}

impl Client {
    fn say(&self, text: String) {
        self.queue(Message::text(text));
    }

    fn say_binary(&self, frame: Vec<u8>) {
        self.queue(Message::binary(frame));
    }

    /// Queues a control message (never dropped) and wakes the client's thread.
    fn queue(&self, message: Message) {
        let mut out = lock(&self.out);
        if out.control.len() >= CONTROL_MAX {
            // a client that takes not even its control messages is going
            self.gone.store(true, Ordering::Relaxed);
        } else {
            out.control.push_back(message);
        }
        drop(out);
        self.wake.wake();
    }

    fn error(&self, message: &str) {
        tracing::info!(client = self.id, peer = %self.peer, "refused: {message}");
        self.say(protocol::status(Level::Error, message));
    }
}

/// The channels advertised, by topic.
#[derive(Default)]
struct Channels {
    by_topic: BTreeMap<String, Channel>,
    next_id: u32,
}

/// What the threads share.
struct Hub {
    opts: Options,
    channels: Mutex<Channels>,
    services: Mutex<services::Services>,
    clients: Mutex<BTreeMap<u64, Arc<Client>>>,
    stop: AtomicBool,
    live: AtomicUsize,
    next_client: AtomicU64,
    served: AtomicU64,
    refused: AtomicU64,
    dropped_messages: AtomicU64,
    dropped_clients: AtomicU64,
    /// wakes the serving thread: a client asked something
    wake: Wake,
}

impl Hub {
    /// Hands `req` to the serving thread and wakes it.
    fn ask(&self, tx: &Sender<Request>, req: Request) {
        // the serving thread is gone only when the server stops
        let _ = tx.send(req);
        self.wake.wake();
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // a panicking client thread must not take the server with it
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The `token` of a query string.
fn query_token(query: Option<&str>) -> Option<&str> {
    query?.split('&').find_map(|kv| kv.strip_prefix("token="))
}

/// Whether a browser page of `origin` may connect: loopback pages (a
/// Foxglove or Lichtblick served on this machine) and the origins given.
fn origin_allowed(origin: &str, allowed: &[String]) -> bool {
    if allowed.iter().any(|a| a.eq_ignore_ascii_case(origin)) {
        return true;
    }
    let Some(rest) = origin.strip_prefix("http://").or_else(|| origin.strip_prefix("https://")) else {
        return false;
    };
    let host = if rest.starts_with('[') {
        rest.split_once(']').map_or(rest, |(h, _)| h).trim_start_matches('[')
    } else {
        rest.split(':').next().unwrap_or(rest)
    };
    matches!(host.to_ascii_lowercase().as_str(), "localhost" | "127.0.0.1" | "::1")
}

fn refusal(status: u16, why: &str) -> ErrorResponse {
    let mut r = ErrorResponse::new(Some(why.to_owned()));
    *r.status_mut() = tungstenite::http::StatusCode::from_u16(status).unwrap_or_default();
    r
}

/// Serves until `stop` says so; calls `listening` with the bound address
/// once the server listens.
pub fn serve(
    opts: &Options,
    robot: &mut dyn Robot,
    listening: &mut dyn FnMut(SocketAddr),
    stop: &dyn Fn() -> bool,
) -> Result<Stats, FoxgloveError> {
    let listener = TcpListener::bind(opts.bind).map_err(|source| FoxgloveError::Bind { addr: opts.bind, source })?;
    let addr = listener.local_addr().map_err(|source| FoxgloveError::Listener { addr: opts.bind, source })?;
    listener.set_nonblocking(true).map_err(|source| FoxgloveError::Listener { addr, source })?;
    let wake = Wake::new().map_err(|source| FoxgloveError::Listener { addr, source })?;
    let hub = Arc::new(Hub {
        opts: opts.clone(),
        channels: Mutex::default(),
        services: Mutex::default(),
        clients: Mutex::default(),
        stop: AtomicBool::new(false),
        live: AtomicUsize::new(0),
        next_client: AtomicU64::new(1),
        served: AtomicU64::new(0),
        refused: AtomicU64::new(0),
        dropped_messages: AtomicU64::new(0),
        dropped_clients: AtomicU64::new(0),
        wake,
    });
    tracing::info!(%addr, read_only = opts.read_only, publish = opts.publish, "nerve foxglove listening");
    // the channels are known before the first client is told them
    refresh_channels(&hub, robot);
    services::refresh(&hub, robot);
    listening(addr);
    let (tx, rx) = mpsc::channel();
    let mut threads: Vec<JoinHandle<()>> = Vec::new();
    let mut last_refresh = Instant::now();
    let mut graph = GraphState::default();
    let mut params = ParamState::default();
    while !stop() {
        accept(&listener, &hub, &tx, &mut threads)?;
        if last_refresh.elapsed() >= opts.refresh {
            last_refresh = Instant::now();
            refresh_channels(&hub, robot);
            services::refresh(&hub, robot);
            graph.refresh(&hub, robot);
            params.refresh(&hub, robot);
        }
        while let Ok(req) = rx.try_recv() {
            answer(&hub, robot, req, &mut params);
        }
        read_ports(&hub, robot);
        threads.retain(|t| !t.is_finished());
        // until a sample, a request or a connection comes, or the next refresh is due (a stop
        // request is seen then at the latest; a signal ends the wait at once)
        let due = opts.refresh.saturating_sub(last_refresh.elapsed());
        robot.wait(&[hub.wake.fd(), listener.as_raw_fd()], due);
        hub.wake.drain();
    }
    hub.stop.store(true, Ordering::Relaxed);
    for c in lock(&hub.clients).values() {
        c.wake.wake();
    }
    drop(rx);
    for t in threads {
        let _ = t.join();
    }
    Ok(Stats {
        clients: hub.served.load(Ordering::Relaxed),
        refused: hub.refused.load(Ordering::Relaxed),
        dropped_messages: hub.dropped_messages.load(Ordering::Relaxed),
        dropped_clients: hub.dropped_clients.load(Ordering::Relaxed),
    })
}

fn accept(
    listener: &TcpListener,
    hub: &Arc<Hub>,
    tx: &Sender<Request>,
    threads: &mut Vec<JoinHandle<()>>,
) -> Result<(), FoxgloveError> {
    loop {
        match listener.accept() {
            Ok((stream, peer)) => {
                let (hub, tx) = (Arc::clone(hub), tx.clone());
                let spawned = std::thread::Builder::new()
                    .name("foxglove-client".into())
                    .spawn(move || client(stream, peer, &hub, &tx));
                match spawned {
                    Ok(t) => threads.push(t),
                    Err(e) => tracing::warn!(%peer, error = %e, "cannot start a thread for a client: refused"),
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => return Ok(()),
            // a connection that died in the backlog, or out of descriptors for a moment
            Err(e) if matches!(e.kind(), ErrorKind::ConnectionAborted | ErrorKind::Interrupted) => {}
            Err(e) if e.raw_os_error().is_some_and(|c| c == 24 || c == 23) => {
                tracing::warn!(error = %e, "out of file descriptors: a client waits");
                return Ok(());
            }
            Err(source) => {
                return Err(FoxgloveError::Listener { addr: hub.opts.bind, source });
            }
        }
    }
}

/// What the handshake decided.
struct Admission {
    subprotocol: &'static str,
    edit: bool,
}

// the callback's error type is tungstenite's (an HTTP response), not ours to box
#[allow(clippy::result_large_err)]
fn handshake(stream: TcpStream, hub: &Hub) -> Result<(WebSocket<TcpStream>, Admission), String> {
    stream.set_read_timeout(Some(HANDSHAKE_TIMEOUT)).map_err(|e| e.to_string())?;
    stream.set_write_timeout(Some(HANDSHAKE_TIMEOUT)).map_err(|e| e.to_string())?;
    let _ = stream.set_nodelay(true);
    let mut admission = None;
    let full = hub.live.load(Ordering::Relaxed) > hub.opts.max_clients;
    let callback = |req: &HttpRequest, mut resp: Response| -> Result<Response, ErrorResponse> {
        if full {
            return Err(refusal(503, "nerve foxglove serves no more clients now: close another and retry"));
        }
        if let Some(origin) = req.headers().get("origin") {
            let origin = origin.to_str().unwrap_or("?");
            if !origin_allowed(origin, &hub.opts.allowed_origins) {
                return Err(refusal(
                    403,
                    &format!(
                        "pages of {origin} may not connect to this robot: start nerve foxglove with \
                         --allow-origin {origin} to let them"
                    ),
                ));
            }
        }
        let offered = req.headers().get_all("sec-websocket-protocol").iter().filter_map(|v| v.to_str().ok());
        let Some(subprotocol) = protocol::choose_subprotocol(offered) else {
            return Err(refusal(
                400,
                &format!("nerve foxglove speaks the subprotocols {}: offer one of them", SUBPROTOCOLS.join(" and ")),
            ));
        };
        let edit = match query_token(req.uri().query()) {
            None => false,
            Some(t) if hub.opts.token.as_deref().is_some_and(|k| token_matches(t, k)) => true,
            Some(_) => return Err(refusal(401, "wrong token: connect with the edit token nerve foxglove printed")),
        };
        resp.headers_mut().insert("sec-websocket-protocol", tungstenite::http::HeaderValue::from_static(subprotocol));
        admission = Some(Admission { subprotocol, edit });
        Ok(resp)
    };
    let config =
        WebSocketConfig::default().max_message_size(Some(MAX_CLIENT_MESSAGE)).max_frame_size(Some(MAX_CLIENT_MESSAGE));
    let ws = tungstenite::accept_hdr_with_config(stream, callback, Some(config)).map_err(|e| e.to_string())?;
    let admission = admission.ok_or("no admission")?;
    Ok((ws, admission))
}

/// A client's thread: handshake, then requests in, queued messages out.
fn client(stream: TcpStream, peer: SocketAddr, hub: &Hub, tx: &Sender<Request>) {
    hub.live.fetch_add(1, Ordering::Relaxed);
    let r = serve_client(stream, peer, hub, tx);
    hub.live.fetch_sub(1, Ordering::Relaxed);
    if let Err(why) = r {
        tracing::info!(%peer, "client refused or gone: {why}");
    }
}

fn serve_client(stream: TcpStream, peer: SocketAddr, hub: &Hub, tx: &Sender<Request>) -> Result<(), String> {
    let (mut ws, admission) = match handshake(stream, hub) {
        Ok(x) => x,
        Err(e) => {
            hub.refused.fetch_add(1, Ordering::Relaxed);
            return Err(e);
        }
    };
    // from now on the thread sleeps in poll(2) (its socket, its queue's wake) and never in a read or write
    ws.get_ref().set_read_timeout(None).map_err(|e| e.to_string())?;
    ws.get_ref().set_write_timeout(None).map_err(|e| e.to_string())?;
    ws.get_ref().set_nonblocking(true).map_err(|e| e.to_string())?;
    let wake = Wake::new().map_err(|e| format!("cannot make the client's wake-up pair: {e}"))?;
    let id = hub.next_client.fetch_add(1, Ordering::Relaxed);
    let client = Arc::new(Client {
        id,
        peer,
        edit: admission.edit && !hub.opts.read_only,
        out: Mutex::default(),
        subs: Mutex::default(),
        publishing: Mutex::default(),
        graph: AtomicBool::new(false),
        params: Mutex::default(),
        calls: AtomicUsize::new(0),
        gone: AtomicBool::new(false),
        wake,
    });
    hub.served.fetch_add(1, Ordering::Relaxed);
    tracing::info!(client = id, %peer, subprotocol = admission.subprotocol, edit = client.edit, "client connected");
    register(hub, &client);
    let r = client_loop(&mut ws, hub, &client, tx);
    lock(&hub.clients).remove(&id);
    client.gone.store(true, Ordering::Relaxed);
    let _ = ws.get_ref().shutdown(std::net::Shutdown::Both);
    tracing::info!(client = id, %peer, dropped = lock(&client.out).dropped, "client disconnected");
    r
}

/// Tells a new client who we are and every channel, and lets it be fanned
/// out to; under the channels' lock so that no change falls in between.
fn register(hub: &Hub, client: &Arc<Client>) {
    let opts = &hub.opts;
    let mut caps = vec!["parameters", "parametersSubscribe", "connectionGraph", "services"];
    if opts.publish && client.edit {
        caps.push("clientPublish");
    }
    let metadata = json!({
        "robot": opts.robot,
        "readOnly": opts.read_only.to_string(),
        "edit": client.edit.to_string(),
        "queue": opts.queue.to_string(),
    });
    let channels = lock(&hub.channels);
    client.say(protocol::server_info(&format!("nerve ({})", opts.robot), &caps, metadata, &client.id.to_string()));
    if !channels.by_topic.is_empty() {
        client.say(protocol::advertise(channels.by_topic.values()));
    }
    let services = lock(&hub.services);
    services::advertise_to(&services, client);
    lock(&hub.clients).insert(client.id, Arc::clone(client));
}

/// Whether a socket operation failed only because it would have waited.
fn would_block(e: &tungstenite::Error) -> bool {
    matches!(e, tungstenite::Error::Io(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted))
}

/// A client's thread after the handshake: its socket is non-blocking, and
/// it sleeps in `poll(2)` until the client sent something, its queue got
/// something (the serving thread wakes it), its socket takes more of what
/// waits to be written, or a ping or the stall timeout is due.
fn client_loop(
    ws: &mut WebSocket<TcpStream>,
    hub: &Hub,
    client: &Arc<Client>,
    tx: &Sender<Request>,
) -> Result<(), String> {
    let stall = hub.opts.stall_timeout;
    let mut unflushed = false;
    // the last moment the client had taken everything written to it
    let mut took = Instant::now();
    let (mut reported, mut report_at) = (0u64, Instant::now());
    // the ping not answered yet: its number and when it was sent
    let (mut pings, mut waiting): (u64, Option<(u64, Instant)>) = (0, None);
    let mut last_ping = Instant::now();
    loop {
        // what was queued before this is taken below; what is queued after it wakes the poll
        client.wake.drain();
        if hub.stop.load(Ordering::Relaxed) {
            let _ = ws.close(None);
            let _ = ws.flush();
            return Ok(());
        }
        if client.gone.load(Ordering::Relaxed) {
            return Err("too many control messages waiting: the client stopped reading".into());
        }
        // the requests that arrived, a bounded number in a row (tungstenite may hold more)
        let mut more_to_read = true;
        for _ in 0..READS_IN_A_ROW {
            match ws.read() {
                Ok(Message::Text(t)) => request(hub, client, tx, t.as_str()),
                Ok(Message::Binary(b)) => publish(hub, client, tx, &b),
                Ok(Message::Pong(p)) => {
                    if waiting.is_some_and(|(n, _)| p.as_ref() == n.to_le_bytes()) {
                        waiting = None;
                    }
                }
                Ok(Message::Close(_)) => {
                    let _ = ws.flush();
                    return Ok(());
                }
                Ok(_) => {}
                Err(e) if would_block(&e) => {
                    more_to_read = false;
                    break;
                }
                Err(tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed) => return Ok(()),
                Err(e) => return Err(format!("connection failed: {e}")),
            }
        }
        if !unflushed && waiting.is_none() && last_ping.elapsed() >= PING_EVERY {
            pings = pings.wrapping_add(1);
            match ws.write(Message::Ping(pings.to_le_bytes().to_vec().into())) {
                Ok(()) => {}
                // queued in tungstenite's buffer: it leaves with the flush
                Err(e) if would_block(&e) => {}
                Err(e) => return Err(format!("connection failed: {e}")),
            }
            unflushed = true;
            waiting = Some((pings, Instant::now()));
            last_ping = Instant::now();
        }
        if !unflushed {
            let (control, data, dropped) = {
                let mut out = lock(&client.out);
                let control: Vec<Message> = out.control.drain(..).collect();
                let n = out.data.len().min(BATCH);
                let data: Vec<Data> = out.data.drain(..n).collect();
                (control, data, out.dropped)
            };
            let mut frames: Vec<Message> = Vec::with_capacity(control.len() + data.len() + 1);
            if dropped > reported && report_at.elapsed() >= DROP_REPORT {
                let msg = format!(
                    "nerve foxglove dropped {} messages for this client (it reads slower than the robot publishes; \
                     {dropped} in all, queue {})",
                    dropped - reported,
                    hub.opts.queue
                );
                tracing::warn!(client = client.id, peer = %client.peer, dropped, "{msg}");
                frames.push(Message::text(protocol::status(Level::Warning, &msg)));
                (reported, report_at) = (dropped, Instant::now());
            }
            frames.extend(control);
            frames.extend(
                data.iter().map(|d| Message::binary(protocol::message_data(d.subscription, d.unix_ns, &d.payload))),
            );
            for frame in frames {
                match ws.write(frame) {
                    Ok(()) => {}
                    Err(e) if would_block(&e) => {}
                    Err(e) => return Err(format!("connection failed: {e}")),
                }
                unflushed = true;
            }
            if !unflushed {
                took = Instant::now();
            }
        }
        if unflushed {
            match ws.flush() {
                Ok(()) => {
                    unflushed = false;
                    took = Instant::now();
                }
                Err(e) if would_block(&e) => {}
                Err(e) => return Err(format!("connection failed: {e}")),
            }
        }
        let unanswered = waiting.is_some_and(|(_, at)| at.elapsed() > stall);
        if unanswered || (unflushed && took.elapsed() > stall) {
            hub.dropped_clients.fetch_add(1, Ordering::Relaxed);
            tracing::warn!(
                client = client.id,
                peer = %client.peer,
                stalled_s = stall.as_secs_f64(),
                "client disconnected: it took nothing (or answered no ping) for the stall timeout"
            );
            return Err("the client stopped reading".into());
        }
        let queued = {
            let out = lock(&client.out);
            !out.data.is_empty() || !out.control.is_empty()
        };
        if more_to_read || (queued && !unflushed) {
            continue;
        }
        // asleep until the next ping or stall check at the latest
        let mut due =
            if waiting.is_none() && !unflushed { PING_EVERY.saturating_sub(last_ping.elapsed()) } else { PING_EVERY };
        if let Some((_, at)) = waiting {
            due = due.min(stall.saturating_sub(at.elapsed()));
        }
        if unflushed {
            due = due.min(stall.saturating_sub(took.elapsed()));
        }
        let socket = (ws.get_ref().as_raw_fd(), if unflushed { Interest::ReadWrite } else { Interest::Read });
        // just past the deadline, so that the check above sees it passed
        wait_fds(&[socket, (client.wake.fd(), Interest::Read)], due.saturating_add(Duration::from_millis(1)))
            .map_err(|e| format!("cannot wait for the client's socket: {e}"))?;
    }
}

/// A client's JSON request.
fn request(hub: &Hub, client: &Arc<Client>, tx: &Sender<Request>, text: &str) {
    let msg: ClientMessage = match serde_json::from_str(text) {
        Ok(m) => m,
        Err(e) => {
            client.error(&format!("nerve foxglove does not understand this request ({e})"));
            return;
        }
    };
    let send = |r: Request| hub.ask(tx, r);
    match msg {
        ClientMessage::Subscribe { subscriptions } => {
            let channels = lock(&hub.channels);
            let known: BTreeSet<u32> = channels.by_topic.values().map(|c| c.id).collect();
            let mut subs = lock(&client.subs);
            for s in subscriptions {
                if known.contains(&s.channel_id) {
                    subs.insert(s.id, s.channel_id);
                } else {
                    client.error(&format!("no channel {} is advertised (any more)", s.channel_id));
                }
            }
        }
        ClientMessage::Unsubscribe { subscription_ids } => {
            let mut subs = lock(&client.subs);
            for id in subscription_ids {
                subs.remove(&id);
            }
        }
        ClientMessage::GetParameters { parameter_names, id } => {
            send(Request::Get { client: Arc::clone(client), names: parameter_names, id })
        }
        ClientMessage::SetParameters { parameters, id } => {
            if let Some(why) = edit_refused(hub, client, "set parameters") {
                client.error(&why);
            } else {
                send(Request::Set { client: Arc::clone(client), parameters, id });
            }
        }
        ClientMessage::Advertise { channels } => {
            if !hub.opts.publish {
                client.error("this nerve foxglove does not take publishing: start it with --publish");
            } else if let Some(why) = edit_refused(hub, client, "publish") {
                client.error(&why);
            } else {
                // known at once, so that messages sent right after the advertise are taken; the
                // serving thread checks the port (in order, before them) and forgets a refused one
                let mut p = lock(&client.publishing);
                for ch in &channels {
                    p.insert(ch.id, ch.topic.clone());
                }
                drop(p);
                send(Request::Advertise { client: Arc::clone(client), channels });
            }
        }
        ClientMessage::Unadvertise { channel_ids } => {
            let mut p = lock(&client.publishing);
            for id in channel_ids {
                p.remove(&id);
            }
        }
        ClientMessage::SubscribeParameterUpdates { parameter_names } => {
            lock(&client.params).extend(parameter_names);
            send(Request::WatchParams);
        }
        ClientMessage::UnsubscribeParameterUpdates { parameter_names } => {
            let mut p = lock(&client.params);
            for n in &parameter_names {
                p.remove(n);
            }
        }
        ClientMessage::SubscribeConnectionGraph => {
            client.graph.store(true, Ordering::Relaxed);
            send(Request::Graph { client: Arc::clone(client) });
        }
        ClientMessage::UnsubscribeConnectionGraph => client.graph.store(false, Ordering::Relaxed),
    }
}

/// Why `client` may not change the robot, if it may not.
fn edit_refused(hub: &Hub, client: &Client, what: &str) -> Option<String> {
    if hub.opts.read_only {
        return Some(format!("this nerve foxglove is read-only: it does not let clients {what}"));
    }
    if !client.edit {
        return Some(format!(
            "to {what}, connect with the edit token: ws://ADDRESS/?token=TOKEN (nerve foxglove printed it, or it is \
             the one in NERVE_FOXGLOVE_TOKEN)"
        ));
    }
    None
}

/// A client's binary frame: a message to publish, or a service call.
fn publish(hub: &Hub, client: &Arc<Client>, tx: &Sender<Request>, frame: &[u8]) {
    if frame.first() == Some(&services::OP_SERVICE_CALL_REQUEST) {
        return services::request(hub, client, tx, frame);
    }
    let Some((channel, payload)) = protocol::client_message_data(frame) else {
        client.error("a binary frame that is not a client message (opcode 1, channel id, payload) was ignored");
        return;
    };
    if let Some(why) = edit_refused(hub, client, "publish") {
        client.error(&why);
        return;
    }
    let topic = lock(&client.publishing).get(&channel).cloned();
    match topic {
        Some(topic) => {
            hub.ask(tx, Request::Publish { client: Arc::clone(client), topic, payload: payload.to_vec() });
        }
        None => client.error(&format!("channel {channel} was not advertised by this client (or was refused)")),
    }
}

/// Brings the channels up to date with the robot's output ports and tells
/// every client what came and went.
fn refresh_channels(hub: &Hub, robot: &mut dyn Robot) {
    let specs = match robot.channels() {
        Ok(s) => s,
        Err(e) => {
            tracing::debug!("no channels now: {e}");
            return;
        }
    };
    let mut channels = lock(&hub.channels);
    let wanted: BTreeMap<&str, &crate::ChannelSpec> = specs.iter().map(|s| (s.topic.as_str(), s)).collect();
    let mut removed = Vec::new();
    channels.by_topic.retain(|topic, c| {
        let same = wanted.get(topic.as_str()).is_some_and(|s| s.schema == c.schema && s.schema_name == c.schema_name);
        if !same {
            removed.push(c.id);
        }
        same
    });
    let mut added = Vec::new();
    for s in &specs {
        if channels.by_topic.contains_key(&s.topic) {
            continue;
        }
        channels.next_id = channels.next_id.wrapping_add(1);
        let c = Channel {
            id: channels.next_id,
            topic: s.topic.clone(),
            encoding: "json".into(),
            schema_name: s.schema_name.clone(),
            schema: s.schema.clone(),
            schema_encoding: "jsonschema".into(),
        };
        added.push(c.clone());
        channels.by_topic.insert(s.topic.clone(), c);
    }
    if removed.is_empty() && added.is_empty() {
        return;
    }
    tracing::info!(added = added.len(), removed = removed.len(), "channels changed");
    let clients = lock(&hub.clients);
    for c in clients.values() {
        if !removed.is_empty() {
            lock(&c.subs).retain(|_, ch| !removed.contains(ch));
            c.say(protocol::unadvertise(&removed));
        }
        if !added.is_empty() {
            c.say(protocol::advertise(&added));
        }
    }
}

/// Reads the subscribed ports and queues each sample for its subscribers.
fn read_ports(hub: &Hub, robot: &mut dyn Robot) {
    // channel id -> [(client, subscription)]
    let mut fan: HashMap<u32, Vec<(Arc<Client>, u32)>> = HashMap::new();
    for c in lock(&hub.clients).values() {
        for (&sub, &ch) in lock(&c.subs).iter() {
            fan.entry(ch).or_default().push((Arc::clone(c), sub));
        }
    }
    let topics: Vec<(String, u32)> = {
        let channels = lock(&hub.channels);
        channels.by_topic.values().filter(|c| fan.contains_key(&c.id)).map(|c| (c.topic.clone(), c.id)).collect()
    };
    let names: Vec<&str> = topics.iter().map(|(t, _)| t.as_str()).collect();
    let queue = hub.opts.queue.max(1);
    // the clients that got something: woken once each, after the read
    let mut fed: BTreeMap<u64, Arc<Client>> = BTreeMap::new();
    robot.read(&names, &mut |topic, unix_ns, payload| {
        let Some(ch) = topics.iter().find(|(t, _)| t == topic).map(|(_, c)| *c) else { return };
        let payload = Arc::new(payload);
        for (c, sub) in fan.get(&ch).into_iter().flatten() {
            let d = Data { subscription: *sub, unix_ns, payload: Arc::clone(&payload) };
            if lock(&c.out).push_data(d, queue) {
                hub.dropped_messages.fetch_add(1, Ordering::Relaxed);
            }
            fed.entry(c.id).or_insert_with(|| Arc::clone(c));
        }
    });
    for c in fed.values() {
        c.wake.wake();
    }
}

/// Answers a request that needs the robot.
fn answer(hub: &Hub, robot: &mut dyn Robot, req: Request, params: &mut ParamState) {
    match req {
        Request::Get { client, names, id } => match robot.parameters() {
            Ok(all) => {
                let chosen: Vec<Parameter> =
                    all.into_iter().filter(|p| names.is_empty() || names.contains(&p.name)).collect();
                client.say(protocol::parameter_values(&chosen, id.as_deref()));
            }
            Err(e) => client.error(&format!("cannot read the parameters: {e}")),
        },
        Request::Set { client, parameters, id } => {
            let mut done = Vec::new();
            for p in &parameters {
                match robot.set_parameter(&p.name, &p.value) {
                    Ok(()) => {
                        tracing::info!(client = client.id, name = %p.name, value = %p.value, "parameter set");
                        done.push(p.name.clone());
                    }
                    Err(e) => client.error(&format!("{} was not set to {}: {e}", p.name, p.value)),
                }
            }
            if id.is_some() {
                let all = robot.parameters().unwrap_or_default();
                let values: Vec<Parameter> = all.into_iter().filter(|p| done.contains(&p.name)).collect();
                client.say(protocol::parameter_values(&values, id.as_deref()));
            }
        }
        Request::Advertise { client, channels } => {
            for ch in channels {
                if ch.encoding != "json" {
                    lock(&client.publishing).remove(&ch.id);
                    client.error(&format!(
                        "channel {} ({}) is in {:?}: nerve foxglove takes json",
                        ch.id, ch.topic, ch.encoding
                    ));
                    continue;
                }
                match robot.input(&ch.topic) {
                    Ok(type_name) => {
                        tracing::info!(client = client.id, topic = %ch.topic, type_name, "client publishes");
                    }
                    Err(e) => {
                        lock(&client.publishing).remove(&ch.id);
                        client.error(&format!("cannot publish on {}: {e}", ch.topic));
                    }
                }
            }
        }
        Request::Publish { client, topic, payload } => {
            if let Err(e) = robot.publish(&topic, &payload) {
                client.error(&format!("a message for {topic} was refused: {e}"));
            }
        }
        Request::Graph { client } => match Graph::read(hub, robot) {
            // the whole graph to the new watcher; the others hear of changes only
            Ok(g) => client.say(graph_update(&g, &[], &[])),
            Err(e) => client.error(&format!("cannot read the connection graph: {e}")),
        },
        Request::Call(call) => services::call(hub, robot, call),
        Request::WatchParams => params.refresh(hub, robot),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_origins_and_the_given_ones_are_allowed() {
        let allowed = vec!["https://app.foxglove.dev".to_owned()];
        for ok in ["http://localhost:8080", "http://127.0.0.1", "https://[::1]:3000", "https://app.foxglove.dev"] {
            assert!(origin_allowed(ok, &allowed), "{ok} refused");
        }
        for bad in ["https://evil.example", "http://localhost.evil.example", "null", "file://", "http://[::2]:1"] {
            assert!(!origin_allowed(bad, &allowed), "{bad} allowed");
        }
    }

    #[test]
    fn the_token_comes_from_the_query_and_is_compared_exactly() {
        assert_eq!(query_token(Some("a=1&token=abc")), Some("abc"));
        assert_eq!(query_token(Some("xtoken=abc")), None);
        assert_eq!(query_token(None), None);
        assert!(token_matches("abcdef", "abcdef"));
        assert!(!token_matches("abcdeg", "abcdef"));
        assert!(!token_matches("abc", "abcdef"));
    }

    #[test]
    fn a_full_queue_drops_its_oldest_and_counts_it() {
        let mut out = Outbox::default();
        let d = |n: u64| Data { subscription: 1, unix_ns: n, payload: Arc::new(Vec::new()) };
        assert!(!out.push_data(d(1), 2));
        assert!(!out.push_data(d(2), 2));
        assert!(out.push_data(d(3), 2));
        assert_eq!(out.dropped, 1);
        let kept: Vec<u64> = out.data.iter().map(|d| d.unix_ns).collect();
        assert_eq!(kept, [2, 3], "the newest are kept");
    }
}
