//! The cooperation experiment's records, verdict and figure (`nerve demo
//! cooperate`, thesis section 4.3, Fig. 4-10).
//!
//! The launcher follows the run and hands over what it recorded from the
//! robots' ports ([`Records`]): each robot's ground truth (the simulator),
//! its recorded pose (the odometry agent's `pose`: dead reckoning with the
//! checkpoint corrections) and, for robot 2, the raw dead reckoning of its
//! motor board (the same run without any correction), the path robot 1 sent
//! and robot 2's reports. [`analyse`] turns them into the verdict
//! ([`CoopSummary`], `summary.json`); [`write_trajectories`] draws the map
//! with both robots' true and recorded paths, the checkpoints, the via
//! points, the target and the correction jumps (`trajectories.png|svg`).
//! [`report`] is the launcher's one call: it does both and writes
//! `estimates.csv` and `summary.json` beside the figure.

use crate::plot::{Figures, map_chart, map_size};
use crate::scene::Scene;
use crate::{DemoError, write_summary};
use nerve_plot_font::figure::{DrawResult, Figure, write_png_and_svg};
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::Path;
use std::time::Instant;

/// One ground-truth sample of a robot.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TruePose {
    /// CLOCK_MONOTONIC ns when the simulator published it.
    pub stamp_ns: u64,
    /// Simulated time, s.
    pub t: f64,
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// Heading, rad.
    pub theta: f64,
    /// Collisions so far.
    pub collisions: u64,
}

/// One recorded (estimated) pose of a robot.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EstPose {
    /// CLOCK_MONOTONIC ns of the estimate.
    pub stamp_ns: u64,
    /// x, m, world frame.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// Heading, rad.
    pub theta: f64,
    /// Corrections applied so far.
    pub corrections: u32,
}

/// A point of the path robot 1 sent.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlannedPoint {
    /// Where, m.
    pub at: [f64; 2],
    /// `checkpoint`, `target-approach`, `target` or `waypoint`.
    pub kind: String,
    /// The checkpoint's id (0: none).
    pub checkpoint: u8,
}

/// Robot 2's report of a via point reached (or of its arrival).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reached {
    /// CLOCK_MONOTONIC ns of the report.
    pub stamp_ns: u64,
    /// Index in the path.
    pub index: u32,
    /// Where robot 2 believed it was, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// The arrival at the last point (else a via point).
    pub arrived: bool,
}

/// Everything the launcher recorded during a run.
#[derive(Debug, Clone, Default)]
pub struct Records {
    /// Robot 1's ground truth.
    pub r1_truth: Vec<TruePose>,
    /// Robot 2's ground truth.
    pub r2_truth: Vec<TruePose>,
    /// Robot 1's recorded pose.
    pub r1_est: Vec<EstPose>,
    /// Robot 2's recorded pose.
    pub r2_est: Vec<EstPose>,
    /// Robot 2's raw dead reckoning (no corrections), world frame.
    pub r2_raw: Vec<EstPose>,
    /// The path robot 1 sent (as robot 2 received it), and when it first came.
    pub path: Vec<PlannedPoint>,
    /// CLOCK_MONOTONIC ns when robot 1's map builder first sent the path.
    pub path_sent_ns: Option<u64>,
    /// CLOCK_MONOTONIC ns when robot 1's camera first saw the target.
    pub target_seen_ns: Option<u64>,
    /// Robot 2's reports.
    pub reached: Vec<Reached>,
    /// CLOCK_MONOTONIC ns when robot 1 was told to resume.
    pub resumed_ns: Option<u64>,
    /// Robot 2's grasp as its mission agent reports it (`held`, `missed`, ...).
    pub grasp: Option<String>,
    /// The bridges' figures at the end, per robot.
    pub bridge: BTreeMap<String, BTreeMap<String, String>>,
}

/// Localisation at one via point.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ViaPointResult {
    /// Index in the path.
    pub index: u32,
    /// What it is.
    pub kind: String,
    /// Where robot 1 placed it, m.
    pub planned: [f64; 2],
    /// Where robot 2 believed it was when it reported it reached, m.
    pub reached_estimate: [f64; 2],
    /// Where robot 2 truly was then, m.
    pub reached_true: [f64; 2],
    /// Simulated time of the report, s.
    pub reached_s: f64,
    /// True position to planned point, m.
    pub miss_m: f64,
    /// Error of the recorded pose (odometry with corrections), m.
    pub error_with_corrections_m: f64,
    /// Error of the raw dead reckoning (no correction at all), m.
    pub error_without_corrections_m: Option<f64>,
}

/// What crossed the bridges.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct BridgeTraffic {
    /// Messages sent, per robot.
    pub messages_out: BTreeMap<String, u64>,
    /// Bytes sent, per robot.
    pub bytes_out: BTreeMap<String, u64>,
    /// Messages received, per robot.
    pub messages_in: BTreeMap<String, u64>,
    /// Bytes received, per robot.
    pub bytes_in: BTreeMap<String, u64>,
    /// Last one-way latency measured by each robot's importer, µs.
    pub latency_us: BTreeMap<String, u64>,
    /// Messages lost (reliable exports: gave up), per robot.
    pub lost: BTreeMap<String, u64>,
}

/// `summary.json` of `nerve demo cooperate`.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct CoopSummary {
    /// The simulator's seed.
    pub seed: u64,
    /// The world file.
    pub world: String,
    /// Whether the checkpoint sensors corrected the poses (false with `--no-checkpoints`).
    pub checkpoints: bool,
    /// How the run ended.
    pub end_reason: String,
    /// Robot 1 confirmed a target (and so sent a path).
    pub target_found: bool,
    /// Robot 1 sent a path to robot 2.
    pub path_sent: bool,
    /// Robot 2 ended within `reach_m` of the target (centre to centre).
    pub robot2_reached_target: bool,
    /// The criterion, m.
    pub reach_m: f64,
    /// Robot 2's centre to the target's centre at the end, m (true positions).
    pub final_distance_to_target_m: Option<f64>,
    /// Robot 2's grasp, as its mission agent reports it.
    pub grasp: Option<String>,
    /// Where robot 1 placed the target, m.
    pub target_estimate: Option<[f64; 2]>,
    /// Where the target truly is, m.
    pub target_true: Option<[f64; 2]>,
    /// The path robot 1 sent.
    pub planned_path: Vec<PlannedPoint>,
    /// Via points: planned and reached.
    pub via_points: Vec<ViaPointResult>,
    /// Corrections applied, per robot.
    pub corrections: BTreeMap<String, u32>,
    /// Robot 2's localisation error at the end: recorded pose and raw dead reckoning, m.
    pub final_error_with_corrections_m: Option<f64>,
    /// Robot 2's raw dead reckoning's error at the end, m.
    pub final_error_without_corrections_m: Option<f64>,
    /// Collisions, per robot.
    pub collisions: BTreeMap<String, u64>,
    /// Simulated time of each stage, s: `target_seen`, `path_sent`,
    /// `via_<i>`, `arrived`, `resumed`, `end`.
    pub stage_times_s: BTreeMap<String, f64>,
    /// What crossed the bridges.
    pub bridge: BridgeTraffic,
    /// Wall-clock time of the whole command, s.
    pub wall_time_s: f64,
    /// The simulated clock's scale when the run was on simulated time
    /// (`--sim-time`); the other times are simulated seconds either way.
    pub time_scale: Option<f64>,
}

/// The truth sample nearest `stamp_ns`.
fn truth_at(rows: &[TruePose], stamp_ns: u64) -> Option<&TruePose> {
    rows.iter().min_by_key(|r| r.stamp_ns.abs_diff(stamp_ns))
}

/// The estimate nearest `stamp_ns`.
fn est_at(rows: &[EstPose], stamp_ns: u64) -> Option<&EstPose> {
    rows.iter().min_by_key(|r| r.stamp_ns.abs_diff(stamp_ns))
}

fn dist(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

fn figure_u64(f: &BTreeMap<String, String>, suffix: &str) -> u64 {
    f.iter().filter(|(k, _)| k.ends_with(suffix)).filter_map(|(_, v)| v.parse::<u64>().ok()).sum()
}

/// The verdict of a run. `reach_m`: robot 2's centre within this of the
/// target's counts as reaching it.
pub fn analyse(scene: &Scene, rec: &Records, reach_m: f64, robots: [&str; 2]) -> CoopSummary {
    let target = scene.world.checkpoints.iter().find(|c| c.target).map(|c| [c.position.x, c.position.y]);
    let mut s = CoopSummary { reach_m, target_true: target, ..CoopSummary::default() };
    let sim_t = |stamp: u64| truth_at(&rec.r1_truth, stamp).map(|r| r.t);
    s.path_sent = rec.path_sent_ns.is_some() || !rec.path.is_empty();
    s.target_found = s.path_sent;
    s.planned_path = rec.path.clone();
    s.target_estimate = rec.path.iter().rev().find(|p| p.kind == "target").map(|p| p.at);
    s.grasp = rec.grasp.clone();
    if let Some(t) = rec.target_seen_ns.and_then(sim_t) {
        s.stage_times_s.insert("target_seen".into(), t);
    }
    if let Some(t) = rec.path_sent_ns.and_then(sim_t) {
        s.stage_times_s.insert("path_sent".into(), t);
    }
    if let Some(t) = rec.resumed_ns.and_then(sim_t) {
        s.stage_times_s.insert("resumed".into(), t);
    }
    if let Some(last) = rec.r1_truth.last() {
        s.stage_times_s.insert("end".into(), last.t);
    }
    // via points: the first report of each index
    let mut seen = std::collections::BTreeSet::new();
    for r in &rec.reached {
        if r.arrived
            && let Some(t) = sim_t(r.stamp_ns)
        {
            s.stage_times_s.entry("arrived".into()).or_insert(t);
        }
        if !seen.insert(r.index) {
            continue;
        }
        let Some(tr) = truth_at(&rec.r2_truth, r.stamp_ns) else { continue };
        let planned = rec.path.get(r.index as usize);
        let raw = est_at(&rec.r2_raw, r.stamp_ns);
        s.stage_times_s.insert(format!("via_{}", r.index), tr.t);
        s.via_points.push(ViaPointResult {
            index: r.index,
            kind: planned.map_or_else(|| "?".into(), |p| p.kind.clone()),
            planned: planned.map_or([f64::NAN; 2], |p| p.at),
            reached_estimate: [r.x, r.y],
            reached_true: [tr.x, tr.y],
            reached_s: tr.t,
            miss_m: planned.map_or(f64::NAN, |p| dist((tr.x, tr.y), (p.at[0], p.at[1]))),
            error_with_corrections_m: dist((r.x, r.y), (tr.x, tr.y)),
            error_without_corrections_m: raw.map(|w| dist((w.x, w.y), (tr.x, tr.y))),
        });
    }
    s.corrections.insert(robots[0].into(), rec.r1_est.last().map_or(0, |e| e.corrections));
    s.corrections.insert(robots[1].into(), rec.r2_est.last().map_or(0, |e| e.corrections));
    s.collisions.insert(robots[0].into(), rec.r1_truth.iter().map(|r| r.collisions).max().unwrap_or(0));
    s.collisions.insert(robots[1].into(), rec.r2_truth.iter().map(|r| r.collisions).max().unwrap_or(0));
    if let Some(end) = rec.r2_truth.last() {
        s.final_distance_to_target_m = target.map(|t| dist((end.x, end.y), (t[0], t[1])));
        s.final_error_with_corrections_m = rec.r2_est.last().map(|e| dist((e.x, e.y), (end.x, end.y)));
        s.final_error_without_corrections_m = rec.r2_raw.last().map(|e| dist((e.x, e.y), (end.x, end.y)));
    }
    s.robot2_reached_target = s.final_distance_to_target_m.is_some_and(|d| d <= reach_m);
    for (robot, f) in &rec.bridge {
        let b = &mut s.bridge;
        b.messages_out.insert(robot.clone(), figure_u64(f, ".msgs_out"));
        b.bytes_out.insert(robot.clone(), figure_u64(f, ".bytes_out"));
        b.messages_in.insert(robot.clone(), figure_u64(f, ".msgs_in"));
        b.bytes_in.insert(robot.clone(), figure_u64(f, ".bytes_in"));
        b.lost.insert(robot.clone(), figure_u64(f, ".lost"));
        if let Some(l) = f.iter().find(|(k, _)| k.ends_with(".latency_us")).and_then(|(_, v)| v.parse().ok()) {
            b.latency_us.insert(robot.clone(), l);
        }
    }
    s
}

const R1: RGBColor = RGBColor(30, 90, 200);
const R2: RGBColor = RGBColor(230, 120, 20);
const JUMP: RGBColor = RGBColor(200, 0, 120);
const VIA: RGBColor = RGBColor(20, 150, 60);

/// At most this many points of a path are drawn.
const MAX_POINTS: usize = 3000;

fn thin<T: Copy>(v: &[T]) -> Vec<T> {
    let step = v.len().div_ceil(MAX_POINTS).max(1);
    let mut out: Vec<T> = v.iter().step_by(step).copied().collect();
    if v.len() > 1 && !(v.len() - 1).is_multiple_of(step) {
        out.extend(v.last().copied());
    }
    out
}

/// The correction jumps of a recorded path: (before, after) where the
/// corrections count went up.
pub fn jumps(est: &[EstPose]) -> Vec<((f64, f64), (f64, f64))> {
    est.windows(2)
        .filter(|w| w[1].corrections > w[0].corrections)
        .map(|w| ((w[0].x, w[0].y), (w[1].x, w[1].y)))
        .collect()
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    scene: &Scene,
    rec: &Records,
    title: &str,
    (xr, yr): ((f64, f64), (f64, f64)),
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let mut chart = map_chart(root, scene, title, 18, (xr, yr))?;
    // the planned path and its via points
    if !rec.path.is_empty() {
        let pts: Vec<(f64, f64)> = rec.path.iter().map(|p| (p.at[0], p.at[1])).collect();
        chart
            .draw_series(DashedLineSeries::new(pts.clone(), 6, 6, VIA.mix(0.7).stroke_width(1)))
            .map_err(e)?
            .label("path sent by robot 1 (via points)")
            .legend(|(x, y)| Rectangle::new([(x + 4, y - 4), (x + 12, y + 4)], VIA.stroke_width(2)));
        chart.draw_series(pts.iter().map(|p| Rectangle::new([*p, *p], VIA.stroke_width(1)))).map_err(e)?;
        chart
            .draw_series(
                pts.iter().map(|p| EmptyElement::at(*p) + Rectangle::new([(-5, -5), (5, 5)], VIA.stroke_width(2))),
            )
            .map_err(e)?;
    }
    let series: [(&[TruePose], &[EstPose], RGBColor, &str); 2] =
        [(&rec.r1_truth, &rec.r1_est, R1, "robot 1"), (&rec.r2_truth, &rec.r2_est, R2, "robot 2")];
    for (truth, est, col, name) in series {
        let t: Vec<(f64, f64)> = thin(truth).iter().map(|r| (r.x, r.y)).collect();
        chart
            .draw_series(LineSeries::new(t.clone(), col.stroke_width(2)))
            .map_err(e)?
            .label(format!("{name}: true path"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], col.stroke_width(2)));
        let r: Vec<(f64, f64)> = thin(est).iter().map(|r| (r.x, r.y)).collect();
        if !r.is_empty() {
            chart
                .draw_series(DashedLineSeries::new(r, 5, 4, col.mix(0.6).stroke_width(2)))
                .map_err(e)?
                .label(format!("{name}: recorded (odometry + corrections)"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 6, y)], col.mix(0.6).stroke_width(2)));
        }
        if let Some(s) = t.first() {
            chart.draw_series(std::iter::once(Circle::new(*s, 6, col.filled()))).map_err(e)?;
        }
        if let Some(s) = t.last() {
            chart.draw_series(std::iter::once(Cross::new(*s, 7, col.stroke_width(3)))).map_err(e)?;
        }
    }
    let raw: Vec<(f64, f64)> = thin(&rec.r2_raw).iter().map(|r| (r.x, r.y)).collect();
    if !raw.is_empty() {
        chart
            .draw_series(DashedLineSeries::new(raw, 2, 4, RGBColor(120, 120, 120).stroke_width(1)))
            .map_err(e)?
            .label("robot 2: raw dead reckoning (no corrections)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], RGBColor(120, 120, 120).stroke_width(1)));
    }
    let mut all_jumps = jumps(&rec.r1_est);
    all_jumps.extend(jumps(&rec.r2_est));
    if !all_jumps.is_empty() {
        chart
            .draw_series(all_jumps.iter().map(|(a, b)| PathElement::new(vec![*a, *b], JUMP.stroke_width(2))))
            .map_err(e)?
            .label("correction jump at a checkpoint")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], JUMP.stroke_width(2)));
        chart.draw_series(all_jumps.iter().map(|(_, b)| Circle::new(*b, 3, JUMP.filled()))).map_err(e)?;
    }
    nerve_plot_font::figure::legend(&mut chart, SeriesLabelPosition::UpperRight, 12).map_err(e)?;
    Ok(())
}

/// Writes `trajectories.png` and `trajectories.svg` into `dir`.
pub fn write_trajectories(dir: &Path, scene: &Scene, rec: &Records, title: &str) -> Result<Figures, DemoError> {
    let (w, h, xr, yr) = map_size(scene);
    let figure = Trajectories { scene, rec, title, range: (xr, yr) };
    let files = write_png_and_svg(&dir.join("trajectories"), (w, h), &figure)?;
    Ok(Figures { files: files.into() })
}

/// Both robots' trajectories (Fig. 4-10).
struct Trajectories<'a> {
    scene: &'a Scene,
    rec: &'a Records,
    title: &'a str,
    range: ((f64, f64), (f64, f64)),
}

impl Figure for Trajectories<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        Ok(draw(root, self.scene, self.rec, self.title, self.range)?)
    }
}

/// How the cooperation run was made.
#[derive(Debug, Clone)]
pub struct Run<'a> {
    /// Seed of the simulator's noise.
    pub seed: u64,
    /// The world file.
    pub world: String,
    /// Whether the checkpoint sensors corrected the poses.
    pub checkpoints: bool,
    /// Why the run ended (`summary.json`'s `end_reason`).
    pub end_reason: String,
    /// Robot 2's centre to the target's centre, m, that counts as reaching it.
    pub reach_m: f64,
    /// The two robots' names.
    pub robots: [&'a str; 2],
    /// When the command started, for the wall time.
    pub started: Instant,
    /// The simulated clock's scale (`--sim-time --time-scale`); `None` on the wall clock.
    pub time_scale: Option<f64>,
}

/// What [`report`] wrote.
#[derive(Debug, Clone)]
pub struct Report {
    /// `summary.json`.
    pub summary: CoopSummary,
    /// The figure.
    pub figures: Figures,
}

/// Writes `estimates.csv`, analyses the run, draws `trajectories.png|svg`
/// and writes `summary.json` into `out`.
pub fn report(out: &Path, scene: &Scene, rec: &Records, run: &Run<'_>) -> Result<Report, DemoError> {
    write_estimates(&out.join("estimates.csv"), rec)?;
    let mut s = analyse(scene, rec, run.reach_m, run.robots);
    s.seed = run.seed;
    s.world = run.world.clone();
    s.checkpoints = run.checkpoints;
    s.end_reason = run.end_reason.clone();
    let title = format!(
        "{} (seed {}{}) — robot 2 {} the target: {} m, {} collision(s)",
        scene.world.name,
        run.seed,
        if run.checkpoints { "" } else { ", no checkpoint corrections" },
        if s.robot2_reached_target { "reached" } else { "did NOT reach" },
        s.final_distance_to_target_m.map_or_else(|| "-".into(), |d| format!("{d:.2}")),
        s.collisions.values().sum::<u64>()
    );
    let figures = write_trajectories(out, scene, rec, &title)?;
    s.wall_time_s = run.started.elapsed().as_secs_f64();
    s.time_scale = run.time_scale;
    write_summary(out, &s)?;
    Ok(Report { summary: s, figures })
}

impl Report {
    /// The run in one line: how it ended, the target, the path, robot 2's
    /// arrival, collisions, corrections, times.
    pub fn headline(&self) -> String {
        let s = &self.summary;
        format!(
            "{}: target {}, path {}, robot 2 {} ({} m from the target), {} collision(s), corrections {:?}, {:.1} s simulated, {:.0} s wall{}",
            s.end_reason,
            if s.target_found { "found" } else { "NOT found" },
            if s.path_sent { "sent" } else { "NOT sent" },
            if s.robot2_reached_target { "reached it" } else { "did NOT reach it" },
            s.final_distance_to_target_m.map_or_else(|| "-".into(), |d| format!("{d:.2}")),
            s.collisions.values().sum::<u64>(),
            s.corrections,
            s.stage_times_s.get("end").copied().unwrap_or(0.0),
            s.wall_time_s,
            s.time_scale.map(|k| format!(" (simulated time at {k}x)")).unwrap_or_default()
        )
    }
}

/// `estimates.csv`: every recorded pose, both robots, and robot 2's raw dead reckoning.
fn write_estimates(path: &Path, rec: &Records) -> Result<(), DemoError> {
    let f = std::fs::File::create(path)
        .map_err(|source| DemoError::Record { context: format!("cannot create {}", path.display()), source })?;
    let mut w = std::io::BufWriter::new(f);
    let err = |source| DemoError::Record { context: format!("cannot write {}", path.display()), source };
    writeln!(w, "robot,source,stamp_ns,x,y,theta,corrections").map_err(err)?;
    for (robot, source, v) in
        [("1", "odometry", &rec.r1_est), ("2", "odometry", &rec.r2_est), ("2", "raw", &rec.r2_raw)]
    {
        for e in v {
            writeln!(w, "{robot},{source},{},{:.4},{:.4},{:.4},{}", e.stamp_ns, e.x, e.y, e.theta, e.corrections)
                .map_err(err)?;
        }
    }
    w.flush().map_err(err)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> Scene {
        let world = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/cooperate.toml");
        Scene::load(&world).expect("the cooperation world loads")
    }

    fn truth(stamp_ns: u64, x: f64, y: f64) -> TruePose {
        TruePose { stamp_ns, t: stamp_ns as f64 / 1e9, x, y, ..TruePose::default() }
    }

    #[test]
    fn the_verdict_reads_the_records() {
        let s = scene();
        let mut rec = Records::default();
        for k in 0..100u64 {
            rec.r1_truth.push(truth(k * 100_000_000, 0.1 * k as f64, 0.0));
            rec.r2_truth.push(TruePose { collisions: u64::from(k > 50), ..truth(k * 100_000_000, 12.4, -2.8) });
        }
        rec.r2_est = vec![
            EstPose { stamp_ns: 1_000_000_000, x: 1.0, y: 0.0, corrections: 0, ..EstPose::default() },
            EstPose { stamp_ns: 2_000_000_000, x: 12.5, y: -2.8, corrections: 2, ..EstPose::default() },
        ];
        rec.r2_raw = vec![EstPose { stamp_ns: 2_000_000_000, x: 12.0, y: -2.0, ..EstPose::default() }];
        rec.path = vec![
            PlannedPoint { at: [10.8, -0.4], kind: "checkpoint".into(), checkpoint: 3 },
            PlannedPoint { at: [12.8, -3.0], kind: "target".into(), checkpoint: 9 },
        ];
        rec.path_sent_ns = Some(3_000_000_000);
        rec.reached = vec![
            Reached { stamp_ns: 2_000_000_000, index: 0, x: 10.7, y: -0.4, arrived: false },
            Reached { stamp_ns: 2_100_000_000, index: 0, x: 10.7, y: -0.4, arrived: false },
            Reached { stamp_ns: 9_000_000_000, index: 1, x: 12.5, y: -2.8, arrived: true },
        ];
        rec.bridge.insert(
            "r1".into(),
            [
                ("export.mission/path.msgs_out", "7"),
                ("export.mission/order.msgs_out", "3"),
                ("import.x.latency_us", "250"),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_owned(), v.to_owned()))
            .collect(),
        );
        let v = analyse(&s, &rec, 0.5, ["r1", "r2"]);
        assert!(v.target_found && v.path_sent);
        assert_eq!(v.target_true, Some([12.8, -3.0]));
        assert_eq!(v.target_estimate, Some([12.8, -3.0]));
        let d = v.final_distance_to_target_m.expect("a distance");
        assert!((d - 0.4472).abs() < 1e-3, "{d}");
        assert!(v.robot2_reached_target);
        assert_eq!(v.via_points.len(), 2, "one entry per via point: {:?}", v.via_points);
        assert!((v.via_points[0].error_with_corrections_m - 8.65f64.sqrt()).abs() < 1e-9);
        assert_eq!(v.collisions["r2"], 1);
        assert_eq!(v.corrections["r2"], 2);
        assert_eq!(v.bridge.messages_out["r1"], 10);
        assert_eq!(v.bridge.latency_us["r1"], 250);
        assert!((v.stage_times_s["path_sent"] - 3.0).abs() < 1e-9);
        assert!((v.stage_times_s["arrived"] - 9.0).abs() < 1e-9);
        assert_eq!(jumps(&rec.r2_est).len(), 1);
        // and the figure is drawn
        let dir = std::env::temp_dir().join(format!("nerve-coop-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let f = write_trajectories(&dir, &s, &rec, "test").expect("figure");
        assert_eq!(f.files.len(), 2);
        for p in &f.files {
            assert!(std::fs::metadata(p).expect("written").len() > 1000, "{}", p.display());
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
