//! The soak: a robot from a launch file left running for minutes or hours
//! while agents come and go, its resources sampled, so that a leak shows.
//!
//! Churn: every few seconds a ticker and a relay are hot-added, wired,
//! checked for data through the relay, unwired and stopped. Sampled every
//! few seconds: the resident memory and open descriptors of the router and
//! of all the robot's processes together, the robot's files in `/dev/shm`
//! and under the iceoryx2 root, and how long `nerve ps` took. A leak is
//! memory, descriptors or files that keep growing in the second half while
//! the robot does the same thing over and over ([`growth`]).
//!
//! Run as a system test (`tests/tests/soak.rs`, ignored by default) and by
//! `nerve bench soak`, which reports and plots the same run.

use crate::{Error, Robot};
use agent_sdk::process::{Holdings, holdings};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

/// How a soak runs.
#[derive(Debug, Clone)]
pub struct SoakOptions {
    /// how long the robot runs
    pub duration: Duration,
    /// time between two samples (at least 0.5 s)
    pub every: Duration,
    /// time between two churn cycles (at least 1 s)
    pub churn_every: Duration,
    /// the robot's launch file; its paths are relative to the folder above the file's
    pub launch: PathBuf,
    /// show the output of `nerve launch`
    pub verbose: bool,
}

/// One sample of the robot's resources.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Sample {
    /// seconds since the robot came up
    pub t_s: f64,
    /// router resident memory, KiB
    pub router_rss_kib: u64,
    /// router open descriptors
    pub router_fds: u64,
    /// every process of the robot together: resident memory, KiB
    pub robot_rss_kib: u64,
    /// every process of the robot together: open descriptors
    pub robot_fds: u64,
    /// processes of the robot
    pub processes: u64,
    /// the robot's files in /dev/shm
    pub shm_files: u64,
    /// the robot's files under the iceoryx2 root
    pub iox2_files: u64,
    /// how long `nerve ps --json` took, ms
    pub ps_ms: f64,
}

/// Growth of one series over the second half of the run, per hour.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Growth {
    /// value at the first sample
    pub first: f64,
    /// value at the last sample
    pub last: f64,
    /// least-squares slope over the second half, per hour
    pub per_hour_second_half: f64,
}

/// What a soak saw.
#[derive(Debug, Clone)]
pub struct Soaked {
    /// the launch file, canonical
    pub launch: PathBuf,
    /// every sample, in time order
    pub samples: Vec<Sample>,
    /// churn cycles run
    pub cycles: u64,
    /// churn cycles that failed (each said on stderr)
    pub failures: u64,
    /// per successful cycle: `nerve start` to the first sample through the relay, ns
    pub hot_add_ns: Vec<u64>,
    /// per successful cycle: the `nerve connect`, ns
    pub rewire_ns: Vec<u64>,
    /// per sample: how long `nerve ps --json` took, ns
    pub ps_ns: Vec<u64>,
}

/// Files under `dir` (recursively) whose names start with `prefix`.
fn count_files(dir: &Path, prefix: &str) -> u64 {
    let Ok(rd) = std::fs::read_dir(dir) else { return 0 };
    rd.filter_map(|e| e.ok())
        .map(|e| {
            let p = e.path();
            if e.file_type().is_ok_and(|t| t.is_dir()) {
                count_files(&p, prefix)
            } else {
                u64::from(e.file_name().to_string_lossy().starts_with(prefix))
            }
        })
        .sum()
}

/// Files directly in `dir` whose names start with `prefix`.
fn count_top_files(dir: &Path, prefix: &str) -> u64 {
    let Ok(rd) = std::fs::read_dir(dir) else { return 0 };
    rd.filter_map(|e| e.ok()).filter(|e| e.file_name().to_string_lossy().starts_with(prefix)).count() as u64
}

/// First and last value of a series `f` of `samples`, and its growth per
/// hour over the second half (a least-squares slope).
pub fn growth(samples: &[Sample], f: impl Fn(&Sample) -> f64) -> Growth {
    let first = samples.first().map_or(0.0, &f);
    let last = samples.last().map_or(0.0, &f);
    let half = &samples[samples.len() / 2..];
    let n = half.len() as f64;
    let slope = if half.len() < 2 {
        0.0
    } else {
        let mx = half.iter().map(|s| s.t_s).sum::<f64>() / n;
        let my = half.iter().map(&f).sum::<f64>() / n;
        let sxy: f64 = half.iter().map(|s| (s.t_s - mx) * (f(s) - my)).sum();
        let sxx: f64 = half.iter().map(|s| (s.t_s - mx).powi(2)).sum();
        if sxx > 0.0 { sxy / sxx * 3600.0 } else { 0.0 }
    };
    Growth { first, last, per_hour_second_half: slope }
}

/// One churn cycle: hot-add a ticker and a relay, wire, wait for data
/// through the relay, unwire, stop both. Returns (hot-add, rewire) in ns.
fn churn(robot: &Robot, i: u64) -> Result<(u64, u64), Error> {
    let (t, r) = (format!("soakt{i}"), format!("soakr{i}"));
    let t0 = Instant::now();
    robot.try_run(&["start", "relay", "--name", &r])?;
    robot.try_run(&["start", "ticker", "--name", &t, "--period", "10ms"])?;
    let c0 = Instant::now();
    robot.try_run(&["connect", &format!("{t}/tick"), &format!("{r}/in")])?;
    let rewire = c0.elapsed().as_nanos() as u64;
    robot.try_run(&["echo", &format!("{r}/out"), "--count", "1", "--timeout", "5"])?;
    let hot_add = t0.elapsed().as_nanos() as u64;
    robot.try_run(&["disconnect", &format!("{t}/tick"), &format!("{r}/in")])?;
    robot.try_run(&["stop", &t])?;
    robot.try_run(&["stop", &r])?;
    Ok((hot_add, rewire))
}

/// The pids of the robot's agents in `nerve ps --json`, without the churn's
/// passing agents (`soak...`).
fn robot_pids(ps: &serde_json::Value) -> Vec<u32> {
    ps.as_array()
        .map(|a| {
            a.iter()
                .filter(|x| !x["name"].as_str().unwrap_or("").starts_with("soak"))
                .filter_map(|x| x["pid"].as_u64())
                .filter_map(|p| u32::try_from(p).ok())
                .filter(|p| *p > 0)
                .collect()
        })
        .unwrap_or_default()
}

/// Launches `o.launch` in `robot` and soaks it for `o.duration`; progress
/// goes to stderr once a minute. The robot stays up (dropping it takes it
/// down).
pub fn run(robot: &Robot, o: &SoakOptions) -> Result<Soaked, Error> {
    let launch = o.launch.canonicalize().map_err(|source| Error::LaunchFile { path: o.launch.clone(), source })?;
    // the exploration robot names its world relative to the repository
    let repo = launch.parent().and_then(Path::parent).ok_or_else(|| Error::NoRepository { path: launch.clone() })?;
    eprintln!(
        "soak: robot {} from {} for {:.1} min, a sample every {:?}, churn every {:?}",
        robot.name,
        launch.display(),
        o.duration.as_secs_f64() / 60.0,
        o.every,
        o.churn_every
    );
    let mut cmd = robot.command("nerve");
    cmd.current_dir(repo).arg("launch").arg(&launch).stdin(Stdio::null());
    if !o.verbose {
        cmd.stdout(Stdio::null()).stderr(Stdio::null());
    }
    let status = cmd.status().map_err(|source| Error::Run { what: "nerve launch".into(), source })?;
    if !status.success() {
        return Err(Error::Launch { path: launch, status });
    }
    let world =
        agent_sdk::World::new(&robot.name).map_err(|source| Error::World { robot: robot.name.clone(), source })?;
    let prefix = world.robot().shm_prefix();
    let router_pid = robot.pid_file("router").ok_or_else(|| Error::NoRouterPid { robot: robot.name.clone() })?;
    let every = o.every.max(Duration::from_millis(500));
    let churn_every = o.churn_every.max(Duration::from_secs(1));
    let mut soaked = Soaked {
        launch,
        samples: Vec::new(),
        cycles: 0,
        failures: 0,
        hot_add_ns: Vec::new(),
        rewire_ns: Vec::new(),
        ps_ns: Vec::new(),
    };
    let t0 = Instant::now();
    let (mut next_sample, mut next_churn) = (t0, t0 + churn_every);
    let mut last_progress: Option<Instant> = None;
    while t0.elapsed() < o.duration {
        let now = Instant::now();
        if now >= next_sample {
            next_sample += every;
            let p0 = Instant::now();
            let ps = robot.try_run(&["ps", "--json"]).ok().and_then(|out| serde_json::from_str(&out).ok());
            let ps_took = p0.elapsed();
            let pids = ps.as_ref().map(robot_pids).unwrap_or_default();
            if ps.is_some() {
                soaked.ps_ns.push(ps_took.as_nanos() as u64);
            }
            let router = holdings(router_pid);
            let all = pids
                .iter()
                .map(|p| holdings(*p))
                .fold(router, |sum, h| Holdings { rss_kib: sum.rss_kib + h.rss_kib, fds: sum.fds + h.fds });
            soaked.samples.push(Sample {
                t_s: t0.elapsed().as_secs_f64(),
                router_rss_kib: router.rss_kib,
                router_fds: router.fds,
                robot_rss_kib: all.rss_kib,
                robot_fds: all.fds,
                processes: pids.len() as u64 + 1,
                shm_files: count_top_files(Path::new("/dev/shm"), &prefix),
                iox2_files: count_files(world.iox2_root(), &prefix),
                ps_ms: ps_took.as_secs_f64() * 1e3,
            });
        }
        if now >= next_churn {
            next_churn += churn_every;
            soaked.cycles += 1;
            match churn(robot, soaked.cycles) {
                Ok((h, r)) => {
                    soaked.hot_add_ns.push(h);
                    soaked.rewire_ns.push(r);
                }
                Err(e) => {
                    soaked.failures += 1;
                    eprintln!("soak: churn cycle {} failed: {e}", soaked.cycles);
                }
            }
        }
        if last_progress.is_none_or(|at| at.elapsed() >= Duration::from_secs(60))
            && let Some(s) = soaked.samples.last()
        {
            last_progress = Some(Instant::now());
            eprintln!(
                "soak: {:.1}/{:.0} min: router {} KiB {} fds, robot {} KiB {} fds in {} processes, {} + {} files, {} churn cycles ({} failed)",
                t0.elapsed().as_secs_f64() / 60.0,
                o.duration.as_secs_f64() / 60.0,
                s.router_rss_kib,
                s.router_fds,
                s.robot_rss_kib,
                s.robot_fds,
                s.processes,
                s.shm_files,
                s.iox2_files,
                soaked.cycles,
                soaked.failures
            );
        }
        let wake = next_sample.min(next_churn);
        std::thread::sleep(wake.saturating_duration_since(Instant::now()).min(Duration::from_millis(500)));
    }
    if soaked.samples.len() < 2 {
        return Err(Error::TooShort { samples: soaked.samples.len() });
    }
    Ok(soaked)
}
