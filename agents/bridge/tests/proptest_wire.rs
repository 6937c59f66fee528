//! Property tests of the bridge's frames (`wire::decode_frame`,
//! `wire::decode_ack`) under generated input (issue 40, "every decoder of
//! outside bytes"): whatever a peer sends, the decoders return a frame or an
//! error, never panic and never allocate (a frame borrows from the bytes it
//! came in). Valid frames round-trip; a frame cut short or with bytes
//! appended is refused; a frame with one byte changed is refused or decodes
//! to exactly what those bytes say (the layout has no checksum: Zenoh's
//! transport carries the bytes intact, the decoder checks structure).
//!
//! The default case count is proptest's (256, or `PROPTEST_CASES`); the long
//! run is in `docs/robustness.md`.

use nerve_bridge::wire::{Ack, Frame, MAX_TYPE_NAME, WireError, decode_ack, decode_frame, encode_ack, encode_frame};
use proptest::prelude::*;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// Counts the allocations of the calling thread, so that a test can show a
/// decoder allocates nothing (or within a bound).
struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded unchanged to the system allocator; the
// counter is a thread-local `Cell` without a destructor, which never
// allocates.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        // SAFETY: the caller's contract is the system allocator's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System.alloc` with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        // SAFETY: `ptr` came from `System.alloc` with this layout.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static COUNTING: Counting = Counting;

/// `f()`, and how many allocations it made on this thread.
fn allocations_of<R>(f: impl FnOnce() -> R) -> (R, usize) {
    let before = ALLOCATIONS.with(Cell::get);
    let r = f();
    (r, ALLOCATIONS.with(Cell::get) - before)
}

/// The owned parts of a frame, to generate and compare.
#[derive(Debug, Clone)]
struct Owned {
    reliable: bool,
    type_name: String,
    fingerprint: u64,
    instance: u64,
    seq: u64,
    oldest: u64,
    stamp_unix_ns: u64,
    origin_seq: u64,
    sender: String,
    payload: Vec<u8>,
}

impl Owned {
    fn frame(&self) -> Frame<'_> {
        Frame {
            reliable: self.reliable,
            type_name: &self.type_name,
            fingerprint: self.fingerprint,
            instance: self.instance,
            seq: self.seq,
            oldest: self.oldest,
            stamp_unix_ns: self.stamp_unix_ns,
            origin_seq: self.origin_seq,
            sender: &self.sender,
            payload: &self.payload,
        }
    }
}

/// A string of at most `max` bytes (of any characters, multi-byte included).
fn text(max: usize) -> impl Strategy<Value = String> {
    any::<String>().prop_map(move |s| {
        let mut end = s.len().min(max);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        s[..end].to_string()
    })
}

fn valid_frame() -> impl Strategy<Value = Owned> {
    (
        any::<bool>(),
        text(MAX_TYPE_NAME),
        any::<[u64; 4]>(),
        (1u64..=u64::MAX, any::<u64>()),
        text(usize::from(u8::MAX)),
        proptest::collection::vec(any::<u8>(), 0..512),
    )
        .prop_map(
            |(
                reliable,
                type_name,
                [fingerprint, instance, stamp_unix_ns, origin_seq],
                (seq, back),
                sender,
                payload,
            )| {
                Owned {
                    reliable,
                    type_name,
                    fingerprint,
                    instance,
                    seq,
                    oldest: seq - back % seq,
                    stamp_unix_ns,
                    origin_seq,
                    sender,
                    payload,
                }
            },
        )
}

/// Where a data frame's flags are (after the magic and the version); only
/// bit 0 (reliable) is defined.
const FLAGS_AT: usize = 5;

fn encoded(f: &Owned) -> Vec<u8> {
    let mut out = Vec::new();
    encode_frame(&mut out, &f.frame());
    out
}

proptest! {
    // no regression files in the source tree: a failure prints its input
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::default() })]

    /// Arbitrary bytes: an error or a frame, no panic, no allocation; what
    /// decodes re-encodes to the same bytes (nothing is read past them).
    #[test]
    fn proptest_bridge_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..1024)) {
        let (frame, n) = allocations_of(|| decode_frame(&bytes));
        prop_assert_eq!(n, 0, "decode_frame allocated");
        if let Ok(f) = frame {
            let mut again = Vec::new();
            encode_frame(&mut again, &f);
            let mut defined = bytes.clone();
            defined[FLAGS_AT] &= 1;
            prop_assert_eq!(again, defined);
        }
        let (ack, n) = allocations_of(|| decode_ack(&bytes));
        prop_assert_eq!(n, 0, "decode_ack allocated");
        if let Ok(a) = ack {
            prop_assert_eq!(encode_ack(&a), bytes);
        }
    }

    /// Arbitrary bytes after a valid magic and version, so that the
    /// decoders' length and text checks are reached, not only the magic's.
    #[test]
    fn proptest_bridge_arbitrary_bodies(
        data in any::<bool>(),
        body in proptest::collection::vec(any::<u8>(), 0..512),
    ) {
        let mut bytes = if data { b"NRVB".to_vec() } else { b"NRVA".to_vec() };
        bytes.push(nerve_bridge::wire::WIRE_VERSION);
        bytes.extend_from_slice(&body);
        let (frame, n) = allocations_of(|| decode_frame(&bytes).map(|f| (f.seq, f.payload.len())));
        prop_assert_eq!(n, 0);
        if let Ok((seq, _)) = frame {
            prop_assert!(seq >= 1);
        }
        let (_, n) = allocations_of(|| decode_ack(&bytes).map(|a| a.acked));
        prop_assert_eq!(n, 0);
    }

    /// decode(encode(x)) == x for every valid data frame and acknowledgement.
    #[test]
    fn proptest_bridge_round_trip(
        f in valid_frame(),
        instance in any::<u64>(),
        acked in any::<u64>(),
        importer in text(usize::from(u8::MAX)),
    ) {
        let bytes = encoded(&f);
        prop_assert_eq!(decode_frame(&bytes), Ok(f.frame()));
        let a = Ack { instance, acked, importer: &importer };
        let ack = encode_ack(&a);
        prop_assert_eq!(decode_ack(&ack), Ok(a));
        // one kind is never taken for the other
        prop_assert_eq!(decode_ack(&bytes), Err(WireError::Magic));
        prop_assert_eq!(decode_frame(&ack), Err(WireError::Magic));
    }

    /// Every cut of a valid frame, and every extension, is refused.
    #[test]
    fn proptest_bridge_truncated_or_extended(
        f in valid_frame(),
        cut in any::<prop::sample::Index>(),
        tail in proptest::collection::vec(any::<u8>(), 1..64),
        importer in text(usize::from(u8::MAX)),
    ) {
        let bytes = encoded(&f);
        let n = cut.index(bytes.len());
        prop_assert!(decode_frame(&bytes[..n]).is_err(), "a frame cut at {} of {} bytes was taken", n, bytes.len());
        let mut longer = bytes.clone();
        longer.extend_from_slice(&tail);
        prop_assert!(decode_frame(&longer).is_err());

        let ack = encode_ack(&Ack { instance: 1, acked: 2, importer: &importer });
        let n = cut.index(ack.len());
        prop_assert!(decode_ack(&ack[..n]).is_err());
        let mut longer = ack.clone();
        longer.extend_from_slice(&tail);
        prop_assert!(decode_ack(&longer).is_err());
    }

    /// One byte changed: refused, or taken as exactly what the bytes say
    /// (the same bytes come out of encoding what was decoded, except the
    /// flag bits that this version does not define: they are ignored).
    #[test]
    fn proptest_bridge_one_byte_flipped(
        f in valid_frame(),
        at in any::<prop::sample::Index>(),
        flip in 1u8..=255,
    ) {
        let mut bytes = encoded(&f);
        let i = at.index(bytes.len());
        bytes[i] ^= flip;
        if let Ok(g) = decode_frame(&bytes) {
            let mut again = Vec::new();
            encode_frame(&mut again, &g);
            bytes[FLAGS_AT] &= 1;
            prop_assert_eq!(again, bytes);
        }
    }
}
