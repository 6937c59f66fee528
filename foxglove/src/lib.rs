//! `nerve foxglove`: a running robot in Foxglove and Lichtblick, live.
//!
//! This crate is the network side: a WebSocket server ([`serve`]) speaking
//! the Foxglove WebSocket protocol (`foxglove/ws-protocol`, subprotocols
//! `foxglove.sdk.v1` and `foxglove.websocket.v1`). Every output port of the
//! robot is a channel `/<agent>/<port>`, in JSON with a JSON Schema made
//! from the port's registered schema, so any type, a user's own included,
//! is readable. The robot side (router session, port subscriptions,
//! decoding) is the `nerve foxglove` command's (`launcher/src/cmd/foxglove.rs`)
//! behind the [`Robot`] trait; it is called only on the thread that called
//! [`serve`], so a router session (not `Send`) never leaves that thread.
//!
//! Nothing is looked at on a timer but the refresh of channels, graph and
//! parameters (every half second) and a client's pings: the serving thread
//! sleeps on its ports' events and its clients' requests ([`Robot::wait`]),
//! a client's thread on its socket and its queue.
//!
//! A client is served by a thread of its own with a bounded queue: a client
//! that reads slower than the robot publishes loses the oldest messages
//! (counted, logged and told to it in a `status`), and one that stops
//! reading is disconnected after `stall_timeout`; the robot never waits for
//! a client. Security is that of `nerve ui` (see `docs/foxglove.md`):
//! loopback by default, `Origin` checked, a token for parameter changes and
//! publishing, `--read-only`.
//!
//! Services that agents offer are advertised as Foxglove services (JSON,
//! with the request's and answer's JSON Schemas) and called for clients
//! that hold the token ([`Robot::call_service`]; `server/services.rs`).

pub mod protocol;
mod server;
mod wake;

pub use server::{FoxgloveError, Options, Stats, serve};
pub use wake::{Interest, wait_fds};

use serde_json::Value;
use std::os::fd::RawFd;
use std::time::Duration;

/// An output port as a channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelSpec {
    /// `/<agent>/<port>`
    pub topic: String,
    /// the type's name (`nerve::Tick`, or a Foxglove schema name)
    pub schema_name: String,
    /// the JSON Schema, as text
    pub schema: String,
}

/// One edge of the robot's graph, for Foxglove's Topic Graph panel.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GraphSpec {
    /// `(topic, publishers)`: every output port and its agent
    pub published: Vec<(String, Vec<String>)>,
    /// `(topic, subscribers)`: every connected output port and the agents it feeds
    pub subscribed: Vec<(String, Vec<String>)>,
}

/// A service an agent offers, as a Foxglove service.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceSpec {
    /// `/<agent>/<service>`
    pub name: String,
    /// the call's type, `call(Req -> Resp)`
    pub type_name: String,
    /// the request's type name
    pub request_name: String,
    /// the request's JSON Schema, as text
    pub request_schema: String,
    /// the answer's type name
    pub response_name: String,
    /// the answer's JSON Schema, as text
    pub response_schema: String,
}

/// What is done with the end of a call: the answer as JSON, or why there
/// is none (the text a client is shown). Called once, from any thread.
pub type CallDone = Box<dyn FnOnce(Result<Vec<u8>, String>) + Send>;

/// What the server asks of the robot. `nerve foxglove` implements it with a
/// router session and port subscriptions.
pub trait Robot {
    /// Every output port of every agent as a channel; an error says why
    /// there is none (no router).
    fn channels(&mut self) -> Result<Vec<ChannelSpec>, String>;
    /// Sleeps until a port read by the last [`Robot::read`] has a sample,
    /// one of `also` (the server's own: a client's request, a connection)
    /// is readable, or `timeout` passed; whichever comes first. An
    /// implementation waits on its ports' events (see [`wait_fds`]); this
    /// default, for a robot without them, waits for `also` only.
    fn wait(&mut self, also: &[RawFd], timeout: Duration) {
        let fds: Vec<(RawFd, Interest)> = also.iter().map(|&fd| (fd, Interest::Read)).collect();
        if let Err(e) = wait_fds(&fds, timeout) {
            tracing::warn!(error = %e, "cannot wait for the server's descriptors: sleeping instead");
            std::thread::sleep(timeout);
        }
    }
    /// Reads the samples that arrived on the ports of `topics` (the
    /// subscribed channels; subscriptions to others are let go) and hands
    /// each to `sink` as `(topic, stamp in ns since 1970, JSON payload)`.
    fn read(&mut self, topics: &[&str], sink: &mut dyn FnMut(&str, u64, Vec<u8>));
    /// The graph: output ports and connections.
    fn graph(&mut self) -> Result<GraphSpec, String>;
    /// Every parameter as `(/<agent>/<key>, value)`.
    fn parameters(&mut self) -> Result<Vec<protocol::Parameter>, String>;
    /// Sets one parameter (`/<agent>/<key>`); the error is the agent's or
    /// the router's refusal.
    fn set_parameter(&mut self, name: &str, value: &Value) -> Result<(), String>;
    /// Whether `topic` (`/<agent>/<port>`) is an input port a client may
    /// publish into, and its type; the error says why not.
    fn input(&mut self, topic: &str) -> Result<String, String>;
    /// Encodes the JSON `payload` through the input port's schema and sends
    /// it into the port; the error says what is wrong with it.
    fn publish(&mut self, topic: &str, payload: &[u8]) -> Result<(), String>;
    /// Every service the robot's agents offer; by default none.
    fn services(&mut self) -> Result<Vec<ServiceSpec>, String> {
        Ok(Vec::new())
    }
    /// Calls service `name` (`/<agent>/<service>`) with the JSON
    /// `request`, waiting at most `timeout` for the answer, and hands the
    /// end to `done`: at once (a request refused before it is sent) or
    /// later from another thread, so that the serving thread never waits
    /// for a server.
    fn call_service(&mut self, name: &str, request: &[u8], timeout: Duration, done: CallDone) {
        let _ = (request, timeout);
        done(Err(format!("{name}: this robot offers no services")));
    }
}
