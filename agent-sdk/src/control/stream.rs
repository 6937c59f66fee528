//! The router's socket for tools: control requests over a Unix stream socket.
//!
//! A `nerve` command that only asks the router something spent most of its
//! time making an iceoryx2 node and client port and tearing them down again
//! (BENCHMARKS.md §6); over this socket it connects, writes one request,
//! sleeps in `read` until the reply, and leaves nothing behind when it is
//! killed. Agents keep iceoryx2 (their registration service is sized for
//! them); the router serves tools on both.
//!
//! One request per connection. A frame is the length of the envelope bytes
//! (`u32`, little-endian) and then the bytes, the same versioned envelope as
//! on iceoryx2 ([`shm_schemas::control`]). The socket is a file in the
//! robot's state directory, which is private to its user
//! ([`crate::world::World::tool_socket`]); the file itself is made `0600`.
//!
//! The server never blocks on a tool: connections are accepted and read
//! without blocking (a request that has not fully come is kept and read on
//! later passes, for at most [`READ_WITHIN`]); the reply is written with a
//! time-out of [`WRITE_WITHIN`], and the write can only wait where a reply
//! larger than the socket's buffer meets a tool that stopped reading.

use super::{Caller, ControlError, Responder};
use iceoryx2::prelude::{FileDescriptor, FileDescriptorBased, SynchronousMultiplexing};
use serde::{Serialize, de::DeserializeOwned};
use shm_schemas::control::{ProtocolError, decode, encode};
use std::cell::RefCell;
use std::io::{self, Read, Write};
use std::marker::PhantomData;
use std::os::fd::AsRawFd;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The largest request a tool may send.
pub const MAX_REQUEST: usize = 1 << 20;
/// The largest reply a tool accepts (a `ps` of 500 agents is well below).
pub const MAX_REPLY: usize = 256 << 20;
/// How long a tool that connected has to send its whole request.
pub const READ_WITHIN: Duration = Duration::from_secs(1);
/// How long the server tries to write a reply.
pub const WRITE_WITHIN: Duration = Duration::from_millis(250);

/// The serving side, to attach to a WaitSet (it wakes on a new connection).
pub struct ToolSocket<Req, Resp> {
    path: PathBuf,
    listener: UnixListener,
    /// the listener's descriptor as iceoryx2's WaitSet takes it (not owned)
    fd: FileDescriptor,
    /// the socket file's (device, inode), so that only this file is removed
    file: (u64, u64),
    /// connections whose request is not whole yet (a cell: the WaitSet
    /// holds the socket borrowed while the server reads)
    reading: RefCell<Vec<Reading>>,
    /// when a failed `accept` was last logged (out of descriptors, say, it
    /// fails at every pass until one is free)
    accept_warned: std::cell::Cell<Option<Instant>>,
    _types: PhantomData<fn(Req) -> Resp>,
}

impl<Req, Resp> std::fmt::Debug for ToolSocket<Req, Resp> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ToolSocket").field("path", &self.path).field("reading", &self.reading.borrow().len()).finish()
    }
}

/// A connection whose request has not fully come yet.
#[derive(Debug)]
struct Reading {
    stream: UnixStream,
    buf: Vec<u8>,
    since: Instant,
}

enum Progress {
    More,
    Done(Vec<u8>),
    Failed(String),
}

impl Reading {
    /// Reads what has come; the request's bytes once they are all in.
    fn progress(&mut self) -> Progress {
        let mut chunk = [0u8; 16 * 1024];
        loop {
            match self.stream.read(&mut chunk) {
                Ok(0) => return Progress::Failed("the tool closed the connection before its request was in".into()),
                Ok(n) => {
                    self.buf.extend_from_slice(&chunk[..n]);
                    match frame_in(&self.buf, MAX_REQUEST) {
                        Ok(Some(body)) => return Progress::Done(body.to_vec()),
                        Ok(None) => {}
                        Err(e) => return Progress::Failed(e),
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Progress::More,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Progress::Failed(format!("cannot read the request: {e}")),
            }
        }
    }
}

/// The body of the frame at the start of `buf`, once it is whole.
fn frame_in(buf: &[u8], max: usize) -> Result<Option<&[u8]>, String> {
    let Some(head) = buf.get(..4) else { return Ok(None) };
    let len = u32::from_le_bytes([head[0], head[1], head[2], head[3]]) as usize;
    if len > max {
        return Err(format!("a frame of {len} bytes is larger than the {max} bytes allowed"));
    }
    Ok(buf.get(4..4 + len))
}

/// `bytes` as a frame.
fn frame(bytes: &[u8]) -> io::Result<Vec<u8>> {
    let len = u32::try_from(bytes.len())
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "a message larger than 4 GiB"))?;
    let mut out = Vec::with_capacity(bytes.len() + 4);
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(bytes);
    Ok(out)
}

fn io_err<'a>(what: &'static str, path: &'a Path) -> impl FnOnce(io::Error) -> ControlError + 'a {
    move |source| ControlError::Io { what, path: path.to_path_buf(), source }
}

impl<Req: DeserializeOwned, Resp: Serialize> ToolSocket<Req, Resp> {
    /// Serves tools at `path`. A file left there by an earlier server is
    /// replaced: call it only once this process is known to be the only
    /// server (the router: after its iceoryx2 services were created).
    pub fn bind(path: &Path) -> Result<Self, ControlError> {
        match std::fs::remove_file(path) {
            Ok(()) => tracing::debug!(path = %path.display(), "removed the tool socket of an earlier router"),
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(io_err("remove the old tool socket", path)(e)),
        }
        let listener = UnixListener::bind(path).map_err(io_err("bind the tool socket", path))?;
        let meta = std::fs::metadata(path).map_err(io_err("look at the tool socket", path))?;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600))
            .map_err(io_err("make the tool socket private", path))?;
        listener.set_nonblocking(true).map_err(io_err("make the tool socket non-blocking", path))?;
        let fd = FileDescriptor::non_owning_new(listener.as_raw_fd()).ok_or_else(|| {
            io_err("wait on the tool socket", path)(io::Error::new(io::ErrorKind::InvalidInput, "no descriptor"))
        })?;
        Ok(ToolSocket {
            path: path.to_path_buf(),
            listener,
            fd,
            file: (meta.dev(), meta.ino()),
            reading: RefCell::new(Vec::new()),
            accept_warned: std::cell::Cell::new(None),
            _types: PhantomData,
        })
    }

    /// Whether requests are partly read: look again soon.
    pub fn busy(&self) -> bool {
        !self.reading.borrow().is_empty()
    }

    /// Takes the next whole request, if any, with the [`Responder`] that
    /// answers it: accepts new connections and reads what came, without
    /// blocking. Requests that took longer than [`READ_WITHIN`] to come are
    /// dropped.
    #[allow(clippy::type_complexity)]
    pub fn receive(&self) -> Option<(Result<Req, ProtocolError>, Responder<Resp>)> {
        let mut reading = self.reading.borrow_mut();
        loop {
            match self.listener.accept() {
                Ok((stream, _)) => match stream.set_nonblocking(true) {
                    Ok(()) => reading.push(Reading { stream, buf: Vec::new(), since: Instant::now() }),
                    Err(e) => tracing::warn!(error = %e, "cannot read from a tool: {e}"),
                },
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => {
                    // out of descriptors, say: the next pass tries again,
                    // and the log hears of it once a second at most
                    if self.accept_warned.get().is_none_or(|t| t.elapsed() >= Duration::from_secs(1)) {
                        tracing::warn!(path = %self.path.display(), error = %e, "cannot accept a tool: {e}");
                        self.accept_warned.set(Some(Instant::now()));
                    }
                    break;
                }
            }
        }
        let mut i = 0;
        while i < reading.len() {
            match reading[i].progress() {
                Progress::More if reading[i].since.elapsed() > READ_WITHIN => {
                    tracing::warn!("a tool sent no whole request within {READ_WITHIN:?}; closed");
                    reading.swap_remove(i);
                }
                Progress::More => i += 1,
                Progress::Failed(why) => {
                    tracing::debug!("a tool's connection dropped: {why}");
                    reading.swap_remove(i);
                }
                Progress::Done(body) => {
                    let r = reading.swap_remove(i);
                    let responder = Responder {
                        active: Some(Caller::Stream(Connection { stream: r.stream })),
                        service: self.path.display().to_string(),
                        max_message: None,
                        replies: None,
                        _types: PhantomData,
                    };
                    return Some((decode::<Req>(&body), responder));
                }
            }
        }
        None
    }
}

impl<Req, Resp> Drop for ToolSocket<Req, Resp> {
    fn drop(&mut self) {
        // only our own file: a router started after this one replaced it
        let ours = std::fs::metadata(&self.path).is_ok_and(|m| (m.dev(), m.ino()) == self.file);
        if ours && let Err(e) = std::fs::remove_file(&self.path) {
            tracing::warn!(path = %self.path.display(), error = %e, "cannot remove the tool socket: {e}");
        }
    }
}

impl<Req, Resp> FileDescriptorBased for ToolSocket<Req, Resp> {
    fn file_descriptor(&self) -> &FileDescriptor {
        &self.fd
    }
}

impl<Req, Resp> SynchronousMultiplexing for ToolSocket<Req, Resp> {}

/// The server's end of one tool's connection: where its answer goes.
#[derive(Debug)]
pub(super) struct Connection {
    stream: UnixStream,
}

impl Connection {
    /// Whether the tool still waits: it has not closed its end.
    pub(super) fn is_open(&self) -> bool {
        let mut b = [0u8; 1];
        // SAFETY: recv into a valid one-byte buffer on a descriptor we own;
        // MSG_PEEK leaves the data, MSG_DONTWAIT never blocks.
        let n = unsafe {
            libc::recv(self.stream.as_raw_fd(), b.as_mut_ptr().cast(), 1, libc::MSG_PEEK | libc::MSG_DONTWAIT)
        };
        // 0: the tool closed its end; -1 with EAGAIN: open and quiet
        n > 0 || (n < 0 && io::Error::last_os_error().kind() == io::ErrorKind::WouldBlock)
    }

    /// Writes the answer, waiting at most [`WRITE_WITHIN`].
    pub(super) fn answer(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.stream.set_nonblocking(false)?;
        self.stream.set_write_timeout(Some(WRITE_WITHIN))?;
        self.stream.write_all(&frame(bytes)?)
    }
}

/// A tool's connection to a [`ToolSocket`], made before the call so that a
/// caller knows at once whether anything listens there.
#[derive(Debug)]
pub struct ToolConnection {
    stream: UnixStream,
    path: PathBuf,
    made: Instant,
}

impl ToolConnection {
    /// Connects to the socket at `path`. Fails where nothing listens: no
    /// file, a file left by a server that is gone, a path too long for a
    /// socket address (the caller may then try iceoryx2).
    pub fn connect(path: &Path) -> io::Result<ToolConnection> {
        Ok(ToolConnection { stream: UnixStream::connect(path)?, path: path.to_path_buf(), made: Instant::now() })
    }

    /// Whether the connection is young enough to carry a request: the
    /// server closes one that brings no whole request within
    /// [`READ_WITHIN`], so a caller that connected early and waited (a
    /// session opened, then ports made) connects again after half of it.
    pub fn fresh(&self) -> bool {
        self.made.elapsed() < READ_WITHIN / 2
    }

    /// Sends `req` and waits up to `timeout` for the reply.
    pub fn call<Req: Serialize, Resp: DeserializeOwned>(
        mut self,
        req: &Req,
        timeout: Duration,
    ) -> Result<Resp, ControlError> {
        let start = Instant::now();
        // what a failed read or write means: no answer in time, a server
        // gone without answering, or the system's own error
        let path = &self.path;
        let fail = |e: io::Error| match e.kind() {
            io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut => {
                ControlError::Timeout { service: path.display().to_string(), timeout }
            }
            io::ErrorKind::UnexpectedEof | io::ErrorKind::BrokenPipe | io::ErrorKind::ConnectionReset => {
                ControlError::NoServer { service: path.display().to_string() }
            }
            _ => ControlError::Io { what: "talk to the router", path: path.clone(), source: e },
        };
        let body = encode(req);
        if body.len() > MAX_REQUEST {
            let service = path.display().to_string();
            return Err(ControlError::TooLarge { service, bytes: body.len(), max: MAX_REQUEST });
        }
        let bytes = frame(&body).map_err(fail)?;
        let left = || timeout.saturating_sub(start.elapsed()).max(Duration::from_millis(1));
        self.stream.set_write_timeout(Some(timeout)).map_err(fail)?;
        self.stream.write_all(&bytes).map_err(fail)?;
        let mut head = [0u8; 4];
        self.stream.set_read_timeout(Some(left())).map_err(fail)?;
        self.stream.read_exact(&mut head).map_err(fail)?;
        let len = u32::from_le_bytes(head) as usize;
        if len > MAX_REPLY {
            let service = path.display();
            return Err(ProtocolError::Malformed(format!("a reply of {len} bytes from {service}")).into());
        }
        // grown as the bytes arrive, not allocated at the length the peer
        // claims: a reply that says 256 MiB and sends 4 bytes costs 4 bytes
        let mut body = Vec::with_capacity(len.min(64 * 1024));
        self.stream.set_read_timeout(Some(left())).map_err(fail)?;
        (&mut self.stream).take(len as u64).read_to_end(&mut body).map_err(fail)?;
        if body.len() < len {
            return Err(fail(io::Error::from(io::ErrorKind::UnexpectedEof)));
        }
        Ok(decode::<Resp>(&body)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::control::unanswered;

    fn socket_path(tag: &str) -> PathBuf {
        std::env::temp_dir().join(format!("nerve-sock-{}-{tag}", std::process::id()))
    }

    #[test]
    fn a_frame_is_whole_only_with_all_its_bytes() {
        let f = frame(b"abc").expect("frame");
        assert_eq!(f, [3, 0, 0, 0, b'a', b'b', b'c']);
        assert_eq!(frame_in(&f[..2], 10), Ok(None));
        assert_eq!(frame_in(&f[..6], 10), Ok(None));
        assert_eq!(frame_in(&f, 10), Ok(Some(&b"abc"[..])));
        assert!(frame_in(&f, 2).is_err(), "larger than allowed");
    }

    /// A request over the socket is answered through the same Responder as
    /// one over iceoryx2; one sent in pieces is read across passes; the
    /// socket file is removed with the server, and a stale one is replaced.
    #[test]
    fn requests_are_answered_and_the_file_goes_with_the_server() {
        let path = socket_path("answer");
        std::fs::write(&path, b"stale").expect("a stale file");
        let server = ToolSocket::<String, String>::bind(&path).expect("bind");
        let mode = std::fs::metadata(&path).expect("socket file").permissions().mode();
        assert_eq!(mode & 0o777, 0o600);

        let p = path.clone();
        let tool = std::thread::spawn(move || {
            let c = ToolConnection::connect(&p).expect("connect");
            c.call::<String, String>(&"ping".to_owned(), Duration::from_secs(5))
        });
        // a second tool sends its request in two pieces
        let mut slow = UnixStream::connect(&path).expect("connect");
        let req = frame(&encode(&"slow".to_owned())).expect("frame");
        slow.write_all(&req[..3]).expect("first piece");
        let mut answered = Vec::new();
        let mut second_sent = false;
        let t0 = Instant::now();
        while answered.len() < 2 && t0.elapsed() < Duration::from_secs(5) {
            // the rest of the slow request once the server holds its first
            // piece and has answered the other tool meanwhile
            if !second_sent && server.busy() && answered.len() == 1 {
                slow.write_all(&req[3..]).expect("second piece");
                second_sent = true;
            }
            match server.receive() {
                Some((Ok(req), responder)) => {
                    assert!(responder.is_connected());
                    responder.respond_or(&format!("{req}-pong"), |e| e.to_string());
                    answered.push(req);
                }
                Some((Err(e), _)) => panic!("bad request: {e}"),
                None => std::thread::sleep(Duration::from_millis(1)),
            }
        }
        assert!(second_sent, "the server never held the partial request");
        assert_eq!(tool.join().expect("tool").expect("reply"), "ping-pong");
        let mut head = [0u8; 4];
        slow.read_exact(&mut head).expect("reply head");
        let mut body = vec![0u8; u32::from_le_bytes(head) as usize];
        slow.read_exact(&mut body).expect("reply body");
        assert_eq!(decode::<String>(&body).expect("decode"), "slow-pong");
        answered.sort();
        assert_eq!(answered, ["ping", "slow"]);
        drop(server);
        assert!(!path.exists(), "the socket file goes with the server");
        assert!(ToolConnection::connect(&path).is_err(), "nothing listens");
    }

    /// A reply that claims more bytes than it sends ends the call with an
    /// error once the peer is gone, without taking the memory it claimed
    /// first (found in the property tests' review).
    #[test]
    fn a_reply_that_claims_more_than_it_sends_is_an_error() {
        use std::os::unix::net::UnixListener;
        let path = socket_path("claims");
        let _ = std::fs::remove_file(&path);
        let listener = UnixListener::bind(&path).expect("bind");
        let liar = std::thread::spawn(move || {
            let (mut s, _) = listener.accept().expect("accept");
            let mut head = [0u8; 4];
            s.read_exact(&mut head).expect("request head");
            let mut req = vec![0u8; u32::from_le_bytes(head) as usize];
            s.read_exact(&mut req).expect("request");
            // 200 MiB announced, four bytes sent, then gone
            s.write_all(&(200u32 << 20).to_le_bytes()).expect("head");
            s.write_all(b"abcd").expect("some bytes");
        });
        let c = ToolConnection::connect(&path).expect("connect");
        let r = c.call::<String, String>(&"x".into(), Duration::from_secs(5));
        liar.join().expect("the liar ran");
        assert!(r.is_err(), "{r:?}");
        let _ = std::fs::remove_file(&path);
    }

    /// A responder dropped unanswered tells the tool so (as on iceoryx2),
    /// and a tool that left is seen as gone.
    #[test]
    fn unanswered_and_gone_tools() {
        let path = socket_path("gone");
        let server = ToolSocket::<String, String>::bind(&path).expect("bind");
        let p = path.clone();
        let tool = std::thread::spawn(move || {
            ToolConnection::connect(&p).expect("connect").call::<String, String>(&"x".into(), Duration::from_secs(5))
        });
        let responder = loop {
            if let Some((_, r)) = server.receive() {
                break r;
            }
            std::thread::sleep(Duration::from_millis(1));
        };
        drop(responder);
        match tool.join().expect("tool") {
            Err(ControlError::Protocol(ProtocolError::Unanswered)) => {}
            other => panic!("expected Unanswered, got {other:?}"),
        }
        assert!(decode::<String>(&unanswered()).is_err());

        // a tool that sends its request and leaves before the answer
        let mut s = UnixStream::connect(&path).expect("connect");
        s.write_all(&frame(&encode(&"bye".to_owned())).expect("frame")).expect("send");
        drop(s);
        let responder = loop {
            if let Some((_, r)) = server.receive() {
                break r;
            }
            std::thread::sleep(Duration::from_millis(1));
        };
        assert!(!responder.is_connected(), "the tool is gone");
    }

    #[test]
    fn a_silent_tool_times_out_and_a_missing_server_is_no_server() {
        let path = socket_path("silent");
        let _server = ToolSocket::<String, String>::bind(&path).expect("bind");
        // the server never serves: the call times out
        let r = ToolConnection::connect(&path)
            .expect("connect")
            .call::<String, String>(&"x".into(), Duration::from_millis(50));
        assert!(matches!(r, Err(ControlError::Timeout { .. })), "{r:?}");
        assert!(ToolConnection::connect(&socket_path("none")).is_err());
    }

    /// A connection left unused is closed by the server after READ_WITHIN;
    /// it stops being fresh well before.
    #[test]
    fn an_unused_connection_goes_stale_before_the_server_drops_it() {
        let path = socket_path("stale");
        let server = ToolSocket::<String, String>::bind(&path).expect("bind");
        let c = ToolConnection::connect(&path).expect("connect");
        assert!(c.fresh());
        let t0 = Instant::now();
        while t0.elapsed() < READ_WITHIN + Duration::from_millis(200) {
            assert!(server.receive().is_none());
            std::thread::sleep(Duration::from_millis(10));
        }
        assert!(!c.fresh());
        assert!(!server.busy(), "the server let the silent connection go");
    }

    /// A state directory too deep for a socket address (107 bytes): the
    /// server says so, and a tool finds nothing there (both then use
    /// iceoryx2).
    #[test]
    fn a_path_too_long_for_a_socket_is_refused_plainly() {
        let dir = std::env::temp_dir().join(format!("nerve-sock-{}-{}", std::process::id(), "d".repeat(100)));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("router.sock");
        match ToolSocket::<String, String>::bind(&path) {
            Err(e @ ControlError::Io { .. }) => assert!(e.to_string().contains("bind the tool socket"), "{e}"),
            other => panic!("expected an Io error, got {other:?}"),
        }
        assert!(ToolConnection::connect(&path).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
