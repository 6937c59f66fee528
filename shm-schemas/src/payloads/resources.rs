//! [`ResourceReport`] = `Seq<AgentLoad, ResourceHeader>`: the resource
//! manager's virtual sensor (thesis section 3.2.6) — CPU and memory of the
//! machine and of each agent of the robot, the load level it judges, and
//! what it did about it.
//!
//! A variable-size payload ([`crate::seq`], issue 42): the header
//! ([`ResourceHeader`]) holds the machine's figures, and one [`AgentLoad`]
//! follows per agent of the robot, busiest first, as many as there are (up
//! to [`MAX_AGENT_LOADS`], the most the resource manager's output takes).
//! The sample's length is the number of agents; no count field stands in
//! for it, so a robot of 40 agents is reported whole (a fixed array of 16
//! lost the rest until issue 42).
//!
//! CPU figures follow `top`: an agent's `cpu_percent` is percent of one core
//! (a process busy on two cores shows 200); the machine's is the average over
//! every core, 0 … 100.

use super::Payload;
use crate::fixed::FixedName;
use crate::seq::Seq;
use serde::Serialize;

/// The most agents a [`ResourceReport`] lists (the busiest first): the
/// maximum the resource manager's output `load` is declared with. A robot
/// has far fewer; past it, the header's [`ResourceHeader::agents`] still
/// counts every agent.
pub const MAX_AGENT_LOADS: usize = 1024;

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

/// What comes before a [`ResourceReport`]'s agents: the machine, the
/// robot's agents together, the load level and what was done about it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::ResourceHeader")]
pub struct ResourceHeader {
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
    /// The robot's agents measured: the elements that follow, unless there
    /// were more than [`MAX_AGENT_LOADS`] (then the busiest of them follow).
    pub agents: u32,
    /// Agents whose period the resource manager lengthened, now.
    pub slowed: u16,
    /// Agents the resource manager suspended, now.
    pub suspended: u16,
    /// A [`LoadLevel`] code.
    pub level: u8,
    /// Padding, zero.
    #[serde(skip)]
    pub _pad: [u8; 3],
}

impl ResourceHeader {
    /// The load level, `None` for an unknown code.
    pub fn level(&self) -> Option<LoadLevel> {
        LoadLevel::from_code(self.level)
    }
}

/// The resource manager's report (output `load` of the `resource` agent):
/// a [`ResourceHeader`], then one [`AgentLoad`] per agent, busiest first.
/// Its type name is `nerve::Seq<nerve::AgentLoad, nerve::ResourceHeader>`.
pub type ResourceReport = Seq<AgentLoad, ResourceHeader>;

/// The bytes of a [`ResourceReport`] sample, laid out as its port lays
/// them out (the header, then the loads): what a test hands to an input
/// (`Harness::send_bytes_from`) or a tool writes.
pub fn report_bytes(header: &ResourceHeader, loads: &[AgentLoad]) -> Vec<u8> {
    // both are 8-aligned and a multiple of 8 long: the loads start right after the header
    let mut out = Vec::with_capacity(size_of::<ResourceHeader>() + std::mem::size_of_val(loads));
    // SAFETY: `ResourceHeader` and `AgentLoad` are `#[repr(C)]` plain data
    // without padding (the derive refuses padding: every gap is a named
    // field), so all their bytes are initialised; the slices borrow them
    // for the copy only.
    unsafe {
        out.extend_from_slice(std::slice::from_raw_parts(
            (header as *const ResourceHeader).cast::<u8>(),
            size_of::<ResourceHeader>(),
        ));
        out.extend_from_slice(std::slice::from_raw_parts(loads.as_ptr().cast::<u8>(), std::mem::size_of_val(loads)));
    }
    out
}

/// A [`ResourceReport`] sample's bytes read back (copied, at any
/// alignment): its header and its loads; `None` unless the bytes are a
/// header and whole loads.
pub fn read_report(bytes: &[u8]) -> Option<(ResourceHeader, Vec<AgentLoad>)> {
    let rest = bytes.get(size_of::<ResourceHeader>()..)?;
    if !rest.len().is_multiple_of(size_of::<AgentLoad>()) {
        return None;
    }
    // SAFETY: `bytes` holds at least a header (checked by `get` above);
    // any bits are a valid `ResourceHeader` (plain numbers and bytes), read
    // unaligned.
    let header = unsafe { bytes.as_ptr().cast::<ResourceHeader>().read_unaligned() };
    let loads = rest
        .chunks_exact(size_of::<AgentLoad>())
        // SAFETY: each chunk is exactly one `AgentLoad`'s bytes; any bits
        // are a valid one (numbers, bytes, and a `FixedName` of bytes that
        // is read through its length, bounded), read unaligned.
        .map(|c| unsafe { c.as_ptr().cast::<AgentLoad>().read_unaligned() })
        .collect();
    Some((header, loads))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Described as _;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<AgentLoad>(), 56);
        assert_eq!(std::mem::offset_of!(AgentLoad, rss_bytes), 40);
        assert_eq!(std::mem::offset_of!(AgentLoad, importance), 48);
        assert_eq!(std::mem::size_of::<ResourceHeader>(), 56);
        assert_eq!(std::mem::align_of::<ResourceHeader>(), 8);
        assert_eq!(std::mem::offset_of!(ResourceHeader, cpus), 40);
        assert_eq!(std::mem::offset_of!(ResourceHeader, agents), 44);
        assert_eq!(std::mem::offset_of!(ResourceHeader, level), 52);
        assert_eq!(<ResourceHeader as Payload>::stable_type_name(), "nerve::ResourceHeader");
        let schema = ResourceReport::schema();
        assert_eq!(schema.type_name, "nerve::Seq<nerve::AgentLoad, nerve::ResourceHeader>");
        let shape = schema.sequence_shape().expect("a sequence");
        assert_eq!((shape.items_at, shape.element, shape.align), (56, 56, 8));
        schema.validate().expect("a valid sequence schema");
    }

    /// 40 agents, more than the 16 the fixed array held: every one is in
    /// the sample, read back in order, and its length is the count.
    #[test]
    fn a_report_of_any_number_of_agents_keeps_every_load() {
        let header = ResourceHeader { cpus: 2, agents: 40, level: 1, ..Default::default() };
        let loads: Vec<AgentLoad> = (0..40)
            .map(|i| AgentLoad { name: FixedName::new(&format!("a{i}")), cpu_percent: i as f32, ..Default::default() })
            .collect();
        let bytes = report_bytes(&header, &loads);
        let shape = ResourceReport::schema().sequence_shape().expect("a sequence");
        assert_eq!(shape.count_of(bytes.len()), Some(40));
        let (h, back) = read_report(&bytes).expect("a whole report");
        assert_eq!((h, back.as_slice()), (header, loads.as_slice()));
        assert_eq!(h.level(), Some(LoadLevel::High));
        assert_eq!(ResourceHeader { level: 7, ..Default::default() }.level(), None);
        // through the schema, as `nerve echo` decodes it
        let decoded = ResourceReport::schema().decode_path("items.39.name", &bytes);
        assert_eq!(decoded.map(|v| v.to_string()).as_deref(), Some("\"a39\""));
        assert_eq!(read_report(&report_bytes(&header, &[])).map(|(_, l)| l.len()), Some(0));
        assert!(read_report(&bytes[..bytes.len() - 1]).is_none(), "not whole loads");
        assert!(read_report(&bytes[..10]).is_none(), "not a header");
    }
}
