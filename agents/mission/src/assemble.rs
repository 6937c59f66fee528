//! Robot 2's path from robot 1's `plan` call (issue 42): the explorer asks
//! its map builder's `plan` service for a path from robot 1 (standing by
//! the target, where it stopped) to where robot 2 is, and [`from_plan`]
//! turns the answer round into robot 2's path to the target.
//!
//! 1. **Reversed.** `plan` answers from robot 1's pose to the goal; robot 2
//!    needs the way from itself: the way points in reverse order, all of
//!    kind `waypoint`. Their legs cross only cells robot 1 drove through.
//! 2. **Cut where it meets the target's approach.** Robot 1 stopped past the
//!    target (it drove `clear_m` on, out of robot 2's way), so the way ends
//!    beyond the target. It is cut at its point nearest the first point of
//!    the map builder's ending (the `target-approach` point, else the
//!    target): robot 2 leaves the planned way there, and what lies on to
//!    robot 1 is dropped.
//! 3. **Ended as the map builder ends its path.** The map builder's
//!    trailing `target-approach` and `target` points follow unchanged (the
//!    target achiever grasps at a path's `target`).
//! 4. **The checkpoints robot 2 passes stay checkpoints.** Robot 2's
//!    checkpoint agent corrects its pose at them, and the target achiever
//!    turns its head to a `checkpoint` point's landmark as it passes (thesis
//!    ch. 4: robot 2 localises by the checkpoints on its way). Each
//!    confirmed checkpoint's via point within [`CHECKPOINT_NEAR_M`] of the
//!    cut way is put in where it lies along it, as a `checkpoint` point with
//!    its id and landmark; one farther off is not on robot 2's way and is
//!    left out.

use shm_schemas::payloads::{ViaKind, ViaPathBuf, ViaPoint};

/// A checkpoint's via point this near the planned way is on robot 2's way, metres.
pub const CHECKPOINT_NEAR_M: f64 = 1.0;
/// Points closer than this are one point, metres.
pub const SAME_POINT_M: f64 = 0.3;

/// Why no path could be made from a plan.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AssembleError {
    /// The plan's answer holds no way point.
    #[error("the plan has no way point; ask again, or check the map builder's `plan` with `nerve call`")]
    EmptyPlan,
    /// A way point is not finite.
    #[error("the plan's way point {0} is not finite; the map builder's answer is broken")]
    NotFinite(usize),
    /// The map builder's path has no point to end robot 2's path with.
    #[error("the map builder's path {0} has no point; it cannot end robot 2's path")]
    NoEnding(u32),
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The point of leg `a`–`b` nearest `q`, and its fraction along the leg.
fn project(a: [f64; 2], b: [f64; 2], q: [f64; 2]) -> ([f64; 2], f64) {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    if len2 < 1e-18 {
        return (a, 0.0);
    }
    let t = (((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / len2).clamp(0.0, 1.0);
    ([a[0] + t * dx, a[1] + t * dy], t)
}

/// Where `q` meets polyline `way`: (leg index, point on it, distance
/// along the way to it, distance from `q`); the first of equally near.
fn nearest_on(way: &[[f64; 2]], q: [f64; 2]) -> (usize, [f64; 2], f64, f64) {
    let mut best = (0, way[0], 0.0, dist(way[0], q));
    let mut along = 0.0;
    for (i, leg) in way.windows(2).enumerate() {
        let (p, t) = project(leg[0], leg[1], q);
        let d = dist(p, q);
        let len = dist(leg[0], leg[1]);
        if d < best.3 - 1e-9 {
            best = (i, p, along + t * len, d);
        }
        along += len;
    }
    best
}

/// The trailing points of `landmarks` that end a path: its
/// `target-approach` and `target` points at the end, else its last point.
pub fn ending(landmarks: &ViaPathBuf) -> Vec<ViaPoint> {
    let is_end = |p: &ViaPoint| matches!(ViaKind::from_code(p.kind), Some(ViaKind::TargetApproach | ViaKind::Target));
    let n = landmarks.points.iter().rev().take_while(|p| is_end(p)).count();
    let from = if n == 0 { landmarks.points.len().saturating_sub(1) } else { landmarks.points.len() - n };
    landmarks.points[from..].to_vec()
}

/// Robot 2's path (id and stamp of `landmarks`, the map builder's path)
/// from `plan`, the way points `plan` answered from robot 1 to robot 2; see
/// the module documentation.
pub fn from_plan(landmarks: &ViaPathBuf, plan: &[[f64; 2]]) -> Result<ViaPathBuf, AssembleError> {
    if plan.is_empty() {
        return Err(AssembleError::EmptyPlan);
    }
    if let Some(i) = plan.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(AssembleError::NotFinite(i));
    }
    let end = ending(landmarks);
    let Some(first_end) = end.first() else { return Err(AssembleError::NoEnding(landmarks.path_id())) };
    let mut way: Vec<[f64; 2]> = plan.iter().rev().copied().collect();
    // cut where the way comes nearest the approach
    let (leg, cut, _, _) = nearest_on(&way, first_end.point);
    way.truncate(leg + 1);
    if way.last().is_none_or(|l| dist(*l, cut) > SAME_POINT_M) {
        way.push(cut);
    }
    // a way point on the approach itself is the approach
    if way.len() > 1 && way.last().is_some_and(|l| dist(*l, first_end.point) <= SAME_POINT_M) {
        way.pop();
    }
    // the checkpoints on the way, by where they lie along it
    let mut along: Vec<(f64, ViaPoint)> = Vec::with_capacity(way.len());
    let mut s = 0.0;
    for (i, p) in way.iter().enumerate() {
        if i > 0 {
            s += dist(way[i - 1], *p);
        }
        along.push((s, ViaPoint::new(*p, ViaKind::Waypoint, 0, *p)));
    }
    for c in landmarks.points.iter().filter(|p| ViaKind::from_code(p.kind) == Some(ViaKind::Checkpoint)) {
        let (_, _, at, d) = nearest_on(&way, c.point);
        if d <= CHECKPOINT_NEAR_M {
            along.push((at, *c));
        }
    }
    // stable: a checkpoint after the way point it coincides with
    along.sort_by(|a, b| a.0.total_cmp(&b.0));
    // a way point on a checkpoint's via point is that checkpoint
    let mut points: Vec<ViaPoint> = Vec::with_capacity(along.len() + end.len());
    for (_, p) in along {
        let checkpoint = ViaKind::from_code(p.kind) == Some(ViaKind::Checkpoint);
        match points.last() {
            Some(l) if checkpoint && l.kind == ViaKind::Waypoint as u8 && dist(l.point, p.point) <= SAME_POINT_M => {
                points.pop();
            }
            Some(l) if !checkpoint && dist(l.point, p.point) <= SAME_POINT_M => continue,
            _ => {}
        }
        points.push(p);
    }
    points.extend(end);
    let mut out = ViaPathBuf::new(landmarks.path_id(), landmarks.header.stamp_ns);
    out.points = points;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn landmarks(pts: &[([f64; 2], ViaKind, u8)]) -> ViaPathBuf {
        let mut p = ViaPathBuf::new(3, 9);
        p.points = pts.iter().map(|&(xy, k, id)| ViaPoint::new(xy, k, id, [xy[0], xy[1] + 1.6])).collect();
        p
    }

    fn kinds(p: &ViaPathBuf) -> Vec<(f64, f64, &'static str)> {
        p.entries()
            .map(|(xy, k, _)| {
                let r = |v: f64| (v * 100.0).round() / 100.0;
                (r(xy[0]), r(xy[1]), ViaKind::from_code(k).map_or("?", |k| k.name()))
            })
            .collect()
    }

    /// The cooperation corridor: robot 2 at (-4, 0), checkpoints' via
    /// points along y = -0.4, the opening at x ≈ 12, the target at
    /// (12.8, -3), robot 1 waiting at (12.2, -4.2), past it.
    #[test]
    fn the_plan_is_turned_round_cut_at_the_approach_and_keeps_the_checkpoints() {
        let lm = landmarks(&[
            ([1.2, -0.4], ViaKind::Checkpoint, 1),
            ([6.0, -0.4], ViaKind::Checkpoint, 2),
            ([10.8, -0.4], ViaKind::Checkpoint, 3),
            ([15.6, -0.4], ViaKind::Checkpoint, 4), // seen from afar, never on the way
            ([12.2, -1.6], ViaKind::Waypoint, 0),   // robot 1's own way: not used
            ([12.3, -1.6], ViaKind::TargetApproach, 0),
            ([12.8, -3.0], ViaKind::Target, 0),
        ]);
        // robot 1 to robot 2's snapped cell: up the open space, round the corner, along the corridor
        let plan = [[12.2, -4.2], [12.2, -1.2], [11.2, -0.3], [0.25, -0.25]];
        let p = from_plan(&lm, &plan).expect("a path");
        assert_eq!((p.path_id(), p.header.stamp_ns), (3, 9));
        assert_eq!(
            kinds(&p),
            [
                (0.25, -0.25, "waypoint"),
                (1.2, -0.4, "checkpoint"),
                (6.0, -0.4, "checkpoint"),
                (10.8, -0.4, "checkpoint"),
                (11.2, -0.3, "waypoint"),
                (12.2, -1.2, "waypoint"),
                (12.3, -1.6, "target-approach"),
                (12.8, -3.0, "target"),
            ],
            "robot 1's stretch past the approach is cut: {:?}",
            kinds(&p)
        );
        let cps: Vec<u8> = p.entries().filter(|e| e.1 == ViaKind::Checkpoint as u8).map(|e| e.2).collect();
        assert_eq!(cps, [1, 2, 3]);
        assert_eq!(p.points[1].landmark, lm.points[0].landmark, "a checkpoint keeps its landmark");
    }

    #[test]
    fn a_way_point_on_the_approach_or_a_checkpoint_is_not_doubled() {
        let lm = landmarks(&[
            ([-2.0, 0.1], ViaKind::Checkpoint, 5),
            ([-3.0, 0.0], ViaKind::TargetApproach, 0),
            ([-2.4, 0.0], ViaKind::Target, 0),
        ]);
        // robot 1 at (-1, 0), robot 2 at (-4, 0): the approach lies on the way
        let p = from_plan(&lm, &[[-1.0, 0.0], [-2.0, 0.0], [-4.0, 0.0]]).expect("a path");
        assert_eq!(kinds(&p), [(-4.0, 0.0, "waypoint"), (-3.0, 0.0, "target-approach"), (-2.4, 0.0, "target")]);
        // the checkpoint at -2 lies past the cut: robot 2 does not pass it
        let p = from_plan(&lm, &[[-1.0, 0.0], [-4.0, 0.0]]).expect("a path");
        assert_eq!(kinds(&p).len(), 3, "{:?}", kinds(&p));
    }

    #[test]
    fn a_path_without_a_target_ends_at_its_last_point_and_bad_plans_are_refused() {
        let lm = landmarks(&[([0.0, 0.0], ViaKind::Waypoint, 0), ([3.0, 0.0], ViaKind::Waypoint, 0)]);
        assert_eq!(ending(&lm).len(), 1);
        let p = from_plan(&lm, &[[5.0, 0.0], [0.0, 0.0]]).expect("a path");
        assert_eq!(kinds(&p), [(0.0, 0.0, "waypoint"), (3.0, 0.0, "waypoint")]);
        assert_eq!(from_plan(&lm, &[]), Err(AssembleError::EmptyPlan));
        assert_eq!(from_plan(&lm, &[[0.0, f64::NAN]]), Err(AssembleError::NotFinite(0)));
        assert_eq!(from_plan(&ViaPathBuf::new(4, 0), &[[0.0, 0.0]]), Err(AssembleError::NoEnding(4)));
        // a plan of one point (robot 2 next to robot 1): that point, then the ending
        let p = from_plan(&lm, &[[1.0, 0.0]]).expect("a path");
        assert_eq!(kinds(&p), [(1.0, 0.0, "waypoint"), (3.0, 0.0, "waypoint")]);
    }
}
