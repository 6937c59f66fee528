//! Tests of [`super`]: layouts as the compiler makes them, mappings checked
//! field by field, and the CDR written, decoded back with the crate's own
//! reader against the values of the sample.

use super::*;
use crate::cdr::Reader;

fn gripper() -> Schema {
    let f = |n: &str, t: &str| (n.to_owned(), t.to_owned());
    struct_layout(
        "lab::Gripper",
        &[
            f("width_m", "f32"),
            f("_pad0", "[u8; 4]"),
            f("force_n", "f64"),
            f("closed", "u8"),
            f("_pad1", "[u8; 3]"),
            f("fingers", "[f32; 3]"),
            f("id", "i64"),
        ],
        &BTreeMap::new(),
    )
    .expect("layout")
}

fn sample(width: f32, force: f64, closed: u8, fingers: [f32; 3], id: i64) -> Vec<u8> {
    // repr(C): width@0, pad, force@8, closed@16, pad, fingers@20, id@32, size 40
    let mut b = vec![0u8; 40];
    b[0..4].copy_from_slice(&width.to_le_bytes());
    b[8..16].copy_from_slice(&force.to_le_bytes());
    b[16] = closed;
    for (i, x) in fingers.iter().enumerate() {
        b[20 + 4 * i..24 + 4 * i].copy_from_slice(&x.to_le_bytes());
    }
    b[32..40].copy_from_slice(&id.to_le_bytes());
    b
}

#[test]
fn layouts_are_repr_c() {
    let s = gripper();
    assert_eq!((s.size, s.align), (40, 8));
    let at = |p: &str| s.field(p).map(|(o, _)| o);
    assert_eq!(
        (at("width_m"), at("force_n"), at("closed"), at("fingers"), at("id")),
        (Some(0), Some(8), Some(16), Some(20), Some(32))
    );
    let e = struct_layout("x::Y", &[("a".into(), "float".into())], &BTreeMap::new()).expect_err("bad type");
    assert!(e.contains("field \"a\"") && e.contains("u8, u16"), "{e}");
    // a built-in payload as a field type, and a declared one
    let mut known = BTreeMap::new();
    known.insert("lab::Gripper".to_owned(), s.clone());
    let two =
        struct_layout("lab::Two", &[("l".into(), "lab::Gripper".into()), ("r".into(), "lab::Gripper".into())], &known)
            .expect("nested");
    assert_eq!(two.field("r.id").map(|(o, _)| o), Some(72));
    // explicit padding takes its bytes but stays out of the schema, as a
    // #[derive(Payload)]'s `_pad` fields do; implicit padding is refused
    assert!(s.field("_pad0").is_none() && s.field("_pad1").is_none());
    let f = |n: &str, t: &str| (n.to_owned(), t.to_owned());
    let e = struct_layout("lab::G", &[f("width_m", "f32"), f("force_n", "f64")], &BTreeMap::new()).expect_err("gap");
    assert!(e.starts_with("4 bytes of implicit padding at offset 4, before field \"force_n\" (at 8)"), "{e}");
    assert!(e.contains("[\"_pad4\", \"[u8; 4]\"]"), "{e}");
}

#[test]
fn a_mapped_type_is_written_as_the_ros_message() {
    let fields = [("x".to_owned(), "width_m".to_owned()), ("z".to_owned(), "id".to_owned())];
    let m = UserMap::new(gripper(), "geometry_msgs/msg/Vector3", Some(&fields)).expect("valid");
    let cdr = m.encode(&sample(0.25, 3.0, 1, [0.0; 3], -7), Time { sec: 0, nanosec: 0 }, "f").expect("encodes");
    let mut r = Reader::new(&cdr).expect("header");
    assert_eq!((r.f64(), r.f64(), r.f64()), (Ok(0.25), Ok(0.0), Ok(-7.0)));
    r.finish().expect("nothing left");
}

#[test]
fn a_header_gets_the_stamp_and_frame_and_arrays_their_values() {
    // sensor_msgs/Range: header, uint8 radiation_type, float32 field_of_view,
    // min_range, max_range, range (and LaserScan's float32[] ranges below)
    let fields = [
        ("radiation_type".to_owned(), "closed".to_owned()),
        ("range".to_owned(), "width_m".to_owned()),
        ("max_range".to_owned(), "force_n".to_owned()),
    ];
    let m = UserMap::new(gripper(), "sensor_msgs/msg/Range", Some(&fields)).expect("valid");
    let cdr = m.encode(&sample(1.5, 5.0, 1, [0.0; 3], 0), Time { sec: 12, nanosec: 34 }, "grip").expect("encodes");
    let mut r = Reader::new(&cdr).expect("header");
    assert_eq!((r.i32(), r.u32(), r.string()), (Ok(12), Ok(34), Ok("grip")));
    assert_eq!(r.u8(), Ok(1));
    assert_eq!((r.f32(), r.f32(), r.f32(), r.f32()), (Ok(0.0), Ok(0.0), Ok(5.0), Ok(1.5)));
    // float32 max_range takes an f64: a float goes into any float
    let fields = [("ranges".to_owned(), "fingers".to_owned()), ("header.frame_id".to_owned(), "fingers".to_owned())];
    let e = UserMap::new(gripper(), "sensor_msgs/msg/LaserScan", Some(&fields)).expect_err("string from floats");
    assert_eq!(e.key.as_deref(), Some("header.frame_id"));
    let fields = [("ranges".to_owned(), "fingers".to_owned())];
    let m = UserMap::new(gripper(), "sensor_msgs/msg/LaserScan", Some(&fields)).expect("valid");
    let cdr = m.encode(&sample(0.0, 0.0, 0, [1.0, 2.0, 3.0], 0), Time { sec: 1, nanosec: 2 }, "s").expect("encodes");
    let mut r = Reader::new(&cdr).expect("header");
    assert_eq!((r.i32(), r.u32(), r.string()), (Ok(1), Ok(2), Ok("s")));
    for _ in 0..7 {
        assert_eq!(r.f32(), Ok(0.0));
    }
    assert_eq!(r.f32_seq(), Ok(vec![1.0, 2.0, 3.0]));
    assert_eq!(r.f32_seq(), Ok(vec![]), "intensities: not mapped, empty");
    r.finish().expect("nothing left");
}

#[test]
fn a_field_without_counterpart_or_of_another_type_is_named() {
    let e = |fields: &[(&str, &str)], ros: &str| {
        let f: Vec<(String, String)> = fields.iter().map(|(a, b)| ((*a).to_owned(), (*b).to_owned())).collect();
        UserMap::new(gripper(), ros, Some(&f)).expect_err("refused")
    };
    let x = e(&[("w", "width_m")], "geometry_msgs/msg/Vector3");
    assert_eq!(x.key.as_deref(), Some("w"));
    assert!(x.what.contains("has no field \"w\"") && x.what.contains("x (float64)"), "{}", x.what);
    let x = e(&[("x", "width")], "geometry_msgs/msg/Vector3");
    assert!(x.what.contains("lab::Gripper has no field \"width\"") && x.what.contains("width_m (f32)"), "{}", x.what);
    let x = e(&[("data", "width_m")], "std_msgs/msg/Int32");
    assert!(x.what.contains("data (int32) cannot take lab::Gripper field width_m (f32)"), "{}", x.what);
    assert!(x.what.contains("a float does not go into a ROS integer"), "{}", x.what);
    let x = e(&[("data", "id")], "std_msgs/msg/Int32");
    assert!(x.what.contains("not every value"), "{}", x.what);
    let ok = [("data".to_owned(), "closed".to_owned())];
    assert!(UserMap::new(gripper(), "std_msgs/msg/Bool", Some(&ok)).is_ok(), "a u8 goes into a bool");
    let x = e(&[("x", "fingers")], "geometry_msgs/msg/Vector3");
    assert!(x.what.contains("one value takes one number"), "{}", x.what);
    let x = e(&[("covariance", "fingers")], "geometry_msgs/msg/PoseWithCovariance");
    assert!(x.what.contains("3 values for 36 places"), "{}", x.what);
    let x = e(&[("x", "width_m")], "geometry_msgs/msg/Accel");
    assert!(x.key.is_none() && x.what.contains("not a vendored ROS message"), "{}", x.what);
    // by name: a nerve field with no ROS field of its name
    let x = UserMap::new(gripper(), "geometry_msgs/msg/Vector3", None).expect_err("no counterpart");
    assert_eq!(x.key.as_deref(), Some("width_m"));
    assert!(
        x.what.contains("lab::Gripper field \"width_m\" has no counterpart in geometry_msgs/msg/Vector3"),
        "{}",
        x.what
    );
}

#[test]
fn by_name_when_the_fields_match() {
    let f = |n: &str, t: &str| (n.to_owned(), t.to_owned());
    let s = struct_layout("lab::V", &[f("x", "f32"), f("y", "f32"), f("z", "i32")], &BTreeMap::new()).expect("layout");
    let m = UserMap::new(s, "geometry_msgs/msg/Vector3", None).expect("by name");
    let mut b = Vec::new();
    for v in [1.5f32.to_le_bytes(), (-2.0f32).to_le_bytes(), 9i32.to_le_bytes()] {
        b.extend_from_slice(&v);
    }
    let cdr = m.encode(&b, Time { sec: 0, nanosec: 0 }, "").expect("encodes");
    let mut r = Reader::new(&cdr).expect("header");
    assert_eq!((r.f64(), r.f64(), r.f64()), (Ok(1.5), Ok(-2.0), Ok(9.0)));
    assert!(matches!(m.encode(&b[..8], Time { sec: 0, nanosec: 0 }, ""), Err(CdrError::Short { need: 12, have: 8 })));
}
