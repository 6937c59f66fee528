//! `nerve::HeadCommand` and `nerve::HeadState`: the pan-tilt head of H1
//! (the camera's neck).
//!
//! Angles are radians: pan positive to the left (counter-clockwise), tilt
//! positive up. The head board accepts pan ±100° and tilt ±30°.

use super::Payload;
use serde::Serialize;

/// A numeric set-point for the head agent's input `cmd`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::HeadCommand")]
pub struct HeadCommand {
    /// Pan, radians, positive to the left.
    pub pan_rad: f64,
    /// Tilt, radians, positive up.
    pub tilt_rad: f64,
    /// CLOCK_MONOTONIC nanoseconds when the command was made (staleness is judged by it).
    pub stamp_ns: u64,
}

/// The measured head position, output `state` of the head agent.
#[derive(Debug, Clone, Copy, Default, PartialEq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::HeadState")]
pub struct HeadState {
    /// Pan, radians, positive to the left.
    pub pan_rad: f64,
    /// Tilt, radians, positive up.
    pub tilt_rad: f64,
    /// The set-point the agent is driving towards: pan, radians.
    pub target_pan_rad: f64,
    /// The set-point the agent is driving towards: tilt, radians.
    pub target_tilt_rad: f64,
    /// CLOCK_MONOTONIC nanoseconds when the board's report was received.
    pub stamp_ns: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<HeadCommand>(), 24);
        assert_eq!(std::mem::align_of::<HeadCommand>(), 8);
        assert_eq!(std::mem::size_of::<HeadState>(), 40);
        assert_eq!(<HeadCommand as Payload>::stable_type_name(), "nerve::HeadCommand");
        assert_eq!(<HeadState as Payload>::stable_type_name(), "nerve::HeadState");
    }
}
