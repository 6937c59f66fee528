//! The standard ROS 2 messages the agent speaks, as Rust values that write
//! and read themselves in CDR ([`crate::cdr`]). Their field lists are those
//! of the vendored `.msg` files (`msg/`), whose hashes `build.rs` computes;
//! a test checks each writer against the field list it must follow.

use crate::cdr::{CdrError, Reader, Writer};

/// A message type the agent can write and read.
pub trait RosMessage: Sized {
    /// `pkg/msg/Name`
    const TYPE: &'static str;
    /// Writes the fields (no header).
    fn write(&self, w: &mut Writer) -> Result<(), CdrError>;
    /// Reads the fields (no header).
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError>;

    /// The whole CDR message, header first.
    fn to_cdr(&self) -> Result<Vec<u8>, CdrError> {
        let mut w = Writer::new();
        self.write(&mut w)?;
        Ok(w.finish())
    }

    /// Reads a whole CDR message.
    fn from_cdr(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(bytes)?;
        let v = Self::read(&mut r)?;
        r.finish()?;
        Ok(v)
    }
}

/// `builtin_interfaces/msg/Time`
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Time {
    /// seconds
    pub sec: i32,
    /// nanoseconds, below 1e9
    pub nanosec: u32,
}

impl Time {
    /// From nanoseconds since the epoch (saturating at the ends of `i32`
    /// seconds).
    pub fn from_ns(ns: i128) -> Self {
        let sec = ns.div_euclid(1_000_000_000);
        let nanosec = ns.rem_euclid(1_000_000_000) as u32;
        match i32::try_from(sec) {
            Ok(sec) => Time { sec, nanosec },
            Err(_) if sec < 0 => Time { sec: i32::MIN, nanosec: 0 },
            Err(_) => Time { sec: i32::MAX, nanosec: 999_999_999 },
        }
    }
}

impl RosMessage for Time {
    const TYPE: &'static str = "builtin_interfaces/msg/Time";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        w.i32(self.sec);
        w.u32(self.nanosec);
        Ok(())
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        Ok(Time { sec: r.i32()?, nanosec: r.u32()? })
    }
}

/// `std_msgs/msg/Header`
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Header {
    /// when
    pub stamp: Time,
    /// in which frame
    pub frame_id: String,
}

impl RosMessage for Header {
    const TYPE: &'static str = "std_msgs/msg/Header";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        self.stamp.write(w)?;
        w.string(&self.frame_id)
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        Ok(Header { stamp: Time::read(r)?, frame_id: r.string()?.to_owned() })
    }
}

/// `geometry_msgs/msg/Vector3` (and `Point`, which has the same fields)
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Vector3 {
    /// x
    pub x: f64,
    /// y
    pub y: f64,
    /// z
    pub z: f64,
}

impl RosMessage for Vector3 {
    const TYPE: &'static str = "geometry_msgs/msg/Vector3";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        w.f64(self.x);
        w.f64(self.y);
        w.f64(self.z);
        Ok(())
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        Ok(Vector3 { x: r.f64()?, y: r.f64()?, z: r.f64()? })
    }
}

/// `geometry_msgs/msg/Quaternion`
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quaternion {
    /// x
    pub x: f64,
    /// y
    pub y: f64,
    /// z
    pub z: f64,
    /// w
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

impl Quaternion {
    /// A rotation by `yaw` radians about z.
    pub fn from_yaw(yaw: f64) -> Self {
        let (s, c) = (yaw / 2.0).sin_cos();
        Quaternion { x: 0.0, y: 0.0, z: s, w: c }
    }

    /// The rotation by `roll` about x, then `pitch` about y, then `yaw`
    /// about z (fixed axes, as tf2's `setRPY`).
    pub fn from_rpy(roll: f64, pitch: f64, yaw: f64) -> Self {
        let (sr, cr) = (roll / 2.0).sin_cos();
        let (sp, cp) = (pitch / 2.0).sin_cos();
        let (sy, cy) = (yaw / 2.0).sin_cos();
        Quaternion {
            x: sr * cp * cy - cr * sp * sy,
            y: cr * sp * cy + sr * cp * sy,
            z: cr * cp * sy - sr * sp * cy,
            w: cr * cp * cy + sr * sp * sy,
        }
    }
}

impl RosMessage for Quaternion {
    const TYPE: &'static str = "geometry_msgs/msg/Quaternion";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        w.f64(self.x);
        w.f64(self.y);
        w.f64(self.z);
        w.f64(self.w);
        Ok(())
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        Ok(Quaternion { x: r.f64()?, y: r.f64()?, z: r.f64()?, w: r.f64()? })
    }
}

/// `geometry_msgs/msg/Twist`
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Twist {
    /// m/s
    pub linear: Vector3,
    /// rad/s
    pub angular: Vector3,
}

impl RosMessage for Twist {
    const TYPE: &'static str = "geometry_msgs/msg/Twist";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        self.linear.write(w)?;
        self.angular.write(w)
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        Ok(Twist { linear: Vector3::read(r)?, angular: Vector3::read(r)? })
    }
}

/// `nav_msgs/msg/Odometry` (pose `geometry_msgs/PoseWithCovariance`, twist
/// `geometry_msgs/TwistWithCovariance`)
#[derive(Debug, Clone, PartialEq)]
pub struct Odometry {
    /// stamp and the pose's frame
    pub header: Header,
    /// the twist's frame
    pub child_frame_id: String,
    /// `pose.pose.position`
    pub position: Vector3,
    /// `pose.pose.orientation`
    pub orientation: Quaternion,
    /// `pose.covariance`, row-major 6x6
    pub pose_covariance: [f64; 36],
    /// `twist.twist`
    pub twist: Twist,
    /// `twist.covariance`, row-major 6x6
    pub twist_covariance: [f64; 36],
}

impl RosMessage for Odometry {
    const TYPE: &'static str = "nav_msgs/msg/Odometry";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        self.header.write(w)?;
        w.string(&self.child_frame_id)?;
        self.position.write(w)?;
        self.orientation.write(w)?;
        w.f64_array(&self.pose_covariance);
        self.twist.write(w)?;
        w.f64_array(&self.twist_covariance);
        Ok(())
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        Ok(Odometry {
            header: Header::read(r)?,
            child_frame_id: r.string()?.to_owned(),
            position: Vector3::read(r)?,
            orientation: Quaternion::read(r)?,
            pose_covariance: r.f64_array()?,
            twist: Twist::read(r)?,
            twist_covariance: r.f64_array()?,
        })
    }
}

/// `geometry_msgs/msg/TransformStamped`
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// stamp and the parent frame
    pub header: Header,
    /// the child frame
    pub child_frame_id: String,
    /// `transform.translation`
    pub translation: Vector3,
    /// `transform.rotation`
    pub rotation: Quaternion,
}

impl RosMessage for TransformStamped {
    const TYPE: &'static str = "geometry_msgs/msg/TransformStamped";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        self.header.write(w)?;
        w.string(&self.child_frame_id)?;
        self.translation.write(w)?;
        self.rotation.write(w)
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        Ok(TransformStamped {
            header: Header::read(r)?,
            child_frame_id: r.string()?.to_owned(),
            translation: Vector3::read(r)?,
            rotation: Quaternion::read(r)?,
        })
    }
}

/// `tf2_msgs/msg/TFMessage`
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TfMessage {
    /// the transforms
    pub transforms: Vec<TransformStamped>,
}

impl RosMessage for TfMessage {
    const TYPE: &'static str = "tf2_msgs/msg/TFMessage";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        w.count("geometry_msgs/TransformStamped[]", self.transforms.len())?;
        for t in &self.transforms {
            t.write(w)?;
        }
        Ok(())
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        let n = r.u32()? as usize;
        // each transform takes at least 60 bytes: no allocation for a count
        // the message cannot hold
        let mut transforms = Vec::with_capacity(n.min(64));
        for _ in 0..n {
            transforms.push(TransformStamped::read(r)?);
        }
        Ok(TfMessage { transforms })
    }
}

/// `sensor_msgs/msg/LaserScan`
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LaserScan {
    /// stamp (of the first ray) and the scanner's frame
    pub header: Header,
    /// first ray's angle, rad
    pub angle_min: f32,
    /// last ray's angle, rad
    pub angle_max: f32,
    /// between rays, rad
    pub angle_increment: f32,
    /// between rays, s
    pub time_increment: f32,
    /// between scans, s
    pub scan_time: f32,
    /// m
    pub range_min: f32,
    /// m
    pub range_max: f32,
    /// m (outside [range_min, range_max]: no echo)
    pub ranges: Vec<f32>,
    /// device-specific (may be empty)
    pub intensities: Vec<f32>,
}

impl RosMessage for LaserScan {
    const TYPE: &'static str = "sensor_msgs/msg/LaserScan";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        self.header.write(w)?;
        for v in [
            self.angle_min,
            self.angle_max,
            self.angle_increment,
            self.time_increment,
            self.scan_time,
            self.range_min,
            self.range_max,
        ] {
            w.f32(v);
        }
        w.f32_seq(&self.ranges)?;
        w.f32_seq(&self.intensities)
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        Ok(LaserScan {
            header: Header::read(r)?,
            angle_min: r.f32()?,
            angle_max: r.f32()?,
            angle_increment: r.f32()?,
            time_increment: r.f32()?,
            scan_time: r.f32()?,
            range_min: r.f32()?,
            range_max: r.f32()?,
            ranges: r.f32_seq()?,
            intensities: r.f32_seq()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::idl::{Arity, Base, parse_msg};

    fn le(v: f64) -> [u8; 8] {
        v.to_le_bytes()
    }

    /// A Twist is the header and six float64, 52 bytes (what rosbags'
    /// `serialize_cdr` gives for it, NOTES-deps.md).
    #[test]
    fn twist_is_header_and_six_doubles() {
        let t = Twist { linear: Vector3 { x: 0.25, y: 0.0, z: 0.0 }, angular: Vector3 { x: 0.0, y: 0.0, z: -0.5 } };
        let b = t.to_cdr().expect("twist");
        assert_eq!(b.len(), 52);
        let mut want = vec![0, 1, 0, 0];
        for v in [0.25, 0.0, 0.0, 0.0, 0.0, -0.5] {
            want.extend_from_slice(&le(v));
        }
        assert_eq!(b, want);
        assert_eq!(Twist::from_cdr(&b), Ok(t));
    }

    /// Worked out by hand: stamp (8) + frame "odom" (4 + 5) ends at byte 17
    /// after the header; 3 bytes of padding align the next length to 20;
    /// "base_link" (4 + 10) ends at 34; 6 bytes of padding align the first
    /// double to 40.
    #[test]
    fn odometry_layout_pads_after_the_strings() {
        let mut o = Odometry {
            header: Header { stamp: Time { sec: 3, nanosec: 5 }, frame_id: "odom".into() },
            child_frame_id: "base_link".into(),
            position: Vector3 { x: 1.0, y: 2.0, z: 0.0 },
            orientation: Quaternion::from_yaw(0.0),
            pose_covariance: [0.0; 36],
            twist: Twist::default(),
            twist_covariance: [0.0; 36],
        };
        o.pose_covariance[0] = 0.01;
        let b = o.to_cdr().expect("odom");
        let mut want = vec![0, 1, 0, 0, 3, 0, 0, 0, 5, 0, 0, 0, 5, 0, 0, 0];
        want.extend_from_slice(b"odom\0");
        want.extend_from_slice(&[0, 0, 0, 10, 0, 0, 0]);
        want.extend_from_slice(b"base_link\0");
        want.extend_from_slice(&[0; 6]);
        assert_eq!(want.len(), 4 + 40);
        assert_eq!(&b[..want.len()], &want[..]);
        assert_eq!(&b[44..52], &le(1.0));
        // position 3, orientation 4, covariance 36, twist 6, covariance 36
        // (724 bytes, as rosbags 0.11.9 serialises the same message)
        assert_eq!(b.len(), 44 + (3 + 4 + 36 + 6 + 36) * 8);
        assert_eq!(&b[44 + 7 * 8..44 + 8 * 8], &le(0.01));
        assert_eq!(Odometry::from_cdr(&b), Ok(o));
    }

    #[test]
    fn tf_and_scan_round_trip() {
        let t = TfMessage {
            transforms: vec![TransformStamped {
                header: Header { stamp: Time { sec: 1, nanosec: 2 }, frame_id: "odom".into() },
                child_frame_id: "base_link".into(),
                translation: Vector3 { x: 1.0, y: -1.0, z: 0.0 },
                rotation: Quaternion::from_yaw(1.0),
            }],
        };
        assert_eq!(TfMessage::from_cdr(&t.to_cdr().expect("tf")), Ok(t));
        let s = LaserScan { ranges: vec![1.0, 2.5], range_max: 4.0, ..Default::default() };
        let b = s.to_cdr().expect("scan");
        // header 4 + stamp 8 + "" (4 + 1) + pad 3 + 7 float32 + count + 2 + count
        assert_eq!(b.len(), 4 + 8 + 5 + 3 + 28 + 4 + 8 + 4);
        assert_eq!(LaserScan::from_cdr(&b), Ok(s));
        // a huge transform count in a short message: an error, no allocation
        let mut w = Writer::new();
        w.u32(u32::MAX);
        assert!(TfMessage::from_cdr(&w.finish()).is_err());
    }

    #[test]
    fn time_from_ns_splits_and_saturates() {
        assert_eq!(Time::from_ns(1_500_000_000), Time { sec: 1, nanosec: 500_000_000 });
        assert_eq!(Time::from_ns(-1), Time { sec: -1, nanosec: 999_999_999 });
        assert_eq!(Time::from_ns(i128::MAX), Time { sec: i32::MAX, nanosec: 999_999_999 });
    }

    /// The writers follow the vendored definitions: each top-level field's
    /// name and kind in order (checked on the .msg text the hashes come
    /// from, so a writer and its hash cannot drift apart unnoticed).
    #[test]
    fn writers_follow_the_vendored_definitions() {
        let names = |pkg: &str, name: &str, text: &str| -> Vec<(String, Base, Arity)> {
            parse_msg(pkg, name, text).expect("parses").fields.into_iter().map(|f| (f.name, f.base, f.arity)).collect()
        };
        let odom = names("nav_msgs", "Odometry", include_str!("../msg/nav_msgs/Odometry.msg"));
        assert_eq!(
            odom.iter().map(|f| f.0.as_str()).collect::<Vec<_>>(),
            ["header", "child_frame_id", "pose", "twist"]
        );
        let pwc =
            names("geometry_msgs", "PoseWithCovariance", include_str!("../msg/geometry_msgs/PoseWithCovariance.msg"));
        assert_eq!(pwc[1], ("covariance".into(), Base::Float64, Arity::Array(36)));
        let scan = names("sensor_msgs", "LaserScan", include_str!("../msg/sensor_msgs/LaserScan.msg"));
        assert_eq!(scan.len(), 10);
        assert_eq!(scan[8], ("ranges".into(), Base::Float32, Arity::Unbounded));
        let tf = names("tf2_msgs", "TFMessage", include_str!("../msg/tf2_msgs/TFMessage.msg"));
        assert_eq!(
            tf,
            [("transforms".into(), Base::Nested("geometry_msgs/msg/TransformStamped".into()), Arity::Unbounded)]
        );
    }
}

/// `sensor_msgs/msg/Range`: one reading of a ranger with a field of view
/// (a sonar transducer, an IR ranger).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Range {
    /// stamp and the ranger's frame (its axis is x)
    pub header: Header,
    /// [`Range::ULTRASOUND`] or [`Range::INFRARED`]
    pub radiation_type: u8,
    /// the arc the reading covers, rad
    pub field_of_view: f32,
    /// m
    pub min_range: f32,
    /// m
    pub max_range: f32,
    /// m; +inf: nothing within max_range (REP-117)
    pub range: f32,
    /// m², 0 when unknown
    pub variance: f32,
}

impl Range {
    /// `radiation_type` of a sonar
    pub const ULTRASOUND: u8 = 0;
    /// `radiation_type` of an IR ranger
    pub const INFRARED: u8 = 1;
}

impl RosMessage for Range {
    const TYPE: &'static str = "sensor_msgs/msg/Range";
    fn write(&self, w: &mut Writer) -> Result<(), CdrError> {
        self.header.write(w)?;
        w.u8(self.radiation_type);
        for v in [self.field_of_view, self.min_range, self.max_range, self.range, self.variance] {
            w.f32(v);
        }
        Ok(())
    }
    fn read(r: &mut Reader<'_>) -> Result<Self, CdrError> {
        Ok(Range {
            header: Header::read(r)?,
            radiation_type: r.u8()?,
            field_of_view: r.f32()?,
            min_range: r.f32()?,
            max_range: r.f32()?,
            range: r.f32()?,
            variance: r.f32()?,
        })
    }
}
