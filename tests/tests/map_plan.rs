//! The map builder's map and its `plan` service, end to end (issue 42: "use
//! them where the robot wants them"): a real map builder under a router,
//! fed poses by `nerve pub` as the odometry agent would send them — the
//! robot drives an L, 3 m east, then 2.5 m north — publishes the cells it
//! has been in (`nerve echo map-builder/map`), and `nerve call
//! map-builder/plan` answers with a path back round the corner over those
//! cells, or with no way points and why.

use nerve_tests::{Robot, wait_until};
use serde_json::{Value, json};
use std::process::{Child, Stdio};
use std::time::Duration;

/// The cells' side, metres (the map builder's default `cell_m`).
const CELL_M: f64 = 0.5;

/// A pose on the map builder's `pose` input (`stamp_ns` left out: `nerve
/// pub` stamps it with the send time).
fn pose(x: f64, y: f64) -> String {
    json!({"x": x, "y": y, "theta": 0.0, "v": 0.0, "omega": 0.0, "corrections": 0, "source": 1,
           "last_checkpoint": 0, "reserved": [0, 0]})
    .to_string()
}

/// A `nerve pub` running in the background, interrupted (as by Ctrl-C, so
/// it detaches cleanly) and reaped when dropped, also when the test fails.
struct Publisher(Child);

impl Drop for Publisher {
    fn drop(&mut self) {
        let pid = nix::unistd::Pid::from_raw(self.0.id() as i32);
        let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT);
        for _ in 0..50 {
            if matches!(self.0.try_wait(), Ok(Some(_))) {
                return;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Whether `(x, y)` lies on the L the robot drove (its cells: row 0 from
/// x = 0 to 3.5, and column 6 from y = 0 to 3).
fn on_the_l(x: f64, y: f64) -> bool {
    let row = (0.0..3.5).contains(&x) && (0.0..CELL_M).contains(&y);
    let column = (3.0..3.5).contains(&x) && (0.0..3.0).contains(&y);
    row || column
}

#[test]
fn the_map_shows_where_the_robot_drove_and_plan_finds_the_way_back_over_it() {
    let r = Robot::new("mapplan");
    r.router();
    r.ok(&["start", "map-builder", "--name", "map-builder", "--param", "map_every=1"]);
    // the L, a pose in the middle of each cell: 7 cells east, 5 north
    let mut way: Vec<(f64, f64)> = (0..7).map(|i| (0.25 + CELL_M * f64::from(i), 0.25)).collect();
    way.extend((1..6).map(|j| (3.25, 0.25 + CELL_M * f64::from(j))));
    for (x, y) in &way {
        r.ok(&["pub", "map-builder/pose", &pose(*x, *y), "--count", "1"]);
    }
    // the robot stays at the L's end, its pose kept fresh (the planner
    // takes poses of at most 1 s) at 20 Hz for at most 60 s
    let _stay = Publisher(
        r.command("nerve")
            .args(["pub", "map-builder/pose", &pose(3.25, 2.75), "--rate", "20", "--count", "1200"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("nerve pub"),
    );

    // the map: the 12 cells, their bounds, the robot in the last one
    let mut map = Value::Null;
    assert!(
        wait_until(Duration::from_secs(15), || {
            map = r.echo("map-builder/map", 1).pop().map_or(Value::Null, |s| s["data"].clone());
            map["header"]["count"] == 12
        }),
        "the map never held the 12 cells driven through: {map}"
    );
    let h = &map["header"];
    assert_eq!(h["cell_m"].as_f64(), Some(CELL_M), "{h}");
    let bounds = [&h["min_ix"], &h["min_iy"], &h["max_ix"], &h["max_iy"]].map(|v| v.as_i64());
    assert_eq!(bounds, [Some(0), Some(0), Some(6), Some(5)], "{h}");
    let cells = map["items"].as_array().expect("items");
    assert_eq!(cells.len(), 12, "{map}");
    for c in cells {
        let (x, y) = (c["x"].as_f64().expect("x"), c["y"].as_f64().expect("y"));
        assert!(on_the_l(x, y) && c["visits"].as_u64() >= Some(1), "a cell off the way driven: {c}");
    }
    let here: Vec<&Value> = cells.iter().filter(|c| c["flags"].as_u64().is_some_and(|f| f & 2 != 0)).collect();
    assert_eq!(here.len(), 1, "{map}");
    assert_eq!((here[0]["ix"].as_i64(), here[0]["iy"].as_i64()), (Some(6), Some(5)));

    // back to the start: round the corner, never across the space not seen
    let out = r.ok(&["call", "map-builder/plan", r#"{"x": 0.3, "y": 0.2}"#]);
    let path: Value = serde_json::from_str(&out).expect("the answer as JSON");
    let h = &path["header"];
    assert_eq!(h["status"].as_u64(), Some(1), "found: {out}");
    let pts: Vec<(f64, f64)> = path["items"]
        .as_array()
        .expect("items")
        .iter()
        .map(|p| (p["x"].as_f64().expect("x"), p["y"].as_f64().expect("y")))
        .collect();
    assert!(pts.len() >= 3, "a corner between the ends: {out}");
    assert_eq!(pts.first(), Some(&(3.25, 2.75)), "from the robot: {out}");
    assert_eq!(pts.last(), Some(&(0.3, 0.2)), "to the goal: {out}");
    for leg in pts.windows(2) {
        for k in 0..=20 {
            let t = f64::from(k) / 20.0;
            let (x, y) = (leg[0].0 + t * (leg[1].0 - leg[0].0), leg[0].1 + t * (leg[1].1 - leg[0].1));
            assert!(on_the_l(x, y), "the leg {leg:?} leaves the cells driven at ({x:.2}, {y:.2}): {out}");
        }
    }
    let length = h["length_m"].as_f64().expect("length_m");
    assert!((5.0..6.0).contains(&length), "about 2.5 m south and 2.95 m west: {out}");
    assert_eq!(h["cells"].as_u64(), Some(11), "5 south, 6 west, the corner cut by one diagonal step: {out}");

    // a goal nowhere near the cells seen: no way points, and why
    let out = r.ok(&["call", "map-builder/plan", r#"{"x": 20.0, "y": 20.0}"#]);
    let none: Value = serde_json::from_str(&out).expect("the answer as JSON");
    assert_eq!(none["header"]["status"].as_u64(), Some(4), "goal-unseen: {out}");
    assert_eq!(none["items"].as_array().map(Vec::len), Some(0), "{out}");
    assert!(r.figure_u64("map-builder", "plans") >= 2, "{:?}", r.figures("map-builder"));
    drop(_stay);
    r.down_and_check_clean();
}
