//! The cooperation experiment's command sender and receiver across two
//! robots: real processes, two routers, two bridges over loopback (Zenoh,
//! explicit endpoints), and the simulator serving robot 2's motor and arm.
//!
//! Robot 1 runs the simulator (which serves robot 2's boards too), the
//! mission agent as the explorer, a scripted path (`via-path`) in place of
//! the map builder's `path` (the target found, with its approach), and a
//! real map builder whose `plan` the explorer calls for robot 2's path
//! (issue 42): its pose comes from robot 1's motor and odometry, the cells
//! behind robot 1 from `nerve pub`, as if robot 1 had come from where robot
//! 2 stands. Robot 2 runs its motor, odometry, target achiever, arm and the
//! mission agent as the executor. The test plays robot 1's decision maker:
//! its mode `wait` lets the path go out. The path goes out from robot 1's
//! mission agent, crosses the bridges, reaches robot 2's target achiever,
//! which drives robot 2 to the last point; the arm tries the grasp (the only
//! target of the world is far away: missed, out of reach); robot 2's
//! "arrived" crosses back, robot 1's mission agent answers "resume".

use nerve_tests::{Robot, free_port, wait_until, write_file};
use std::path::{Path, PathBuf};
use std::time::Duration;

fn launch(r: &Robot, file: &Path) {
    let out = r.command("nerve").arg("launch").arg(file).output().expect("run nerve launch");
    assert!(out.status.success(), "launch of {} failed: {}", r.name, String::from_utf8_lossy(&out.stderr));
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Robot 1's map builder has been in the cells from robot 2's start (-4, 0)
/// to its own (0, 0), its 0.5 m cells along y = 0 … 0.5 (`stamp_ns` 1: older than
/// every pose of the odometry, which stays the robot's pose); then the test,
/// as robot 1's decision maker, stops the robot: mode `wait`.
fn trail_then_wait(r1: &Robot) {
    for i in 0..8 {
        let x = -0.25 - 0.5 * f64::from(i);
        let pose = format!(
            r#"{{"x": {x}, "y": 0.25, "theta": 0, "v": 0, "omega": 0, "stamp_ns": 1, "corrections": 0, "source": 1, "last_checkpoint": 0, "reserved": [0, 0]}}"#
        );
        r1.ok(&["pub", "map-builder/pose", &pose]);
    }
    let cells = || r1.figure_u64("map-builder", "cells");
    assert!(
        wait_until(Duration::from_secs(10), || cells() >= 9),
        "the trail did not reach the map builder: {}",
        cells()
    );
    r1.ok(&[
        "pub",
        "mission/mode",
        r#"{"name": "wait", "index": 0, "since_ns": 0, "changes": 0, "danger_level": 255, "target": 255, "load_level": 255, "reserved": [0, 0, 0, 0, 0]}"#,
    ]);
}

/// Robot 1's explorer made robot 2's path from the map builder's `plan`.
fn path_came_from_plan(r1: &Robot) {
    assert_eq!(r1.figure("mission", "path_from"), "plan", "{:?}", r1.figures("mission"));
    assert!(r1.figure_u64("mission", "plans") >= 1, "{:?}", r1.figures("mission"));
    assert!(r1.figure_u64("map-builder", "plans") >= 1, "{:?}", r1.figures("map-builder"));
}

/// The two robots of the tests, launched: robot 1 with the simulator, a
/// scripted path (id 7), a map builder (its pose from robot 1's motor and
/// odometry) and the explorer calling its `plan`; robot 2 with motor,
/// odometry, target achiever, arm and the executor; each with its bridge.
/// Robot 1 has been where robot 2 stands and stopped ([`trail_then_wait`]).
/// Returns them with robot 2's bridge configuration.
fn two_robots(tag: &str) -> (Robot, Robot, PathBuf) {
    let (r1, r2) = (Robot::new(&format!("{tag}a")), Robot::new(&format!("{tag}b")));
    let port = free_port();
    let world = repo().join("worlds").join("cooperate.toml");
    let r2_dev = r2.home.join(&r2.name).join("dev");

    let r1_bridge = write_file(
        &r1.home,
        "bridge.toml",
        &format!(
            r#"listen = ["tcp/127.0.0.1:{port}"]
lease = "1s"
[[export]]
port = "mission/path"
type = "nerve::Seq<nerve::ViaPoint, nerve::ViaPathHeader>"
reliable = true
[[export]]
port = "mission/order"
type = "nerve::MissionCommand"
reliable = true
[[import]]
port = "{r2}/mission/report"
type = "nerve::MissionCommand"
as = "report"
"#,
            r2 = r2.name
        ),
    );
    let r2_bridge = write_file(
        &r2.home,
        "bridge.toml",
        &format!(
            r#"connect = ["tcp/127.0.0.1:{port}"]
lease = "1s"
[[export]]
port = "mission/report"
type = "nerve::MissionCommand"
reliable = true
[[import]]
port = "{r1}/mission/path"
type = "nerve::Seq<nerve::ViaPoint, nerve::ViaPathHeader>"
as = "path"
[[import]]
port = "{r1}/mission/order"
type = "nerve::MissionCommand"
as = "order"
"#,
            r1 = r1.name
        ),
    );
    // robot 2 starts at (-4, 0) facing +x: the target's approach 0.7 m
    // ahead, the "target" 1.4 m ahead (it stops 0.42 m short of it); plan's
    // way from robot 1 (0, 0) to robot 2 adds robot 2's own place before them
    let r1_launch = r1.launch_file(
        "r1.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "sim"
kind = "sim"
args = ["--world", "{world}", "--robot-model", "h1", "--seed", "1", "--dev-dir", "{{state}}/dev",
        "--extra-robot", "{r2}:h2:{r2_dev}"]
[[agent]]
name = "motor"
kind = "motor"
device = "{{state}}/dev/motor"
args = ["--robot-model", "h1"]
[[agent]]
name = "odometry"
kind = "odometry"
args = ["--start", "0,0,0"]
[[agent]]
name = "map-builder"
kind = "map-builder"
params = {{ map_every = 0 }}
[[agent]]
name = "plan"
kind = "via-path"
args = ["--points", "-3.3,0,target-approach;-2.6,0,target", "--path-id", "7"]
[[agent]]
name = "mission"
kind = "mission"
args = ["--role", "explorer"]
params = {{ wait_mode = "wait", resend_ms = 1000, peer_start = "-4,0" }}
[[agent]]
name = "bridge"
kind = "bridge"
args = ["--config", "{cfg}"]
[[connect]]
from = "motor/odom"
to = "odometry/odom"
[[connect]]
from = "odometry/pose"
to = "map-builder/pose"
[[connect]]
from = "plan/path"
to = "mission/path_in"
[[connect]]
from = "mission/planner"
to = "map-builder/plan"
[[connect]]
from = "bridge/report"
to = "mission/report"
"#,
            world = world.display(),
            r2 = r2.name,
            r2_dev = r2_dev.display(),
            cfg = r1_bridge.display()
        ),
    );
    let r2_launch = r2.launch_file(
        "r2.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "motor"
kind = "motor"
device = "{{state}}/dev/motor"
args = ["--robot-model", "h2"]
[[agent]]
name = "odometry"
kind = "odometry"
args = ["--start=-4,0,0"]
[[agent]]
name = "target"
kind = "target"
params = {{ standoff_m = 0.42 }}
[[agent]]
name = "arm"
kind = "arm"
device = "{{state}}/dev/arm"
[[agent]]
name = "mission"
kind = "mission"
args = ["--role", "executor"]
params = {{ resend_ms = 1000 }}
[[agent]]
name = "bridge"
kind = "bridge"
args = ["--config", "{cfg}"]
[[connect]]
from = "motor/odom"
to = "odometry/odom"
[[connect]]
from = "bridge/path"
to = "mission/path_in"
[[connect]]
from = "bridge/order"
to = "mission/order_in"
[[connect]]
from = "mission/path"
to = "target/path"
[[connect]]
from = "mission/order"
to = "target/mission_in"
[[connect]]
from = "odometry/pose"
to = "target/pose"
[[connect]]
from = "target/cmd"
to = "motor/cmd"
[[connect]]
from = "target/mission"
to = "mission/progress"
[[connect]]
from = "mission/grasp"
to = "arm/cmd"
[[connect]]
from = "arm/state"
to = "mission/arm"
[[connect]]
from = "odometry/pose"
to = "mission/pose"
"#,
            cfg = r2_bridge.display()
        ),
    );
    launch(&r1, &r1_launch);
    launch(&r2, &r2_launch);
    trail_then_wait(&r1);
    (r1, r2, r2_bridge)
}

/// Robot 1's path goes to robot 2's target achiever across the bridges;
/// robot 2 drives it, grasps (and misses: no target in reach), and its
/// "arrived" comes back to robot 1, which answers "resume".
#[test]
fn a_path_crosses_to_robot_2_and_its_arrival_comes_back() {
    let (r1, r2, _) = two_robots("coop");

    // robot 1 sent the path; it crossed to robot 2's mission agent, which
    // handed it to the target achiever: robot 2 follows path 7
    assert!(
        wait_until(Duration::from_secs(60), || r1.figure("mission", "phase") == "sent"),
        "robot 1 did not send the path: {:?}",
        r1.figures("mission")
    );
    assert!(
        wait_until(Duration::from_secs(60), || {
            matches!(r2.figure("mission", "phase").as_str(), "following" | "grasping" | "arrived" | "done")
        }),
        "robot 2 did not take the path: mission {:?}, bridge {:?}",
        r2.figures("mission"),
        r2.figures("bridge")
    );
    assert_eq!(r2.figure_u64("mission", "path_id"), 7);
    path_came_from_plan(&r1);
    assert!(r2.figure_u64("bridge", &format!("import.{}/mission/path.msgs_in", r1.name)) >= 1);
    let edges = r2.edges();
    assert!(edges.contains(&"mission/path -> target/path".to_owned()), "{edges:?}");

    // robot 2 drives to the end of the path, the arm tries, robot 2 reports
    // "arrived"; it crosses back and robot 1 is done
    assert!(
        wait_until(Duration::from_secs(120), || r1.figure("mission", "phase") == "done"),
        "robot 2's arrival did not reach robot 1: r1 mission {:?}, r2 mission {:?}, r2 arm {:?}",
        r1.figures("mission"),
        r2.figures("mission"),
        r2.figures("arm")
    );
    assert_eq!(r1.figure_u64("mission", "path_id"), 7);
    assert!(r1.figure_u64("bridge", &format!("import.{}/mission/report.msgs_in", r2.name)) >= 1);
    // the target achiever really drove robot 2 there: the simulator's truth
    let truth = r1.echo(&format!("sim/truth-{}", r2.name), 1);
    let x = truth[0]["data"]["x"].as_f64().expect("truth x");
    assert!(x > -3.6, "robot 2 is still near its start: {truth:?}");
    // the arm grasped at the target of the path, and missed: the world's
    // only target is 15 m away, which its probes tell
    assert_eq!(r2.figure("mission", "grasp"), "missed", "{:?}", r2.figures("mission"));
    assert_eq!(r2.figure_u64("arm", "missed"), 1, "{:?}", r2.figures("arm"));
    let arm = r2.echo("arm/state", 1);
    assert_eq!(arm[0]["data"]["reason"].as_u64(), Some(2), "out of reach expected: {arm:?}");
    // robot 1's "resume" reached robot 2: it stops repeating "arrived"
    assert!(
        wait_until(Duration::from_secs(30), || r2.figure("mission", "phase") == "done"),
        "robot 1's resume did not reach robot 2: {:?}",
        r2.figures("mission")
    );

    r2.down_and_check_clean();
    r1.down_and_check_clean();
}

/// Robot 2's bridge is stopped while robot 2 follows the path: its
/// "arrived" goes nowhere (a bridge that is not running never sees it), and
/// robot 1 keeps waiting. Once the bridge is started again, robot 2's
/// repeated report crosses, robot 1 answers, and both are done.
#[test]
fn an_arrival_reported_while_the_bridge_is_down_arrives_after_it_restarts() {
    let (r1, r2, r2_bridge) = two_robots("coup");
    assert!(
        wait_until(Duration::from_secs(60), || r2.figure("mission", "phase") == "following"),
        "robot 2 did not take the path: {:?}",
        r2.figures("mission")
    );
    r2.ok(&["stop", "bridge"]);
    assert!(
        wait_until(Duration::from_secs(120), || r2.figure("mission", "phase") == "arrived"),
        "robot 2 did not arrive: {:?}",
        r2.figures("mission")
    );
    // robot 2 repeats its report into the void; robot 1 still waits
    let sent = r2.figure_u64("mission", "sent");
    assert!(wait_until(Duration::from_secs(30), || r2.figure_u64("mission", "sent") > sent + 1));
    assert_eq!(r1.figure("mission", "phase"), "sent", "robot 1 heard of an arrival with the link down");
    // the path robot 1 repeats to robot 2 is plan's way from robot 1 to robot
    // 2 turned round: robot 2's own place (plan's goal), then the scripted
    // approach and target; the scripted path alone has no (-4, 0)
    path_came_from_plan(&r1);
    let path = r1.echo("mission/path", 1);
    let points: Vec<(f64, f64, u64)> = path[0]["data"]["items"]
        .as_array()
        .unwrap_or_else(|| panic!("no items: {path:?}"))
        .iter()
        .map(|p| {
            (p["point"][0].as_f64().expect("x"), p["point"][1].as_f64().expect("y"), p["kind"].as_u64().expect("kind"))
        })
        .collect();
    assert_eq!(points, [(-4.0, 0.0, 4), (-3.3, 0.0, 2), (-2.6, 0.0, 3)], "waypoint, target-approach, target: {path:?}");
    // the bridge back: the next repetition crosses
    let cfg = r2_bridge.display().to_string();
    r2.ok(&["start", "bridge", "--name", "bridge", "--", "--config", &cfg]);
    assert!(
        wait_until(Duration::from_secs(60), || r1.figure("mission", "phase") == "done"),
        "robot 2's repeated arrival did not reach robot 1: r1 {:?}, r2 {:?}, r2 bridge {:?}",
        r1.figures("mission"),
        r2.figures("mission"),
        r2.figures("bridge")
    );
    assert!(
        wait_until(Duration::from_secs(30), || r2.figure("mission", "phase") == "done"),
        "robot 1's resume did not reach robot 2: {:?}",
        r2.figures("mission")
    );
    r2.down_and_check_clean();
    r1.down_and_check_clean();
}

/// The experiment's launch files as shipped (launch/cooperate-r1.toml,
/// -r2.toml and their bridge configurations), with this test's robot names
/// and a free port: every agent comes up, the bridges meet, each mission
/// agent is in its first phase, and `nerve down` leaves nothing behind.
#[test]
fn the_shipped_launch_files_come_up_and_their_bridges_meet() {
    let (r1, r2) = (Robot::new("shipa"), Robot::new("shipb"));
    let port = free_port().to_string();
    let dir = r1.home.join("shipped");
    std::fs::create_dir_all(&dir).expect("launch dir");
    let r2_dev = r2.home.join(&r2.name).join("dev");
    // the bridges speak mutual TLS: the fleet's keys, as docs/cooperate.md makes them
    let keys = dir.join("keys").display().to_string();
    for args in [vec!["init"], vec!["add", r1.name.as_str()], vec!["add", r2.name.as_str()]] {
        let full: Vec<&str> = ["bridge", "keys"].into_iter().chain(args).chain(["--dir", keys.as_str()]).collect();
        let out = r1.nerve(&full);
        assert!(out.status.success(), "nerve {}: {}", full.join(" "), String::from_utf8_lossy(&out.stderr));
    }
    for f in ["cooperate-r1.toml", "cooperate-r2.toml", "cooperate-r1.zenoh.toml", "cooperate-r2.zenoh.toml"] {
        let text = std::fs::read_to_string(repo().join("launch").join(f)).expect("shipped launch file");
        // robot 2's boards go to robot 2's state directory (another NERVE_HOME here)
        let text = text
            .replace("\"coop-r2:h2\"", &format!("\"coop-r2:h2:{}\"", r2_dev.display()))
            .replace("coop-r1", &r1.name)
            .replace("coop-r2", &r2.name)
            .replace("7451", &port)
            .replace("\n[tls]\n", &format!("\n[tls]\nkeys = {keys:?}\n"));
        std::fs::write(dir.join(f), text).expect("write launch file");
    }
    // the launch files name the world and the knowledge bases from the source tree
    for (r, f) in [(&r1, "cooperate-r1.toml"), (&r2, "cooperate-r2.toml")] {
        let out = r.command("nerve").arg("launch").arg(dir.join(f)).current_dir(repo()).output().expect("nerve launch");
        assert!(out.status.success(), "launch of {f} failed: {}", String::from_utf8_lossy(&out.stderr));
    }
    assert_eq!(r1.ps().len(), 15, "robot 1's agents");
    assert_eq!(r2.ps().len(), 10, "robot 2's agents");
    assert!(
        wait_until(Duration::from_secs(30), || r2.figure_u64("bridge", "peers") == 1
            && r1.figure_u64("bridge", "peers") == 1),
        "the bridges did not meet: {:?}",
        r2.figures("bridge")
    );
    assert_eq!(r1.figure("mission", "role"), "explorer");
    assert_eq!(r2.figure("mission", "role"), "executor");
    // the phase is set by the agent's first step, up to a period (100 ms)
    // after its start; the bridges can meet before that
    assert!(
        wait_until(Duration::from_secs(5), || !r2.figure("mission", "phase").is_empty()),
        "robot 2's mission agent reported no phase: {:?}",
        r2.figures("mission")
    );
    assert_eq!(r2.figure("mission", "phase"), "waiting");
    // robot 2's decision maker holds the foot while nothing is to be done
    let mode = r2.echo("decision/mode", 1);
    assert_eq!(mode[0]["data"]["name"], "wait", "{mode:?}");
    r2.down_and_check_clean();
    r1.down_and_check_clean();
}
