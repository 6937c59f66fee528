//! CPU used by each agent during a run: the agents' own figures (`nerve ps`
//! statistics, percent of one core over the last second) sampled every few
//! seconds, and each process's total user + system time from `/proc`.

use crate::analysis::AgentCpu;
use std::collections::BTreeMap;

/// User + system CPU seconds of process `pid` so far, from `/proc/PID/stat`.
pub fn process_cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // the command name (field 2) may hold blanks: count from the last ')'
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    // fields after the name start at field 3 (state); utime is 14, stime 15
    let utime: f64 = f.get(11)?.parse().ok()?;
    let stime: f64 = f.get(12)?.parse().ok()?;
    // SAFETY: sysconf has no preconditions.
    let tck = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    let tck = if tck > 0 { tck as f64 } else { 100.0 };
    Some((utime + stime) / tck)
}

/// Samples accumulated per agent.
#[derive(Debug, Clone, Default)]
pub struct CpuTable {
    agents: BTreeMap<String, Acc>,
}

#[derive(Debug, Clone, Default)]
struct Acc {
    cpu: AgentCpu,
    sum: f64,
    /// CPU seconds of each process the agent ran as (restarts make new ones)
    per_pid: BTreeMap<u32, f64>,
}

impl CpuTable {
    /// Records one sample of agent `name`: its reported percent (if it
    /// answered), its restarts and its pid (for `/proc`).
    pub fn record(&mut self, name: &str, kind: &str, percent: Option<f64>, restarts: u32, pid: u32) {
        let acc = self.agents.entry(name.to_owned()).or_default();
        let a = &mut acc.cpu;
        a.kind = kind.to_owned();
        a.restarts = a.restarts.max(restarts);
        if let Some(p) = percent.filter(|p| p.is_finite() && *p >= 0.0) {
            a.samples += 1;
            acc.sum += p;
            a.max_percent = a.max_percent.max(p);
            a.mean_percent = acc.sum / a.samples as f64;
        }
        if pid > 0
            && let Some(s) = process_cpu_seconds(pid)
        {
            acc.per_pid.insert(pid, s);
            a.cpu_seconds = Some(acc.per_pid.values().sum());
        }
    }

    /// The table.
    pub fn finish(self) -> BTreeMap<String, AgentCpu> {
        self.agents.into_iter().map(|(k, acc)| (k, acc.cpu)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn own_process_has_cpu_time_and_samples_average() {
        assert!(process_cpu_seconds(std::process::id()).is_some());
        let mut t = CpuTable::default();
        t.record("a", "sonar", Some(2.0), 0, 0);
        t.record("a", "sonar", Some(4.0), 1, 0);
        t.record("a", "sonar", None, 1, 0);
        let a = &t.finish()["a"];
        assert_eq!((a.samples, a.mean_percent, a.max_percent, a.restarts), (2, 3.0, 4.0, 1));
    }
}
