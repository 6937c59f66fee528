//! Paths over the cells the robot has seen (issue 42: the map builder's
//! `plan` service): [`plan`] answers "how do I get from here to that point"
//! with way points whose legs cross only cells of the [`VisitedGrid`] — the
//! places the robot has driven through, so free of walls as far as it knows.
//!
//! 1. **The ends.** The start is the robot's cell, the goal the goal
//!    point's cell. A point whose cell the robot has not been in is snapped
//!    to the nearest seen cell whose centre lies within `tolerance_m` of it;
//!    none there: no path ([`PlanStatus::StartUnseen`],
//!    [`PlanStatus::GoalUnseen`]).
//! 2. **The cells.** A* over seen cells, 8-connected: a straight step costs
//!    1 cell, a diagonal one √2 (10 and 14 in integer units). A diagonal
//!    step needs one of the two cells beside it seen too (the robot went
//!    round that corner), so a path never slips between two cells that only
//!    touch at a corner. No chain of seen cells: [`PlanStatus::Unreachable`].
//! 3. **The way points.** The cells' centres, from the robot's own position
//!    to the goal itself (or to the centre of the cell it was snapped to),
//!    simplified by line of sight: a way point is left out while the
//!    straight leg past it still crosses only seen cells (sampled every
//!    quarter cell) and is at most [`MAX_LEG_CELLS`] cells long.
//!
//! Work is bounded by the grid: A* expands each seen cell at most once.

use crate::VisitedGrid;
use shm_schemas::payloads::{PathHeader, PathPoint, PlanStatus};
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, HashSet};

/// A leg between two way points is at most this many cells long (so the
/// line-of-sight checks stay bounded, and a long straight corridor still
/// has a way point every 32 m at 0.5 m cells).
pub const MAX_LEG_CELLS: f64 = 64.0;

/// A straight step between cells, in A*'s integer cost units.
const STRAIGHT: u64 = 10;
/// A diagonal step (≈ 10 √2).
const DIAGONAL: u64 = 14;

/// A planned path: the header `plan` answers with and its way points (empty
/// unless the header's status is `found`).
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Status, ends, length, cells.
    pub header: PathHeader,
    /// From the robot's position to the goal.
    pub points: Vec<PathPoint>,
}

impl Plan {
    /// The status (always a known one: the planner sets it).
    pub fn status(&self) -> Option<PlanStatus> {
        self.header.status()
    }
}

type Key = (i64, i64);

/// A path from `start` (the robot's position; `None` when not known) to
/// `goal` over the cells of `grid`, at most `max_points` way points (see
/// the module). Never fails: the header's status says why there is no path.
pub fn plan(
    grid: &VisitedGrid,
    start: Option<(f64, f64)>,
    goal: (f64, f64),
    tolerance_m: f64,
    max_points: usize,
    stamp_ns: u64,
) -> Plan {
    let mut header = PathHeader { stamp_ns, goal_x: goal.0, goal_y: goal.1, ..Default::default() };
    let none = |mut header: PathHeader, status: PlanStatus| {
        header.status = status as u8;
        Plan { header, points: Vec::new() }
    };
    if !(goal.0.is_finite() && goal.1.is_finite()) {
        return none(header, PlanStatus::BadGoal);
    }
    let Some(start) = start.filter(|s| s.0.is_finite() && s.1.is_finite()) else {
        return none(header, PlanStatus::NoPose);
    };
    (header.start_x, header.start_y) = start;
    let tolerance_m = if tolerance_m.is_finite() { tolerance_m.max(0.0) } else { 0.0 };
    let Some(from) = snap(grid, start, tolerance_m) else {
        return none(header, PlanStatus::StartUnseen);
    };
    let Some(to) = snap(grid, goal, tolerance_m) else {
        return none(header, PlanStatus::GoalUnseen);
    };
    let Some(cells) = astar(grid, from, to) else {
        return none(header, PlanStatus::Unreachable);
    };
    header.cells = u32::try_from(cells.len()).unwrap_or(u32::MAX);
    // the robot's own position, the cells between, the goal (or its cell's centre)
    let end = if grid.key(goal.0, goal.1) == Some(to) { goal } else { grid.centre(to) };
    let mut pts = Vec::with_capacity(cells.len() + 1);
    pts.push(start);
    pts.extend(cells.iter().skip(1).take(cells.len().saturating_sub(2)).map(|k| grid.centre(*k)));
    pts.push(end);
    let way = by_line_of_sight(grid, &pts);
    if way.len() > max_points {
        return none(header, PlanStatus::TooLong);
    }
    header.length_m = way.windows(2).map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1)).sum();
    header.status = PlanStatus::Found as u8;
    Plan { header, points: way.into_iter().map(|(x, y)| PathPoint { x, y }).collect() }
}

/// The cell of `p` if seen, else the seen cell whose centre is nearest `p`
/// within `tolerance_m` (ties to the smaller key, so the answer is stable).
fn snap(grid: &VisitedGrid, p: (f64, f64), tolerance_m: f64) -> Option<Key> {
    let k = grid.key(p.0, p.1)?;
    if grid.seen(k) {
        return Some(k);
    }
    let r = (tolerance_m / grid.cell_m()).ceil().min(1000.0) as i64 + 1;
    let mut best: Option<(f64, Key)> = None;
    for di in -r..=r {
        for dj in -r..=r {
            let c = (k.0 + di, k.1 + dj);
            if !grid.seen(c) {
                continue;
            }
            let (cx, cy) = grid.centre(c);
            let d = (cx - p.0).hypot(cy - p.1);
            if d <= tolerance_m && best.is_none_or(|b| (d, c) < b) {
                best = Some((d, c));
            }
        }
    }
    best.map(|b| b.1)
}

/// The two ends of a `plan` and the islands of cells they are in (see
/// [`islands`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Islands {
    /// The cell the start snapped to.
    pub start_cell: (i64, i64),
    /// Seen cells chained to it by the steps A* takes (up to the limit).
    pub start_cells: usize,
    /// The cell the goal snapped to.
    pub goal_cell: (i64, i64),
    /// Seen cells chained to it.
    pub goal_cells: usize,
}

/// Why `plan` found no way from `start` to `goal` (for the log of an
/// `unreachable` answer): the cells the two ends snap to and how many seen
/// cells each one's island holds (cells chained by the steps A* takes).
/// Each island is counted up to `limit` cells; `None` when an end snaps to
/// no cell.
pub fn islands(
    grid: &VisitedGrid,
    start: (f64, f64),
    goal: (f64, f64),
    tolerance_m: f64,
    limit: usize,
) -> Option<Islands> {
    let tolerance_m = if tolerance_m.is_finite() { tolerance_m.max(0.0) } else { 0.0 };
    let (from, to) = (snap(grid, start, tolerance_m)?, snap(grid, goal, tolerance_m)?);
    let island = |k: Key| {
        let mut seen = HashSet::from([k]);
        let mut todo = vec![k];
        while let Some(k) = todo.pop() {
            if seen.len() >= limit {
                break;
            }
            for n in steps(grid, k) {
                if seen.insert(n) {
                    todo.push(n);
                }
            }
        }
        seen.len()
    };
    Some(Islands { start_cell: from, start_cells: island(from), goal_cell: to, goal_cells: island(to) })
}

/// The seen cells one A* step from `k`: its 4 neighbours, and its diagonal
/// ones with a cell beside the step seen too.
fn steps(grid: &VisitedGrid, k: Key) -> impl Iterator<Item = Key> + '_ {
    [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)].into_iter().filter_map(move |(di, dj)| {
        let n = (k.0 + di, k.1 + dj);
        let diagonal = di != 0 && dj != 0;
        let cut = diagonal && !grid.seen((k.0 + di, k.1)) && !grid.seen((k.0, k.1 + dj));
        (grid.seen(n) && !cut).then_some(n)
    })
}

/// The octile distance between two cells, in cost units (never more than
/// the cost of the cheapest chain of steps: A*'s heuristic).
fn octile(a: Key, b: Key) -> u64 {
    let (dx, dy) = (a.0.abs_diff(b.0), a.1.abs_diff(b.1));
    STRAIGHT * dx.max(dy) + (DIAGONAL - STRAIGHT) * dx.min(dy)
}

/// The cheapest chain of seen cells from `from` to `to` (both ends
/// included), or `None` when there is none.
fn astar(grid: &VisitedGrid, from: Key, to: Key) -> Option<Vec<Key>> {
    let mut open = BinaryHeap::new();
    let mut cost: HashMap<Key, u64> = HashMap::new();
    let mut came: HashMap<Key, Key> = HashMap::new();
    let mut done: HashSet<Key> = HashSet::new();
    cost.insert(from, 0);
    open.push(Reverse((octile(from, to), from)));
    while let Some(Reverse((_, k))) = open.pop() {
        if k == to {
            let mut path = vec![k];
            let mut at = k;
            while let Some(p) = came.get(&at) {
                path.push(*p);
                at = *p;
            }
            path.reverse();
            return Some(path);
        }
        if !done.insert(k) {
            continue;
        }
        let g = cost.get(&k).copied().unwrap_or(u64::MAX);
        for n in steps(grid, k) {
            if done.contains(&n) {
                continue;
            }
            let step = if n.0 != k.0 && n.1 != k.1 { DIAGONAL } else { STRAIGHT };
            let ng = g.saturating_add(step);
            if cost.get(&n).is_none_or(|c| ng < *c) {
                cost.insert(n, ng);
                came.insert(n, k);
                open.push(Reverse((ng.saturating_add(octile(n, to)), n)));
            }
        }
    }
    None
}

/// Whether the straight leg from `a` to `b` crosses only seen cells
/// (sampled every quarter cell) and is at most [`MAX_LEG_CELLS`] long.
fn line_clear(grid: &VisitedGrid, a: (f64, f64), b: (f64, f64)) -> bool {
    let len = (b.0 - a.0).hypot(b.1 - a.1);
    let cell = grid.cell_m();
    if len > MAX_LEG_CELLS * cell {
        return false;
    }
    let n = ((len / (cell / 4.0)).ceil() as usize).max(1);
    (0..=n).all(|s| {
        let t = s as f64 / n as f64;
        point_clear(grid, a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1))
    })
}

/// Whether a point of a leg lies on seen cells: the cell it is in; on the
/// edge between two cells either of them; on a corner three of the four
/// (the A* rule for a diagonal step: one of the cells beside it seen).
fn point_clear(grid: &VisitedGrid, x: f64, y: f64) -> bool {
    let Some((i, j)) = grid.key(x, y) else { return false };
    let cell = grid.cell_m();
    // on an edge, the cell below or left of it is a candidate too
    let edge = |v: f64| {
        let f = v / cell;
        (f - f.round()).abs() < 1e-9
    };
    let is = if edge(x) { [i - 1, i] } else { [i, i] };
    let js = if edge(y) { [j - 1, j] } else { [j, j] };
    match (edge(x), edge(y)) {
        (false, false) => grid.seen((i, j)),
        (true, true) => is.iter().flat_map(|i| js.iter().map(move |j| (*i, *j))).filter(|k| grid.seen(*k)).count() >= 3,
        _ => is.iter().zip(js).any(|(i, j)| grid.seen((*i, j))),
    }
}

/// `pts` with every point left out whose neighbours see each other (see
/// [`line_clear`]); the first and last are kept. Neighbouring points of
/// `pts` are taken as connected (they are neighbouring cells).
fn by_line_of_sight(grid: &VisitedGrid, pts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let (Some(first), Some(last)) = (pts.first(), pts.last()) else { return Vec::new() };
    let mut out = vec![*first];
    let mut anchor = 0;
    for k in 2..pts.len() {
        if !line_clear(grid, pts[anchor], pts[k]) {
            out.push(pts[k - 1]);
            anchor = k - 1;
        }
    }
    if pts.len() > 1 {
        out.push(*last);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of 1 m cells from a picture: `o` a cell the robot has been in;
    /// the last row is y = 0 … 1, the first column x = 0 … 1.
    fn grid(rows: &[&str]) -> VisitedGrid {
        let mut g = VisitedGrid::new(1.0, 0, 10_000);
        for (r, row) in rows.iter().enumerate() {
            let j = (rows.len() - 1 - r) as f64;
            for (i, c) in row.chars().enumerate() {
                if c == 'o' {
                    g.visit(i as f64 + 0.5, j + 0.5, 0);
                }
            }
        }
        g
    }

    fn xy(p: &Plan) -> Vec<(f64, f64)> {
        p.points.iter().map(|p| (p.x, p.y)).collect()
    }

    /// Every leg of a found path crosses only seen cells.
    fn on_seen_cells(g: &VisitedGrid, p: &Plan) -> bool {
        xy(p).windows(2).all(|w| line_clear(g, w[0], w[1]))
    }

    #[test]
    fn a_path_round_a_corner_keeps_to_the_cells_seen() {
        // an L: along y = 0 … 1 from x = 0 to 5, then up x = 5 … 6 to y = 5
        let g = grid(&["     o", "     o", "     o", "     o", "oooooo"]);
        let p = plan(&g, Some((0.2, 0.4)), (5.5, 4.6), 0.5, 100, 42);
        assert_eq!(p.status(), Some(PlanStatus::Found), "{p:?}");
        assert_eq!((p.header.stamp_ns, p.header.start_x, p.header.goal_y), (42, 0.2, 4.6));
        assert_eq!(p.header.cells, 9, "5 along, one diagonal step round the corner (the corner cell beside it), 3 up");
        // from the robot, round the corner, to the goal itself
        assert_eq!(xy(&p), [(0.2, 0.4), (4.5, 0.5), (5.5, 1.5), (5.5, 4.6)]);
        let want = 4.3f64.hypot(0.1) + 2f64.sqrt() + 3.1;
        assert!((p.header.length_m - want).abs() < 1e-9, "{}", p.header.length_m);
        assert!(on_seen_cells(&g, &p));
        // a room: the straight line across it
        let room = grid(&["oooo", "oooo", "oooo"]);
        let p = plan(&room, Some((0.5, 0.5)), (3.5, 2.5), 0.0, 100, 0);
        assert_eq!(xy(&p), [(0.5, 0.5), (3.5, 2.5)]);
    }

    #[test]
    fn a_goal_in_another_island_is_unreachable_and_a_goal_nowhere_unseen() {
        let g = grid(&["ooo ooo"]);
        let p = plan(&g, Some((0.5, 0.5)), (5.5, 0.5), 0.5, 100, 0);
        assert_eq!((p.status(), p.points.len()), (Some(PlanStatus::Unreachable), 0));
        assert_eq!(
            islands(&g, (0.5, 0.5), (5.5, 0.5), 0.5, 100),
            Some(Islands { start_cell: (0, 0), start_cells: 3, goal_cell: (5, 0), goal_cells: 3 })
        );
        // cells that touch only at a corner are not a way through …
        let corner = grid(&[" o", "o "]);
        assert_eq!(plan(&corner, Some((0.5, 0.5)), (1.5, 1.5), 0.0, 100, 0).status(), Some(PlanStatus::Unreachable));
        // … with a cell beside them they are, diagonally
        let beside = grid(&[" o", "oo"]);
        let p = plan(&beside, Some((0.5, 0.5)), (1.5, 1.5), 0.0, 100, 0);
        assert_eq!((p.status(), p.header.cells), (Some(PlanStatus::Found), 2));
        // far from every cell seen
        let p = plan(&g, Some((0.5, 0.5)), (20.0, 20.0), 2.0, 100, 0);
        assert_eq!((p.status(), p.points.len()), (Some(PlanStatus::GoalUnseen), 0));
    }

    #[test]
    fn a_robot_driving_close_past_a_corner_leaves_a_way_plan_can_follow() {
        // issue 42, the demo's "unreachable": a pose step that passes a cell
        // corner by a centimetre crosses the cell beside it (0, 1) only for
        // 1 cm; cells sampled every eighth of a cell missed it and the two
        // cells driven through touched only at the corner
        for (a, b) in [((0.3, 0.31), (0.7, 0.71)), ((0.3, 0.3), (0.7, 0.7)), ((0.71, 0.7), (0.31, 0.3))] {
            let mut g = VisitedGrid::new(0.5, 0, 10_000);
            g.visit_along(a.0, a.1, 0);
            g.visit_along(b.0, b.1, 1);
            let p = plan(&g, Some(b), a, 0.0, 100, 0);
            assert_eq!(p.status(), Some(PlanStatus::Found), "{a:?} -> {b:?}: {p:?}");
            assert!(on_seen_cells(&g, &p), "{a:?} -> {b:?}: {p:?}");
        }
        // a long step along a row's edge, wiggling across it: every cell crossed is a way
        let mut g = VisitedGrid::new(0.5, 0, 10_000);
        let mut at = (0.0, -0.49);
        g.visit_along(at.0, at.1, 0);
        for k in 1..40u64 {
            at = (k as f64 * 0.37, if k % 2 == 0 { -0.49 } else { -0.52 });
            g.visit_along(at.0, at.1, k);
        }
        assert_eq!(plan(&g, Some(at), (0.0, -0.49), 0.0, 100, 0).status(), Some(PlanStatus::Found));
    }

    #[test]
    fn a_goal_near_a_seen_cell_is_snapped_to_it_within_the_tolerance() {
        let g = grid(&["oooo"]);
        // 0.9 m above the corridor's last cell centre (3.5, 0.5): out of 0.5 m, within 1.0 m
        assert_eq!(plan(&g, Some((0.5, 0.5)), (3.5, 1.4), 0.5, 100, 0).status(), Some(PlanStatus::GoalUnseen));
        let p = plan(&g, Some((0.5, 0.5)), (3.5, 1.4), 1.0, 100, 0);
        assert_eq!(p.status(), Some(PlanStatus::Found));
        assert_eq!(xy(&p), [(0.5, 0.5), (3.5, 0.5)], "ends at the cell's centre");
        assert_eq!((p.header.goal_x, p.header.goal_y), (3.5, 1.4), "the goal asked for");
        // a robot standing just off the cells seen (the grid was full) is snapped too
        let p = plan(&g, Some((0.5, -0.3)), (2.5, 0.5), 1.0, 100, 0);
        assert_eq!(p.status(), Some(PlanStatus::Found));
        assert_eq!(plan(&g, Some((0.5, -3.0)), (2.5, 0.5), 1.0, 100, 0).status(), Some(PlanStatus::StartUnseen));
    }

    #[test]
    fn start_and_goal_in_one_cell_is_a_path_of_one_leg() {
        let g = grid(&["oo"]);
        let p = plan(&g, Some((0.2, 0.2)), (0.8, 0.6), 0.5, 100, 0);
        assert_eq!(p.status(), Some(PlanStatus::Found));
        assert_eq!((xy(&p), p.header.cells), (vec![(0.2, 0.2), (0.8, 0.6)], 1));
        assert!((p.header.length_m - 0.6f64.hypot(0.4)).abs() < 1e-12);
    }

    #[test]
    fn no_pose_a_bad_goal_and_a_path_too_long_are_said() {
        let g = grid(&["oooo"]);
        assert_eq!(plan(&g, None, (1.5, 0.5), 0.5, 100, 0).status(), Some(PlanStatus::NoPose));
        assert_eq!(plan(&g, Some((f64::NAN, 0.5)), (1.5, 0.5), 0.5, 100, 0).status(), Some(PlanStatus::NoPose));
        assert_eq!(plan(&g, Some((0.5, 0.5)), (f64::INFINITY, 0.5), 0.5, 100, 0).status(), Some(PlanStatus::BadGoal));
        // a zigzag needs 5 way points
        let z = grid(&["ooo  ", "  o  ", "  ooo"]);
        let p = plan(&z, Some((0.5, 2.5)), (4.5, 0.5), 0.0, 100, 0);
        assert_eq!(p.points.len(), 4, "{:?}", xy(&p));
        assert!(on_seen_cells(&z, &p));
        let p = plan(&z, Some((0.5, 2.5)), (4.5, 0.5), 0.0, 3, 0);
        assert_eq!((p.status(), p.points.len()), (Some(PlanStatus::TooLong), 0));
    }

    #[test]
    fn a_long_corridor_gets_a_way_point_every_max_leg() {
        let g = grid(&[&"o".repeat(200)]);
        let p = plan(&g, Some((0.5, 0.5)), (199.5, 0.5), 0.0, 100, 0);
        assert_eq!(p.status(), Some(PlanStatus::Found));
        assert!(p.points.len() >= 4, "199 m in legs of at most 64: {:?}", xy(&p));
        assert!(xy(&p).windows(2).all(|w| (w[1].0 - w[0].0) <= MAX_LEG_CELLS));
        assert!((p.header.length_m - 199.0).abs() < 1e-9);
    }
}
