//! Framing tests: round trips of every message, and the decoder's
//! resynchronisation after garbage, truncated frames, bad checksums and
//! 64 KiB of random noise, with every drop counted.

use nerve_devices::frame::write_frame;
use nerve_devices::{
    ArmCommand, ArmState, DecodeStats, EncoderReport, FrameDecoder, GRASP_NOTHING, GraspAction, GraspCommand,
    GraspState, GripperPhase, HeadCommand, HeadState, IrReport, IrSighting, MAX_FRAME_LEN, Message, SONAR_NO_ECHO,
    SonarScan, WheelCommand,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn samples() -> Vec<Message> {
    let mut ranges = [0u16; 12];
    for (i, r) in ranges.iter_mut().enumerate() {
        *r = 150 + 700 * i as u16;
    }
    ranges[3] = SONAR_NO_ECHO;
    vec![
        SonarScan { seq: 65535, ranges_mm: ranges }.into(),
        WheelCommand { left_mm_s: -300, right_mm_s: 450 }.into(),
        EncoderReport { seq: 7, time_ms: 123_456, left: -5_000_000, right: i32::MAX }.into(),
        HeadCommand { pan_cdeg: -9000, tilt_cdeg: 1500 }.into(),
        HeadState { seq: 1, pan_cdeg: 4500, tilt_cdeg: -2000 }.into(),
        IrReport { seq: 2, sighting: None }.into(),
        IrReport { seq: 3, sighting: Some(IrSighting { checkpoint_id: 4, transmitters: 0b0011 }) }.into(),
        ArmCommand { joints_cdeg: [100, -200, 300] }.into(),
        ArmState { seq: 9, joints_cdeg: [-1, 0, 1] }.into(),
        GraspCommand { action: GraspAction::Grasp }.into(),
        GraspState { seq: 9, phase: GripperPhase::Missed, held_id: GRASP_NOTHING, nearest_mm: 1234 }.into(),
        GraspState { seq: 10, phase: GripperPhase::Holding, held_id: 9, nearest_mm: 35 }.into(),
    ]
}

fn stream(msgs: &[Message]) -> Vec<u8> {
    let mut out = Vec::new();
    for m in msgs {
        m.encode_into(&mut out);
    }
    out
}

#[test]
fn round_trip_all_messages_whole_and_bytewise() {
    let msgs = samples();
    let bytes = stream(&msgs);

    let mut d = FrameDecoder::new();
    let got: Vec<Message> = d.push(&bytes).collect();
    assert_eq!(got, msgs);
    assert_eq!(d.stats(), DecodeStats { frames: msgs.len() as u64, ..Default::default() });

    let mut d = FrameDecoder::new();
    let mut got = Vec::new();
    for b in &bytes {
        got.extend(d.push(std::slice::from_ref(b)));
    }
    assert_eq!(got, msgs);
    assert_eq!(d.stats().garbage_bytes, 0);
    assert_eq!(d.pending(), 0);
}

#[test]
fn garbage_is_counted_and_skipped() {
    let msgs = samples();
    let mut bytes = b"hello\xA5\x00\xA5".to_vec();
    msgs[0].encode_into(&mut bytes);
    bytes.extend_from_slice(&[0x5A, 0xA5, 0x01, 0x02]);
    msgs[1].encode_into(&mut bytes);
    let mut d = FrameDecoder::new();
    let got: Vec<Message> = d.push(&bytes).collect();
    assert_eq!(got, msgs[..2].to_vec());
    assert_eq!(d.stats().garbage_bytes, 8 + 4);
    assert_eq!(d.stats().frames, 2);
}

#[test]
fn truncated_frame_is_counted_and_next_frame_recovered() {
    let msgs = samples();
    let full = msgs[0].encode();
    let mut bytes = full[..full.len() / 2].to_vec(); // sender died mid-frame
    msgs[2].encode_into(&mut bytes);
    msgs[0].encode_into(&mut bytes); // enough bytes to complete the bogus length
    let mut d = FrameDecoder::new();
    let got: Vec<Message> = d.push(&bytes).collect();
    assert_eq!(got, vec![msgs[2], msgs[0]]);
    assert_eq!(d.stats().truncated, 1);
    assert_eq!(d.stats().bad_checksums, 0);
    assert_eq!(d.stats().garbage_bytes, (full.len() / 2) as u64);
}

#[test]
fn bad_checksum_is_counted_and_next_frame_recovered() {
    let msgs = samples();
    let mut bad = msgs[1].encode();
    bad[5] ^= 0x40; // corrupt a payload bit
    let mut bytes = bad.clone();
    msgs[3].encode_into(&mut bytes);
    let mut d = FrameDecoder::new();
    let got: Vec<Message> = d.push(&bytes).collect();
    assert_eq!(got, vec![msgs[3]]);
    assert_eq!(d.stats().bad_checksums, 1);
    assert_eq!(d.stats().garbage_bytes, bad.len() as u64);

    // a corrupted CRC byte is caught the same way
    let mut bad = msgs[4].encode();
    let last = bad.len() - 1;
    bad[last] ^= 0x01;
    let got: Vec<Message> = d.push(&bad).chain(std::iter::empty()).collect();
    assert!(got.is_empty());
    let got: Vec<Message> = d.push(&msgs[4].encode()).collect();
    assert_eq!(got, vec![msgs[4]]);
    assert_eq!(d.stats().bad_checksums, 2);
}

#[test]
fn bad_header_and_invalid_payload_are_counted() {
    let mut bytes = Vec::new();
    write_frame(0x7E, &[1, 2, 3], &mut bytes); // unknown type
    write_frame(0x20, &[1, 2, 3], &mut bytes); // wheel command must be 4 bytes
    write_frame(0x40, &[0, 0, 1, 0x30], &mut bytes); // IR mask above 4 transmitters
    let ok: Message = WheelCommand { left_mm_s: 1, right_mm_s: 2 }.into();
    ok.encode_into(&mut bytes);
    let mut d = FrameDecoder::new();
    let got: Vec<Message> = d.push(&bytes).collect();
    assert_eq!(got, vec![ok]);
    assert_eq!(d.stats().bad_headers, 2);
    assert_eq!(d.stats().invalid_payloads, 1);
    assert_eq!(d.stats().rejected_frames(), 3);
}

#[test]
fn reset_stream_counts_partial_frame_as_truncated() {
    let m = samples()[0].encode();
    let mut d = FrameDecoder::new();
    assert_eq!(d.push(&m[..10]).count(), 0);
    d.reset_stream();
    assert_eq!(d.stats().truncated, 1);
    assert_eq!(d.pending(), 0);
    assert_eq!(d.push(&m).count(), 1);
}

#[test]
fn survives_64_kib_of_noise_and_resynchronises() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5eed);
    let mut noise = vec![0u8; 64 * 1024];
    rng.fill(&mut noise[..]);
    // make sync pairs and plausible headers frequent, to exercise resync
    for i in (0..noise.len() - 4).step_by(97) {
        noise[i] = 0xA5;
        noise[i + 1] = 0x5A;
        noise[i + 2] = 0x10;
        noise[i + 3] = 26;
    }
    let msgs = samples();
    let mut bytes = stream(&msgs[..3]);
    bytes.extend_from_slice(&noise);
    bytes.extend_from_slice(&stream(&msgs));

    let mut d = FrameDecoder::new();
    let mut got = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let n = rng.random_range(1..300).min(bytes.len() - i);
        got.extend(d.push(&bytes[i..i + n]));
        assert!(d.pending() < MAX_FRAME_LEN, "decoder buffer must stay bounded");
        i += n;
    }
    let mut want = msgs[..3].to_vec();
    want.extend_from_slice(&msgs);
    assert_eq!(got, want, "no frame invented from noise, none lost after it");
    let s = d.stats();
    assert_eq!(s.frames, want.len() as u64);
    assert!(s.garbage_bytes >= noise.len() as u64 - 2 * MAX_FRAME_LEN as u64);
    assert!(s.garbage_bytes <= noise.len() as u64);
    assert!(s.bad_checksums + s.truncated > 600, "planted headers rejected by CRC: {s:?}");
}
