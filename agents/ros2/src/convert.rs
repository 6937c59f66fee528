//! nerve's built-in payloads to and from standard ROS 2 messages. Pure
//! functions: the agent supplies the ROS stamp ([`ros_stamp`]) and frames.
//!
//! | nerve | ROS 2 |
//! |---|---|
//! | `nerve::Odometry` (x, y, θ, v, ω) | `nav_msgs/msg/Odometry`: position (x, y, 0), yaw θ, twist linear.x v, angular.z ω |
//! | `nerve::Odometry` | `tf2_msgs/msg/TFMessage`: one transform frame_id → child_frame_id |
//! | `nerve::GroundTruth` | `nav_msgs/msg/Odometry`, as above |
//! | `nerve::VelocityCommand` (v, ω) | `geometry_msgs/msg/Twist`: linear.x, angular.z |
//! | `nerve::SonarScan` (12 directions, 30° apart) | `sensor_msgs/msg/LaserScan`, a direction without echo is +inf (REP-117) |
//! | `nerve::SonarScan` | `sensor_msgs/msg/Range`, one per direction, frame `<frame>_<i>` (i = 0 ahead, counter-clockwise) |
//! | `geometry_msgs/msg/Twist` | `nerve::VelocityCommand`: v = linear.x, ω = angular.z (the other four must be 0) |

use crate::msgs::{
    Header, LaserScan, Odometry, Quaternion, Range, RosMessage as _, TfMessage, Time, TransformStamped, Twist, Vector3,
};
use shm_schemas::payloads::motion::{GroundTruth, Odometry as NerveOdometry, VelocityCommand};
use shm_schemas::payloads::sonar::{SONAR_DIRECTIONS, SonarScan};

/// The ROS stamp (ns since the UNIX epoch) of a sample stamped `stamp_ns`
/// on the robot's clock when that clock reads `now_ns` and the system clock
/// reads `epoch_now_ns`: the epoch time less the sample's age.
pub fn ros_stamp(stamp_ns: u64, now_ns: u64, epoch_now_ns: i128) -> Time {
    let age = i128::from(now_ns) - i128::from(stamp_ns);
    Time::from_ns(epoch_now_ns - age.max(0))
}

/// The system clock, ns since the UNIX epoch.
pub fn epoch_now_ns() -> i128 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as i128).unwrap_or_default()
}

/// The pose (x, y, θ) and speeds (v, ω) of a ground robot.
struct Planar {
    x: f64,
    y: f64,
    theta: f64,
    v: f64,
    omega: f64,
}

fn odometry(stamp: Time, frame: &str, child: &str, p: Planar) -> Odometry {
    let Planar { x, y, theta, v, omega } = p;
    Odometry {
        header: Header { stamp, frame_id: frame.to_owned() },
        child_frame_id: child.to_owned(),
        position: Vector3 { x, y, z: 0.0 },
        orientation: Quaternion::from_yaw(theta),
        pose_covariance: [0.0; 36],
        twist: Twist { linear: Vector3 { x: v, y: 0.0, z: 0.0 }, angular: Vector3 { x: 0.0, y: 0.0, z: omega } },
        twist_covariance: [0.0; 36],
    }
}

/// `nerve::Odometry` → `nav_msgs/msg/Odometry`.
pub fn odometry_to_ros(o: &NerveOdometry, stamp: Time, frame: &str, child: &str) -> Odometry {
    odometry(stamp, frame, child, Planar { x: o.x, y: o.y, theta: o.theta, v: o.v, omega: o.omega })
}

/// `nerve::GroundTruth` → `nav_msgs/msg/Odometry`.
pub fn truth_to_ros(t: &GroundTruth, stamp: Time, frame: &str, child: &str) -> Odometry {
    odometry(stamp, frame, child, Planar { x: t.x, y: t.y, theta: t.theta, v: t.v, omega: t.omega })
}

/// `nerve::Odometry` → `tf2_msgs/msg/TFMessage` with one transform.
pub fn odometry_to_tf(o: &NerveOdometry, stamp: Time, frame: &str, child: &str) -> TfMessage {
    TfMessage {
        transforms: vec![TransformStamped {
            header: Header { stamp, frame_id: frame.to_owned() },
            child_frame_id: child.to_owned(),
            translation: Vector3 { x: o.x, y: o.y, z: 0.0 },
            rotation: Quaternion::from_yaw(o.theta),
        }],
    }
}

/// The `[[static_transform]]`s of the configuration as one
/// `tf2_msgs/msg/TFMessage` for /tf_static, all stamped `stamp` (as tf2's
/// static broadcaster sends them: every transform in one message).
pub fn static_tf(transforms: &[crate::config::Static], stamp: Time) -> TfMessage {
    TfMessage {
        transforms: transforms
            .iter()
            .map(|t| {
                let [x, y, z] = t.translation;
                let [roll, pitch, yaw] = t.rotation;
                TransformStamped {
                    header: Header { stamp, frame_id: t.frame_id.clone() },
                    child_frame_id: t.child_frame_id.clone(),
                    translation: Vector3 { x, y, z },
                    rotation: Quaternion::from_rpy(roll, pitch, yaw),
                }
            })
            .collect(),
    }
}

/// `nerve::VelocityCommand` → `geometry_msgs/msg/Twist`.
pub fn velocity_to_twist(c: &VelocityCommand) -> Twist {
    Twist { linear: Vector3 { x: c.v, y: 0.0, z: 0.0 }, angular: Vector3 { x: 0.0, y: 0.0, z: c.omega } }
}

/// The angle between two sonar directions, rad.
pub const SONAR_STEP: f32 = std::f32::consts::TAU / SONAR_DIRECTIONS as f32;
/// The sonar's shortest range, m.
pub const SONAR_RANGE_MIN: f32 = 0.15;
/// The sonar's longest range, m.
pub const SONAR_RANGE_MAX: f32 = 5.0;

/// `nerve::SonarScan` → `sensor_msgs/msg/LaserScan`: direction i at
/// i·30°, a direction without echo +inf.
/// The arc of one sonar transducer's beam: 25° (the H1's, as the simulator
/// models it: a half beam of 12.5°).
pub const SONAR_FIELD_OF_VIEW: f32 = 25.0 * std::f32::consts::PI / 180.0;

/// `nerve::SonarScan` → one `sensor_msgs/msg/Range` per direction, the
/// frame of direction `i` (`i` × 30° from ahead, counter-clockwise) named
/// `<frame>_<i>`; a direction without echo is +inf (REP-117).
pub fn sonar_to_ranges(s: &SonarScan, stamp: Time, frame: &str) -> Vec<Range> {
    (0..SONAR_DIRECTIONS)
        .map(|i| Range {
            header: Header { stamp, frame_id: format!("{frame}_{i}") },
            radiation_type: Range::ULTRASOUND,
            field_of_view: SONAR_FIELD_OF_VIEW,
            min_range: SONAR_RANGE_MIN,
            max_range: SONAR_RANGE_MAX,
            range: if s.valid[i] == 1 && s.ranges_m[i].is_finite() { s.ranges_m[i] } else { f32::INFINITY },
            variance: 0.0,
        })
        .collect()
}

pub fn sonar_to_scan(s: &SonarScan, stamp: Time, frame: &str) -> LaserScan {
    LaserScan {
        header: Header { stamp, frame_id: frame.to_owned() },
        angle_min: 0.0,
        angle_max: SONAR_STEP * (SONAR_DIRECTIONS - 1) as f32,
        angle_increment: SONAR_STEP,
        time_increment: 0.0,
        scan_time: 0.0,
        range_min: SONAR_RANGE_MIN,
        range_max: SONAR_RANGE_MAX,
        ranges: (0..SONAR_DIRECTIONS)
            .map(|i| if s.valid[i] == 1 && s.ranges_m[i].is_finite() { s.ranges_m[i] } else { f32::INFINITY })
            .collect(),
        intensities: Vec::new(),
    }
}

/// The `encoding` of `sensor_msgs/msg/Image` for a ring's pixel format
/// code (`rgb8`, `mono8`), or `None` for a format ROS has no name for.
pub fn image_encoding(format: Option<agent_sdk::memory::PixelFormat>) -> Option<&'static str> {
    use agent_sdk::memory::PixelFormat;
    match format? {
        PixelFormat::Rgb8 => Some("rgb8"),
        PixelFormat::Gray8 => Some("mono8"),
        _ => None,
    }
}

/// A `sensor_msgs/msg/Image` written in CDR straight from the pixels of a
/// ring slot (one copy, into the message): `width` x `height`, `channels`
/// bytes per pixel, rows packed. `None` when the sizes overflow or do not
/// fit in `px` (the sizes come from another process's ring).
pub fn image_cdr(
    stamp: Time,
    frame: &str,
    width: u32,
    height: u32,
    encoding: &str,
    channels: u32,
    px: &[u8],
) -> Option<Result<Vec<u8>, crate::cdr::CdrError>> {
    let step = width.checked_mul(channels)?;
    let n = usize::try_from(u64::from(step).checked_mul(u64::from(height))?).ok()?;
    let data = px.get(..n)?;
    let mut w = crate::cdr::Writer::with_capacity(n + 64);
    let run = |w: &mut crate::cdr::Writer| -> Result<(), crate::cdr::CdrError> {
        Header { stamp, frame_id: frame.to_owned() }.write(w)?;
        w.u32(height);
        w.u32(width);
        w.string(encoding)?;
        w.u8(0); // is_bigendian
        w.u32(step);
        w.bytes(data)
    };
    Some(run(&mut w).map(|()| w.finish()))
}

/// Why a ROS message was not delivered to nerve.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RefusedMessage {
    /// A value is NaN or infinite.
    #[error("a Twist with a value that is not finite ({twist:?})")]
    NotFinite {
        /// the message
        twist: Twist,
    },
    /// A component a ground robot cannot follow.
    #[error(
        "a Twist asks for motion a ground robot cannot make (linear.y/z or angular.x/y not 0: {twist:?}); only linear.x and angular.z are followed"
    )]
    NotPlanar {
        /// the message
        twist: Twist,
    },
}

/// `geometry_msgs/msg/Twist` → `nerve::VelocityCommand` stamped `now_ns`
/// (the robot's clock: the motor refuses stale commands by it).
pub fn twist_to_velocity(t: &Twist, now_ns: u64) -> Result<VelocityCommand, RefusedMessage> {
    let all = [t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z];
    if !all.iter().all(|v| v.is_finite()) {
        return Err(RefusedMessage::NotFinite { twist: *t });
    }
    if [t.linear.y, t.linear.z, t.angular.x, t.angular.y].iter().any(|v| *v != 0.0) {
        return Err(RefusedMessage::NotPlanar { twist: *t });
    }
    Ok(VelocityCommand { v: t.linear.x, omega: t.angular.z, stamp_ns: now_ns })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn odometry_maps_pose_and_speeds() {
        let o = NerveOdometry { x: 1.5, y: -2.0, theta: std::f64::consts::FRAC_PI_2, v: 0.3, omega: 0.1, stamp_ns: 5 };
        let r = odometry_to_ros(&o, Time { sec: 1, nanosec: 0 }, "odom", "base_link");
        assert_eq!((r.position.x, r.position.y, r.position.z), (1.5, -2.0, 0.0));
        let q = r.orientation;
        assert!(
            (q.z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12
                && (q.w - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12
        );
        assert_eq!((r.twist.linear.x, r.twist.angular.z), (0.3, 0.1));
        assert_eq!((r.header.frame_id.as_str(), r.child_frame_id.as_str()), ("odom", "base_link"));
        let tf = odometry_to_tf(&o, Time::default(), "odom", "base_link");
        assert_eq!(tf.transforms[0].translation.x, 1.5);
    }

    #[test]
    fn twist_both_ways_and_refusals() {
        let c = VelocityCommand { v: 0.2, omega: -0.4, stamp_ns: 7 };
        let t = velocity_to_twist(&c);
        assert_eq!(twist_to_velocity(&t, 9), Ok(VelocityCommand { v: 0.2, omega: -0.4, stamp_ns: 9 }));
        let mut bad = t;
        bad.linear.x = f64::NAN;
        assert!(matches!(twist_to_velocity(&bad, 9), Err(RefusedMessage::NotFinite { .. })));
        let mut side = t;
        side.linear.y = 0.1;
        assert!(twist_to_velocity(&side, 9).expect_err("sideways").to_string().contains("linear.y"));
    }

    #[test]
    fn stamps_move_to_the_epoch_by_the_sample_age() {
        // a sample 0.25 s old when the epoch reads 100.5 s
        assert_eq!(ros_stamp(750_000_000, 1_000_000_000, 100_500_000_000), Time { sec: 100, nanosec: 250_000_000 });
        // a stamp from the future counts as now
        assert_eq!(ros_stamp(2, 1, 3_000_000_000), Time { sec: 3, nanosec: 0 });
    }

    /// The Image as `sensor_msgs/msg/Image` lays it out, worked out by
    /// hand: header (stamp 8, frame "cam" 4 + 4), height, width, encoding
    /// "rgb8" (4 + 5), is_bigendian, 2 bytes of padding, step, the data's
    /// count and bytes.
    #[test]
    fn image_is_written_from_the_ring_bytes() {
        let px: Vec<u8> = (0..2 * 3 * 3 + 5).map(|i| i as u8).collect(); // a slot larger than the frame
        let b = image_cdr(Time { sec: 1, nanosec: 2 }, "cam", 2, 3, "rgb8", 3, &px).expect("fits").expect("cdr");
        let mut want = vec![0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 4, 0, 0, 0, b'c', b'a', b'm', 0];
        want.extend_from_slice(&[3, 0, 0, 0, 2, 0, 0, 0, 5, 0, 0, 0, b'r', b'g', b'b', b'8', 0]);
        want.extend_from_slice(&[0, 0, 0, 6, 0, 0, 0, 18, 0, 0, 0]);
        want.extend_from_slice(&px[..18]);
        assert_eq!(b, want);
        // sizes that overflow or do not fit the slot are refused
        assert!(image_cdr(Time::default(), "", u32::MAX, u32::MAX, "rgb8", 3, &px).is_none());
        assert!(image_cdr(Time::default(), "", 4, 4, "rgb8", 3, &px).is_none());
    }

    /// tf2's `setRPY` conventions: a quarter turn about z is (0, 0, sin 45°,
    /// cos 45°); a half turn about x is (1, 0, 0, 0); all transforms go in
    /// one message.
    #[test]
    fn static_transforms_in_one_message() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let q = Quaternion::from_rpy(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!((q.z - h).abs() < 1e-12 && (q.w - h).abs() < 1e-12 && q.x == 0.0 && q.y == 0.0, "{q:?}");
        let q = Quaternion::from_rpy(std::f64::consts::PI, 0.0, 0.0);
        assert!((q.x - 1.0).abs() < 1e-12 && q.w.abs() < 1e-12, "{q:?}");
        let t = |child: &str| crate::config::Static {
            frame_id: "base_link".into(),
            child_frame_id: child.into(),
            translation: [1.0, 2.0, 3.0],
            rotation: [0.0; 3],
        };
        let m = static_tf(&[t("camera"), t("sonar")], Time { sec: 5, nanosec: 6 });
        assert_eq!(m.transforms.len(), 2);
        assert_eq!((m.transforms[1].child_frame_id.as_str(), m.transforms[1].header.stamp.sec), ("sonar", 5));
        assert_eq!(m.transforms[0].translation, Vector3 { x: 1.0, y: 2.0, z: 3.0 });
    }

    /// A Range as `sensor_msgs/msg/Range` lays it out, worked out by hand:
    /// header (stamp 8, frame "s_1" 4 + 4), radiation_type 1 byte, 3 bytes
    /// of padding to the f32s, five f32.
    #[test]
    fn sonar_directions_are_ranges() {
        let mut s = SonarScan::default();
        s.ranges_m[1] = 1.5;
        s.valid[1] = 1;
        let r = sonar_to_ranges(&s, Time { sec: 2, nanosec: 3 }, "s");
        assert_eq!(r.len(), 12);
        assert!(r[0].range.is_infinite() && r[11].header.frame_id == "s_11");
        let b = r[1].to_cdr().expect("cdr");
        let mut want = vec![0, 1, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, 4, 0, 0, 0, b's', b'_', b'1', 0, 0, 0, 0, 0];
        for v in [SONAR_FIELD_OF_VIEW, SONAR_RANGE_MIN, SONAR_RANGE_MAX, 1.5, 0.0] {
            want.extend_from_slice(&v.to_le_bytes());
        }
        assert_eq!(b, want);
        assert_eq!(Range::from_cdr(&b).expect("reads back"), r[1]);
    }

    #[test]
    fn sonar_without_echo_is_infinite() {
        let mut s = SonarScan::default();
        s.ranges_m[0] = 1.25;
        s.valid[0] = 1;
        s.ranges_m[3] = 2.0; // no echo flag: not a reading
        let l = sonar_to_scan(&s, Time::default(), "base_link");
        assert_eq!(l.ranges.len(), 12);
        assert_eq!(l.ranges[0], 1.25);
        assert!(l.ranges[3].is_infinite());
        assert!((l.angle_increment - 30f32.to_radians()).abs() < 1e-6);
    }
}
