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
/// Rate at which the arm controller sends [`ArmState`], Hz.
pub const ARM_RATE_HZ: f64 = 10.0;

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
}

impl MessageType {
    /// Every message type, for tables and exhaustive tests.
    pub const ALL: [MessageType; 8] = [
        Self::SonarScan,
        Self::WheelCommand,
        Self::EncoderReport,
        Self::HeadCommand,
        Self::HeadState,
        Self::IrReport,
        Self::ArmCommand,
        Self::ArmState,
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
from_variant!(SonarScan, WheelCommand, EncoderReport, HeadCommand, HeadState, IrReport, ArmCommand, ArmState);

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
}
