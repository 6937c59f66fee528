//! The resource manager's report, free of any I/O: what it measured and
//! did, laid out as a `nerve::ResourceReport` sample
//! (`Seq<AgentLoad, ResourceHeader>`): the header, then one load per agent,
//! busiest first. Every agent measured is listed (a fixed array of 16 lost
//! the rest before issue 42), up to [`MAX_AGENT_LOADS`].

use crate::plan::{AgentObs, Measures, Planner};
use shm_schemas::FixedName;
use shm_schemas::payloads::{AgentLoad, LoadLevel, MAX_AGENT_LOADS, ResourceHeader};

/// The machine's figures beside [`Measures`]: what the header carries
/// that the load level is not judged on.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Machine {
    /// CLOCK_MONOTONIC nanoseconds of the measurement.
    pub stamp_ns: u64,
    /// Logical CPUs.
    pub cpus: u32,
    /// Memory, bytes.
    pub mem_total_bytes: u64,
    /// Memory in use, bytes.
    pub mem_used_bytes: u64,
}

/// The report of one measurement: `obs` are the agents with their resident
/// bytes, in any order; the loads come out busiest first (ties by name, so
/// a report is the same for the same figures), at most [`MAX_AGENT_LOADS`]
/// of them, and the header counts every agent.
pub fn report(
    machine: Machine,
    m: &Measures,
    level: LoadLevel,
    planner: &Planner,
    obs: &[(AgentObs, u64)],
) -> (ResourceHeader, Vec<AgentLoad>) {
    let mut order: Vec<&(AgentObs, u64)> = obs.iter().collect();
    order.sort_by(|a, b| b.0.cpu_percent.total_cmp(&a.0.cpu_percent).then_with(|| a.0.name.cmp(&b.0.name)));
    let loads: Vec<AgentLoad> = order
        .iter()
        .take(MAX_AGENT_LOADS)
        .map(|(o, rss)| AgentLoad {
            name: FixedName::new(&o.name),
            cpu_percent: o.cpu_percent as f32,
            rss_bytes: *rss,
            importance: o.importance,
            action: planner.action_of(&o.name),
            reserved: [0; 6],
        })
        .collect();
    let header = ResourceHeader {
        stamp_ns: machine.stamp_ns,
        machine_cpu_percent: m.machine_cpu as f32,
        agents_cpu_percent: m.agents_cpu as f32,
        mem_total_bytes: machine.mem_total_bytes,
        mem_used_bytes: machine.mem_used_bytes,
        agents_rss_bytes: obs.iter().map(|(_, rss)| *rss).fold(0u64, u64::saturating_add),
        cpus: machine.cpus,
        agents: u32::try_from(obs.len()).unwrap_or(u32::MAX),
        slowed: u16::try_from(planner.slowed().len()).unwrap_or(u16::MAX),
        suspended: u16::try_from(planner.suspended().len()).unwrap_or(u16::MAX),
        level: level as u8,
        _pad: [0; 3],
    };
    (header, loads)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nerve_decision::ResourcePolicy;
    use shm_schemas::payloads::resources::{ACTION_NONE, ACTION_SLOWED};

    fn obs(i: usize) -> (AgentObs, u64) {
        let o = AgentObs {
            name: format!("agent{i:02}"),
            importance: (i % 10) as u8 + 1,
            period_ns: Some(10_000_000),
            suspended: false,
            cpu_percent: i as f64,
        };
        (o, 1000 + i as u64)
    }

    /// 40 agents, more than the 16 the report held before issue 42: every
    /// one is listed, busiest first, with its own figures and the action
    /// taken on it; the header counts and sums them all.
    #[test]
    fn every_agent_of_a_large_robot_is_reported_busiest_first() {
        let mut planner = Planner::new(ResourcePolicy::default(), "rm");
        let all: Vec<(AgentObs, u64)> = (0..40).map(obs).collect();
        let agents: Vec<AgentObs> = all.iter().map(|(o, _)| o.clone()).collect();
        let action = planner.plan(LoadLevel::High, &agents, 1).expect("one to slow down");
        planner.done(&action, true, 1);
        let m = Measures { machine_cpu: 50.0, agents_cpu: agents.iter().map(|o| o.cpu_percent).sum(), memory: 10.0 };
        let machine = Machine { stamp_ns: 7, cpus: 2, mem_total_bytes: 100, mem_used_bytes: 40 };

        let (header, loads) = report(machine, &m, LoadLevel::High, &planner, &all);
        assert_eq!(loads.len(), 40, "nothing lost");
        assert_eq!(header.agents, 40);
        assert_eq!(header.agents_rss_bytes, (0..40u64).map(|i| 1000 + i).sum::<u64>());
        assert_eq!((header.cpus, header.stamp_ns, header.level()), (2, 7, Some(LoadLevel::High)));
        assert_eq!((header.slowed, header.suspended), (1, 0));
        let names: Vec<String> = loads.iter().map(|l| l.name.as_str().to_owned()).collect();
        let want: Vec<String> = (0..40).rev().map(|i| format!("agent{i:02}")).collect();
        assert_eq!(names, want, "busiest first");
        assert_eq!((loads[0].cpu_percent, loads[0].rss_bytes, loads[0].importance), (39.0, 1039, 10));
        let slowed: Vec<&str> = loads.iter().filter(|l| l.action == ACTION_SLOWED).map(|l| l.name.as_str()).collect();
        assert_eq!(slowed, planner.slowed(), "the action is on the agent it was taken on");
        assert!(loads.iter().filter(|l| l.action != ACTION_SLOWED).all(|l| l.action == ACTION_NONE));
    }

    /// More agents than a report lists: the busiest [`MAX_AGENT_LOADS`]
    /// are, and the header still counts every one.
    #[test]
    fn past_the_most_a_report_lists_the_busiest_and_counts_all() {
        let planner = Planner::new(ResourcePolicy::default(), "rm");
        let all: Vec<(AgentObs, u64)> = (0..MAX_AGENT_LOADS + 5).map(obs).collect();
        let (header, loads) = report(Machine::default(), &Measures::default(), LoadLevel::Normal, &planner, &all);
        assert_eq!(loads.len(), MAX_AGENT_LOADS);
        assert_eq!(header.agents as usize, MAX_AGENT_LOADS + 5);
        assert_eq!(loads.last().map(|l| l.cpu_percent), Some(5.0), "the five least busy are left out");
    }
}
