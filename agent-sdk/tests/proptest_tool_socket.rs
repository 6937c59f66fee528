//! Property tests of the router's tool socket (`ToolSocket`,
//! `ToolConnection`) under generated input (issue 40, "every decoder of
//! outside bytes"), over real Unix stream sockets:
//!
//! * the server side: whatever a tool writes before it closes its end
//!   (arbitrary bytes, a length that lies, a frame above
//!   [`MAX_REQUEST`], a valid request with bytes after it), the server never
//!   panics, takes exactly the frame the bytes hold (the same result as
//!   decoding its body directly) or nothing, drops the connection, and
//!   answers a request it took with one well-formed frame;
//! * the client side: whatever a server answers (arbitrary bytes, a length
//!   that lies, one above [`MAX_REPLY`]), `ToolConnection::call` returns a
//!   reply or an error, never a panic.
//!
//! The default case count is proptest's (256, or `PROPTEST_CASES`); the long
//! run is in `docs/robustness.md`.

use agent_sdk::control::{ToolConnection, ToolSocket};
use proptest::prelude::*;
use shm_schemas::control::cli_to_router::{CliRequest, RouterRequest};
use shm_schemas::control::{decode, encode};
use std::io::{Read, Write};
use std::net::Shutdown;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Mirrors of the socket's limits (`agent_sdk::control::stream`).
const MAX_REQUEST: usize = 1 << 20;
const MAX_REPLY: usize = 256 << 20;

/// A socket path of this test process, removed when dropped (also when a
/// case fails).
struct SocketPath(PathBuf);

impl SocketPath {
    fn new(tag: &str) -> Self {
        let p = std::env::temp_dir().join(format!("nerve-proptest-{}-{tag}.sock", std::process::id()));
        let _ = std::fs::remove_file(&p);
        SocketPath(p)
    }
}

impl Drop for SocketPath {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// What the server must make of `bytes`: the body of the frame they start
/// with, if whole and within the limit.
fn expected_body(bytes: &[u8]) -> Option<&[u8]> {
    let head: [u8; 4] = bytes.get(..4)?.try_into().ok()?;
    let len = usize::try_from(u32::from_le_bytes(head)).ok()?;
    if len > MAX_REQUEST {
        return None;
    }
    bytes.get(4..4 + len)
}

fn framed(body: &[u8]) -> Vec<u8> {
    let mut out = u32::try_from(body.len()).expect("small").to_le_bytes().to_vec();
    out.extend_from_slice(body);
    out
}

/// A tool's bytes: arbitrary, or a frame around arbitrary or valid bodies
/// with a true or lying length, with or without bytes after it.
fn tool_bytes() -> impl Strategy<Value = Vec<u8>> {
    let request = prop_oneof![
        Just(RouterRequest::Cli(CliRequest::Ps)),
        any::<u64>().prop_map(|after| RouterRequest::Cli(CliRequest::Events { after })),
        ("[a-z]{1,12}", any::<u64>())
            .prop_map(|(name, period_ns)| RouterRequest::Cli(CliRequest::Rate { name, period_ns })),
    ];
    let body = prop_oneof![request.prop_map(|r| encode(&r)), proptest::collection::vec(any::<u8>(), 0..256)];
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 0..512),
        (body, prop_oneof![Just(None), any::<u32>().prop_map(Some)], proptest::collection::vec(any::<u8>(), 0..32))
            .prop_map(|(body, lie, tail)| {
                let mut out = framed(&body);
                if let Some(len) = lie {
                    out[..4].copy_from_slice(&len.to_le_bytes());
                }
                out.extend_from_slice(&tail);
                out
            }),
        // just above the limit: refused before the body is awaited
        Just(u32::try_from(MAX_REQUEST + 1).expect("small").to_le_bytes().to_vec()),
    ]
}

/// Sends `bytes` as a tool that then closes its writing end, serves with
/// `server` until it has taken a request or let the connection go (bounded
/// in passes and time), answers a taken request, and returns what the
/// server made of the bytes and the answer the tool read.
fn serve_once(
    server: &ToolSocket<RouterRequest, String>,
    path: &Path,
    bytes: &[u8],
) -> (Option<Result<Vec<u8>, shm_schemas::ProtocolError>>, Vec<u8>) {
    let mut tool = UnixStream::connect(path).expect("connect to the socket");
    tool.write_all(bytes).expect("write the request");
    tool.shutdown(Shutdown::Write).expect("close the writing end");
    let start = Instant::now();
    let mut taken = None;
    for pass in 0..2000 {
        if let Some((req, responder)) = server.receive() {
            taken = Some(req.map(|r| encode(&r)));
            responder.respond_or(&"taken".to_string(), |e| e.to_string());
            break;
        }
        if (pass > 0 && !server.busy()) || start.elapsed() > Duration::from_secs(5) {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(!server.busy(), "the server still holds the connection");
    let mut answer = Vec::new();
    tool.set_read_timeout(Some(Duration::from_secs(5))).expect("a read time-out");
    let _ = tool.read_to_end(&mut answer);
    (taken, answer)
}

/// A server that answers one connection with `reply` and closes it.
fn answer_once(listener: UnixListener, reply: Vec<u8>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        if let Ok((mut s, _)) = listener.accept() {
            let mut head = [0u8; 4];
            let _ = s.read_exact(&mut head);
            let len = usize::try_from(u32::from_le_bytes(head)).unwrap_or(0).min(MAX_REQUEST);
            let mut body = vec![0u8; len];
            let _ = s.read_exact(&mut body);
            let _ = s.write_all(&reply);
        }
    })
}

proptest! {
    // no regression files in the source tree: a failure prints its input
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::default() })]

    /// The server's side: see the module documentation.
    #[test]
    fn proptest_tool_socket_requests(cases in proptest::collection::vec(tool_bytes(), 1..8)) {
        let path = SocketPath::new("server");
        let server = ToolSocket::<RouterRequest, String>::bind(&path.0).expect("bind the tool socket");
        for bytes in &cases {
            let (taken, answer) = serve_once(&server, &path.0, bytes);
            match (expected_body(bytes), taken) {
                (Some(body), Some(got)) => {
                    let direct = decode::<RouterRequest>(body).map(|r| encode(&r));
                    prop_assert_eq!(got, direct);
                    // one whole frame of an encoded String
                    prop_assert_eq!(expected_body(&answer).map(|b| b.len() + 4), Some(answer.len()));
                    let text: String = decode(&answer[4..]).expect("the answer decodes");
                    prop_assert_eq!(text, "taken");
                }
                (None, None) => prop_assert!(answer.is_empty()),
                (want, got) => prop_assert!(false, "expected a request: {}, took one: {}", want.is_some(), got.is_some()),
            }
        }
    }

    /// The tool's side: arbitrary answers, and frames with a true, lying
    /// or too large length.
    #[test]
    fn proptest_tool_socket_replies(
        reply in prop_oneof![
            proptest::collection::vec(any::<u8>(), 0..512),
            (".{0,64}", 0u32..1024, any::<bool>()).prop_map(|(text, lie, lies)| {
                let mut out = framed(&encode(&text));
                if lies {
                    out[..4].copy_from_slice(&lie.to_le_bytes());
                }
                out
            }),
            Just(u32::try_from(MAX_REPLY + 1).expect("small").to_le_bytes().to_vec()),
        ],
    ) {
        let path = SocketPath::new("client");
        let listener = UnixListener::bind(&path.0).expect("bind");
        let server = answer_once(listener, reply.clone());
        let got = ToolConnection::connect(&path.0)
            .expect("connect")
            .call::<RouterRequest, String>(&RouterRequest::Cli(CliRequest::Ps), Duration::from_secs(5));
        server.join().expect("the answering thread");
        match expected_body(&reply) {
            Some(body) if reply.len() >= 4 => match decode::<String>(body) {
                Ok(text) => prop_assert_eq!(got.ok(), Some(text)),
                Err(_) => prop_assert!(got.is_err()),
            },
            _ => prop_assert!(got.is_err()),
        }
    }
}
