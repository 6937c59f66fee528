//! Property tests of every decoder of bytes that come from the network
//! (another ROS node): any bytes give a value or an error, never a panic or
//! an allocation the bytes cannot back; and what the writers write, the
//! readers read back unchanged.

use nerve_ros2::cdr::{Reader, Writer};
use nerve_ros2::msgs::{Header, LaserScan, Odometry, Quaternion, RosMessage, TfMessage, Time, Twist, Vector3};
use nerve_ros2::wire::Attachment;
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn any_bytes_decode_or_fail_cleanly(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let _ = Twist::from_cdr(&bytes);
        let _ = Odometry::from_cdr(&bytes);
        let _ = TfMessage::from_cdr(&bytes);
        let _ = LaserScan::from_cdr(&bytes);
        let _ = Attachment::decode(&bytes);
        if let Ok(mut r) = Reader::new(&bytes) {
            let _ = r.string();
            let _ = r.f32_seq();
            let _ = r.bytes();
        }
    }

    /// A valid header followed by anything: the decoders still only fail.
    #[test]
    fn cdr_bodies_decode_or_fail_cleanly(body in proptest::collection::vec(any::<u8>(), 0..300)) {
        let mut bytes = vec![0, 1, 0, 0];
        bytes.extend_from_slice(&body);
        let _ = Twist::from_cdr(&bytes);
        let _ = Odometry::from_cdr(&bytes);
        let _ = TfMessage::from_cdr(&bytes);
        let _ = LaserScan::from_cdr(&bytes);
    }

    #[test]
    fn what_is_written_reads_back(
        v in proptest::array::uniform6(-1e9f64..1e9),
        sec in any::<i32>(),
        nanosec in 0u32..1_000_000_000,
        frame in "[a-z_/]{0,20}",
        ranges in proptest::collection::vec(0f32..100.0, 0..40),
        seq in any::<i64>(),
        stamp in any::<i64>(),
        gid in proptest::array::uniform16(any::<u8>()),
    ) {
        let twist = Twist { linear: Vector3 { x: v[0], y: v[1], z: v[2] }, angular: Vector3 { x: v[3], y: v[4], z: v[5] } };
        prop_assert_eq!(Twist::from_cdr(&twist.to_cdr().expect("twist")), Ok(twist));
        let header = Header { stamp: Time { sec, nanosec }, frame_id: frame.clone() };
        let odom = Odometry {
            header: header.clone(),
            child_frame_id: frame.clone(),
            position: twist.linear,
            orientation: Quaternion::from_yaw(v[5]),
            pose_covariance: [v[0]; 36],
            twist,
            twist_covariance: [v[1]; 36],
        };
        prop_assert_eq!(Odometry::from_cdr(&odom.to_cdr().expect("odom")), Ok(odom));
        let scan = LaserScan { header, ranges: ranges.clone(), intensities: ranges, ..Default::default() };
        prop_assert_eq!(LaserScan::from_cdr(&scan.to_cdr().expect("scan")), Ok(scan));
        let a = Attachment { sequence_number: seq, source_timestamp: stamp, gid };
        prop_assert_eq!(Attachment::decode(&a.encode()), Ok(a));
        let mut w = Writer::new();
        w.string(&frame).expect("short");
        let b = w.finish();
        let mut r = Reader::new(&b).expect("header");
        prop_assert_eq!(r.string(), Ok(frame.as_str()));
    }
}
