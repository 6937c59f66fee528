//! `nerve::ResourceReport`: the resource manager's virtual sensor (thesis
//! section 3.2.6) — CPU and memory of the machine and of each agent of the
//! robot, the load level it judges, and what it did about it.
//!
//! CPU figures follow `top`: an agent's `cpu_percent` is percent of one core
//! (a process busy on two cores shows 200); the machine's is the average over
//! every core, 0 … 100.

use super::Payload;
use crate::fixed::FixedName;
use serde::Serialize;

/// Agents a [`ResourceReport`] lists at most (the busiest first).
pub const MAX_AGENT_LOADS: usize = 16;

/// How loaded the machine is, as the resource manager judges it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[repr(u8)]
pub enum LoadLevel {
    /// Below the thresholds.
    Normal = 0,
    /// Over the high threshold: less important agents are slowed down.
    High = 1,
    /// Over the critical threshold.
    Critical = 2,
}

impl LoadLevel {
    /// Every level, lowest first.
    pub const ALL: [LoadLevel; 3] = [Self::Normal, Self::High, Self::Critical];

    /// The level of a wire code; `None` for an unknown code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|l| *l as u8 == code)
    }

    /// The level's name: `normal`, `high`, `critical`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Normal => "normal",
            Self::High => "high",
            Self::Critical => "critical",
        }
    }
}

/// [`AgentLoad::action`]: the resource manager left the agent alone.
pub const ACTION_NONE: u8 = 0;
/// [`AgentLoad::action`]: the resource manager lengthened the agent's period.
pub const ACTION_SLOWED: u8 = 1;
/// [`AgentLoad::action`]: the resource manager suspended the agent.
pub const ACTION_SUSPENDED: u8 = 2;

/// One agent's use of the machine.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::AgentLoad")]
pub struct AgentLoad {
    /// The agent's name.
    pub name: FixedName,
    /// CPU over the last interval, percent of one core.
    pub cpu_percent: f32,
    /// Resident memory, bytes.
    pub rss_bytes: u64,
    /// Importance 1 (least) … 10 (most), as the resource manager applies it.
    pub importance: u8,
    /// What the resource manager has done to it: [`ACTION_NONE`], [`ACTION_SLOWED`], [`ACTION_SUSPENDED`].
    pub action: u8,
    /// Padding, zero.
    pub reserved: [u8; 6],
}

/// The resource manager's report (output `load` of the `resource` agent).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::ResourceReport")]
pub struct ResourceReport {
    /// CLOCK_MONOTONIC nanoseconds of the measurement.
    pub stamp_ns: u64,
    /// Machine CPU, average over every core, percent (0 … 100).
    pub machine_cpu_percent: f32,
    /// The robot's agents together, percent of one core.
    pub agents_cpu_percent: f32,
    /// Machine memory, bytes.
    pub mem_total_bytes: u64,
    /// Machine memory in use, bytes.
    pub mem_used_bytes: u64,
    /// The robot's agents together, resident bytes.
    pub agents_rss_bytes: u64,
    /// Logical CPUs of the machine.
    pub cpus: u32,
    /// A [`LoadLevel`] code.
    pub level: u8,
    /// How many entries of `agents` are used.
    pub agent_count: u8,
    /// Agents whose period the resource manager lengthened, now.
    pub slowed: u8,
    /// Agents the resource manager suspended, now.
    pub suspended: u8,
    /// The agents, busiest first; `agent_count` of them are used.
    pub agents: [AgentLoad; MAX_AGENT_LOADS],
}

impl ResourceReport {
    /// The load level, `None` for an unknown code.
    pub fn level(&self) -> Option<LoadLevel> {
        LoadLevel::from_code(self.level)
    }

    /// The used entries of `agents`.
    pub fn agents(&self) -> &[AgentLoad] {
        &self.agents[..(self.agent_count as usize).min(MAX_AGENT_LOADS)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<AgentLoad>(), 56);
        assert_eq!(std::mem::offset_of!(AgentLoad, rss_bytes), 40);
        assert_eq!(std::mem::offset_of!(AgentLoad, importance), 48);
        assert_eq!(std::mem::size_of::<ResourceReport>(), 48 + 56 * MAX_AGENT_LOADS);
        assert_eq!(std::mem::align_of::<ResourceReport>(), 8);
        assert_eq!(std::mem::offset_of!(ResourceReport, cpus), 40);
        assert_eq!(std::mem::offset_of!(ResourceReport, level), 44);
        assert_eq!(std::mem::offset_of!(ResourceReport, agents), 48);
        assert_eq!(<ResourceReport as Payload>::stable_type_name(), "nerve::ResourceReport");
    }

    #[test]
    fn used_entries_are_bounded() {
        let r = ResourceReport { agent_count: 200, level: 1, ..Default::default() };
        assert_eq!(r.agents().len(), MAX_AGENT_LOADS);
        assert_eq!(r.level(), Some(LoadLevel::High));
        assert_eq!(ResourceReport { level: 7, ..Default::default() }.level(), None);
    }
}
