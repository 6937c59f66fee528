//! Where the robot has been ([`VisitedGrid`]): a coarse grid of cells with
//! the times the robot entered and left them, and the map the map builder
//! publishes from it ([`VisitedGrid::write_map`], issue 42).
//!
//! [`VisitedGrid::visited_before`] says whether a place was passed before
//! (left at least `revisit_after` ago and now reached again — the robot is
//! going round in circles), [`VisitedGrid::visited_ahead`] how much of what
//! lies ahead in a direction was visited, for exploration that prefers new
//! space. Cell `(i, j)` covers `i·cell_m ≤ x < (i + 1)·cell_m` (and the same
//! in y): the grid's origin is the frame's origin. The planner
//! ([`crate::plan`]) finds paths over its cells.

use crate::Pose;
use shm_schemas::payloads::{MAP_CELL_HERE, MAP_CELL_VISITED, MapCell, MapHeader};
use std::collections::HashMap;

/// [`VisitedGrid::visit_along`] fills in the cells between two positions
/// at most this far apart, metres (a step of the odometry, or a checkpoint's
/// correction of the pose); farther is a jump the robot did not drive.
pub const FILL_MAX_M: f64 = 2.0;

/// A cell of the [`VisitedGrid`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Cell {
    /// Times the robot entered it.
    pub entries: u32,
    /// When it last entered it, ns.
    pub last_enter_ns: u64,
    /// When it last left it, ns (`None` while it never left).
    pub last_leave_ns: Option<u64>,
}

/// Where the robot has been: a coarse grid.
#[derive(Debug, Clone)]
pub struct VisitedGrid {
    cell_m: f64,
    revisit_after_ns: u64,
    max_cells: usize,
    cells: HashMap<(i64, i64), Cell>,
    current: Option<(i64, i64)>,
    /// The last position given to [`VisitedGrid::visit_along`].
    last_point: Option<(f64, f64)>,
    full: bool,
    revision: u32,
}

impl VisitedGrid {
    /// A grid of `cell_m` cells; a place left at least `revisit_after_ns`
    /// ago counts as visited before. At most `max_cells` cells are kept.
    pub fn new(cell_m: f64, revisit_after_ns: u64, max_cells: usize) -> Self {
        VisitedGrid {
            cell_m: if cell_m.is_finite() && cell_m > 0.01 { cell_m } else { 0.5 },
            revisit_after_ns,
            max_cells,
            cells: HashMap::new(),
            current: None,
            last_point: None,
            full: false,
            revision: 0,
        }
    }

    /// The cell `(i, j)` that holds `(x, y)`; `None` for a point beyond
    /// ±1e9 cells or not finite.
    pub fn key(&self, x: f64, y: f64) -> Option<(i64, i64)> {
        let (i, j) = ((x / self.cell_m).floor(), (y / self.cell_m).floor());
        // beyond ±1e9 cells is nonsense (and would not fit an i64 exactly)
        (i.abs() < 1e9 && j.abs() < 1e9).then_some((i as i64, j as i64))
    }

    /// The robot went from the last position given here to `(x, y)` at
    /// `now_ns`: it visits every cell the straight line between crosses
    /// (each sharing a side with the one before) when the two are at most [`FILL_MAX_M`]
    /// apart, then `(x, y)`'s. Poses come often, but a checkpoint's
    /// correction moves the pose by decimetres at once, and a robot at 4x
    /// simulated time may step farther than a cell: without the cells
    /// between, the planner would find no way across the gap.
    pub fn visit_along(&mut self, x: f64, y: f64, now_ns: u64) {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        if let Some((px, py)) = self.last_point
            && (x - px).hypot(y - py) <= FILL_MAX_M
        {
            self.visit_crossed((px, py), (x, y), now_ns);
        }
        self.visit(x, y, now_ns);
        self.last_point = Some((x, y));
    }

    /// Visits every cell the straight line from `a` to `b` crosses, in
    /// order, each sharing a side with the one before (a grid walk, not
    /// samples: a line that passes a corner by millimetres still crosses
    /// the cell beside it, and the planner needs that cell to step
    /// diagonally; through a corner exactly, the cell beside it in x is
    /// taken). `b`'s own cell is left to the caller.
    fn visit_crossed(&mut self, a: (f64, f64), b: (f64, f64), now_ns: u64) {
        let (Some(mut k), Some(end)) = (self.key(a.0, a.1), self.key(b.0, b.1)) else { return };
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let cell = self.cell_m;
        // the line's parameter t (0 at a, 1 at b) where it crosses the next
        // cell side in x (in y), and how far t goes from one side to the next
        let first = |i: i64, d: f64, from: f64| {
            let side = if d > 0.0 { (i + 1) as f64 * cell } else { i as f64 * cell };
            if d == 0.0 { f64::INFINITY } else { (side - from) / d }
        };
        let (mut tx, mut ty) = (first(k.0, dx, a.0), first(k.1, dy, a.1));
        let (ddx, ddy) = (
            if dx == 0.0 { f64::INFINITY } else { cell / dx.abs() },
            if dy == 0.0 { f64::INFINITY } else { cell / dy.abs() },
        );
        let (si, sj) = (if dx > 0.0 { 1 } else { -1 }, if dy > 0.0 { 1 } else { -1 });
        // one side crossed a step: at most as many steps as cells between the ends
        let steps = k.0.abs_diff(end.0).saturating_add(k.1.abs_diff(end.1)).min(10_000);
        for _ in 0..steps {
            if k == end {
                break;
            }
            if tx <= ty {
                k.0 += si;
                tx += ddx;
            } else {
                k.1 += sj;
                ty += ddy;
            }
            let (cx, cy) = self.centre(k);
            self.visit(cx, cy, now_ns);
        }
    }

    /// The robot is at `(x, y)` at `now_ns`.
    pub fn visit(&mut self, x: f64, y: f64, now_ns: u64) {
        let Some(k) = self.key(x, y) else { return };
        if self.current == Some(k) {
            return;
        }
        if let Some(c) = self.current.and_then(|c| self.cells.get_mut(&c)) {
            c.last_leave_ns = Some(now_ns);
        }
        if !self.cells.contains_key(&k) && self.cells.len() >= self.max_cells {
            self.full = true;
            self.current = None;
            return;
        }
        let c = self.cells.entry(k).or_default();
        c.entries = c.entries.saturating_add(1);
        c.last_enter_ns = now_ns;
        self.current = Some(k);
        self.revision = self.revision.wrapping_add(1);
    }

    /// The cell at `(x, y)`, if the robot was ever there.
    pub fn cell(&self, x: f64, y: f64) -> Option<&Cell> {
        self.key(x, y).and_then(|k| self.cells.get(&k))
    }

    /// Whether the place `(x, y)` was already visited: a cell within
    /// `radius_m` of it that the robot left at least `revisit_after` before
    /// `now_ns` (so the cells just behind a robot passing for the first
    /// time do not count).
    pub fn visited_before(&self, x: f64, y: f64, radius_m: f64, now_ns: u64) -> bool {
        let Some((ci, cj)) = self.key(x, y) else { return false };
        let r = (radius_m.max(0.0) / self.cell_m).ceil() as i64;
        for di in -r..=r {
            for dj in -r..=r {
                let Some(c) = self.cells.get(&(ci + di, cj + dj)) else { continue };
                if c.last_leave_ns.is_some_and(|t| now_ns.saturating_sub(t) >= self.revisit_after_ns) {
                    return true;
                }
            }
        }
        false
    }

    /// The fraction (0 … 1) of points along `distance_m` ahead of `pose`
    /// in direction `pose.theta + angle` that fall in visited cells.
    pub fn visited_ahead(&self, pose: &Pose, angle: f64, distance_m: f64) -> f64 {
        let n = ((distance_m / self.cell_m).ceil() as usize).clamp(1, 1000);
        let a = pose.theta + angle;
        let hits = (1..=n)
            .filter(|k| {
                let d = distance_m * *k as f64 / n as f64;
                self.key(pose.x + d * a.cos(), pose.y + d * a.sin()).is_some_and(|key| self.cells.contains_key(&key))
            })
            .count();
        hits as f64 / n as f64
    }

    /// A cell's side, metres.
    pub fn cell_m(&self) -> f64 {
        self.cell_m
    }

    /// The centre of cell `(i, j)`, metres.
    pub fn centre(&self, (i, j): (i64, i64)) -> (f64, f64) {
        ((i as f64 + 0.5) * self.cell_m, (j as f64 + 0.5) * self.cell_m)
    }

    /// Whether the robot has been in cell `(i, j)`.
    pub fn seen(&self, key: (i64, i64)) -> bool {
        self.cells.contains_key(&key)
    }

    /// The cells the robot has been in, in no order.
    pub fn cells(&self) -> impl Iterator<Item = ((i64, i64), &Cell)> {
        self.cells.iter().map(|(k, c)| (*k, c))
    }

    /// Grows by one (wrapping) whenever the robot enters a cell: the same
    /// revision is the same grid.
    pub fn revision(&self) -> u32 {
        self.revision
    }

    /// The map as the `map` output sends it: `header` and one [`MapCell`]
    /// per cell in `items` (ordered by row `iy`, then column `ix`). `items`
    /// should be [`VisitedGrid::len`] long; extra items are left zero, and
    /// cells past its end are left out (the header's `count` says how many
    /// were written).
    pub fn write_map(&self, stamp_ns: u64, header: &mut MapHeader, items: &mut [MapCell]) {
        let mut keys: Vec<(i64, i64)> = self.cells.keys().copied().collect();
        keys.sort_unstable_by_key(|&(i, j)| (j, i));
        let mut written = 0usize;
        let (mut lo, mut hi) = ((i32::MAX, i32::MAX), (i32::MIN, i32::MIN));
        for (slot, key) in items.iter_mut().zip(&keys) {
            // keys are within ±1e9 cells (VisitedGrid::key), so they fit an i32
            let (Ok(ix), Ok(iy)) = (i32::try_from(key.0), i32::try_from(key.1)) else { continue };
            let Some(c) = self.cells.get(key) else { continue };
            let (x, y) = self.centre(*key);
            let here = if self.current == Some(*key) { MAP_CELL_HERE } else { 0 };
            *slot = MapCell {
                last_seen_ns: c.last_enter_ns,
                ix,
                iy,
                x: x as f32,
                y: y as f32,
                visits: c.entries,
                flags: MAP_CELL_VISITED | here,
                _pad: [0; 3],
            };
            (lo, hi) = ((lo.0.min(ix), lo.1.min(iy)), (hi.0.max(ix), hi.1.max(iy)));
            written += 1;
        }
        if written == 0 {
            (lo, hi) = ((0, 0), (0, 0));
        }
        *header = MapHeader {
            stamp_ns,
            cell_m: self.cell_m,
            origin_x: 0.0,
            origin_y: 0.0,
            min_ix: lo.0,
            min_iy: lo.1,
            max_ix: hi.0,
            max_iy: hi.1,
            count: u32::try_from(written).unwrap_or(u32::MAX),
            revision: self.revision,
            max_cells: u32::try_from(self.max_cells).unwrap_or(u32::MAX),
            full: u8::from(self.full),
            _pad: [0; 3],
        };
    }

    /// Cells visited.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// No cell visited yet.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The grid reached `max_cells` (new places are no longer recorded).
    pub fn is_full(&self) -> bool {
        self.full
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn the_cells_between_two_near_positions_are_visited_and_a_far_jump_is_not_filled() {
        let mut g = VisitedGrid::new(0.5, 0, 10_000);
        g.visit_along(0.25, 0.25, 0);
        // a correction moves the pose 0.7 m diagonally: the cells on the way count
        g.visit_along(0.75, 0.75, 1);
        g.visit_along(0.95, 0.75, 2);
        g.visit_along(0.25, 1.45, 3);
        let keys = |g: &VisitedGrid| {
            let mut k: Vec<_> = g.cells.keys().copied().collect();
            k.sort_unstable();
            k
        };
        assert!(keys(&g).contains(&(1, 1)) && keys(&g).contains(&(0, 2)), "{:?}", keys(&g));
        let n = g.len();
        assert!(n >= 4, "{:?}", keys(&g));
        // 3 m away: a jump, only its own cell
        g.visit_along(3.25, 1.45, 4);
        assert_eq!(g.len(), n + 1, "{:?}", keys(&g));
        // nonsense is not a position
        g.visit_along(f64::NAN, 0.0, 5);
        assert_eq!(g.len(), n + 1);
    }

    #[test]
    fn the_grid_knows_a_place_passed_before() {
        let s = 1_000_000_000u64;
        let mut g = VisitedGrid::new(0.5, 20 * s, 10_000);
        // a lap around a 4 x 4 m box at 0.5 m/s, one point per second
        let mut t = 0;
        let mut lap = Vec::new();
        for k in 0..8 {
            lap.push((k as f64 * 0.5, 0.0));
        }
        for k in 0..8 {
            lap.push((4.0, k as f64 * 0.5));
        }
        for k in 0..8 {
            lap.push((4.0 - k as f64 * 0.5, 4.0));
        }
        for k in 0..8 {
            lap.push((0.0, 4.0 - k as f64 * 0.5));
        }
        for &(x, y) in &lap {
            g.visit(x, y, t);
            // during the first lap nothing was passed before, until the lap closes near the start
            if x.hypot(y) > 1.0 {
                assert!(!g.visited_before(x + 0.01, y + 0.01, 0.3, t), "({x}, {y}) at {t}");
            }
            t += s;
        }
        // back at the start after 32 s: passed before
        g.visit(0.1, 0.1, t);
        assert!(g.visited_before(0.1, 0.1, 0.3, t));
        assert_eq!(g.cell(0.1, 0.1).map(|c| c.entries), Some(2));
        // a place never visited
        assert!(!g.visited_before(10.0, 10.0, 0.3, t));
        // looking ahead along the box's side: visited; away from it: new
        let at = Pose { x: 0.1, y: 0.1, theta: 0.0 };
        assert!(g.visited_ahead(&at, 0.0, 3.0) > 0.9);
        assert!(g.visited_ahead(&at, PI, 3.0) < 0.1);
        // the grid is bounded
        let mut small = VisitedGrid::new(0.5, s, 3);
        for k in 0..10 {
            small.visit(k as f64, 0.0, k);
        }
        assert_eq!(small.len(), 3);
        assert!(small.is_full());
        small.visit(f64::NAN, 0.0, 99);
    }

    #[test]
    fn the_map_holds_every_cell_visited_with_its_bounds_and_where_the_robot_is() {
        let s = 1_000_000_000u64;
        let mut g = VisitedGrid::new(0.5, s, 100);
        let (mut h, mut items) = (MapHeader::default(), Vec::<MapCell>::new());
        g.write_map(7, &mut h, &mut items);
        assert_eq!((h.count, h.min_ix, h.max_ix, h.revision, h.cell_m, h.full), (0, 0, 0, 0, 0.5, 0));
        // out along x, then back into the first cell, then down into negative y
        for (k, (x, y)) in [(0.1, 0.1), (0.6, 0.1), (1.1, 0.2), (0.2, 0.3), (0.2, -0.4)].into_iter().enumerate() {
            g.visit(x, y, k as u64 * s);
        }
        assert_eq!(g.revision(), 5);
        items = vec![MapCell::default(); g.len()];
        g.write_map(9, &mut h, &mut items);
        assert_eq!((h.stamp_ns, h.count, h.revision, h.max_cells), (9, 4, 5, 100));
        assert_eq!((h.min_ix, h.min_iy, h.max_ix, h.max_iy), (0, -1, 2, 0));
        let cells: Vec<(i32, i32, u32, u8)> = items.iter().map(|c| (c.ix, c.iy, c.visits, c.flags)).collect();
        // ordered by row, then column; the first cell entered twice; the robot in (0, -1)
        assert_eq!(cells, [(0, -1, 1, 3), (0, 0, 2, 1), (1, 0, 1, 1), (2, 0, 1, 1)]);
        assert_eq!((items[2].x, items[2].y, items[2].last_seen_ns), (0.75, 0.25, s));
        // staying in a cell is no change; a short slice takes the first cells
        g.visit(0.3, -0.3, 9 * s);
        assert_eq!(g.revision(), 5);
        let mut two = vec![MapCell::default(); 2];
        g.write_map(10, &mut h, &mut two);
        assert_eq!((h.count, two[1].ix, two[1].iy), (2, 0, 0));
    }
}
