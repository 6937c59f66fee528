//! The `ros2` agent's configuration (TOML, `--config FILE`): the Zenoh
//! session, the ROS node it appears as, and the topics both ways.
//!
//! ```toml
//! node = "nerve"                      # the ROS node name (default: the agent's name)
//! namespace = ""                      # the ROS namespace ("" or "/robot1")
//! domain = 0                          # ROS_DOMAIN_ID
//! distro = "jazzy"                    # "humble": no type hashes in keys
//! mode = "client"                     # or "peer"
//! connect = ["tcp/127.0.0.1:7447"]    # rmw_zenohd's default
//! listen = []                         # peer mode: endpoints to listen on
//!
//! [[publish]]                         # a nerve input becomes a ROS topic
//! input = "odom"                      # the agent's input (wire it: motor/odom -> ros2/odom)
//! from = "nerve::Odometry"
//! topic = "/odom"
//! type = "nav_msgs/msg/Odometry"
//! frame_id = "odom"                   # header.frame_id (default "odom")
//! child_frame_id = "base_link"        # (default "base_link")
//! reliability = "reliable"            # or "best_effort"
//! depth = 10
//!
//! [[subscribe]]                       # a ROS topic becomes a nerve output
//! topic = "/cmd_vel"
//! type = "geometry_msgs/msg/Twist"
//! output = "cmd_vel"                  # the agent's output (wire it: ros2/cmd_vel -> motor/cmd)
//! to = "nerve::VelocityCommand"
//!
//! [[type]]                            # a payload of your own (its #[repr(C)] fields in order)
//! name = "lab::Gripper"
//! fields = [["width_m", "f32"], ["force_n", "f32"], ["closed", "u8"], ["_pad", "[u8; 3]"]]   # no implicit padding
//!
//! [[publish]]                         # any payload as a vendored ROS message, field by field
//! input = "gripper"
//! from = "lab::Gripper"
//! topic = "/gripper"
//! type = "geometry_msgs/msg/Vector3"
//! fields = { "x" = "width_m", "y" = "force_n", "z" = "closed" }   # "ROS field" = "nerve field"
//!
//! [[subscribe]]                       # any vendored ROS message as a payload, field by field
//! topic = "/gripper_cmd"
//! type = "geometry_msgs/msg/Vector3"
//! output = "gripper_cmd"
//! to = "lab::Gripper"
//! fields = { "width_m" = "x", "force_n" = "y" }   # "nerve field" = "ROS field" (the key is filled)
//!
//! [[static_transform]]                # on /tf_static, transient local (late joiners get it)
//! frame_id = "base_link"
//! child_frame_id = "camera"
//! translation = [0.1, 0.0, 0.3]       # m (default 0)
//! rotation = [0.0, 0.0, 0.0]          # roll, pitch, yaw in rad (default 0)
//! ```

use crate::usermap::UserMap;
use crate::usersub::UserSub;
use crate::wire::Distro;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// A nerve payload → ROS message conversion the agent knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PubMap {
    /// `nerve::Odometry` → `nav_msgs/msg/Odometry`
    OdometryToOdometry,
    /// `nerve::Odometry` → `tf2_msgs/msg/TFMessage` (frame_id → child_frame_id)
    OdometryToTf,
    /// `nerve::GroundTruth` → `nav_msgs/msg/Odometry`
    TruthToOdometry,
    /// `nerve::VelocityCommand` → `geometry_msgs/msg/Twist`
    VelocityToTwist,
    /// `nerve::SonarScan` → `sensor_msgs/msg/LaserScan` (12 rays, 30° apart)
    SonarToLaserScan,
    /// `nerve::SonarScan` → 12 `sensor_msgs/msg/Range`, frames `<frame_id>_<i>`
    SonarToRange,
    /// `nerve::RingNotice` of an rgb8 or gray8 ring → `sensor_msgs/msg/Image`
    FramesToImage,
    /// any payload → any vendored message, field by field ([`Publish::user`])
    User,
}

/// The conversions of `[[publish]]`: (nerve type, ROS type, conversion).
pub const PUB_MAPS: &[(&str, &str, PubMap)] = &[
    ("nerve::Odometry", "nav_msgs/msg/Odometry", PubMap::OdometryToOdometry),
    ("nerve::Odometry", "tf2_msgs/msg/TFMessage", PubMap::OdometryToTf),
    ("nerve::GroundTruth", "nav_msgs/msg/Odometry", PubMap::TruthToOdometry),
    ("nerve::VelocityCommand", "geometry_msgs/msg/Twist", PubMap::VelocityToTwist),
    ("nerve::SonarScan", "sensor_msgs/msg/LaserScan", PubMap::SonarToLaserScan),
    ("nerve::SonarScan", "sensor_msgs/msg/Range", PubMap::SonarToRange),
    ("nerve::RingNotice", "sensor_msgs/msg/Image", PubMap::FramesToImage),
];

/// A ROS message → nerve payload conversion the agent knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SubMap {
    /// `geometry_msgs/msg/Twist` → `nerve::VelocityCommand` (linear.x, angular.z)
    TwistToVelocity,
    /// any vendored message → any payload, field by field ([`Subscribe::user`])
    User,
}

/// The conversions of `[[subscribe]]`: (ROS type, nerve type, conversion).
pub const SUB_MAPS: &[(&str, &str, SubMap)] =
    &[("geometry_msgs/msg/Twist", "nerve::VelocityCommand", SubMap::TwistToVelocity)];

/// Reliable or best effort.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reliability {
    /// RELIABLE
    #[default]
    Reliable,
    /// BEST_EFFORT
    BestEffort,
}

/// Volatile, or transient local (the last `depth` messages served to
/// subscriptions that join later, as rmw_zenoh's advanced publisher cache).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Durability {
    /// VOLATILE: only subscriptions present when a message is sent get it
    #[default]
    Volatile,
    /// TRANSIENT_LOCAL: late joiners get the last `depth` messages
    TransientLocal,
}

/// Client of a router, or peer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// a client of the routers in `connect` (rmw_zenohd's default)
    #[default]
    Client,
    /// a peer, with explicit `connect` and `listen` endpoints
    Peer,
}

fn default_connect() -> Vec<String> {
    vec!["tcp/127.0.0.1:7447".into()]
}
fn default_depth() -> u32 {
    10
}
fn default_frame() -> String {
    "odom".into()
}
fn default_child() -> String {
    "base_link".into()
}

/// `[[publish]]` as written.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPublish {
    input: String,
    from: Spanned<String>,
    topic: String,
    #[serde(rename = "type")]
    ros_type: String,
    #[serde(default = "default_frame")]
    frame_id: String,
    #[serde(default = "default_child")]
    child_frame_id: String,
    #[serde(default)]
    reliability: Reliability,
    #[serde(default)]
    durability: Durability,
    #[serde(default = "default_depth")]
    depth: u32,
    /// `"ROS field" = "nerve field"` (a user's mapping)
    fields: Option<BTreeMap<String, Spanned<String>>>,
}

/// `[[type]]` as written: a payload's fields in order, `[name, type]`.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawType {
    name: Spanned<String>,
    fields: Vec<Spanned<(String, String)>>,
}

/// `[[static_transform]]` as written.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStatic {
    frame_id: String,
    child_frame_id: String,
    #[serde(default)]
    translation: [f64; 3],
    #[serde(default)]
    rotation: [f64; 3],
}

/// `[[subscribe]]` as written.
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSubscribe {
    topic: String,
    #[serde(rename = "type")]
    ros_type: String,
    output: String,
    to: Spanned<String>,
    #[serde(default)]
    reliability: Reliability,
    #[serde(default = "default_depth")]
    depth: u32,
    /// `"nerve field" = "ROS field"` (a user's mapping)
    fields: Option<BTreeMap<String, Spanned<String>>>,
}

#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConfig {
    node: Option<String>,
    #[serde(default)]
    namespace: String,
    #[serde(default)]
    domain: u32,
    #[serde(default)]
    distro: Distro,
    #[serde(default)]
    mode: Mode,
    #[serde(default = "default_connect")]
    connect: Vec<String>,
    #[serde(default)]
    listen: Vec<String>,
    #[serde(default)]
    publish: Vec<RawPublish>,
    #[serde(default)]
    subscribe: Vec<RawSubscribe>,
    #[serde(default)]
    static_transform: Vec<RawStatic>,
    #[serde(default, rename = "type")]
    types: Vec<RawType>,
}

/// One nerve input published as a ROS topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Publish {
    /// the agent's input
    pub input: String,
    /// the fully qualified topic
    pub topic: String,
    /// `pkg/msg/Name`
    pub ros_type: String,
    /// the conversion
    pub map: PubMap,
    /// header.frame_id
    pub frame_id: String,
    /// child_frame_id (odometry, tf)
    pub child_frame_id: String,
    /// the QoS in its token
    pub qos: crate::wire::Qos,
    /// [`PubMap::User`]: the payload's layout and its field-by-field plan
    pub user: Option<UserMap>,
}

/// One ROS topic delivered on a nerve output.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Subscribe {
    /// the fully qualified topic
    pub topic: String,
    /// `pkg/msg/Name`
    pub ros_type: String,
    /// the agent's output
    pub output: String,
    /// the conversion
    pub map: SubMap,
    /// the QoS in its token
    pub qos: crate::wire::Qos,
    /// [`SubMap::User`]: the payload's layout and its field-by-field plan
    pub user: Option<UserSub>,
}

/// The topic static transforms go on, as tf2's static broadcaster's.
pub const TF_STATIC_TOPIC: &str = "/tf_static";

/// A fixed transform between two frames (a sensor's place on the robot),
/// published once on [`TF_STATIC_TOPIC`], transient local: a
/// `[[static_transform]]`, checked (frame names, finite numbers).
#[derive(Debug, Clone, PartialEq)]
pub struct Static {
    /// the parent frame
    pub frame_id: String,
    /// the child frame
    pub child_frame_id: String,
    /// x, y, z in m
    pub translation: [f64; 3],
    /// roll, pitch, yaw in rad
    pub rotation: [f64; 3],
}

// the numbers are finite (checked by `parse`), so equality is reflexive
impl Eq for Static {}

/// The checked configuration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Config {
    /// the ROS node's name
    pub node: String,
    /// its namespace ("" for the root)
    pub namespace: String,
    /// ROS_DOMAIN_ID
    pub domain: u32,
    /// which type hashes the keys carry
    pub distro: Distro,
    /// client or peer
    pub mode: Mode,
    /// endpoints to connect to
    pub connect: Vec<String>,
    /// endpoints to listen on (peer)
    pub listen: Vec<String>,
    /// nerve → ROS
    pub publish: Vec<Publish>,
    /// ROS → nerve
    pub subscribe: Vec<Subscribe>,
    /// fixed transforms for /tf_static (none: no /tf_static publisher)
    pub static_transforms: Vec<Static>,
}

impl Config {
    /// The QoS of /tf_static: reliable, transient local, keep the last one
    /// (all the transforms go in one message, as tf2's static broadcaster
    /// sends them).
    pub fn tf_static_qos() -> crate::wire::Qos {
        crate::wire::Qos { reliable: true, transient_local: true, depth: 1 }
    }
}

/// Why the configuration was refused.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read the ros2 agent's configuration {path}: {source}")]
    Read {
        /// the file
        path: PathBuf,
        /// why
        #[source]
        source: std::io::Error,
    },
    /// Not TOML, or an unknown or mistyped key.
    #[error("{path}: {source}")]
    Toml {
        /// the file
        path: PathBuf,
        /// what toml said (with line and column)
        #[source]
        source: toml::de::Error,
    },
    /// A value that cannot be used, at a line of the file.
    #[error("{path}:{line}: {what}")]
    At {
        /// the file
        path: PathBuf,
        /// 1-based line
        line: usize,
        /// what is wrong and what to write instead
        what: String,
    },
    /// A value that cannot be used.
    #[error("{path}: {what}")]
    Invalid {
        /// the file
        path: PathBuf,
        /// what is wrong and what to write instead
        what: String,
    },
}

/// A ROS name: letters, digits and `_`, not starting with a digit.
fn ros_name_ok(s: &str) -> bool {
    !s.is_empty() && s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_') && !s.as_bytes()[0].is_ascii_digit()
}

/// A topic: `/`-separated ROS names, absolute or relative.
fn topic_ok(s: &str) -> bool {
    let body = s.strip_prefix('/').unwrap_or(s);
    !body.is_empty() && body.split('/').all(ros_name_ok)
}

fn list(pairs: impl Iterator<Item = String>) -> String {
    pairs.collect::<Vec<_>>().join(", ")
}

/// Parses and checks the text of a configuration; `agent` is the agent's
/// name (the default node name, with `-` as `_`).
pub fn parse(path: &Path, text: &str, agent: &str) -> Result<Config, ConfigError> {
    let invalid = |what: String| ConfigError::Invalid { path: path.to_owned(), what };
    let raw: RawConfig = toml::from_str(text).map_err(|source| ConfigError::Toml { path: path.to_owned(), source })?;
    let node = raw.node.unwrap_or_else(|| agent.replace('-', "_"));
    if !ros_name_ok(&node) {
        return Err(invalid(format!(
            "node = {node:?} is not a ROS node name (letters, digits and _, not starting with a digit)"
        )));
    }
    let namespace = raw.namespace.trim_end_matches('/').to_owned();
    if !namespace.is_empty() && (!namespace.starts_with('/') || !topic_ok(&namespace)) {
        return Err(invalid(format!("namespace = {:?} must be empty or like \"/robot1\"", raw.namespace)));
    }
    if raw.domain > 232 {
        return Err(invalid(format!("domain = {} is not a ROS domain id (0 to 232)", raw.domain)));
    }
    if raw.connect.is_empty() && raw.mode == Mode::Client {
        return Err(invalid("mode = \"client\" needs a router in connect = [\"tcp/HOST:7447\"]".into()));
    }
    let line = |at: usize| text.get(..at).map_or(1, |t| t.matches('\n').count() + 1);
    let at = |span: std::ops::Range<usize>, what: String| ConfigError::At {
        path: path.to_owned(),
        line: line(span.start),
        what,
    };
    let mut types: BTreeMap<String, (BTreeMap<String, usize>, shm_schemas::Schema)> = BTreeMap::new();
    for t in &raw.types {
        let name = t.name.get_ref();
        let fields: Vec<(String, String)> = t.fields.iter().map(|f| f.get_ref().clone()).collect();
        let known: BTreeMap<String, shm_schemas::Schema> =
            types.iter().map(|(k, v)| (k.clone(), v.1.clone())).collect();
        if types.contains_key(name) || shm_schemas::schema::built_in_named(name).is_some() {
            return Err(at(t.name.span(), format!("[[type]] {name} is declared twice (or is a built-in payload)")));
        }
        let schema = crate::usermap::struct_layout(name, &fields, &known)
            .map_err(|e| at(t.name.span(), format!("[[type]] {name}: {e}")))?;
        let lines = t.fields.iter().map(|f| (f.get_ref().0.clone(), f.span().start)).collect();
        types.insert(name.clone(), (lines, schema));
    }
    let mut inputs = std::collections::BTreeSet::new();
    let mut publish = Vec::new();
    for p in raw.publish {
        if !topic_ok(&p.topic) {
            return Err(invalid(format!("[[publish]] topic = {:?} is not a ROS topic name", p.topic)));
        }
        if !ros_name_ok(&p.input) || !inputs.insert(p.input.clone()) {
            return Err(invalid(format!("[[publish]] input = {:?}: a port name, once per agent", p.input)));
        }
        let from = p.from.get_ref();
        let built = PUB_MAPS.iter().find(|(f, to, _)| f == from && *to == p.ros_type).map(|m| m.2);
        let declared = types.get(from);
        let (map, user) = match (&p.fields, built, declared) {
            (None, Some(m), _) => (m, None),
            (fields, _, _) if fields.is_some() || declared.is_some() => {
                let schema = match declared.map(|d| d.1.clone()).or_else(|| shm_schemas::schema::built_in_named(from)) {
                    Some(s) => s,
                    None => {
                        return Err(at(
                            p.from.span(),
                            format!(
                                "[[publish]] {}: from = {from:?} is neither a built-in payload nor a [[type]] of this file",
                                p.topic
                            ),
                        ));
                    }
                };
                let pairs: Option<Vec<(String, String)>> =
                    p.fields.as_ref().map(|f| f.iter().map(|(k, v)| (k.clone(), v.get_ref().clone())).collect());
                let m = UserMap::new(schema, &p.ros_type, pairs.as_deref()).map_err(|e| {
                    let start = match (&e.key, &p.fields, declared) {
                        (Some(k), Some(f), _) => f.get(k).map(|v| v.span().start),
                        (Some(k), None, Some((lines, _))) => lines.get(k).copied(),
                        _ => None,
                    };
                    let start = start.unwrap_or(p.from.span().start);
                    at(start..start, format!("[[publish]] {}: {}", p.topic, e.what))
                })?;
                (PubMap::User, Some(m))
            }
            _ => {
                return Err(at(
                    p.from.span(),
                    format!(
                        "[[publish]] {}: no conversion from {from} to {}; the agent knows {}; or map the fields \
                         yourself: fields = {{ \"ROS field\" = \"nerve field\", ... }}",
                        p.topic,
                        p.ros_type,
                        list(PUB_MAPS.iter().map(|(a, b, _)| format!("{a} -> {b}")))
                    ),
                ));
            }
        };
        publish.push(Publish {
            input: p.input,
            topic: crate::wire::qualified_topic(&namespace, &p.topic),
            ros_type: p.ros_type,
            map,
            frame_id: p.frame_id,
            child_frame_id: p.child_frame_id,
            qos: crate::wire::Qos {
                reliable: p.reliability == Reliability::Reliable,
                transient_local: p.durability == Durability::TransientLocal,
                depth: p.depth,
            },
            user,
        });
    }
    let mut outputs = std::collections::BTreeSet::new();
    let mut subscribe = Vec::new();
    for s in raw.subscribe {
        if !topic_ok(&s.topic) {
            return Err(invalid(format!("[[subscribe]] topic = {:?} is not a ROS topic name", s.topic)));
        }
        if !ros_name_ok(&s.output) || !outputs.insert(s.output.clone()) {
            return Err(invalid(format!("[[subscribe]] output = {:?}: a port name, once per agent", s.output)));
        }
        let to = s.to.get_ref();
        let built = SUB_MAPS.iter().find(|(from, t, _)| *from == s.ros_type && t == to).map(|m| m.2);
        let declared = types.get(to);
        let (map, user) = match (&s.fields, built, declared) {
            (None, Some(m), _) => (m, None),
            (fields, _, _) if fields.is_some() || declared.is_some() => {
                let Some(schema) = declared.map(|d| d.1.clone()).or_else(|| shm_schemas::schema::built_in_named(to))
                else {
                    return Err(at(
                        s.to.span(),
                        format!(
                            "[[subscribe]] {}: to = {to:?} is neither a built-in payload nor a [[type]] of this file",
                            s.topic
                        ),
                    ));
                };
                let pairs: Option<Vec<(String, String)>> =
                    s.fields.as_ref().map(|f| f.iter().map(|(k, v)| (k.clone(), v.get_ref().clone())).collect());
                let m = UserSub::new(schema, &s.ros_type, pairs.as_deref()).map_err(|e| {
                    // an entry's line; by name, the line of the nerve
                    // field's first part in [[type]]
                    let start = match (&e.key, &s.fields, declared) {
                        (Some(k), Some(f), _) => f.get(k).map(|v| v.span().start),
                        (Some(k), None, Some((lines, _))) => lines.get(k.split('.').next().unwrap_or(k)).copied(),
                        _ => None,
                    };
                    let start = start.unwrap_or(s.to.span().start);
                    at(start..start, format!("[[subscribe]] {}: {}", s.topic, e.what))
                })?;
                (SubMap::User, Some(m))
            }
            _ => {
                return Err(at(
                    s.to.span(),
                    format!(
                        "[[subscribe]] {}: no conversion from {} to {to}; the agent knows {}; or map the fields \
                         yourself: fields = {{ \"nerve field\" = \"ROS field\", ... }}",
                        s.topic,
                        s.ros_type,
                        list(SUB_MAPS.iter().map(|(a, b, _)| format!("{a} -> {b}")))
                    ),
                ));
            }
        };
        subscribe.push(Subscribe {
            topic: crate::wire::qualified_topic(&namespace, &s.topic),
            ros_type: s.ros_type,
            output: s.output,
            map,
            qos: crate::wire::Qos {
                reliable: s.reliability == Reliability::Reliable,
                transient_local: false,
                depth: s.depth,
            },
            user,
        });
    }
    let mut static_transforms = Vec::new();
    for t in raw.static_transform {
        if !frame_ok(&t.frame_id) || !frame_ok(&t.child_frame_id) || t.frame_id == t.child_frame_id {
            return Err(invalid(format!(
                "[[static_transform]] {:?} -> {:?}: two different frame names (letters, digits, _ and /)",
                t.frame_id, t.child_frame_id
            )));
        }
        if !t.translation.iter().chain(&t.rotation).all(|v| v.is_finite()) {
            return Err(invalid(format!(
                "[[static_transform]] {} -> {}: translation and rotation must be finite numbers",
                t.frame_id, t.child_frame_id
            )));
        }
        static_transforms.push(Static {
            frame_id: t.frame_id,
            child_frame_id: t.child_frame_id,
            translation: t.translation,
            rotation: t.rotation,
        });
    }
    Ok(Config {
        node,
        namespace,
        domain: raw.domain,
        distro: raw.distro,
        mode: raw.mode,
        connect: raw.connect,
        listen: raw.listen,
        publish,
        subscribe,
        static_transforms,
    })
}

/// A tf frame name: a ROS name, possibly with `/` inside.
fn frame_ok(s: &str) -> bool {
    let body = s.strip_prefix('/').unwrap_or(s);
    !body.is_empty() && body.split('/').all(ros_name_ok)
}

/// Reads and checks the configuration file.
pub fn load(path: &Path, agent: &str) -> Result<Config, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read { path: path.to_owned(), source })?;
    parse(path, &text, agent)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(text: &str) -> Result<Config, String> {
        parse(Path::new("r.toml"), text, "ros-2").map_err(|e| e.to_string())
    }

    #[test]
    fn defaults_are_rmw_zenoh_s() {
        let c = p("").expect("empty is fine");
        assert_eq!(c.node, "ros_2");
        assert_eq!((c.domain, c.distro, c.mode), (0, Distro::Jazzy, Mode::Client));
        assert_eq!(c.connect, ["tcp/127.0.0.1:7447"]);
    }

    #[test]
    fn topics_both_ways() {
        let c = p(r#"
namespace = "/robot1"
distro = "humble"
[[publish]]
input = "odom"
from = "nerve::Odometry"
topic = "odom"
type = "nav_msgs/msg/Odometry"
reliability = "best_effort"
[[subscribe]]
topic = "/cmd_vel"
type = "geometry_msgs/msg/Twist"
output = "cmd_vel"
to = "nerve::VelocityCommand"
"#)
        .expect("valid");
        assert_eq!(c.publish[0].topic, "/robot1/odom");
        assert_eq!(c.publish[0].map, PubMap::OdometryToOdometry);
        assert!(!c.publish[0].qos.reliable);
        assert_eq!(c.subscribe[0].topic, "/cmd_vel");
        assert_eq!(c.distro, Distro::Humble);
    }

    /// The configuration launch/ros2.toml starts the agent with.
    #[test]
    fn the_example_of_the_launch_file_is_valid() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples").join("explore.toml");
        let c = load(&path, "ros2").expect("examples/explore.toml");
        let topics: Vec<&str> = c.publish.iter().map(|p| p.topic.as_str()).collect();
        assert_eq!(topics, ["/odom", "/tf", "/scan", "/camera/image_raw"]);
        assert_eq!(c.subscribe[0].topic, "/cmd_vel");
        let launch = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../launch/ros2.toml"))
            .expect("launch/ros2.toml");
        for input in ["ros2/odom", "ros2/tf", "ros2/scan", "ros2/image"] {
            assert!(launch.contains(&format!("to = \"{input}\"")), "launch/ros2.toml wires {input}");
        }
        assert!(launch.contains("from = \"ros2/cmd_vel\""), "launch/ros2.toml wires ros2/cmd_vel");
    }

    #[test]
    fn mistakes_are_named() {
        let e =
            p("[[publish]]\ninput = \"o\"\nfrom = \"nerve::Tick\"\ntopic = \"/o\"\ntype = \"nav_msgs/msg/Odometry\"\n")
                .expect_err("no such conversion");
        assert!(
            e.contains("no conversion from nerve::Tick") && e.contains("nerve::Odometry -> nav_msgs/msg/Odometry"),
            "{e}"
        );
        let e = p("nodes = \"x\"").expect_err("unknown key");
        assert!(e.contains("unknown field") && e.contains("nodes"), "{e}");
        let e = p("distro = \"foxy\"").expect_err("unknown distro");
        assert!(e.contains("foxy"), "{e}");
        let e = p("[[subscribe]]\ntopic = \"/cmd vel\"\ntype = \"geometry_msgs/msg/Twist\"\noutput = \"c\"\nto = \"nerve::VelocityCommand\"\n")
            .expect_err("bad topic");
        assert!(e.contains("not a ROS topic name"), "{e}");
        let e = p("mode = \"client\"\nconnect = []").expect_err("client without router");
        assert!(e.contains("needs a router"), "{e}");
    }

    #[test]
    fn static_transforms_and_transient_local_topics() {
        let c = p(r#"
[[publish]]
input = "odom"
from = "nerve::Odometry"
topic = "/odom"
type = "nav_msgs/msg/Odometry"
durability = "transient_local"
depth = 3
[[static_transform]]
frame_id = "base_link"
child_frame_id = "camera"
translation = [0.1, 0.0, 0.3]
"#)
        .expect("valid");
        assert_eq!(c.publish[0].qos, crate::wire::Qos { reliable: true, transient_local: true, depth: 3 });
        assert_eq!(c.static_transforms[0].child_frame_id, "camera");
        assert_eq!(c.static_transforms[0].rotation, [0.0; 3]);
        let e = p("[[static_transform]]\nframe_id = \"a\"\nchild_frame_id = \"a\"\n").expect_err("one frame");
        assert!(e.contains("two different frame names"), "{e}");
        let e = p("[[static_transform]]\nframe_id = \"a\"\nchild_frame_id = \"b\"\ntranslation = [nan, 0.0, 0.0]\n")
            .expect_err("not finite");
        assert!(e.contains("finite"), "{e}");
        let e = p("[[static_transform]]\nframe_id = \"a\"\nchild = \"b\"\n").expect_err("unknown key");
        assert!(e.contains("unknown field"), "{e}");
    }

    /// A user's own type (`[[type]]`) and a built-in one, published as
    /// vendored ROS messages field by field; a field without counterpart or
    /// of a type the other side cannot take is refused at its line.
    #[test]
    fn a_users_type_mapped_field_by_field_and_its_mistakes_at_their_line() {
        let head = r#"[[type]]
name = "lab::Gripper"
fields = [
  ["width_m", "f32"],
  ["force_n", "f32"],
  ["closed", "u8"],
  ["_pad", "[u8; 3]"],
]
[[publish]]
input = "gripper"
from = "lab::Gripper"
topic = "/gripper"
"#;
        let c = p(&format!(
            "{head}type = \"geometry_msgs/msg/Vector3\"\n[publish.fields]\n\"x\" = \"width_m\"\nz = \"closed\"\n"
        ))
        .expect("valid");
        let m = c.publish[0].user.as_ref().expect("a user mapping");
        assert_eq!((c.publish[0].map, m.schema.type_name.as_str(), m.schema.size), (PubMap::User, "lab::Gripper", 12));
        // a ROS field that does not exist: line 16 (its entry)
        let e = p(&format!(
            "{head}type = \"geometry_msgs/msg/Vector3\"\n[publish.fields]\nx = \"width_m\"\nw = \"closed\"\n"
        ))
        .expect_err("no ROS field w");
        assert!(e.starts_with("r.toml:16: [[publish]] /gripper: geometry_msgs/msg/Vector3 has no field \"w\""), "{e}");
        // a nerve field that does not exist, and a float into an integer
        let e = p(&format!("{head}type = \"std_msgs/msg/Int32\"\nfields = {{ data = \"width\" }}\n"))
            .expect_err("no width");
        assert!(e.starts_with("r.toml:14:") && e.contains("lab::Gripper has no field \"width\""), "{e}");
        let e =
            p(&format!("{head}type = \"std_msgs/msg/Int32\"\nfields = {{ data = \"force_n\" }}\n")).expect_err("float");
        assert!(e.contains("data (int32) cannot take lab::Gripper field force_n (f32)"), "{e}");
        // no `fields`: by name, and the first nerve field without a ROS
        // field of its name is refused at its line in [[type]]
        let e = p(&format!("{head}type = \"geometry_msgs/msg/Vector3\"\n")).expect_err("by name");
        assert!(e.starts_with("r.toml:4:") && e.contains("\"width_m\" has no counterpart"), "{e}");
        // a type neither built in nor declared
        let e = p("[[publish]]\ninput = \"g\"\nfrom = \"lab::Nope\"\ntopic = \"/g\"\ntype = \"std_msgs/msg/Float32\"\nfields = { data = \"x\" }\n")
            .expect_err("unknown type");
        assert!(e.starts_with("r.toml:3:") && e.contains("neither a built-in payload nor a [[type]]"), "{e}");
        // a built-in payload mapped to another message
        let c = p("[[publish]]\ninput = \"o\"\nfrom = \"nerve::Odometry\"\ntopic = \"/pose2d\"\ntype = \"geometry_msgs/msg/Vector3\"\nfields = { x = \"x\", y = \"y\", z = \"theta\" }\n")
            .expect("built-in mapped");
        assert_eq!(c.publish[0].user.as_ref().map(|m| m.schema.type_name.as_str()), Some("nerve::Odometry"));
        // [[type]] mistakes at the type's line
        let e = p("x = 1\n[[type]]\nname = \"lab::T\"\nfields = [[\"a\", \"float\"]]\n").expect_err("bad field type");
        assert!(e.contains("unknown field") || e.starts_with("r.toml:"), "{e}");
        let e = p("[[type]]\nname = \"lab::T\"\nfields = [[\"a\", \"float\"]]\n").expect_err("bad field type");
        assert!(e.starts_with("r.toml:2: [[type]] lab::T: field \"a\""), "{e}");
        // implicit padding, which a Rust agent's #[derive(Payload)] refuses:
        // the gap named, and the _pad field that fills it
        let e = p("[[type]]\nname = \"lab::T\"\nfields = [[\"a\", \"u8\"], [\"b\", \"f32\"]]\n").expect_err("a gap");
        assert!(
            e.starts_with(
                "r.toml:2: [[type]] lab::T: 3 bytes of implicit padding at offset 1, before field \"b\" (at 4)"
            ) && e.contains("[\"_pad1\", \"[u8; 3]\"]"),
            "{e}"
        );
        let e = p("[[type]]\nname = \"lab::T\"\nfields = [[\"b\", \"f32\"], [\"a\", \"u8\"]]\n").expect_err("a tail");
        assert!(
            e.contains("3 bytes of implicit padding at offset 5, after the last field") && e.contains("_pad5"),
            "{e}"
        );
        let e = p("[[type]]\nname = \"lab::T\"\nfields = [[\"b\", \"f32\"], [\"_pad\", \"u32\"]]\n")
            .expect_err("not bytes");
        assert!(e.contains("its type must be [u8; N]"), "{e}");
    }

    /// A ROS message received as a user's own type (`[[subscribe]]` with
    /// `fields`, "nerve field" = "ROS field"), by name without `fields`, and
    /// its mistakes at their lines.
    #[test]
    fn a_ros_message_subscribed_as_a_users_type_and_its_mistakes_at_their_line() {
        let head = r#"[[type]]
name = "lab::Pose2D"
fields = [
  ["x", "f64"],
  ["y", "f32"],
  ["_pad", "[u8; 4]"],
  ["sec", "i64"],
]
[[subscribe]]
topic = "/odom_in"
output = "odom_in"
to = "lab::Pose2D"
"#;
        let c = p(&format!(
            "{head}type = \"nav_msgs/msg/Odometry\"\n[subscribe.fields]\nx = \"pose.pose.position.x\"\nsec = \"header.stamp.sec\"\n"
        ))
        .expect("valid");
        let m = c.subscribe[0].user.as_ref().expect("a user mapping");
        assert_eq!((c.subscribe[0].map, m.schema.type_name.as_str(), m.schema.size), (SubMap::User, "lab::Pose2D", 24));
        // a ROS field that does not exist: line 16 (its entry)
        let e = p(&format!(
            "{head}type = \"nav_msgs/msg/Odometry\"\n[subscribe.fields]\nx = \"pose.pose.position.x\"\ny = \"pose.position.y\"\n"
        ))
        .expect_err("no such ROS field");
        assert!(
            e.starts_with("r.toml:16: [[subscribe]] /odom_in: nav_msgs/msg/Odometry has no field \"pose.position.y\""),
            "{e}"
        );
        // a float into an integer, at its entry's line
        let e = p(&format!("{head}type = \"geometry_msgs/msg/Vector3\"\nfields = {{ sec = \"x\" }}\n"))
            .expect_err("float into i64");
        assert!(
            e.starts_with("r.toml:14:") && e.contains("sec (i64) cannot take geometry_msgs/msg/Vector3 field x"),
            "{e}"
        );
        // by name: the first nerve field without a ROS field of its path,
        // at its line in [[type]]
        let e = p(&format!("{head}type = \"geometry_msgs/msg/Vector3\"\n")).expect_err("by name");
        assert!(e.starts_with("r.toml:7:") && e.contains("\"sec\" has no counterpart"), "{e}");
        // neither built in nor declared; no conversion and no fields
        let e = p("[[subscribe]]\ntopic = \"/a\"\ntype = \"std_msgs/msg/Int32\"\noutput = \"a\"\nto = \"lab::Nope\"\nfields = { n = \"data\" }\n")
            .expect_err("unknown type");
        assert!(e.starts_with("r.toml:5:") && e.contains("neither a built-in payload nor a [[type]]"), "{e}");
        let e = p(
            "[[subscribe]]\ntopic = \"/a\"\ntype = \"std_msgs/msg/Int32\"\noutput = \"a\"\nto = \"nerve::Odometry\"\n",
        )
        .expect_err("no conversion");
        assert!(
            e.contains("no conversion from std_msgs/msg/Int32 to nerve::Odometry")
                && e.contains("\"nerve field\" = \"ROS field\""),
            "{e}"
        );
        // a built-in payload filled from another message
        let c = p("[[subscribe]]\ntopic = \"/v\"\ntype = \"geometry_msgs/msg/Vector3\"\noutput = \"v\"\nto = \"nerve::VelocityCommand\"\nfields = { v = \"x\", omega = \"z\" }\n")
            .expect("built-in filled");
        assert_eq!(c.subscribe[0].user.as_ref().map(|m| m.schema.type_name.as_str()), Some("nerve::VelocityCommand"));
    }
}
