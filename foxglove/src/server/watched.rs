//! What clients watch that the router does not announce: parameter values
//! and the connection graph. Both are read again at each refresh while a
//! client watches them, and only what changed is sent: [`ParamState`] to
//! the clients subscribed to those parameters, [`GraphState`] to the
//! clients subscribed to the graph (Foxglove's Topic Graph panel).
//!
//! The graph is the robot's topics (who publishes, who is fed) and the
//! services advertised (`advertisedServices`, each with the agent that
//! provides it): an agent that comes or goes changes both, and a service
//! that went is named in `removedServices`.

use super::{Client, Hub, lock, services};
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

/// The connection graph as told to clients: the robot's topics, and every
/// service advertised with its providers (`(/<agent>/<service>, [agent])`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct Graph {
    topics: GraphSpec,
    services: Vec<(String, Vec<String>)>,
}

impl Graph {
    /// The robot's graph now, with the services the server advertises.
    pub(super) fn read(hub: &Hub, robot: &mut dyn Robot) -> Result<Graph, String> {
        let topics = robot.graph()?;
        Ok(Graph { topics, services: services::providers(&lock(&hub.services)) })
    }
}

/// The connection graph last sent.
#[derive(Default)]
pub(super) struct GraphState {
    last: Option<Graph>,
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
        let g = match Graph::read(hub, robot) {
            Ok(g) => g,
            Err(e) => {
                tracing::debug!("no graph now: {e}");
                return;
            }
        };
        if self.last.as_ref() == Some(&g) {
            return;
        }
        let topics = |g: &Graph| -> BTreeSet<String> {
            g.topics.published.iter().chain(&g.topics.subscribed).map(|(t, _)| t.clone()).collect()
        };
        let names = |g: &Graph| -> BTreeSet<String> { g.services.iter().map(|(s, _)| s.clone()).collect() };
        let (old_topics, old_services) = self.last.as_ref().map(|l| (topics(l), names(l))).unwrap_or_default();
        let (now_topics, now_services) = (topics(&g), names(&g));
        let removed_topics: Vec<&str> = old_topics.difference(&now_topics).map(String::as_str).collect();
        let removed_services: Vec<&str> = old_services.difference(&now_services).map(String::as_str).collect();
        let msg = graph_update(&g, &removed_topics, &removed_services);
        for c in &watchers {
            c.say(msg.clone());
        }
        self.last = Some(g);
    }
}

/// `connectionGraphUpdate`: the whole graph `g` (each list replaces what a
/// client knew of its names), and the topics and services gone since the
/// last one.
pub(super) fn graph_update(g: &Graph, removed_topics: &[&str], removed_services: &[&str]) -> String {
    let t = &g.topics;
    let published: Vec<Value> = t.published.iter().map(|(t, ids)| json!({ "name": t, "publisherIds": ids })).collect();
    let subscribed: Vec<Value> =
        t.subscribed.iter().map(|(t, ids)| json!({ "name": t, "subscriberIds": ids })).collect();
    let services: Vec<Value> = g.services.iter().map(|(s, ids)| json!({ "name": s, "providerIds": ids })).collect();
    json!({
        "op": "connectionGraphUpdate",
        "publishedTopics": published,
        "subscribedTopics": subscribed,
        "advertisedServices": services,
        "removedTopics": removed_topics,
        "removedServices": removed_services,
    })
    .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_graph_update_names_services_their_providers_and_what_left() {
        let g = Graph {
            topics: GraphSpec {
                published: vec![("/t/tick".into(), vec!["t".into()])],
                subscribed: vec![("/t/tick".into(), vec!["r".into()])],
            },
            services: vec![("/s/plan".into(), vec!["s".into()])],
        };
        let v: Value = serde_json::from_str(&graph_update(&g, &["/x/y"], &["/x/go"])).expect("json");
        assert_eq!(v["op"], "connectionGraphUpdate");
        assert_eq!(v["publishedTopics"][0]["publisherIds"][0], "t");
        assert_eq!(v["subscribedTopics"][0]["subscriberIds"][0], "r");
        assert_eq!(v["advertisedServices"][0]["name"], "/s/plan");
        assert_eq!(v["advertisedServices"][0]["providerIds"], json!(["s"]));
        assert_eq!(v["removedTopics"][0], "/x/y");
        assert_eq!(v["removedServices"], json!(["/x/go"]));
    }
}
