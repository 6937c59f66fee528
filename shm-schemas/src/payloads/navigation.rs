//! Navigation and cooperation (thesis section 4.3, Fig. 4-8 and 4-9): the
//! robot's pose estimate and its corrections at checkpoints, what the
//! checkpoint sensor sees, the path of via points robot 1 sends robot 2,
//! and the mission messages between them.
//!
//! * `nerve::PoseEstimate` — the odometry agent's pose in the world frame
//!   (dead reckoning plus checkpoint corrections), with the count of
//!   corrections so far;
//! * `nerve::PoseCorrection` — the checkpoint sensor's corrected pose at the
//!   instant of an observation (the odometry agent applies it there and
//!   carries the motion since then over);
//! * `nerve::CheckpointSighting` — a checkpoint or the target seen: its id,
//!   the IR transmitters received, range and bearing from the robot, and its
//!   position and facing direction in the world frame;
//! * [`ViaPath`] = `Seq<ViaPoint, ViaPathHeader>` — a path of any length:
//!   its via points in order (each with its kind, checkpoint and landmark),
//!   the last one possibly the target itself; [`ViaPathBuf`] is a copy of one
//!   an agent keeps;
//! * `nerve::MissionCommand` — "come" (follow path N), "via point reached",
//!   "arrived", "resume", "abort".
//!
//! Units: metres, radians (counter-clockwise, world frame unless a field
//! says "robot frame"), seconds; stamps are CLOCK_MONOTONIC nanoseconds of
//! the robot that made them (they do not compare across robots). Enumerations
//! travel as integer codes; read them with the `from_code` functions, which
//! return `None` for a code this build does not know.

use super::Payload;
use crate::seq::Seq;
use serde::Serialize;

/// Where a pose estimate or correction comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[repr(u8)]
pub enum PoseSource {
    /// Dead reckoning only since the start pose.
    DeadReckoning = 1,
    /// The last change was a checkpoint correction.
    Checkpoint = 2,
    /// Set by hand (a parameter or a tool).
    Manual = 3,
}

impl PoseSource {
    /// Every source, in code order.
    pub const ALL: [PoseSource; 3] = [Self::DeadReckoning, Self::Checkpoint, Self::Manual];

    /// The source of a wire code; `None` for an unknown code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|s| *s as u8 == code)
    }

    /// `dead-reckoning`, `checkpoint`, `manual`.
    pub fn name(self) -> &'static str {
        match self {
            Self::DeadReckoning => "dead-reckoning",
            Self::Checkpoint => "checkpoint",
            Self::Manual => "manual",
        }
    }
}

/// [`PoseCorrection::fields`] bit: the position is corrected.
pub const CORRECTS_POSITION: u8 = 1;
/// [`PoseCorrection::fields`] bit: the heading is corrected.
pub const CORRECTS_HEADING: u8 = 2;

/// The robot's pose in the world frame (output `pose` of the `odometry` agent).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::PoseEstimate")]
pub struct PoseEstimate {
    /// x, metres, world frame.
    pub x: f64,
    /// y, metres, world frame.
    pub y: f64,
    /// Heading, radians, (-π, π].
    pub theta: f64,
    /// Forward speed, m/s (from the motor's odometry).
    pub v: f64,
    /// Turn rate, rad/s.
    pub omega: f64,
    /// The instant the pose holds for (the stamp of the motor's report).
    pub stamp_ns: u64,
    /// Checkpoint corrections applied since the start.
    pub corrections: u32,
    /// A [`PoseSource`] code: what changed the pose last.
    pub source: u8,
    /// The checkpoint of the last correction, 0 when none yet.
    pub last_checkpoint: u8,
    /// Padding, zero.
    pub reserved: [u8; 2],
}

impl PoseEstimate {
    /// The source, or `None` for an unknown code.
    pub fn source(&self) -> Option<PoseSource> {
        PoseSource::from_code(self.source)
    }
}

/// A corrected pose at the instant of an observation (output `correction`
/// of the `checkpoint` agent, input `correction` of the `odometry` agent).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::PoseCorrection")]
pub struct PoseCorrection {
    /// Corrected x at `stamp_ns`, metres, world frame.
    pub x: f64,
    /// Corrected y, metres.
    pub y: f64,
    /// Corrected heading, radians (equal to the estimate's when
    /// [`CORRECTS_HEADING`] is not set).
    pub theta: f64,
    /// The known position of the checkpoint seen, x, metres, world frame
    /// (so that the odometry agent can refine the heading from two
    /// checkpoints, see `nerve-odometry`).
    pub checkpoint_x: f64,
    /// The known position of the checkpoint seen, y, metres.
    pub checkpoint_y: f64,
    /// The instant of the observation (the camera frame's stamp).
    pub stamp_ns: u64,
    /// Range to the checkpoint's centre, metres.
    pub range_m: f32,
    /// Bearing of the checkpoint, radians, robot frame, positive left.
    pub bearing_rad: f32,
    /// [`CORRECTS_POSITION`] | [`CORRECTS_HEADING`].
    pub fields: u8,
    /// A [`PoseSource`] code (normally `Checkpoint`).
    pub source: u8,
    /// The checkpoint that was seen.
    pub checkpoint_id: u8,
    /// Padding, zero.
    pub reserved: [u8; 5],
}

impl PoseCorrection {
    /// The source, or `None` for an unknown code.
    pub fn source(&self) -> Option<PoseSource> {
        PoseSource::from_code(self.source)
    }
}

/// A checkpoint (or the target) seen by the checkpoint sensor (output
/// `sighting` of the `checkpoint` agent, input `sighting` of the map builder).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::CheckpointSighting")]
pub struct CheckpointSighting {
    /// The instant of the observation (the camera frame's stamp).
    pub stamp_ns: u64,
    /// The tube's centre, x, metres, world frame (the known position of a
    /// configured checkpoint; estimated from the pose otherwise).
    pub x: f64,
    /// The tube's centre, y, metres.
    pub y: f64,
    /// Range from the camera to the tube's centre, metres.
    pub range_m: f32,
    /// Bearing of the tube, radians, robot frame, positive left.
    pub bearing_rad: f32,
    /// The direction the transmitter(s) received face, radians, world
    /// frame ("in front of" the checkpoint); when no heading of the tube is
    /// known, the direction from the tube to the robot.
    pub facing_rad: f32,
    /// The checkpoint's IR code, 0 when it was not identified by IR.
    pub checkpoint_id: u8,
    /// The IR transmitters received (bit `i`: the one facing `i × 90°`
    /// from the checkpoint's heading), 0 when none.
    pub transmitters: u8,
    /// 1 when the IR receiver identified it.
    pub from_ir: u8,
    /// 1 when the range comes from the camera (Appendix A).
    pub from_camera: u8,
    /// 1 for the target (the tube upside down).
    pub is_target: u8,
    /// Padding, zero.
    pub reserved: [u8; 7],
}

/// The most via points the nerve agents' path ports are declared with (a
/// path's `max_len`); a path is as long as it is, up to this.
pub const VIA_PATH_MAX_LEN: usize = 1024;

/// What a point of a [`ViaPath`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[repr(u8)]
pub enum ViaKind {
    /// A via point in front of a checkpoint (a correction is expected near it).
    Checkpoint = 1,
    /// The via point in front of the target.
    TargetApproach = 2,
    /// The target itself: stop short of it (the follower keeps a stand-off).
    Target = 3,
    /// Any other point (a corner of the path).
    Waypoint = 4,
}

impl ViaKind {
    /// Every kind, in code order.
    pub const ALL: [ViaKind; 4] = [Self::Checkpoint, Self::TargetApproach, Self::Target, Self::Waypoint];

    /// The kind of a wire code; `None` for an unknown code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|k| *k as u8 == code)
    }

    /// `checkpoint`, `target-approach`, `target`, `waypoint`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Checkpoint => "checkpoint",
            Self::TargetApproach => "target-approach",
            Self::Target => "target",
            Self::Waypoint => "waypoint",
        }
    }
}

/// The header of a [`ViaPath`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::ViaPathHeader")]
pub struct ViaPathHeader {
    /// When the path was made (sender's clock).
    pub stamp_ns: u64,
    /// Identifies this path; a new path gets a new id (from 1).
    pub path_id: u32,
    /// Padding, zero.
    #[serde(skip)]
    pub _pad: [u8; 4],
}

/// One via point of a [`ViaPath`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::ViaPoint")]
pub struct ViaPoint {
    /// Where to go, `[x, y]`, metres, world frame.
    pub point: [f64; 2],
    /// The landmark the point belongs to (the checkpoint's or the target's
    /// position, `[x, y]`, world frame), for the follower to look at and
    /// localise by; the point itself when it belongs to none.
    pub landmark: [f64; 2],
    /// A [`ViaKind`] code.
    pub kind: u8,
    /// The checkpoint the point belongs to, 0 for none.
    pub checkpoint_id: u8,
    /// Padding, zero.
    #[serde(skip)]
    pub _pad: [u8; 6],
}

impl ViaPoint {
    /// A point of `kind` at `point`, of checkpoint `checkpoint_id` (0: none),
    /// belonging to `landmark`.
    pub fn new(point: [f64; 2], kind: ViaKind, checkpoint_id: u8, landmark: [f64; 2]) -> Self {
        ViaPoint { point, landmark, kind: kind as u8, checkpoint_id, _pad: [0; 6] }
    }
}

/// A path of via points of any length (output `path` of the map builder or
/// of robot 1's mission agent, carried to robot 2 by the bridge, input
/// `path` of the target achiever): a [`ViaPathHeader`], then the points in
/// the order to visit.
pub type ViaPath = Seq<ViaPoint, ViaPathHeader>;

/// A copy of a [`ViaPath`] sample, for an agent that keeps it past a step.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ViaPathBuf {
    /// Its header.
    pub header: ViaPathHeader,
    /// Its points, in the order to visit.
    pub points: Vec<ViaPoint>,
}

impl ViaPathBuf {
    /// An empty path `path_id`, made at `stamp_ns`.
    pub fn new(path_id: u32, stamp_ns: u64) -> Self {
        ViaPathBuf { header: ViaPathHeader { stamp_ns, path_id, _pad: [0; 4] }, points: Vec::new() }
    }

    /// A copy of a sample's header and points.
    pub fn of(header: &ViaPathHeader, points: &[ViaPoint]) -> Self {
        ViaPathBuf { header: *header, points: points.to_vec() }
    }

    /// The path's id.
    pub fn path_id(&self) -> u32 {
        self.header.path_id
    }

    /// The points with their kind codes and checkpoint ids.
    pub fn entries(&self) -> impl Iterator<Item = ([f64; 2], u8, u8)> + '_ {
        self.points.iter().map(|p| (p.point, p.kind, p.checkpoint_id))
    }

    /// The sample's bytes (the header, then the points), as a sequence port
    /// carries them: for tools and tests that handle bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(size_of::<ViaPathHeader>() + self.points.len() * size_of::<ViaPoint>());
        // SAFETY: `ViaPathHeader` and `ViaPoint` are `#[repr(C)]`, `Copy` and
        // without padding (`#[derive(Payload)]` checks it: `_pad` fills
        // theirs), so all their bytes are initialised; the views live only
        // for the copies.
        unsafe {
            out.extend_from_slice(std::slice::from_raw_parts(
                (&self.header as *const ViaPathHeader).cast::<u8>(),
                size_of::<ViaPathHeader>(),
            ));
            out.extend_from_slice(std::slice::from_raw_parts(
                self.points.as_ptr().cast::<u8>(),
                self.points.len() * size_of::<ViaPoint>(),
            ));
        }
        out
    }

    /// A sample read from its bytes; `None` unless they are a header and
    /// whole points.
    pub fn from_bytes(bytes: &[u8]) -> Option<Self> {
        let (head, rest) = bytes.split_at_checked(size_of::<ViaPathHeader>())?;
        if !rest.len().is_multiple_of(size_of::<ViaPoint>()) {
            return None;
        }
        // SAFETY: `head` holds size_of::<ViaPathHeader>() bytes and each chunk
        // size_of::<ViaPoint>(); both types are plain data of any bits
        // (`AnyBitPattern`, given by `#[derive(Payload)]`), and
        // `read_unaligned` needs no alignment.
        let header = unsafe { std::ptr::read_unaligned(head.as_ptr().cast::<ViaPathHeader>()) };
        let points = rest
            .chunks_exact(size_of::<ViaPoint>())
            // SAFETY: as above, for one point's bytes
            .map(|c| unsafe { std::ptr::read_unaligned(c.as_ptr().cast::<ViaPoint>()) })
            .collect();
        Some(ViaPathBuf { header, points })
    }
}

/// What a [`MissionCommand`] says.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[repr(u32)]
pub enum MissionCode {
    /// Robot 1 to robot 2: come, follow path `path_id`.
    Come = 1,
    /// Robot 2: via point `index` of path `path_id` reached.
    ViaReached = 2,
    /// Robot 2 to robot 1: the last point of path `path_id` reached.
    Arrived = 3,
    /// Resume exploring (robot 1's decision maker, after "arrived").
    Resume = 4,
    /// Stop following the path.
    Abort = 5,
}

impl MissionCode {
    /// Every code, in code order.
    pub const ALL: [MissionCode; 5] = [Self::Come, Self::ViaReached, Self::Arrived, Self::Resume, Self::Abort];

    /// The code of a wire value; `None` for an unknown one.
    pub fn from_code(code: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|c| *c as u32 == code)
    }

    /// `come`, `via-reached`, `arrived`, `resume`, `abort`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Come => "come",
            Self::ViaReached => "via-reached",
            Self::Arrived => "arrived",
            Self::Resume => "resume",
            Self::Abort => "abort",
        }
    }
}

/// A mission message between the robots' agents (map builder → target
/// achiever: "come"; target achiever → robot 1: "via-reached", "arrived").
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::MissionCommand")]
pub struct MissionCommand {
    /// When it was made (sender's clock).
    pub stamp_ns: u64,
    /// Where the sender believed it was, x, metres, world frame.
    pub x: f64,
    /// Where the sender believed it was, y, metres.
    pub y: f64,
    /// A [`MissionCode`]; read it with [`MissionCommand::code`].
    pub code: u32,
    /// The path it is about (0: none).
    pub path_id: u32,
    /// The via point it is about (`ViaReached`, `Arrived`), from 0.
    pub index: u32,
    /// Padding, zero.
    pub reserved: u32,
}

impl MissionCommand {
    /// A message of `code` about `path_id`.
    pub fn new(code: MissionCode, path_id: u32, stamp_ns: u64) -> Self {
        MissionCommand { code: code as u32, path_id, stamp_ns, ..Default::default() }
    }

    /// The code, or `None` for an unknown one.
    pub fn code(&self) -> Option<MissionCode> {
        MissionCode::from_code(self.code)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<PoseEstimate>(), 56);
        assert_eq!(std::mem::align_of::<PoseEstimate>(), 8);
        assert_eq!(std::mem::offset_of!(PoseEstimate, corrections), 48);
        assert_eq!(std::mem::offset_of!(PoseEstimate, source), 52);
        assert_eq!(std::mem::size_of::<PoseCorrection>(), 64);
        assert_eq!(std::mem::offset_of!(PoseCorrection, stamp_ns), 40);
        assert_eq!(std::mem::offset_of!(PoseCorrection, range_m), 48);
        assert_eq!(std::mem::offset_of!(PoseCorrection, fields), 56);
        assert_eq!(std::mem::size_of::<CheckpointSighting>(), 48);
        assert_eq!(std::mem::offset_of!(CheckpointSighting, facing_rad), 32);
        assert_eq!(std::mem::offset_of!(CheckpointSighting, checkpoint_id), 36);
        assert_eq!(std::mem::offset_of!(CheckpointSighting, is_target), 40);
        assert_eq!(std::mem::size_of::<ViaPathHeader>(), 16);
        assert_eq!(std::mem::size_of::<ViaPoint>(), 40);
        assert_eq!(std::mem::offset_of!(ViaPoint, landmark), 16);
        assert_eq!(std::mem::offset_of!(ViaPoint, kind), 32);
        assert_eq!(std::mem::offset_of!(ViaPoint, checkpoint_id), 33);
        assert_eq!(std::mem::size_of::<MissionCommand>(), 40);
        assert_eq!(std::mem::offset_of!(MissionCommand, code), 24);
        for (name, got) in [
            ("nerve::PoseEstimate", <PoseEstimate as Payload>::stable_type_name()),
            ("nerve::PoseCorrection", <PoseCorrection as Payload>::stable_type_name()),
            ("nerve::CheckpointSighting", <CheckpointSighting as Payload>::stable_type_name()),
            ("nerve::ViaPathHeader", <ViaPathHeader as Payload>::stable_type_name()),
            ("nerve::ViaPoint", <ViaPoint as Payload>::stable_type_name()),
            ("nerve::MissionCommand", <MissionCommand as Payload>::stable_type_name()),
        ] {
            assert_eq!(got, name);
        }
    }

    #[test]
    fn codes_round_trip_and_unknown_codes_are_none() {
        for s in PoseSource::ALL {
            assert_eq!(PoseSource::from_code(s as u8), Some(s));
        }
        for k in ViaKind::ALL {
            assert_eq!(ViaKind::from_code(k as u8), Some(k));
        }
        for c in MissionCode::ALL {
            assert_eq!(MissionCode::from_code(c as u32), Some(c));
        }
        assert_eq!(PoseSource::from_code(0), None);
        assert_eq!(ViaKind::from_code(9), None);
        assert_eq!(MissionCode::from_code(0), None);
        let m = MissionCommand::new(MissionCode::Arrived, 3, 7);
        assert_eq!((m.code(), m.path_id), (Some(MissionCode::Arrived), 3));
        assert_eq!(MissionCommand { code: 99, ..m }.code(), None);
        assert_eq!(PoseEstimate { source: 2, ..Default::default() }.source(), Some(PoseSource::Checkpoint));
    }

    /// A path is a sequence of any length; its bytes are the header and
    /// its points, as a sequence port carries them, and read back the same.
    #[test]
    fn a_path_is_a_sequence_and_round_trips_through_its_bytes() {
        use crate::schema::Described;
        let schema = ViaPath::schema();
        assert_eq!(schema.type_name, "nerve::Seq<nerve::ViaPoint, nerve::ViaPathHeader>");
        assert_eq!(schema.validate(), Ok(()));
        let shape = schema.sequence_shape().expect("a sequence");
        assert_eq!((shape.items_at, shape.element), (16, 40));
        let mut p = ViaPathBuf::new(7, 9);
        assert_eq!(ViaPathBuf::from_bytes(&p.to_bytes()), Some(p.clone()), "no point");
        p.points.push(ViaPoint::new([1.0, 2.0], ViaKind::Checkpoint, 3, [1.0, 3.6]));
        p.points.push(ViaPoint::new([4.0, 2.0], ViaKind::Target, 0, [4.0, 2.0]));
        let bytes = p.to_bytes();
        assert_eq!(bytes.len(), 16 + 2 * 40);
        assert_eq!(schema.decode_path("items[1].kind", &bytes), Some(crate::schema::Value::Unsigned(3)));
        assert_eq!(ViaPathBuf::from_bytes(&bytes), Some(p.clone()));
        assert_eq!(p.entries().nth(1), Some(([4.0, 2.0], ViaKind::Target as u8, 0)));
        assert_eq!(ViaPathBuf::from_bytes(&bytes[..17]), None, "not whole points");
        assert_eq!(ViaPathBuf::from_bytes(&bytes[..8]), None, "not a header");
    }
}

// ---- the grasp (H2's arm; appended with the arm agent) ----

/// What a [`GraspRequest`] asks of the arm agent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[repr(u8)]
pub enum GraspAction {
    /// Reach for the target and close the gripper on it.
    Grasp = 1,
    /// Open the gripper, let go and fold the arm back.
    Release = 2,
}

impl GraspAction {
    /// Every action, in code order.
    pub const ALL: [GraspAction; 2] = [Self::Grasp, Self::Release];

    /// The action of a wire code; `None` for an unknown code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|a| *a as u8 == code)
    }

    /// `grasp`, `release`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Grasp => "grasp",
            Self::Release => "release",
        }
    }
}

/// A request to the arm agent (input `cmd` of the `arm` agent; robot 2's
/// mission agent sends it at the target).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::GraspRequest")]
pub struct GraspRequest {
    /// When it was made.
    pub stamp_ns: u64,
    /// Where the sender believes the target's axis is, x, metres, robot
    /// frame (forward); meaningful when `has_point` is 1.
    pub x: f64,
    /// Where the sender believes the target's axis is, y, metres, robot
    /// frame (left).
    pub y: f64,
    /// Identifies the request (from 1); the arm's [`ArmGraspState`] echoes it.
    pub request_id: u32,
    /// A [`GraspAction`] code; read it with [`GraspRequest::action`].
    pub action: u8,
    /// 1 when `x`, `y` hold a guess of where the target is.
    pub has_point: u8,
    /// Padding, zero.
    pub reserved: [u8; 2],
}

impl GraspRequest {
    /// The action, or `None` for an unknown code.
    pub fn action(&self) -> Option<GraspAction> {
        GraspAction::from_code(self.action)
    }
}

/// Where a grasp stands, as the arm agent reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[repr(u8)]
pub enum GraspPhase {
    /// Open, holding nothing, no grasp under way.
    Open = 0,
    /// Opening, probing or reaching: the arm moves.
    Moving = 1,
    /// Closing on the target; the outcome is not known yet.
    Closing = 2,
    /// Closed on the target: `held_id` names it.
    Holding = 3,
    /// The grasp failed: `reason` says why.
    Missed = 4,
}

impl GraspPhase {
    /// Every phase, in code order.
    pub const ALL: [GraspPhase; 5] = [Self::Open, Self::Moving, Self::Closing, Self::Holding, Self::Missed];

    /// The phase of a wire code; `None` for an unknown code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|p| *p as u8 == code)
    }

    /// `open`, `moving`, `closing`, `holding`, `missed`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Open => "open",
            Self::Moving => "moving",
            Self::Closing => "closing",
            Self::Holding => "holding",
            Self::Missed => "missed",
        }
    }

    /// Whether the grasp is decided (holding or missed).
    pub fn is_final(self) -> bool {
        matches!(self, Self::Holding | Self::Missed)
    }
}

/// Why a grasp missed ([`ArmGraspState::reason`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[repr(u8)]
pub enum GraspMiss {
    /// Not missed.
    None = 0,
    /// The gripper closed on nothing.
    ClosedEmpty = 1,
    /// The proximity sensor located no target within the arm's reach.
    OutOfReach = 2,
    /// The arm board reported no target at all.
    NoTarget = 3,
    /// The arm did not reach its set-point, or the board did not answer, in time.
    Timeout = 4,
    /// The arm board vanished during the grasp.
    DeviceLost = 5,
    /// A release (or a new request) ended the grasp.
    Cancelled = 6,
}

impl GraspMiss {
    /// Every reason, in code order.
    pub const ALL: [GraspMiss; 7] = [
        Self::None,
        Self::ClosedEmpty,
        Self::OutOfReach,
        Self::NoTarget,
        Self::Timeout,
        Self::DeviceLost,
        Self::Cancelled,
    ];

    /// The reason of a wire code; `None` for an unknown code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|r| *r as u8 == code)
    }

    /// `none`, `closed-empty`, `out-of-reach`, `no-target`, `timeout`, `device-lost`, `cancelled`.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::ClosedEmpty => "closed-empty",
            Self::OutOfReach => "out-of-reach",
            Self::NoTarget => "no-target",
            Self::Timeout => "timeout",
            Self::DeviceLost => "device-lost",
            Self::Cancelled => "cancelled",
        }
    }
}

/// [`ArmGraspState::held_id`] when nothing is held.
pub const HELD_NOTHING: u8 = 0xFF;

/// The arm agent's report (output `state` of the `arm` agent), 10 Hz and
/// at every change of phase.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::ArmGraspState")]
pub struct ArmGraspState {
    /// When the board's report was read.
    pub stamp_ns: u64,
    /// Measured joints (shoulder, elbow, gripper), radians.
    pub joints_rad: [f32; 3],
    /// Distance from the gripper's tip to the nearest target's axis,
    /// metres; negative when the board sees none.
    pub nearest_m: f32,
    /// The request this state belongs to (0: none yet).
    pub request_id: u32,
    /// A [`GraspPhase`] code; read it with [`ArmGraspState::phase`].
    pub phase: u8,
    /// The held tube's id while holding, [`HELD_NOTHING`] otherwise.
    pub held_id: u8,
    /// A [`GraspMiss`] code (`missed` only).
    pub reason: u8,
    /// 1 while the arm board is connected.
    pub connected: u8,
}

impl ArmGraspState {
    /// The phase, or `None` for an unknown code.
    pub fn phase(&self) -> Option<GraspPhase> {
        GraspPhase::from_code(self.phase)
    }

    /// The reason of a miss, or `None` for an unknown code.
    pub fn reason(&self) -> Option<GraspMiss> {
        GraspMiss::from_code(self.reason)
    }
}

#[cfg(test)]
mod grasp_tests {
    use super::*;

    #[test]
    fn grasp_layout_is_stable_and_codes_round_trip() {
        assert_eq!(std::mem::size_of::<GraspRequest>(), 32);
        assert_eq!(std::mem::offset_of!(GraspRequest, request_id), 24);
        assert_eq!(std::mem::offset_of!(GraspRequest, action), 28);
        assert_eq!(std::mem::size_of::<ArmGraspState>(), 32);
        assert_eq!(std::mem::align_of::<ArmGraspState>(), 8);
        assert_eq!(std::mem::offset_of!(ArmGraspState, request_id), 24);
        assert_eq!(std::mem::offset_of!(ArmGraspState, phase), 28);
        assert_eq!(<GraspRequest as Payload>::stable_type_name(), "nerve::GraspRequest");
        assert_eq!(<ArmGraspState as Payload>::stable_type_name(), "nerve::ArmGraspState");
        for a in GraspAction::ALL {
            assert_eq!(GraspAction::from_code(a as u8), Some(a));
        }
        for p in GraspPhase::ALL {
            assert_eq!(GraspPhase::from_code(p as u8), Some(p));
        }
        for r in GraspMiss::ALL {
            assert_eq!(GraspMiss::from_code(r as u8), Some(r));
        }
        assert_eq!(GraspAction::from_code(0), None);
        assert_eq!(GraspPhase::from_code(9), None);
        assert_eq!(GraspMiss::from_code(99), None);
        assert!(GraspPhase::Missed.is_final() && !GraspPhase::Closing.is_final());
    }
}
