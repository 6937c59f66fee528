//! Scenario `scale`: 100 agents on these 2 cores.
//!
//! `nerve launch` of 50 tickers at 10 Hz, each feeding a relay (100 agents,
//! every one of them running at 10 Hz), then, over a measuring window:
//!
//! * CPU of the whole machine (`/proc/stat`), of all the robot's agents
//!   together and of the router (`/proc/<pid>/stat`, user + system), in % of
//!   one core; the machine's CPU is also measured over the same window
//!   before the launch, since these machines are shared;
//! * memory per agent and of the router: RSS and PSS
//!   (`/proc/<pid>/smaps_rollup`; PSS shares the pages of shared libraries
//!   and of the shared-memory segments out among the processes that map
//!   them, so it is what one more agent really costs);
//! * how long `nerve ps --json` takes (the router asks each of the 100 agents
//!   for its statistics).
//!
//! Then every agent is suspended (`nerve suspend`: its task stops, the
//! process and its ports stay) and the router's CPU is measured again: the
//! issue's "100 idle agents: router under 1% of a core".

use crate::machine::{Machine, clock_ticks};
use crate::procs::Robot;
use crate::report::Report;
use crate::stats::Summary;
use anyhow::{Context as _, Result, anyhow, bail};
use serde::Serialize;
use std::time::{Duration, Instant};

/// Router CPU allowed with 100 idle agents, % of one core.
pub const ROUTER_TARGET_PCT: f64 = 1.0;

/// Options of the scale scenario.
#[derive(Debug, Clone)]
pub struct ScaleOpts {
    /// agents in all (half tickers, half relays)
    pub agents: usize,
    /// ticker period, ms
    pub period_ms: u64,
    /// measuring window, s
    pub window_s: f64,
    /// `nerve ps` repetitions
    pub ps_runs: usize,
    /// show children's output
    pub verbose: bool,
}

/// Memory of one process, KiB.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Mem {
    /// resident set size, KiB
    pub rss_kib: u64,
    /// proportional set size, KiB
    pub pss_kib: u64,
}

/// CPU over a window, % of one core.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Cpu {
    /// the whole machine (all cores together, so up to 100 x cores)
    pub machine_pct: f64,
    /// every agent of the robot together
    pub agents_pct: f64,
    /// the router
    pub router_pct: f64,
}

/// The scale report: the [`Head`](crate::report::Head) and [`ScaleResults`].
pub type ScaleReport = Report<ScaleResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Clone, Serialize)]
pub struct ScaleResults {
    /// agents launched
    pub agents: usize,
    /// rate of every agent, Hz
    pub rate_hz: f64,
    /// measuring window, s
    pub window_s: f64,
    /// wall time of `nerve launch`, ms
    pub launch_ms: f64,
    /// the machine before the launch (same window)
    pub machine_before_pct: f64,
    /// CPU with every agent running at the rate
    pub running: Cpu,
    /// CPU with every agent suspended
    pub idle: Cpu,
    /// per-agent memory: median, max
    pub agent_rss_kib_p50: u64,
    /// largest agent RSS
    pub agent_rss_kib_max: u64,
    /// median agent PSS
    pub agent_pss_kib_p50: u64,
    /// largest agent PSS
    pub agent_pss_kib_max: u64,
    /// PSS of all agents together, MiB
    pub agents_pss_total_mib: f64,
    /// the router's memory
    pub router: Mem,
    /// `nerve ps --json` wall time, ns
    pub ps: Summary,
    /// idle router CPU / 1 %
    pub router_idle_vs_target: f64,
    /// whether the idle router is under the target
    pub target_met: bool,
    /// wall time of the scenario, s
    pub seconds: f64,
}

/// utime + stime of a process, in clock ticks; None when it is gone.
pub(crate) fn proc_ticks(pid: u32) -> Option<u64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // the command name may hold spaces: fields start after the last ')'
    let rest = &s[s.rfind(')')? + 1..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // rest[0] is field 3 (state); utime is field 14, stime 15
    Some(f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?)
}

/// (busy, total) jiffies of the whole machine.
fn machine_ticks() -> Result<(u64, u64)> {
    let s = std::fs::read_to_string("/proc/stat").context("cannot read /proc/stat")?;
    let line = s.lines().next().ok_or_else(|| anyhow!("empty /proc/stat"))?;
    let v: Vec<u64> = line.split_whitespace().skip(1).filter_map(|x| x.parse().ok()).collect();
    if v.len() < 5 {
        bail!("unexpected /proc/stat line {line:?}");
    }
    let total: u64 = v.iter().take(8).sum();
    let idle = v[3] + v[4]; // idle + iowait
    Ok((total - idle, total))
}

fn mem_of(pid: u32) -> Option<Mem> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/smaps_rollup")).ok()?;
    let field = |name: &str| {
        s.lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|x| x.parse::<u64>().ok())
    };
    Some(Mem { rss_kib: field("Rss:")?, pss_kib: field("Pss:")? })
}

/// CPU of the machine (of `cores` cores), the agents and the router over `window`.
fn measure_cpu(agents: &[u32], router: Option<u32>, window: Duration, cores: usize) -> Result<Cpu> {
    let sum = |pids: &[u32]| pids.iter().filter_map(|&p| proc_ticks(p)).sum::<u64>();
    let router_ticks = || router.and_then(proc_ticks).unwrap_or(0);
    let (b0, t0) = machine_ticks()?;
    let (a0, r0) = (sum(agents), router_ticks());
    let start = Instant::now();
    std::thread::sleep(window);
    let secs = start.elapsed().as_secs_f64();
    let (b1, t1) = machine_ticks()?;
    let (a1, r1) = (sum(agents), router_ticks());
    let hz = clock_ticks();
    Ok(Cpu {
        machine_pct: if t1 > t0 { 100.0 * cores.max(1) as f64 * (b1 - b0) as f64 / (t1 - t0) as f64 } else { 0.0 },
        agents_pct: 100.0 * a1.saturating_sub(a0) as f64 / hz / secs,
        router_pct: 100.0 * r1.saturating_sub(r0) as f64 / hz / secs,
    })
}

fn launch_file(robot: &str, agents: usize, period_ms: u64) -> String {
    let pairs = (agents / 2).max(1);
    let mut s = format!("robot = \"{robot}\"\n");
    for i in 0..pairs {
        s += &format!("\n[[agent]]\nname = \"t{i}\"\nkind = \"ticker\"\nperiod = \"{period_ms}ms\"\n");
        s += &format!("\n[[agent]]\nname = \"r{i}\"\nkind = \"relay\"\n");
    }
    for i in 0..pairs {
        s += &format!("\n[[connect]]\nfrom = \"t{i}/tick\"\nto = \"r{i}/in\"\n");
    }
    s
}

fn pids_of(ps: &serde_json::Value) -> Vec<(String, u32)> {
    ps.as_array()
        .map(|a| {
            a.iter()
                .filter_map(|x| Some((x["name"].as_str()?.to_owned(), u32::try_from(x["pid"].as_u64()?).ok()?)))
                .collect()
        })
        .unwrap_or_default()
}

/// Runs the scenario.
pub fn run(opts: &ScaleOpts) -> Result<ScaleReport> {
    let started = Instant::now();
    let machine = Machine::probe();
    let window = Duration::from_secs_f64(opts.window_s);
    eprintln!("scale: the machine alone for {:.0} s", opts.window_s);
    let machine_before_pct = measure_cpu(&[], None, window, machine.nproc)?.machine_pct;

    let robot = Robot::new("s", opts.verbose)?;
    let file = robot.home.join("scale.toml");
    std::fs::write(&file, launch_file(&robot.name, opts.agents, opts.period_ms))
        .with_context(|| format!("cannot write {}", file.display()))?;
    eprintln!("scale: launching {} agents on robot {}", opts.agents, robot.name);
    let tl = Instant::now();
    robot.run(&["launch", &file.display().to_string()])?;
    let launch_ms = tl.elapsed().as_secs_f64() * 1e3;
    let ps = robot.ps()?;
    let agents = pids_of(&ps);
    if agents.len() != opts.agents / 2 * 2 {
        bail!("{} agents running after the launch, expected {}", agents.len(), opts.agents / 2 * 2);
    }
    let router_pid_file = robot.home.join(&robot.name).join("pids").join("router.pid");
    let router: u32 = std::fs::read_to_string(&router_pid_file)
        .with_context(|| format!("cannot read {}", router_pid_file.display()))?
        .trim()
        .parse()
        .context("bad router pid file")?;
    let pids: Vec<u32> = agents.iter().map(|(_, p)| *p).collect();
    // let start-up settle
    std::thread::sleep(Duration::from_secs(if opts.window_s < 5.0 { 1 } else { 3 }));

    eprintln!(
        "scale: measuring {} agents at {:.0} Hz for {:.0} s",
        pids.len(),
        1e3 / opts.period_ms as f64,
        opts.window_s
    );
    let running = measure_cpu(&pids, Some(router), window, machine.nproc)?;
    let mems: Vec<Mem> = pids.iter().filter_map(|&p| mem_of(p)).collect();
    let router_mem = mem_of(router).unwrap_or_default();

    eprintln!("scale: `nerve ps --json` x{}", opts.ps_runs);
    let mut ps_ns = Vec::new();
    for _ in 0..opts.ps_runs {
        let t = Instant::now();
        robot.run(&["ps", "--json"])?;
        ps_ns.push(t.elapsed().as_nanos() as u64);
    }

    eprintln!("scale: suspending every agent");
    for (name, _) in &agents {
        robot.run(&["suspend", name])?;
    }
    std::thread::sleep(Duration::from_secs(1));
    eprintln!("scale: measuring {} idle agents for {:.0} s", pids.len(), opts.window_s);
    let idle = measure_cpu(&pids, Some(router), window, machine.nproc)?;

    let rss = Summary::of(&mems.iter().map(|m| m.rss_kib).collect::<Vec<_>>());
    let pss = Summary::of(&mems.iter().map(|m| m.pss_kib).collect::<Vec<_>>());
    drop(robot); // nerve down
    Ok(Report::new(
        "scale",
        machine,
        ScaleResults {
            agents: pids.len(),
            rate_hz: 1e3 / opts.period_ms as f64,
            window_s: opts.window_s,
            launch_ms,
            machine_before_pct,
            running,
            idle,
            agent_rss_kib_p50: rss.p50_ns,
            agent_rss_kib_max: rss.max_ns,
            agent_pss_kib_p50: pss.p50_ns,
            agent_pss_kib_max: pss.max_ns,
            agents_pss_total_mib: mems.iter().map(|m| m.pss_kib).sum::<u64>() as f64 / 1024.0,
            router: router_mem,
            ps: Summary::of(&ps_ns),
            router_idle_vs_target: idle.router_pct / ROUTER_TARGET_PCT,
            target_met: idle.router_pct < ROUTER_TARGET_PCT,
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
}

/// Prints the tables (markdown).
pub fn print_tables(r: &ScaleReport) {
    println!(
        "{} agents ({} tickers at {:.0} Hz, each feeding a relay); `nerve launch` took {:.0} ms",
        r.agents,
        r.agents / 2,
        r.rate_hz,
        r.launch_ms
    );
    println!();
    println!("| CPU, % of one core, {:.0} s window | machine (2 cores = 200) | all agents | router |", r.window_s);
    println!("|---|---:|---:|---:|");
    println!("| before the launch | {:.1} | - | - |", r.machine_before_pct);
    println!(
        "| agents running at {:.0} Hz | {:.1} | {:.2} | {:.3} |",
        r.rate_hz, r.running.machine_pct, r.running.agents_pct, r.running.router_pct
    );
    println!(
        "| agents suspended (idle) | {:.1} | {:.2} | {:.3} |",
        r.idle.machine_pct, r.idle.agents_pct, r.idle.router_pct
    );
    println!();
    println!("| memory | RSS MiB | PSS MiB |");
    println!("|---|---:|---:|");
    let mib = |k: u64| k as f64 / 1024.0;
    println!("| one agent, median | {:.1} | {:.2} |", mib(r.agent_rss_kib_p50), mib(r.agent_pss_kib_p50));
    println!("| one agent, max | {:.1} | {:.2} |", mib(r.agent_rss_kib_max), mib(r.agent_pss_kib_max));
    println!("| all agents (PSS sum) | - | {:.1} |", r.agents_pss_total_mib);
    println!("| router | {:.1} | {:.2} |", mib(r.router.rss_kib), mib(r.router.pss_kib));
    println!();
    println!(
        "`nerve ps --json` with {} agents: median {:.1} ms, p99 {:.1} ms, max {:.1} ms (n = {})",
        r.agents,
        r.ps.p50_ns as f64 / 1e6,
        r.ps.p99_ns as f64 / 1e6,
        r.ps.max_ns as f64 / 1e6,
        r.ps.n
    );
    println!();
    println!(
        "router with {} idle agents: {:.3} % of a core (target < {ROUTER_TARGET_PCT} %: {})",
        r.agents,
        r.idle.router_pct,
        if r.target_met { "met" } else { "missed" }
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn launch_file_pairs_tickers_and_relays() {
        let s = launch_file("rb", 6, 100);
        assert_eq!(s.matches("kind = \"ticker\"").count(), 3);
        assert_eq!(s.matches("kind = \"relay\"").count(), 3);
        assert!(s.contains("from = \"t2/tick\"\nto = \"r2/in\""));
        assert!(s.contains("period = \"100ms\""));
    }

    #[test]
    fn own_process_has_ticks_and_memory() {
        let me = std::process::id();
        assert!(proc_ticks(me).is_some());
        let m = mem_of(me).expect("smaps_rollup of this process");
        assert!(m.rss_kib > 0 && m.pss_kib > 0 && m.pss_kib <= m.rss_kib);
        let (busy, total) = machine_ticks().expect("/proc/stat");
        assert!(total >= busy);
    }
}
