//! What crosses the link: a data frame (a sample's bytes with its type name,
//! size and layout fingerprint, and the bridge's sequence numbers) and an
//! acknowledgement of a reliable topic. Little-endian, versioned, every
//! length checked on the way in: a frame from a misbehaving peer is refused,
//! never trusted.
//!
//! ```text
//! data: "NRVB" ver:u8 flags:u8 name_len:u16 name size:u32 fingerprint:u64
//!       instance:u64 seq:u64 oldest:u64 stamp_unix_ns:u64
//!       origin_seq:u64 sender_len:u8 sender payload[size]
//! ack:  "NRVA" ver:u8 instance:u64 acked:u64 importer_len:u8 importer
//! ```

/// Version of the frame layout; a peer with another is refused.
pub const WIRE_VERSION: u8 = 1;
const DATA_MAGIC: &[u8; 4] = b"NRVB";
const ACK_MAGIC: &[u8; 4] = b"NRVA";
const FLAG_RELIABLE: u8 = 1;
/// Longest type name carried.
pub const MAX_TYPE_NAME: usize = 256;

/// A data frame, as decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame<'a> {
    /// the topic is reliable (the receiver acknowledges and keeps order)
    pub reliable: bool,
    /// the payload's stable type name
    pub type_name: &'a str,
    /// the layout fingerprint of the sender's build
    pub fingerprint: u64,
    /// the sending bridge's run (a new one after a restart)
    pub instance: u64,
    /// the bridge's sequence number on this topic, from 1
    pub seq: u64,
    /// the oldest sequence number the sender still holds (reliable); older
    /// ones that the receiver has not seen are lost
    pub oldest: u64,
    /// when the sender took the sample (CLOCK_REALTIME ns)
    pub stamp_unix_ns: u64,
    /// sequence number of the sample on its local port
    pub origin_seq: u64,
    /// the local agent that sent the sample
    pub sender: &'a str,
    /// the payload's bytes
    pub payload: &'a [u8],
}

/// Why a frame was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    /// Not a nerve bridge frame.
    #[error("not a nerve bridge frame (bad magic)")]
    Magic,
    /// Another version of the frame layout.
    #[error("frame version {theirs}, this bridge speaks {ours}: run the same nerve version on both robots")]
    Version {
        /// the peer's version
        theirs: u8,
        /// ours
        ours: u8,
    },
    /// Shorter than its lengths say.
    #[error("truncated frame")]
    Truncated,
    /// A length field out of bounds, or text that is not UTF-8.
    #[error("malformed frame: {0}")]
    Malformed(&'static str),
}

/// The longest prefix of `s` of at most `max` bytes that ends on a
/// character: a name cut in the middle of one would not decode as UTF-8 at
/// the other end, and the frame would be refused whole.
fn char_floor(s: &str, max: usize) -> usize {
    let mut n = s.len().min(max);
    while !s.is_char_boundary(n) {
        n -= 1;
    }
    n
}

/// Appends a data frame to `out` (cleared first).
pub fn encode_frame(out: &mut Vec<u8>, f: &Frame<'_>) {
    out.clear();
    let name = &f.type_name.as_bytes()[..char_floor(f.type_name, MAX_TYPE_NAME)];
    let sender = &f.sender.as_bytes()[..char_floor(f.sender, u8::MAX as usize)];
    out.reserve(64 + name.len() + sender.len() + f.payload.len());
    out.extend_from_slice(DATA_MAGIC);
    out.push(WIRE_VERSION);
    out.push(if f.reliable { FLAG_RELIABLE } else { 0 });
    out.extend_from_slice(&(name.len() as u16).to_le_bytes());
    out.extend_from_slice(name);
    out.extend_from_slice(&(f.payload.len() as u32).to_le_bytes());
    for v in [f.fingerprint, f.instance, f.seq, f.oldest, f.stamp_unix_ns, f.origin_seq] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.push(sender.len() as u8);
    out.extend_from_slice(sender);
    out.extend_from_slice(f.payload);
}

struct Reader<'a> {
    buf: &'a [u8],
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], WireError> {
        if self.buf.len() < n {
            return Err(WireError::Truncated);
        }
        let (head, rest) = self.buf.split_at(n);
        self.buf = rest;
        Ok(head)
    }
    fn u8(&mut self) -> Result<u8, WireError> {
        Ok(self.take(1)?[0])
    }
    fn u16(&mut self) -> Result<u16, WireError> {
        let b = self.take(2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }
    fn u32(&mut self) -> Result<u32, WireError> {
        let mut a = [0u8; 4];
        a.copy_from_slice(self.take(4)?);
        Ok(u32::from_le_bytes(a))
    }
    fn u64(&mut self) -> Result<u64, WireError> {
        let mut a = [0u8; 8];
        a.copy_from_slice(self.take(8)?);
        Ok(u64::from_le_bytes(a))
    }
    fn text(&mut self, n: usize) -> Result<&'a str, WireError> {
        std::str::from_utf8(self.take(n)?).map_err(|_| WireError::Malformed("text is not UTF-8"))
    }
    fn header(&mut self, magic: &[u8; 4]) -> Result<(), WireError> {
        if self.take(4)? != magic {
            return Err(WireError::Magic);
        }
        let v = self.u8()?;
        if v != WIRE_VERSION {
            return Err(WireError::Version { theirs: v, ours: WIRE_VERSION });
        }
        Ok(())
    }
}

/// Decodes a data frame; the payload is borrowed from `buf`.
pub fn decode_frame(buf: &[u8]) -> Result<Frame<'_>, WireError> {
    let mut r = Reader { buf };
    r.header(DATA_MAGIC)?;
    let flags = r.u8()?;
    if flags & !FLAG_RELIABLE != 0 {
        // a later version's flag this one would silently misread
        return Err(WireError::Malformed("unknown flag bits"));
    }
    let name_len = r.u16()? as usize;
    if name_len > MAX_TYPE_NAME {
        return Err(WireError::Malformed("type name too long"));
    }
    let type_name = r.text(name_len)?;
    let size = r.u32()? as usize;
    let fingerprint = r.u64()?;
    let instance = r.u64()?;
    let seq = r.u64()?;
    let oldest = r.u64()?;
    let stamp_unix_ns = r.u64()?;
    let origin_seq = r.u64()?;
    let sender_len = r.u8()? as usize;
    let sender = r.text(sender_len)?;
    let payload = r.take(size)?;
    if !r.buf.is_empty() {
        return Err(WireError::Malformed("bytes after the payload"));
    }
    if seq == 0 || oldest > seq {
        return Err(WireError::Malformed("sequence numbers out of order"));
    }
    Ok(Frame {
        reliable: flags & FLAG_RELIABLE != 0,
        type_name,
        fingerprint,
        instance,
        seq,
        oldest,
        stamp_unix_ns,
        origin_seq,
        sender,
        payload,
    })
}

/// An acknowledgement: `importer` has delivered every message of run
/// `instance` up to `acked`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ack<'a> {
    /// the sender's run being acknowledged
    pub instance: u64,
    /// the highest sequence number delivered in order
    pub acked: u64,
    /// who acknowledges: `ROBOT.BRIDGE`
    pub importer: &'a str,
}

/// Encodes an acknowledgement.
pub fn encode_ack(a: &Ack<'_>) -> Vec<u8> {
    let who = &a.importer.as_bytes()[..a.importer.len().min(u8::MAX as usize)];
    let mut out = Vec::with_capacity(22 + who.len());
    out.extend_from_slice(ACK_MAGIC);
    out.push(WIRE_VERSION);
    out.extend_from_slice(&a.instance.to_le_bytes());
    out.extend_from_slice(&a.acked.to_le_bytes());
    out.push(who.len() as u8);
    out.extend_from_slice(who);
    out
}

/// Decodes an acknowledgement.
pub fn decode_ack(buf: &[u8]) -> Result<Ack<'_>, WireError> {
    let mut r = Reader { buf };
    r.header(ACK_MAGIC)?;
    let instance = r.u64()?;
    let acked = r.u64()?;
    let n = r.u8()? as usize;
    let importer = r.text(n)?;
    if !r.buf.is_empty() {
        return Err(WireError::Malformed("bytes after the acknowledgement"));
    }
    Ok(Ack { instance, acked, importer })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Found by the property tests' review: a long name was cut inside a
    /// character (the frame then failed to decode at the other end), and
    /// flag bits this version does not know were ignored.
    #[test]
    fn long_names_are_cut_on_a_character_and_unknown_flags_refused() {
        let long = format!("lab::{}", "é".repeat(200));
        let mut f = sample(&[1, 2, 3]);
        f.type_name = &long;
        f.sender = &long;
        let mut buf = Vec::new();
        encode_frame(&mut buf, &f);
        let back = decode_frame(&buf).expect("a cut name still decodes");
        assert!(long.starts_with(back.type_name) && back.type_name.len() <= MAX_TYPE_NAME);
        assert!(long.starts_with(back.sender) && back.sender.len() <= u8::MAX as usize);
        encode_frame(&mut buf, &sample(&[1]));
        buf[5] |= 0x80; // the flags byte follows "NRVB" and the version
        assert!(matches!(decode_frame(&buf), Err(WireError::Malformed("unknown flag bits"))));
    }

    fn sample<'a>(payload: &'a [u8]) -> Frame<'a> {
        Frame {
            reliable: true,
            type_name: "nerve::Tick",
            fingerprint: 0xfeed,
            instance: 7,
            seq: 42,
            oldest: 40,
            stamp_unix_ns: 1_700_000_000_000_000_000,
            origin_seq: 99,
            sender: "t1",
            payload,
        }
    }

    #[test]
    fn frames_round_trip() {
        let payload: Vec<u8> = (0..=255).collect();
        let f = sample(&payload);
        let mut buf = Vec::new();
        encode_frame(&mut buf, &f);
        assert_eq!(decode_frame(&buf), Ok(f));
        let a = Ack { instance: 7, acked: 41, importer: "r2.bridge" };
        assert_eq!(decode_ack(&encode_ack(&a)), Ok(a));
    }

    #[test]
    fn every_cut_and_every_bad_field_is_refused() {
        let payload = [1u8; 16];
        let mut buf = Vec::new();
        encode_frame(&mut buf, &sample(&payload));
        for n in 0..buf.len() {
            assert!(decode_frame(&buf[..n]).is_err(), "a frame cut at {n} bytes was accepted");
        }
        let mut longer = buf.clone();
        longer.push(0);
        assert!(decode_frame(&longer).is_err());
        let mut v = buf.clone();
        v[4] = 9;
        assert_eq!(decode_frame(&v), Err(WireError::Version { theirs: 9, ours: WIRE_VERSION }));
        assert_eq!(decode_frame(b"XXXXXXXXXXXXXXXX"), Err(WireError::Magic));
        let mut bad = buf.clone();
        bad[8] = 0xff; // a type name byte that is not UTF-8
        assert!(decode_frame(&bad).is_err());
        assert!(decode_ack(&buf).is_err(), "a data frame is not an acknowledgement");
    }

    #[test]
    fn out_of_order_sequence_fields_are_refused() {
        let payload = [0u8; 8];
        let mut f = sample(&payload);
        f.oldest = 50;
        let mut buf = Vec::new();
        encode_frame(&mut buf, &f);
        assert!(decode_frame(&buf).is_err());
    }
}
