//! What holding PM QoS costs an idle robot: where the CPUs spend their idle
//! time, with and without a bound of 0 µs held, read from cpuidle's
//! per-state residency counters (`/sys/devices/system/cpu/cpu*/cpuidle/
//! state*/time`). A CPU that may not halt polls instead: the guest counts it
//! idle, but the core (or the host's vCPU thread) stays busy and draws power.

use serde::Serialize;
use std::time::{Duration, Instant};

/// Idle-state residency of all CPUs over a stretch of time.
#[derive(Debug, Clone, Serialize)]
pub struct IdleShare {
    /// whether a PM QoS bound of 0 µs was held
    pub pm_qos: bool,
    /// length of the stretch, s
    pub seconds: f64,
    /// (state name, share of all CPUs' time spent in it, 0..1)
    pub states: Vec<(String, f64)>,
    /// share of all CPUs' time in no idle state (running something)
    pub busy: f64,
}

/// Cumulative residency (µs) per state name, summed over CPUs.
fn residency() -> Vec<(String, u64)> {
    let mut by_state: Vec<(String, u64)> = Vec::new();
    for cpu in 0..1024 {
        let base = format!("/sys/devices/system/cpu/cpu{cpu}/cpuidle");
        if std::fs::metadata(&base).is_err() {
            if cpu > 0 && std::fs::metadata(format!("/sys/devices/system/cpu/cpu{cpu}")).is_err() {
                break;
            }
            continue;
        }
        for k in 0..16 {
            let dir = format!("{base}/state{k}");
            let Ok(name) = std::fs::read_to_string(format!("{dir}/name")) else { break };
            let t: u64 =
                std::fs::read_to_string(format!("{dir}/time")).ok().and_then(|s| s.trim().parse().ok()).unwrap_or(0);
            let name = name.trim().to_owned();
            match by_state.iter_mut().find(|(n, _)| *n == name) {
                Some(e) => e.1 = e.1.saturating_add(t),
                None => by_state.push((name, t)),
            }
        }
    }
    by_state
}

/// Measures the idle-state shares over `span`, holding a PM QoS bound of 0
/// µs for it when `pm_qos` (and failing over to not holding, noted in the
/// result, when the device cannot be written).
pub fn measure(pm_qos: bool, span: Duration) -> IdleShare {
    let hold = if pm_qos { agent_sdk::cpu_latency::hold(0).ok() } else { None };
    // the idle CPUs re-pick their state when the bound changes; give them a moment
    std::thread::sleep(Duration::from_millis(50));
    let before = residency();
    let t0 = Instant::now();
    std::thread::sleep(span);
    let after = residency();
    let wall_us = t0.elapsed().as_micros() as f64;
    let held = hold.is_some();
    drop(hold);
    let cpus = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1) as f64;
    let total = (wall_us * cpus).max(1.0);
    let states: Vec<(String, f64)> = after
        .iter()
        .map(|(n, a)| {
            let b = before.iter().find(|(m, _)| m == n).map(|x| x.1).unwrap_or(0);
            (n.clone(), a.saturating_sub(b) as f64 / total)
        })
        .collect();
    let idle: f64 = states.iter().map(|s| s.1).sum();
    IdleShare { pm_qos: held, seconds: wall_us / 1e6, states, busy: (1.0 - idle).max(0.0) }
}
