//! Edges from tools that are not agents ([`CliRequest::Attach`]): `nerve
//! cmd` publishes on a port of its own for a moment, and the router has the
//! input's agent subscribe to it, as for any other source.
//!
//! Unlike the connection list ([`crate::wiring::Wiring`]) these edges are
//! never saved and never made again after a restart: each belongs to a
//! process, and goes when that process is gone (looked at with the agents'
//! liveness), when the tool detaches, or when the input's agent leaves
//! (its subscription went with it).
//!
//! [`CliRequest::Attach`]: shm_schemas::control::cli_to_router::CliRequest::Attach

use crate::store::Connection;
use agent_sdk::process::ProcessHandle;
use shm_schemas::PortRef;

/// One edge from a tool.
#[derive(Debug, Clone)]
pub struct Attached {
    /// the edge (`from` is the tool's port)
    pub conn: Connection,
    /// the tool's process, taken when it attached
    pub process: ProcessHandle,
}

/// The tools' edges.
#[derive(Debug, Default)]
pub struct Transient {
    edges: Vec<Attached>,
}

impl Transient {
    /// Records `a`; false if that edge was there (the older one is replaced).
    pub fn add(&mut self, a: Attached) -> bool {
        let fresh = self.remove(&a.conn.from, &a.conn.to).is_none();
        self.edges.push(a);
        fresh
    }

    /// Forgets the edge `from -> to` and returns it.
    pub fn remove(&mut self, from: &PortRef, to: &PortRef) -> Option<Attached> {
        let i = self.edges.iter().position(|a| a.conn.from == *from && a.conn.to == *to)?;
        Some(self.edges.remove(i))
    }

    /// Forgets and returns the edges of the tools `gone` says are gone
    /// (the router's driver looks at the processes, [`Transient::tools`]).
    pub fn orphaned(&mut self, gone: impl Fn(&ProcessHandle) -> bool) -> Vec<Attached> {
        let (gone, kept) = std::mem::take(&mut self.edges).into_iter().partition(|a| gone(&a.process));
        self.edges = kept;
        gone
    }

    /// Forgets and returns the edges into agent `name`, which left.
    pub fn into_agent(&mut self, name: &str) -> Vec<Attached> {
        let (gone, kept) = std::mem::take(&mut self.edges).into_iter().partition(|a| a.conn.to.agent.as_str() == name);
        self.edges = kept;
        gone
    }

    /// The tools' processes, one per edge.
    pub fn tools(&self) -> impl Iterator<Item = &ProcessHandle> {
        self.edges.iter().map(|a| &a.process)
    }

    /// Every edge, in the order they were made.
    pub fn connections(&self) -> impl Iterator<Item = &Connection> {
        self.edges.iter().map(|a| &a.conn)
    }

    /// Whether no tool feeds any input.
    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn a(from: &str, to: &str, process: &ProcessHandle) -> Attached {
        Attached {
            conn: Connection {
                from: from.parse().expect("a port"),
                to: to.parse().expect("a port"),
                type_name: "nerve::Tick".into(),
                allow_cycle: false,
            },
            process: process.clone(),
        }
    }

    #[test]
    fn edges_go_with_their_tool_with_their_agent_and_on_detach() {
        let me = ProcessHandle::take(std::process::id()).expect("this process");
        let mut tool = std::process::Command::new("sleep").arg("30").spawn().expect("sleep runs");
        let gone_tool = ProcessHandle::take(tool.id()).expect("sleep runs");
        let mut t = Transient::default();
        assert!(t.add(a("cli-7/in", "r1/in", &me)));
        assert!(!t.add(a("cli-7/in", "r1/in", &me)), "the same edge twice is one edge");
        assert!(t.add(a("cli-8/in", "r2/in", &gone_tool)));
        assert!(t.add(a("cli-9/in", "r1/in", &me)));
        assert_eq!(t.connections().count(), 3);
        assert!(t.orphaned(|p| !p.is_alive()).is_empty(), "every tool runs");

        tool.kill().expect("kill sleep");
        tool.wait().expect("reap sleep");
        let gone = t.orphaned(|p| !p.is_alive());
        assert_eq!(gone.iter().map(|g| g.conn.from.to_string()).collect::<Vec<_>>(), ["cli-8/in"]);
        assert!(t.connections().all(|c| c.from.to_string() != "cli-8/in"));

        let left = t.into_agent("r1");
        assert_eq!(left.len(), 2, "both tools fed r1");
        assert!(t.is_empty());

        t.add(a("cli-7/in", "r1/in", &me));
        assert_eq!(
            t.remove(&"cli-7/in".parse().expect("a port"), &"r1/in".parse().expect("a port")).map(|x| x.process.pid()),
            Some(std::process::id())
        );
        assert!(t.remove(&"cli-7/in".parse().expect("a port"), &"r1/in".parse().expect("a port")).is_none());
    }
}
