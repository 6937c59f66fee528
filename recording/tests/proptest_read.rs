//! Property tests of the recording reader (`read::RecordingReader`, the one
//! reader of `nerve replay`, `export` and `snapshot`, and
//! `read::nerve_schema`) under generated input (issue 40, "every decoder of
//! outside bytes"):
//!
//! * a recording written by `RecordingWriter` (any messages, any chunk
//!   size) reads back the same messages, and ends complete;
//! * cut anywhere, it reads a prefix of them (never a message that was not
//!   written), and says it was cut;
//! * with one byte changed, bytes appended, or arbitrary bytes after MCAP's
//!   magic, it reads or fails without a panic, in a bounded number of
//!   events (never more than the file has bytes), and every channel's
//!   schema is parsed and checked without a panic.
//!
//! The default case count is proptest's (256, or `PROPTEST_CASES`); the long
//! run is in `docs/robustness.md`.

use nerve_recording::read::{End, Event, RecordingReader, nerve_schema};
use nerve_recording::{PortChannel, RecordingWriter, Sample};
use proptest::prelude::*;
use shm_schemas::{Described, Schema};
use std::cell::RefCell;
use std::io::{Cursor, Seek, SeekFrom, Write};
use std::rc::Rc;

/// A message as written, and as read back.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Msg {
    seq: u32,
    log_time: u64,
    stamp: u64,
    data: Vec<u8>,
}

fn msg() -> impl Strategy<Value = Msg> {
    (any::<u32>(), any::<u64>(), any::<u64>(), proptest::collection::vec(any::<u8>(), 0..64))
        .prop_map(|(seq, log_time, stamp, data)| Msg { seq, log_time, stamp, data })
}

/// A file the test keeps while the writer owns a handle to it.
#[derive(Clone, Default)]
struct SharedFile(Rc<RefCell<Cursor<Vec<u8>>>>);

impl Write for SharedFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.borrow_mut().write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for SharedFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.0.borrow_mut().seek(pos)
    }
}

/// A finished recording of `msgs` on one port, in chunks of `chunk` bytes.
fn recording(msgs: &[Msg], chunk: u64) -> Vec<u8> {
    let schema: Schema = <[u32; 2]>::schema();
    let file = SharedFile::default();
    let mut w = RecordingWriter::with_chunk_size(file.clone(), chunk).expect("a writer");
    let port = PortChannel {
        robot: "r",
        agent: "a",
        port: "out",
        type_name: &schema.type_name,
        fingerprint: schema.fingerprint(),
        schema: &schema,
    };
    let ch = w.add_port(&port).expect("a channel");
    for m in msgs {
        let s = Sample { seq: u64::from(m.seq), log_time_ns: m.log_time, stamp_ns: m.stamp, bytes: &m.data };
        w.write_sample(ch, &s).expect("a sample");
    }
    w.finish().expect("the file closes");
    file.0.borrow().get_ref().clone()
}

/// Everything a reader gives for `bytes`: the messages, whether it ended
/// complete; bounded in events by the length of the input.
fn read_all(bytes: &[u8]) -> Result<(Vec<Msg>, Option<End>), TestCaseError> {
    let Ok(mut r) = RecordingReader::new(bytes, "proptest.mcap") else { return Ok((Vec::new(), None)) };
    let mut got = Vec::new();
    for _ in 0..=bytes.len() {
        match r.next_event() {
            Ok(Some(Event::Channel(ch))) => {
                let _ = nerve_schema("proptest.mcap", &ch);
            }
            Ok(Some(Event::Message(m))) => {
                got.push(Msg { seq: m.sequence, log_time: m.log_time, stamp: m.publish_time, data: m.data.to_vec() })
            }
            Ok(None) => return Ok((got, r.end().cloned())),
            Err(_) => return Ok((got, None)),
        }
    }
    Err(TestCaseError::fail(format!("more events than the {} bytes of the file", bytes.len())))
}

proptest! {
    // no regression files in the source tree: a failure prints its input
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::default() })]

    /// Written, then read: the same messages, and a complete end.
    #[test]
    fn proptest_mcap_round_trip(msgs in proptest::collection::vec(msg(), 0..32), chunk in 1u64..4096) {
        let bytes = recording(&msgs, chunk);
        let (got, end) = read_all(&bytes)?;
        prop_assert_eq!(got, msgs);
        prop_assert_eq!(end, Some(End::Complete));
    }

    /// Cut anywhere: a prefix of the messages, and an end that says so
/// unless every message was read.
    #[test]
    fn proptest_mcap_truncated(
        msgs in proptest::collection::vec(msg(), 0..32),
        chunk in 1u64..4096,
        cut in any::<prop::sample::Index>(),
    ) {
        let bytes = recording(&msgs, chunk);
        let n = cut.index(bytes.len());
        let (got, end) = read_all(&bytes[..n])?;
        prop_assert!(got.len() <= msgs.len());
        prop_assert_eq!(&got[..], &msgs[..got.len()]);
        // complete only when nothing was lost: a cut after the data's end
        // takes only the summary (an index of what was read)
        if end == Some(End::Complete) {
            prop_assert_eq!(got.len(), msgs.len(), "a file cut at {} of {} bytes read as complete", n, bytes.len());
        }
    }

    /// One byte changed, or bytes appended: no panic, bounded.
    #[test]
    fn proptest_mcap_mutated(
        msgs in proptest::collection::vec(msg(), 0..16),
        chunk in 1u64..4096,
        at in any::<prop::sample::Index>(),
        flip in 1u8..=255,
        tail in proptest::collection::vec(any::<u8>(), 0..64),
    ) {
        let mut bytes = recording(&msgs, chunk);
        let mut longer = bytes.clone();
        longer.extend_from_slice(&tail);
        read_all(&longer)?;
        let i = at.index(bytes.len());
        bytes[i] ^= flip;
        read_all(&bytes)?;
    }

    /// Arbitrary bytes after MCAP's magic (and after a valid header).
    #[test]
    fn proptest_mcap_arbitrary(body in proptest::collection::vec(any::<u8>(), 0..1024), header in any::<bool>()) {
        let mut bytes = if header { header_of(&recording(&[], 4096)) } else { mcap::MAGIC.to_vec() };
        bytes.extend_from_slice(&body);
        read_all(&bytes)?;
    }
}

/// MCAP's magic and the header record of a file nerve writes.
fn header_of(file: &[u8]) -> Vec<u8> {
    // magic (8), opcode (1), length (8), the record
    let len: [u8; 8] = file[9..17].try_into().expect("a header record");
    file[..17 + usize::try_from(u64::from_le_bytes(len)).expect("small")].to_vec()
}
