//! The verdict of a run, computed from the ground truth and the world.
//!
//! Definitions (also in `docs/demo.md`):
//!
//! * **reached_doorway**: the robot's centre crossed the opening of a door of
//!   the world file (the segment between the door's jambs on the wall's
//!   line), going from the side of the wall where the robot started to the
//!   other side. `doorway_time_s` is the first such crossing.
//! * **reached_target**: after `doorway_time_s`, at a time when the target
//!   has finished its path (the end of a `once` path; any time for a fixed
//!   target or a path that never ends), the distance between the robot's
//!   centre and the target's centre is at most
//!   [`Criteria::target_reach_m`]. The target is the object named
//!   `red-object` (else the first red object). `target_time_s` is the first
//!   such time. This is "the robot followed the person": it has to be near
//!   the red object where the person ended up, not where they stood.
//! * **collisions**: the simulator's contact counter at the end (each new
//!   contact with a wall, box, tube or object counts once).
//! * **min_clearance_m**: the smallest distance between the robot's disc and
//!   any solid thing (walls, box sides, tubes, objects low enough to bump
//!   into, at their position at that time) over the run; 0 means touching.
//! * **first_track_s**: the first change of the decision maker into a mode
//!   in which the tracker leads the foot ([`TRACKING_MODES`]: it saw the
//!   target); **time_in_mode_before_track_s**: the seconds spent in each mode
//!   before it (before the end when the target was never tracked) — how long
//!   the robot explored before it saw the person.

use crate::scene::Scene;
use crate::truth::TruthRow;
use nerve_sim::Vec2;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Thresholds of the verdict.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Criteria {
    /// Robot centre to target centre, m, that counts as "at the target".
    pub target_reach_m: f64,
}

impl Default for Criteria {
    fn default() -> Self {
        Criteria { target_reach_m: 1.5 }
    }
}

/// The modes of `kb/explore.toml` in which the tracker leads the foot: the
/// target is in sight.
pub const TRACKING_MODES: [&str; 2] = ["track", "hold"];

/// The modes of `kb/explore.toml` in which the wall follower leads the foot
/// (`lean` is `explore` slowed down under load).
pub const EXPLORING_MODES: [&str; 2] = ["explore", "lean"];

/// One change of the decision maker's mode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModeChange {
    /// Simulated time of the change, s (the `since_ns` of `decision/mode`
    /// placed on the simulator's clock through the newest `sim/truth` sample).
    pub t_s: Option<f64>,
    /// Wall-clock time of day (UTC) when the demo saw it, `HH:MM:SS.mmm`.
    pub clock: String,
    /// The new mode.
    pub mode: String,
    /// The mode before, when the log says.
    pub from: Option<String>,
    /// What was seen, e.g. `decision/mode: explore -> track (change 3)`.
    pub line: String,
}

/// CPU used by one agent during the run.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct AgentCpu {
    /// Agent kind.
    pub kind: String,
    /// Mean of the sampled CPU percentages (percent of one core).
    pub mean_percent: f64,
    /// Largest sample.
    pub max_percent: f64,
    /// Number of samples.
    pub samples: usize,
    /// User + system CPU seconds of the process at the last sample (/proc).
    pub cpu_seconds: Option<f64>,
    /// Restarts by the supervisor.
    pub restarts: u32,
}

/// `summary.json`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Summary {
    /// World name.
    pub world: String,
    /// World file.
    pub world_file: String,
    /// Simulator seed.
    pub seed: u64,
    /// Robot (nerve world) name.
    pub robot: String,
    /// See the module doc.
    pub reached_doorway: bool,
    /// First doorway crossing, s.
    pub doorway_time_s: Option<f64>,
    /// The door crossed: its opening's two jambs.
    pub doorway: Option<[[f64; 2]; 2]>,
    /// See the module doc.
    pub reached_target: bool,
    /// When the target was reached, s.
    pub target_time_s: Option<f64>,
    /// Closest approach to the target after the doorway, m (centre to centre).
    pub min_target_distance_m: Option<f64>,
    /// Distance to the target at the end, m.
    pub final_target_distance_m: Option<f64>,
    /// Collision count at the end.
    pub collisions: u64,
    /// See the module doc.
    pub min_clearance_m: f64,
    /// When the clearance was smallest, s.
    pub min_clearance_at_s: f64,
    /// Simulated time covered by the log, s.
    pub duration_s: f64,
    /// Path length, m.
    pub distance_m: f64,
    /// Largest forward speed, m/s.
    pub max_speed_m_s: f64,
    /// Mean |speed|, m/s.
    pub mean_speed_m_s: f64,
    /// Spread (max − min) of the unwrapped heading after the doorway, degrees:
    /// about 180 or more when the robot made a U-turn.
    pub turn_after_doorway_deg: Option<f64>,
    /// Final pose [x, y, heading_deg].
    pub final_pose: [f64; 3],
    /// Why the run ended.
    pub end_reason: String,
    /// Wall-clock seconds from launch to everything stopped.
    pub wall_time_s: f64,
    /// The simulated clock's scale when the run was on simulated time
    /// (`--sim-time`): the figures above are in simulated seconds either way.
    #[serde(default)]
    pub time_scale: Option<f64>,
    /// Thresholds used.
    pub criteria: Criteria,
    /// Decision maker's mode changes, in order.
    pub mode_changes: Vec<ModeChange>,
    /// Seconds spent in each mode (from the mode changes).
    pub time_in_mode_s: BTreeMap<String, f64>,
    /// First change into a [`TRACKING_MODES`] mode (the target seen), s.
    #[serde(default)]
    pub first_track_s: Option<f64>,
    /// Seconds spent in each mode before `first_track_s` (before the end
    /// when the target was never tracked).
    #[serde(default)]
    pub time_in_mode_before_track_s: BTreeMap<String, f64>,
    /// CPU per agent.
    pub cpu: BTreeMap<String, AgentCpu>,
}

/// The summary and what was computed per row.
#[derive(Debug, Clone, PartialEq)]
pub struct Analysis {
    /// The verdict (fields about the run itself — seed, robot, modes, CPU —
    /// are left for the caller).
    pub summary: Summary,
    /// Clearance of the robot's disc at each row, m.
    pub clearance: Vec<f64>,
    /// Target position at each row.
    pub target: Vec<Option<Vec2>>,
}

fn side(seg: &nerve_sim::Segment, p: Vec2) -> f64 {
    (seg.b - seg.a).cross(p - seg.a)
}

/// Where the step `p0 → p1` crosses the door opening from side `from_sign`
/// to the other side, if it does.
fn crosses(seg: &nerve_sim::Segment, p0: Vec2, p1: Vec2, from_sign: f64) -> bool {
    let (s0, s1) = (side(seg, p0), side(seg, p1));
    if s0 * from_sign < 0.0 || s1 * from_sign >= 0.0 {
        return false;
    }
    // the crossing point on the wall's line, as a fraction along the opening
    let k = s0 / (s0 - s1);
    let q = p0 + (p1 - p0) * k;
    let d = seg.b - seg.a;
    let u = (q - seg.a).dot(d) / d.dot(d);
    (0.0..=1.0).contains(&u)
}

/// Whether the target counts as reached at row `r` (see the module doc).
pub fn at_target(scene: &Scene, criteria: &Criteria, doorway_time: Option<f64>, r: &TruthRow) -> bool {
    let (Some(td), Some(tp)) = (doorway_time, scene.target_at(r.t)) else { return false };
    let settled = scene.target_settles_at().is_none_or(|ts| r.t >= ts);
    r.t >= td && settled && tp.dist(Vec2::new(r.x, r.y)) <= criteria.target_reach_m
}

/// Incremental doorway detection, for following a run live.
#[derive(Debug, Clone, Default)]
pub struct DoorwayWatch {
    start_sides: Option<Vec<f64>>,
    last: Option<Vec2>,
    /// First crossing: (time, door index).
    pub crossed: Option<(f64, usize)>,
}

impl DoorwayWatch {
    /// Feeds the next row; returns the crossing when this row completes it.
    pub fn push(&mut self, scene: &Scene, r: &TruthRow) -> Option<(f64, usize)> {
        let p = Vec2::new(r.x, r.y);
        let sides = self.start_sides.get_or_insert_with(|| {
            let s = Vec2::new(scene.world.start.x, scene.world.start.y);
            scene.doors.iter().map(|d| side(&d.opening, s).signum()).collect()
        });
        if let (Some(p0), None) = (self.last, self.crossed) {
            for (i, d) in scene.doors.iter().enumerate() {
                if sides[i] != 0.0 && crosses(&d.opening, p0, p, sides[i]) {
                    self.crossed = Some((r.t, i));
                    self.last = Some(p);
                    return self.crossed;
                }
            }
        }
        self.last = Some(p);
        None
    }
}

/// Computes the verdict of a run; see the module doc for the definitions.
pub fn analyse(scene: &Scene, rows: &[TruthRow], criteria: Criteria) -> Analysis {
    let mut s = Summary {
        world: scene.world.name.clone(),
        world_file: scene.world.source.display().to_string(),
        criteria,
        min_clearance_m: f64::INFINITY,
        ..Summary::default()
    };
    let mut watch = DoorwayWatch::default();
    let mut clearance = Vec::with_capacity(rows.len());
    let mut target = Vec::with_capacity(rows.len());
    let mut speed_sum = 0.0;
    for (i, r) in rows.iter().enumerate() {
        let p = Vec2::new(r.x, r.y);
        let c = scene.clearance(p, r.t) - scene.robot_radius;
        if c < s.min_clearance_m {
            s.min_clearance_m = c;
            s.min_clearance_at_s = r.t;
        }
        clearance.push(c);
        target.push(scene.target_at(r.t));
        if i > 0 {
            s.distance_m += p.dist(Vec2::new(rows[i - 1].x, rows[i - 1].y));
        }
        s.max_speed_m_s = s.max_speed_m_s.max(r.v);
        speed_sum += r.v.abs();
        if let Some((t, d)) = watch.push(scene, r) {
            s.reached_doorway = true;
            s.doorway_time_s = Some(t);
            let o = scene.doors[d].opening;
            s.doorway = Some([[o.a.x, o.a.y], [o.b.x, o.b.y]]);
        }
        if let (Some(td), Some(tp)) = (s.doorway_time_s, scene.target_at(r.t))
            && r.t >= td
        {
            let dist = tp.dist(p);
            s.min_target_distance_m = Some(s.min_target_distance_m.map_or(dist, |m: f64| m.min(dist)));
        }
        if !s.reached_target && at_target(scene, &criteria, s.doorway_time_s, r) {
            s.reached_target = true;
            s.target_time_s = Some(r.t);
        }
    }
    if let Some(last) = rows.last() {
        s.duration_s = last.t;
        s.collisions = last.collisions;
        s.final_pose = [last.x, last.y, last.theta.to_degrees()];
        s.final_target_distance_m = scene.target_at(last.t).map(|tp| tp.dist(Vec2::new(last.x, last.y)));
        s.mean_speed_m_s = speed_sum / rows.len() as f64;
    }
    if let Some(td) = s.doorway_time_s {
        let mut unwrapped = None::<f64>;
        let (mut lo, mut hi, mut prev) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
        for r in rows.iter().filter(|r| r.t >= td) {
            let u = match unwrapped {
                None => r.theta,
                Some(u) => u + wrap(r.theta - prev),
            };
            prev = r.theta;
            unwrapped = Some(u);
            lo = lo.min(u);
            hi = hi.max(u);
        }
        if unwrapped.is_some() {
            s.turn_after_doorway_deg = Some((hi - lo).to_degrees());
        }
    }
    if !s.min_clearance_m.is_finite() {
        s.min_clearance_m = 0.0;
    }
    Analysis { summary: s, clearance, target }
}

/// Unwraps a sequence of headings (radians) into a continuous curve.
pub fn unwrap_angles(theta: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(theta.len());
    for (i, th) in theta.iter().enumerate() {
        match i {
            0 => out.push(*th),
            _ => {
                let prev = out[i - 1];
                out.push(prev + wrap(th - theta[i - 1]));
            }
        }
    }
    out
}

/// Seconds spent in each mode, given the changes (with times) and the run's end.
pub fn time_in_modes(changes: &[ModeChange], end: f64) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    let timed: Vec<(f64, &str)> = changes.iter().filter_map(|c| c.t_s.map(|t| (t.max(0.0), c.mode.as_str()))).collect();
    for (i, (t, m)) in timed.iter().enumerate() {
        let until = timed.get(i + 1).map_or(end, |n| n.0).max(*t);
        *out.entry((*m).to_owned()).or_insert(0.0) += until.min(end).max(*t) - t;
    }
    out
}

/// The time of the first change into one of `modes`, if any (and timed).
pub fn first_change_into(changes: &[ModeChange], modes: &[&str]) -> Option<f64> {
    changes.iter().find(|c| modes.contains(&c.mode.as_str())).and_then(|c| c.t_s)
}

/// Seconds spent in each mode before `until` (modes not entered by then are left out).
pub fn time_in_modes_before(changes: &[ModeChange], until: f64) -> BTreeMap<String, f64> {
    let mut out = time_in_modes(changes, until);
    out.retain(|_, s| *s > 0.0);
    out
}

/// An angle wrapped into (-π, π].
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI { w - std::f64::consts::TAU } else { w }
}
