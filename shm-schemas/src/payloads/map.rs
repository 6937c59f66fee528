//! The map builder's map and its `plan` service (issue 42: "use them where
//! the robot wants them"): variable-size payloads ([`crate::Seq`]) of
//! fixed-size elements.
//!
//! * [`MapCells`] = `Seq<MapCell, MapHeader>` — output `map` of the map
//!   builder: every cell of its grid the robot has been in, any count,
//!   growing as the robot explores. The header says the grid's cell size,
//!   origin and bounds, so a viewer can lay the cells out densely (a
//!   `foxglove.Grid` of `max_ix - min_ix + 1` columns and `max_iy - min_iy +
//!   1` rows whose corner is at `origin + (min_ix, min_iy) × cell_m`).
//! * [`PlanRequest`] — a goal point in the world frame, the request of the
//!   map builder's `plan` service (`nerve call map-builder/plan '{"x": 1.0,
//!   "y": 2.6}'`).
//! * [`PlannedPath`] = `Seq<PathPoint, PathHeader>` — the answer: way points
//!   from the robot's position to the goal over the cells it has seen, any
//!   count (none when no path was found; the header's [`PlanStatus`] says
//!   why).
//!
//! Cell `(ix, iy)` covers `origin_x + ix·cell_m ≤ x < origin_x + (ix + 1)·cell_m`
//! (and the same in y). Units: metres, world frame (the frame of the pose the
//! map builder reads: the odometry's); stamps are CLOCK_MONOTONIC
//! nanoseconds of the robot that made them. Enumerations travel as integer
//! codes; read them with the `from_code` functions, which return `None` for
//! a code this build does not know.

use super::Payload;
use crate::seq::Seq;
use serde::Serialize;

/// [`MapCell::flags`] bit: the robot has been in the cell.
pub const MAP_CELL_VISITED: u8 = 1;
/// [`MapCell::flags`] bit: the robot is in the cell now (at the last pose).
pub const MAP_CELL_HERE: u8 = 2;

/// One cell of the map: a square of [`MapHeader::cell_m`] the robot has
/// been in.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::MapCell")]
pub struct MapCell {
    /// When the robot last entered the cell (the pose's stamp).
    pub last_seen_ns: u64,
    /// Column: the cell covers `origin_x + ix·cell_m ≤ x < origin_x + (ix + 1)·cell_m`.
    pub ix: i32,
    /// Row, as `ix` in y.
    pub iy: i32,
    /// The cell's centre, x, metres, world frame (for reading; `ix` is exact).
    pub x: f32,
    /// The cell's centre, y, metres, world frame.
    pub y: f32,
    /// Times the robot entered the cell.
    pub visits: u32,
    /// [`MAP_CELL_VISITED`] | [`MAP_CELL_HERE`].
    pub flags: u8,
    /// Padding, zero.
    #[serde(skip)]
    pub _pad: [u8; 3],
}

/// What comes before a map's cells.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::MapHeader")]
pub struct MapHeader {
    /// When the map was sent (sender's clock).
    pub stamp_ns: u64,
    /// A cell's side, metres.
    pub cell_m: f64,
    /// The corner of cell (0, 0), x, metres, world frame.
    pub origin_x: f64,
    /// The corner of cell (0, 0), y, metres, world frame.
    pub origin_y: f64,
    /// The smallest `ix` of any cell (0 when there is none).
    pub min_ix: i32,
    /// The smallest `iy` of any cell.
    pub min_iy: i32,
    /// The largest `ix` of any cell.
    pub max_ix: i32,
    /// The largest `iy` of any cell.
    pub max_iy: i32,
    /// Cells that follow (the sample's length says it too).
    pub count: u32,
    /// Grows by one whenever the map changes (a cell entered); the same
    /// revision is the same map.
    pub revision: u32,
    /// The most cells the map keeps.
    pub max_cells: u32,
    /// 1 once the map holds `max_cells` and records no new place.
    pub full: u8,
    /// Padding, zero.
    #[serde(skip)]
    pub _pad: [u8; 3],
}

/// The map: a [`MapHeader`] and its [`MapCell`]s.
pub type MapCells = Seq<MapCell, MapHeader>;

/// A goal for the `plan` service, world frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::PlanRequest")]
pub struct PlanRequest {
    /// Goal, x, metres, world frame.
    pub x: f64,
    /// Goal, y, metres, world frame.
    pub y: f64,
    /// When it was asked (`nerve call` fills it in when left out).
    pub stamp_ns: u64,
}

/// One way point of a [`PlannedPath`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::PathPoint")]
pub struct PathPoint {
    /// x, metres, world frame.
    pub x: f64,
    /// y, metres, world frame.
    pub y: f64,
}

/// Whether a path was found, and if not why.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[repr(u8)]
pub enum PlanStatus {
    /// A path follows, from the robot's cell to the goal's.
    Found = 1,
    /// The planner has no recent pose of the robot (is its `pose` input wired?).
    NoPose = 2,
    /// The robot stands in a cell the map does not hold (the map is full).
    StartUnseen = 3,
    /// No cell the robot has seen lies within the goal tolerance of the goal.
    GoalUnseen = 4,
    /// The goal's cell is seen but not connected to the robot's over seen cells.
    Unreachable = 5,
    /// The goal is not a finite point.
    BadGoal = 6,
    /// The path has more way points than the service answers with.
    TooLong = 7,
}

impl PlanStatus {
    /// Every status, in code order.
    pub const ALL: [PlanStatus; 7] = [
        Self::Found,
        Self::NoPose,
        Self::StartUnseen,
        Self::GoalUnseen,
        Self::Unreachable,
        Self::BadGoal,
        Self::TooLong,
    ];

    /// The status of a wire code; `None` for an unknown code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|s| *s as u8 == code)
    }

    /// `found`, `no-pose`, `start-unseen`, `goal-unseen`, `unreachable`,
    /// `bad-goal`, `too-long`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Found => "found",
            Self::NoPose => "no-pose",
            Self::StartUnseen => "start-unseen",
            Self::GoalUnseen => "goal-unseen",
            Self::Unreachable => "unreachable",
            Self::BadGoal => "bad-goal",
            Self::TooLong => "too-long",
        }
    }
}

/// What comes before a path's way points.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::PathHeader")]
pub struct PathHeader {
    /// When the path was made (the planner's clock).
    pub stamp_ns: u64,
    /// The goal asked for, x, metres, world frame.
    pub goal_x: f64,
    /// The goal asked for, y, metres, world frame.
    pub goal_y: f64,
    /// Where the path starts (the robot's position), x, metres.
    pub start_x: f64,
    /// Where the path starts, y, metres.
    pub start_y: f64,
    /// The path's length along its way points, metres (0 when none).
    pub length_m: f64,
    /// Grid cells the path crosses (before it was simplified to way points).
    pub cells: u32,
    /// A [`PlanStatus`] code; read it with [`PathHeader::status`]. Only
    /// `found` has way points.
    pub status: u8,
    /// Padding, zero.
    #[serde(skip)]
    pub _pad: [u8; 3],
}

impl PathHeader {
    /// The status, or `None` for an unknown code.
    pub fn status(&self) -> Option<PlanStatus> {
        PlanStatus::from_code(self.status)
    }
}

/// A planned path: a [`PathHeader`] and its [`PathPoint`]s, from the
/// robot's position (the first) to the goal's cell (the last).
pub type PlannedPath = Seq<PathPoint, PathHeader>;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schema::Described;

    #[test]
    fn layout_is_stable() {
        assert_eq!((std::mem::size_of::<MapCell>(), std::mem::align_of::<MapCell>()), (32, 8));
        assert_eq!(std::mem::offset_of!(MapCell, ix), 8);
        assert_eq!(std::mem::offset_of!(MapCell, visits), 24);
        assert_eq!(std::mem::offset_of!(MapCell, flags), 28);
        assert_eq!(std::mem::size_of::<MapHeader>(), 64);
        assert_eq!(std::mem::offset_of!(MapHeader, min_ix), 32);
        assert_eq!(std::mem::offset_of!(MapHeader, count), 48);
        assert_eq!(std::mem::offset_of!(MapHeader, full), 60);
        assert_eq!(std::mem::size_of::<PlanRequest>(), 24);
        assert_eq!(std::mem::size_of::<PathPoint>(), 16);
        assert_eq!(std::mem::size_of::<PathHeader>(), 56);
        assert_eq!(std::mem::offset_of!(PathHeader, cells), 48);
        assert_eq!(std::mem::offset_of!(PathHeader, status), 52);
        for (name, got) in [
            ("nerve::MapCell", <MapCell as Payload>::stable_type_name()),
            ("nerve::MapHeader", <MapHeader as Payload>::stable_type_name()),
            ("nerve::PlanRequest", <PlanRequest as Payload>::stable_type_name()),
            ("nerve::PathPoint", <PathPoint as Payload>::stable_type_name()),
            ("nerve::PathHeader", <PathHeader as Payload>::stable_type_name()),
        ] {
            assert_eq!(got, name);
        }
    }

    #[test]
    fn the_sequences_are_valid_and_padding_is_not_in_the_schema() {
        let map = MapCells::schema();
        assert_eq!(map.validate(), Ok(()));
        assert_eq!(map.type_name, "nerve::Seq<nerve::MapCell, nerve::MapHeader>");
        assert_eq!(map.sequence_shape().map(|s| (s.items_at, s.element)), Some((64, 32)));
        let path = PlannedPath::schema();
        assert_eq!(path.validate(), Ok(()));
        assert_eq!(path.sequence_shape().map(|s| (s.items_at, s.element)), Some((56, 16)));
        let fields = |s: crate::Schema| match s.kind {
            crate::schema::Kind::Struct { fields } => fields.into_iter().map(|f| f.name).collect::<Vec<_>>(),
            k => panic!("{k:?}"),
        };
        assert_eq!(fields(PlanRequest::schema()), ["x", "y", "stamp_ns"]);
        assert!(!fields(MapCell::schema()).iter().any(|f| f.starts_with("_pad")));
    }

    #[test]
    fn status_codes_round_trip_and_unknown_codes_are_none() {
        for s in PlanStatus::ALL {
            assert_eq!(PlanStatus::from_code(s as u8), Some(s));
        }
        assert_eq!(PlanStatus::from_code(0), None);
        assert_eq!(PathHeader { status: 5, ..Default::default() }.status(), Some(PlanStatus::Unreachable));
        assert_eq!(PlanStatus::GoalUnseen.name(), "goal-unseen");
    }
}
