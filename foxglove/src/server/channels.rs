//! The channels: every output port of the robot, advertised to every
//! client as it comes and unadvertised as it goes ([`refresh_channels`]),
//! and the samples of the subscribed ports fanned out to the clients'
//! queues ([`read_ports`]). Only ports some client subscribed to are read.

use super::client::{Client, Data};
use super::{Hub, lock};
use crate::Robot;
use crate::protocol::{self, Channel};
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// The channels advertised, by topic.
#[derive(Default)]
pub(super) struct Channels {
    pub(super) by_topic: BTreeMap<String, Channel>,
    pub(super) next_id: u32,
}

/// Brings the channels up to date with the robot's output ports and tells
/// every client what came and went.
pub(super) fn refresh_channels(hub: &Hub, robot: &mut dyn Robot) {
    let specs = match robot.channels() {
        Ok(s) => s,
        Err(e) => {
            tracing::debug!("no channels now: {e}");
            return;
        }
    };
    let mut channels = lock(&hub.channels);
    let wanted: BTreeMap<&str, &crate::ChannelSpec> = specs.iter().map(|s| (s.topic.as_str(), s)).collect();
    let mut removed = Vec::new();
    channels.by_topic.retain(|topic, c| {
        let same = wanted.get(topic.as_str()).is_some_and(|s| s.schema == c.schema && s.schema_name == c.schema_name);
        if !same {
            removed.push(c.id);
        }
        same
    });
    let mut added = Vec::new();
    for s in &specs {
        if channels.by_topic.contains_key(&s.topic) {
            continue;
        }
        channels.next_id = channels.next_id.wrapping_add(1);
        let c = Channel {
            id: channels.next_id,
            topic: s.topic.clone(),
            encoding: "json".into(),
            schema_name: s.schema_name.clone(),
            schema: s.schema.clone(),
            schema_encoding: "jsonschema".into(),
        };
        added.push(c.clone());
        channels.by_topic.insert(s.topic.clone(), c);
    }
    if removed.is_empty() && added.is_empty() {
        return;
    }
    tracing::info!(added = added.len(), removed = removed.len(), "channels changed");
    let clients = lock(&hub.clients);
    for c in clients.values() {
        if !removed.is_empty() {
            lock(&c.subs).retain(|_, ch| !removed.contains(ch));
            c.say(protocol::unadvertise(&removed));
        }
        if !added.is_empty() {
            c.say(protocol::advertise(&added));
        }
    }
}

/// Reads the subscribed ports and queues each sample for its subscribers;
/// whether a sample was queued for someone.
pub(super) fn read_ports(hub: &Hub, robot: &mut dyn Robot) -> bool {
    // channel id -> [(client, subscription)]
    let mut fan: HashMap<u32, Vec<(Arc<Client>, u32)>> = HashMap::new();
    for c in lock(&hub.clients).values() {
        for (&sub, &ch) in lock(&c.subs).iter() {
            fan.entry(ch).or_default().push((Arc::clone(c), sub));
        }
    }
    let topics: Vec<(String, u32)> = {
        let channels = lock(&hub.channels);
        channels.by_topic.values().filter(|c| fan.contains_key(&c.id)).map(|c| (c.topic.clone(), c.id)).collect()
    };
    let names: Vec<&str> = topics.iter().map(|(t, _)| t.as_str()).collect();
    let queue = hub.opts.queue.max(1);
    // the clients that got something: woken once each, after the read
    let mut fed: BTreeMap<u64, Arc<Client>> = BTreeMap::new();
    robot.read(&names, &mut |topic, unix_ns, payload| {
        let Some(ch) = topics.iter().find(|(t, _)| t == topic).map(|(_, c)| *c) else { return };
        let payload = Arc::new(payload);
        for (c, sub) in fan.get(&ch).into_iter().flatten() {
            let d = Data { subscription: *sub, unix_ns, payload: Arc::clone(&payload) };
            if lock(&c.out).push_data(d, queue) {
                hub.dropped_messages.fetch_add(1, Ordering::Relaxed);
            }
            fed.entry(c.id).or_insert_with(|| Arc::clone(c));
        }
    });
    for c in fed.values() {
        c.wake.wake();
    }
    !fed.is_empty()
}
