//! Tests of [`super`]: mappings checked field by field, messages written by
//! the crate's own CDR writer (and the standard messages' encoders) decoded
//! into the nerve layout, values that do not fit refused, and the layout
//! the same as a Rust agent's `#[derive(Payload)]` of the type.

use super::*;
use crate::cdr::Writer;
use crate::msgs::{Header, Odometry, Quaternion, RosMessage as _, Time, Twist, Vector3};
use crate::usermap::struct_layout;

fn f(n: &str, t: &str) -> (String, String) {
    (n.to_owned(), t.to_owned())
}

/// `lab::Pose2D` as the tests' `[[type]]`: x@0 f64, y@8 f32, v@12 f32,
/// sec@16 i64, seq@24 u32, cov@28 [f32; 3], size 40 (no padding: a Rust
/// `#[derive(Payload)]` refuses padding).
fn pose2d() -> Schema {
    struct_layout(
        "lab::Pose2D",
        &[f("x", "f64"), f("y", "f32"), f("v", "f32"), f("sec", "i64"), f("seq", "u32"), f("cov", "[f32; 3]")],
        &BTreeMap::new(),
    )
    .expect("layout")
}

fn odom(x: f64, y: f64, v: f64, sec: i32, cov: [f64; 36]) -> Vec<u8> {
    Odometry {
        header: Header { stamp: Time { sec, nanosec: 5 }, frame_id: "odom".into() },
        child_frame_id: "base_link".into(),
        position: Vector3 { x, y, z: 0.5 },
        orientation: Quaternion::from_yaw(0.3),
        pose_covariance: cov,
        twist: Twist { linear: Vector3 { x: v, y: 0.0, z: 0.0 }, angular: Vector3 { x: 0.0, y: 0.0, z: 0.2 } },
        twist_covariance: [0.0; 36],
    }
    .to_cdr()
    .expect("cdr")
}

fn pairs(p: &[(&str, &str)]) -> Vec<(String, String)> {
    p.iter().map(|(a, b)| ((*a).to_owned(), (*b).to_owned())).collect()
}

fn read<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    b[at..at + N].try_into().expect("in the sample")
}

#[test]
fn nested_ros_fields_fill_the_users_type() {
    let fields = pairs(&[
        ("x", "pose.pose.position.x"),
        ("y", "pose.pose.position.y"),
        ("v", "twist.twist.linear.x"),
        ("sec", "header.stamp.sec"),
    ]);
    let m = UserSub::new(pose2d(), "nav_msgs/msg/Odometry", Some(&fields)).expect("valid");
    let s = m.decode(&odom(1.25, -0.5, 0.3, 1_700_000_000, [0.0; 36])).expect("decodes");
    assert_eq!(s.len(), 40);
    assert_eq!(f64::from_le_bytes(read(&s, 0)), 1.25);
    assert_eq!(f32::from_le_bytes(read(&s, 8)), -0.5);
    assert_eq!(f32::from_le_bytes(read(&s, 12)), 0.3f32);
    assert_eq!(i64::from_le_bytes(read(&s, 16)), 1_700_000_000);
    assert_eq!(s[24..40], [0u8; 16], "seq and cov: not mapped, zero");
}

#[test]
fn by_name_including_nested_types() {
    // a nerve type of two nested ones fills geometry_msgs/Twist by path
    let v3 = struct_layout(
        "lab::V3",
        &[f("x", "f64"), f("y", "f32"), f("_pad", "[u8; 4]"), f("z", "f64")],
        &BTreeMap::new(),
    )
    .expect("v3");
    let mut known = BTreeMap::new();
    known.insert("lab::V3".to_owned(), v3);
    let t = struct_layout("lab::Twist", &[f("linear", "lab::V3"), f("angular", "lab::V3")], &known).expect("twist");
    let m = UserSub::new(t.clone(), "geometry_msgs/msg/Twist", None).expect("by name");
    let twist = Twist { linear: Vector3 { x: 1.0, y: 2.0, z: 3.0 }, angular: Vector3 { x: 4.0, y: 5.0, z: 6.0 } };
    let s = m.decode(&twist.to_cdr().expect("cdr")).expect("decodes");
    let at = |p: &str| t.field(p).map(|(o, _)| o).expect("field");
    assert_eq!(f64::from_le_bytes(read(&s, at("linear.x"))), 1.0);
    assert_eq!(f32::from_le_bytes(read(&s, at("linear.y"))), 2.0);
    assert_eq!(f64::from_le_bytes(read(&s, at("angular.z"))), 6.0);
    // a nerve field with no ROS field of its path is named
    let e = UserSub::new(pose2d(), "geometry_msgs/msg/Vector3", None).expect_err("no counterpart");
    assert_eq!(e.key.as_deref(), Some("v"));
    assert!(e.what.contains("lab::Pose2D field \"v\" has no counterpart in geometry_msgs/msg/Vector3"), "{}", e.what);
}

#[test]
fn arrays_sequences_strings_and_skipped_fields() {
    // sensor_msgs/LaserScan: header (a string to skip), seven float32, then
    // float32[] ranges and intensities
    let s = struct_layout("lab::Ring", &[f("r", "[f32; 3]"), f("_pad", "[u8; 4]"), f("max", "f64")], &BTreeMap::new())
        .expect("layout");
    let fields = pairs(&[("r", "ranges"), ("max", "range_max")]);
    let m = UserSub::new(s, "sensor_msgs/msg/LaserScan", Some(&fields)).expect("valid");
    let scan = |ranges: &[f32]| {
        let mut w = Writer::new();
        w.i32(1);
        w.u32(2);
        w.string("a frame id the plan must skip").expect("string");
        for x in [0.0f32, 1.0, 0.5, 0.0, 0.1, 0.15, 5.0] {
            w.f32(x);
        }
        w.f32_seq(ranges).expect("ranges");
        w.f32_seq(&[9.0]).expect("intensities");
        w.finish()
    };
    let out = m.decode(&scan(&[1.0, 2.0, 3.0])).expect("three");
    let got: Vec<f32> = (0..3).map(|i| f32::from_le_bytes(read(&out, 4 * i))).collect();
    assert_eq!(got, [1.0, 2.0, 3.0]);
    assert_eq!(f64::from_le_bytes(read(&out, 16)), 5.0, "a float32 into an f64");
    let out = m.decode(&scan(&[7.0])).expect("fewer: the rest zero");
    assert_eq!((f32::from_le_bytes(read(&out, 0)), f32::from_le_bytes(read(&out, 4))), (7.0, 0.0));
    let e = m.decode(&scan(&[1.0, 2.0, 3.0, 4.0])).expect_err("more than the nerve array holds");
    assert!(matches!(&e, SubError::DoesNotFit { ros, nerve, .. } if ros == "ranges" && nerve == "r ([f32; 3])"), "{e}");
    // a fixed array of another length is refused at start
    let fields = pairs(&[("cov", "pose.covariance")]);
    let e = UserSub::new(pose2d(), "nav_msgs/msg/Odometry", Some(&fields)).expect_err("36 into 3");
    assert!(e.what.contains("36 values into 3 places"), "{}", e.what);
    // a nerve string (a built-in payload's) from a ROS string
    let header = struct_layout("lab::Id", &[f("n", "u32")], &BTreeMap::new()).expect("layout");
    let e = UserSub::new(header, "std_msgs/msg/String", Some(&pairs(&[("n", "data")]))).expect_err("string");
    assert!(e.what.contains("a ROS string goes into a nerve string"), "{}", e.what);
}

#[test]
fn values_that_do_not_fit_are_refused_not_wrapped() {
    let fields = pairs(&[("y", "pose.pose.position.y")]);
    let m = UserSub::new(pose2d(), "nav_msgs/msg/Odometry", Some(&fields)).expect("float64 into f32");
    let e = m.decode(&odom(0.0, 1e300, 0.0, 0, [0.0; 36])).expect_err("beyond f32");
    assert_eq!(
        e.to_string(),
        "nav_msgs/msg/Odometry field pose.pose.position.y = 1e300 does not fit y (f32): beyond the range of an f32; \
         the message is refused"
    );
    // infinities and NaN are f32 values: carried
    let s = m.decode(&odom(0.0, f64::INFINITY, 0.0, 0, [0.0; 36])).expect("inf");
    assert_eq!(f32::from_le_bytes(read(&s, 8)), f32::INFINITY);
    // another message type, cut short, or with bytes left
    let cdr = odom(0.0, 1.0, 0.0, 0, [0.0; 36]);
    assert!(matches!(m.decode(&cdr[..cdr.len() - 9]), Err(SubError::Cdr { .. })));
    let twist = Twist { linear: Vector3 { x: 1.0, y: 0.0, z: 0.0 }, angular: Vector3 { x: 0.0, y: 0.0, z: 0.0 } };
    assert!(matches!(m.decode(&twist.to_cdr().expect("cdr")), Err(SubError::Cdr { .. })));
    // a count beyond the message is refused before anything is repeated
    let m = UserSub::new(pose2d(), "tf2_msgs/msg/TFMessage", Some(&[])).map(|_| ()).expect_err("nothing mapped");
    assert!(m.what.contains("no field is mapped"), "{}", m.what);
    let s = struct_layout("lab::N", &[f("n", "u8")], &BTreeMap::new()).expect("layout");
    let b = UserSub::new(s, "std_msgs/msg/Bool", Some(&pairs(&[("n", "data")]))).expect("a bool into a u8");
    assert_eq!(b.decode(&[0, 1, 0, 0, 1]).expect("true"), [1]);
}

#[test]
fn narrowing_and_missing_fields_are_named_at_start() {
    let e =
        |fields: &[(&str, &str)], ros: &str| UserSub::new(pose2d(), ros, Some(&pairs(fields))).expect_err("refused");
    let x = e(&[("x", "pose.pose.position.w")], "nav_msgs/msg/Odometry");
    assert_eq!(x.key.as_deref(), Some("x"));
    assert!(
        x.what.contains("has no field \"pose.pose.position.w\"") && x.what.contains("pose.pose.position.x (float64)"),
        "{}",
        x.what
    );
    let x = e(&[("theta", "z")], "geometry_msgs/msg/Vector3");
    assert!(x.what.contains("lab::Pose2D has no field \"theta\"") && x.what.contains("cov ([f32; 3])"), "{}", x.what);
    let x = e(&[("sec", "x")], "geometry_msgs/msg/Vector3");
    assert!(
        x.what.contains("sec (i64) cannot take geometry_msgs/msg/Vector3 field x (float64): a ROS float"),
        "{}",
        x.what
    );
    let x = e(&[("seq", "data")], "std_msgs/msg/Int32");
    assert!(x.what.contains("not every value of the ROS integer fits a nerve u32"), "{}", x.what);
    let x = e(&[("sec", "data")], "std_msgs/msg/UInt64");
    assert!(x.what.contains("fits a nerve i64"), "a uint64 into an i64: {}", x.what);
    assert!(UserSub::new(pose2d(), "std_msgs/msg/UInt32", Some(&pairs(&[("sec", "data")]))).is_ok(), "u32 into i64");
    let x = e(&[("x", "pose.pose")], "nav_msgs/msg/Odometry");
    assert!(x.what.contains("has no field \"pose.pose\""), "a message is not a leaf: {}", x.what);
    let x = e(&[("cov", "x")], "geometry_msgs/msg/Vector3");
    assert!(x.what.contains("one value goes into one number"), "{}", x.what);
    let x = e(&[("x", "ranges")], "sensor_msgs/msg/LaserScan");
    assert!(x.what.contains("a ROS array goes into a nerve array"), "{}", x.what);
    let x = e(&[("x", "x")], "geometry_msgs/msg/Accel");
    assert!(x.key.is_none() && x.what.contains("not a vendored ROS message"), "{}", x.what);
}

/// The layout of a `[[type]]` is what `#[derive(Payload)]` gives the same
/// `#[repr(C)]` struct: same schema, same fingerprint (`nerve types`).
#[test]
fn the_layout_is_a_rust_agents() {
    #[derive(Debug, Clone, Copy, Default, shm_schemas::Payload, serde::Serialize)]
    #[repr(C)]
    #[payload(name = "lab::Pose2D")]
    struct Pose2D {
        x: f64,
        y: f32,
        v: f32,
        sec: i64,
        seq: u32,
        cov: [f32; 3],
    }
    let rust = <Pose2D as shm_schemas::schema::Described>::schema();
    assert_eq!(pose2d(), rust);
    assert_eq!(pose2d().fingerprint(), <Pose2D as shm_schemas::Payload>::layout_fingerprint());
    let _ = Pose2D::default();
    // with its gaps filled by `_pad` fields, as the derive asks and as the
    // [[type]] check asks: the same schema and fingerprint both ways
    #[derive(Debug, Clone, Copy, Default, shm_schemas::Payload, serde::Serialize)]
    #[repr(C)]
    #[payload(name = "lab::Gripper")]
    struct Gripper {
        width_m: f32,
        #[serde(skip)]
        _pad0: [u8; 4],
        force_n: f64,
        closed: u8,
        #[serde(skip)]
        _pad1: [u8; 7],
    }
    let fields =
        [f("width_m", "f32"), f("_pad0", "[u8; 4]"), f("force_n", "f64"), f("closed", "u8"), f("_pad1", "[u8; 7]")];
    let declared = struct_layout("lab::Gripper", &fields, &BTreeMap::new()).expect("padded layout");
    assert_eq!(declared, <Gripper as shm_schemas::schema::Described>::schema());
    assert_eq!(declared.fingerprint(), <Gripper as shm_schemas::Payload>::layout_fingerprint());
    let _ = Gripper::default();
}
