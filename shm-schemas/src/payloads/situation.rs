//! `nerve::Situation` and `nerve::Mode`: what the functional agents report
//! to the global decision maker, and the mode it decides (thesis sections
//! 3.2.5 and 4.2.2.4).
//!
//! * `nerve::Situation` — one functional agent's view of the robot's
//!   situation: the danger it sees (the safety monitor) and the target it
//!   sees (the image tracker). A report says which of the two it speaks
//!   about ([`Situation::reports`]); the decision maker combines the fresh
//!   reports of every sender.
//! * `nerve::Mode` — the decision maker's current mode (a row of its
//!   knowledge base) and the situation that selected it.
//!
//! Levels are small enumerations coded as `u8` on the wire; read them with
//! [`DangerLevel::from_code`] and [`TargetState::from_code`].

use super::Payload;
use crate::fixed::FixedName;
use serde::Serialize;

/// [`Situation::reports`] bit: the report speaks about danger.
pub const REPORTS_DANGER: u8 = 1;
/// [`Situation::reports`] bit: the report speaks about the target.
pub const REPORTS_TARGET: u8 = 2;

/// How dangerous the surroundings are, as the safety monitor judges them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[repr(u8)]
pub enum DangerLevel {
    /// Nothing near.
    None = 0,
    /// Something in the slow-down range, or a narrow place.
    Low = 1,
    /// Something near, or approaching fast.
    High = 2,
    /// Too close: the safety monitor stops the robot (turning still allowed).
    Stop = 3,
}

impl DangerLevel {
    /// Every level, lowest first.
    pub const ALL: [DangerLevel; 4] = [Self::None, Self::Low, Self::High, Self::Stop];

    /// The level of a wire code; `None` for an unknown code (a misbehaving peer).
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|l| *l as u8 == code)
    }

    /// The level's name: `none`, `low`, `high`, `stop`.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Low => "low",
            Self::High => "high",
            Self::Stop => "stop",
        }
    }
}

/// What the image tracker sees of its target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[repr(u8)]
pub enum TargetState {
    /// No target in sight.
    None = 0,
    /// A target is in sight, not yet close.
    Seen = 1,
    /// The target is close: the tracker stops the robot in front of it.
    Close = 2,
}

impl TargetState {
    /// Every state, in code order.
    pub const ALL: [TargetState; 3] = [Self::None, Self::Seen, Self::Close];

    /// The state of a wire code; `None` for an unknown code.
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|l| *l as u8 == code)
    }

    /// The state's name: `none`, `seen`, `close`.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Seen => "seen",
            Self::Close => "close",
        }
    }
}

/// A functional agent's report of the situation (output `situation` of the
/// `safety` and `tracker` agents, input `situation` of the decision maker).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::Situation")]
pub struct Situation {
    /// CLOCK_MONOTONIC nanoseconds when the situation was judged.
    pub stamp_ns: u64,
    /// Danger, 0 (none) … 1 (collision imminent); meaningful with [`REPORTS_DANGER`].
    pub danger: f32,
    /// Target area as a fraction of the image, 0 … 1; meaningful with [`REPORTS_TARGET`].
    pub target_size: f32,
    /// Bearing of the target from the robot's forward axis, radians,
    /// positive to the left; meaningful when a target is seen.
    pub target_bearing_rad: f32,
    /// A [`DangerLevel`] code.
    pub danger_level: u8,
    /// A [`TargetState`] code.
    pub target: u8,
    /// Which parts this report speaks about: [`REPORTS_DANGER`] | [`REPORTS_TARGET`].
    pub reports: u8,
    /// Padding, zero.
    pub reserved: u8,
}

impl Situation {
    /// A danger report.
    pub fn danger(level: DangerLevel, danger: f32, stamp_ns: u64) -> Self {
        Situation {
            stamp_ns,
            danger: danger.clamp(0.0, 1.0),
            danger_level: level as u8,
            reports: REPORTS_DANGER,
            ..Default::default()
        }
    }

    /// A target report.
    pub fn target(state: TargetState, size: f32, bearing_rad: f32, stamp_ns: u64) -> Self {
        Situation {
            stamp_ns,
            target_size: size.clamp(0.0, 1.0),
            target_bearing_rad: bearing_rad,
            target: state as u8,
            reports: REPORTS_TARGET,
            ..Default::default()
        }
    }

    /// The danger level, when this report speaks about danger with a known code.
    pub fn danger_level(&self) -> Option<DangerLevel> {
        (self.reports & REPORTS_DANGER != 0).then(|| DangerLevel::from_code(self.danger_level)).flatten()
    }

    /// The target state, when this report speaks about the target with a known code.
    pub fn target_state(&self) -> Option<TargetState> {
        (self.reports & REPORTS_TARGET != 0).then(|| TargetState::from_code(self.target)).flatten()
    }
}

/// The decision maker's mode (output `mode` of the `decision` agent).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::Mode")]
pub struct Mode {
    /// The mode's name in the knowledge base (`explore`, `track`, `avoid`...).
    pub name: FixedName,
    /// The mode's index in the knowledge base (order of `[modes.*]` tables).
    pub index: u32,
    /// CLOCK_MONOTONIC nanoseconds since when this mode holds.
    pub since_ns: u64,
    /// Mode changes since the decision maker started.
    pub changes: u64,
    /// CLOCK_MONOTONIC nanoseconds when this was published.
    pub stamp_ns: u64,
    /// The danger level that selected the mode; 255 when unknown.
    pub danger_level: u8,
    /// The target state that selected the mode; 255 when unknown.
    pub target: u8,
    /// The load level (`nerve::ResourceHeader::level` of the resource manager's report) that selected the mode; 255 when unknown.
    pub load_level: u8,
    /// Padding, zero.
    pub reserved: [u8; 5],
}

/// Code of an unknown level in [`Mode`].
pub const UNKNOWN_LEVEL: u8 = 255;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<Situation>(), 24);
        assert_eq!(std::mem::align_of::<Situation>(), 8);
        assert_eq!(std::mem::offset_of!(Situation, target_bearing_rad), 16);
        assert_eq!(std::mem::offset_of!(Situation, danger_level), 20);
        assert_eq!(std::mem::offset_of!(Situation, reports), 22);
        assert_eq!(std::mem::size_of::<Mode>(), 72);
        assert_eq!(std::mem::offset_of!(Mode, index), 36);
        assert_eq!(std::mem::offset_of!(Mode, since_ns), 40);
        assert_eq!(std::mem::offset_of!(Mode, danger_level), 64);
        assert_eq!(<Situation as Payload>::stable_type_name(), "nerve::Situation");
        assert_eq!(<Mode as Payload>::stable_type_name(), "nerve::Mode");
    }

    #[test]
    fn reports_say_what_they_speak_about() {
        let d = Situation::danger(DangerLevel::High, 2.0, 5);
        assert_eq!((d.danger_level(), d.target_state(), d.danger), (Some(DangerLevel::High), None, 1.0));
        let t = Situation::target(TargetState::Close, 0.3, 0.1, 5);
        assert_eq!((t.danger_level(), t.target_state()), (None, Some(TargetState::Close)));
        let bad = Situation { reports: REPORTS_DANGER, danger_level: 9, ..Default::default() };
        assert_eq!(bad.danger_level(), None);
        assert!(DangerLevel::Low < DangerLevel::Stop);
        for l in DangerLevel::ALL {
            assert_eq!(DangerLevel::from_code(l as u8), Some(l));
        }
    }
}
