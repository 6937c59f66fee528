//! The messages of every device, their payload layouts, and encode/decode
//! for both sides of the line.
//!
//! All multi-byte fields are little-endian. Every type has a fixed payload
//! length, which the decoder checks before the CRC. Angles are in
//! centidegrees (1/100 degree), lengths in millimetres, speeds in mm/s.

use crate::frame::write_frame;

/// Number of sonars in H1's ring.
pub const SONAR_COUNT: usize = 12;
/// Range value of a sonar that heard no echo (nothing within range).
pub const SONAR_NO_ECHO: u16 = u16::MAX;

/// Rate at which the sonar module sends [`SonarScan`], Hz.
pub const SONAR_RATE_HZ: f64 = 4.0;
/// Rate at which the motor DSP board sends [`EncoderReport`], Hz.
pub const ENCODER_RATE_HZ: f64 = 20.0;
/// Rate at which the head DSP board sends [`HeadState`], Hz.
pub const HEAD_RATE_HZ: f64 = 10.0;
/// Rate at which the IR receiver sends [`IrReport`], Hz.
pub const IR_RATE_HZ: f64 = 10.0;
/// Rate at which the arm controller sends [`ArmState`] and [`GraspState`], Hz.
pub const ARM_RATE_HZ: f64 = 10.0;
/// [`GraspState::held_id`] when the gripper holds nothing.
pub const GRASP_NOTHING: u8 = 0xFF;

/// The type byte of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum MessageType {
    /// Sonar ring → host, 4 Hz.
    SonarScan = 0x10,
    /// Host → motor DSP board.
    WheelCommand = 0x20,
    /// Motor DSP board → host, 20 Hz.
    EncoderReport = 0x21,
    /// Host → head DSP board.
    HeadCommand = 0x30,
    /// Head DSP board → host, 10 Hz.
    HeadState = 0x31,
    /// IR receiver → host, 10 Hz.
    IrReport = 0x40,
    /// Host → arm controller (H2).
    ArmCommand = 0x50,
    /// Arm controller (H2) → host, 10 Hz.
    ArmState = 0x51,
    /// Host → arm controller (H2): close the gripper on what is in reach, or open it.
    GraspCommand = 0x52,
    /// Arm controller (H2) → host, 10 Hz, after each [`ArmState`].
    GraspState = 0x53,
}

impl MessageType {
    /// Every message type, for tables and exhaustive tests.
    pub const ALL: [MessageType; 10] = [
        Self::SonarScan,
        Self::WheelCommand,
        Self::EncoderReport,
        Self::HeadCommand,
        Self::HeadState,
        Self::IrReport,
        Self::ArmCommand,
        Self::ArmState,
        Self::GraspCommand,
        Self::GraspState,
    ];
    /// The longest payload of any type.
    pub const MAX_PAYLOAD_LEN: usize = 2 + 2 * SONAR_COUNT;

    /// The type for a type byte, if it is one.
    pub fn from_u8(b: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|t| *t as u8 == b)
    }

    /// The fixed payload length of this type, in bytes.
    pub fn payload_len(self) -> usize {
        match self {
            Self::SonarScan => 2 + 2 * SONAR_COUNT,
            Self::WheelCommand => 4,
            Self::EncoderReport => 14,
            Self::HeadCommand => 4,
            Self::HeadState => 6,
            Self::IrReport => 4,
            Self::ArmCommand => 6,
            Self::ArmState => 8,
            Self::GraspCommand => 1,
            Self::GraspState => 6,
        }
    }
}

/// One reading of the 12-sonar ring. Sonar `i` points at `i * 30°`
/// counter-clockwise from the robot's forward axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SonarScan {
    /// Wrapping sequence number, +1 per scan.
    pub seq: u16,
    /// Range per sonar in mm; [`SONAR_NO_ECHO`] for no echo.
    pub ranges_mm: [u16; SONAR_COUNT],
}

/// Wheel velocity set-point for the motor DSP board.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WheelCommand {
    /// Left wheel ground speed, mm/s, positive forward.
    pub left_mm_s: i16,
    /// Right wheel ground speed, mm/s, positive forward.
    pub right_mm_s: i16,
}

/// Cumulative wheel encoder counts from the motor DSP board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EncoderReport {
    /// Wrapping sequence number, +1 per report.
    pub seq: u16,
    /// Board time in ms since power-up (wraps after 49 days).
    pub time_ms: u32,
    /// Left wheel counts since power-up, positive forward.
    pub left: i32,
    /// Right wheel counts since power-up, positive forward.
    pub right: i32,
}

/// Pan-tilt set-point for the head DSP board.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HeadCommand {
    /// Pan, centidegrees, positive to the left (counter-clockwise).
    pub pan_cdeg: i16,
    /// Tilt, centidegrees, positive up.
    pub tilt_cdeg: i16,
}

/// Measured pan-tilt position from the head DSP board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HeadState {
    /// Wrapping sequence number.
    pub seq: u16,
    /// Pan, centidegrees, positive to the left.
    pub pan_cdeg: i16,
    /// Tilt, centidegrees, positive up.
    pub tilt_cdeg: i16,
}

/// A checkpoint seen by the IR receiver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IrSighting {
    /// The checkpoint's identification code.
    pub checkpoint_id: u8,
    /// Which of the checkpoint's four transmitters are received: bit `i`
    /// is the transmitter facing `i * 90°` from the checkpoint's heading.
    /// Never zero, never above 0x0F.
    pub transmitters: u8,
}

/// One report of the IR receiver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IrReport {
    /// Wrapping sequence number.
    pub seq: u16,
    /// The nearest checkpoint received, or `None` when nothing is seen.
    pub sighting: Option<IrSighting>,
}

/// Joint set-points for H2's 3-DOF arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ArmCommand {
    /// Shoulder, elbow, gripper, centidegrees.
    pub joints_cdeg: [i16; 3],
}

/// Measured joint positions of H2's arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArmState {
    /// Wrapping sequence number.
    pub seq: u16,
    /// Shoulder, elbow, gripper, centidegrees.
    pub joints_cdeg: [i16; 3],
}

/// What the host asks of H2's gripper.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum GraspAction {
    /// Open the gripper and let go of what it holds.
    #[default]
    Release = 0,
    /// Close the gripper on whatever is within reach of its tip.
    Grasp = 1,
}

/// Grasp or release with H2's gripper. The arm controller closes (or
/// opens) the gripper joint itself; the outcome comes back in
/// [`GraspState`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GraspCommand {
    /// Grasp or release.
    pub action: GraspAction,
}

/// The gripper's state, as its controller sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum GripperPhase {
    /// Open (or opening), holding nothing.
    #[default]
    Open = 0,
    /// Closing after a grasp command; the outcome is not known yet.
    Closing = 1,
    /// Closed on an object: [`GraspState::held_id`] names it.
    Holding = 2,
    /// Closed on nothing: nothing was within reach when the fingers met.
    Missed = 3,
}

/// One report of H2's gripper (sent right after each [`ArmState`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GraspState {
    /// Wrapping sequence number, the same as the [`ArmState`] it follows.
    pub seq: u16,
    /// Open, closing, holding or missed.
    pub phase: GripperPhase,
    /// Identification code of the tube held; [`GRASP_NOTHING`] unless holding.
    pub held_id: u8,
    /// Distance from the gripper's tip to the nearest graspable tube's
    /// axis, mm (saturating; `u16::MAX` when there is none). The arm's
    /// proximity sensor: lets the host see how far it is from a grasp.
    pub nearest_mm: u16,
}

/// Any message of any device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    /// See [`SonarScan`].
    SonarScan(SonarScan),
    /// See [`WheelCommand`].
    WheelCommand(WheelCommand),
    /// See [`EncoderReport`].
    EncoderReport(EncoderReport),
    /// See [`HeadCommand`].
    HeadCommand(HeadCommand),
    /// See [`HeadState`].
    HeadState(HeadState),
    /// See [`IrReport`].
    IrReport(IrReport),
    /// See [`ArmCommand`].
    ArmCommand(ArmCommand),
    /// See [`ArmState`].
    ArmState(ArmState),
    /// See [`GraspCommand`].
    GraspCommand(GraspCommand),
    /// See [`GraspState`].
    GraspState(GraspState),
}

/// Little-endian reader over a payload whose length was checked.
struct Rd<'a>(&'a [u8]);
impl Rd<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        let n = N.min(self.0.len());
        out[..n].copy_from_slice(&self.0[..n]);
        self.0 = &self.0[n..];
        out
    }
    fn u8(&mut self) -> u8 {
        self.take::<1>()[0]
    }
    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }
    fn i16(&mut self) -> i16 {
        i16::from_le_bytes(self.take())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    fn i32(&mut self) -> i32 {
        i32::from_le_bytes(self.take())
    }
}

impl Message {
    /// The type byte this message is framed with.
    pub fn message_type(&self) -> MessageType {
        match self {
            Self::SonarScan(_) => MessageType::SonarScan,
            Self::WheelCommand(_) => MessageType::WheelCommand,
            Self::EncoderReport(_) => MessageType::EncoderReport,
            Self::HeadCommand(_) => MessageType::HeadCommand,
            Self::HeadState(_) => MessageType::HeadState,
            Self::IrReport(_) => MessageType::IrReport,
            Self::ArmCommand(_) => MessageType::ArmCommand,
            Self::ArmState(_) => MessageType::ArmState,
            Self::GraspCommand(_) => MessageType::GraspCommand,
            Self::GraspState(_) => MessageType::GraspState,
        }
    }

    /// The payload bytes (without framing).
    pub fn payload(&self) -> Vec<u8> {
        let mut p = Vec::with_capacity(self.message_type().payload_len());
        match self {
            Self::SonarScan(m) => {
                p.extend_from_slice(&m.seq.to_le_bytes());
                for r in m.ranges_mm {
                    p.extend_from_slice(&r.to_le_bytes());
                }
            }
            Self::WheelCommand(m) => {
                p.extend_from_slice(&m.left_mm_s.to_le_bytes());
                p.extend_from_slice(&m.right_mm_s.to_le_bytes());
            }
            Self::EncoderReport(m) => {
                p.extend_from_slice(&m.seq.to_le_bytes());
                p.extend_from_slice(&m.time_ms.to_le_bytes());
                p.extend_from_slice(&m.left.to_le_bytes());
                p.extend_from_slice(&m.right.to_le_bytes());
            }
            Self::HeadCommand(m) => {
                p.extend_from_slice(&m.pan_cdeg.to_le_bytes());
                p.extend_from_slice(&m.tilt_cdeg.to_le_bytes());
            }
            Self::HeadState(m) => {
                p.extend_from_slice(&m.seq.to_le_bytes());
                p.extend_from_slice(&m.pan_cdeg.to_le_bytes());
                p.extend_from_slice(&m.tilt_cdeg.to_le_bytes());
            }
            Self::IrReport(m) => {
                p.extend_from_slice(&m.seq.to_le_bytes());
                let (id, mask) = m.sighting.map_or((0, 0), |s| (s.checkpoint_id, s.transmitters & 0x0F));
                p.push(id);
                p.push(mask);
            }
            Self::ArmCommand(m) => {
                for j in m.joints_cdeg {
                    p.extend_from_slice(&j.to_le_bytes());
                }
            }
            Self::ArmState(m) => {
                p.extend_from_slice(&m.seq.to_le_bytes());
                for j in m.joints_cdeg {
                    p.extend_from_slice(&j.to_le_bytes());
                }
            }
            Self::GraspCommand(m) => p.push(m.action as u8),
            Self::GraspState(m) => {
                p.extend_from_slice(&m.seq.to_le_bytes());
                p.push(m.phase as u8);
                p.push(m.held_id);
                p.extend_from_slice(&m.nearest_mm.to_le_bytes());
            }
        }
        p
    }

    /// Appends the framed message to `out`.
    pub fn encode_into(&self, out: &mut Vec<u8>) {
        write_frame(self.message_type() as u8, &self.payload(), out);
    }

    /// The framed message, ready to write to the line.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(crate::frame::MAX_FRAME_LEN);
        self.encode_into(&mut out);
        out
    }

    /// Decodes a payload of type `t`; `None` if the length is wrong or a
    /// field holds an impossible value.
    pub fn decode_payload(t: MessageType, payload: &[u8]) -> Option<Message> {
        if payload.len() != t.payload_len() {
            return None;
        }
        let mut r = Rd(payload);
        Some(match t {
            MessageType::SonarScan => {
                let seq = r.u16();
                let mut ranges_mm = [0u16; SONAR_COUNT];
                for v in &mut ranges_mm {
                    *v = r.u16();
                }
                Self::SonarScan(SonarScan { seq, ranges_mm })
            }
            MessageType::WheelCommand => Self::WheelCommand(WheelCommand { left_mm_s: r.i16(), right_mm_s: r.i16() }),
            MessageType::EncoderReport => {
                Self::EncoderReport(EncoderReport { seq: r.u16(), time_ms: r.u32(), left: r.i32(), right: r.i32() })
            }
            MessageType::HeadCommand => Self::HeadCommand(HeadCommand { pan_cdeg: r.i16(), tilt_cdeg: r.i16() }),
            MessageType::HeadState => {
                Self::HeadState(HeadState { seq: r.u16(), pan_cdeg: r.i16(), tilt_cdeg: r.i16() })
            }
            MessageType::IrReport => {
                let seq = r.u16();
                let id = r.u8();
                let mask = r.u8();
                if mask > 0x0F {
                    return None;
                }
                let sighting = (mask != 0).then_some(IrSighting { checkpoint_id: id, transmitters: mask });
                Self::IrReport(IrReport { seq, sighting })
            }
            MessageType::ArmCommand => Self::ArmCommand(ArmCommand { joints_cdeg: [r.i16(), r.i16(), r.i16()] }),
            MessageType::ArmState => {
                Self::ArmState(ArmState { seq: r.u16(), joints_cdeg: [r.i16(), r.i16(), r.i16()] })
            }
            MessageType::GraspCommand => {
                let action = match r.u8() {
                    0 => GraspAction::Release,
                    1 => GraspAction::Grasp,
                    _ => return None,
                };
                Self::GraspCommand(GraspCommand { action })
            }
            MessageType::GraspState => {
                let seq = r.u16();
                let phase = match r.u8() {
                    0 => GripperPhase::Open,
                    1 => GripperPhase::Closing,
                    2 => GripperPhase::Holding,
                    3 => GripperPhase::Missed,
                    _ => return None,
                };
                let held_id = r.u8();
                // only a holding gripper names what it holds
                if (phase == GripperPhase::Holding) != (held_id != GRASP_NOTHING) {
                    return None;
                }
                Self::GraspState(GraspState { seq, phase, held_id, nearest_mm: r.u16() })
            }
        })
    }
}

macro_rules! from_variant {
    ($($t:ident),*) => {$(
        impl From<$t> for Message {
            fn from(m: $t) -> Message { Message::$t(m) }
        }
    )*};
}
from_variant!(
    SonarScan,
    WheelCommand,
    EncoderReport,
    HeadCommand,
    HeadState,
    IrReport,
    ArmCommand,
    ArmState,
    GraspCommand,
    GraspState
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payload_lengths_match_table() {
        for t in MessageType::ALL {
            assert!(t.payload_len() <= MessageType::MAX_PAYLOAD_LEN);
            assert_eq!(MessageType::from_u8(t as u8), Some(t));
        }
        assert_eq!(MessageType::from_u8(0x00), None);
    }

    #[test]
    fn grasp_messages_round_trip_and_refuse_impossible_values() {
        let held = GraspState { seq: 7, phase: GripperPhase::Holding, held_id: 9, nearest_mm: 40 };
        let p = Message::from(held).payload();
        assert_eq!(p, [7, 0, 2, 9, 40, 0]);
        assert_eq!(Message::decode_payload(MessageType::GraspState, &p), Some(held.into()));
        // holding nothing, or naming an object while open, is impossible
        assert_eq!(Message::decode_payload(MessageType::GraspState, &[7, 0, 2, 0xFF, 0, 0]), None);
        assert_eq!(Message::decode_payload(MessageType::GraspState, &[7, 0, 0, 3, 0, 0]), None);
        assert_eq!(Message::decode_payload(MessageType::GraspState, &[7, 0, 4, 0xFF, 0, 0]), None);
        let grasp = GraspCommand { action: GraspAction::Grasp };
        assert_eq!(Message::from(grasp).payload(), [1]);
        assert_eq!(Message::decode_payload(MessageType::GraspCommand, &[1]), Some(grasp.into()));
        assert_eq!(Message::decode_payload(MessageType::GraspCommand, &[2]), None);
    }
}
