//! What clients watch that the router does not announce: parameter values
//! and the connection graph. Both are read again at each refresh while a
//! client watches them, and only what changed is sent: [`ParamState`] to
//! the clients subscribed to those parameters, [`GraphState`] to the
//! clients subscribed to the graph (Foxglove's Topic Graph panel).

use super::{Client, Hub, lock};
use crate::protocol::{self, Parameter};
use crate::{GraphSpec, Robot};
use serde_json::{Value, json};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// The parameter values last seen, for the clients that subscribed to
/// changes (the router sends no notice of them: they are looked at each
/// refresh while someone listens).
#[derive(Default)]
pub(super) struct ParamState {
    last: Option<BTreeMap<String, Value>>,
}

impl ParamState {
    pub(super) fn refresh(&mut self, hub: &Hub, robot: &mut dyn Robot) {
        let listeners: Vec<Arc<Client>> =
            lock(&hub.clients).values().filter(|c| !lock(&c.params).is_empty()).cloned().collect();
        if listeners.is_empty() {
            self.last = None;
            return;
        }
        let now: BTreeMap<String, Value> = match robot.parameters() {
            Ok(all) => all.into_iter().map(|p| (p.name, p.value)).collect(),
            Err(e) => {
                tracing::debug!("no parameters now: {e}");
                return;
            }
        };
        if let Some(last) = &self.last {
            let changed: Vec<Parameter> = now
                .iter()
                .filter(|(n, v)| last.get(*n) != Some(*v))
                .map(|(n, v)| Parameter { name: n.clone(), value: v.clone() })
                .collect();
            for c in &listeners {
                let wanted = lock(&c.params);
                let mine: Vec<Parameter> = changed.iter().filter(|p| wanted.contains(&p.name)).cloned().collect();
                drop(wanted);
                if !mine.is_empty() {
                    c.say(protocol::parameter_values(&mine, None));
                }
            }
        }
        self.last = Some(now);
    }
}

/// The connection graph last sent.
#[derive(Default)]
pub(super) struct GraphState {
    last: Option<GraphSpec>,
}

impl GraphState {
    /// Reads the graph when a client watches it and sends what changed.
    pub(super) fn refresh(&mut self, hub: &Hub, robot: &mut dyn Robot) {
        let watchers: Vec<Arc<Client>> =
            lock(&hub.clients).values().filter(|c| c.graph.load(Ordering::Relaxed)).cloned().collect();
        if watchers.is_empty() {
            self.last = None;
            return;
        }
        let g = match robot.graph() {
            Ok(g) => g,
            Err(e) => {
                tracing::debug!("no graph now: {e}");
                return;
            }
        };
        if self.last.as_ref() == Some(&g) {
            return;
        }
        let old: BTreeSet<&str> =
            self.last.iter().flat_map(|l| l.published.iter().chain(&l.subscribed).map(|(t, _)| t.as_str())).collect();
        let now: BTreeSet<&str> = g.published.iter().chain(&g.subscribed).map(|(t, _)| t.as_str()).collect();
        let removed: Vec<&str> = old.difference(&now).copied().collect();
        let msg = graph_update(&g, &removed);
        for c in &watchers {
            c.say(msg.clone());
        }
        self.last = Some(g);
    }
}

pub(super) fn graph_update(g: &GraphSpec, removed: &[&str]) -> String {
    let published: Vec<Value> = g.published.iter().map(|(t, ids)| json!({ "name": t, "publisherIds": ids })).collect();
    let subscribed: Vec<Value> =
        g.subscribed.iter().map(|(t, ids)| json!({ "name": t, "subscriberIds": ids })).collect();
    json!({
        "op": "connectionGraphUpdate",
        "publishedTopics": published,
        "subscribedTopics": subscribed,
        "advertisedServices": [],
        "removedTopics": removed,
        "removedServices": [],
    })
    .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_graph_update_names_what_left() {
        let g = GraphSpec {
            published: vec![("/t/tick".into(), vec!["t".into()])],
            subscribed: vec![("/t/tick".into(), vec!["r".into()])],
        };
        let v: Value = serde_json::from_str(&graph_update(&g, &["/x/y"])).expect("json");
        assert_eq!(v["op"], "connectionGraphUpdate");
        assert_eq!(v["publishedTopics"][0]["publisherIds"][0], "t");
        assert_eq!(v["subscribedTopics"][0]["subscriberIds"][0], "r");
        assert_eq!(v["removedTopics"][0], "/x/y");
    }
}
