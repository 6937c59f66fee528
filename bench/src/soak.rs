//! Scenario `soak`: the exploration robot (`launch/explore.toml`: the
//! simulator and every agent of the thesis' first experiment) for N
//! minutes, plus churn: every few seconds a ticker and a relay are
//! hot-added, wired, checked for data, unwired and stopped.
//!
//! The run itself is the test kit's ([`nerve_testkit::soak`], also run as
//! the system test `tests/tests/soak.rs`); this entry writes its report:
//! first and last values, growth per hour from the second half (after
//! warm-up) and percentiles, and `soak.png`, which plots the series.

use crate::machine::Machine;
use crate::procs::Robot;
use crate::report::Report;
use crate::stats::Summary;
use anyhow::{Result, anyhow};
use nerve_testkit::soak::{self, growth};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub use nerve_testkit::soak::{Growth, Sample};

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

/// The soak report: the [`Head`](crate::report::Head) and [`SoakResults`].
pub type SoakReport = Report<SoakResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Clone, Serialize)]
pub struct SoakResults {
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

/// Runs the scenario.
pub fn run(o: &SoakOpts) -> Result<SoakReport> {
    let started = Instant::now();
    let robot = Robot::new("soak", o.verbose)?;
    let soaked = soak::run(
        &robot,
        &soak::SoakOptions {
            duration: Duration::from_secs_f64(o.minutes * 60.0),
            every: Duration::from_secs_f64(o.every_s.max(0.5)),
            churn_every: Duration::from_secs_f64(o.churn_s.max(1.0)),
            launch: o.launch.clone(),
            verbose: o.verbose,
        },
    )?;
    let samples = soaked.samples;
    Ok(Report::new(
        "soak",
        Machine::probe(),
        SoakResults {
            minutes: o.minutes,
            launch: soaked.launch.display().to_string(),
            churn_cycles: soaked.cycles,
            churn_failures: soaked.failures,
            hot_add: Summary::of(&soaked.hot_add_ns),
            rewire: Summary::of(&soaked.rewire_ns),
            ps: Summary::of(&soaked.ps_ns),
            router_rss_kib: growth(&samples, |s| s.router_rss_kib as f64),
            router_fds: growth(&samples, |s| s.router_fds as f64),
            robot_rss_kib: growth(&samples, |s| s.robot_rss_kib as f64),
            robot_fds: growth(&samples, |s| s.robot_fds as f64),
            files: growth(&samples, |s| (s.shm_files + s.iox2_files) as f64),
            samples,
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
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
    // the figure's set-up (font, background, file) is nerve_plot_font::figure's
    Ok(nerve_plot_font::figure::write_png_with(path, (1200, 900), |root| {
        let panels = root.split_evenly((2, 2));
        let minutes: Vec<f64> = r.samples.iter().map(|s| s.t_s / 60.0).collect();
        let xmax = minutes.last().copied().unwrap_or(1.0).max(0.1);
        type Series<'a> = (&'a str, RGBColor, Vec<f64>);
        let series: [(&str, Vec<Series<'_>>); 4] = [
            (
                "resident memory, MiB",
                vec![
                    (
                        "router",
                        RGBColor(200, 30, 30),
                        r.samples.iter().map(|s| s.router_rss_kib as f64 / 1024.0).collect(),
                    ),
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
        Ok(())
    })?)
}
