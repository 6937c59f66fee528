//! The WebSocket handshake of a new connection, and what it checks: the
//! subprotocol (one of [`SUBPROTOCOLS`]), the page's `Origin` (loopback or
//! given with `--allow-origin`), the edit token in the query (compared in
//! constant time, as `nerve ui` does) and the number of clients. A refusal
//! is an HTTP status with a reason the client can act on.

use super::Hub;
use crate::protocol::{self, SUBPROTOCOLS};
use nerve_ui::token_matches;
use std::net::TcpStream;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tungstenite::WebSocket;
use tungstenite::handshake::server::{ErrorResponse, Request as HttpRequest, Response};
use tungstenite::protocol::WebSocketConfig;

/// How long a handshake may take.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(3);
/// Largest message a client may send.
const MAX_CLIENT_MESSAGE: usize = 1 << 20;

/// What the handshake decided.
pub(super) struct Admission {
    pub(super) subprotocol: &'static str,
    pub(super) edit: bool,
}

// the callback's error type is tungstenite's (an HTTP response), not ours to box
#[allow(clippy::result_large_err)]
pub(super) fn handshake(stream: TcpStream, hub: &Hub) -> Result<(WebSocket<TcpStream>, Admission), String> {
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
}
