//! The exploration run's report: what `nerve demo explore` recorded goes in
//! ([`Recorded`]), the files of its output directory come out — `log.csv`,
//! the figures ([`crate::plot`]) and `summary.json` — with the one line that
//! sums the run up ([`Report::headline`]). The launcher runs the robot and
//! records; this is the only call it makes to turn the record into results.

use crate::analysis::{
    AgentCpu, Analysis, Criteria, EXPLORING_MODES, ModeChange, Summary, TRACKING_MODES, analyse, first_change_into,
    time_in_modes, time_in_modes_before,
};
use crate::plot::{Figures, write_all};
use crate::scene::Scene;
use crate::truth::TruthRow;
use crate::{DemoError, write_summary};
use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::Path;
use std::time::Instant;

/// What the launcher recorded during the run.
#[derive(Debug, Clone, Default)]
pub struct Recorded {
    /// The ground truth as it came on `sim/truth`.
    pub rows: Vec<TruthRow>,
    /// The decision maker's mode changes as they came on `decision/mode`.
    pub modes: Vec<ModeChange>,
    /// CPU used by each agent, sampled during the run.
    pub cpu: BTreeMap<String, AgentCpu>,
}

/// How the run was made.
#[derive(Debug, Clone)]
pub struct Run<'a> {
    /// Seed of the simulator's noise.
    pub seed: u64,
    /// The robot's name.
    pub robot: &'a str,
    /// Why the run ended (`summary.json`'s `end_reason`).
    pub end_reason: String,
    /// What counts as reaching the target.
    pub criteria: Criteria,
    /// When the command started, for the wall time.
    pub started: Instant,
    /// The simulated clock's scale (`--sim-time --time-scale`); `None` on the wall clock.
    pub time_scale: Option<f64>,
}

/// What [`report`] wrote.
#[derive(Debug, Clone)]
pub struct Report {
    /// `summary.json`.
    pub summary: Summary,
    /// The figures.
    pub figures: Figures,
}

/// Analyses the run and writes `log.csv`, the figures and `summary.json`
/// into `out`.
pub fn report(out: &Path, scene: &Scene, rec: &Recorded, run: &Run<'_>) -> Result<Report, DemoError> {
    let analysis = analyse(scene, &rec.rows, run.criteria);
    let mut s = analysis.summary.clone();
    s.seed = run.seed;
    s.robot = run.robot.to_owned();
    s.end_reason = run.end_reason.clone();
    s.time_in_mode_s = time_in_modes(&rec.modes, s.duration_s);
    s.first_track_s = first_change_into(&rec.modes, &TRACKING_MODES);
    s.time_in_mode_before_track_s = time_in_modes_before(&rec.modes, s.first_track_s.unwrap_or(s.duration_s));
    s.mode_changes = rec.modes.clone();
    s.cpu = rec.cpu.clone();
    write_log_csv(&out.join("log.csv"), &rec.rows, &analysis, &rec.modes)?;
    let title = format!("{} (seed {})", scene.world.name, run.seed);
    let figures = write_all(out, scene, &rec.rows, &analysis, &rec.modes, &title)?;
    s.wall_time_s = run.started.elapsed().as_secs_f64();
    s.time_scale = run.time_scale;
    write_summary(out, &s)?;
    Ok(Report { summary: s, figures })
}

impl Report {
    /// The run in one line: how it ended, exploration, doorway, target,
    /// collisions, clearance, times.
    pub fn headline(&self) -> String {
        let s = &self.summary;
        let explored: f64 = EXPLORING_MODES.iter().filter_map(|m| s.time_in_mode_before_track_s.get(*m)).sum();
        format!(
            "{}: explored {explored:.1} s{}, doorway {}{}, target {}{}, {} collision(s), min clearance {:.2} m, {:.1} s simulated, {} mode change(s), {:.0} s wall{}",
            s.end_reason,
            s.first_track_s
                .map(|t| format!(" before tracking at {t:.1} s"))
                .unwrap_or_else(|| ", never tracked".into()),
            if s.reached_doorway { "reached" } else { "NOT reached" },
            s.doorway_time_s.map(|t| format!(" at {t:.1} s")).unwrap_or_default(),
            if s.reached_target { "reached" } else { "NOT reached" },
            s.target_time_s.map(|t| format!(" at {t:.1} s")).unwrap_or_default(),
            s.collisions,
            s.min_clearance_m,
            s.duration_s,
            s.mode_changes.len(),
            s.wall_time_s,
            s.time_scale.map(|k| format!(" (simulated time at {k}x)")).unwrap_or_default()
        )
    }
}

/// `log.csv`: the truth with derived columns and the mode in force.
fn write_log_csv(path: &Path, rows: &[TruthRow], a: &Analysis, modes: &[ModeChange]) -> Result<(), DemoError> {
    let f = std::fs::File::create(path)
        .map_err(|source| DemoError::Record { context: format!("cannot create {}", path.display()), source })?;
    let mut w = std::io::BufWriter::new(f);
    let err = |source| DemoError::Record { context: format!("cannot write {}", path.display()), source };
    writeln!(w, "t,x,y,theta,v,omega,collisions,in_contact,clearance_m,target_x,target_y,target_dist_m,mode")
        .map_err(err)?;
    let mut k = 0;
    let mut mode = "";
    for (i, r) in rows.iter().enumerate() {
        while k < modes.len() && modes[k].t_s.is_some_and(|t| t <= r.t) {
            mode = &modes[k].mode;
            k += 1;
        }
        let (tx, ty, td) = match a.target.get(i).copied().flatten() {
            Some(p) => {
                (format!("{:.3}", p.x), format!("{:.3}", p.y), format!("{:.3}", p.dist(nerve_sim::Vec2::new(r.x, r.y))))
            }
            None => (String::new(), String::new(), String::new()),
        };
        writeln!(
            w,
            "{:.3},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{:.4},{tx},{ty},{td},{mode}",
            r.t,
            r.x,
            r.y,
            r.theta,
            r.v,
            r.omega,
            r.collisions,
            u8::from(r.in_contact),
            a.clearance.get(i).copied().unwrap_or(f64::NAN)
        )
        .map_err(err)?;
    }
    w.flush().map_err(err)
}
