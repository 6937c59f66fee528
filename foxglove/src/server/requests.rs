//! What clients ask: a client's thread parses its requests ([`request`],
//! [`publish`]) and does at once what needs only the server (subscribing,
//! unsubscribing, refusals); what needs the robot goes to the serving thread
//! as a [`Request`], in order, and is answered there ([`answer`]):
//! parameters read and set, input ports checked and published into, the
//! graph, service calls.

use super::client::Client;
use super::watched::{Graph, ParamState, graph_update};
use super::{Hub, lock, services};
use crate::Robot;
use crate::protocol::{self, ClientMessage, Parameter};
use std::collections::BTreeSet;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::Sender;

/// What a client's thread sends to the serving thread.
pub(super) enum Request {
    Get {
        client: Arc<Client>,
        names: Vec<String>,
        id: Option<String>,
    },
    Set {
        client: Arc<Client>,
        parameters: Vec<Parameter>,
        id: Option<String>,
    },
    Advertise {
        client: Arc<Client>,
        channels: Vec<protocol::ClientChannel>,
    },
    Publish {
        client: Arc<Client>,
        topic: String,
        payload: Vec<u8>,
    },
    Graph {
        client: Arc<Client>,
    },
    /// a service call
    Call(services::Call),
    /// a client subscribed to parameter updates: the values it is measured against are taken now,
    /// before any later request of it (the channel keeps their order)
    WatchParams,
}

/// A client's JSON request.
pub(super) fn request(hub: &Hub, client: &Arc<Client>, tx: &Sender<Request>, text: &str) {
    let msg: ClientMessage = match serde_json::from_str(text) {
        Ok(m) => m,
        Err(e) => {
            client.error(&format!("nerve foxglove does not understand this request ({e})"));
            return;
        }
    };
    let send = |r: Request| hub.ask(tx, r);
    match msg {
        ClientMessage::Subscribe { subscriptions } => {
            let channels = lock(&hub.channels);
            let known: BTreeSet<u32> = channels.by_topic.values().map(|c| c.id).collect();
            let mut subs = lock(&client.subs);
            for s in subscriptions {
                if known.contains(&s.channel_id) {
                    subs.insert(s.id, s.channel_id);
                } else {
                    client.error(&format!("no channel {} is advertised (any more)", s.channel_id));
                }
            }
        }
        ClientMessage::Unsubscribe { subscription_ids } => {
            let mut subs = lock(&client.subs);
            for id in subscription_ids {
                subs.remove(&id);
            }
        }
        ClientMessage::GetParameters { parameter_names, id } => {
            send(Request::Get { client: Arc::clone(client), names: parameter_names, id })
        }
        ClientMessage::SetParameters { parameters, id } => {
            if let Some(why) = edit_refused(hub, client, "set parameters") {
                client.error(&why);
            } else {
                send(Request::Set { client: Arc::clone(client), parameters, id });
            }
        }
        ClientMessage::Advertise { channels } => {
            if !hub.opts.publish {
                client.error("this nerve foxglove does not take publishing: start it with --publish");
            } else if let Some(why) = edit_refused(hub, client, "publish") {
                client.error(&why);
            } else {
                // known at once, so that messages sent right after the advertise are taken; the
                // serving thread checks the port (in order, before them) and forgets a refused one
                let mut p = lock(&client.publishing);
                for ch in &channels {
                    p.insert(ch.id, ch.topic.clone());
                }
                drop(p);
                send(Request::Advertise { client: Arc::clone(client), channels });
            }
        }
        ClientMessage::Unadvertise { channel_ids } => {
            let mut p = lock(&client.publishing);
            for id in channel_ids {
                p.remove(&id);
            }
        }
        ClientMessage::SubscribeParameterUpdates { parameter_names } => {
            lock(&client.params).extend(parameter_names);
            send(Request::WatchParams);
        }
        ClientMessage::UnsubscribeParameterUpdates { parameter_names } => {
            let mut p = lock(&client.params);
            for n in &parameter_names {
                p.remove(n);
            }
        }
        ClientMessage::SubscribeConnectionGraph => {
            client.graph.store(true, Ordering::Relaxed);
            send(Request::Graph { client: Arc::clone(client) });
        }
        ClientMessage::UnsubscribeConnectionGraph => client.graph.store(false, Ordering::Relaxed),
    }
}

/// Why `client` may not change the robot, if it may not.
pub(super) fn edit_refused(hub: &Hub, client: &Client, what: &str) -> Option<String> {
    if hub.opts.read_only {
        return Some(format!("this nerve foxglove is read-only: it does not let clients {what}"));
    }
    if !client.edit {
        return Some(format!(
            "to {what}, connect with the edit token: ws://ADDRESS/?token=TOKEN (nerve foxglove printed it, or it is \
             the one in NERVE_FOXGLOVE_TOKEN)"
        ));
    }
    None
}

/// A client's binary frame: a message to publish, or a service call.
pub(super) fn publish(hub: &Hub, client: &Arc<Client>, tx: &Sender<Request>, frame: &[u8]) {
    if frame.first() == Some(&services::OP_SERVICE_CALL_REQUEST) {
        return services::request(hub, client, tx, frame);
    }
    let Some((channel, payload)) = protocol::client_message_data(frame) else {
        client.error("a binary frame that is not a client message (opcode 1, channel id, payload) was ignored");
        return;
    };
    if let Some(why) = edit_refused(hub, client, "publish") {
        client.error(&why);
        return;
    }
    let topic = lock(&client.publishing).get(&channel).cloned();
    match topic {
        Some(topic) => {
            hub.ask(tx, Request::Publish { client: Arc::clone(client), topic, payload: payload.to_vec() });
        }
        None => client.error(&format!("channel {channel} was not advertised by this client (or was refused)")),
    }
}

/// Answers a request that needs the robot.
pub(super) fn answer(hub: &Hub, robot: &mut dyn Robot, req: Request, params: &mut ParamState) {
    match req {
        Request::Get { client, names, id } => match robot.parameters() {
            Ok(all) => {
                let chosen: Vec<Parameter> =
                    all.into_iter().filter(|p| names.is_empty() || names.contains(&p.name)).collect();
                client.say(protocol::parameter_values(&chosen, id.as_deref()));
            }
            Err(e) => client.error(&format!("cannot read the parameters: {e}")),
        },
        Request::Set { client, parameters, id } => {
            let mut done = Vec::new();
            for p in &parameters {
                match robot.set_parameter(&p.name, &p.value) {
                    Ok(()) => {
                        tracing::info!(client = client.id, name = %p.name, value = %p.value, "parameter set");
                        done.push(p.name.clone());
                    }
                    Err(e) => client.error(&format!("{} was not set to {}: {e}", p.name, p.value)),
                }
            }
            if id.is_some() {
                let all = robot.parameters().unwrap_or_default();
                let values: Vec<Parameter> = all.into_iter().filter(|p| done.contains(&p.name)).collect();
                client.say(protocol::parameter_values(&values, id.as_deref()));
            }
        }
        Request::Advertise { client, channels } => {
            for ch in channels {
                if ch.encoding != "json" {
                    lock(&client.publishing).remove(&ch.id);
                    client.error(&format!(
                        "channel {} ({}) is in {:?}: nerve foxglove takes json",
                        ch.id, ch.topic, ch.encoding
                    ));
                    continue;
                }
                match robot.input(&ch.topic) {
                    Ok(type_name) => {
                        tracing::info!(client = client.id, topic = %ch.topic, type_name, "client publishes");
                    }
                    Err(e) => {
                        lock(&client.publishing).remove(&ch.id);
                        client.error(&format!("cannot publish on {}: {e}", ch.topic));
                    }
                }
            }
        }
        Request::Publish { client, topic, payload } => {
            if let Err(e) = robot.publish(&topic, &payload) {
                client.error(&format!("a message for {topic} was refused: {e}"));
            }
        }
        Request::Graph { client } => match Graph::read(hub, robot) {
            // the whole graph to the new watcher; the others hear of changes only
            Ok(g) => client.say(graph_update(&g, &[], &[])),
            Err(e) => client.error(&format!("cannot read the connection graph: {e}")),
        },
        Request::Call(call) => services::call(hub, robot, call),
        Request::WatchParams => params.refresh(hub, robot),
    }
}
