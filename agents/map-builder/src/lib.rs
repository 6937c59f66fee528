//! The map builder of robot 1 (thesis section 4.3.2.2, Fig. 4-8) as a
//! library: it records the checkpoints and the target as the robot meets
//! them, marks a via point in front of each, orders them into a path for
//! robot 2, and remembers where the robot has been.
//!
//! **Landmarks** ([`MapBuilder::on_sighting`]). A sighting with an IR code
//! is the checkpoint of that code; the target (the tube upside down) is
//! matched by position (within `merge_m`). Positions are averaged over the
//! sightings (a known checkpoint's is its known position anyway). A
//! landmark counts once it was seen `min_sightings` times, so that a single
//! misread frame does not enter the map.
//!
//! **Via points** ("Step 2: mark via points between the robot and
//! checkpoints (or the final target), 1.6 m from them"). In front of a
//! checkpoint means along the direction the IR transmitter seen faces; a
//! checkpoint passed by is seen by several transmitters in turn, and the
//! one received most often wins. The target's transmitters are not known in
//! advance, so its via point lies toward where the robot saw it from (the
//! circular mean of those directions).
//!
//! **The path** ([`MapBuilder::path`]; "Step 3: connect via points and
//! target point according to the sequence of their relative location").
//! The via points in the order robot 1 first saw their landmarks — an order
//! robot 1 has driven, so free of walls — then the target's via point and
//! the target itself, each with the position of its landmark (for the
//! follower to look at). A via point that is a detour (going through it is
//! more than `detour_factor` times longer than going past it) is left out.
//!
//! **Robot 1's own way to the target** ([`MapBuilder::on_pose`]). From the
//! last checkpoint's via point to the target, a straight line may cut a
//! corner (the target stands in an open space beside the corridor, behind
//! an opening). So the map builder keeps robot 1's trail (a point every
//! `TRAIL_STEP_M`) and, between the last checkpoint's via point and the
//! target, puts in the way robot 1 drove up to where it found the target —
//! simplified (Douglas–Peucker, `TRAIL_TOLERANCE_M`) into `waypoint`s. The
//! target's via point then lies on the line from there to the target: robot
//! 2 comes the way robot 1 came. A target counts only when seen within
//! `target_range_m` (0: at any range), so robot 1 has come near it — into
//! the space where it stands. And the path is ready only once robot 1 has
//! driven `clear_m` on from where it found the target and stands at least
//! [`KEEP_OFF_M`] from every leg of the path ([`MapBuilder::path`] says
//! `None` until then; with `clear_m` = 0 neither is asked), so that robot 1,
//! which waits where it then stops, is not in robot 2's way.
//!
//! **Where the robot has been** ([`VisitedGrid`], module [`grid`]): a
//! coarse grid of cells with the times the robot entered and left them.
//! [`VisitedGrid::visited_before`] says whether a place was passed before
//! (left at least `revisit_after` ago and now reached again — the robot is
//! going round in circles), [`VisitedGrid::visited_ahead`] how much of what
//! lies ahead in a direction was visited, for exploration that prefers new
//! space. [`VisitedGrid::write_map`] lays the grid out as the map the agent
//! publishes (`map`: `nerve::MapCells`, any count of cells).
//!
//! **Paths over the cells seen** ([`plan::plan`], module [`plan`]): from
//! the robot's cell to a goal's, A* over the cells the robot has been in
//! (8-connected), simplified to way points whose legs stay on seen cells;
//! the agent's `plan` service answers with it (`nerve::PlannedPath`).

#![cfg_attr(test, allow(clippy::unwrap_used))]

pub mod grid;
pub mod plan;

pub use grid::{Cell, VisitedGrid};
pub use shm_schemas::geom::{Pose, wrap_angle};
use shm_schemas::payloads::{CheckpointSighting, ViaKind, ViaPathBuf, ViaPoint};
use std::f64::consts::FRAC_PI_2;

/// Settings (the agent's parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Distance of a via point in front of its landmark, metres (the thesis: 1.6).
    pub via_distance_m: f64,
    /// Target sightings closer than this are the same target, metres.
    pub merge_m: f64,
    /// Sightings before a landmark counts.
    pub min_sightings: u32,
    /// A via point is left out when the path through it is longer than
    /// this times the path past it (0: never).
    pub detour_factor: f64,
    /// A target sighting counts only within this range, metres (0: any).
    pub target_range_m: f64,
    /// Robot 1 drives this far on after finding the target before the path
    /// is ready, metres (0: at once).
    pub clear_m: f64,
}

/// With `clear_m` > 0, the path is ready only while robot 1 stands this far
/// from every leg of it, metres (the two robots' radii, 0.47 m, with room
/// for the few decimetres robot 1 needs to stop).
pub const KEEP_OFF_M: f64 = 0.9;

/// Robot 1 drove past a via point when its trail came this near it, metres.
pub const PASSED_VIA_M: f64 = 1.0;

/// Robot 1's trail keeps a point every this many metres.
pub const TRAIL_STEP_M: f64 = 0.25;
/// The trail is simplified to within this many metres.
pub const TRAIL_TOLERANCE_M: f64 = 0.2;
/// The trail keeps at most this many points (then every other one is dropped).
pub const TRAIL_MAX_POINTS: usize = 8192;

impl Default for Settings {
    fn default() -> Self {
        Settings {
            via_distance_m: 1.6,
            merge_m: 1.0,
            min_sightings: 3,
            detour_factor: 2.0,
            target_range_m: 0.0,
            clear_m: 0.0,
        }
    }
}

/// A recorded landmark.
#[derive(Debug, Clone, PartialEq)]
pub struct Landmark {
    /// IR code, 0 when not known.
    pub id: u8,
    /// The target (upside down).
    pub is_target: bool,
    /// Mean position, metres, world frame.
    pub x: f64,
    /// Mean position, metres.
    pub y: f64,
    /// Sightings so far.
    pub sightings: u32,
    /// Order of first sighting (0 first).
    pub order: u32,
    /// Sightings per transmitter direction (bit i), with the direction it faces.
    transmitter_votes: [(u32, f64); 4],
    /// Sum of unit vectors toward where the robot saw it from (no transmitter known).
    seen_from: (f64, f64),
}

impl Landmark {
    /// The direction "in front of" the landmark, radians, world frame.
    pub fn facing(&self) -> f64 {
        let from = self.seen_from.1.atan2(self.seen_from.0);
        let has_from = self.seen_from.0.hypot(self.seen_from.1) > 1e-9;
        // most votes; a tie goes to the direction nearer where the robot saw it from
        let off = |dir: f64| if has_from { wrap_angle(dir - from).abs() } else { 0.0 };
        let best = self
            .transmitter_votes
            .iter()
            .filter(|(n, _)| *n > 0)
            .max_by(|a, b| a.0.cmp(&b.0).then_with(|| off(b.1).total_cmp(&off(a.1))));
        match best {
            Some((_, dir)) => *dir,
            None => from,
        }
    }

    /// Its via point: `distance` in front of it.
    pub fn via_point(&self, distance: f64) -> (f64, f64) {
        let f = self.facing();
        (self.x + distance * f.cos(), self.y + distance * f.sin())
    }
}

/// What a sighting did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SightingEvent {
    /// Ignored (nonsense values, or no id and not the target).
    Ignored,
    /// A landmark seen for the first time (not counted yet).
    New,
    /// A known landmark seen again.
    Again,
    /// A landmark just reached `min_sightings`: it now counts.
    Confirmed {
        /// Its IR code.
        id: u8,
        /// Whether it is the target.
        is_target: bool,
    },
}

/// The recorded landmarks and the path between them.
#[derive(Debug, Clone, Default)]
pub struct MapBuilder {
    settings: Settings,
    landmarks: Vec<Landmark>,
    trail: Vec<[f64; 2]>,
    /// Length of the trail when the target was confirmed.
    found_at: Option<usize>,
}

/// Which transmitter directions a sighting reports: bit `i` faces
/// `facing − (sector − i)·90°`, `sector` being the mean of the bits set
/// (the sighting's `facing_rad` is the direction of that mean).
fn transmitter_directions(transmitters: u8, facing: f64) -> Vec<(usize, f64)> {
    let m = transmitters & 0x0F;
    let bits: Vec<usize> = (0..4).filter(|i| m & (1 << i) != 0).collect();
    let sector = match bits.as_slice() {
        [a] => *a as f64,
        [0, 3] => -0.5, // between 3 (= -1) and 0
        [a, b] if b - a == 1 => *a as f64 + 0.5,
        _ => return Vec::new(),
    };
    bits.iter()
        .map(|&i| {
            let i_f = if sector < 0.0 && i == 3 { -1.0 } else { i as f64 };
            (i, facing - (sector - i_f) * FRAC_PI_2)
        })
        .collect()
}

impl MapBuilder {
    /// An empty map.
    pub fn new(settings: Settings) -> Self {
        MapBuilder { settings, landmarks: Vec::new(), trail: Vec::new(), found_at: None }
    }

    /// Robot 1 is at `(x, y)`: extends its trail.
    pub fn on_pose(&mut self, x: f64, y: f64) {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        if self.trail.last().is_some_and(|l| (l[0] - x).hypot(l[1] - y) < TRAIL_STEP_M) {
            return;
        }
        if self.trail.len() >= TRAIL_MAX_POINTS {
            // thin out: every other point (landmarks' marks are halved with it)
            let mut k = 0;
            self.trail.retain(|_| {
                k += 1;
                k % 2 == 1
            });
            self.found_at = self.found_at.map(|f| f / 2);
        }
        self.trail.push([x, y]);
    }

    /// Robot 1's trail so far.
    pub fn trail(&self) -> &[[f64; 2]] {
        &self.trail
    }

    /// Changes the settings.
    pub fn set_settings(&mut self, s: Settings) {
        self.settings = s;
    }

    /// The landmarks, counted or not, in the order first seen.
    pub fn landmarks(&self) -> &[Landmark] {
        &self.landmarks
    }

    /// The landmarks that count (seen `min_sightings` times).
    pub fn confirmed(&self) -> impl Iterator<Item = &Landmark> {
        self.landmarks.iter().filter(|l| l.sightings >= self.settings.min_sightings.max(1))
    }

    /// The confirmed target, if any.
    pub fn target(&self) -> Option<&Landmark> {
        self.confirmed().find(|l| l.is_target)
    }

    /// Records a sighting; `robot` is where the robot was (for the
    /// direction it saw the landmark from when no transmitter says it).
    pub fn on_sighting(&mut self, s: &CheckpointSighting, robot: Option<Pose>) -> SightingEvent {
        let finite = s.x.is_finite() && s.y.is_finite() && s.facing_rad.is_finite();
        let is_target = s.is_target == 1;
        if !finite || (s.checkpoint_id == 0 && !is_target) {
            return SightingEvent::Ignored;
        }
        let far = !(s.range_m.is_finite() && f64::from(s.range_m) <= self.settings.target_range_m);
        if is_target && self.settings.target_range_m > 0.0 && far {
            return SightingEvent::Ignored;
        }
        let merge = self.settings.merge_m;
        let idx = self.landmarks.iter().position(|l| {
            l.is_target == is_target
                && if s.checkpoint_id != 0 && l.id != 0 {
                    l.id == s.checkpoint_id
                } else {
                    (l.x - s.x).hypot(l.y - s.y) <= merge
                }
        });
        let (idx, event) = match idx {
            Some(i) => (i, SightingEvent::Again),
            None => {
                let order = self.landmarks.len() as u32;
                self.landmarks.push(Landmark {
                    id: s.checkpoint_id,
                    is_target,
                    x: s.x,
                    y: s.y,
                    sightings: 0,
                    order,
                    transmitter_votes: [(0, 0.0); 4],
                    seen_from: (0.0, 0.0),
                });
                (self.landmarks.len() - 1, SightingEvent::New)
            }
        };
        let min = self.settings.min_sightings.max(1);
        let l = &mut self.landmarks[idx];
        let n = f64::from(l.sightings);
        l.x = (l.x * n + s.x) / (n + 1.0);
        l.y = (l.y * n + s.y) / (n + 1.0);
        l.sightings = l.sightings.saturating_add(1);
        if l.id == 0 {
            l.id = s.checkpoint_id;
        }
        let dirs = if s.from_ir == 1 && !is_target {
            transmitter_directions(s.transmitters, f64::from(s.facing_rad))
        } else {
            vec![]
        };
        for (i, dir) in &dirs {
            l.transmitter_votes[*i].0 += 1;
            l.transmitter_votes[*i].1 = *dir;
        }
        // where the robot saw it from
        let from = match robot {
            Some(r) => (r.x - l.x, r.y - l.y),
            None => (f64::from(s.facing_rad).cos(), f64::from(s.facing_rad).sin()),
        };
        let norm = from.0.hypot(from.1);
        if norm > 1e-9 {
            l.seen_from.0 += from.0 / norm;
            l.seen_from.1 += from.1 / norm;
        }
        if l.sightings == min {
            if l.is_target && self.found_at.is_none() {
                self.found_at = Some(self.trail.len());
            }
            return SightingEvent::Confirmed { id: l.id, is_target: l.is_target };
        }
        event
    }

    /// The path for robot 2: via points of the confirmed checkpoints in the
    /// order first seen (detours left out), then the target's via point and
    /// the target. `None` until a target is confirmed and robot 1 has
    /// driven `clear_m` on from where it was then.
    pub fn path(&self, path_id: u32, stamp_ns: u64) -> Option<ViaPathBuf> {
        let target = self.target()?;
        let from = self.found_at.unwrap_or(0).saturating_sub(1).min(self.trail.len());
        let driven: f64 = self.trail[from..].windows(2).map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1])).sum();
        if driven < self.settings.clear_m {
            return None;
        }
        let dist = self.settings.via_distance_m;
        let mut pts: Vec<([f64; 2], ViaKind, u8, [f64; 2])> = self
            .confirmed()
            .filter(|l| !l.is_target)
            .map(|l| {
                let v = l.via_point(dist);
                ([v.0, v.1], ViaKind::Checkpoint, l.id, [l.x, l.y])
            })
            .collect();
        let t = [target.x, target.y];
        for w in self.way_to_target(t) {
            pts.push((w, ViaKind::Waypoint, 0, w));
        }
        // the target's via point: toward where robot 2 comes from when the
        // path has robot 1's way in it, else in front of the target
        let tv = match pts.last().copied() {
            Some((w, ViaKind::Waypoint, _, _)) => {
                let (dx, dy) = (w[0] - t[0], w[1] - t[1]);
                let n = dx.hypot(dy);
                // on the line from the last waypoint, at most 70 % of the way
                let k = dist.min(0.7 * n) / n;
                if n - k * n < 0.3 {
                    pts.pop(); // the waypoint is (about) the via point
                }
                (t[0] + k * dx, t[1] + k * dy)
            }
            _ => target.via_point(dist),
        };
        pts.push(([tv.0, tv.1], ViaKind::TargetApproach, target.id, t));
        pts.push((t, ViaKind::Target, target.id, t));
        // leave out detours (never the last two, never robot 1's own way)
        if self.settings.detour_factor > 0.0 {
            let mut i = 1;
            while i + 2 < pts.len() {
                if pts[i].1 == ViaKind::Waypoint {
                    i += 1;
                    continue;
                }
                let (a, b, c) = (pts[i - 1].0, pts[i].0, pts[i + 1].0);
                let d = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
                if d(a, b) + d(b, c) > self.settings.detour_factor * d(a, c).max(1e-6) {
                    pts.remove(i);
                } else {
                    i += 1;
                }
            }
        }
        // robot 1 must not stand in robot 2's way
        if let (true, Some(at)) = (self.settings.clear_m > 0.0, self.trail.last()) {
            let near = pts.iter().map(|p| p.0).collect::<Vec<_>>().windows(2).any(|leg| {
                let (a, b) = (leg[0], leg[1]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let len2 = (dx * dx + dy * dy).max(1e-12);
                let t = (((at[0] - a[0]) * dx + (at[1] - a[1]) * dy) / len2).clamp(0.0, 1.0);
                (a[0] + t * dx - at[0]).hypot(a[1] + t * dy - at[1]) < KEEP_OFF_M
            });
            if near {
                return None;
            }
        }
        let mut path = ViaPathBuf::new(path_id, stamp_ns);
        path.points = pts.iter().map(|&(p, kind, id, landmark)| ViaPoint::new(p, kind, id, landmark)).collect();
        Some(path)
    }
}

impl MapBuilder {
    /// Robot 1's way from the last checkpoint's via point it drove past
    /// (within [`PASSED_VIA_M`]) before it found the target, to where it found
    /// it, simplified; empty without such a via point.
    fn way_to_target(&self, target: [f64; 2]) -> Vec<[f64; 2]> {
        let end = self.found_at.unwrap_or(self.trail.len()).min(self.trail.len());
        let trail = &self.trail[..end];
        let d = |p: &[f64; 2], q: (f64, f64)| (p[0] - q.0).hypot(p[1] - q.1);
        let dist = self.settings.via_distance_m;
        // the latest trail point near a confirmed checkpoint's via point
        let passed = self
            .confirmed()
            .filter(|l| !l.is_target)
            .filter_map(|l| {
                let via = l.via_point(dist);
                trail.iter().rposition(|p| d(p, via) <= PASSED_VIA_M).map(|i| (i, via))
            })
            .max_by_key(|(i, _)| *i);
        let Some((start, via)) = passed else { return Vec::new() };
        let mut out = simplify(&trail[start..], TRAIL_TOLERANCE_M);
        // the first point is (about) the via point itself
        out.retain(|p| d(p, via) > 0.5 && d(p, (target[0], target[1])) > 0.8);
        out
    }
}

/// Douglas–Peucker simplification of a polyline to within `tol` metres
/// (the first and last points are kept).
pub fn simplify(pts: &[[f64; 2]], tol: f64) -> Vec<[f64; 2]> {
    if pts.len() <= 2 {
        return pts.to_vec();
    }
    let mut keep = vec![false; pts.len()];
    keep[0] = true;
    keep[pts.len() - 1] = true;
    let mut stack = vec![(0usize, pts.len() - 1)];
    while let Some((a, b)) = stack.pop() {
        let (pa, pb) = (pts[a], pts[b]);
        let (dx, dy) = (pb[0] - pa[0], pb[1] - pa[1]);
        let len = dx.hypot(dy);
        let dist = |p: &[f64; 2]| {
            if len < 1e-12 {
                (p[0] - pa[0]).hypot(p[1] - pa[1])
            } else {
                ((p[0] - pa[0]) * dy - (p[1] - pa[1]) * dx).abs() / len
            }
        };
        let far = (a + 1..b).map(|i| (i, dist(&pts[i]))).max_by(|x, y| x.1.total_cmp(&y.1));
        if let Some((i, dmax)) = far
            && dmax > tol
        {
            keep[i] = true;
            stack.push((a, i));
            stack.push((i, b));
        }
    }
    pts.iter().zip(keep).filter(|(_, k)| *k).map(|(p, _)| *p).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    /// A sighting of checkpoint `id` at `(x, y)` whose transmitter 0 faces
    /// −90°, received through transmitter mask `tx`.
    fn cp(id: u8, x: f64, y: f64, tx: u8) -> CheckpointSighting {
        let sector = match tx {
            0b0001 => 0.0,
            0b0011 => 0.5,
            0b0010 => 1.0,
            0b1001 => -0.5,
            0b1000 => 3.0,
            _ => 0.0,
        };
        CheckpointSighting {
            x,
            y,
            checkpoint_id: id,
            transmitters: tx,
            from_ir: 1,
            from_camera: 1,
            facing_rad: wrap_angle(-FRAC_PI_2 + sector * FRAC_PI_2) as f32,
            ..Default::default()
        }
    }

    fn target(x: f64, y: f64) -> CheckpointSighting {
        CheckpointSighting { x, y, is_target: 1, from_camera: 1, ..Default::default() }
    }

    /// The cooperation world: robot 1 follows the corridor's right wall
    /// (y = -0.4) past checkpoint 3 at (10.8, 1.2), turns right through the
    /// opening at x = 11.6 … 14.8 and down the open space's west side
    /// (x = 12.2), sees the target at (12.8, -3) within 2 m from (12.2, -1.4)
    /// and drives 2.5 m on before it stops.
    #[test]
    fn robot_1s_way_round_the_corner_enters_the_path() {
        let mut m =
            MapBuilder::new(Settings { min_sightings: 1, target_range_m: 2.0, clear_m: 2.5, ..Settings::default() });
        let mut x = 8.0;
        while x < 12.2 {
            m.on_pose(x, -0.4 - 0.6 * ((x - 11.6).max(0.0) / 0.6).min(1.0) * 0.5);
            if (x - 10.0).abs() < 0.01 {
                assert!(matches!(m.on_sighting(&cp(3, 10.8, 1.2, 0b0001), None), SightingEvent::Confirmed { .. }));
            }
            if (x - 11.5).abs() < 0.01 {
                // checkpoint 4, seen from afar and never passed: not where robot 1's way starts
                m.on_sighting(&cp(4, 15.6, 1.2, 0b0011), None);
            }
            x += 0.05;
        }
        let mut y = -0.7;
        // seen from afar first: not counted
        let mut far = target(12.8, -3.0);
        far.range_m = 2.9;
        assert_eq!(m.on_sighting(&far, Some(Pose { x: 12.0, y: -0.4, theta: 0.0 })), SightingEvent::Ignored);
        while y > -1.4 {
            m.on_pose(12.2, y);
            y -= 0.05;
        }
        let mut near = target(12.8, -3.0);
        near.range_m = 1.7;
        m.on_sighting(&near, Some(Pose { x: 12.2, y: -1.4, theta: -FRAC_PI_2 }));
        assert!(m.path(1, 0).is_none(), "robot 1 has not cleared the way yet");
        while y > -4.0 {
            m.on_pose(12.2, y);
            y -= 0.05;
        }
        // robot 1 drove on but came back into the opening: still in the way
        m.on_pose(12.2, -3.7);
        m.on_pose(12.2, -3.4);
        m.on_pose(12.2, -3.1);
        assert!(m.path(1, 0).is_none(), "robot 1 stands 0.6 m from the last leg");
        m.on_pose(12.2, -3.4);
        m.on_pose(12.2, -3.7);
        m.on_pose(12.2, -4.0);
        m.on_pose(13.8, -4.0);
        let p = m.path(1, 0).expect("a path once robot 1 drove on, off the path");
        let kinds: Vec<ViaKind> = p.entries().map(|(_, k, _)| ViaKind::from_code(k).unwrap()).collect();
        let pts: Vec<[f64; 2]> = p.entries().map(|(p, _, _)| p).collect();
        assert_eq!(kinds.first(), Some(&ViaKind::Checkpoint));
        assert_eq!(&kinds[kinds.len() - 2..], &[ViaKind::TargetApproach, ViaKind::Target]);
        assert!(kinds.contains(&ViaKind::Waypoint), "robot 1's turn through the opening is in the path: {pts:?}");
        // the corner is passed the way robot 1 went: no leg passes within
        // 0.4 m of the opening's west corner (11.6, -1), and none within
        // KEEP_OFF_M of robot 1, waiting at (13.8, -4)
        let dist_to = |a: [f64; 2], b: [f64; 2], q: [f64; 2]| {
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let t = (((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
            (a[0] + t * dx - q[0]).hypot(a[1] + t * dy - q[1])
        };
        let legs: Vec<_> = pts.windows(2).collect();
        for leg in &legs {
            let d = dist_to(leg[0], leg[1], [11.6, -1.0]);
            assert!(d > 0.4, "leg {leg:?} passes {d:.2} m from the corner: {pts:?}");
        }
        for leg in &legs {
            let d = dist_to(leg[0], leg[1], [13.8, -4.0]);
            assert!(d > KEEP_OFF_M, "leg {leg:?} passes {d:.2} m from robot 1: {pts:?}");
        }
        let approach = pts[pts.len() - 2];
        assert!((approach[0] - 12.8).hypot(approach[1] + 3.0) <= 1.6 + 1e-9, "{approach:?}");
    }

    #[test]
    fn the_trail_is_simplified_and_bounded() {
        let line: Vec<[f64; 2]> = (0..100).map(|i| [f64::from(i) * 0.1, 0.0]).collect();
        assert_eq!(simplify(&line, 0.2), vec![[0.0, 0.0], [9.9, 0.0]]);
        let corner = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, -1.0], [2.0, -2.0]];
        assert_eq!(simplify(&corner, 0.2), vec![[0.0, 0.0], [2.0, 0.0], [2.0, -2.0]]);
        let mut m = MapBuilder::new(Settings::default());
        for i in 0..(TRAIL_MAX_POINTS + 10) {
            m.on_pose(i as f64, 0.0);
        }
        assert!(m.trail().len() <= TRAIL_MAX_POINTS);
        m.on_pose(f64::NAN, 0.0);
        assert!(m.trail().iter().all(|p| p[0].is_finite()));
    }

    #[test]
    fn transmitter_directions_from_the_cone_centre() {
        let d = transmitter_directions(0b0011, 0.25 * PI);
        assert_eq!(d.len(), 2);
        assert!(close(d[0].1, 0.0, 1e-12) && close(d[1].1, FRAC_PI_2, 1e-12), "{d:?}");
        let d = transmitter_directions(0b1001, -0.25 * PI);
        assert!(close(d[0].1, 0.0, 1e-12) && close(wrap_angle(d[1].1), -FRAC_PI_2, 1e-12), "{d:?}");
        assert!(transmitter_directions(0b0101, 0.0).is_empty());
    }

    #[test]
    fn a_tie_of_transmitters_goes_to_the_side_the_robot_saw_it_from() {
        // robot 1 at its start, south-west of checkpoint 1: transmitters 0
        // (south) and 3 (west) both reach it, as often; it is a little more
        // south than west, and drives on east
        let mut m = MapBuilder::new(Settings { min_sightings: 1, ..Settings::default() });
        for x in [0.0, 0.1, 0.2] {
            m.on_sighting(&cp(1, 1.2, 1.2, 0b1001), Some(Pose { x, y: 0.0, theta: 0.0 }));
        }
        let (vx, vy) = m.landmarks()[0].via_point(1.6);
        assert!(close(vx, 1.2, 1e-6) && close(vy, -0.4, 1e-6), "({vx}, {vy}): in front of it, not beside it");
    }

    #[test]
    fn the_corridor_of_the_thesis_gives_its_path() {
        let mut m = MapBuilder::new(Settings::default());
        let robot = |x: f64| Some(Pose { x, y: 0.0, theta: 0.0 });
        // robot 1 drives along y = 0 and passes the checkpoints: transmitters 3+0, then 0
        for (id, x) in [(1u8, 1.2), (2, 6.0), (3, 10.8)] {
            assert_eq!(m.on_sighting(&cp(id, x, 1.2, 0b1001), robot(x - 1.2)), SightingEvent::New);
            for _ in 0..4 {
                m.on_sighting(&cp(id, x, 1.2, 0b0001), robot(x));
            }
        }
        assert!(m.path(1, 0).is_none(), "no target yet");
        // a misread id-less upright tube is ignored
        assert_eq!(m.on_sighting(&CheckpointSighting::default(), robot(11.0)), SightingEvent::Ignored);
        // the target, seen from the north (robot at (12.8, -1.2)), position a little noisy
        let r2 = Some(Pose { x: 12.8, y: -1.2, theta: -FRAC_PI_2 });
        let mut confirmed = false;
        for k in 0..5 {
            let e = m.on_sighting(&target(12.8 + 0.02 * (k as f64 - 2.0), -3.0), r2);
            confirmed |= e == SightingEvent::Confirmed { id: 0, is_target: true };
        }
        assert!(confirmed);
        let p = m.path(7, 42).unwrap();
        assert_eq!((p.path_id(), p.header.stamp_ns, p.points.len()), (7, 42, 5));
        assert_eq!(p.points[1].landmark, [6.0, 1.2]);
        assert!((p.points[3].landmark[1] + 3.0).abs() < 0.03, "the target approach looks at the target");
        let e: Vec<_> = p.entries().collect();
        let want = [
            ([1.2, -0.4], 1, 1),
            ([6.0, -0.4], 1, 2),
            ([10.8, -0.4], 1, 3),
            ([12.8, -1.4], 2, 0),
            ([12.8, -3.0], 3, 0),
        ];
        for (got, want) in e.iter().zip(want) {
            // the target's position and the direction it was seen from are means of noisy sightings
            assert!(close(got.0[0], want.0[0], 0.03) && close(got.0[1], want.0[1], 0.03), "{got:?} vs {want:?}");
            assert_eq!((got.1, got.2), (want.1, want.2));
        }
    }

    #[test]
    fn a_checkpoint_behind_the_target_is_a_detour_left_out() {
        let mut m = MapBuilder::new(Settings { min_sightings: 1, ..Settings::default() });
        for (id, x) in [(1u8, 1.2), (2, 6.0), (3, 10.8), (4, 15.6)] {
            m.on_sighting(&cp(id, x, 1.2, 0b0001), None);
        }
        m.on_sighting(&target(12.8, -3.0), Some(Pose { x: 12.8, y: -1.2, theta: 0.0 }));
        let p = m.path(1, 0).unwrap();
        let ids: Vec<u8> = p.entries().map(|e| e.2).collect();
        assert_eq!(ids, vec![1, 2, 3, 0, 0], "checkpoint 4 lies past the target's turn");
        // with detours allowed it stays
        m.set_settings(Settings { min_sightings: 1, detour_factor: 0.0, ..Settings::default() });
        assert_eq!(m.path(1, 0).unwrap().points.len(), 6);
    }

    #[test]
    fn unconfirmed_landmarks_do_not_count_and_nonsense_is_ignored() {
        let mut m = MapBuilder::new(Settings::default());
        m.on_sighting(&target(3.0, 3.0), None);
        m.on_sighting(&target(9.0, 9.0), None);
        assert_eq!(m.landmarks().len(), 2, "far apart: two targets");
        assert!(m.target().is_none());
        let bad = CheckpointSighting { x: f64::NAN, ..cp(1, 0.0, 0.0, 1) };
        assert_eq!(m.on_sighting(&bad, None), SightingEvent::Ignored);
    }
}
