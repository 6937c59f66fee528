//! The wiring: the connection list (output port to input port, with the
//! checked type), the user's intent, persisted; the commands that carry a
//! connection out (the input's agent subscribes); and the figures of each
//! connection as its input sees them.
//!
//! An edge is in the list exactly when the user asked for it and its input
//! agent was either told to subscribe or was not running (it is wired when
//! it registers). A `disconnect` that the input agent did not answer keeps
//! the edge: the agent may still be reading (reliability review F2d).

use crate::store::Connection;
use shm_schemas::PortRef;
use shm_schemas::control::cli_to_router::{AgentView, ConnectionView};
use shm_schemas::control::router_to_agent::AgentCommand;

/// An input's depth when its agent does not say (one that has not answered yet).
const DEFAULT_DEPTH: u32 = agent_sdk::port::SUBSCRIBER_BUFFER as u32;

/// `c` as an edge, agent to agent, that a loop may not run through; `None`
/// when it is allowed to close one.
pub fn loop_edge(c: &Connection) -> Option<(&str, &str)> {
    (!c.allow_cycle).then(|| (c.from.agent.as_str(), c.to.agent.as_str()))
}

/// The connection list.
#[derive(Debug, Default)]
pub struct Wiring {
    list: Vec<Connection>,
}

impl Wiring {
    /// The list loaded from the store.
    pub fn new(list: Vec<Connection>) -> Self {
        Wiring { list }
    }

    /// Every connection.
    pub fn list(&self) -> &[Connection] {
        &self.list
    }

    /// Adds `c` (an edge already listed takes `c`'s settings); whether the
    /// list changed.
    pub fn add(&mut self, c: Connection) -> bool {
        match self.list.iter_mut().find(|e| e.from == c.from && e.to == c.to) {
            Some(e) if *e == c => false,
            Some(e) => {
                *e = c;
                true
            }
            None => {
                self.list.push(c);
                true
            }
        }
    }

    /// The edges, agent to agent, that a loop may not run through: those not
    /// allowed to close one.
    pub fn loop_edges(&self) -> impl Iterator<Item = (&str, &str)> {
        self.list.iter().filter_map(loop_edge)
    }

    /// The connection `from` → `to`.
    pub fn find(&self, from: &PortRef, to: &PortRef) -> Option<&Connection> {
        self.list.iter().find(|c| c.from == *from && c.to == *to)
    }

    /// Removes `from` → `to`; whether it was there.
    pub fn remove(&mut self, from: &PortRef, to: &PortRef) -> bool {
        let before = self.list.len();
        self.list.retain(|c| !(c.from == *from && c.to == *to));
        self.list.len() != before
    }

    /// The connections that involve `name` and whose two agents are live.
    pub fn involving(&self, name: &str, live: impl Fn(&str) -> bool) -> Vec<Connection> {
        self.list
            .iter()
            .filter(|c| c.from.agent.as_str() == name || c.to.agent.as_str() == name)
            .filter(|c| live(c.from.agent.as_str()) && live(c.to.agent.as_str()))
            .cloned()
            .collect()
    }

    /// The agent to command and the command that carries `c` out.
    pub fn connect_command(c: &Connection) -> (String, AgentCommand) {
        let cmd = AgentCommand::Connect {
            input: c.to.port.clone(),
            from_agent: c.from.agent.to_string(),
            from_port: c.from.port.clone(),
            type_name: c.type_name.clone(),
        };
        (c.to.agent.to_string(), cmd)
    }

    /// The agent to command and the command that undoes `c`.
    pub fn disconnect_command(c: &Connection) -> (String, AgentCommand) {
        let cmd = AgentCommand::Disconnect {
            input: c.to.port.clone(),
            from_agent: c.from.agent.to_string(),
            from_port: c.from.port.clone(),
        };
        (c.to.agent.to_string(), cmd)
    }

    /// Each connection with the figures its input reports in `agents`.
    pub fn views(&self, agents: &[AgentView]) -> Vec<ConnectionView> {
        self.list.iter().map(|c| view(c, agents, false)).collect()
    }
}

/// Connection `c` with the figures its input reports in `agents`
/// (`transient`: made by a tool, see [`crate::transient`]).
pub fn view(c: &Connection, agents: &[AgentView], transient: bool) -> ConnectionView {
    let (fa, fp) = (c.from.agent.as_str(), c.from.port.as_str());
    let (ta, tp) = (c.to.agent.as_str(), c.to.port.as_str());
    let input = agents
        .iter()
        .find(|a| a.name == ta)
        .and_then(|a| a.stats.as_ref())
        .and_then(|s| s.inputs.iter().find(|i| i.input == tp && i.from_agent == fa && i.from_port == fp));
    // the input's depth and policy, and what its queue and the source's keep-all side counted (issue 46)
    let queue = agents
        .iter()
        .find(|a| a.name == ta)
        .and_then(|a| a.stats.as_ref())
        .and_then(|s| s.queues.iter().find(|q| q.input == tp && q.from_agent == fa && q.from_port == fp));
    let sent = agents
        .iter()
        .find(|a| a.name == fa)
        .and_then(|a| a.stats.as_ref())
        .and_then(|s| s.outputs.iter().find(|o| o.output == fp))
        .filter(|_| queue.is_some_and(|q| q.lossless));
    // a tool is no agent: its edge is live while the input holds it
    let from_live = transient || agents.iter().any(|a| a.name == fa && a.pid != 0);
    ConnectionView {
        from: c.from.to_string(),
        to: c.to.to_string(),
        type_name: c.type_name.clone(),
        active: from_live && input.is_some(),
        rate_hz: input.map(|i| i.rate_hz).unwrap_or(0.0),
        last_age_ms: input.and_then(|i| i.last_age_ns).map(|ns| ns as f64 / 1e6),
        received: input.map(|i| i.received).unwrap_or(0),
        dropped: input.map(|i| i.dropped).unwrap_or(0),
        transient,
        depth: queue.map_or(DEFAULT_DEPTH, |q| q.depth),
        keep: if queue.is_some_and(|q| q.keep_all) { "all" } else { "latest" }.into(),
        lossless: queue.is_some_and(|q| q.lossless),
        overwritten: queue.map_or(0, |q| q.overwritten),
        back_pressure: queue.map_or(0, |q| q.back_pressure).saturating_add(sent.map_or(0, |o| o.back_pressure)),
        lost: sent.map_or(0, |o| o.lost),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(text: &str) -> PortRef {
        text.parse().expect("a port")
    }

    fn c(from: &str, to: &str) -> Connection {
        Connection { from: p(from), to: p(to), type_name: "nerve::Tick".into(), allow_cycle: false }
    }

    #[test]
    fn the_list_holds_each_edge_once_and_finds_those_of_an_agent() {
        let mut w = Wiring::default();
        assert!(w.add(c("t1/tick", "r1/in")));
        assert!(!w.add(c("t1/tick", "r1/in")));
        assert!(w.add(c("r1/out", "r2/in")));
        assert_eq!(w.involving("r1", |_| true).len(), 2);
        assert_eq!(w.involving("r1", |a| a != "t1").len(), 1, "only edges whose two ends are live");
        let (agent, cmd) = Wiring::connect_command(&c("t1/tick", "r1/in"));
        assert_eq!(agent, "r1");
        assert!(
            matches!(cmd, AgentCommand::Connect { ref input, ref from_agent, .. } if input == "in" && from_agent == "t1")
        );
        assert!(w.remove(&p("t1/tick"), &p("r1/in")));
        assert!(!w.remove(&p("t1/tick"), &p("r1/in")));
        assert_eq!(w.list().len(), 1);
    }
}
