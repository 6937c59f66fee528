//! CDR, little-endian, as ROS 2 puts it on the wire (plain CDR / XCDR1 of
//! the OMG DDS-XTypes and CORBA specifications, final types only):
//!
//! * a 4-byte encapsulation header first: `00 01` (CDR_LE) and two bytes of
//!   options, `00 00`;
//! * every primitive aligned to its own size (1, 2, 4 or 8), counted from the
//!   first byte after the header, padding with zeros;
//! * a string: its length as `u32` including the terminating NUL, the UTF-8
//!   bytes, the NUL;
//! * a sequence: its element count as `u32`, then the elements; a fixed
//!   array: the elements only;
//! * a nested message: its fields in order, no header of its own.

/// The encapsulation header of CDR little-endian (representation id
/// CDR_LE = 0x0001, options 0).
pub const HEADER_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Why bytes could not be read or written as CDR.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    /// Fewer than 4 bytes: no encapsulation header.
    #[error("CDR message of {len} byte(s) has no 4-byte encapsulation header")]
    NoHeader {
        /// the message's length
        len: usize,
    },
    /// A representation other than CDR_LE (big-endian CDR, or XCDR2).
    #[error(
        "CDR representation {id:02x?} is not supported (only CDR_LE, 00 01, which every ROS 2 middleware sends by default)"
    )]
    Representation {
        /// the first two header bytes
        id: [u8; 2],
    },
    /// The message ended inside a value.
    #[error("CDR message ends at byte {have} inside {what}, which needs {need} byte(s) from offset {at}")]
    Truncated {
        /// what was being read
        what: &'static str,
        /// its offset after the header
        at: usize,
        /// how many bytes it needs
        need: usize,
        /// how many bytes follow the header
        have: usize,
    },
    /// A string without its NUL, or not UTF-8.
    #[error("CDR string at offset {at}: {reason}")]
    BadString {
        /// its offset after the header
        at: usize,
        /// what is wrong
        reason: &'static str,
    },
    /// A sequence or string longer than `u32` can count.
    #[error("{what} of {len} elements is longer than CDR can count (u32)")]
    TooLong {
        /// what
        what: &'static str,
        /// its length
        len: usize,
    },
    /// A nerve sample shorter than its layout (a mapped type, `usermap`).
    #[error("a sample of {have} byte(s) is shorter than its layout's {need}: sent with another layout?")]
    Short {
        /// the layout's size
        need: usize,
        /// the sample's length
        have: usize,
    },
    /// Bytes were left after the last field.
    #[error("{extra} byte(s) left after the last field (a different message type?)")]
    Trailing {
        /// how many
        extra: usize,
    },
}

/// Writes one CDR message.
#[derive(Debug, Clone)]
pub struct Writer {
    buf: Vec<u8>,
}

impl Default for Writer {
    fn default() -> Self {
        Self::new()
    }
}

impl Writer {
    /// A message with its encapsulation header written.
    pub fn new() -> Self {
        Self::with_capacity(64)
    }

    /// Like [`Writer::new`], with room for `n` bytes.
    pub fn with_capacity(n: usize) -> Self {
        let mut buf = Vec::with_capacity(n.saturating_add(4));
        buf.extend_from_slice(&HEADER_LE);
        Writer { buf }
    }

    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - HEADER_LE.len();
        let pad = (n - pos % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    /// `uint8`, `byte`, `char`
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    /// `bool`: one byte, 0 or 1
    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }
    /// `int8`
    pub fn i8(&mut self, v: i8) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// `uint16`
    pub fn u16(&mut self, v: u16) {
        self.align(2);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// `int16`
    pub fn i16(&mut self, v: i16) {
        self.align(2);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// `uint32`
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// `int32`
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// `float32`
    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// `uint64`
    pub fn u64(&mut self, v: u64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// `int64`
    pub fn i64(&mut self, v: i64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    /// `float64`
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A sequence's element count.
    pub fn count(&mut self, what: &'static str, n: usize) -> Result<(), CdrError> {
        let n32 = u32::try_from(n).map_err(|_| CdrError::TooLong { what, len: n })?;
        self.u32(n32);
        Ok(())
    }

    /// `string`: length with the NUL, bytes, NUL.
    pub fn string(&mut self, s: &str) -> Result<(), CdrError> {
        self.count("string", s.len().saturating_add(1))?;
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        Ok(())
    }

    /// `uint8[]`: count, bytes.
    pub fn bytes(&mut self, b: &[u8]) -> Result<(), CdrError> {
        self.count("uint8[]", b.len())?;
        self.buf.extend_from_slice(b);
        Ok(())
    }

    /// `float32[]`: count, values.
    pub fn f32_seq(&mut self, v: &[f32]) -> Result<(), CdrError> {
        self.count("float32[]", v.len())?;
        for x in v {
            self.f32(*x);
        }
        Ok(())
    }

    /// `float64[N]`: the values (no count).
    pub fn f64_array(&mut self, v: &[f64]) {
        for x in v {
            self.f64(*x);
        }
    }

    /// The message, header first.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// Reads one CDR message.
#[derive(Debug, Clone)]
pub struct Reader<'a> {
    body: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// Checks the encapsulation header (CDR_LE only) and reads after it.
    pub fn new(msg: &'a [u8]) -> Result<Self, CdrError> {
        if msg.len() < 4 {
            return Err(CdrError::NoHeader { len: msg.len() });
        }
        if msg[..2] != HEADER_LE[..2] {
            return Err(CdrError::Representation { id: [msg[0], msg[1]] });
        }
        Ok(Reader { body: &msg[4..], pos: 0 })
    }

    fn take(&mut self, what: &'static str, align: usize, n: usize) -> Result<&'a [u8], CdrError> {
        let pad = (align - self.pos % align) % align;
        let truncated =
            || CdrError::Truncated { what, at: self.pos, need: pad.saturating_add(n), have: self.body.len() };
        let start = self.pos.checked_add(pad).ok_or_else(truncated)?;
        let end = start.checked_add(n).ok_or_else(truncated)?;
        let s = self.body.get(start..end).ok_or_else(truncated)?;
        self.pos = end;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], CdrError> {
        let s = self.take(what, N, N)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    /// `uint8`
    pub fn u8(&mut self) -> Result<u8, CdrError> {
        Ok(self.take("uint8", 1, 1)?[0])
    }
    /// `bool` (any non-zero byte is true)
    pub fn bool(&mut self) -> Result<bool, CdrError> {
        Ok(self.take("bool", 1, 1)?[0] != 0)
    }
    /// `int8`
    pub fn i8(&mut self) -> Result<i8, CdrError> {
        Ok(i8::from_le_bytes(self.array("int8")?))
    }
    /// `uint16`
    pub fn u16(&mut self) -> Result<u16, CdrError> {
        Ok(u16::from_le_bytes(self.array("uint16")?))
    }
    /// `int16`
    pub fn i16(&mut self) -> Result<i16, CdrError> {
        Ok(i16::from_le_bytes(self.array("int16")?))
    }
    /// How many bytes are left to read (a count from the wire is checked
    /// against it before anything is done that many times).
    pub fn remaining(&self) -> usize {
        self.body.len().saturating_sub(self.pos)
    }
    /// `uint32`
    pub fn u32(&mut self) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.array("uint32")?))
    }
    /// `int32`
    pub fn i32(&mut self) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.array("int32")?))
    }
    /// `float32`
    pub fn f32(&mut self) -> Result<f32, CdrError> {
        Ok(f32::from_le_bytes(self.array("float32")?))
    }
    /// `uint64`
    pub fn u64(&mut self) -> Result<u64, CdrError> {
        Ok(u64::from_le_bytes(self.array("uint64")?))
    }
    /// `int64`
    pub fn i64(&mut self) -> Result<i64, CdrError> {
        Ok(i64::from_le_bytes(self.array("int64")?))
    }
    /// `float64`
    pub fn f64(&mut self) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.array("float64")?))
    }

    /// `string`
    pub fn string(&mut self) -> Result<&'a str, CdrError> {
        let n = self.u32()? as usize;
        let at = self.pos;
        if n == 0 {
            return Err(CdrError::BadString { at, reason: "length 0 (even an empty string has its NUL)" });
        }
        let s = self.take("string", 1, n)?;
        let (text, nul) = s.split_at(n - 1);
        if nul != [0] {
            return Err(CdrError::BadString { at, reason: "no terminating NUL" });
        }
        std::str::from_utf8(text).map_err(|_| CdrError::BadString { at, reason: "not UTF-8" })
    }

    /// `uint8[]`
    pub fn bytes(&mut self) -> Result<&'a [u8], CdrError> {
        let n = self.u32()? as usize;
        self.take("uint8[]", 1, n)
    }

    /// `float32[]`
    pub fn f32_seq(&mut self) -> Result<Vec<f32>, CdrError> {
        let n = self.u32()? as usize;
        // the count is outside input: check it against what is there before
        // allocating for it
        let raw = self.take("float32[]", 4, n.saturating_mul(4))?;
        Ok(raw.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }

    /// `float64[N]`
    pub fn f64_array<const N: usize>(&mut self) -> Result<[f64; N], CdrError> {
        let mut a = [0.0; N];
        for x in &mut a {
            *x = self.f64()?;
        }
        Ok(a)
    }

    /// Checks that nothing follows the last field. CDR allows padding to a
    /// multiple of 4 after the message (some writers add it), so up to 3
    /// bytes are accepted.
    pub fn finish(self) -> Result<(), CdrError> {
        let extra = self.body.len().saturating_sub(self.pos);
        if extra > 3 { Err(CdrError::Trailing { extra }) } else { Ok(()) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Alignment is counted after the header: a u8 then a u64 puts 7 bytes
    /// of padding, a u8 then a u32 three, a u8 then a string three.
    #[test]
    fn primitives_align_to_their_size_after_the_header() {
        let mut w = Writer::new();
        w.u8(0xab);
        w.u64(0x0102_0304_0506_0708);
        w.u8(1);
        w.u32(7);
        w.bool(true);
        w.string("hi").expect("short");
        let b = w.finish();
        let want: Vec<u8> = [
            &[0x00, 0x01, 0x00, 0x00][..],
            &[0xab, 0, 0, 0, 0, 0, 0, 0],
            &[0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01],
            &[0x01, 0, 0, 0],
            &[0x07, 0, 0, 0],
            &[0x01, 0, 0, 0],
            &[0x03, 0, 0, 0, b'h', b'i', 0],
        ]
        .concat();
        assert_eq!(b, want);
        let mut r = Reader::new(&b).expect("header");
        assert_eq!(r.u8(), Ok(0xab));
        assert_eq!(r.u64(), Ok(0x0102_0304_0506_0708));
        assert_eq!(r.u8(), Ok(1));
        assert_eq!(r.u32(), Ok(7));
        assert_eq!(r.bool(), Ok(true));
        assert_eq!(r.string(), Ok("hi"));
        assert_eq!(r.finish(), Ok(()));
    }

    /// An empty string is its count 1 and the NUL; a sequence is a u32
    /// count then the elements, each aligned.
    #[test]
    fn strings_and_sequences() {
        let mut w = Writer::new();
        w.string("").expect("empty");
        w.f32_seq(&[1.0, -2.0]).expect("short");
        w.bytes(&[9, 8, 7]).expect("short");
        w.f64(0.5);
        let b = w.finish();
        let mut want = vec![0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0];
        want.extend_from_slice(&1.0f32.to_le_bytes());
        want.extend_from_slice(&(-2.0f32).to_le_bytes());
        want.extend_from_slice(&[3, 0, 0, 0, 9, 8, 7, 0, 0, 0, 0, 0]);
        want.extend_from_slice(&0.5f64.to_le_bytes());
        assert_eq!(b, want);
        let mut r = Reader::new(&b).expect("header");
        assert_eq!(r.string(), Ok(""));
        assert_eq!(r.f32_seq(), Ok(vec![1.0, -2.0]));
        assert_eq!(r.bytes(), Ok(&[9u8, 8, 7][..]));
        assert_eq!(r.f64(), Ok(0.5));
    }

    #[test]
    fn bad_input_is_refused_with_where() {
        assert_eq!(Reader::new(&[0, 1]).err(), Some(CdrError::NoHeader { len: 2 }));
        assert_eq!(Reader::new(&[0, 0, 0, 0]).err(), Some(CdrError::Representation { id: [0, 0] }));
        // a huge sequence count over a short message: refused, not allocated
        let mut r = Reader::new(&[0, 1, 0, 0, 0xff, 0xff, 0xff, 0xff, 1, 2]).expect("header");
        assert!(matches!(r.f32_seq(), Err(CdrError::Truncated { what: "float32[]", .. })));
        let mut r = Reader::new(&[0, 1, 0, 0, 2, 0, 0, 0, b'a', b'b']).expect("header");
        assert_eq!(r.string(), Err(CdrError::BadString { at: 4, reason: "no terminating NUL" }));
        let mut r = Reader::new(&[0, 1, 0, 0, 0, 0, 0, 0]).expect("header");
        assert!(matches!(r.string(), Err(CdrError::BadString { .. })));
        let mut r = Reader::new(&[0, 1, 0, 0, 1, 2, 3]).expect("header");
        assert!(matches!(r.u32(), Err(CdrError::Truncated { what: "uint32", at: 0, need: 4, have: 3 })));
        let r = Reader::new(&[0, 1, 0, 0, 1, 2, 3, 4]).expect("header");
        assert_eq!(r.finish(), Err(CdrError::Trailing { extra: 4 }));
    }
}
