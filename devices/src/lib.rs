//! Byte protocols of nerve's robot devices, shared by the simulator (device
//! side) and the sensor and actuator agents (host side).
//!
//! Every device of the robots H1 and H2 of the thesis (section 4.1) talks over
//! a serial line with **one framing** ([`frame`]):
//!
//! ```text
//! 0xA5 0x5A | type u8 | len u8 | payload (len bytes) | CRC-16/CCITT-FALSE u16 LE
//! ```
//!
//! The messages ([`Message`]) are:
//!
//! | device | direction | message |
//! |---|---|---|
//! | sonar ring module (12 sonars, 4 Hz) | device → host | [`SonarScan`] |
//! | motor DSP board (wheels) | host → device | [`WheelCommand`] |
//! | motor DSP board (wheels) | device → host | [`EncoderReport`] |
//! | head DSP board (pan-tilt) | host → device | [`HeadCommand`] |
//! | head DSP board (pan-tilt) | device → host | [`HeadState`] |
//! | IR receiver | device → host | [`IrReport`] |
//! | arm controller (H2, 3 joints) | host → device | [`ArmCommand`] |
//! | arm controller (H2, 3 joints) | device → host | [`ArmState`] |
//! | arm controller (H2, gripper) | host → device | [`GraspCommand`] |
//! | arm controller (H2, gripper) | device → host | [`GraspState`] |
//!
//! The encoder of either side is [`Message::encode`]; the decoder is the
//! streaming [`FrameDecoder`], which resynchronises after garbage and counts
//! what it drops in [`DecodeStats`]. [`serial`] opens a real serial port (or a
//! simulator's pseudo-terminal) by path; [`motor`] holds the wheel geometry of
//! H1 and H2 and turns encoder counts into odometry.
//!
//! The full byte-level reference is `docs/devices.md`.
#![warn(missing_docs)]

pub mod frame;
pub mod messages;
pub mod motor;
pub mod serial;

pub use frame::{DecodeStats, FrameDecoder, Frames, MAX_FRAME_LEN, SYNC, crc16};
pub use messages::{
    ARM_RATE_HZ, ArmCommand, ArmState, ENCODER_RATE_HZ, EncoderReport, GRASP_NOTHING, GraspAction, GraspCommand,
    GraspState, GripperPhase, HEAD_RATE_HZ, HeadCommand, HeadState, IR_RATE_HZ, IrReport, IrSighting, Message,
    MessageType, SONAR_COUNT, SONAR_NO_ECHO, SONAR_RATE_HZ, SonarScan, WheelCommand,
};
pub use motor::{DiffDriveGeometry, Odometry, Pose2, wrap_angle};
pub use serial::{SerialLink, SerialOpenError, open_serial};
