//! What machine a result came from: cores, CPU model, kernel, load, and
//! how its idle CPUs sleep (the idle driver, its states and their exit
//! latencies, and the PM QoS bound in force when the run started: what a
//! wake-up costs depends on them, issue 17).

use serde::Serialize;

/// The machine a benchmark ran on.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    /// `nproc`
    pub nproc: usize,
    /// `model name` from /proc/cpuinfo
    pub cpu: String,
    /// `uname -r`
    pub kernel: String,
    /// 1-minute load average when the run started
    pub loadavg_1m: f64,
    /// the cpuidle driver (`haltpoll`, `intel_idle`, `acpi_idle`...), `none` without one
    pub idle_driver: String,
    /// the cpuidle governor
    pub idle_governor: String,
    /// CPU 0's idle states: (name, exit latency µs)
    pub idle_states: Vec<(String, u64)>,
    /// the PM QoS bound in force when the run started, µs (2000000000: none
    /// held; lower: some process holds one, and rows "without" it are not)
    pub pm_qos_bound_us: Option<u32>,
}

impl Machine {
    /// Reads the machine's description; unknown fields read `unknown`.
    pub fn probe() -> Self {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split_once(':'))
                    .map(|(_, v)| v.trim().to_owned())
            })
            .unwrap_or_else(|| "unknown".into());
        let kernel =
            std::fs::read_to_string("/proc/sys/kernel/osrelease").map(|s| s.trim().to_owned()).unwrap_or_default();
        let loadavg_1m = std::fs::read_to_string("/proc/loadavg")
            .ok()
            .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()))
            .unwrap_or(0.0);
        let read = |p: &str| std::fs::read_to_string(p).map(|s| s.trim().to_owned()).unwrap_or_else(|_| "none".into());
        let mut idle_states = Vec::new();
        for k in 0..16 {
            let dir = format!("/sys/devices/system/cpu/cpu0/cpuidle/state{k}");
            let Ok(name) = std::fs::read_to_string(format!("{dir}/name")) else { break };
            let latency =
                std::fs::read_to_string(format!("{dir}/latency")).ok().and_then(|s| s.trim().parse().ok()).unwrap_or(0);
            idle_states.push((name.trim().to_owned(), latency));
        }
        Machine {
            nproc: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0),
            cpu,
            kernel,
            loadavg_1m,
            idle_driver: read("/sys/devices/system/cpu/cpuidle/current_driver"),
            idle_governor: read("/sys/devices/system/cpu/cpuidle/current_governor"),
            idle_states,
            pm_qos_bound_us: agent_sdk::cpu_latency::current_bound_us(),
        }
    }

    /// One line for a run's header: the idle driver and states, and any PM QoS bound already held.
    pub fn idle_line(&self) -> String {
        let states: Vec<String> = self.idle_states.iter().map(|(n, l)| format!("{n} ({l} µs)")).collect();
        let qos = match self.pm_qos_bound_us {
            Some(b) if b < 2_000_000_000 => format!(
                "; WARNING: a PM QoS bound of {b} µs is already held by some process, so rows without PM QoS are not"
            ),
            Some(_) => "; no PM QoS bound held".into(),
            None => String::new(),
        };
        format!("idle driver {} (governor {}), states {}{qos}", self.idle_driver, self.idle_governor, states.join(", "))
    }
}

/// Ticks per second of the CPU times in /proc (USER_HZ).
pub(crate) fn clock_ticks() -> f64 {
    // SAFETY: sysconf has no preconditions and no memory effects.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 { t as f64 } else { 100.0 }
}

/// Time the hypervisor ran something else while this guest's CPUs had
/// work, all CPUs together, ms since boot (`steal` in /proc/stat); None
/// where the kernel does not say. The difference over a round tells
/// whether the host took the CPUs away during it.
pub(crate) fn steal_ms() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/stat").ok()?;
    // "cpu user nice system idle iowait irq softirq steal ..."
    let ticks: u64 = s.lines().next()?.split_whitespace().nth(8)?.parse().ok()?;
    Some(ticks as f64 * 1000.0 / clock_ticks())
}

/// The command line this process was started with, for the report.
pub fn command_line() -> String {
    let mut args = std::env::args();
    let _ = args.next();
    std::iter::once("nerve-bench".to_owned()).chain(args).collect::<Vec<_>>().join(" ")
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_stolen_time_is_read_and_never_goes_back() {
        let a = super::steal_ms().expect("/proc/stat has a steal column");
        let b = super::steal_ms().expect("and still has it");
        assert!(a >= 0.0 && b >= a, "{a} then {b}");
    }
}
