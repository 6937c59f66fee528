//! The exploration demo (`nerve demo explore`, docs/demo.md).
//!
//! * the analysis on synthetic ground truth: doorway crossing, reaching the
//!   target after it settled, clearance and collisions; the time explored
//!   before the target was first tracked, from the decision maker's log;
//! * the figures are written and not empty;
//! * `nerve demo` and `nerve calibrate` run the program `nerve-demo`, and
//!   say what to build where it is missing;
//! * end to end: the whole robot against the simulator on two seeds and on
//!   the second world must explore (follow walls) for a while before it sees
//!   the person, then reach the doorway and the target without a
//!   collision, and must do so when the tracker is killed mid-run (the
//!   supervisor restarts it) and with a CPU-hungry agent added (the
//!   resource manager lengthens periods);
//! * end to end on the island world (issue 12): a robot that only followed
//!   the nearest wall would circle the island for ever; back at a place it
//!   passed, the wall follower switches sides, leaves the island, and the
//!   robot finds the door and the person.
//!
//! The end-to-end tests (`demo_*`) each run a whole robot on simulated
//! time at four times real time (`--sim-time --time-scale 4`, issue 46):
//! the same assertions as in real time, in about a quarter of the wall
//! time. Seeds 1 to 3 of `explore.toml` run so (seed 1 in the tracker
//! test), the second world and the island. The CPU-hungry agent's run
//! stays in real time: its load is CPU time, which a faster clock cannot
//! compress (at 4x the hog would need three cores), and it is the suite's
//! real-time run of the same robot. `.config/nextest.toml` runs them one
//! at a time.

use nerve_demo::analysis::{EXPLORING_MODES, ModeChange, TRACKING_MODES, first_change_into, time_in_modes_before};
use nerve_demo::{Criteria, Scene, analyse, read_truth};
use nerve_tests::{Robot, reap, wait_until};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn scene(name: &str) -> Scene {
    Scene::load(&repo().join("worlds").join(name)).expect("world loads")
}

const HEADER: &str = "t,x,y,theta,v,omega,wheel_left,wheel_right,enc_left,enc_right,collisions,in_contact,pan,tilt";

/// A synthetic truth log: the robot drives through `waypoints` at 0.3 m/s,
/// sampled at 10 Hz, pausing `(index, seconds)` at given waypoints;
/// `collide_at` sets the collision counter from that time on.
fn synthetic(dir: &Path, waypoints: &[(f64, f64)], pauses: &[(usize, f64)], collide_at: Option<f64>) -> PathBuf {
    let mut rows = vec![HEADER.to_owned()];
    let mut t = 0.0;
    let mut push = |t: f64, x: f64, y: f64, th: f64, v: f64| {
        let c = u8::from(collide_at.is_some_and(|c| t >= c));
        rows.push(format!("{t:.3},{x:.4},{y:.4},{th:.4},{v:.3},0.0,0,0,0,0,{c},{c},0,0"));
    };
    for (i, w) in waypoints.windows(2).enumerate() {
        let (a, b) = (w[0], w[1]);
        let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        let th = (b.1 - a.1).atan2(b.0 - a.0);
        if let Some((_, p)) = pauses.iter().find(|(k, _)| *k == i) {
            let n = (p * 10.0) as usize;
            for _ in 0..n {
                push(t, a.0, a.1, th, 0.0);
                t += 0.1;
            }
        }
        let n = ((len / 0.3) * 10.0).ceil().max(1.0) as usize;
        for k in 0..n {
            let f = k as f64 / n as f64;
            push(t, a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f, th, 0.3);
            t += 0.1;
        }
    }
    if let Some(last) = waypoints.last() {
        for _ in 0..30 {
            push(t, last.0, last.1, 3.1, 0.0);
            t += 0.1;
        }
    }
    std::fs::create_dir_all(dir).expect("dir");
    let p = dir.join("truth.csv");
    std::fs::write(&p, rows.join("\n") + "\n").expect("write truth");
    p
}

fn tmp(tag: &str) -> PathBuf {
    std::env::temp_dir().join(format!("nerve-demo-test-{}-{tag}", std::process::id()))
}

/// Through the room (round the shelf's north end), the doorway and the
/// corridor to where the person stops, waiting there until the person has
/// finished stepping back, then following them: doorway and target reached,
/// no collision, positive clearance.
const GOOD_RUN: &[(f64, f64)] =
    &[(1.0, 2.6), (1.6, 3.2), (4.6, 3.2), (4.8, 1.1), (6.0, 1.1), (10.0, 1.1), (12.0, 1.1), (11.4, 1.3)];

#[test]
fn analysis_of_a_good_synthetic_run() {
    let s = scene("explore.toml");
    let dir = tmp("good");
    // pause at (12.0, 2.2) (the 7th waypoint, segment 6) long enough for the person to settle (~97 s)
    let truth = synthetic(&dir, GOOD_RUN, &[(6, 70.0)], None);
    let rows = read_truth(&truth).expect("reads");
    let a = analyse(&s, &rows, Criteria::default());
    let sum = &a.summary;
    assert!(sum.reached_doorway, "{sum:?}");
    let td = sum.doorway_time_s.expect("doorway time");
    // the door is at x = 7: the crossing happens between the rows on either side
    let before = rows.iter().rfind(|r| r.t < td).expect("row before");
    let at = rows.iter().find(|r| r.t >= td).expect("row at");
    assert!(before.x < 7.0 && at.x >= 7.0, "crossing at {td}: {before:?} -> {at:?}");
    assert!(sum.reached_target, "{sum:?}");
    let tt = sum.target_time_s.expect("target time");
    let settle = s.target_settles_at().expect("the person's path ends");
    assert!(tt >= settle, "target counted at {tt} before the person settled at {settle}");
    assert_eq!(sum.collisions, 0);
    assert!(sum.min_clearance_m > 0.05 && sum.min_clearance_m < 1.0, "{}", sum.min_clearance_m);
    assert!(sum.turn_after_doorway_deg.is_some_and(|d| d > 150.0), "U-turn: {:?}", sum.turn_after_doorway_deg);
    assert_eq!(a.clearance.len(), rows.len());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn analysis_counts_collisions_clearance_and_misses() {
    let s = scene("explore.toml");
    let dir = tmp("bad");
    // stays in the room and scrapes the box on the south wall (x = 1.75 .. 2.65, y = 0 .. 0.7)
    let truth = synthetic(&dir, &[(1.0, 2.6), (1.8, 0.95), (3.0, 0.95)], &[], Some(10.0));
    let rows = read_truth(&truth).expect("reads");
    let sum = analyse(&s, &rows, Criteria::default()).summary;
    assert!(!sum.reached_doorway && !sum.reached_target, "{sum:?}");
    assert_eq!(sum.collisions, 1);
    assert!(sum.min_clearance_m.abs() < 0.02, "touching the boxes: {}", sum.min_clearance_m);
    // near the door, with a huge reach, but without going through the door
    // (e.g. a log of another world): not reached
    let truth = synthetic(&dir, &[(6.0, 1.1), (6.5, 1.1)], &[], None);
    let rows = read_truth(&truth).expect("reads");
    let sum = analyse(&s, &rows, Criteria { target_reach_m: 10.0 }).summary;
    assert!(!sum.reached_doorway && !sum.reached_target, "{sum:?}");
    // reaching the person before they stepped back is not following them
    let truth = synthetic(&dir, &GOOD_RUN[..7], &[], None);
    let rows = read_truth(&truth).expect("reads");
    let sum = analyse(&s, &rows, Criteria::default()).summary;
    assert!(sum.reached_doorway && !sum.reached_target, "{sum:?}");
    assert!(sum.min_target_distance_m.is_some_and(|d| d < 1.5), "{sum:?}");
    // backing out through the door is not reaching it
    let truth = synthetic(&dir, &[(8.0, 1.1), (6.0, 1.1)], &[], None);
    let rows = read_truth(&truth).expect("reads");
    let sum = analyse(&s, &rows, Criteria::default()).summary;
    assert!(!sum.reached_doorway, "wrong direction counts: {sum:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn second_world_doorway_is_on_another_wall() {
    let s = scene("explore-2.toml");
    let d = s.doors[0].opening;
    assert!((d.a.y - 6.5).abs() < 1e-9 && (d.b.y - 6.5).abs() < 1e-9, "door in the north wall: {d:?}");
    let dir = tmp("w2");
    // west along the south wing, north up the west wing, through the door
    let path = [(5.6, 1.6), (2.0, 1.8), (1.5, 4.0), (1.5, 7.0), (1.5, 11.7), (2.3, 10.6)];
    let truth = synthetic(&dir, &path, &[(4, 80.0)], None);
    let rows = read_truth(&truth).expect("reads");
    let sum = analyse(&s, &rows, Criteria::default()).summary;
    assert!(sum.reached_doorway && sum.reached_target && sum.collisions == 0, "{sum:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Mode changes at the given simulated times.
fn changes(v: &[(f64, &str)]) -> Vec<ModeChange> {
    let mut from: Option<String> = None;
    v.iter()
        .map(|(t, m)| {
            let c = ModeChange {
                t_s: Some(*t),
                clock: String::new(),
                mode: (*m).to_owned(),
                from: from.clone(),
                line: format!("decision/mode: {} -> {m}", from.as_deref().unwrap_or("-")),
            };
            from = Some((*m).to_owned());
            c
        })
        .collect()
}

#[test]
fn time_explored_before_the_target_is_tracked() {
    // as `nerve demo explore` records them from `decision/mode`
    let modes = changes(&[
        (1.0, "avoid"),
        (2.0, "explore"),
        (10.0, "lean"),
        (14.5, "avoid"),
        (16.0, "track"),
        (30.0, "hold"),
        (40.0, "explore"),
    ]);
    let first = first_change_into(&modes, &TRACKING_MODES).expect("tracked");
    assert!((first - 16.0).abs() < 1e-9, "{first}");
    let before = time_in_modes_before(&modes, first);
    let explored: f64 = EXPLORING_MODES.iter().filter_map(|m| before.get(*m)).sum();
    assert!((explored - 12.5).abs() < 1e-9, "{before:?}");
    assert!((before["avoid"] - 2.5).abs() < 1e-9, "{before:?}");
    assert!(!before.contains_key("track") && !before.contains_key("hold"), "{before:?}");
    // never tracked: everything counts, up to the end
    let never = &modes[..3];
    assert_eq!(first_change_into(never, &TRACKING_MODES), None);
    assert!((time_in_modes_before(never, 20.0)["lean"] - 10.0).abs() < 1e-9);
}

#[test]
fn figures_are_written_as_png_and_svg() {
    let s = scene("explore.toml");
    let dir = tmp("plots");
    let truth = synthetic(&dir, GOOD_RUN, &[(6, 70.0)], None);
    let rows = read_truth(&truth).expect("reads");
    let a = analyse(&s, &rows, Criteria::default());
    let modes = changes(&[(1.0, "explore"), (40.0, "track")]);
    let figs = nerve_demo::plot::write_all(&dir, &s, &rows, &a, &modes, "synthetic").expect("plots");
    assert_eq!(figs.files.len(), 4);
    for f in &figs.files {
        let len = std::fs::metadata(f).map(|m| m.len()).unwrap_or(0);
        assert!(len > 5_000, "{} is {len} bytes", f.display());
    }
    let png = std::fs::read(dir.join("trajectory.png")).expect("png");
    assert_eq!(&png[1..4], b"PNG");
    let svg = std::fs::read_to_string(dir.join("motion.svg")).expect("svg");
    if let Some(keep) = std::env::var_os("NERVE_DEMO_KEEP_PLOTS") {
        for f in &figs.files {
            let _ = std::fs::copy(f, Path::new(&keep).join(f.file_name().expect("file name")));
        }
    }
    assert!(svg.contains("<svg") && svg.contains("velocity"), "svg has its labels");
    let _ = std::fs::remove_dir_all(&dir);
}

// ---------------------------------------------------------------- end to end

/// How many times as fast as real time the simulated runs go.
const SCALE: f64 = 4.0;
/// The flags of a run on simulated time at [`SCALE`].
const SIM_TIME: [&str; 3] = ["--sim-time", "--time-scale", "4"];

/// `args` followed by [`SIM_TIME`].
fn at_4x<'a>(args: &[&'a str]) -> Vec<&'a str> {
    args.iter().copied().chain(SIM_TIME).collect()
}

/// Runs `nerve demo explore ARGS` for robot `r` with `launch/explore.toml`; returns the parsed summary.
fn run_demo(r: &Robot, args: &[&str], during: impl FnOnce(&Robot)) -> Value {
    run_demo_with(r, &repo().join("launch/explore.toml"), args, during)
}

/// Runs `nerve demo explore --launch LAUNCH ARGS` for robot `r`; returns the parsed summary.
fn run_demo_with(r: &Robot, launch: &Path, args: &[&str], during: impl FnOnce(&Robot)) -> Value {
    let out = r.home.join("out");
    let t0 = Instant::now();
    let child = r
        .command("nerve")
        .args(["demo", "explore", "--out"])
        .arg(&out)
        .arg("--launch")
        .arg(launch)
        // The demo's default limit is 140 s of simulated time. A run that
        // loops round the shelf before it finds the doorway took 120 s (one
        // in ten); the tests give such runs room rather than fail them,
        // and still hold the whole run to the issue's 3 minutes of wall time.
        .args(["--time-limit", "160"])
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start nerve demo");
    during(r);
    let res = child.wait_with_output().expect("nerve demo");
    let stdout = String::from_utf8_lossy(&res.stdout);
    let stderr = String::from_utf8_lossy(&res.stderr);
    assert!(res.status.success(), "nerve demo failed:\n{stdout}\n{stderr}");
    let wall = t0.elapsed();
    assert!(wall < Duration::from_secs(180), "took {wall:?}:\n{stdout}");
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    let s: Value = serde_json::from_str(&text).expect("summary is JSON");
    // the figures of the run, for the test's output (`--success-output final`)
    println!(
        "explored {:.1} s, first track {}, doorway {}, target {}, collisions {}, min clearance {} at {}, {} s simulated, {:.0} s wall",
        explored_before_tracking(&s),
        s["first_track_s"],
        s["doorway_time_s"],
        s["target_time_s"],
        s["collisions"],
        s["min_clearance_m"],
        s["min_clearance_at_s"],
        s["duration_s"],
        wall.as_secs_f64()
    );
    for f in ["trajectory.png", "trajectory.svg", "motion.png", "motion.svg", "truth.csv", "log.csv", "launch.toml"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // the run's clock, as the summary records it
    if args.contains(&"--sim-time") {
        assert_eq!(s["time_scale"].as_f64(), Some(SCALE), "{s:#}");
        let sim_log = std::fs::read_to_string(out.join("logs/sim.log")).unwrap_or_default();
        assert!(sim_log.contains("the simulator owns the robot's clock"), "the simulator's log:\n{sim_log}");
        // a busy machine holds the simulator's clock: the resource manager
        // does not judge the machine's CPU (agents/resource, docs/time.md)
        let rm_log = std::fs::read_to_string(out.join("logs/resource.log")).unwrap_or_default();
        assert!(rm_log.contains("the machine's CPU is not judged"), "the resource manager's log:\n{rm_log}");
    } else {
        assert!(s["time_scale"].is_null(), "{s:#}");
    }
    // nothing is left behind
    reap();
    assert!(r.shm_files().is_empty(), "left in /dev/shm: {:?}", r.shm_files());
    s
}

fn world(name: &str) -> String {
    repo().join("worlds").join(name).display().to_string()
}

/// Seconds the decision maker spent in the wall-following modes (`explore`,
/// `lean`) before it first tracked the target.
fn explored_before_tracking(s: &Value) -> f64 {
    EXPLORING_MODES.iter().filter_map(|m| s["time_in_mode_before_track_s"][*m].as_f64()).sum()
}

/// The run was a success: the robot explored the room before it saw the
/// person (in both worlds the person is out of sight from the start), went
/// through the doorway and followed the person, touching nothing.
fn assert_success(s: &Value) {
    assert!(s["first_track_s"].as_f64().is_some(), "the target was never tracked: {s:#}");
    let explored = explored_before_tracking(s);
    assert!(explored >= 5.0, "explored only {explored:.1} s before tracking the target: {s:#}");
    assert_eq!(s["reached_doorway"], true, "{s:#}");
    assert_eq!(s["reached_target"], true, "{s:#}");
    assert_eq!(s["collisions"], 0, "{s:#}");
    assert!(s["mode_changes"].as_array().is_some_and(|m| !m.is_empty()), "{s:#}");
    assert!(s["cpu"].as_object().is_some_and(|c| c.contains_key("tracker")), "{s:#}");
}

/// A copy of `launch/explore.toml` in `r`'s home (as `name`), with `extra`
/// appended and its knowledge base named by its absolute path (the copy
/// lives outside the source tree).
fn launch_copy(r: &Robot, name: &str, extra: &str) -> PathBuf {
    let template = std::fs::read_to_string(repo().join("launch/explore.toml")).expect("launch/explore.toml");
    assert!(template.contains("\"kb/explore.toml\""), "the launch file names its knowledge base");
    let kb = repo().join("kb/explore.toml").display().to_string();
    r.launch_file(name, &(template.replace("\"kb/explore.toml\"", &format!("{kb:?}")) + extra))
}

/// Removes the robot's home (the run's output) once a test has passed; a
/// failed test leaves it for reading. With `NERVE_DEMO_KEEP_RUNS=DIR` the
/// run's summary and figures are copied to `DIR/<robot>/` first.
fn clean_up(r: &Robot) {
    if let Some(keep) = std::env::var_os("NERVE_DEMO_KEEP_RUNS") {
        let to = Path::new(&keep).join(&r.name);
        if std::fs::create_dir_all(&to).is_ok() {
            for f in ["summary.json", "trajectory.png", "motion.png"] {
                let _ = std::fs::copy(r.home.join("out").join(f), to.join(f));
            }
        }
    }
    let _ = std::fs::remove_dir_all(&r.home);
}

/// `nerve demo` and `nerve calibrate` run the program `nerve-demo`: their
/// help is its help, and a `nerve` without `nerve-demo` beside it (or on
/// `PATH`) says what to build instead of failing obscurely (issue 41 part 4).
#[test]
fn nerve_demo_runs_for_demo_and_calibrate_or_says_what_to_build() {
    let r = Robot::new("nodemo");
    let help = r.nerve(&["demo", "--help"]);
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(help.status.success() && text.contains("explore") && text.contains("cooperate"), "{text}");
    let help = r.nerve(&["calibrate", "checkpoint", "--help"]);
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(help.status.success() && text.contains("--samples") && text.contains("nerve calibrate"), "{text}");

    // a `nerve` alone in a folder, with a PATH that has no nerve-demo
    let alone = r.home.join("alone");
    std::fs::create_dir_all(&alone).expect("a folder for nerve alone");
    std::fs::copy(nerve_tests::bin_dir().join("nerve"), alone.join("nerve")).expect("copy nerve");
    for args in [&["demo", "explore"][..], &["calibrate", "checkpoint", "--samples", "s.csv"]] {
        let out = std::process::Command::new(alone.join("nerve"))
            .args(args)
            .env("PATH", "/usr/bin:/bin")
            .env("NERVE_ROBOT", &r.name)
            .env("NERVE_HOME", &r.home)
            .output()
            .expect("run nerve");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(
            err.contains("nerve-demo is not installed") && err.contains("cargo build --release -p nerve-demo"),
            "{args:?}: {err}"
        );
    }
}

/// On simulated time a device agent whose device is real hardware is
/// refused with what to do, and so is an agent given a clock that is no
/// clock (issue 46); the simulator's kind of device (a link that appears
/// when the simulator starts) is accepted. No simulator needed.
#[test]
fn sim_time_refuses_a_real_device_and_a_broken_clock() {
    let r = Robot::new("simref");
    let page = r.home.join(agent_sdk::simclock::PAGE_FILE);
    agent_sdk::simclock::create(&page, SCALE).expect("a clock page");
    let start = |clock: &Path, kind: &str, args: &[&str]| {
        let out = r
            .command("nerve")
            .args(["start", kind, "--name", kind, "--"])
            .args(args)
            .env(agent_sdk::simclock::SIM_CLOCK_ENV, clock)
            .stdin(std::process::Stdio::null())
            .output()
            .expect("nerve start");
        let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        (out.status.success(), text)
    };
    let (ok, text) = start(&page, "sonar", &["--device", "/dev/null"]);
    assert!(!ok, "a real device was accepted on simulated time:\n{text}");
    assert!(text.contains("real hardware") && text.contains("without --sim-time"), "{text}");
    let junk = r.home.join("junk");
    std::fs::write(&junk, "not a clock").expect("write");
    let (ok, text) = start(&junk, "testagent", &[]);
    assert!(!ok, "a broken clock was accepted:\n{text}");
    assert!(text.contains("not a simulated clock") && text.contains("--sim-time"), "{text}");
    let sim_link = r.home.join("dev").join("sonar").display().to_string();
    let (ok, text) = start(&page, "sonar", &["--device", sim_link.as_str()]);
    assert!(ok, "the simulator's device was refused:\n{text}");
}

/// `nerve launch --sim-time --time-scale 4`: the robot's clock page is
/// made, every agent says it runs on it, and a robot already running on
/// its own clock is not switched under its agents.
#[test]
fn sim_time_launch_puts_the_agents_on_the_clock() {
    let r = Robot::new("simla");
    let file =
        r.launch_file("ticker.toml", "robot = \"x\"\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nperiod = \"10ms\"\n");
    let file = file.display().to_string();
    let out = r.nerve(&["launch", "--sim-time", "--time-scale", "4", file.as_str()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "nerve launch --sim-time failed:\n{err}");
    assert!(err.contains("runs on simulated time at 4x"), "{err}");
    assert!(r.home.join(&r.name).join(agent_sdk::simclock::PAGE_FILE).exists(), "no clock page");
    let log_file = r.home.join(&r.name).join("logs/t1.log");
    let said = wait_until(Duration::from_secs(10), || {
        std::fs::read_to_string(&log_file).is_ok_and(|l| l.contains("on simulated time") && l.contains("scale=4"))
    });
    assert!(
        said,
        "the ticker's log does not say it runs on simulated time:\n{}",
        std::fs::read_to_string(&log_file).unwrap_or_default()
    );
    let again = r.nerve(&["launch", "--sim-time", file.as_str()]);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(!again.status.success() && err.contains("already runs") && err.contains("down"), "{err}");
}

/// Seeds 2 and 3 of `explore.toml` and seed 3 of the second world, the
/// three robots side by side at 4x (as the cooperation test runs its
/// seeds): about 31 s of wall time for the three instead of 30 s each
/// (session 37, load 3-4). The simulator holds each robot's clock when the
/// machine is too busy for it, so a run beside others is longer, not
/// different — and on simulated time the resource manager does not judge
/// the machine's CPU, which the three of them fill (as the island's run).
#[test]
fn demo_explore_seeds_2_and_3_and_the_second_world_side_by_side() {
    let runs = [("demob", "2", "explore.toml"), ("demo3", "3", "explore.toml"), ("democ", "3", "explore-2.toml")];
    std::thread::scope(|scope| {
        let started: Vec<_> = runs
            .iter()
            .map(|&(tag, seed, name)| {
                let handle = scope.spawn(move || {
                    let r = Robot::new(tag);
                    let s = run_demo(&r, &at_4x(&["--seed", seed, "--world", world(name).as_str()]), |_| {});
                    assert_success(&s);
                    assert_eq!(s["world"], name.trim_end_matches(".toml"), "{s:#}");
                    clean_up(&r);
                });
                (format!("seed {seed} of {name}"), handle)
            })
            .collect();
        let failed: Vec<String> = started.into_iter().filter_map(|(run, h)| h.join().is_err().then_some(run)).collect();
        assert!(failed.is_empty(), "failed (their panics above): {failed:?}");
    });
}

/// The island world (issue 12): the robot starts beside a round
/// free-standing workbench, more than the sonar's reach from every wall,
/// and follows it round. Back at the place it passed a lap ago (the map
/// builder's `revisit`, from odometry), the wall follower switches sides,
/// leaves the island for the room's walls, and so finds the door and the
/// person — within the same time limit as the other runs.
///
/// At 4x. The machine's CPU was why this run failed at 4x (stop 47; found
/// in session 37): the resource manager read it in real time, where the
/// robot at 4x weighs four times what it weighs at 1x (about 40 % of a
/// core against 10 %) beside whatever else the machine runs (here, the
/// rest of the suite). Over 95 % the decision maker goes `lean` and the
/// resource manager slows the wall follower to 2 s and suspends it, again
/// and again; the follower then barely runs, and the robot drifts off the
/// island without a switch or circles the room: of four 4x runs on a
/// loaded machine (load 2.8-4.4) none would have passed (three never left
/// the room, one left without a switch; a 1x run beside them too), and
/// without the machine's thresholds three of three did, alike (target at
/// 111 s). The same drift is the real-time flake `.config/nextest.toml`
/// records (2026-11-25: left the island before a lap, without switching).
/// On simulated time a busy machine holds the simulator's clock instead
/// (docs/time.md), so those thresholds made a busy run different, not
/// safer: the resource manager no longer judges the machine's CPU there
/// (`run_demo_with` checks its log). Its answer to load is
/// `demo_with_a_cpu_hungry_agent`'s to test, on the wall clock.
#[test]
fn demo_explore_island_leaves_the_island() {
    let r = Robot::new("demoi");
    let s = run_demo(&r, &at_4x(&["--seed", "1", "--world", world("explore-island.toml").as_str()]), |_| {});
    let log = std::fs::read_to_string(r.home.join("out/logs/wall-follow.log")).unwrap_or_default();
    let switches = log.lines().filter(|l| l.contains("back at a place passed before: switching to the")).count();
    assert!(switches >= 1, "the wall follower never switched sides; its log:\n{log}");
    println!("wall follower: {switches} side switch(es)");
    assert_success(&s);
    assert_eq!(s["world"], "explore-island");
    clean_up(&r);
}

/// `nerve kill tracker` while the robot explores: the supervisor restarts
/// it, and the robot still finishes. This is also the suite's run of seed 1
/// on `explore.toml`: it asserts the whole success an undisturbed run does,
/// so a run of its own (about 105 s of the serial group) was dropped; a
/// failure here that is not about the tracker reproduces with `nerve demo
/// explore --seed 1`.
#[test]
fn demo_survives_killing_the_tracker() {
    let r = Robot::new("demok");
    let s = run_demo(&r, &at_4x(&["--seed", "1", "--world", world("explore.toml").as_str()]), |r| {
        let up = wait_until(Duration::from_secs(60), || {
            r.nerve(&["ps", "--json"]).status.success()
                && r.agent("tracker").is_some_and(|a| a["pid"].as_u64() > Some(0))
        });
        assert!(up, "the tracker never came up");
        // about 20 s of simulated time in
        std::thread::sleep(Duration::from_secs_f64(20.0 / SCALE));
        r.ok(&["kill", "tracker"]);
    });
    assert_success(&s);
    assert!(s["cpu"]["tracker"]["restarts"].as_u64() >= Some(1), "{s:#}");
    clean_up(&r);
}

/// The agent added to the robot by [`demo_with_a_cpu_hungry_agent`]: it
/// burns 15 ms of CPU every 20 ms (75 % of a core, five times what the
/// whole robot uses), at the default importance.
const HOG: &str = r#"
[[agent]]
name = "hog"
kind = "testagent"
args = ["--mode", "burn"]
"#;

/// A CPU-hungry agent is added to the robot: the resource manager (policy in
/// `kb/explore.toml`) sees the robot's agents over their CPU threshold and
/// lengthens periods, least important first — the wall follower's, then
/// the hog's — and the robot still reaches the doorway and the target
/// without touching anything. In real time (see the module doc): the
/// suite's run of the robot at 1x beside those at 4x.
#[test]
fn demo_with_a_cpu_hungry_agent() {
    let r = Robot::new("demoh");
    let launch = launch_copy(&r, "explore-hog.toml", HOG);
    let s = run_demo_with(&r, &launch, &["--seed", "4", "--world", world("explore.toml").as_str()], |_| {});
    let log = std::fs::read_to_string(r.home.join("out/logs/resource.log")).unwrap_or_default();
    assert!(s["cpu"].as_object().is_some_and(|c| c.contains_key("hog")), "the hog ran: {s:#}");
    assert!(log.contains("resource: slow down"), "no period was lengthened; the resource manager's log:\n{log}");
    assert_success(&s);
    clean_up(&r);
}
