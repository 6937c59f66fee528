//! Property tests of the serial framing (`FrameDecoder`) under generated
//! input (issue 40, "every decoder of outside bytes"): whatever a serial
//! line carries, in whatever pieces the reads return it, the decoder never
//! panics, keeps at most one frame's worth of bytes, accounts for every byte
//! (decoded, dropped as garbage, or pending), and gives the same messages
//! however the stream is cut into reads. Valid messages come back equal
//! (round trip); a stream with one byte flipped, a frame cut short or
//! garbage appended loses exactly the frame that was hit and resynchronises
//! on the next one.
//!
//! The default case count is proptest's (256, or `PROPTEST_CASES`); the long
//! run is in `docs/robustness.md`.

use nerve_devices::{
    ArmCommand, ArmState, EncoderReport, FrameDecoder, GRASP_NOTHING, GraspAction, GraspCommand, GraspState,
    GripperPhase, HeadCommand, HeadState, IrReport, IrSighting, MAX_FRAME_LEN, Message, SONAR_COUNT, SonarScan,
    WheelCommand,
};
use proptest::prelude::*;

/// What the line carries next in the tests that need it to go on: as many
/// zeros as the longest frame, which complete any claimed frame and hold no
/// sync pair.
const FLUSH: [u8; MAX_FRAME_LEN] = [0; MAX_FRAME_LEN];

/// Bytes of one framed message: sync (2), type, length, payload, CRC (2).
fn frame_len(m: &Message) -> usize {
    4 + m.message_type().payload_len() + 2
}

fn any_message() -> impl Strategy<Value = Message> {
    let phase = prop_oneof![
        Just(GripperPhase::Open),
        Just(GripperPhase::Closing),
        Just(GripperPhase::Holding),
        Just(GripperPhase::Missed)
    ];
    prop_oneof![
        (any::<u16>(), any::<[u16; SONAR_COUNT]>()).prop_map(|(seq, ranges_mm)| SonarScan { seq, ranges_mm }.into()),
        (any::<i16>(), any::<i16>()).prop_map(|(left_mm_s, right_mm_s)| WheelCommand { left_mm_s, right_mm_s }.into()),
        (any::<u16>(), any::<u32>(), any::<i32>(), any::<i32>())
            .prop_map(|(seq, time_ms, left, right)| EncoderReport { seq, time_ms, left, right }.into()),
        (any::<i16>(), any::<i16>()).prop_map(|(pan_cdeg, tilt_cdeg)| HeadCommand { pan_cdeg, tilt_cdeg }.into()),
        (any::<u16>(), any::<i16>(), any::<i16>()).prop_map(|(seq, pan_cdeg, tilt_cdeg)| HeadState {
            seq,
            pan_cdeg,
            tilt_cdeg
        }
        .into()),
        (any::<u16>(), proptest::option::of((any::<u8>(), 1u8..=0x0F))).prop_map(|(seq, s)| IrReport {
            seq,
            sighting: s.map(|(checkpoint_id, transmitters)| IrSighting { checkpoint_id, transmitters })
        }
        .into()),
        any::<[i16; 3]>().prop_map(|joints_cdeg| ArmCommand { joints_cdeg }.into()),
        (any::<u16>(), any::<[i16; 3]>()).prop_map(|(seq, joints_cdeg)| ArmState { seq, joints_cdeg }.into()),
        prop_oneof![Just(GraspAction::Release), Just(GraspAction::Grasp)]
            .prop_map(|action| GraspCommand { action }.into()),
        (any::<u16>(), phase, 0u8..GRASP_NOTHING, any::<u16>()).prop_map(|(seq, phase, id, nearest_mm)| {
            // only a holding gripper names what it holds
            let held_id = if phase == GripperPhase::Holding { id } else { GRASP_NOTHING };
            GraspState { seq, phase, held_id, nearest_mm }.into()
        }),
    ]
}

fn encode_all(msgs: &[Message]) -> Vec<u8> {
    let mut out = Vec::new();
    for m in msgs {
        m.encode_into(&mut out);
    }
    out
}

/// Feeds `bytes` in reads cut at `cuts` (fractions of the length), draining
/// the decoder after each read as an agent does; checks the bound on what it
/// keeps after every read and returns the messages.
fn feed(decoder: &mut FrameDecoder, bytes: &[u8], cuts: &[u16]) -> Vec<Message> {
    let mut at: Vec<usize> = cuts.iter().map(|&c| bytes.len() * usize::from(c) / usize::from(u16::MAX)).collect();
    at.push(0);
    at.push(bytes.len());
    at.sort_unstable();
    let mut got = Vec::new();
    for w in at.windows(2) {
        got.extend(decoder.push(&bytes[w[0]..w[1]]));
        assert!(decoder.pending() < MAX_FRAME_LEN, "the decoder keeps {} bytes after a read", decoder.pending());
    }
    got
}

/// Every byte fed is in a frame, dropped as garbage, or pending.
fn assert_accounted(decoder: &FrameDecoder, got: &[Message], fed: usize) {
    let in_frames: usize = got.iter().map(frame_len).sum();
    let garbage = usize::try_from(decoder.stats().garbage_bytes).expect("fits");
    assert_eq!(in_frames + garbage + decoder.pending(), fed, "bytes unaccounted for: {:?}", decoder.stats());
    assert_eq!(decoder.stats().frames, got.len() as u64);
}

proptest! {
    // no regression files in the source tree: a failure prints its input
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::default() })]

    /// Arbitrary bytes in arbitrary reads: no panic, bounded buffer, every
    /// byte accounted for, and the same result however the reads fall.
    #[test]
    fn proptest_serial_arbitrary_bytes(
        bytes in proptest::collection::vec(any::<u8>(), 0..2048),
        cuts in proptest::collection::vec(any::<u16>(), 0..16),
    ) {
        let mut whole = FrameDecoder::new();
        let once: Vec<Message> = whole.push(&bytes).collect();
        assert_accounted(&whole, &once, bytes.len());
        let mut pieces = FrameDecoder::new();
        let got = feed(&mut pieces, &bytes, &cuts);
        prop_assert_eq!(&got, &once);
        prop_assert_eq!(pieces.stats(), whole.stats());
        pieces.reset_stream();
        prop_assert_eq!(pieces.pending(), 0);
    }

    /// Random bytes rich in sync pairs and valid headers, so that the
    /// decoder's header, length and CRC paths are taken, not only the hunt.
    #[test]
    fn proptest_serial_sync_rich_bytes(
        parts in proptest::collection::vec(
            prop_oneof![
                Just(vec![0xA5, 0x5A]),
                any_message().prop_map(|m| {
                    let mut f = m.encode();
                    f.truncate(4); // a plausible header, then whatever follows
                    f
                }),
                proptest::collection::vec(any::<u8>(), 0..8),
            ],
            0..64,
        ),
        cuts in proptest::collection::vec(any::<u16>(), 0..16),
    ) {
        let bytes: Vec<u8> = parts.concat();
        let mut whole = FrameDecoder::new();
        let once: Vec<Message> = whole.push(&bytes).collect();
        assert_accounted(&whole, &once, bytes.len());
        let mut pieces = FrameDecoder::new();
        prop_assert_eq!(feed(&mut pieces, &bytes, &cuts), once);
    }

    /// decode(encode(x)) == x for every valid message, in any reads.
    #[test]
    fn proptest_serial_round_trip(
        msgs in proptest::collection::vec(any_message(), 0..24),
        cuts in proptest::collection::vec(any::<u16>(), 0..16),
    ) {
        let bytes = encode_all(&msgs);
        let mut d = FrameDecoder::new();
        let got = feed(&mut d, &bytes, &cuts);
        prop_assert_eq!(got, msgs);
        prop_assert_eq!(d.stats().rejected_frames(), 0);
        prop_assert_eq!(d.stats().garbage_bytes, 0);
        prop_assert_eq!(d.pending(), 0);
    }

    /// One byte flipped: exactly the frame that holds it is lost, every
    /// other one comes through (CRC-16 catches every single-byte error).
    #[test]
    fn proptest_serial_one_byte_flipped(
        msgs in proptest::collection::vec(any_message(), 1..16),
        at in any::<prop::sample::Index>(),
        flip in 1u8..=255,
        cuts in proptest::collection::vec(any::<u16>(), 0..8),
    ) {
        let mut bytes = encode_all(&msgs);
        let i = at.index(bytes.len());
        bytes[i] ^= flip;
        let hit = hit_frame(&msgs, i);
        // a flip may make a header whose claimed frame runs past the end:
        // the decoder then waits for more, as it must; the line goes on
        bytes.extend_from_slice(&FLUSH);
        let mut d = FrameDecoder::new();
        let got = feed(&mut d, &bytes, &cuts);
        let want: Vec<Message> = msgs.iter().enumerate().filter(|(k, _)| *k != hit).map(|(_, m)| *m).collect();
        prop_assert_eq!(got, want);
        prop_assert!(d.stats().rejected_frames() + d.stats().garbage_bytes > 0);
    }

    /// A frame cut short (the sender stopped mid-frame and began the next):
    /// every frame before it, and every frame that starts a longest frame's
    /// length after it or later, come through in order, and nothing is
    /// invented in their place. The cut frame is lost, and so is nothing
    /// else, except where the bytes that follow it happen to complete it
    /// with a good CRC (1 in 65536: a 16-bit CRC cannot tell): then a wrong
    /// message is taken in its place (or, with an impossible payload, its
    /// claimed length skipped), and the frames that length covers are lost. A stream cut short yields every whole frame before
    /// the cut.
    #[test]
    fn proptest_serial_truncated(
        msgs in proptest::collection::vec(any_message(), 1..16),
        which in any::<prop::sample::Index>(),
        keep in any::<prop::sample::Index>(),
        end in any::<prop::sample::Index>(),
    ) {
        let k = which.index(msgs.len());
        let mut bytes = Vec::new();
        // the first frame that starts a longest frame after the cut one
        let mut clear = msgs.len();
        let mut cut_at = usize::MAX - MAX_FRAME_LEN;
        for (j, m) in msgs.iter().enumerate() {
            if j > k && clear == msgs.len() && bytes.len() >= cut_at + MAX_FRAME_LEN {
                clear = j;
            }
            let f = m.encode();
            if j == k {
                cut_at = bytes.len();
                bytes.extend_from_slice(&f[..keep.index(f.len())]);
            } else {
                bytes.extend_from_slice(&f);
            }
        }
        // the cut frame's header claims bytes that may run past the end
        bytes.extend_from_slice(&FLUSH);
        let mut d = FrameDecoder::new();
        let got: Vec<Message> = d.push(&bytes).collect();
        let after = &msgs[clear..];
        prop_assert!(got.len() < msgs.len() || got == msgs, "{} messages from {}", got.len(), msgs.len());
        prop_assert!(got.len() >= k + after.len(), "{} messages from {}", got.len(), msgs.len());
        prop_assert_eq!(&got[..k], &msgs[..k]);
        prop_assert_eq!(&got[got.len() - after.len()..], after);
        // no CRC coincidence (nothing taken that was not sent, the cut frame
        // not completed by the bytes after it, no good CRC over an
        // impossible payload, whose whole claimed length is skipped): then
        // exactly the cut frame is lost
        let want: Vec<Message> = msgs.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, m)| *m).collect();
        if got.iter().all(|m| msgs.contains(m)) && got.get(k) != Some(&msgs[k]) && d.stats().invalid_payloads == 0 {
            prop_assert_eq!(got, want);
        }

        let whole = encode_all(&msgs);
        let cut = end.index(whole.len());
        let mut d = FrameDecoder::new();
        let got: Vec<Message> = d.push(&whole[..cut]).collect();
        let mut ends = 0;
        let before: Vec<Message> = msgs.iter().take_while(|m| { ends += frame_len(m); ends <= cut }).copied().collect();
        assert_accounted(&d, &before, cut);
        prop_assert_eq!(got, before);
    }

    /// Garbage after valid frames (or before them) never hides them.
    #[test]
    fn proptest_serial_extended(
        msgs in proptest::collection::vec(any_message(), 0..16),
        before in proptest::collection::vec(any::<u8>(), 0..64),
        after in proptest::collection::vec(any::<u8>(), 0..256),
    ) {
        let mut bytes = encode_all(&msgs);
        bytes.extend_from_slice(&after);
        let mut d = FrameDecoder::new();
        let got: Vec<Message> = d.push(&bytes).collect();
        prop_assert!(got.len() >= msgs.len());
        prop_assert_eq!(&got[..msgs.len()], &msgs[..]);
        // garbage first: the decoder hunts through it and finds every frame
        // after it (a header in the garbage whose claimed frame runs past
        // the end only holds them until the line goes on)
        let mut lead = before.clone();
        lead.extend_from_slice(&encode_all(&msgs));
        lead.extend_from_slice(&FLUSH);
        let mut d = FrameDecoder::new();
        let got: Vec<Message> = d.push(&lead).collect();
        prop_assert_eq!(got, msgs);
    }
}

/// The index of the frame that holds byte `i` of the encoded `msgs`.
fn hit_frame(msgs: &[Message], i: usize) -> usize {
    let mut end = 0;
    for (k, m) in msgs.iter().enumerate() {
        end += frame_len(m);
        if i < end {
            return k;
        }
    }
    msgs.len()
}
