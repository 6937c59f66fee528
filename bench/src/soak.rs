//! Scenario `soak`: the exploration robot (`launch/explore.toml`: the
//! simulator and every agent of the thesis' first experiment) for N
//! minutes, plus churn: every few seconds a ticker and a relay are
//! hot-added, wired, checked for data, unwired and stopped.
//!
//! Sampled every `--every` seconds: the resident memory and open
//! descriptors of the router and of all the robot's processes together,
//! the robot's files in `/dev/shm` and under the iceoryx2 root, and how long
//! `nerve ps` took. Each churn cycle times its hot-add (from `nerve start`
//! to the first sample through the relay) and its rewire (`connect`). The
//! report gives first and last values, growth per hour from the second
//! half (after warm-up) and percentiles; `soak.png` plots the series.
//!
//! What a leak looks like: memory, descriptors or files that keep growing
//! in the second half while the robot does the same thing over and over.

use crate::machine::{Machine, command_line};
use crate::procs::Robot;
use crate::stats::Summary;
use agent_sdk::process::{Holdings, holdings};
use anyhow::{Context as _, Result, anyhow, bail};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Options of the soak scenario.
#[derive(Debug, Clone)]
pub struct SoakOpts {
    /// how long, minutes
    pub minutes: f64,
    /// seconds between two samples
    pub every_s: f64,
    /// seconds between two churn cycles
    pub churn_s: f64,
    /// the launch file of the robot
    pub launch: PathBuf,
    /// show children's output
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

/// The soak report.
#[derive(Debug, Clone, Serialize)]
pub struct SoakReport {
    /// "soak"
    pub scenario: &'static str,
    /// the command that produced it
    pub command: String,
    /// the machine
    pub machine: Machine,
    /// minutes asked for
    pub minutes: f64,
    /// the launch file
    pub launch: String,
    /// churn cycles done, and how many failed
    pub churn_cycles: u64,
    /// churn cycles whose hot-add or rewire failed
    pub churn_failures: u64,
    /// hot-add: `nerve start` to the first sample through the relay, ns
    pub hot_add: Summary,
    /// rewire: `nerve connect`, ns
    pub rewire: Summary,
    /// `nerve ps --json`, ns
    pub ps: Summary,
    /// router memory, KiB
    pub router_rss_kib: Growth,
    /// router descriptors
    pub router_fds: Growth,
    /// the robot's memory, KiB
    pub robot_rss_kib: Growth,
    /// the robot's descriptors
    pub robot_fds: Growth,
    /// the robot's files in /dev/shm and under the iceoryx2 root
    pub files: Growth,
    /// every sample
    pub samples: Vec<Sample>,
    /// wall time of the scenario, s
    pub seconds: f64,
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

fn growth(samples: &[Sample], f: impl Fn(&Sample) -> f64) -> Growth {
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
fn churn(robot: &Robot, i: u64) -> Result<(u64, u64)> {
    let (t, r) = (format!("soakt{i}"), format!("soakr{i}"));
    let t0 = Instant::now();
    robot.run(&["start", "relay", "--name", &r])?;
    robot.run(&["start", "ticker", "--name", &t, "--period", "10ms"])?;
    let c0 = Instant::now();
    robot.run(&["connect", &format!("{t}/tick"), &format!("{r}/in")])?;
    let rewire = c0.elapsed().as_nanos() as u64;
    robot.run(&["echo", &format!("{r}/out"), "--count", "1", "--timeout", "5"])?;
    let hot_add = t0.elapsed().as_nanos() as u64;
    robot.run(&["disconnect", &format!("{t}/tick"), &format!("{r}/in")])?;
    robot.run(&["stop", &t])?;
    robot.run(&["stop", &r])?;
    Ok((hot_add, rewire))
}

/// Runs the scenario.
pub fn run(o: &SoakOpts) -> Result<SoakReport> {
    let started = Instant::now();
    let launch = o.launch.canonicalize().with_context(|| format!("no launch file {}", o.launch.display()))?;
    // the exploration robot names its world relative to the repository
    let repo =
        launch.parent().and_then(Path::parent).ok_or_else(|| anyhow!("{} has no repository", launch.display()))?;
    let robot = Robot::new("soak", o.verbose)?;
    eprintln!(
        "soak: robot {} from {} for {} min, a sample every {} s, churn every {} s",
        robot.name,
        launch.display(),
        o.minutes,
        o.every_s,
        o.churn_s
    );
    let mut cmd = robot.nerve();
    cmd.current_dir(repo).arg("launch").arg(&launch);
    robot.quiet(&mut cmd);
    let status = cmd.status().context("cannot run nerve launch")?;
    if !status.success() {
        bail!("`nerve launch {}` failed ({status})", launch.display());
    }
    let world = agent_sdk::World::new(&robot.name).context("the robot's world")?;
    let prefix = world.robot().shm_prefix();
    let router_pid: u32 = std::fs::read_to_string(robot.home.join(&robot.name).join("pids").join("router.pid"))
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .ok_or_else(|| anyhow!("the robot's router left no pid file"))?;
    let total = Duration::from_secs_f64(o.minutes * 60.0);
    let every = Duration::from_secs_f64(o.every_s.max(0.5));
    let churn_every = Duration::from_secs_f64(o.churn_s.max(1.0));
    let (mut samples, mut hot_add, mut rewire, mut ps_ns) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut cycles, mut failures) = (0u64, 0u64);
    let t0 = Instant::now();
    let (mut next_sample, mut next_churn) = (t0, t0 + churn_every);
    let mut last_progress: Option<Instant> = None;
    while t0.elapsed() < total {
        let now = Instant::now();
        if now >= next_sample {
            next_sample += every;
            let p0 = Instant::now();
            let ps = robot.ps();
            let ps_took = p0.elapsed();
            let pids: Vec<u32> = ps
                .as_ref()
                .ok()
                .and_then(|v| v.as_array())
                .map(|a| {
                    // the robot itself, not the churn's passing agents
                    a.iter()
                        .filter(|x| !x["name"].as_str().unwrap_or("").starts_with("soak"))
                        .filter_map(|x| x["pid"].as_u64())
                        .map(|p| p as u32)
                        .filter(|p| *p > 0)
                        .collect()
                })
                .unwrap_or_default();
            if ps.is_ok() {
                ps_ns.push(ps_took.as_nanos() as u64);
            }
            let router = holdings(router_pid);
            let robot = pids
                .iter()
                .map(|p| holdings(*p))
                .fold(router, |sum, h| Holdings { rss_kib: sum.rss_kib + h.rss_kib, fds: sum.fds + h.fds });
            samples.push(Sample {
                t_s: t0.elapsed().as_secs_f64(),
                router_rss_kib: router.rss_kib,
                router_fds: router.fds,
                robot_rss_kib: robot.rss_kib,
                robot_fds: robot.fds,
                processes: pids.len() as u64 + 1,
                shm_files: count_top_files(Path::new("/dev/shm"), &prefix),
                iox2_files: count_files(world.iox2_root(), &prefix),
                ps_ms: ps_took.as_secs_f64() * 1e3,
            });
        }
        if now >= next_churn {
            next_churn += churn_every;
            cycles += 1;
            match churn(&robot, cycles) {
                Ok((h, r)) => {
                    hot_add.push(h);
                    rewire.push(r);
                }
                Err(e) => {
                    failures += 1;
                    eprintln!("soak: churn cycle {cycles} failed: {e:#}");
                }
            }
        }
        if last_progress.is_none_or(|at| at.elapsed() >= Duration::from_secs(60)) && !samples.is_empty() {
            last_progress = Some(Instant::now());
            if let Some(s) = samples.last() {
                eprintln!(
                    "soak: {:.1}/{:.0} min: router {} KiB {} fds, robot {} KiB {} fds in {} processes, {} + {} files, {cycles} churn cycles ({failures} failed)",
                    t0.elapsed().as_secs_f64() / 60.0,
                    o.minutes,
                    s.router_rss_kib,
                    s.router_fds,
                    s.robot_rss_kib,
                    s.robot_fds,
                    s.processes,
                    s.shm_files,
                    s.iox2_files
                );
            }
        }
        let wake = next_sample.min(next_churn);
        std::thread::sleep(wake.saturating_duration_since(Instant::now()).min(Duration::from_millis(500)));
    }
    if samples.len() < 2 {
        bail!("too short a run to say anything: {} sample(s)", samples.len());
    }
    Ok(SoakReport {
        scenario: "soak",
        command: command_line(),
        machine: Machine::probe(),
        minutes: o.minutes,
        launch: launch.display().to_string(),
        churn_cycles: cycles,
        churn_failures: failures,
        hot_add: Summary::of(&hot_add),
        rewire: Summary::of(&rewire),
        ps: Summary::of(&ps_ns),
        router_rss_kib: growth(&samples, |s| s.router_rss_kib as f64),
        router_fds: growth(&samples, |s| s.router_fds as f64),
        robot_rss_kib: growth(&samples, |s| s.robot_rss_kib as f64),
        robot_fds: growth(&samples, |s| s.robot_fds as f64),
        files: growth(&samples, |s| (s.shm_files + s.iox2_files) as f64),
        samples,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Prints the report as a table.
pub fn print_tables(r: &SoakReport) {
    let ms = |ns: u64| format!("{:.1} ms", ns as f64 / 1e6);
    println!(
        "soak: {:.0} min of {} with churn ({} cycles, {} failed)",
        r.minutes, r.launch, r.churn_cycles, r.churn_failures
    );
    println!("{:<22} {:>12} {:>12} {:>22}", "", "first", "last", "per hour (2nd half)");
    for (name, g) in [
        ("router RSS, KiB", r.router_rss_kib),
        ("router descriptors", r.router_fds),
        ("robot RSS, KiB", r.robot_rss_kib),
        ("robot descriptors", r.robot_fds),
        ("robot files", r.files),
    ] {
        println!("{name:<22} {:>12.0} {:>12.0} {:>22.1}", g.first, g.last, g.per_hour_second_half);
    }
    for (name, s) in [("hot-add", &r.hot_add), ("rewire", &r.rewire), ("nerve ps", &r.ps)] {
        println!("{name:<22} p50 {:>10} p99 {:>10} max {:>10}", ms(s.p50_ns), ms(s.p99_ns), ms(s.max_ns));
    }
}

/// Draws the series into `path` (PNG): memory, descriptors, files and `ps` time against minutes.
pub fn png(r: &SoakReport, path: &Path) -> Result<()> {
    use plotters::prelude::*;
    let e = |x: &dyn std::fmt::Display| anyhow!("plot {}: {x}", path.display());
    nerve_plot_font::register();
    let root = BitMapBackend::new(path, (1200, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let panels = root.split_evenly((2, 2));
    let minutes: Vec<f64> = r.samples.iter().map(|s| s.t_s / 60.0).collect();
    let xmax = minutes.last().copied().unwrap_or(1.0).max(0.1);
    type Series<'a> = (&'a str, RGBColor, Vec<f64>);
    let series: [(&str, Vec<Series<'_>>); 4] = [
        (
            "resident memory, MiB",
            vec![
                ("router", RGBColor(200, 30, 30), r.samples.iter().map(|s| s.router_rss_kib as f64 / 1024.0).collect()),
                (
                    "whole robot",
                    RGBColor(30, 90, 200),
                    r.samples.iter().map(|s| s.robot_rss_kib as f64 / 1024.0).collect(),
                ),
            ],
        ),
        (
            "open descriptors",
            vec![
                ("router", RGBColor(200, 30, 30), r.samples.iter().map(|s| s.router_fds as f64).collect()),
                ("whole robot", RGBColor(30, 90, 200), r.samples.iter().map(|s| s.robot_fds as f64).collect()),
            ],
        ),
        (
            "the robot's files",
            vec![
                ("/dev/shm", RGBColor(20, 150, 60), r.samples.iter().map(|s| s.shm_files as f64).collect()),
                ("iceoryx2 root", RGBColor(140, 60, 170), r.samples.iter().map(|s| s.iox2_files as f64).collect()),
            ],
        ),
        ("nerve ps, ms", vec![("ps", RGBColor(230, 140, 20), r.samples.iter().map(|s| s.ps_ms).collect())]),
    ];
    for (area, (title, lines)) in panels.iter().zip(series.iter()) {
        let ymax = lines.iter().flat_map(|l| l.2.iter().copied()).fold(1.0, f64::max) * 1.15;
        let mut chart = ChartBuilder::on(area)
            .caption(*title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(0f64..xmax, 0f64..ymax)
            .map_err(|x| e(&x))?;
        chart.configure_mesh().x_desc("minutes").draw().map_err(|x| e(&x))?;
        for (label, colour, ys) in lines {
            let c = *colour;
            chart
                .draw_series(LineSeries::new(minutes.iter().copied().zip(ys.iter().copied()), c.stroke_width(2)))
                .map_err(|x| e(&x))?
                .label(*label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        }
        crate::plot::draw_legend(&mut chart, 14).map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))?;
    Ok(())
}
