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
//! * [`link`]: the Zenoh session, in a thread of its own (not real-time);
//! * [`bag`]: recorded samples as the CDR messages, definitions and
//!   metadata of a rosbag2 MCAP file (`nerve export --ros2`).
//!
//! The task is periodic: each step it converts what arrived on the inputs
//! and hands the CDR bytes to the link thread, and delivers on the outputs
//! what the link's subscribers received.

pub mod bag;
pub mod cdr;
pub mod config;
pub mod convert;
pub mod idl;
pub mod link;
pub mod msgs;
pub mod wire;

include!(concat!(env!("OUT_DIR"), "/type_hashes.rs"));

/// The RIHS01 hash of a vendored message type (`pkg/msg/Name`).
pub fn type_hash(ros_type: &str) -> Option<&'static str> {
    TYPE_HASHES.binary_search_by(|(n, _)| (*n).cmp(ros_type)).ok().map(|i| TYPE_HASHES[i].1)
}

use agent_sdk::{Agent, AgentError, Context, Input, Output, Setup, Task};
use config::{Config, PubMap, SubMap};
use link::{Inbox, Outgoing, Stats};
use msgs::RosMessage;
use shm_schemas::payloads::motion::{GroundTruth, Odometry, VelocityCommand};
use shm_schemas::payloads::sonar::SonarScan;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::thread::JoinHandle;
use std::time::Duration;

/// How many samples per input one step converts at most.
const BATCH: usize = 64;
/// How many messages may wait for the link thread.
const OUTGOING: usize = 256;

/// The agent's own arguments (after `--`).
#[derive(Debug, clap::Parser)]
#[command(name = "nerve-ros2")]
struct Ros2Args {
    /// The agent's configuration (TOML; see docs/ros2.md).
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

enum PubInput {
    Odometry(Input<Odometry>),
    Truth(Input<GroundTruth>),
    Velocity(Input<VelocityCommand>),
    Sonar(Input<SonarScan>),
    Frames(agent_sdk::memory::RingInput),
}

struct SubOutput {
    out: Output<VelocityCommand>,
    inbox: Arc<Inbox>,
}

/// The `ros2` agent.
pub struct Ros2 {
    cfg: Config,
    inputs: Vec<PubInput>,
    outputs: Vec<SubOutput>,
    stats: Arc<Stats>,
    tx: Option<SyncSender<Outgoing>>,
    stop: Arc<AtomicBool>,
    link_thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Ros2 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2").field("node", &self.cfg.node).field("publish", &self.cfg.publish.len()).finish()
    }
}

impl Agent for Ros2 {
    const KIND: &'static str = "ros2";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(20))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let path = setup.args::<Ros2Args>()?.config.ok_or_else(|| {
            AgentError::Config(
                "the ros2 agent needs its configuration: nerve start ros2 --name NAME -- --config FILE (see docs/ros2.md)"
                    .into(),
            )
        })?;
        let cfg = config::load(&path, setup.name()).map_err(|e| AgentError::Config(e.to_string()))?;
        let mut inputs = Vec::new();
        for p in &cfg.publish {
            inputs.push(match p.map {
                PubMap::OdometryToOdometry | PubMap::OdometryToTf => PubInput::Odometry(setup.input(&p.input)?),
                PubMap::TruthToOdometry => PubInput::Truth(setup.input(&p.input)?),
                PubMap::VelocityToTwist => PubInput::Velocity(setup.input(&p.input)?),
                PubMap::SonarToLaserScan | PubMap::SonarToRange => PubInput::Sonar(setup.input(&p.input)?),
                PubMap::FramesToImage => PubInput::Frames(agent_sdk::memory::MemorySetup::ring_input(setup, &p.input)?),
            });
        }
        let mut outputs = Vec::new();
        for s in &cfg.subscribe {
            match s.map {
                SubMap::TwistToVelocity => {
                    outputs.push(SubOutput { out: setup.output(&s.output)?, inbox: Arc::new(Inbox::default()) })
                }
            }
        }
        let stats = Arc::new(Stats::new(cfg.publish.len()));
        {
            let stats = stats.clone();
            let inboxes: Vec<Arc<Inbox>> = outputs.iter().map(|o| o.inbox.clone()).collect();
            let topics: Vec<String> = cfg.publish.iter().map(|p| p.topic.clone()).collect();
            let subs: Vec<String> = cfg.subscribe.iter().map(|s| s.topic.clone()).collect();
            setup.figures(move || {
                let mut v = stats.figures(&topics);
                for (t, i) in subs.iter().zip(&inboxes) {
                    v.extend(i.figures(t));
                }
                v
            });
        }
        Ok(Ros2 { cfg, inputs, outputs, stats, tx: None, stop: Arc::new(AtomicBool::new(false)), link_thread: None })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        // a configuration zenoh refuses fails the start; a router that is
        // not up yet does not: the link thread keeps trying
        link::zenoh_config(&self.cfg).map_err(|e| AgentError::Config(e.to_string()))?;
        let (tx, rx) = std::sync::mpsc::sync_channel::<Outgoing>(OUTGOING);
        let cfg = self.cfg.clone();
        let inboxes: Vec<Arc<Inbox>> = self.outputs.iter().map(|o| o.inbox.clone()).collect();
        let (stats, stop) = (self.stats.clone(), self.stop.clone());
        let handle = std::thread::Builder::new()
            .name("ros2-link".into())
            .spawn(move || {
                agent_sdk::rt::drop_realtime();
                if let Some(mut link) = link::Link::open_retrying(&cfg, &inboxes, &rx, &stats, &stop) {
                    link.run(&rx, &stats, &stop);
                    link.close();
                }
            })
            .map_err(|e| AgentError::Other(format!("cannot start the ros2 link thread: {e}")))?;
        self.link_thread = Some(handle);
        self.tx = Some(tx);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let epoch = convert::epoch_now_ns();
        for (i, (input, spec)) in self.inputs.iter_mut().zip(&self.cfg.publish).enumerate() {
            let mut encoded: Vec<Vec<u8>> = Vec::new();
            let mut failed = None;
            let mut push = |r: Result<Vec<u8>, cdr::CdrError>| match r {
                Ok(b) => encoded.push(b),
                Err(e) => failed = Some(e),
            };
            let (frame, child) = (spec.frame_id.as_str(), spec.child_frame_id.as_str());
            match input {
                PubInput::Odometry(inp) => {
                    inp.drain_up_to(BATCH, |_, o| {
                        let stamp = convert::ros_stamp(o.stamp_ns, now, epoch);
                        push(if spec.map == PubMap::OdometryToTf {
                            convert::odometry_to_tf(o, stamp, frame, child).to_cdr()
                        } else {
                            convert::odometry_to_ros(o, stamp, frame, child).to_cdr()
                        })
                    });
                }
                PubInput::Truth(inp) => {
                    inp.drain_up_to(BATCH, |_, t| {
                        let stamp = convert::ros_stamp(t.stamp_ns, now, epoch);
                        push(convert::truth_to_ros(t, stamp, frame, child).to_cdr())
                    });
                }
                PubInput::Velocity(inp) => {
                    inp.drain_up_to(BATCH, |_, c| push(convert::velocity_to_twist(c).to_cdr()));
                }
                PubInput::Sonar(inp) => {
                    inp.drain_up_to(BATCH, |_, s| {
                        let stamp = convert::ros_stamp(s.stamp_ns, now, epoch);
                        if spec.map == PubMap::SonarToRange {
                            for r in convert::sonar_to_ranges(s, stamp, frame) {
                                push(r.to_cdr());
                            }
                        } else {
                            push(convert::sonar_to_scan(s, stamp, frame).to_cdr())
                        }
                    });
                }
                PubInput::Frames(ring) => {
                    // the newest frame only, read in place from the ring and
                    // written into the message (older notices are skipped)
                    let read = ring.latest_with(|meta, px| {
                        let enc = convert::image_encoding(meta.format());
                        let channels = if enc == Some("rgb8") { 3 } else { 1 };
                        let stamp = convert::ros_stamp(meta.stamp_ns, now, epoch);
                        enc.and_then(|e| convert::image_cdr(stamp, frame, meta.width, meta.height, e, channels, px))
                    });
                    match read {
                        Ok(None) => {}
                        Ok(Some(Some(r))) => push(r),
                        Ok(Some(None)) => self.stats.refused_frame(i),
                        // overwritten before it was read: the next one comes
                        Err(agent_sdk::memory::MemoryError::Read(e)) => tracing::debug!(error = %e, "frame skipped"),
                        Err(e) => return Err(e.into()),
                    }
                }
            }
            if let Some(e) = failed {
                tracing::warn!(topic = %spec.topic, error = %e, "a sample could not be written as CDR");
            }
            if let Some(tx) = &self.tx {
                for bytes in encoded {
                    match tx.try_send(Outgoing { topic: i, bytes }) {
                        Ok(()) => {}
                        Err(TrySendError::Full(_)) => self.stats.dropped(i),
                        Err(TrySendError::Disconnected(_)) => {
                            return Err(AgentError::Other("the ros2 link thread ended".into()));
                        }
                    }
                }
            }
        }
        for o in &self.outputs {
            for twist in o.inbox.take() {
                match convert::twist_to_velocity(&twist, now) {
                    Ok(cmd) => o.out.send(cmd)?,
                    Err(e) => o.inbox.refuse(&e.to_string()),
                }
            }
        }
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) {
        self.stop.store(true, Ordering::Release);
        self.tx = None;
        if let Some(h) = self.link_thread.take() {
            let _ = h.join();
        }
    }
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
