//! A client's side of the server: what is queued for it ([`Outbox`]:
//! control messages never dropped, message data bounded with the oldest
//! dropped and counted), and its thread: handshake, registration (server
//! info, channels and services told before it can be fanned out to), then
//! requests in and queued messages out on a non-blocking socket, with
//! pings and the stall timeout that disconnects a client that stopped
//! reading.

use super::handshake::handshake;
use super::requests::{Request, publish, request};
use super::{Hub, lock, services};
use crate::protocol::{self, Level};
use crate::wake::{Interest, Wake, wait_fds};
use serde_json::json;
use std::collections::{BTreeSet, HashMap, VecDeque};
use std::io::ErrorKind;
use std::net::{SocketAddr, TcpStream};
use std::os::fd::AsRawFd as _;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tungstenite::{Message, WebSocket};

/// Requests read from a client in a row before its queue is looked at.
const READS_IN_A_ROW: usize = 64;
/// Messages written per batch.
const BATCH: usize = 64;
/// Control messages a client may have waiting before it is disconnected.
const CONTROL_MAX: usize = 4096;
/// Seconds between two drop reports to a client.
const DROP_REPORT: Duration = Duration::from_secs(2);
/// How often a client is pinged: one that does not answer within the
/// stall timeout has stopped reading (WebSocket clients answer pings
/// themselves, browsers included).
const PING_EVERY: Duration = Duration::from_millis(500);

/// A queued message data frame.
pub(super) struct Data {
    pub(super) subscription: u32,
    pub(super) unix_ns: u64,
    pub(super) payload: Arc<Vec<u8>>,
}

/// What waits to be written to a client.
#[derive(Default)]
pub(super) struct Outbox {
    /// text frames, and the binary answers of service calls
    pub(super) control: VecDeque<Message>,
    pub(super) data: VecDeque<Data>,
    pub(super) dropped: u64,
}

impl Outbox {
    /// Queues `d`; when `queue` messages already wait, the oldest is
    /// dropped (and counted) instead of the robot waiting. Whether one was.
    pub(super) fn push_data(&mut self, d: Data, queue: usize) -> bool {
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
pub(super) struct Client {
    pub(super) id: u64,
    pub(super) peer: SocketAddr,
    /// may set parameters and publish
    pub(super) edit: bool,
    pub(super) out: Mutex<Outbox>,
    /// subscription id -> channel id
    pub(super) subs: Mutex<HashMap<u32, u32>>,
    /// client channel id -> input port topic
    pub(super) publishing: Mutex<HashMap<u32, String>>,
    pub(super) graph: AtomicBool,
    /// the parameters whose changes it is sent
    pub(super) params: Mutex<BTreeSet<String>>,
    /// its service calls in flight
    pub(super) calls: AtomicUsize,
    pub(super) gone: AtomicBool,
    /// wakes its thread: something was queued for it, or the server stops
    pub(super) wake: Wake,
}

impl Client {
    pub(super) fn say(&self, text: String) {
        self.queue(Message::text(text));
    }

    pub(super) fn say_binary(&self, frame: Vec<u8>) {
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

    pub(super) fn error(&self, message: &str) {
        tracing::info!(client = self.id, peer = %self.peer, "refused: {message}");
        self.say(protocol::status(Level::Error, message));
    }
}

/// A client's thread: handshake, then requests in, queued messages out.
pub(super) fn thread(stream: TcpStream, peer: SocketAddr, hub: &Hub, tx: &Sender<Request>) {
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

#[cfg(test)]
mod tests {
    use super::*;

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
