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
//! A client is served by a thread of its own with a bounded queue: a client
//! that reads slower than the robot publishes loses the oldest messages
//! (counted, logged and told to it in a `status`), and one that stops
//! reading is disconnected after `stall_timeout`; the robot never waits for
//! a client. Security is that of `nerve ui` (see `docs/foxglove.md`):
//! loopback by default, `Origin` checked, a token for parameter changes and
//! publishing, `--read-only`.

pub mod protocol;
mod server;

pub use server::{FoxgloveError, Options, Stats, serve};

use serde_json::Value;

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

/// What the server asks of the robot. `nerve foxglove` implements it with a
/// router session and port subscriptions.
pub trait Robot {
    /// Every output port of every agent as a channel; an error says why
    /// there is none (no router).
    fn channels(&mut self) -> Result<Vec<ChannelSpec>, String>;
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
}
