//! Scenario `fleet` (issue 44): robots that meet through one Zenoh router
//! instead of a full mesh, as the fleet grows.
//!
//! For every fleet size N (`--robots 2,4,8,16`) a fresh Zenoh router in
//! router mode (`nerve-ros2-router`, what ROS 2's `rmw_zenohd` is) listens
//! in this host's network namespace, and N robots start one after the
//! other, each in a network namespace of its own (`nerve-fleet-<pid>-<N>-<i>`)
//! joined to the host by a veth pair (`10.<100+N>.<i+1>.2/30` inside,
//! `.1` on the host side): a robot reaches the router only over its veth
//! link, as a robot on a LAN reaches the fleet's router. Every robot runs a
//! ticker (`t`, one `nerve::Tick` every `--period-ms`) and a bridge agent in
//! `mode = "client"` that exports the ticker and imports the ticker of the
//! robot started before it (robot 0 that of the last robot: a ring, so
//! every topic has one remote reader and the router carries N topics).
//!
//! Reported for each N:
//! * **join time**: from `nerve launch` of a robot to the first tick from
//!   the robot before it (already in the fleet) arriving at its bridge, over
//!   robots 1..N (robot 0 has nobody before it yet); median and max;
//! * **latency** per topic, one way (the importing bridge's median of
//!   `arrival - stamp`, one host so one clock): median and max over topics;
//! * **delivered**: ticks arriving in the measured window against those the
//!   bridges sent in it (best effort: a tick may be dropped under load);
//! * **the router's CPU** over the measured window (`--seconds`), % of one
//!   core, and its resident memory.
//!
//! Network namespaces need CAP_NET_ADMIN (root); `--no-netns` runs the same
//! fleet on loopback instead (said in the results). Every namespace, robot
//! and router is removed at the end, also when the run fails (a process
//! left in a namespace is named and killed).

use crate::machine::{Machine, clock_ticks};
use crate::procs::{ChildGuard, Robot};
use crate::report::Report;
use crate::stats::median_f64;
use anyhow::{Context as _, Result, anyhow, bail};
use serde::Serialize;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The default fleet sizes of the scenario (the issue's).
pub const ROBOTS: [usize; 4] = [2, 4, 8, 16];
/// The most robots one fleet may have (one /30 per robot in 10.<100+N>.0.0/16).
pub const MAX_ROBOTS: usize = 64;
/// How long a robot may take to join before the run fails.
const JOIN_TIMEOUT: Duration = Duration::from_secs(30);

/// The scenario's options.
#[derive(Debug, Clone)]
pub struct FleetOpts {
    /// the fleet sizes, in order
    pub robots: Vec<usize>,
    /// the measured window per fleet size, s
    pub seconds: f64,
    /// the tickers' period, ms
    pub period_ms: u64,
    /// each robot in its own network namespace (else all on loopback)
    pub netns: bool,
    /// show the children's output
    pub verbose: bool,
}

/// One fleet size's results.
#[derive(Debug, Clone, Serialize)]
pub struct FleetRow {
    /// robots in the fleet
    pub robots: usize,
    /// join time, median over robots 1..N, ms
    pub join_ms_median: f64,
    /// join time, the slowest robot, ms
    pub join_ms_max: f64,
    /// one-way latency, median over topics of each topic's median, µs
    pub latency_us_median: f64,
    /// one-way latency, the slowest topic's median, µs
    pub latency_us_max: f64,
    /// ticks arriving in the window / ticks the exporting bridges sent in it
    /// (all topics; each robot's two counts are read at one instant, a
    /// topic's two ends at two, so a tick either way is noise)
    pub delivered: f64,
    /// the Zenoh router's CPU over the window, % of one core
    pub router_cpu_pct: f64,
    /// the Zenoh router's resident memory at the end of the window, KiB
    pub router_rss_kib: u64,
}

/// The scenario's results.
#[derive(Debug, Clone, Serialize)]
pub struct FleetResults {
    /// one row per fleet size
    pub rows: Vec<FleetRow>,
    /// the tickers' period, ms
    pub period_ms: u64,
    /// the measured window per fleet size, s
    pub window_s: f64,
    /// each robot in its own network namespace (false: loopback)
    pub netns: bool,
    /// wall time of the scenario, s
    pub seconds: f64,
}

/// The scenario's report.
pub type FleetReport = Report<FleetResults>;

/// Runs `ip ARGS...` (in namespace `ns` when given); fails with its stderr.
fn ip(ns: Option<&str>, args: &[&str]) -> Result<()> {
    let mut cmd = Command::new("ip");
    if let Some(ns) = ns {
        cmd.args(["netns", "exec", ns, "ip"]);
    }
    let out = cmd.args(args).stdin(Stdio::null()).output().context("cannot run `ip` (install iproute2)")?;
    if !out.status.success() {
        bail!("`ip {}` failed: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim());
    }
    Ok(())
}

/// A network namespace joined to the host by a veth pair; removed when dropped.
struct Netns {
    name: String,
    /// the host side of the veth pair
    host_if: String,
    /// the host side's address, which the robot dials
    host_addr: String,
}

impl Netns {
    /// Namespace `i` of the fleet of `n`: `10.<100+n>.<i+1>.2/30` inside,
    /// `.1` on the host (a subnet per fleet, so that one fleet's
    /// namespaces never meet the next one's while the kernel frees them).
    fn new(n: usize, i: usize) -> Result<Self> {
        let pid = std::process::id() % 10_000;
        let name = format!("nerve-fleet-{pid}-{n}-{i}");
        let (host_if, ns_if) = (format!("nfh{pid}n{n}x{i}"), format!("nfn{pid}n{n}x{i}"));
        if n > MAX_ROBOTS || i >= n {
            bail!("robot {i} of {n}: a fleet has at most {MAX_ROBOTS} robots");
        }
        let (host_addr, ns_addr) = (format!("10.{}.{}.1", 100 + n, i + 1), format!("10.{}.{}.2", 100 + n, i + 1));
        ip(None, &["netns", "add", &name]).context(
            "a network namespace per robot needs CAP_NET_ADMIN (run as root), or run with --no-netns on loopback",
        )?;
        // from here on, Drop removes the namespace and the veth
        let me = Netns { name, host_if, host_addr };
        ip(None, &["link", "add", &me.host_if, "type", "veth", "peer", "name", &ns_if])?;
        ip(None, &["link", "set", &ns_if, "netns", &me.name])?;
        ip(None, &["addr", "add", &format!("{}/30", me.host_addr), "dev", &me.host_if])?;
        ip(None, &["link", "set", &me.host_if, "up"])?;
        ip(Some(&me.name), &["addr", "add", &format!("{ns_addr}/30"), "dev", &ns_if])?;
        ip(Some(&me.name), &["link", "set", &ns_if, "up"])?;
        ip(Some(&me.name), &["link", "set", "lo", "up"])?;
        Ok(me)
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        // anything still running in the namespace (the robots went down
        // first: nothing should be) would keep it, and its veth, alive
        let left = Command::new("ip").args(["netns", "pids", &self.name]).output();
        for pid in left.iter().flat_map(|o| {
            String::from_utf8_lossy(&o.stdout).into_owned().lines().map(str::to_owned).collect::<Vec<_>>()
        }) {
            if let Ok(pid) = pid.trim().parse::<i32>() {
                eprintln!("warning: process {pid} was left in {}; killing it", self.name);
                let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), nix::sys::signal::Signal::SIGKILL);
            }
        }
        // deleting one end of a veth deletes both, at once
        let _ = ip(None, &["link", "del", &self.host_if]);
        if let Err(e) = ip(None, &["netns", "del", &self.name]) {
            eprintln!("warning: {e:#}");
        }
    }
}

/// A free TCP port on all addresses of this namespace.
pub(crate) fn free_port() -> Result<u16> {
    let l = std::net::TcpListener::bind("0.0.0.0:0").context("cannot find a free port")?;
    Ok(l.local_addr().context("cannot read the free port")?.port())
}

/// `nerve-ros2-router`, beside this benchmark's `nerve`.
pub(crate) fn start_router(robot: &Robot, listen: &str, verbose: bool) -> Result<ChildGuard> {
    let exe = robot.nerve_path().with_file_name("nerve-ros2-router");
    if !exe.exists() {
        bail!(
            "{} is missing; build it with `cargo build --release -p nerve-ros2 --bins` (the fleet's Zenoh router)",
            exe.display()
        );
    }
    let mut cmd = Command::new(exe);
    cmd.args(["--listen", listen]).stdin(Stdio::null()).stdout(Stdio::piped());
    if !verbose {
        cmd.stderr(Stdio::null());
    }
    let mut router = ChildGuard::spawn("nerve-ros2-router", cmd)?;
    router.await_ready("nerve-ros2-router")?;
    Ok(router)
}

/// utime + stime of a process, seconds; None when it is gone.
fn cpu_s(pid: u32) -> Option<f64> {
    crate::scale::proc_ticks(pid).map(|t| t as f64 / clock_ticks())
}

/// Resident memory of a process, KiB (0 when unknown).
fn rss_kib(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmRSS:")).and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

/// What a robot's bridge says of its one export and its one import.
#[derive(Debug, Clone, Copy)]
struct Counts {
    /// ticks sent to the fleet
    sent: u64,
    /// ticks arrived from the robot before
    arrived: u64,
    /// the import's median one-way latency, µs
    latency_us: Option<f64>,
}

/// Reads [`Counts`] from `nerve bridge status --json`.
fn counts(robot: &Robot) -> Result<Counts> {
    let out = robot.run(&["bridge", "status", "--json"])?;
    let json: serde_json::Value = serde_json::from_str(&out).context("cannot parse `nerve bridge status --json`")?;
    let bridge =
        json.as_array().and_then(|b| b.first()).ok_or_else(|| anyhow!("robot {}: no bridge: {out}", robot.name))?;
    let first = |list: &str| {
        bridge[list]
            .as_array()
            .and_then(|i| i.first())
            .ok_or_else(|| anyhow!("robot {}: its bridge lists no {list}: {out}", robot.name))
    };
    let (export, import) = (first("exports")?, first("imports")?);
    let figure = |t: &serde_json::Value, k: &str| t["figures"][k].as_str().and_then(|v| v.parse::<f64>().ok());
    Ok(Counts {
        sent: figure(export, "msgs_out").map_or(0, |v| v as u64),
        arrived: figure(import, "msgs_in").map_or(0, |v| v as u64),
        latency_us: figure(import, "latency_us"),
    })
}

/// The launch file of robot `i`: the ticker and the bridge (client of `router`), importing `from`'s ticks.
fn robot_files(robot: &Robot, router: &str, insecure: bool, from: &str, period_ms: u64) -> Result<std::path::PathBuf> {
    let cfg = robot.home.join("bridge.toml");
    std::fs::write(
        &cfg,
        format!(
            "# a fleet robot: its bridge meets the others through the router\n\
             mode = \"client\"\nconnect = [\"{router}\"]\n\
             # the veth link is this benchmark's own; a real fleet uses tls/ and [tls]\n\
             insecure = {insecure}\n\
             [[export]]\nport = \"t/tick\"\ntype = \"nerve::Tick\"\n\
             [[import]]\nport = \"{from}/t/tick\"\ntype = \"nerve::Tick\"\nas = \"prev\"\n"
        ),
    )
    .with_context(|| format!("cannot write {}", cfg.display()))?;
    let launch = robot.home.join("fleet.toml");
    std::fs::write(
        &launch,
        format!(
            "robot = \"x\"\n[[agent]]\nname = \"t\"\nkind = \"ticker\"\nperiod = \"{period_ms}ms\"\n\
             [[agent]]\nname = \"bridge\"\nkind = \"bridge\"\nargs = [\"--config\", {:?}]\n",
            cfg.display().to_string()
        ),
    )
    .with_context(|| format!("cannot write {}", launch.display()))?;
    Ok(launch)
}

/// `nerve launch FILE` for `robot`, inside `ns` when given.
fn launch(robot: &Robot, file: &std::path::Path, ns: Option<&Netns>) -> Result<()> {
    let mut cmd = match ns {
        None => robot.nerve(),
        Some(ns) => {
            let mut c = Command::new("ip");
            c.args(["netns", "exec", &ns.name]).arg(robot.nerve_path()).arg("--robot").arg(&robot.name);
            c.env("NERVE_HOME", &robot.home);
            c
        }
    };
    let out = cmd.arg("launch").arg(file).stdin(Stdio::null()).output().context("cannot run nerve launch")?;
    if !out.status.success() {
        bail!("launch of robot {} failed: {}", robot.name, String::from_utf8_lossy(&out.stderr).trim());
    }
    Ok(())
}

/// One fleet of `n` robots: started, joined, measured, taken down.
fn one_fleet(opts: &FleetOpts, n: usize) -> Result<FleetRow> {
    let names: Vec<String> = (0..n).map(|i| Robot::name_of(&format!("f{n}r{i}"))).collect();
    // namespaces first: dropped last, after the robots went down
    let nets: Vec<Netns> =
        if opts.netns { (0..n).map(|i| Netns::new(n, i)).collect::<Result<_>>()? } else { Vec::new() };
    let robots: Vec<Robot> = (0..n).map(|i| Robot::new(&format!("f{n}r{i}"), opts.verbose)).collect::<Result<_>>()?;
    let port = free_port()?;
    let listen = if opts.netns { format!("tcp/0.0.0.0:{port}") } else { format!("tcp/127.0.0.1:{port}") };
    let mut router = start_router(&robots[0], &listen, opts.verbose)?;
    let list: Vec<String> = names.iter().map(|r| format!("robot {r}")).collect();
    eprintln!("fleet {n}: {} through the Zenoh router on {listen}", list.join(" and "));

    let mut joins = Vec::new();
    for (i, robot) in robots.iter().enumerate() {
        let dial = match nets.get(i) {
            Some(ns) => format!("tcp/{}:{port}", ns.host_addr),
            None => format!("tcp/127.0.0.1:{port}"),
        };
        let from = &names[(i + n - 1) % n];
        let file = robot_files(robot, &dial, opts.netns, from, opts.period_ms)?;
        let t0 = Instant::now();
        launch(robot, &file, nets.get(i))?;
        if i == 0 {
            continue;
        }
        loop {
            if counts(robot)?.arrived > 0 {
                joins.push(t0.elapsed().as_secs_f64() * 1000.0);
                break;
            }
            router.check_alive()?;
            if t0.elapsed() > JOIN_TIMEOUT {
                bail!("robot {} did not receive robot {from}'s ticks within {JOIN_TIMEOUT:?}", robot.name);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        eprintln!("fleet {n}: {}/{n} joined in {:.0} ms", i + 1, joins.last().copied().unwrap_or(0.0));
    }
    // robot 0 hears the last robot once it is up
    let t0 = Instant::now();
    while counts(&robots[0])?.arrived == 0 {
        if t0.elapsed() > JOIN_TIMEOUT {
            bail!("robot {} did not receive the last robot's ticks within {JOIN_TIMEOUT:?}", robots[0].name);
        }
        std::thread::sleep(Duration::from_millis(20));
    }

    let before: Vec<Counts> = robots.iter().map(counts).collect::<Result<_>>()?;
    let (cpu0, w0) = (cpu_s(router.id()), Instant::now());
    std::thread::sleep(Duration::from_secs_f64(opts.seconds));
    let (cpu1, window) = (cpu_s(router.id()), w0.elapsed().as_secs_f64());
    let rss = rss_kib(router.id());
    router.check_alive()?;
    let after: Vec<Counts> = robots.iter().map(counts).collect::<Result<_>>()?;
    let delta =
        |f: fn(&Counts) -> u64| -> u64 { after.iter().zip(&before).map(|(a, b)| f(a).saturating_sub(f(b))).sum() };
    let (sent, arrived) = (delta(|c| c.sent), delta(|c| c.arrived));
    let lat: Vec<f64> = after.iter().filter_map(|c| c.latency_us).collect();
    let cpu = match (cpu0, cpu1) {
        (Some(a), Some(b)) => (b - a) / window * 100.0,
        _ => bail!("the Zenoh router ended during the run"),
    };
    drop(robots);
    drop(router);
    drop(nets);
    Ok(FleetRow {
        robots: n,
        join_ms_median: median_f64(&joins),
        join_ms_max: joins.iter().copied().fold(0.0, f64::max),
        latency_us_median: median_f64(&lat),
        latency_us_max: lat.iter().copied().fold(0.0, f64::max),
        delivered: if sent > 0 { arrived as f64 / sent as f64 } else { 0.0 },
        router_cpu_pct: cpu,
        router_rss_kib: rss,
    })
}

/// Runs the scenario.
pub fn run(opts: &FleetOpts) -> Result<FleetReport> {
    if let Some(&n) = opts.robots.iter().find(|&&n| !(2..=MAX_ROBOTS).contains(&n)) {
        bail!("--robots {n}: a fleet has 2 to {MAX_ROBOTS} robots");
    }
    let t0 = Instant::now();
    let machine = Machine::probe();
    let mut rows = Vec::new();
    for &n in &opts.robots {
        let row = one_fleet(opts, n).with_context(|| format!("fleet of {n}"))?;
        eprintln!(
            "fleet {n}: join {:.0} ms (max {:.0}), latency {:.0} µs (max {:.0}), router {:.1}% CPU",
            row.join_ms_median, row.join_ms_max, row.latency_us_median, row.latency_us_max, row.router_cpu_pct
        );
        rows.push(row);
    }
    Ok(Report::new(
        "fleet",
        machine,
        FleetResults {
            rows,
            period_ms: opts.period_ms,
            window_s: opts.seconds,
            netns: opts.netns,
            seconds: t0.elapsed().as_secs_f64(),
        },
    ))
}

/// The results as a table.
pub fn print_tables(r: &FleetReport) {
    println!(
        "fleet through one Zenoh router ({}; a tick every {} ms per robot, {:.0} s window)",
        if r.netns { "a network namespace per robot" } else { "loopback" },
        r.period_ms,
        r.window_s
    );
    println!(
        "{:>6}  {:>14}  {:>12}  {:>16}  {:>14}  {:>9}  {:>10}  {:>10}",
        "robots",
        "join median ms",
        "join max ms",
        "latency median µs",
        "latency max µs",
        "delivered",
        "router CPU",
        "router RSS"
    );
    for row in &r.rows {
        println!(
            "{:>6}  {:>14.0}  {:>12.0}  {:>16.0}  {:>14.0}  {:>8.1}%  {:>9.1}%  {:>7} MiB",
            row.robots,
            row.join_ms_median,
            row.join_ms_max,
            row.latency_us_median,
            row.latency_us_max,
            row.delivered * 100.0,
            row.router_cpu_pct,
            row.router_rss_kib / 1024
        );
    }
}
