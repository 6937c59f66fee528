//! What machine a result came from: cores, CPU model, kernel, load.

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
        Machine { nproc: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0), cpu, kernel, loadavg_1m }
    }
}

/// The command line this process was started with, for the report.
pub fn command_line() -> String {
    let mut args = std::env::args();
    let _ = args.next();
    std::iter::once("nerve-bench".to_owned()).chain(args).collect::<Vec<_>>().join(" ")
}
