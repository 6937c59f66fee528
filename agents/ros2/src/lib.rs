//! `ros2`: makes chosen ports of a nerve robot ROS 2 topics, and chosen ROS 2
//! topics nerve ports, on rmw_zenoh's wire (ROS 2's Zenoh middleware, Tier 1
//! since Jazzy), so that ROS 2 tools see and drive the robot with no ROS
//! installation on it.
//!
//! * [`cdr`]: CDR little-endian with the encapsulation header;
//! * [`idl`]: the `.msg` parser and RIHS01 type hashes (REP-2016), computed
//!   at build time from the vendored definitions in `msg/` ([`type_hash`]);
//! * [`msgs`]: the standard messages as Rust values;
//! * [`wire`]: rmw_zenoh's keys, liveliness tokens, QoS text and attachment;
//! * [`convert`]: nerve's payloads to and from the standard messages;
//! * [`config`]: the agent's TOML configuration;
//! * [`usermap`]: any payload (a user's own type) as a vendored ROS
//!   message, field by field as the configuration says, and [`usersub`]:
//!   a vendored ROS message received as any payload, the other way;
//! * [`link`]: the Zenoh session, in a thread of its own (not real-time),
//!   and [`route`]: which topics the task puts itself (small messages) and
//!   which it hands to the link thread (Images); they and the agent are the
//!   `agent` feature (default): without it the crate has no Zenoh, as the
//!   `nerve` command uses it;
//! * [`bag`]: recorded samples as the CDR messages, definitions and
//!   metadata of a rosbag2 MCAP file (`nerve export --ros2`), and
//!   [`bag_image`]: recorded camera frames as `sensor_msgs/Image`.
//!
//! The task is event-driven: each step it converts what arrived on the
//! inputs, puts the small messages itself and hands Images to the link
//! thread, and delivers on the outputs what the link's subscribers
//! received (they wake it through the SDK's waker).

#[cfg(feature = "agent")]
mod agent;
pub mod bag;
pub mod bag_image;
pub mod cdr;
pub mod config;
pub mod convert;
pub mod idl;
#[cfg(feature = "agent")]
pub use agent::Ros2;
#[cfg(feature = "agent")]
pub mod link;
pub mod msgs;
#[cfg(feature = "agent")]
pub mod route;
pub mod usermap;
pub mod usersub;
pub mod wire;

include!(concat!(env!("OUT_DIR"), "/type_hashes.rs"));

/// The RIHS01 hash of a vendored message type (`pkg/msg/Name`).
pub fn type_hash(ros_type: &str) -> Option<&'static str> {
    TYPE_HASHES.binary_search_by(|(n, _)| (*n).cmp(ros_type)).ok().map(|i| TYPE_HASHES[i].1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// RIHS01 hashes computed at build time from the vendored `.msg` files,
    /// against the hashes real ROS 2 Jazzy uses:
    ///
    /// * `std_msgs/msg/String`: the example keys of rmw_zenoh's
    ///   docs/design.md ("Topic and Service name mapping to Zenoh key
    ///   expressions": `0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...`);
    /// * `geometry_msgs/msg/Twist`: `RIHS01_9c45bf16...`, the `/cmd_vel`
    ///   key in public rmw_zenoh clients (e.g. an embedded zenoh-pico
    ///   teleop's `0/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45...`
    ///   and a Rust nucleo board's `KEY_CMD_VEL`, found with code search),
    ///   and PyPI rosbags 0.11.9's `get_typestore(Stores.ROS2_JAZZY).hash_rihs01`;
    /// * the others: rosbags 0.11.9's Jazzy type store (`hash_rihs01`),
    ///   an independent implementation of REP-2016 on its own copies of the
    ///   definitions.
    #[test]
    fn type_hashes_match_ros2_jazzy() {
        let want = [
            ("std_msgs/msg/String", "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"),
            ("geometry_msgs/msg/Twist", "9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"),
            ("builtin_interfaces/msg/Time", "b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"),
            ("builtin_interfaces/msg/Duration", "e8d009f659816f758b75334ee1a9ca5b5c0b859843261f14c7f937349599d93b"),
            ("std_msgs/msg/Header", "f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"),
            ("std_msgs/msg/Bool", "feb91e995ff9ebd09c0cb3d2aed18b11077585839fb5db80193b62d74528f6c9"),
            ("std_msgs/msg/Float32", "7170d3d8f841f7be3172ce5f4f59f3a4d7f63b0447e8b33327601ad64d83d6e2"),
            ("std_msgs/msg/Float64", "705ba9c3d1a09df43737eb67095534de36fd426c0587779bda2bc51fe790182a"),
            ("std_msgs/msg/Int32", "b6578ded3c58c626cfe8d1a6fb6e04f706f97e9f03d2727c9ff4e74b1cef0deb"),
            ("std_msgs/msg/Int64", "8cd1048c2f186b6bd9a92472dc1ce51723c0833a221e2b7aecfff111774f4b49"),
            ("std_msgs/msg/UInt32", "a5c874829b752bc5fa190024b0ad76f578cc278271e855c7d02a818b3516fb4a"),
            ("std_msgs/msg/UInt64", "fbdc52018fc13755dce18024d1a671c856aa8b4aaf63adfb095b608f98e8c943"),
            ("geometry_msgs/msg/Vector3", "cc12fe83e4c02719f1ce8070bfd14aecd40f75a96696a67a2a1f37f7dbb0765d"),
            ("geometry_msgs/msg/Point", "6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881"),
            ("geometry_msgs/msg/Quaternion", "8a765f66778c8ff7c8ab94afcc590a2ed5325a1d9a076ffff38fbce36f458684"),
            ("geometry_msgs/msg/Pose", "d501954e9476cea2996984e812054b68026ae0bfae789d9a10b23daf35cc90fa"),
            ("geometry_msgs/msg/Transform", "beb83fbe698636351461f6f35d1abb20010c43d55374d81bd041f1ba2581fddc"),
            ("geometry_msgs/msg/TransformStamped", "0a241f87d04668d94099cbb5ba11691d5ad32c2f29682e4eb5653424bd275206"),
            (
                "geometry_msgs/msg/PoseWithCovariance",
                "9a7c0fd234b7f45c6098745ecccd773ca1085670e64107135397aee31c02e1bb",
            ),
            (
                "geometry_msgs/msg/TwistWithCovariance",
                "49f574f033f095d8b6cd1beaca5ca7925e296e84af1716d16c89d38b059c8c18",
            ),
            ("nav_msgs/msg/Odometry", "3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"),
            ("tf2_msgs/msg/TFMessage", "e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"),
            ("sensor_msgs/msg/Range", "b42b62562e93cbfe9d42b82fe5994dfa3d63d7d5c90a317981703f7388adff3a"),
            ("sensor_msgs/msg/LaserScan", "64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"),
            ("sensor_msgs/msg/Image", "d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"),
        ];
        for (t, h) in want {
            assert_eq!(type_hash(t), Some(format!("RIHS01_{h}").as_str()), "{t}");
        }
        assert_eq!(TYPE_HASHES.len(), want.len(), "every vendored type is checked");
        assert_eq!(type_hash("geometry_msgs/msg/Accel"), None);
    }

    /// The canonical JSON of a small type, written out from REP-2016's rules
    /// by hand (field type ids of type_description_interfaces/FieldType:
    /// int32 6, uint32 7), and SHA-256's own test vector.
    #[test]
    fn type_description_json_and_sha256() {
        let mut defs = std::collections::BTreeMap::new();
        let time = idl::parse_msg("builtin_interfaces", "Time", "int32 sec\nuint32 nanosec # ns\n").expect("parses");
        defs.insert(time.type_name.clone(), time);
        assert_eq!(
            idl::type_description_json("builtin_interfaces/msg/Time", &defs).expect("json"),
            "{\"type_description\": {\"type_name\": \"builtin_interfaces/msg/Time\", \"fields\": [\
             {\"name\": \"sec\", \"type\": {\"type_id\": 6, \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"\"}}, \
             {\"name\": \"nanosec\", \"type\": {\"type_id\": 7, \"capacity\": 0, \"string_capacity\": 0, \"nested_type_name\": \"\"}}]}, \
             \"referenced_type_descriptions\": []}"
        );
        let abc = idl::sha256(b"abc");
        assert_eq!(abc[..4], [0xba, 0x78, 0x16, 0xbf]);
        assert_eq!(abc[28..], [0xf2, 0x00, 0x15, 0xad]);
        // two blocks (56 bytes of input: the length goes to a second block)
        let two = idl::sha256(b"abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq");
        assert_eq!(two[..4], [0x24, 0x8d, 0x6a, 0x61]);
    }

    #[test]
    fn msg_parser_reads_arrays_bounds_and_constants() {
        let d = idl::parse_msg(
            "p",
            "M",
            "uint8 A=1\nstring<=8 s\nint32[<=4] b\nfloat64[3] c \"ignored\"\nOther[] o\nq/N n\n",
        )
        .expect("parses");
        use idl::{Arity, Base};
        let got: Vec<(&str, &Base, Arity)> = d.fields.iter().map(|f| (f.name.as_str(), &f.base, f.arity)).collect();
        assert_eq!(
            got,
            [
                ("s", &Base::String(Some(8)), Arity::Single),
                ("b", &Base::Int32, Arity::Bounded(4)),
                ("c", &Base::Float64, Arity::Array(3)),
                ("o", &Base::Nested("p/msg/Other".into()), Arity::Unbounded),
                ("n", &Base::Nested("q/msg/N".into()), Arity::Single),
            ]
        );
        let e = idl::parse_msg("p", "M", "int32\n").expect_err("no name").to_string();
        assert!(e.contains("p/msg/M.msg line 1"), "{e}");
        let e = idl::parse_msg("p", "M", "int32[x] a\n").expect_err("bad size").to_string();
        assert!(e.contains("bad array size"), "{e}");
    }
}
