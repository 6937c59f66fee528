//! The HTTP server of `nerve ui`.
//!
//! A few worker threads take requests from the socket. Requests for the
//! robot go, with a channel to answer on, to the thread that called
//! [`serve`]; that thread also reads the graph once per interval and
//! publishes it to every open event stream (`/api/events`, server-sent
//! events: one thread per browser, at most [`Options::max_clients`]).
//! After an action the graph is read again at once, so the page shows its
//! effect without waiting for the next interval.
//!
//! Routes:
//! - `GET /`, `/app.js`, `/style.css`: the page;
//! - `GET /api/info`: the robot's name, whether the page may edit;
//! - `GET /api/graph`: the graph now; `GET /api/events`: the graph as it changes;
//! - `GET /api/kinds`, `/api/samples?port=A/P&after=N`, `/api/image?port=A/P`;
//! - `POST /api/action`: an [`Action`], with the token in `X-Nerve-Token`.

use crate::action::Action;
use crate::{Robot, assets, token};
use serde_json::{Value, json};
use std::io::{Read, Write};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tiny_http::{Header, Method, Request, Response, Server};

/// How `nerve ui` serves.
#[derive(Debug, Clone)]
pub struct Options {
    /// where to listen (127.0.0.1 unless told otherwise)
    pub bind: SocketAddr,
    /// refuse every action, and say so to the page
    pub read_only: bool,
    /// how often the graph is read and sent to the pages
    pub interval: Duration,
    /// the editing token
    pub token: String,
    /// the robot's name, for the page's title
    pub robot: String,
    /// open event streams at most (browser tabs)
    pub max_clients: usize,
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
        /// tiny_http's error
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A thread of the server could not be started.
    #[error("cannot start a thread of the server: {0}")]
    Thread(#[source] std::io::Error),
}

/// Worker threads taking requests (event streams have their own).
const WORKERS: usize = 4;
/// The largest request body accepted (an action is a few hundred bytes).
const MAX_BODY: u64 = 64 * 1024;
/// How long a worker waits for the robot's thread to answer.
const ROBOT_TIMEOUT: Duration = Duration::from_secs(30);
/// The least time between two reads of the graph, however slow the last was.
const MIN_PAUSE: Duration = Duration::from_millis(20);
/// A comment line on an idle event stream at least this often, so that a
/// closed browser is noticed.
const KEEP_ALIVE: Duration = Duration::from_secs(10);

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

/// What the worker threads share.
struct Shared {
    opts: Options,
    hub: Hub,
    stopping: AtomicBool,
    streams: Mutex<Vec<JoinHandle<()>>>,
}

/// Serves the page until `should_stop` says so (checked every 100 ms),
/// answering the robot's calls on this thread. `listening` is told the
/// address once the socket is open (the port, when 0 was asked for). Every
/// thread it started has ended when it returns.
pub fn serve(
    opts: &Options,
    robot: &mut dyn Robot,
    listening: &mut dyn FnMut(SocketAddr),
    should_stop: &dyn Fn() -> bool,
) -> Result<(), UiError> {
    let server = Arc::new(Server::http(opts.bind).map_err(|source| UiError::Bind { addr: opts.bind, source })?);
    listening(server.server_addr().to_ip().unwrap_or(opts.bind));
    let shared = Arc::new(Shared {
        opts: opts.clone(),
        hub: Hub::default(),
        stopping: AtomicBool::new(false),
        streams: Mutex::new(Vec::new()),
    });
    let (tx, rx) = mpsc::channel();
    let mut workers = Vec::with_capacity(WORKERS);
    for i in 0..WORKERS {
        let (srv, sh, tx) = (server.clone(), shared.clone(), tx.clone());
        let spawned = std::thread::Builder::new().name(format!("ui-http-{i}")).spawn(move || work(&srv, &sh, &tx));
        match spawned {
            Ok(h) => workers.push(h),
            Err(e) => {
                shared.stopping.store(true, Ordering::SeqCst);
                workers.into_iter().for_each(|h| drop(h.join()));
                return Err(UiError::Thread(e));
            }
        }
    }
    drop(tx);
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
    for h in workers {
        let _ = h.join();
    }
    let streams = std::mem::take(&mut *shared.streams.lock().unwrap_or_else(PoisonError::into_inner));
    for h in streams {
        let _ = h.join();
    }
    Ok(())
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

/// A worker: takes requests until the server stops.
fn work(server: &Server, shared: &Arc<Shared>, calls: &Calls) {
    while !shared.stopping.load(Ordering::SeqCst) {
        match server.recv_timeout(Duration::from_millis(100)) {
            Ok(Some(req)) => handle(req, shared, calls),
            Ok(None) => {}
            Err(e) => {
                tracing::warn!(error = %e, "the HTTP server cannot take requests");
                return;
            }
        }
    }
}

fn send(req: Request, status: u16, content_type: &str, body: Vec<u8>) {
    let mut resp = Response::from_data(body).with_status_code(status);
    // the names and values are ASCII constants, which tiny_http always accepts
    for (name, value) in
        [("Content-Type", content_type), ("Cache-Control", "no-store"), ("X-Content-Type-Options", "nosniff")]
    {
        if let Ok(h) = Header::from_bytes(name.as_bytes(), value.as_bytes()) {
            resp.add_header(h);
        }
    }
    if let Err(e) = req.respond(resp) {
        tracing::debug!(error = %e, "a browser left before its answer");
    }
}

fn send_json(req: Request, status: u16, v: &Value) {
    send(req, status, "application/json", v.to_string().into_bytes());
}

fn send_error(req: Request, status: u16, message: &str) {
    send_json(req, status, &json!({ "error": message }));
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
    while i < bytes.len() {
        let hex = bytes.get(i + 1..i + 3).and_then(|h| std::str::from_utf8(h).ok());
        match (bytes[i], hex.map(|h| u8::from_str_radix(h, 16))) {
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

fn presented_token(req: &Request) -> Option<String> {
    req.headers().iter().find(|h| h.field.equiv("X-Nerve-Token")).map(|h| h.value.as_str().to_owned())
}

/// Asks the robot's thread and waits for its answer.
fn ask(calls: &Calls, call: Call) -> Reply {
    let (tx, rx) = mpsc::sync_channel(1);
    calls.send((call, tx)).map_err(|_| "nerve ui is stopping".to_string())?;
    rx.recv_timeout(ROBOT_TIMEOUT).map_err(|_| "the robot did not answer in time".to_string())?
}

fn handle(req: Request, shared: &Arc<Shared>, calls: &Calls) {
    let (path, pairs) = split_url(req.url());
    let path = path.to_owned();
    tracing::debug!(method = %req.method(), path = %path, "request");
    match (req.method(), path.as_str()) {
        (Method::Get, "/" | "/index.html") => {
            send(req, 200, "text/html; charset=utf-8", assets::INDEX_HTML.as_bytes().to_vec());
        }
        (Method::Get, "/app.js") => {
            send(req, 200, "text/javascript; charset=utf-8", assets::APP_JS.as_bytes().to_vec())
        }
        (Method::Get, "/style.css") => send(req, 200, "text/css; charset=utf-8", assets::STYLE_CSS.as_bytes().to_vec()),
        (Method::Get, "/api/info") => {
            let editable =
                !shared.opts.read_only && presented_token(&req).is_some_and(|t| token::matches(&t, &shared.opts.token));
            let info = json!({
                "robot": shared.opts.robot,
                "read_only": shared.opts.read_only,
                "editable": editable,
                "interval_ms": u64::try_from(shared.opts.interval.as_millis()).unwrap_or(u64::MAX),
            });
            send_json(req, 200, &info);
        }
        (Method::Get, "/api/events") => open_stream(req, shared),
        (Method::Get, "/api/graph") => reply(req, ask(calls, Call::Graph)),
        (Method::Get, "/api/kinds") => reply(req, ask(calls, Call::Kinds)),
        (Method::Get, "/api/samples") => {
            let Some(port) = query(&pairs, "port").map(str::to_owned) else {
                return send_error(req, 400, "say which port: /api/samples?port=AGENT/PORT");
            };
            let after = query(&pairs, "after").and_then(|a| a.parse().ok()).unwrap_or(0);
            reply(req, ask(calls, Call::Samples { port, after }));
        }
        (Method::Get, "/api/image") => {
            let Some(port) = query(&pairs, "port").map(str::to_owned) else {
                return send_error(req, 400, "say which port: /api/image?port=AGENT/PORT");
            };
            reply(req, ask(calls, Call::Image { port }));
        }
        (Method::Post, "/api/action") => act(req, shared, calls),
        (_, "/api/action") => send_error(req, 405, "an action is a POST"),
        _ => send_error(req, 404, &format!("nothing at {path}")),
    }
}

fn reply(req: Request, answer: Reply) {
    match answer {
        Ok(Answer::Json(v)) => send_json(req, 200, &v),
        Ok(Answer::Png(png)) => send(req, 200, "image/png", png),
        Err(e) => send_error(req, 409, &e),
    }
}

/// `POST /api/action`: refused in read-only mode and without the token.
fn act(mut req: Request, shared: &Arc<Shared>, calls: &Calls) {
    if shared.opts.read_only {
        return send_error(req, 403, "this nerve ui is read-only (started with --read-only): it changes nothing");
    }
    if !presented_token(&req).is_some_and(|t| token::matches(&t, &shared.opts.token)) {
        tracing::warn!(remote = ?req.remote_addr(), "an action without the right token was refused");
        return send_error(
            req,
            401,
            "editing needs the token `nerve ui` printed at start: open the address it printed (ending in ?token=...)",
        );
    }
    let mut body = String::new();
    if let Err(e) = req.as_reader().take(MAX_BODY).read_to_string(&mut body) {
        return send_error(req, 400, &format!("cannot read the request: {e}"));
    }
    let action: Action = match serde_json::from_str(&body) {
        Ok(a) => a,
        Err(e) => return send_error(req, 400, &format!("not an action: {e}")),
    };
    tracing::info!(?action, "action from the page");
    reply(req, ask(calls, Call::Act(action)));
}

/// `GET /api/events`: the graph as server-sent events, on a thread of its own.
fn open_stream(req: Request, shared: &Arc<Shared>) {
    {
        let mut s = shared.hub.lock();
        if s.clients >= shared.opts.max_clients {
            drop(s);
            return send_error(req, 503, "too many pages are open on this nerve ui; close one");
        }
        s.clients += 1;
    }
    let sh = shared.clone();
    let spawned = std::thread::Builder::new().name("ui-events".into()).spawn(move || {
        stream(req, &sh);
        sh.hub.lock().clients -= 1;
    });
    match spawned {
        Ok(h) => shared.streams.lock().unwrap_or_else(PoisonError::into_inner).push(h),
        Err(e) => {
            shared.hub.lock().clients -= 1;
            tracing::warn!(error = %e, "cannot start an event stream");
        }
    }
}

fn stream(req: Request, shared: &Shared) {
    let mut w = req.into_writer();
    let head =
        "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n";
    if w.write_all(head.as_bytes()).and_then(|()| w.flush()).is_err() {
        return;
    }
    let mut seen = 0;
    while !shared.stopping.load(Ordering::SeqCst) {
        let Some((seq, json)) = shared.hub.next_after(seen, KEEP_ALIVE) else { break };
        let written = if seq == seen {
            w.write_all(b": keep-alive\n\n")
        } else {
            seen = seq;
            write!(w, "id: {seq}\ndata: {json}\n\n")
        };
        if written.and_then(|()| w.flush()).is_err() {
            break; // the page was closed
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
}
