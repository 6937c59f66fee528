//! `nerve::IrSighting`: what the IR receiver sees — the nearest checkpoint's
//! identification code and which of its four transmitters are received.

use super::Payload;
use serde::Serialize;

/// One report of the IR receiver, sent by the `ir` agent (10 Hz).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Payload, Serialize)]
#[repr(C)]
#[payload(name = "nerve::IrSighting")]
pub struct IrSighting {
    /// Report number (the receiver's wrapping counter, unwrapped).
    pub seq: u64,
    /// CLOCK_MONOTONIC nanoseconds when the report was received.
    pub stamp_ns: u64,
    /// 1 when a checkpoint is seen, 0 when nothing is.
    pub seen: u8,
    /// The checkpoint's code (meaningful only when `seen == 1`).
    pub checkpoint_id: u8,
    /// Bit `i` set: the transmitter facing `i * 90°` from the checkpoint's
    /// heading is received (bits 0..=3; 0 when nothing is seen).
    pub transmitters: u8,
    /// Padding, zero.
    pub reserved: [u8; 5],
}

impl IrSighting {
    /// The bearing of the robot as seen from the checkpoint, in units of
    /// 90° from its heading (0..4, halves for two adjacent transmitters);
    /// `None` when nothing or an impossible pattern is received.
    pub fn sector(&self) -> Option<f32> {
        let m = self.transmitters & 0x0F;
        if self.seen == 0 || m == 0 {
            return None;
        }
        let bits: Vec<u8> = (0..4).filter(|i| m & (1 << i) != 0).collect();
        match bits.as_slice() {
            [a] => Some(f32::from(*a)),
            [0, 3] => Some(3.5),
            [a, b] if b - a == 1 => Some(f32::from(*a) + 0.5),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_stable() {
        assert_eq!(std::mem::size_of::<IrSighting>(), 24);
        assert_eq!(std::mem::align_of::<IrSighting>(), 8);
        assert_eq!(std::mem::offset_of!(IrSighting, seen), 16);
        assert_eq!(<IrSighting as Payload>::stable_type_name(), "nerve::IrSighting");
    }

    #[test]
    fn sectors() {
        let s = |t| IrSighting { seen: 1, transmitters: t, ..Default::default() };
        assert_eq!(s(0b0001).sector(), Some(0.0));
        assert_eq!(s(0b0110).sector(), Some(1.5));
        assert_eq!(s(0b1001).sector(), Some(3.5));
        assert_eq!(s(0b0101).sector(), None);
        assert_eq!(IrSighting::default().sector(), None);
    }
}
