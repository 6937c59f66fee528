//! Loops in the wiring: whether a new connection closes a cycle of
//! event-driven agents.
//!
//! An event-driven agent runs its step when an input has a new sample; if
//! its output reaches its own input again through other event-driven agents
//! (`nerve connect r1/out r1/in`, or two relays feeding each other), every
//! sample wakes the next agent at once, forever: under SCHED_FIFO the loop
//! takes whole cores (reliability review F3c, F3d). A periodic agent on the
//! way breaks such a loop (it runs at its own rate), so only cycles made of
//! event-driven agents alone are reported. The router refuses such a
//! `connect` and the launch-file check refuses such a file, unless the
//! connection is allowed explicitly (`--allow-cycle`, `allow_cycle = true`).

use std::collections::{BTreeMap, BTreeSet, VecDeque};

/// The agents of the cycle that the edge `from_agent -> to_agent` would
/// close through `edges` (agent to agent), every one of them event-driven,
/// starting and ending with `from_agent`; `None` when it closes none.
pub fn event_cycle<'a>(
    edges: impl IntoIterator<Item = (&'a str, &'a str)>,
    from_agent: &str,
    to_agent: &str,
    event_driven: impl Fn(&str) -> bool,
) -> Option<Vec<String>> {
    if !event_driven(from_agent) || !event_driven(to_agent) {
        return None;
    }
    if from_agent == to_agent {
        return Some(vec![from_agent.to_owned(), to_agent.to_owned()]);
    }
    let mut next: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    for (a, b) in edges {
        next.entry(a).or_default().insert(b);
    }
    // breadth first from to_agent back to from_agent, through event-driven agents only
    let mut came_from: BTreeMap<&str, &str> = BTreeMap::new();
    let mut queue = VecDeque::from([to_agent]);
    let mut seen = BTreeSet::from([to_agent]);
    while let Some(a) = queue.pop_front() {
        for &b in next.get(a).into_iter().flatten() {
            if b == from_agent {
                // walk back from `a` to `to_agent`: the loop runs from_agent -> to_agent -> ... -> a -> from_agent
                let mut back = vec![a];
                let mut at = a;
                while let Some(&p) = came_from.get(at) {
                    back.push(p);
                    at = p;
                }
                let mut cycle = vec![from_agent.to_owned()];
                cycle.extend(back.iter().rev().map(|s| (*s).to_owned()));
                cycle.push(from_agent.to_owned());
                return Some(cycle);
            }
            if event_driven(b) && seen.insert(b) {
                came_from.insert(b, a);
                queue.push_back(b);
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn self_loops_and_cycles_of_event_driven_agents_are_found_and_named() {
        let event = |a: &str| a != "t1";
        assert_eq!(event_cycle([], "r1", "r1", event), Some(vec!["r1".to_owned(), "r1".to_owned()]));
        let edges = [("r2", "r3"), ("r3", "r1"), ("t1", "r1")];
        assert_eq!(
            event_cycle(edges, "r1", "r2", event),
            Some(vec!["r1".into(), "r2".into(), "r3".into(), "r1".into()]),
            "r1 -> r2 -> r3 -> r1"
        );
        assert_eq!(event_cycle([("r2", "r1")], "r1", "r2", event), Some(vec!["r1".into(), "r2".into(), "r1".into()]));
        // a periodic agent on the way breaks the loop
        assert_eq!(event_cycle([("r2", "t1"), ("t1", "r1")], "r1", "r2", event), None);
        assert_eq!(event_cycle([("t1", "r1")], "r1", "t1", event), None);
        // no way back
        assert_eq!(event_cycle([("r2", "r3")], "r1", "r2", event), None);
    }
}
