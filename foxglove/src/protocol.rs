//! The messages of the Foxglove WebSocket protocol that nerve speaks
//! (`foxglove/ws-protocol`, spec version 1): what a client sends (JSON text
//! and binary frames) and what the server answers. Names and numbers are the
//! protocol's; the code is nerve's own.

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

/// The subprotocol names accepted, in nerve's order of preference: the
/// current Foxglove app offers the first, Lichtblick and the npm client the
/// second; both are the same protocol.
pub const SUBPROTOCOLS: [&str; 2] = ["foxglove.sdk.v1", "foxglove.websocket.v1"];

/// Binary opcode of a server's message data frame.
pub const OP_MESSAGE_DATA: u8 = 1;
/// Binary opcode of a client's message data frame (client publish).
pub const OP_CLIENT_MESSAGE_DATA: u8 = 1;

/// The status levels of a `status` message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// information
    Info = 0,
    /// something the user should know
    Warning = 1,
    /// a refused request
    Error = 2,
}

/// One subscription a client asks for.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Subscription {
    /// the client's id of this subscription
    pub id: u32,
    /// the channel
    pub channel_id: u32,
}

/// A parameter as the protocol carries it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Parameter {
    /// `/<agent>/<key>`
    pub name: String,
    /// number, boolean or string (nerve's parameters are scalars)
    #[serde(default)]
    pub value: Value,
}

/// A channel a client advertises to publish on.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ClientChannel {
    /// the client's id of the channel
    pub id: u32,
    /// the input port, `/<agent>/<port>`
    pub topic: String,
    /// the message encoding (nerve takes `json`)
    pub encoding: String,
    /// the type's name, as the client knows it
    #[serde(default)]
    pub schema_name: String,
}

/// A JSON message from a client.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
pub enum ClientMessage {
    /// subscribe to channels
    Subscribe {
        /// what to subscribe
        subscriptions: Vec<Subscription>,
    },
    /// end subscriptions
    #[serde(rename_all = "camelCase")]
    Unsubscribe {
        /// the client's subscription ids
        subscription_ids: Vec<u32>,
    },
    /// channels to publish on
    Advertise {
        /// the channels
        channels: Vec<ClientChannel>,
    },
    /// end client channels
    #[serde(rename_all = "camelCase")]
    Unadvertise {
        /// the client's channel ids
        channel_ids: Vec<u32>,
    },
    /// read parameters (all of them when the list is empty)
    #[serde(rename_all = "camelCase")]
    GetParameters {
        /// names, `/<agent>/<key>`
        #[serde(default)]
        parameter_names: Vec<String>,
        /// echoed in the answer
        id: Option<String>,
    },
    /// change parameters
    SetParameters {
        /// names and new values
        parameters: Vec<Parameter>,
        /// when given, the new values are sent back with this id
        id: Option<String>,
    },
    /// be told of changes of these parameters
    #[serde(rename_all = "camelCase")]
    SubscribeParameterUpdates {
        /// names
        #[serde(default)]
        parameter_names: Vec<String>,
    },
    /// see above
    #[serde(rename_all = "camelCase")]
    UnsubscribeParameterUpdates {
        /// names
        #[serde(default)]
        parameter_names: Vec<String>,
    },
    /// be sent the connection graph and its changes
    SubscribeConnectionGraph,
    /// stop that
    UnsubscribeConnectionGraph,
}

/// A channel the server advertises.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Channel {
    /// the server's id
    pub id: u32,
    /// `/<agent>/<port>`
    pub topic: String,
    /// `json`
    pub encoding: String,
    /// the type's name
    pub schema_name: String,
    /// the JSON Schema, as text
    pub schema: String,
    /// `jsonschema`
    pub schema_encoding: String,
}

impl Channel {
    /// The channel as an `advertise` entry.
    pub fn to_json(&self) -> Value {
        json!({
            "id": self.id,
            "topic": self.topic,
            "encoding": self.encoding,
            "schemaName": self.schema_name,
            "schema": self.schema,
            "schemaEncoding": self.schema_encoding,
        })
    }
}

/// `serverInfo`.
pub fn server_info(name: &str, capabilities: &[&str], metadata: Value, session_id: &str) -> String {
    json!({
        "op": "serverInfo",
        "name": name,
        "capabilities": capabilities,
        "supportedEncodings": ["json"],
        "metadata": metadata,
        "sessionId": session_id,
    })
    .to_string()
}

/// `advertise` of `channels`.
pub fn advertise<'a>(channels: impl IntoIterator<Item = &'a Channel>) -> String {
    let list: Vec<Value> = channels.into_iter().map(Channel::to_json).collect();
    json!({ "op": "advertise", "channels": list }).to_string()
}

/// `unadvertise` of channel ids.
pub fn unadvertise(ids: &[u32]) -> String {
    json!({ "op": "unadvertise", "channelIds": ids }).to_string()
}

/// `status`.
pub fn status(level: Level, message: &str) -> String {
    json!({ "op": "status", "level": level as u8, "message": message }).to_string()
}

/// `parameterValues`.
pub fn parameter_values(parameters: &[Parameter], id: Option<&str>) -> String {
    let mut v = json!({ "op": "parameterValues", "parameters": parameters });
    if let Some(id) = id {
        v["id"] = json!(id);
    }
    v.to_string()
}

/// A binary message data frame: opcode, subscription id, timestamp (ns
/// since 1970), payload; integers little-endian.
pub fn message_data(subscription: u32, unix_ns: u64, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(13 + payload.len());
    out.push(OP_MESSAGE_DATA);
    out.extend_from_slice(&subscription.to_le_bytes());
    out.extend_from_slice(&unix_ns.to_le_bytes());
    out.extend_from_slice(payload);
    out
}

/// A client's binary frame, parsed: `(channel id, payload)` of a client
/// message data frame; `None` for anything else (too short, another opcode).
pub fn client_message_data(frame: &[u8]) -> Option<(u32, &[u8])> {
    let (&op, rest) = frame.split_first()?;
    if op != OP_CLIENT_MESSAGE_DATA {
        return None;
    }
    let id = u32::from_le_bytes(rest.get(..4)?.try_into().ok()?);
    Some((id, rest.get(4..)?))
}

/// The subprotocol to answer with, of those a client offers in
/// `Sec-WebSocket-Protocol` (comma-separated): the first it offers that
/// nerve speaks.
pub fn choose_subprotocol<'a>(offered: impl IntoIterator<Item = &'a str>) -> Option<&'static str> {
    offered
        .into_iter()
        .flat_map(|h| h.split(','))
        .map(str::trim)
        .find_map(|p| SUBPROTOCOLS.iter().copied().find(|s| *s == p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_subprotocol_names_are_spoken_and_no_other() {
        assert_eq!(choose_subprotocol(["foxglove.websocket.v1"]), Some("foxglove.websocket.v1"));
        assert_eq!(choose_subprotocol(["foxglove.sdk.v1"]), Some("foxglove.sdk.v1"));
        assert_eq!(choose_subprotocol(["x, foxglove.sdk.v1", "foxglove.websocket.v1"]), Some("foxglove.sdk.v1"));
        assert_eq!(choose_subprotocol(["foxglove.websocket.v2", "ros"]), None);
        assert_eq!(choose_subprotocol([]), None);
    }

    #[test]
    fn a_message_frame_is_opcode_subscription_time_payload() {
        let f = message_data(7, 0x0102_0304_0506_0708, b"{}");
        assert_eq!(f[0], 1);
        assert_eq!(&f[1..5], &[7, 0, 0, 0]);
        assert_eq!(&f[5..13], &[8, 7, 6, 5, 4, 3, 2, 1]);
        assert_eq!(&f[13..], b"{}");
    }

    #[test]
    fn client_frames_are_parsed_or_refused() {
        assert_eq!(client_message_data(&[1, 5, 0, 0, 0, b'{', b'}']), Some((5, &b"{}"[..])));
        assert_eq!(client_message_data(&[1, 5, 0, 0]), None);
        assert_eq!(client_message_data(&[2, 5, 0, 0, 0]), None);
        assert_eq!(client_message_data(&[]), None);
    }

    #[test]
    fn client_messages_parse_by_op() {
        let m: ClientMessage =
            serde_json::from_str(r#"{"op":"subscribe","subscriptions":[{"id":3,"channelId":9}]}"#).expect("subscribe");
        assert!(matches!(m, ClientMessage::Subscribe { subscriptions } if subscriptions[0].channel_id == 9));
        let m: ClientMessage = serde_json::from_str(r#"{"op":"unsubscribe","subscriptionIds":[3]}"#).expect("unsub");
        assert!(matches!(m, ClientMessage::Unsubscribe { subscription_ids } if subscription_ids == [3]));
        let m: ClientMessage =
            serde_json::from_str(r#"{"op":"setParameters","parameters":[{"name":"/a/b","value":2.5}],"id":"x"}"#)
                .expect("set");
        assert!(matches!(m, ClientMessage::SetParameters { parameters, .. } if parameters[0].value == json!(2.5)));
        assert!(serde_json::from_str::<ClientMessage>(r#"{"op":"fly"}"#).is_err());
    }
}
