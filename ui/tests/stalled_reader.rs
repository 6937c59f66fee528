//! A page that stops reading its event stream is dropped at the write
//! timeout and its place given back (issue 40: limits on idle streams).
//!
//! The real server (`nerve_ui::serve`) on a loopback port, with a robot
//! whose graph is large and changes at every read, so that the stream's
//! socket buffers fill within a second once the reader stops. One page may
//! be open at a time: while the stalled reader holds that place a second
//! page is answered 503; once the server's write has been stuck for the
//! write timeout it drops the stalled connection (the reader sees its end)
//! and a new page is served.

use nerve_ui::{Action, Options, Robot};
use serde_json::{Value, json};
use std::io::{Read as _, Write as _};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A graph of one agent carrying `PAD` bytes that change at every read.
struct BigGraph {
    reads: u64,
}

const PAD: usize = 256 * 1024;

impl Robot for BigGraph {
    fn graph(&mut self) -> Result<Value, String> {
        self.reads += 1;
        let pad = format!("{}{}", self.reads, "x".repeat(PAD));
        Ok(json!({"agents": [{"name": "big", "note": pad}], "connections": []}))
    }
    fn act(&mut self, _: Action) -> Result<Value, String> {
        Err("this test's robot takes no actions".into())
    }
    fn samples(&mut self, _: &str, _: u64) -> Result<Value, String> {
        Ok(json!([]))
    }
    fn image(&mut self, _: &str) -> Result<Vec<u8>, String> {
        Err("no images".into())
    }
    fn kinds(&mut self) -> Vec<String> {
        Vec::new()
    }
}

const TOKEN: &str = "edit-token-of-the-stalled-reader-test-0123456789";
const READ_TOKEN: &str = "read-token-of-the-stalled-reader-test-0123456789";

/// Opens `/api/events` on `addr` and returns the stream and the status line.
fn open_events(addr: SocketAddr) -> (TcpStream, String) {
    let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(2)).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(5))).expect("read timeout");
    write!(s, "GET /api/events HTTP/1.1\r\nHost: {addr}\r\nX-Nerve-Token: {READ_TOKEN}\r\n\r\n").expect("request");
    // the status line, byte by byte so that nothing of the stream is taken
    let mut line = Vec::new();
    let mut b = [0u8; 1];
    while !line.ends_with(b"\r\n") && line.len() < 200 {
        match s.read(&mut b) {
            Ok(1) => line.push(b[0]),
            _ => break,
        }
    }
    (s, String::from_utf8_lossy(&line).trim().to_string())
}

/// Stops the server when dropped, even when an assertion failed.
struct Server {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn start(write_timeout: Duration) -> (Server, SocketAddr) {
    let opts = Options {
        bind: "127.0.0.1:0".parse().expect("addr"),
        read_only: true,
        interval: Duration::from_millis(20),
        token: TOKEN.into(),
        read_token: READ_TOKEN.into(),
        robot: "stalled".into(),
        max_clients: 1,
        max_connections: 8,
        idle_timeout: Duration::from_secs(5),
        write_timeout,
        allowed_hosts: Vec::new(),
    };
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = std::sync::mpsc::channel();
    let thread = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let mut robot = BigGraph { reads: 0 };
            let mut listening = |a: SocketAddr| {
                let _ = tx.send(a);
            };
            nerve_ui::serve(&opts, &mut robot, &mut listening, &|| stop.load(Ordering::SeqCst)).expect("serve");
        })
    };
    let server = Server { stop, thread: Some(thread) };
    let addr = rx.recv_timeout(Duration::from_secs(5)).expect("the server listens");
    (server, addr)
}

#[test]
fn a_page_that_stops_reading_is_dropped_at_the_write_timeout_and_its_place_given_back() {
    let write_timeout = Duration::from_millis(800);
    let (_server, addr) = start(write_timeout);

    let (mut stalled, status) = open_events(addr);
    assert!(status.contains(" 200 "), "the first page: {status}");
    // it reads a little, then stops reading
    let mut some = [0u8; 4096];
    stalled.read_exact(&mut some).expect("the stream's first bytes");

    let (_, second) = open_events(addr);
    assert!(second.contains(" 503 "), "a second page while the first holds the only place: {second}");

    // the stalled reader's place comes back once the server gave up writing
    // to it (its buffers full, then the write timeout); bounded in time
    let t0 = Instant::now();
    let mut served = None;
    while t0.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(200));
        let (s, status) = open_events(addr);
        if status.contains(" 200 ") {
            served = Some(s);
            break;
        }
        assert!(status.contains(" 503 "), "while the stalled page holds its place: {status}");
    }
    assert!(served.is_some(), "the stalled page was never dropped: a new page is still refused after 30 s");

    // the stalled reader finds its stream ended: what the buffers held, then EOF
    stalled.set_read_timeout(Some(Duration::from_secs(5))).expect("read timeout");
    let mut buf = vec![0u8; 1 << 20];
    let mut total = 0usize;
    let ended = loop {
        match stalled.read(&mut buf) {
            Ok(0) => break true,
            Ok(n) => total += n,
            // a reset is an end too
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => break true,
            Err(_) => break false,
        }
        assert!(total < 1 << 30, "the stalled stream never ends ({total} bytes read)");
    };
    assert!(ended, "the stalled page's connection was not closed by the server ({total} bytes drained)");
}
