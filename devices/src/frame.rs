//! The one framing every nerve device speaks, and its streaming decoder.
//!
//! ```text
//! offset  size  field
//! 0       2     sync: 0xA5 0x5A
//! 2       1     message type (see `MessageType`)
//! 3       1     payload length N (fixed per type)
//! 4       N     payload, little-endian fields
//! 4+N     2     CRC-16/CCITT-FALSE over bytes 2 .. 4+N (type, length,
//!               payload), little-endian
//! ```
//!
//! CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection,
//! no final XOR; the check value of `"123456789"` is 0x29B1.
//!
//! [`FrameDecoder`] is fed whatever bytes a serial read returned and yields
//! every complete, valid frame as a [`Message`]. It never blocks and never
//! fails: bytes that are not part of a valid frame are dropped and counted in
//! [`DecodeStats`], and the decoder hunts for the next sync pair
//! (resynchronisation). After a rejected candidate frame only its first byte
//! is dropped, so a real frame hidden inside a bogus header's claimed length
//! is still found. Its buffer holds at most one frame's worth of bytes, so
//! memory stays bounded whatever the line carries.

use crate::messages::{Message, MessageType};

/// The two bytes that start every frame.
pub const SYNC: [u8; 2] = [0xA5, 0x5A];
/// Bytes before the payload: sync (2), type (1), length (1).
pub const HEADER_LEN: usize = 4;
/// Bytes after the payload: the CRC.
pub const TRAILER_LEN: usize = 2;
/// The longest frame any message type produces.
pub const MAX_FRAME_LEN: usize = HEADER_LEN + MessageType::MAX_PAYLOAD_LEN + TRAILER_LEN;

/// CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, not reflected, no final XOR).
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
        }
    }
    crc
}

/// Appends one frame (sync, type, length, payload, CRC) to `out`.
///
/// # Panics
/// If `payload` is longer than 255 bytes; every message of this crate is far
/// shorter, so this is a programming error, not a run-time condition.
pub fn write_frame(msg_type: u8, payload: &[u8], out: &mut Vec<u8>) {
    let len = u8::try_from(payload.len()).expect("frame payload longer than 255 bytes");
    out.extend_from_slice(&SYNC);
    let body_start = out.len();
    out.push(msg_type);
    out.push(len);
    out.extend_from_slice(payload);
    let crc = crc16(&out[body_start..]);
    out.extend_from_slice(&crc.to_le_bytes());
}

/// What a [`FrameDecoder`] has seen and dropped since it was created.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecodeStats {
    /// Valid frames yielded.
    pub frames: u64,
    /// Bytes dropped while hunting for a frame start, including the bytes of
    /// rejected candidate frames.
    pub garbage_bytes: u64,
    /// Candidate frames whose type is unknown or whose length does not match
    /// the type.
    pub bad_headers: u64,
    /// Complete candidate frames whose CRC did not match.
    pub bad_checksums: u64,
    /// Frames cut short: a CRC mismatch where a new sync pair starts inside
    /// the claimed frame (the sender stopped mid-frame and began another), or
    /// a partial frame discarded by [`FrameDecoder::reset_stream`].
    pub truncated: u64,
    /// Frames with a good CRC whose payload holds an impossible value (for
    /// example an IR transmitter mask with bits above the four transmitters).
    pub invalid_payloads: u64,
}

impl DecodeStats {
    /// Everything rejected, in frames (garbage bytes not included).
    pub fn rejected_frames(&self) -> u64 {
        self.bad_headers + self.bad_checksums + self.truncated + self.invalid_payloads
    }
}

/// Streaming frame decoder; see the module documentation.
#[derive(Debug, Default)]
pub struct FrameDecoder {
    buf: Vec<u8>,
    start: usize,
    stats: DecodeStats,
}

/// Iterator over the messages decodable after a [`FrameDecoder::push`].
///
/// Frames are decoded lazily; whatever is not consumed stays buffered in the
/// decoder and is returned by the next `push` or [`FrameDecoder::next_message`].
#[derive(Debug)]
pub struct Frames<'a> {
    decoder: &'a mut FrameDecoder,
}

impl Iterator for Frames<'_> {
    type Item = Message;
    fn next(&mut self) -> Option<Message> {
        self.decoder.next_message()
    }
}

enum Step {
    /// A valid message; `consumed` bytes belong to it.
    Frame(Message, usize),
    /// Need more bytes.
    Incomplete,
    /// Drop this many bytes as garbage and try again.
    Skip(usize),
}

impl FrameDecoder {
    /// A decoder with an empty buffer and zeroed counters.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends `bytes` and returns an iterator over the messages now complete.
    pub fn push(&mut self, bytes: &[u8]) -> Frames<'_> {
        if self.start > 0 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
        Frames { decoder: self }
    }

    /// The next complete, valid message in the buffer, if any.
    pub fn next_message(&mut self) -> Option<Message> {
        loop {
            match self.step() {
                Step::Frame(msg, used) => {
                    self.start += used;
                    self.stats.frames += 1;
                    return Some(msg);
                }
                Step::Incomplete => return None,
                Step::Skip(n) => {
                    self.start += n;
                    self.stats.garbage_bytes += n as u64;
                }
            }
        }
    }

    /// Counters since creation.
    pub fn stats(&self) -> DecodeStats {
        self.stats
    }

    /// Bytes buffered and not yet decoded (at most one frame's worth once
    /// the iterator of the last `push` is drained).
    pub fn pending(&self) -> usize {
        self.buf.len() - self.start
    }

    /// Forgets buffered bytes, e.g. when the other end closed the line. A
    /// partial frame (the buffer starts with a sync pair) counts as
    /// truncated, anything else as garbage.
    pub fn reset_stream(&mut self) {
        let rest = &self.buf[self.start..];
        if rest.len() >= 2 && rest[..2] == SYNC {
            self.stats.truncated += 1;
        }
        self.stats.garbage_bytes += rest.len() as u64;
        self.buf.clear();
        self.start = 0;
    }

    fn step(&mut self) -> Step {
        let rest = &self.buf[self.start..];
        if rest.is_empty() {
            return Step::Incomplete;
        }
        // Hunt for the sync pair.
        if rest[0] != SYNC[0] {
            let skip = rest.iter().position(|&b| b == SYNC[0]).unwrap_or(rest.len());
            return Step::Skip(skip);
        }
        if rest.len() < 2 {
            return Step::Incomplete;
        }
        if rest[1] != SYNC[1] {
            return Step::Skip(1);
        }
        if rest.len() < HEADER_LEN {
            return Step::Incomplete;
        }
        let (type_byte, len) = (rest[2], usize::from(rest[3]));
        let Some(msg_type) = MessageType::from_u8(type_byte) else {
            self.stats.bad_headers += 1;
            return Step::Skip(1);
        };
        if len != msg_type.payload_len() {
            self.stats.bad_headers += 1;
            return Step::Skip(1);
        }
        let total = HEADER_LEN + len + TRAILER_LEN;
        if rest.len() < total {
            return Step::Incomplete;
        }
        let body = &rest[2..HEADER_LEN + len];
        let got = u16::from_le_bytes([rest[total - 2], rest[total - 1]]);
        if crc16(body) != got {
            // A sync pair after the header means another frame began before
            // this one ended: the sender cut it short.
            let inner = &rest[2..total];
            if inner.windows(2).any(|w| w == SYNC) {
                self.stats.truncated += 1;
            } else {
                self.stats.bad_checksums += 1;
            }
            return Step::Skip(1);
        }
        match Message::decode_payload(msg_type, &rest[HEADER_LEN..HEADER_LEN + len]) {
            Some(msg) => Step::Frame(msg, total),
            None => {
                self.stats.invalid_payloads += 1;
                Step::Skip(total)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_check_value() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }

    #[test]
    fn frame_layout() {
        let mut out = Vec::new();
        write_frame(0x20, &[1, 2, 3, 4], &mut out);
        assert_eq!(&out[..4], &[0xA5, 0x5A, 0x20, 4]);
        assert_eq!(out.len(), 10);
        let crc = crc16(&out[2..8]);
        assert_eq!(&out[8..], &crc.to_le_bytes());
    }
}
