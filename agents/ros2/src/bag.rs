//! Bags ROS 2 reads (`nerve export --ros2`): a recorded nerve sample, as
//! its schema decodes it (JSON), to the CDR of the standard message the
//! `ros2` agent maps its type to ([`crate::convert`], the same
//! conversions), with what rosbag2 writes around it in an MCAP file: the
//! `ros2msg` definition of each type ([`msg_definition`]), the offered QoS
//! of each topic ([`offered_qos`]) and the bag's metadata
//! ([`metadata_yaml`]).
//!
//! | nerve | ROS 2 |
//! |---|---|
//! | `nerve::Odometry` | `nav_msgs/msg/Odometry` (frame `odom`, child `base_link`) |
//! | `nerve::GroundTruth` | `nav_msgs/msg/Odometry` (frame `world`, child `base_link`) |
//! | `nerve::VelocityCommand` | `geometry_msgs/msg/Twist` |
//! | `nerve::SonarScan` | `sensor_msgs/msg/LaserScan` (frame `base_link`) |
//!
//! Header stamps are the samples' recording times (ns since the epoch).

use crate::msgs::{RosMessage as _, Time};
use shm_schemas::payloads::motion::{GroundTruth, Odometry, VelocityCommand};
use shm_schemas::payloads::sonar::{SONAR_DIRECTIONS, SonarScan};

/// MCAP profile of rosbag2 files.
pub const PROFILE: &str = "ros2";
/// MCAP schema encoding of `.msg` definitions.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// MCAP message encoding of ROS 2 messages.
pub const MESSAGE_ENCODING: &str = "cdr";

/// A nerve type a bag can carry, and as what.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BagMap {
    /// `nerve::Odometry` → `nav_msgs/msg/Odometry`
    Odometry,
    /// `nerve::GroundTruth` → `nav_msgs/msg/Odometry`
    Truth,
    /// `nerve::VelocityCommand` → `geometry_msgs/msg/Twist`
    Velocity,
    /// `nerve::SonarScan` → `sensor_msgs/msg/LaserScan`
    Sonar,
}

/// The conversions: (nerve type, ROS type, conversion).
pub const BAG_MAPS: &[(&str, &str, BagMap)] = &[
    ("nerve::Odometry", "nav_msgs/msg/Odometry", BagMap::Odometry),
    ("nerve::GroundTruth", "nav_msgs/msg/Odometry", BagMap::Truth),
    ("nerve::VelocityCommand", "geometry_msgs/msg/Twist", BagMap::Velocity),
    ("nerve::SonarScan", "sensor_msgs/msg/LaserScan", BagMap::Sonar),
];

/// The ROS type and conversion of a nerve type, `None` when a bag cannot
/// carry it.
pub fn mapping_of(nerve_type: &str) -> Option<(&'static str, BagMap)> {
    BAG_MAPS.iter().find(|(n, _, _)| *n == nerve_type).map(|(_, r, m)| (*r, *m))
}

/// The `ros2msg` definition of a vendored type (`pkg/msg/Name`): its text,
/// then the messages it uses, as rosbag2 writes it in a bag's schema.
pub fn msg_definition(ros_type: &str) -> Option<&'static str> {
    crate::MSG_DEFINITIONS.binary_search_by(|(n, _)| (*n).cmp(ros_type)).ok().map(|i| crate::MSG_DEFINITIONS[i].1)
}

/// Why a recorded sample could not be written as its ROS message.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    /// A field the conversion needs is missing or not a number.
    #[error("a recorded {nerve_type} has no number {field} (a recording of another nerve version?)")]
    Field {
        /// the nerve type
        nerve_type: &'static str,
        /// the field
        field: &'static str,
    },
    /// The message could not be written as CDR.
    #[error("cannot write the message as CDR: {0}")]
    Cdr(#[from] crate::cdr::CdrError),
}

fn num(v: &serde_json::Value, nerve_type: &'static str, field: &'static str) -> Result<f64, BagError> {
    v[field].as_f64().ok_or(BagError::Field { nerve_type, field })
}

fn array<const N: usize>(
    v: &serde_json::Value,
    nerve_type: &'static str,
    field: &'static str,
) -> Result<[f64; N], BagError> {
    let err = || BagError::Field { nerve_type, field };
    let items = v[field].as_array().ok_or_else(err)?;
    if items.len() != N {
        return Err(err());
    }
    let mut out = [0.0; N];
    for (o, i) in out.iter_mut().zip(items) {
        *o = i.as_f64().ok_or_else(err)?;
    }
    Ok(out)
}

/// The CDR of the ROS message for a recorded sample (`value`: the sample
/// decoded by its nerve schema), stamped `unix_ns`.
pub fn encode(map: BagMap, value: &serde_json::Value, unix_ns: u64) -> Result<Vec<u8>, BagError> {
    let stamp = Time::from_ns(i128::from(unix_ns));
    Ok(match map {
        BagMap::Odometry => {
            const T: &str = "nerve::Odometry";
            let o = Odometry {
                x: num(value, T, "x")?,
                y: num(value, T, "y")?,
                theta: num(value, T, "theta")?,
                v: num(value, T, "v")?,
                omega: num(value, T, "omega")?,
                ..Odometry::default()
            };
            crate::convert::odometry_to_ros(&o, stamp, "odom", "base_link").to_cdr()?
        }
        BagMap::Truth => {
            const T: &str = "nerve::GroundTruth";
            let t = GroundTruth {
                x: num(value, T, "x")?,
                y: num(value, T, "y")?,
                theta: num(value, T, "theta")?,
                v: num(value, T, "v")?,
                omega: num(value, T, "omega")?,
                ..GroundTruth::default()
            };
            crate::convert::truth_to_ros(&t, stamp, "world", "base_link").to_cdr()?
        }
        BagMap::Velocity => {
            const T: &str = "nerve::VelocityCommand";
            let c = VelocityCommand { v: num(value, T, "v")?, omega: num(value, T, "omega")?, stamp_ns: 0 };
            crate::convert::velocity_to_twist(&c).to_cdr()?
        }
        BagMap::Sonar => {
            const T: &str = "nerve::SonarScan";
            let ranges: [f64; SONAR_DIRECTIONS] = array(value, T, "ranges_m")?;
            let valid: [f64; SONAR_DIRECTIONS] = array(value, T, "valid")?;
            let mut s = SonarScan::default();
            for i in 0..SONAR_DIRECTIONS {
                s.ranges_m[i] = ranges[i] as f32;
                s.valid[i] = u8::from(valid[i] != 0.0);
            }
            crate::convert::sonar_to_scan(&s, stamp, "base_link").to_cdr()?
        }
    })
}

/// The `offered_qos_profiles` rosbag2 (Jazzy, metadata version 9) writes
/// for a topic: one publisher, reliable, keep last `depth`, volatile or
/// transient local, no deadline, lifespan or lease.
pub fn offered_qos(depth: u32, transient_local: bool) -> String {
    let durability = if transient_local { "transient_local" } else { "volatile" };
    let infinite = "\n    sec: 9223372036\n    nsec: 854775807";
    format!(
        "- history: keep_last\n  depth: {depth}\n  reliability: reliable\n  durability: {durability}\n  deadline:{infinite}\n  lifespan:{infinite}\n  liveliness: automatic\n  liveliness_lease_duration:{infinite}\n  avoid_ros_namespace_conventions: false"
    )
}

/// One topic of a bag, for its metadata.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicCount {
    /// the ROS topic
    pub topic: String,
    /// `pkg/msg/Name`
    pub ros_type: String,
    /// its `offered_qos_profiles`
    pub qos: String,
    /// how many messages
    pub count: u64,
}

fn indent(text: &str, by: &str) -> String {
    text.lines().map(|l| format!("{by}{l}")).collect::<Vec<_>>().join("\n")
}

/// The bag's `metadata.yaml` (`rosbag2_bagfile_information`, version 9)
/// as rosbag2 also keeps it in the MCAP file's `rosbag2` metadata record
/// (`serialized_metadata`): the file, its time span and each topic's
/// count, QoS and type hash.
pub fn metadata_yaml(file_name: &str, start_ns: u64, end_ns: u64, topics: &[TopicCount]) -> String {
    let total: u64 = topics.iter().map(|t| t.count).sum();
    let duration = end_ns.saturating_sub(start_ns);
    let mut y = format!(
        "version: 9\nstorage_identifier: mcap\nduration:\n  nanoseconds: {duration}\nstarting_time:\n  nanoseconds_since_epoch: {start_ns}\nmessage_count: {total}\ntopics_with_message_count:\n"
    );
    if topics.is_empty() {
        y = y.replace("topics_with_message_count:\n", "topics_with_message_count: []\n");
    }
    for t in topics {
        let hash = crate::type_hash(&t.ros_type).unwrap_or_default();
        y.push_str(&format!(
            "  - topic_metadata:\n      name: {:?}\n      type: {}\n      serialization_format: cdr\n      offered_qos_profiles:\n{}\n      type_description_hash: {hash}\n    message_count: {}\n",
            t.topic,
            t.ros_type,
            indent(&t.qos, "        "),
            t.count
        ));
    }
    y.push_str(&format!(
        "compression_format: \"\"\ncompression_mode: \"\"\nrelative_file_paths:\n  - {file_name:?}\nfiles:\n  - path: {file_name:?}\n    starting_time:\n      nanoseconds_since_epoch: {start_ns}\n    duration:\n      nanoseconds: {duration}\n    message_count: {total}\ncustom_data: ~\nros_distro: jazzy"
    ));
    y
}

/// A nerve port `agent/port` as a ROS topic: `/agent/port`, each character
/// a ROS name cannot have (`-` in `wall-follow`) as `_`.
pub fn ros_topic(nerve_topic: &str) -> String {
    let t: String = nerve_topic.chars().map(|c| if c.is_ascii_alphanumeric() || c == '/' { c } else { '_' }).collect();
    format!("/{}", t.trim_start_matches('/'))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definitions are the vendored texts with their dependencies in
    /// the order and form rosbags' `generate_msgdef` gives (checked by
    /// hand against rosbags 0.11.9 for `TwistWithCovariance`).
    #[test]
    fn definitions_carry_their_dependencies_once() {
        let d = msg_definition("geometry_msgs/msg/TwistWithCovariance").expect("vendored");
        let sep = "=".repeat(80);
        let sections: Vec<&str> = d.split(&format!("{sep}\n")).collect();
        assert_eq!(sections.len(), 3, "{d}");
        assert!(sections[1].starts_with("MSG: geometry_msgs/Twist\n"), "{d}");
        assert!(sections[2].starts_with("MSG: geometry_msgs/Vector3\n"), "{d}");
        let odom = msg_definition("nav_msgs/msg/Odometry").expect("vendored");
        assert_eq!(odom.matches("MSG: geometry_msgs/Vector3\n").count(), 1, "{odom}");
        assert!(odom.contains("MSG: builtin_interfaces/Time\n"), "{odom}");
        assert!(msg_definition("my_msgs/msg/Nothing").is_none());
    }

    #[test]
    fn samples_become_their_ros_messages() {
        let odom = serde_json::json!({"x": 1.0, "y": 2.0, "theta": 0.5, "v": 0.1, "omega": 0.2, "stamp_ns": 7});
        let cdr = encode(BagMap::Odometry, &odom, 1_500_000_000).expect("encodes");
        let m = crate::msgs::Odometry::from_cdr(&cdr).expect("decodes");
        assert_eq!((m.position.x, m.position.y, m.twist.angular.z), (1.0, 2.0, 0.2));
        assert_eq!((m.header.stamp, m.header.frame_id.as_str()), (Time { sec: 1, nanosec: 500_000_000 }, "odom"));
        let e = encode(BagMap::Velocity, &serde_json::json!({"v": 1.0}), 0).expect_err("no omega");
        assert!(e.to_string().contains("no number omega"), "{e}");
        let mut ranges = vec![2.0; 12];
        ranges[1] = 0.5;
        let mut valid = vec![1; 12];
        valid[3] = 0;
        let scan = serde_json::json!({"ranges_m": ranges, "valid": valid});
        let cdr = encode(BagMap::Sonar, &scan, 0).expect("encodes");
        let m = crate::msgs::LaserScan::from_cdr(&cdr).expect("decodes");
        assert_eq!((m.ranges[1], m.ranges.len()), (0.5, 12));
        assert!(m.ranges[3].is_infinite());
    }

    #[test]
    fn topics_and_metadata() {
        assert_eq!(ros_topic("wall-follow/cmd"), "/wall_follow/cmd");
        let y = metadata_yaml(
            "run-ros2.mcap",
            10,
            25,
            &[TopicCount {
                topic: "/motor/odom".into(),
                ros_type: "nav_msgs/msg/Odometry".into(),
                qos: offered_qos(10, false),
                count: 3,
            }],
        );
        assert!(y.contains("duration:\n  nanoseconds: 15\n"), "{y}");
        assert!(y.contains("message_count: 3\n"), "{y}");
        assert!(y.contains("type_description_hash: RIHS01_3cc97dc7"), "{y}");
        assert!(y.contains("        - history: keep_last\n          depth: 10\n"), "{y}");
    }
}
