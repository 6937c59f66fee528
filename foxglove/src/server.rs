//! The server: a listener, a thread per client, and the serving thread
//! (the caller of [`serve`]) that owns the [`Robot`].
//!
//! - The handshake ([`handshake`]) refuses, with an HTTP status and a
//!   reason: a subprotocol other than [`SUBPROTOCOLS`](crate::protocol::SUBPROTOCOLS)
//!   (400), an `Origin` that is neither loopback nor given with
//!   `--allow-origin` (403), a wrong token (401), more clients than allowed
//!   (503).
//! - A client's thread ([`client`]) reads its requests and writes what the
//!   serving thread queued for it: control messages (never dropped) and
//!   message data (at most [`Options::queue`]; when full the oldest is
//!   dropped and counted). It writes a new batch only once the last one has
//!   left, so a client that stops reading holds at most one batch and its
//!   queue, and is disconnected when nothing left for
//!   [`Options::stall_timeout`].
//! - The serving thread (this file's [`serve`]) refreshes the channels
//!   ([`channels`]: advertise/unadvertise) and what clients watch
//!   (parameters, the graph: [`watched`]), reads the subscribed ports only
//!   and fans samples out to the queues ([`channels`]), answers parameter,
//!   graph and publish requests ([`requests`]), hands service calls to the
//!   robot ([`services`]), and never blocks on a client or a server.

use crate::Robot;
use crate::wake::{Interest, Wake, wait_fds};
use channels::{Channels, read_ports, refresh_channels};
use client::Client;
use requests::{Request, answer, edit_refused};
use std::collections::BTreeMap;
use std::io::ErrorKind;
use std::net::{SocketAddr, TcpListener};
use std::os::fd::{AsRawFd as _, RawFd};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use watched::{GraphState, ParamState};

mod channels;
mod client;
mod handshake;
mod requests;
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
    /// after a read that found samples, how long the serving thread lets
    /// the next ones gather before it reads again (requests still wake it):
    /// a port that publishes in a burst is read once per `gather`, not once
    /// per sample, and its senders pay no wake-up of this server meanwhile
    /// (an unread notice is not sent again). A lone sample is read at once.
    /// Zero: every sample wakes the server.
    pub gather: Duration,
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
            gather: GATHER,
        }
    }
}

/// How long samples gather between two reads of a busy port (see
/// [`Options::gather`]): under a viewer's frame (Foxglove draws at 60 Hz at
/// most), and a port's 16 buffered samples last it up to 1.6 kHz.
const GATHER: Duration = Duration::from_millis(10);

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
    pub(super) fn ask(&self, tx: &Sender<Request>, req: Request) {
        // the serving thread is gone only when the server stops
        let _ = tx.send(req);
        self.wake.wake();
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // a panicking client thread must not take the server with it
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
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
        let fed = read_ports(&hub, robot);
        threads.retain(|t| !t.is_finished());
        // until a sample, a request or a connection comes, or the next refresh is due (a stop
        // request is seen then at the latest; a signal ends the wait at once)
        let due = opts.refresh.saturating_sub(last_refresh.elapsed());
        let own = [hub.wake.fd(), listener.as_raw_fd()];
        if fed && !opts.gather.is_zero() {
            // samples came: the next ones gather in the ports for a while, and a request still
            // wakes the thread; the ports' events are not looked at (nor taken) meanwhile, so a
            // sender's next notices cost it no system call
            gather(&own, opts.gather.min(due));
        } else {
            robot.wait(&own, due);
        }
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

/// Sleeps for `time` or until one of `fds` (the server's own: a request, a
/// connection) is readable.
fn gather(fds: &[RawFd], time: Duration) {
    let fds: Vec<(RawFd, Interest)> = fds.iter().map(|&fd| (fd, Interest::Read)).collect();
    if let Err(e) = wait_fds(&fds, time) {
        tracing::warn!(error = %e, "cannot wait for the server's descriptors: sleeping instead");
        std::thread::sleep(time);
    }
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
                    .spawn(move || client::thread(stream, peer, &hub, &tx));
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
