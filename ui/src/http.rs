//! A small HTTP/1.1 request reader with limits, for `nerve ui` (review
//! finding B10).
//!
//! Why not tiny_http (used before) or hyper: tiny_http reads a header line
//! of any length, runs one thread per connection without a cap or a read
//! timeout, and has no write timeout, so a local process could grow
//! `nerve ui` until it ran out of memory, pin its threads (slowloris), or
//! hang its exit. Its listener cannot be wrapped with limits from outside.
//! hyper with tokio would do, but would add an async runtime and a dozen
//! crates to a server that answers one browser tab a few times a second.
//! The page needs little of HTTP: one request per connection (answered
//! with `Connection: close`), `Content-Length` bodies of at most a few KiB,
//! no chunked bodies, no pipelining, no upgrades. That fits in this file,
//! with every size and every wait bounded:
//!
//! - the head (request line and headers) at most [`Limits::max_head`]
//!   bytes, each line at most [`Limits::max_line`], at most
//!   [`Limits::max_headers`] headers: more is refused with 431;
//! - a body only with `Content-Length`, at most [`Limits::max_body`]
//!   (413); `Transfer-Encoding` is refused (501);
//! - the whole request must arrive within one deadline (the idle timeout),
//!   however slowly it trickles in: a slowloris client is cut off (408).
//!
//! [`parse_head`] is a pure function over bytes; its tests feed it
//! generated input (random bytes and mutated valid requests, 40,000 heads
//! by default, `PROPTEST_CASES=N` rounds of two for a longer run) and check
//! that it never panics and that whatever it accepts respects the limits.

use std::io::Read;
use std::net::TcpStream;
use std::time::{Duration, Instant};

/// The bounds on a request.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Limits {
    /// one line of the head (request line or one header), CRLF excluded
    pub max_line: usize,
    /// the whole head, the blank line included
    pub max_head: usize,
    /// header lines
    pub max_headers: usize,
    /// the body
    pub max_body: usize,
}

/// The limits `nerve ui` serves with.
pub(crate) const LIMITS: Limits =
    Limits { max_line: 8 * 1024, max_head: 16 * 1024, max_headers: 64, max_body: 64 * 1024 };

/// A request, read whole.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Request {
    /// `GET`, `POST`...
    pub method: String,
    /// the target as sent: `/api/samples?port=a%2Fb`
    pub target: String,
    /// the headers in order; names as sent
    pub headers: Vec<(String, String)>,
    /// the body (empty without `Content-Length`)
    pub body: Vec<u8>,
}

impl Request {
    /// The first header of that name (names compare without case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)).map(|(_, v)| v.as_str())
    }

    /// Every header of that name.
    pub fn headers_named<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a str> + 'a {
        self.headers.iter().filter(move |(n, _)| n.eq_ignore_ascii_case(name)).map(|(_, v)| v.as_str())
    }
}

/// Why a request was not read; [`RequestError::status`] is the answer to send.
#[derive(Debug, thiserror::Error)]
pub(crate) enum RequestError {
    /// Too large a head: a line, the whole head, or too many headers.
    #[error("request header fields too large: {0}")]
    TooLarge(&'static str),
    /// Not HTTP/1.x as this server speaks it.
    #[error("malformed request: {0}")]
    Malformed(&'static str),
    /// A body larger than the limit.
    #[error("the request body is larger than {limit} bytes")]
    BodyTooLarge {
        /// the limit
        limit: usize,
    },
    /// A chunked (or otherwise encoded) body.
    #[error("Transfer-Encoding is not accepted here: send the body with Content-Length")]
    TransferEncoding,
    /// The request did not arrive whole within the deadline.
    #[error("the request did not arrive within {0:?}")]
    TimedOut(Duration),
    /// The client closed the connection before a whole request.
    #[error("the connection was closed before a whole request")]
    Closed,
    /// The socket failed.
    #[error("cannot read the request: {0}")]
    Io(#[source] std::io::Error),
}

impl RequestError {
    /// The status to answer with, `None` when nobody is left to answer.
    pub fn status(&self) -> Option<u16> {
        match self {
            RequestError::TooLarge(_) => Some(431),
            RequestError::Malformed(_) => Some(400),
            RequestError::BodyTooLarge { .. } => Some(413),
            RequestError::TransferEncoding => Some(501),
            RequestError::TimedOut(_) => Some(408),
            RequestError::Closed | RequestError::Io(_) => None,
        }
    }
}

/// The head of a request, parsed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Head {
    pub method: String,
    pub target: String,
    pub headers: Vec<(String, String)>,
    /// from `Content-Length` (0 without one)
    pub content_length: usize,
}

/// `tchar` of RFC 9110: what a method or a header name is made of.
fn is_tchar(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b"!#$%&'*+-.^_`|~".contains(&b)
}

/// Parses a head: the bytes before the blank line (`\r\n\r\n` excluded).
pub(crate) fn parse_head(head: &[u8], limits: &Limits) -> Result<Head, RequestError> {
    if head.len() > limits.max_head {
        return Err(RequestError::TooLarge("the head is too long"));
    }
    // lines end with CRLF; a bare CR or LF left inside a line is refused below (a control character)
    let mut rest = head;
    let mut lines = std::iter::from_fn(move || {
        if rest.is_empty() {
            return None;
        }
        let at = rest.windows(2).position(|w| w == b"\r\n").unwrap_or(rest.len());
        let line = &rest[..at];
        rest = rest.get(at + 2..).unwrap_or(&[]);
        Some(line)
    });
    let request_line = lines.next().ok_or(RequestError::Malformed("no request line"))?;
    if request_line.len() > limits.max_line {
        return Err(RequestError::TooLarge("the request line is too long"));
    }
    let mut parts = request_line.split(|&b| b == b' ');
    let (Some(method), Some(target), Some(version), None) = (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(RequestError::Malformed("the request line is not METHOD TARGET HTTP/1.1"));
    };
    if method.is_empty() || !method.iter().all(|&b| is_tchar(b)) {
        return Err(RequestError::Malformed("bad method"));
    }
    if !target.starts_with(b"/") || !target.iter().all(|&b| b.is_ascii_graphic()) {
        return Err(RequestError::Malformed("the target must be a path starting with /"));
    }
    if version != b"HTTP/1.1" && version != b"HTTP/1.0" {
        return Err(RequestError::Malformed("only HTTP/1.0 and HTTP/1.1 are spoken here"));
    }
    let mut headers = Vec::new();
    for line in lines {
        if line.len() > limits.max_line {
            return Err(RequestError::TooLarge("a header line is too long"));
        }
        if headers.len() >= limits.max_headers {
            return Err(RequestError::TooLarge("too many headers"));
        }
        let colon = line.iter().position(|&b| b == b':').ok_or(RequestError::Malformed("a header without a colon"))?;
        let (name, value) = (&line[..colon], &line[colon + 1..]);
        if name.is_empty() || !name.iter().all(|&b| is_tchar(b)) {
            return Err(RequestError::Malformed("bad header name (or a folded line)"));
        }
        if value.iter().any(|&b| b.is_ascii_control() && b != b'\t') {
            return Err(RequestError::Malformed("a control character in a header value"));
        }
        let value = std::str::from_utf8(value).map_err(|_| RequestError::Malformed("a header value is not UTF-8"))?;
        // tchar is ASCII
        let name = String::from_utf8_lossy(name).into_owned();
        headers.push((name, value.trim_matches([' ', '\t']).to_owned()));
    }
    if headers.iter().any(|(n, _)| n.eq_ignore_ascii_case("transfer-encoding")) {
        return Err(RequestError::TransferEncoding);
    }
    let mut lengths = headers.iter().filter(|(n, _)| n.eq_ignore_ascii_case("content-length")).map(|(_, v)| v);
    let content_length = match (lengths.next(), lengths.next()) {
        (None, _) => 0,
        (Some(v), None) => {
            if v.is_empty() || !v.bytes().all(|b| b.is_ascii_digit()) {
                return Err(RequestError::Malformed("Content-Length is not a number"));
            }
            // digits only: a failure to parse is an overflow
            match v.parse::<usize>() {
                Ok(n) if n <= limits.max_body => n,
                _ => return Err(RequestError::BodyTooLarge { limit: limits.max_body }),
            }
        }
        (Some(_), Some(_)) => return Err(RequestError::Malformed("more than one Content-Length")),
    };
    // ASCII graphic bytes only, checked above
    let (method, target) = (String::from_utf8_lossy(method).into_owned(), String::from_utf8_lossy(target).into_owned());
    Ok(Head { method, target, headers, content_length })
}

/// Where the head ends (the index after `\r\n\r\n`), if it has.
fn head_end(buf: &[u8]) -> Option<usize> {
    buf.windows(4).position(|w| w == b"\r\n\r\n").map(|i| i + 4)
}

/// Reads one request from `stream`, all of it within `deadline` of now.
pub(crate) fn read_request(
    stream: &mut TcpStream,
    limits: &Limits,
    deadline: Duration,
) -> Result<Request, RequestError> {
    let until = Instant::now() + deadline;
    let mut buf = Vec::with_capacity(2048);
    let mut chunk = [0u8; 4096];
    let mut read_some = |stream: &mut TcpStream, buf: &mut Vec<u8>, max: usize| -> Result<(), RequestError> {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(RequestError::TimedOut(deadline));
        }
        stream.set_read_timeout(Some(left)).map_err(RequestError::Io)?;
        let want = max.min(chunk.len());
        match stream.read(&mut chunk[..want]) {
            Ok(0) => Err(RequestError::Closed),
            Ok(n) => {
                buf.extend_from_slice(&chunk[..n]);
                Ok(())
            }
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                Err(RequestError::TimedOut(deadline))
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => Ok(()),
            Err(e) => Err(RequestError::Io(e)),
        }
    };
    let end = loop {
        // the blank line may straddle two reads: look again from 3 bytes back
        if let Some(end) = head_end(&buf) {
            break end;
        }
        if buf.len() >= limits.max_head {
            return Err(RequestError::TooLarge("the head is too long"));
        }
        let room = limits.max_head.saturating_add(4).saturating_sub(buf.len());
        read_some(stream, &mut buf, room)?;
    };
    let head = parse_head(&buf[..end - 4], limits)?;
    let mut body = buf.split_off(end);
    while body.len() < head.content_length {
        let room = head.content_length - body.len();
        read_some(stream, &mut body, room)?;
    }
    body.truncate(head.content_length);
    Ok(Request { method: head.method, target: head.target, headers: head.headers, body })
}

/// The reason phrase of the statuses this server sends.
pub(crate) fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        400 => "Bad Request",
        401 => "Unauthorized",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        409 => "Conflict",
        413 => "Content Too Large",
        431 => "Request Header Fields Too Large",
        501 => "Not Implemented",
        503 => "Service Unavailable",
        _ => "",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &[u8] =
        b"POST /api/action?x=1 HTTP/1.1\r\nHost: 127.0.0.1:8080\r\nX-Nerve-Token: abc\r\nContent-Length: 12";

    #[test]
    fn a_good_head_is_read() {
        let h = parse_head(GOOD, &LIMITS).expect("parse");
        assert_eq!(h.method, "POST");
        assert_eq!(h.target, "/api/action?x=1");
        assert_eq!(h.content_length, 12);
        assert_eq!(h.headers[1], ("X-Nerve-Token".to_owned(), "abc".to_owned()));
    }

    #[test]
    fn bad_heads_are_refused_with_their_status() {
        let status = |head: &[u8]| parse_head(head, &LIMITS).err().and_then(|e| e.status());
        assert_eq!(status(b"GET / HTTP/1.1\r\nTransfer-Encoding: chunked"), Some(501));
        assert_eq!(status(b"GET / HTTP/1.1\r\nContent-Length: 1\r\nContent-Length: 1"), Some(400));
        assert_eq!(status(b"GET / HTTP/1.1\r\nContent-Length: 99999999999999999999"), Some(413));
        assert_eq!(status(b"GET / HTTP/1.1\r\nContent-Length: -1"), Some(400));
        assert_eq!(status(b"GET / HTTP/2\r\nHost: x"), Some(400));
        assert_eq!(status(b"GET http://evil/ HTTP/1.1"), Some(400));
        assert_eq!(status(b"GET / HTTP/1.1\r\n folded"), Some(400));
        assert_eq!(status(b"GET / HTTP/1.1\r\nHost: a\x01b"), Some(400));
        let long = format!("GET / HTTP/1.1\r\nX: {}", "a".repeat(LIMITS.max_line));
        assert_eq!(status(long.as_bytes()), Some(431));
        let many = format!("GET / HTTP/1.1{}", "\r\nX: y".repeat(LIMITS.max_headers + 1));
        assert_eq!(status(many.as_bytes()), Some(431));
    }

    /// xorshift64*: generated input without a dependency, the same every run.
    struct Gen(u64);
    impl Gen {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }
        fn below(&mut self, n: usize) -> usize {
            usize::try_from(self.next() % (n as u64).max(1)).unwrap_or(0)
        }
    }

    /// What is accepted respects every limit.
    fn check(head: &[u8], limits: &Limits) {
        if let Ok(h) = parse_head(head, limits) {
            assert!(h.headers.len() <= limits.max_headers);
            assert!(h.content_length <= limits.max_body);
            assert!(h.target.starts_with('/'));
            assert!(h.headers.iter().all(|(n, v)| n.len() <= limits.max_line && v.len() <= limits.max_line));
        }
    }

    #[test]
    fn generated_heads_never_panic_and_what_is_accepted_is_bounded() {
        let small = Limits { max_line: 64, max_head: 256, max_headers: 4, max_body: 100 };
        let alphabet: &[u8] = b"GET POST/ HTTP/1.1\r\n:Content-Length0123456789 \t\x00\xff%?=Host";
        let mut g = Gen(0x9E37_79B9_7F4A_7C15);
        // 20,000 rounds (40,000 heads) by default; `PROPTEST_CASES=N` for a longer run
        let rounds = std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse::<u64>().ok()).unwrap_or(20_000);
        for _ in 0..rounds {
            // random bytes, mostly from the alphabet of requests
            let len = g.below(300);
            let bytes: Vec<u8> = (0..len)
                .map(|_| if g.below(8) == 0 { (g.next() & 0xff) as u8 } else { alphabet[g.below(alphabet.len())] })
                .collect();
            check(&bytes, &small);
            check(&bytes, &LIMITS);
            // a valid request with a few bytes changed, cut or repeated
            let mut m = GOOD.to_vec();
            for _ in 0..1 + g.below(4) {
                let at = g.below(m.len());
                match g.below(3) {
                    0 => m[at] = (g.next() & 0xff) as u8,
                    1 => m.truncate(at),
                    _ => {
                        let piece = m[at..].to_vec();
                        m.extend_from_slice(&piece);
                    }
                }
                if m.is_empty() {
                    break;
                }
            }
            check(&m, &small);
            check(&m, &LIMITS);
        }
    }
}
