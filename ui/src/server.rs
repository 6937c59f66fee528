//! The HTTP server of `nerve ui`.
//!
//! One thread accepts connections on a plain `TcpListener`; each connection
//! gets a thread of its own, reads one request through [`crate::http`]
//! (bounded in size and time) and is answered with `Connection: close`. At
//! most [`Options::max_connections`] connections are served at once (more
//! are answered 503 at once), of which at most [`Options::max_clients`]
//! event streams. Requests for the robot go, with a channel to answer on,
//! to the thread that called [`serve`]; that thread also reads the graph
//! once per interval and publishes it to every open event stream
//! (`/api/events`, server-sent events). After an action the graph is read
//! again at once, so the page shows its effect without waiting.
//!
//! Every request is checked before it is routed:
//! - `Host` must name this server: the bound address, `localhost`,
//!   `127.0.0.1` or `[::1]` with the port, or a name given with
//!   `--allow-host` (DNS rebinding); otherwise 403;
//! - `Origin`, when sent, must be this server's own (`http://` + its
//!   `Host`); otherwise 403;
//! - every `/api/*` route needs a token (401 without): the read token or
//!   the edit token to watch, in the `X-Nerve-Token` header or in the
//!   cookie set when the page is opened with `/?token=...` (`HttpOnly`,
//!   `SameSite=Strict`, and holding the read token only: `EventSource` and
//!   `<img>` cannot send headers); an action needs the edit token in the
//!   header (a cookie is never enough, so no other page can make the
//!   browser act).
//!
//! Exit never waits for a connection: the robot's channel closes (pending
//! requests are answered "stopping"), the event streams are woken and end,
//! and a stream whose reader stalled ends at its write timeout.
//!
//! Routes:
//! - `GET /`, `/app.js`, `/style.css`: the page;
//! - `GET /api/info`: the robot's name, whether the page may edit;
//! - `GET /api/graph`: the graph now; `GET /api/events`: the graph as it changes;
//! - `GET /api/kinds`, `/api/samples?port=A/P&after=N`, `/api/image?port=A/P`;
//! - `POST /api/action`: an [`Action`], with the edit token in `X-Nerve-Token`.

use crate::action::Action;
use crate::http::{self, LIMITS, Request};
use crate::{Robot, assets, token};
use serde_json::{Value, json};
use std::io::Write;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::time::{Duration, Instant};

#[cfg(test)]
mod proptests;

/// How `nerve ui` serves.
#[derive(Debug, Clone)]
pub struct Options {
    /// where to listen (127.0.0.1 unless told otherwise)
    pub bind: SocketAddr,
    /// refuse every action, and say so to the page
    pub read_only: bool,
    /// how often the graph is read and sent to the pages
    pub interval: Duration,
    /// the edit token (also lets its holder watch)
    pub token: String,
    /// the read token: watching only
    pub read_token: String,
    /// the robot's name, for the page's title
    pub robot: String,
    /// open event streams at most (browser tabs)
    pub max_clients: usize,
    /// connections served at once at most (event streams included)
    pub max_connections: usize,
    /// how long a request may take to arrive, from the connection on
    pub idle_timeout: Duration,
    /// how long a write to a page may be stuck (a reader that stopped
    /// reading) before its connection is dropped ([`WRITE_TIMEOUT`] by default)
    pub write_timeout: Duration,
    /// host names (besides the bound address and loopback) the page may be
    /// reached by: `robot.local` or `robot.local:8080`
    pub allowed_hosts: Vec<String>,
}

/// Why `nerve ui` cannot serve.
#[derive(Debug, thiserror::Error)]
pub enum UiError {
    /// The address is taken or not ours.
    #[error(
        "cannot listen on {addr}: {source}; is another `nerve ui` (or another server) using it? choose another address with --bind"
    )]
    Bind {
        /// the address asked for
        addr: SocketAddr,
        /// the socket's error
        #[source]
        source: std::io::Error,
    },
    /// A thread of the server could not be started.
    #[error("cannot start a thread of the server: {0}")]
    Thread(#[source] std::io::Error),
}

/// How long a worker waits for the robot's thread to answer.
const ROBOT_TIMEOUT: Duration = Duration::from_secs(30);
/// The least time between two reads of the graph, however slow the last was.
const MIN_PAUSE: Duration = Duration::from_millis(20);
/// A comment line on an idle event stream at least this often, so that a
/// closed browser is noticed.
const KEEP_ALIVE: Duration = Duration::from_secs(10);
/// A write that cannot go on this long (a reader that stopped reading)
/// drops the connection: the default of [`Options::write_timeout`].
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

/// A request for the robot's thread.
enum Call {
    Graph,
    Act(Action),
    Samples { port: String, after: u64 },
    Image { port: String },
    Kinds,
}

/// The robot's thread's answer.
enum Answer {
    Json(Value),
    Png(Vec<u8>),
}

type Reply = Result<Answer, String>;
type Calls = mpsc::Sender<(Call, mpsc::SyncSender<Reply>)>;

/// The latest graph, published to the event streams.
#[derive(Default)]
struct Hub {
    state: Mutex<HubState>,
    changed: Condvar,
}

#[derive(Default)]
struct HubState {
    seq: u64,
    json: Arc<String>,
    closed: bool,
    clients: usize,
}

impl Hub {
    fn lock(&self) -> std::sync::MutexGuard<'_, HubState> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn publish(&self, mut snapshot: Value) {
        let mut s = self.lock();
        s.seq += 1;
        snapshot["seq"] = json!(s.seq);
        s.json = Arc::new(snapshot.to_string());
        drop(s);
        self.changed.notify_all();
    }

    fn close(&self) {
        self.lock().closed = true;
        self.changed.notify_all();
    }

    /// Waits for a graph newer than `seen`; `None` once closed.
    fn next_after(&self, seen: u64, wait: Duration) -> Option<(u64, Arc<String>)> {
        let s = self.lock();
        let (s, _) = self
            .changed
            .wait_timeout_while(s, wait, |s| !s.closed && s.seq == seen)
            .unwrap_or_else(PoisonError::into_inner);
        if s.closed { None } else { Some((s.seq, s.json.clone())) }
    }
}

/// What the connection threads share.
struct Shared {
    opts: Options,
    hub: Hub,
    stopping: AtomicBool,
    connections: AtomicUsize,
    /// `Host` values accepted, lower case
    hosts: Vec<String>,
    /// the cookie carrying the token: one name per port, so that two
    /// servers on one host do not overwrite each other's
    cookie: String,
}

/// Takes one from a counter when dropped (also when a thread panics).
struct Slot<'a>(&'a AtomicUsize);
impl Drop for Slot<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// What a request may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Access {
    None,
    Read,
    Edit,
}

/// The `Host` values that name this server.
fn accepted_hosts(local: SocketAddr, allowed: &[String]) -> Vec<String> {
    let port = local.port();
    let mut hosts =
        vec![local.to_string(), format!("localhost:{port}"), format!("127.0.0.1:{port}"), format!("[::1]:{port}")];
    for name in allowed {
        hosts.push(name.clone());
        if !name.ends_with(&format!(":{port}")) {
            hosts.push(format!("{name}:{port}"));
        }
    }
    hosts.iter_mut().for_each(|h| h.make_ascii_lowercase());
    hosts.sort();
    hosts.dedup();
    hosts
}

/// Serves the page until `should_stop` says so (checked every 100 ms),
/// answering the robot's calls on this thread. `listening` is told the
/// address once the socket is open (the port, when 0 was asked for). The
/// accepting thread has ended when it returns; connections still open end
/// by themselves (see the module doc) and are not waited for.
pub fn serve(
    opts: &Options,
    robot: &mut dyn Robot,
    listening: &mut dyn FnMut(SocketAddr),
    should_stop: &dyn Fn() -> bool,
) -> Result<(), UiError> {
    let listener = TcpListener::bind(opts.bind).map_err(|source| UiError::Bind { addr: opts.bind, source })?;
    let local = listener.local_addr().unwrap_or(opts.bind);
    let shared = Arc::new(Shared {
        opts: opts.clone(),
        hub: Hub::default(),
        stopping: AtomicBool::new(false),
        connections: AtomicUsize::new(0),
        hosts: accepted_hosts(local, &opts.allowed_hosts),
        cookie: format!("nerve_ui_{}", local.port()),
    });
    let (tx, rx) = mpsc::channel();
    let acceptor = {
        let sh = shared.clone();
        std::thread::Builder::new()
            .name("ui-accept".into())
            .spawn(move || accept(&listener, &sh, &tx))
            .map_err(UiError::Thread)?
    };
    listening(local);
    let mut next_read = Instant::now();
    while !should_stop() {
        let now = Instant::now();
        if now >= next_read {
            robot.tick();
            shared.hub.publish(snapshot(robot));
            // from when this read began: a slow router does not stretch the interval
            next_read = (now + opts.interval).max(Instant::now() + MIN_PAUSE);
        }
        let wait = next_read.saturating_duration_since(Instant::now()).min(Duration::from_millis(100));
        match rx.recv_timeout(wait) {
            Ok((call, reply)) => {
                let acted = matches!(call, Call::Act(_));
                let _ = reply.send(answer(robot, call));
                if acted {
                    next_read = Instant::now();
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    shared.stopping.store(true, Ordering::SeqCst);
    shared.hub.close();
    drop(rx);
    // wake the accepting thread with a connection of our own
    let wake = match local.ip() {
        IpAddr::V4(ip) if ip.is_unspecified() => SocketAddr::new(Ipv4Addr::LOCALHOST.into(), local.port()),
        IpAddr::V6(ip) if ip.is_unspecified() => SocketAddr::new(Ipv6Addr::LOCALHOST.into(), local.port()),
        _ => local,
    };
    match TcpStream::connect_timeout(&wake, Duration::from_secs(1)) {
        Ok(_) => {
            let _ = acceptor.join();
        }
        Err(e) => tracing::warn!(error = %e, addr = %wake, "cannot wake the accepting thread; leaving it"),
    }
    let open = shared.connections.load(Ordering::SeqCst);
    if open > 0 {
        tracing::debug!(open, "connections still open at exit end by themselves");
    }
    Ok(())
}

/// The accepting thread: admits connections up to the limit.
fn accept(listener: &TcpListener, shared: &Arc<Shared>, calls: &Calls) {
    for conn in listener.incoming() {
        if shared.stopping.load(Ordering::SeqCst) {
            return;
        }
        let stream = match conn {
            Ok(s) => s,
            Err(e) => {
                // out of descriptors, or a connection reset before it was taken
                tracing::warn!(error = %e, "cannot accept a connection");
                std::thread::sleep(Duration::from_millis(50));
                continue;
            }
        };
        let _ = stream.set_write_timeout(Some(shared.opts.write_timeout));
        let _ = stream.set_nodelay(true);
        if shared.connections.fetch_add(1, Ordering::SeqCst) >= shared.opts.max_connections {
            shared.connections.fetch_sub(1, Ordering::SeqCst);
            let remote = stream.peer_addr().ok();
            tracing::warn!(?remote, limit = shared.opts.max_connections, "too many connections: refused with 503");
            let _ = stream.set_write_timeout(Some(Duration::from_secs(1)));
            let message = "too many connections to this nerve ui; close a page or try again";
            send_error(stream, 503, message);
            continue;
        }
        let (sh, calls) = (shared.clone(), calls.clone());
        let spawned = std::thread::Builder::new().name("ui-conn".into()).spawn(move || {
            let _slot = Slot(&sh.connections);
            connection(stream, &sh, &calls);
        });
        if let Err(e) = spawned {
            // the closure (and its slot) never ran
            shared.connections.fetch_sub(1, Ordering::SeqCst);
            tracing::warn!(error = %e, "cannot start a thread for a connection");
        }
    }
}

/// One connection: one request, one answer.
fn connection(mut stream: TcpStream, shared: &Arc<Shared>, calls: &Calls) {
    let req = match http::read_request(&mut stream, &LIMITS, shared.opts.idle_timeout) {
        Ok(r) => r,
        Err(e) => {
            let remote = stream.peer_addr().ok();
            tracing::debug!(?remote, error = %e, "a request was not read");
            if let (Some(status), Ok(answer)) = (e.status(), stream.try_clone()) {
                send_error(answer, status, &e.to_string());
                drain(&mut stream);
            }
            return;
        }
    };
    handle(stream, &req, shared, calls);
}

/// Reads and drops what the client still sends after a refusal (at most
/// 256 KiB, for at most a second), so that closing the socket does not reset
/// the connection before the client has read the answer.
fn drain(stream: &mut TcpStream) {
    use std::io::Read;
    let until = Instant::now() + Duration::from_secs(1);
    let mut buf = [0u8; 8192];
    let mut left = 256 * 1024usize;
    while left > 0 {
        let wait = until.saturating_duration_since(Instant::now());
        if wait.is_zero() || stream.set_read_timeout(Some(wait)).is_err() {
            return;
        }
        match stream.read(&mut buf) {
            Ok(0) | Err(_) => return,
            Ok(n) => left = left.saturating_sub(n),
        }
    }
}

/// An answer: the head, then the body; `Connection: close`.
fn send_with(mut stream: TcpStream, status: u16, content_type: &str, extra: &[(&str, &str)], body: &[u8]) {
    let mut head = format!(
        "HTTP/1.1 {status} {}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nConnection: close\r\n\
         Cache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nX-Frame-Options: DENY\r\n\
         Referrer-Policy: no-referrer\r\n",
        http::reason(status),
        body.len()
    );
    for (name, value) in extra {
        head.push_str(&format!("{name}: {value}\r\n"));
    }
    head.push_str("\r\n");
    let written = stream.write_all(head.as_bytes()).and_then(|()| stream.write_all(body)).and_then(|()| stream.flush());
    if let Err(e) = written {
        tracing::debug!(error = %e, "a browser left before its answer");
    }
    // the rest of what the client sent is not read: close our side cleanly
    let _ = stream.shutdown(std::net::Shutdown::Write);
}

fn send(stream: TcpStream, status: u16, content_type: &str, body: &[u8]) {
    send_with(stream, status, content_type, &[], body);
}

fn send_json(stream: TcpStream, status: u16, v: &Value) {
    send(stream, status, "application/json", v.to_string().as_bytes());
}

fn send_error(stream: TcpStream, status: u16, message: &str) {
    send_json(stream, status, &json!({ "error": message }));
}

/// The graph as the pages receive it.
fn snapshot(robot: &mut dyn Robot) -> Value {
    let unix_ms = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX));
    match robot.graph() {
        Ok(graph) => json!({ "unix_ms": unix_ms, "graph": graph }),
        Err(error) => json!({ "unix_ms": unix_ms, "error": error }),
    }
}

fn answer(robot: &mut dyn Robot, call: Call) -> Reply {
    match call {
        Call::Graph => robot.graph().map(Answer::Json),
        Call::Act(a) => robot.act(a).map(Answer::Json),
        Call::Samples { port, after } => robot.samples(&port, after).map(Answer::Json),
        Call::Image { port } => robot.image(&port).map(Answer::Png),
        Call::Kinds => Ok(Answer::Json(json!(robot.kinds()))),
    }
}

/// `path?a=1&b=2` split, the values percent-decoded.
fn split_url(url: &str) -> (&str, Vec<(String, String)>) {
    let (path, query) = url.split_once('?').unwrap_or((url, ""));
    let pairs = query
        .split('&')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let (k, v) = p.split_once('=').unwrap_or((p, ""));
            (percent_decode(k), percent_decode(v))
        })
        .collect();
    (path, pairs)
}

fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while let Some(&b) = bytes.get(i) {
        let hex = bytes.get(i + 1..i + 3).and_then(|h| std::str::from_utf8(h).ok());
        match (b, hex.map(|h| u8::from_str_radix(h, 16))) {
            (b'%', Some(Ok(b))) => {
                out.push(b);
                i += 3;
            }
            (b'+', _) => {
                out.push(b' ');
                i += 1;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn query<'a>(pairs: &'a [(String, String)], key: &str) -> Option<&'a str> {
    pairs.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
}

impl Shared {
    /// What a presented token allows.
    fn access_of(&self, presented: &str) -> Access {
        if token::matches(presented, &self.opts.token) {
            Access::Edit
        } else if token::matches(presented, &self.opts.read_token) {
            Access::Read
        } else {
            Access::None
        }
    }

    /// The token in the `X-Nerve-Token` header.
    fn header_access(&self, req: &Request) -> Access {
        req.header("X-Nerve-Token").map_or(Access::None, |t| self.access_of(t))
    }

    /// The token in the header, or this server's cookie (which carries the
    /// read token only, and so never allows more than watching).
    fn access(&self, req: &Request) -> Access {
        let cookie = req
            .headers_named("Cookie")
            .flat_map(|c| c.split(';'))
            .filter_map(|c| c.trim().split_once('='))
            .any(|(name, value)| name == self.cookie && token::matches(value, &self.opts.read_token));
        self.header_access(req).max(if cookie { Access::Read } else { Access::None })
    }

    /// Refuses a request by a name that is not this server's, or from
    /// another site's page: the reason, or `None` if it may go on.
    fn foreign(&self, req: &Request) -> Option<String> {
        let Some(host) = req.header("Host") else {
            return Some("a request without a Host header is refused".into());
        };
        let host_lower = host.to_ascii_lowercase();
        if !self.hosts.contains(&host_lower) {
            return Some(format!(
                "this nerve ui does not answer to the name {host:?}: open it by its address or localhost \
                 (or start it with --allow-host NAME for another name)"
            ));
        }
        match req.header("Origin") {
            Some(origin) if !origin.eq_ignore_ascii_case(&format!("http://{host}")) => {
                Some(format!("requests from the page of another site ({origin:?}) are refused"))
            }
            _ => None,
        }
    }
}

fn handle(stream: TcpStream, req: &Request, shared: &Arc<Shared>, calls: &Calls) {
    let (path, pairs) = split_url(&req.target);
    let remote = stream.peer_addr().ok();
    tracing::debug!(method = %req.method, path = %path, ?remote, "request");
    if let Some(why) = shared.foreign(req) {
        tracing::warn!(?remote, host = ?req.header("Host"), origin = ?req.header("Origin"), "refused: {why}");
        return send_error(stream, 403, &why);
    }
    let method = req.method.as_str();
    if !path.starts_with("/api/") {
        return match (method, path) {
            ("GET", "/" | "/index.html") => page(stream, shared, query(&pairs, "token")),
            ("GET", "/app.js") => send(stream, 200, "text/javascript; charset=utf-8", assets::APP_JS.as_bytes()),
            ("GET", "/style.css") => send(stream, 200, "text/css; charset=utf-8", assets::STYLE_CSS.as_bytes()),
            _ => send_error(stream, 404, &format!("nothing at {path}")),
        };
    }
    let access = shared.access(req);
    if access == Access::None {
        tracing::warn!(?remote, path, "a request without the right token was refused");
        return send_error(
            stream,
            401,
            "this needs a token of `nerve ui`: open the address it printed (ending in ?token=...), \
             or send the token in the X-Nerve-Token header",
        );
    }
    match (method, path) {
        ("GET", "/api/info") => {
            let editable = !shared.opts.read_only && shared.header_access(req) == Access::Edit;
            let info = json!({
                "robot": shared.opts.robot,
                "read_only": shared.opts.read_only,
                "editable": editable,
                "interval_ms": u64::try_from(shared.opts.interval.as_millis()).unwrap_or(u64::MAX),
            });
            send_json(stream, 200, &info);
        }
        ("GET", "/api/events") => event_stream(stream, shared),
        ("GET", "/api/graph") => reply(stream, ask(calls, Call::Graph)),
        ("GET", "/api/kinds") => reply(stream, ask(calls, Call::Kinds)),
        ("GET", "/api/samples") => {
            let Some(port) = query(&pairs, "port").map(str::to_owned) else {
                return send_error(stream, 400, "say which port: /api/samples?port=AGENT/PORT");
            };
            let after = query(&pairs, "after").and_then(|a| a.parse().ok()).unwrap_or(0);
            reply(stream, ask(calls, Call::Samples { port, after }));
        }
        ("GET", "/api/image") => {
            let Some(port) = query(&pairs, "port").map(str::to_owned) else {
                return send_error(stream, 400, "say which port: /api/image?port=AGENT/PORT");
            };
            reply(stream, ask(calls, Call::Image { port }));
        }
        ("POST", "/api/action") => act(stream, req, shared, calls),
        (_, "/api/action") => send_error(stream, 405, "an action is a POST"),
        _ => send_error(stream, 404, &format!("nothing at {path}")),
    }
}

/// `GET /`: the page; opened with a right token, it also sets the cookie
/// that the page's event stream and images carry. The cookie holds the read
/// token whichever token opened the page: browsers send a host's cookies to
/// every port of it (RFC 6265, 8.5), so another server on this host that
/// the browser visits could read it, and it must never allow an action.
fn page(stream: TcpStream, shared: &Shared, presented: Option<&str>) {
    let html = assets::INDEX_HTML.as_bytes();
    let kind = "text/html; charset=utf-8";
    match presented.filter(|t| shared.access_of(t) != Access::None) {
        Some(_) => {
            let cookie = format!("{}={}; HttpOnly; SameSite=Strict; Path=/api/", shared.cookie, shared.opts.read_token);
            send_with(stream, 200, kind, &[("Set-Cookie", &cookie)], html);
        }
        None => send(stream, 200, kind, html),
    }
}

fn reply(stream: TcpStream, answer: Reply) {
    match answer {
        Ok(Answer::Json(v)) => send_json(stream, 200, &v),
        Ok(Answer::Png(png)) => send(stream, 200, "image/png", &png),
        Err(e) => send_error(stream, 409, &e),
    }
}

/// Asks the robot's thread and waits for its answer.
fn ask(calls: &Calls, call: Call) -> Reply {
    let (tx, rx) = mpsc::sync_channel(1);
    calls.send((call, tx)).map_err(|_| "nerve ui is stopping".to_string())?;
    rx.recv_timeout(ROBOT_TIMEOUT).map_err(|_| "the robot did not answer in time".to_string())?
}

/// Why a kind may not be started from the page, if it may not.
fn refused_kind(kind: &str, known: &[String]) -> Option<String> {
    if kind.contains('/') {
        return Some(format!(
            "the page starts only agent kinds installed next to nerve, not paths ({kind:?}); \
             start a program by its path with `nerve start PATH` on the robot"
        ));
    }
    if !known.iter().any(|k| k == kind) {
        let list = if known.is_empty() { "none found".to_owned() } else { known.join(", ") };
        return Some(format!("unknown agent kind {kind:?}: the kinds this robot knows are {list}"));
    }
    None
}

/// `POST /api/action`: refused in read-only mode and without the edit token.
fn act(stream: TcpStream, req: &Request, shared: &Shared, calls: &Calls) {
    if shared.opts.read_only {
        return send_error(stream, 403, "this nerve ui is read-only (started with --read-only): it changes nothing");
    }
    match shared.header_access(req) {
        Access::Edit => {}
        Access::Read => {
            return send_error(stream, 403, "the read token watches only: actions need the edit token");
        }
        Access::None => {
            tracing::warn!(remote = ?stream.peer_addr().ok(), "an action without the edit token was refused");
            return send_error(
                stream,
                401,
                "an action needs the edit token of `nerve ui` in the X-Nerve-Token header: open the address it \
                 printed (ending in ?token=...)",
            );
        }
    }
    let action: Action = match serde_json::from_slice(&req.body) {
        Ok(a) => a,
        Err(e) => return send_error(stream, 400, &format!("not an action: {e}")),
    };
    if let Action::Start { kind, .. } = &action {
        let known = match ask(calls, Call::Kinds) {
            Ok(Answer::Json(v)) => serde_json::from_value::<Vec<String>>(v).unwrap_or_default(),
            Ok(Answer::Png(_)) => Vec::new(),
            Err(e) => return send_error(stream, 409, &e),
        };
        if let Some(why) = refused_kind(kind, &known) {
            tracing::warn!(kind = %kind, "hot add of an unknown kind refused");
            return send_error(stream, 400, &why);
        }
    }
    tracing::info!(?action, "action from the page");
    reply(stream, ask(calls, Call::Act(action)));
}

/// `GET /api/events`: the graph as server-sent events, on this connection's
/// thread, until the page goes, the server stops, or a write stalls for
/// [`Options::write_timeout`].
fn event_stream(mut stream: TcpStream, shared: &Shared) {
    {
        let mut s = shared.hub.lock();
        if s.clients >= shared.opts.max_clients {
            drop(s);
            return send_error(stream, 503, "too many pages are open on this nerve ui; close one");
        }
        s.clients += 1;
    }
    struct Client<'a>(&'a Hub);
    impl Drop for Client<'_> {
        fn drop(&mut self) {
            self.0.lock().clients -= 1;
        }
    }
    let _client = Client(&shared.hub);
    let head = "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\n\
                X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n";
    if stream.write_all(head.as_bytes()).and_then(|()| stream.flush()).is_err() {
        return;
    }
    let mut seen = 0;
    while !shared.stopping.load(Ordering::SeqCst) {
        let Some((seq, json)) = shared.hub.next_after(seen, KEEP_ALIVE) else { break };
        let written = if seq == seen {
            stream.write_all(b": keep-alive\n\n")
        } else {
            seen = seq;
            write!(stream, "id: {seq}\ndata: {json}\n\n")
        };
        if let Err(e) = written.and_then(|()| stream.flush()) {
            // the page was closed, or stopped reading for the write timeout
            tracing::debug!(error = %e, "an event stream ended");
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn queries_are_split_and_decoded() {
        let (path, q) = split_url("/api/samples?port=t1%2Ftick&after=7&x");
        assert_eq!(path, "/api/samples");
        assert_eq!(query(&q, "port"), Some("t1/tick"));
        assert_eq!(query(&q, "after"), Some("7"));
        assert_eq!(query(&q, "x"), Some(""));
        assert_eq!(percent_decode("a%2"), "a%2");
        assert_eq!(percent_decode("%zz+b"), "%zz b");
        assert_eq!(percent_decode("%41"), "A");
    }

    #[test]
    fn hosts_are_the_address_loopback_and_the_names_given() {
        let hosts = accepted_hosts("0.0.0.0:8080".parse().expect("addr"), &["Robot.local".into()]);
        for ok in ["0.0.0.0:8080", "localhost:8080", "127.0.0.1:8080", "[::1]:8080", "robot.local", "robot.local:8080"]
        {
            assert!(hosts.contains(&ok.to_owned()), "{ok} refused: {hosts:?}");
        }
        for bad in ["evil.example:8080", "localhost:8081", "127.0.0.1", "localhost"] {
            assert!(!hosts.contains(&bad.to_owned()), "{bad} accepted");
        }
    }

    #[test]
    fn only_known_kinds_without_a_slash_are_started() {
        let known = vec!["ticker".to_owned(), "relay".to_owned()];
        assert_eq!(refused_kind("ticker", &known), None);
        assert!(refused_kind("/tmp/x", &known).is_some_and(|m| m.contains("not paths")));
        assert!(refused_kind("./ticker", &known).is_some());
        assert!(refused_kind("gripper", &known).is_some_and(|m| m.contains("ticker, relay") || m.contains("ticker")));
    }
}
