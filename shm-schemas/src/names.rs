//! Naming rules: robots, agents, ports and the iceoryx2 services they map to.
//!
//! * every service of robot `R` lives under `nerve/R/`;
//! * output port `A/P` is the publish-subscribe (and event) service `nerve/R/A/P`;
//! * agent `A`'s control service is `nerve/R/A/ctl`;
//! * the router's service is `nerve/R/router`.
//!
//! Names are validated here once, so that every process agrees on them.

use crate::fixed::FIXED_NAME_CAPACITY;
use serde::{Deserialize, Serialize};
use std::fmt;

/// A name that is not allowed, with the rule it breaks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    /// The name is empty.
    #[error("{what} name is empty")]
    Empty {
        /// robot, agent or port
        what: &'static str,
    },
    /// The name is longer than allowed.
    #[error("{what} name {name:?} is {len} bytes long; at most {max} are allowed")]
    TooLong {
        /// robot, agent or port
        what: &'static str,
        /// the offending name
        name: String,
        /// its length
        len: usize,
        /// the limit
        max: usize,
    },
    /// The name contains a character outside the allowed set.
    #[error("{what} name {name:?} contains {ch:?}; use lowercase letters, digits and {allowed}")]
    BadChar {
        /// robot, agent or port
        what: &'static str,
        /// the offending name
        name: String,
        /// the first bad character
        ch: char,
        /// the punctuation that is allowed
        allowed: &'static str,
    },
    /// The name is reserved for nerve's own services.
    #[error("{what} name {name:?} is reserved by nerve; choose another")]
    Reserved {
        /// robot, agent or port
        what: &'static str,
        /// the offending name
        name: String,
    },
    /// A port reference is not of the form `agent/port`.
    #[error("{0:?} is not a port reference; write AGENT/PORT, e.g. t1/tick")]
    NotAPortRef(String),
}

/// The calling process's effective user id (the owner of every file it creates).
pub fn effective_uid() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

fn check(what: &'static str, name: &str, max: usize, extra: &[char], allowed: &'static str) -> Result<(), NameError> {
    if name.is_empty() {
        return Err(NameError::Empty { what });
    }
    if name.len() > max {
        return Err(NameError::TooLong { what, name: name.into(), len: name.len(), max });
    }
    let first = name.chars().next().unwrap_or('a');
    if !(first.is_ascii_lowercase() || first.is_ascii_digit()) {
        return Err(NameError::BadChar { what, name: name.into(), ch: first, allowed });
    }
    if let Some(ch) = name.chars().find(|c| !(c.is_ascii_lowercase() || c.is_ascii_digit() || extra.contains(c))) {
        return Err(NameError::BadChar { what, name: name.into(), ch, allowed });
    }
    Ok(())
}

/// The name of a robot: its own isolated world of services.
///
/// Lowercase letters, digits and `-`, at most 24 bytes. The underscore is not
/// allowed because the robot name is embedded in the shared-memory file prefix
/// `nerve_<uid>_<robot>_`, and `_` would let one robot's prefix be a prefix of
/// another's.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct RobotName(String);

impl RobotName {
    /// Longest robot name.
    pub const MAX_LEN: usize = 24;

    /// Validates a robot name.
    pub fn new(name: &str) -> Result<Self, NameError> {
        check("robot", name, Self::MAX_LEN, &['-'], "'-'")?;
        Ok(RobotName(name.to_owned()))
    }

    /// The name as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The shared-memory file prefix of this robot's world for the calling
    /// user, `nerve_<uid>_<robot>_` (effective uid): two users who both run
    /// a robot named `default` on one host never share a file.
    pub fn shm_prefix(&self) -> String {
        Self::shm_prefix_of(effective_uid(), &self.0)
    }

    /// The shared-memory file prefix of robot `robot` of user `uid`.
    pub fn shm_prefix_of(uid: u32, robot: &str) -> String {
        format!("nerve_{uid}_{robot}_")
    }

    /// The router's service for agents (registration), `nerve/<robot>/router`.
    pub fn router_service(&self) -> String {
        format!("nerve/{}/router", self.0)
    }

    /// The router's service for tools and programs (`nerve` commands, the
    /// decision maker), `nerve/<robot>/router/cli`: few clients, replies of
    /// any size. Agents register on [`RobotName::router_service`].
    pub fn router_cli_service(&self) -> String {
        format!("nerve/{}/router/cli", self.0)
    }

    /// The router's epoch service, on which a (re)started router announces itself.
    pub fn router_epoch_service(&self) -> String {
        format!("nerve/{}/router/epoch", self.0)
    }

    /// The control service of an agent, `nerve/<robot>/<agent>/ctl`.
    pub fn ctl_service(&self, agent: &AgentName) -> String {
        format!("nerve/{}/{}/ctl", self.0, agent.as_str())
    }

    /// The service of an output port, `nerve/<robot>/<agent>/<port>`.
    pub fn port_service(&self, agent: &str, port: &str) -> String {
        format!("nerve/{}/{}/{}", self.0, agent, port)
    }
}

impl fmt::Display for RobotName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl TryFrom<String> for RobotName {
    type Error = NameError;
    fn try_from(s: String) -> Result<Self, NameError> {
        RobotName::new(&s)
    }
}

impl From<RobotName> for String {
    fn from(r: RobotName) -> String {
        r.0
    }
}

/// Names an agent may not take: they would collide with nerve's own services.
pub const RESERVED_AGENT_NAMES: &[&str] = &["router", "nerve", "cli"];

/// Port names an agent may not use: `ctl` is the control service.
pub const RESERVED_PORT_NAMES: &[&str] = &["ctl", "epoch"];

/// The name of an agent, unique within its robot.
///
/// Lowercase letters, digits, `-` and `_`, at most 32 bytes (so that it fits a
/// [`crate::FixedName`] in every sample header).
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct AgentName(String);

impl AgentName {
    /// Validates an agent name.
    pub fn new(name: &str) -> Result<Self, NameError> {
        check("agent", name, FIXED_NAME_CAPACITY, &['-', '_'], "'-' or '_'")?;
        if RESERVED_AGENT_NAMES.contains(&name) {
            return Err(NameError::Reserved { what: "agent", name: name.into() });
        }
        Ok(AgentName(name.to_owned()))
    }

    /// The name as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for AgentName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl TryFrom<String> for AgentName {
    type Error = NameError;
    fn try_from(s: String) -> Result<Self, NameError> {
        AgentName::new(&s)
    }
}

impl From<AgentName> for String {
    fn from(r: AgentName) -> String {
        r.0
    }
}

/// Validates a port name: lowercase letters, digits, `-`, `_` and `.`, at
/// most 32 bytes. The dot lets a bridge name an imported port after its
/// origin (`r1.map.path` for robot r1's `map/path`).
pub fn validate_port_name(name: &str) -> Result<(), NameError> {
    check("port", name, FIXED_NAME_CAPACITY, &['-', '_', '.'], "'-', '_' or '.'")?;
    if RESERVED_PORT_NAMES.contains(&name) {
        return Err(NameError::Reserved { what: "port", name: name.into() });
    }
    Ok(())
}

/// A reference to a port, written `agent/port` on the command line.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct PortRef {
    /// The agent.
    pub agent: AgentName,
    /// The port of that agent.
    pub port: String,
}

impl PortRef {
    /// Builds a reference from validated parts.
    pub fn new(agent: &str, port: &str) -> Result<Self, NameError> {
        let agent = AgentName::new(agent)?;
        validate_port_name(port)?;
        Ok(PortRef { agent, port: port.to_owned() })
    }
}

impl std::str::FromStr for PortRef {
    type Err = NameError;
    fn from_str(s: &str) -> Result<Self, NameError> {
        let (agent, port) = s.split_once('/').ok_or_else(|| NameError::NotAPortRef(s.into()))?;
        if port.contains('/') {
            return Err(NameError::NotAPortRef(s.into()));
        }
        PortRef::new(agent, port)
    }
}

impl fmt::Display for PortRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.agent, self.port)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robot_names() {
        assert!(RobotName::new("h1").is_ok());
        assert!(RobotName::new("t-1234-7").is_ok());
        assert!(matches!(RobotName::new("H1"), Err(NameError::BadChar { ch: 'H', .. })));
        assert!(matches!(RobotName::new("a_b"), Err(NameError::BadChar { ch: '_', .. })));
        assert!(matches!(RobotName::new(""), Err(NameError::Empty { .. })));
        assert!(matches!(RobotName::new(&"a".repeat(25)), Err(NameError::TooLong { .. })));
        assert_eq!(RobotName::new("h1").map(|r| r.port_service("t1", "tick")).ok(), Some("nerve/h1/t1/tick".into()));
    }

    #[test]
    fn agent_and_port_names() {
        assert!(AgentName::new("wall_follow-2").is_ok());
        assert!(matches!(AgentName::new("router"), Err(NameError::Reserved { .. })));
        assert!(matches!(AgentName::new("-x"), Err(NameError::BadChar { ch: '-', .. })));
        assert!(matches!(validate_port_name("ctl"), Err(NameError::Reserved { .. })));
        let p: PortRef = "t1/tick".parse().expect("valid");
        assert_eq!(p.to_string(), "t1/tick");
        assert!(matches!("t1".parse::<PortRef>(), Err(NameError::NotAPortRef(_))));
        assert!(matches!("a/b/c".parse::<PortRef>(), Err(NameError::NotAPortRef(_))));
    }

    #[test]
    fn messages_say_what_to_do() {
        let e = RobotName::new("H1").expect_err("uppercase");
        assert!(e.to_string().contains("use lowercase letters"), "{e}");
    }
}
