//! End-to-end runs of `nerve demo cooperate` (the thesis' second experiment,
//! section 4.3): two robots, two routers, two bridges over loopback, the
//! real-time simulator serving both robots' boards, every agent a process.
//!
//! One run with the checkpoint corrections, during which each robot's bridge
//! is killed once (its supervisor restarts it; reliable messages arrive
//! after the restart), and beside it the same run without corrections, by
//! two other robots: robot 2 must reach the target within 0.5 m with no
//! collision in the first, and be farther from where it believes it is at
//! the via points in the second. Each run takes about two and a half
//! minutes of simulated time, on simulated time at four times real time
//! (`--sim-time --time-scale 4`, issue 46: the simulator owns both robots'
//! clock; the same assertions as in real time). The two run at the same
//! time (their own robots, simulators and bridge ports), which halves the
//! test's share of CI's serial `demo-runs` group (`.config/nextest.toml`).
//! Seeds 2 and 3 run likewise side by side in a second test (issue 46:
//! the same outcomes at 4x for seeds 1 to 3).

use nerve_tests::{Robot, free_port, sigkill, wait_until};
use serde_json::Value;
use std::io::{BufRead as _, BufReader};
use std::path::Path;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

/// How many times as fast as real time the runs go.
const SCALE: f64 = 4.0;

/// The demo as a child process, killed (with its robots brought down by the
/// robots' guards) if the test fails.
struct Demo(Child);

impl Drop for Demo {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
        }
        let _ = self.0.wait();
    }
}

/// Starts `nerve demo cooperate` for robots `r1` and `r2`; its stdout lines
/// are printed (tagged with robot 1's name, as two runs print at once) and
/// sent to the returned receiver.
fn start(r1: &Robot, r2: &Robot, out: &Path, extra: &[&str]) -> (Demo, std::sync::mpsc::Receiver<String>) {
    start_seed(r1, r2, out, 1, extra)
}

/// [`start`] with the simulator's seed `seed`.
fn start_seed(
    r1: &Robot,
    r2: &Robot,
    out: &Path,
    seed: u32,
    extra: &[&str],
) -> (Demo, std::sync::mpsc::Receiver<String>) {
    let port = free_port().to_string();
    let robots = format!("{},{}", r1.name, r2.name);
    let seed = seed.to_string();
    let mut cmd = r1.command("nerve");
    cmd.args(["demo", "cooperate", "--seed", &seed, "--robots", &robots, "--port", &port, "--out"])
        .arg(out)
        .args(["--sim-time", "--time-scale", &SCALE.to_string()])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    let mut child = cmd.spawn().expect("start nerve demo cooperate");
    let stdout = child.stdout.take().expect("stdout");
    let (tx, rx) = std::sync::mpsc::channel();
    let tag = r1.name.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            println!("[{tag}] {line}");
            // keep reading after the test stops listening: the pipe must not fill
            let _ = tx.send(line);
        }
    });
    (Demo(child), rx)
}

/// Waits for the demo to end (at most `limit`) and returns its summary.
fn finish(mut demo: Demo, out: &Path, limit: Duration) -> Value {
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = demo.0.try_wait().expect("wait for the demo") {
            break s;
        }
        assert!(t0.elapsed() < limit, "nerve demo cooperate did not end within {limit:?}");
        std::thread::sleep(Duration::from_millis(200));
    };
    assert!(status.success(), "nerve demo cooperate failed: {status}");
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

fn distance(s: &Value) -> f64 {
    s["final_distance_to_target_m"].as_f64().unwrap_or_else(|| panic!("no final distance: {s:#}"))
}

/// The largest of robot 2's pose errors `field` at the via points, m.
fn worst_error(s: &Value, field: &str) -> f64 {
    let via = s["via_points"].as_array().unwrap_or_else(|| panic!("no via points: {s:#}"));
    via.iter().filter_map(|v| v[field].as_f64()).fold(f64::NAN, f64::max)
}

#[test]
fn demo_cooperate_robot_2_reaches_the_target_through_bridge_restarts_and_misses_without_checkpoints() {
    let r1 = Robot::new("coa");
    let r2 = r1.sibling("cob");
    let out = r1.home.join("run");
    // the run without corrections, by robots of its own, beside the other
    let n1 = Robot::new("coc");
    let n2 = n1.sibling("cod");
    let out_n = n1.home.join("run-no-checkpoints");
    let (demo_n, lines_n) = start(&n1, &n2, &out_n, &["--no-checkpoints"]);
    drop(lines_n);
    // ---- with corrections; each bridge killed once on the way ----
    let (demo, lines) = start(&r1, &r2, &out, &[]);
    let t0 = Instant::now();
    // robot 2 follows the path: kill its bridge (the path and "come" are in,
    // its reports must still cross later)
    let following = |l: &String| l.contains("robot 2") && l.contains("following");
    assert!(
        lines.iter().take_while(|_| t0.elapsed() < Duration::from_secs(240)).any(|l| following(&l)),
        "robot 2 never started to follow the path"
    );
    let b2 = r2.pid("bridge");
    sigkill(b2);
    assert!(
        wait_until(Duration::from_secs(30), || r2
            .agent("bridge")
            .is_some_and(|a| a["pid"].as_u64().is_some_and(|p| p != 0 && p != u64::from(b2)))),
        "robot 2's bridge was not restarted"
    );
    // a little later (10 s of simulated time), robot 1's (robot 2's reports come in through it)
    std::thread::sleep(Duration::from_secs_f64(10.0 / SCALE));
    let b1 = r1.pid("bridge");
    sigkill(b1);
    assert!(
        wait_until(Duration::from_secs(30), || r1
            .agent("bridge")
            .is_some_and(|a| a["pid"].as_u64().is_some_and(|p| p != 0 && p != u64::from(b1)))),
        "robot 1's bridge was not restarted"
    );
    drop(lines);
    let with = finish(demo, &out, Duration::from_secs(480));
    assert_eq!(with["time_scale"].as_f64(), Some(SCALE), "{with:#}");
    assert_eq!(with["target_found"], true, "{with:#}");
    assert_eq!(with["path_sent"], true, "{with:#}");
    assert_eq!(with["end_reason"], "robot 2 arrived and robot 1 resumed", "{with:#}");
    assert!(distance(&with) <= 0.5, "robot 2 ended {} m from the target: {with:#}", distance(&with));
    assert_eq!(with["robot2_reached_target"], true);
    for (robot, n) in with["collisions"].as_object().expect("collisions per robot") {
        assert_eq!(n.as_u64(), Some(0), "robot {robot} collided: {with:#}");
    }
    let corrections = with["corrections"][&r2.name].as_u64().expect("robot 2's corrections");
    assert!(corrections >= 3, "robot 2 was corrected at the checkpoints: {with:#}");
    assert!(with["via_points"].as_array().is_some_and(|v| v.len() >= 5), "{with:#}");
    // the path came from robot 1's `plan` call: it starts at the seen cell
    // robot 2's start snaps to, a way point (the map builder's own path, the
    // fallback, starts at checkpoint 1's via point)
    assert_eq!(with["planned_path"][0]["kind"], "waypoint", "{with:#}");
    // in the same run, the raw dead reckoning (uncorrected) drifts away from
    // the recorded pose's error
    let (recorded, raw) =
        (worst_error(&with, "error_with_corrections_m"), worst_error(&with, "error_without_corrections_m"));
    assert!(
        raw > recorded,
        "the corrections kept robot 2's pose closer to the truth: worst {recorded:.2} m, raw {raw:.2} m"
    );
    for b in ["messages_out", "bytes_out"] {
        for r in [&r1.name, &r2.name] {
            assert!(with["bridge"][b][r].as_u64().is_some_and(|n| n > 0), "{b} of {r}: {with:#}");
        }
    }
    for f in ["trajectories.png", "trajectories.svg", "estimates.csv", "truth-r1.csv", "truth-r2.csv"] {
        let len = std::fs::metadata(out.join(f)).map(|m| m.len()).unwrap_or(0);
        assert!(len > 1000, "{f} is missing or empty");
    }

    // ---- the same run without corrections, which ran beside it ----
    let without = finish(demo_n, &out_n, Duration::from_secs(480));
    // nothing left behind by either run
    for r in [&r1, &r2, &n1, &n2] {
        assert!(r.shm_files().is_empty(), "left in /dev/shm by robot {}: {:?}", r.name, r.shm_files());
    }
    assert_eq!(without["checkpoints"], false);
    assert_eq!(without["corrections"][&n2.name], 0, "{without:#}");
    // What the corrections remove is robot 2's localisation error; without
    // them it is lost on the way. Whether it then also misses the target
    // varies: usually it scrapes the south wall short of the opening and ends
    // 2-3 m off, but once (CI, 2026-11-24) it slid through the opening and its
    // own camera's sighting of the target brought it within 0.37 m.
    let (lost_with, lost_without) =
        (worst_error(&with, "error_with_corrections_m"), worst_error(&without, "error_with_corrections_m"));
    assert!(
        lost_without > lost_with,
        "without corrections robot 2's pose at the via points is farther from the truth: worst {lost_without:.2} m, with them {lost_with:.2} m"
    );
    eprintln!(
        "robot 2 ended {:.2} m from the target with corrections, {:.2} m without; worst pose error at a via point {lost_with:.2} m with, {lost_without:.2} m without",
        distance(&with),
        distance(&without)
    );
}

/// Seeds 2 and 3 on simulated time at 4x (issue 46: both demos reach the
/// same outcomes at 4x as in real time, seeds 1 to 3; seed 1 is the run
/// above): the two runs side by side, each robot 2 within 0.5 m of the
/// target with no collision, nothing left behind.
#[test]
fn demo_cooperate_seeds_2_and_3_reach_the_target_at_4x() {
    let runs: Vec<(u32, Robot, Robot)> = [2, 3]
        .into_iter()
        .map(|seed| {
            let r1 = Robot::new(&format!("cs{seed}a"));
            let r2 = r1.sibling(&format!("cs{seed}b"));
            (seed, r1, r2)
        })
        .collect();
    let demos: Vec<_> = runs
        .iter()
        .map(|(seed, r1, r2)| {
            let out = r1.home.join("run");
            let (demo, lines) = start_seed(r1, r2, &out, *seed, &[]);
            drop(lines);
            (demo, out)
        })
        .collect();
    for ((demo, out), (seed, r1, r2)) in demos.into_iter().zip(&runs) {
        let s = finish(demo, &out, Duration::from_secs(480));
        assert_eq!(s["time_scale"].as_f64(), Some(SCALE), "seed {seed}: {s:#}");
        assert_eq!(s["end_reason"], "robot 2 arrived and robot 1 resumed", "seed {seed}: {s:#}");
        assert!(distance(&s) <= 0.5, "seed {seed}: robot 2 ended {} m from the target: {s:#}", distance(&s));
        assert_eq!(s["planned_path"][0]["kind"], "waypoint", "seed {seed}: the path came from `plan`: {s:#}");
        for (robot, n) in s["collisions"].as_object().expect("collisions per robot") {
            assert_eq!(n.as_u64(), Some(0), "seed {seed}: robot {robot} collided: {s:#}");
        }
        for r in [r1, r2] {
            assert!(r.shm_files().is_empty(), "left in /dev/shm by robot {}: {:?}", r.name, r.shm_files());
        }
    }
}
