//! The registry: the agents live now, as they registered (name, pid, kind,
//! task, ports, log file) and the state the router last set (running or
//! suspended). It holds live agents only: a dead agent is removed by the
//! liveness check ([`Registry::dead`]) and its supervision decides what
//! follows.

use agent_sdk::world::pid_alive;
use shm_schemas::control::agent_to_router::Registration;
use shm_schemas::control::cli_to_router::{AgentState, RouterError};
use shm_schemas::{AgentName, PortRef};
use std::collections::BTreeMap;

/// One live agent.
#[derive(Debug)]
pub struct Entry {
    /// what it told the router at registration (its period follows `nerve rate`)
    pub reg: Registration,
    /// running or suspended, as last set
    pub state: AgentState,
}

/// The live agents, by name.
#[derive(Debug, Default)]
pub struct Registry {
    agents: BTreeMap<String, Entry>,
}

impl Registry {
    /// Adds `reg`, replacing an earlier instance of the same name that is
    /// dead; refuses a bad name or a name a live process holds.
    pub fn register(&mut self, reg: Registration) -> Result<(), RouterError> {
        AgentName::new(&reg.name).map_err(|e| RouterError::InvalidName(e.to_string()))?;
        if let Some(existing) = self.agents.get(&reg.name)
            && existing.reg.pid != reg.pid
            && pid_alive(existing.reg.pid)
        {
            return Err(RouterError::DuplicateName { name: reg.name, pid: existing.reg.pid });
        }
        let state = if reg.suspended { AgentState::Suspended } else { AgentState::Running };
        self.agents.insert(reg.name.clone(), Entry { reg, state });
        Ok(())
    }

    /// Removes `name` if its pid is `pid` (an agent leaving); whether it did.
    pub fn unregister(&mut self, name: &str, pid: u32) -> bool {
        if self.agents.get(name).is_some_and(|e| e.reg.pid == pid) {
            self.agents.remove(name);
            return true;
        }
        false
    }

    /// Removes the agents whose process is gone (a few `/proc` reads);
    /// returns their names and pids.
    pub fn dead(&mut self) -> Vec<(String, u32)> {
        let dead: Vec<(String, u32)> =
            self.agents.iter().filter(|(_, e)| !pid_alive(e.reg.pid)).map(|(n, e)| (n.clone(), e.reg.pid)).collect();
        for (name, _) in &dead {
            self.agents.remove(name);
        }
        dead
    }

    /// The live agent `name`.
    pub fn get(&self, name: &str) -> Option<&Entry> {
        self.agents.get(name)
    }

    /// The live agent `name`, to change.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut Entry> {
        self.agents.get_mut(name)
    }

    /// Whether `name` is live.
    pub fn contains(&self, name: &str) -> bool {
        self.agents.contains_key(name)
    }

    /// The live agents, by name.
    pub fn iter(&self) -> impl Iterator<Item = (&String, &Entry)> {
        self.agents.iter()
    }

    /// The live agent `name`, or the error that lists the live ones.
    pub fn live(&self, name: &str) -> Result<&Entry, RouterError> {
        self.agents.get(name).ok_or_else(|| self.unknown(name))
    }

    /// The error for an agent that is not live.
    pub fn unknown(&self, name: &str) -> RouterError {
        RouterError::UnknownAgent { name: name.into(), running: self.agents.keys().cloned().collect() }
    }

    /// The payload type of port `p` (an output when `output`), or why there is none.
    pub fn port_type(&self, p: &PortRef, output: bool) -> Result<String, RouterError> {
        let entry = self.live(p.agent.as_str())?;
        let ports = if output { &entry.reg.outputs } else { &entry.reg.inputs };
        ports.iter().find(|s| s.name == p.port).map(|s| s.type_name.clone()).ok_or_else(|| RouterError::UnknownPort {
            agent: p.agent.to_string(),
            port: p.port.clone(),
            direction: if output { "output" } else { "input" }.into(),
            available: ports.iter().map(|s| s.name.clone()).collect(),
        })
    }
}
