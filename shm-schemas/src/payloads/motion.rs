//! Motion of the base ("foot"): numeric and linguistic commands, the safety
//! stop, odometry and the simulator's ground truth.
//!
//! * `nerve::VelocityCommand` — a numeric command: forward speed and turn rate;
//! * `nerve::LinguisticCommand` — a bounded, enum-coded linguistic command
//!   ("turn right a little", "increase speed", ...) with an intensity, turned
//!   into numbers by the actuator agent's fuzzy rule base;
//! * `nerve::SafetyStop` — a stop from a safety source, which always wins;
//! * `nerve::Odometry` — dead-reckoned pose and speeds;
//! * `nerve::GroundTruth` — the simulator's true pose and collision count.
//!
//! Units: metres, radians (counter-clockwise), seconds; stamps are
//! CLOCK_MONOTONIC nanoseconds.

use super::Payload;
use serde::Serialize;

/// A numeric motion command (input `cmd` of the motor agent).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::VelocityCommand")]
pub struct VelocityCommand {
    /// Forward speed, m/s (negative: backwards).
    pub v: f64,
    /// Turn rate, rad/s, positive to the left (counter-clockwise).
    pub omega: f64,
    /// When the command was made; the actuator refuses stale commands by it.
    pub stamp_ns: u64,
}

/// The terms of the linguistic command language, as carried in
/// [`LinguisticCommand::term`]. The codes are part of the wire format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[repr(u32)]
pub enum LinguisticTerm {
    /// Keep going straight ahead (turn rate to zero).
    GoForward = 1,
    /// Stop the base (speed and turn to zero).
    Stop = 2,
    /// Turn left a little.
    TurnLeftALittle = 3,
    /// Turn left much.
    TurnLeftMuch = 4,
    /// Turn right a little.
    TurnRightALittle = 5,
    /// Turn right much.
    TurnRightMuch = 6,
    /// Increase the forward speed.
    IncreaseSpeed = 7,
    /// Decrease the forward speed.
    DecreaseSpeed = 8,
    /// Head: tilt up.
    LookUp = 9,
    /// Head: tilt down.
    LookDown = 10,
    /// Head: back to straight ahead.
    LookAhead = 11,
}

impl LinguisticTerm {
    /// Every term, in code order.
    pub const ALL: [LinguisticTerm; 11] = [
        Self::GoForward,
        Self::Stop,
        Self::TurnLeftALittle,
        Self::TurnLeftMuch,
        Self::TurnRightALittle,
        Self::TurnRightMuch,
        Self::IncreaseSpeed,
        Self::DecreaseSpeed,
        Self::LookUp,
        Self::LookDown,
        Self::LookAhead,
    ];

    /// The term of a wire code; `None` for an unknown code (a misbehaving peer).
    pub fn from_code(code: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|t| *t as u32 == code)
    }

    /// The canonical phrase: `turn right a little`.
    pub fn phrase(self) -> &'static str {
        match self {
            Self::GoForward => "go forward",
            Self::Stop => "stop",
            Self::TurnLeftALittle => "turn left a little",
            Self::TurnLeftMuch => "turn left much",
            Self::TurnRightALittle => "turn right a little",
            Self::TurnRightMuch => "turn right much",
            Self::IncreaseSpeed => "increase speed",
            Self::DecreaseSpeed => "decrease speed",
            Self::LookUp => "look up",
            Self::LookDown => "look down",
            Self::LookAhead => "look ahead",
        }
    }

    /// Parses a phrase: case and extra blanks are ignored, and a few
    /// synonyms are accepted ("a little bit", "a lot", "speed up", "slow
    /// down", "forward", "halt"). `None` when it is not a known phrase; the
    /// known ones are [`LinguisticTerm::ALL`]'s [`LinguisticTerm::phrase`]s.
    pub fn parse(text: &str) -> Option<Self> {
        let norm: Vec<String> = text
            .split_whitespace()
            .map(|w| w.trim_matches(|c: char| !c.is_alphanumeric()).to_lowercase())
            .filter(|w| !w.is_empty())
            .collect();
        let s = norm.join(" ");
        let s = s.strip_suffix(" bit").unwrap_or(&s).replace("a lot", "much").replace("slightly", "a little");
        if let Some(t) = Self::ALL.into_iter().find(|t| t.phrase() == s) {
            return Some(t);
        }
        Some(match s.as_str() {
            "forward" | "go ahead" | "go straight" => Self::GoForward,
            "halt" | "stop moving" => Self::Stop,
            "speed up" | "faster" | "accelerate" => Self::IncreaseSpeed,
            "slow down" | "slower" => Self::DecreaseSpeed,
            "turn left" => Self::TurnLeftALittle,
            "turn right" => Self::TurnRightALittle,
            "look straight" | "look forward" | "center" | "centre" => Self::LookAhead,
            _ => return None,
        })
    }

    /// The canonical phrases, for error messages.
    pub fn known_phrases() -> Vec<&'static str> {
        Self::ALL.iter().map(|t| t.phrase()).collect()
    }
}

impl std::fmt::Display for LinguisticTerm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.phrase())
    }
}

/// A linguistic command (input `say` of the motor and head agents).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::LinguisticCommand")]
pub struct LinguisticCommand {
    /// A [`LinguisticTerm`] code; read it with [`LinguisticCommand::term`].
    pub term: u32,
    /// How strongly the sender means it, 0 … 1 (the truth value of the
    /// term, used as the firing strength of its rule).
    pub intensity: f32,
    /// When the command was made; the actuator refuses stale commands by it.
    pub stamp_ns: u64,
}

impl LinguisticCommand {
    /// A command of `term` with `intensity` (clamped to 0 … 1).
    pub fn new(term: LinguisticTerm, intensity: f32, stamp_ns: u64) -> Self {
        LinguisticCommand { term: term as u32, intensity: intensity.clamp(0.0, 1.0), stamp_ns }
    }

    /// The term, or `None` for an unknown code.
    pub fn term(&self) -> Option<LinguisticTerm> {
        LinguisticTerm::from_code(self.term)
    }
}

/// A stop from a safety source (input `stop` of the motor agent). An active
/// stop overrides every other source.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::SafetyStop")]
pub struct SafetyStop {
    /// 1: stop; 0: this source releases its stop.
    pub active: u8,
    /// 1: stop moving but allow turning on the spot (the thesis' safety
    /// monitor: "stop moving (but not turning)"); 0: stop everything.
    pub allow_turn: u8,
    /// Padding, zero.
    pub reserved: [u8; 2],
    /// How long the stop holds without being repeated, ms; 0 = until released.
    pub hold_ms: u32,
    /// When the stop was sent.
    pub stamp_ns: u64,
}

/// Dead-reckoned pose and speeds (output `odom` of the motor agent).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::Odometry")]
pub struct Odometry {
    /// x, metres, in the odometry frame (the start pose is the origin unless configured).
    pub x: f64,
    /// y, metres.
    pub y: f64,
    /// Heading, radians, (-π, π].
    pub theta: f64,
    /// Measured forward speed, m/s.
    pub v: f64,
    /// Measured turn rate, rad/s.
    pub omega: f64,
    /// When the encoder report it integrates was received.
    pub stamp_ns: u64,
}

/// The simulator's ground truth (output `truth` of the `sim` agent).
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::GroundTruth")]
pub struct GroundTruth {
    /// Simulated time, s.
    pub sim_time: f64,
    /// True x, metres, world frame.
    pub x: f64,
    /// True y, metres.
    pub y: f64,
    /// True heading, radians.
    pub theta: f64,
    /// True forward speed, m/s.
    pub v: f64,
    /// True turn rate, rad/s.
    pub omega: f64,
    /// Collisions so far.
    pub collisions: u64,
    /// 1 while touching an obstacle.
    pub in_contact: u8,
    /// Padding, zero.
    pub reserved: [u8; 7],
    /// CLOCK_MONOTONIC nanoseconds of the step.
    pub stamp_ns: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<VelocityCommand>(), 24);
        assert_eq!(std::mem::size_of::<LinguisticCommand>(), 16);
        assert_eq!(std::mem::offset_of!(LinguisticCommand, stamp_ns), 8);
        assert_eq!(std::mem::size_of::<SafetyStop>(), 16);
        assert_eq!(std::mem::offset_of!(SafetyStop, hold_ms), 4);
        assert_eq!(std::mem::size_of::<Odometry>(), 48);
        assert_eq!(std::mem::size_of::<GroundTruth>(), 72);
        assert_eq!(std::mem::offset_of!(GroundTruth, stamp_ns), 64);
        for (name, got) in [
            ("nerve::VelocityCommand", <VelocityCommand as Payload>::stable_type_name()),
            ("nerve::LinguisticCommand", <LinguisticCommand as Payload>::stable_type_name()),
            ("nerve::SafetyStop", <SafetyStop as Payload>::stable_type_name()),
            ("nerve::Odometry", <Odometry as Payload>::stable_type_name()),
            ("nerve::GroundTruth", <GroundTruth as Payload>::stable_type_name()),
        ] {
            assert_eq!(got, name);
        }
    }

    #[test]
    fn phrases_round_trip_and_synonyms() {
        for t in LinguisticTerm::ALL {
            assert_eq!(LinguisticTerm::parse(t.phrase()), Some(t));
            assert_eq!(LinguisticTerm::from_code(t as u32), Some(t));
        }
        assert_eq!(LinguisticTerm::parse("  Turn RIGHT a little bit! "), Some(LinguisticTerm::TurnRightALittle));
        assert_eq!(LinguisticTerm::parse("turn left a lot"), Some(LinguisticTerm::TurnLeftMuch));
        assert_eq!(LinguisticTerm::parse("slow down"), Some(LinguisticTerm::DecreaseSpeed));
        assert_eq!(LinguisticTerm::parse("dance"), None);
        assert_eq!(LinguisticTerm::from_code(0), None);
        let c = LinguisticCommand::new(LinguisticTerm::Stop, 3.0, 1);
        assert_eq!((c.term(), c.intensity), (Some(LinguisticTerm::Stop), 1.0));
    }
}
