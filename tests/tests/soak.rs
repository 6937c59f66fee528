//! The soak as a system test: the exploration robot (`launch/explore.toml`:
//! the simulator and the 13 agents of the thesis' first experiment) for a
//! few minutes while a ticker and a relay are hot-added, wired, checked,
//! unwired and stopped every two seconds ([`nerve_tests::soak`], the run
//! `nerve bench soak` reports and plots).
//!
//! Ignored by default (minutes long): `cargo nextest run -p nerve-tests
//! --test soak --run-ignored only`; `NERVE_SOAK_MINUTES` sets the length
//! (default 2). Needs the binaries: `cargo build --workspace --bins`.

use nerve_tests::soak::{self, SoakOptions};
use nerve_tests::{Robot, reap};
use std::path::PathBuf;
use std::time::Duration;

/// Descriptors or files the router and the robot may gain over the second
/// half of the run (the robot settles in its first minute: its agents finish
/// starting, the first churn cycles map their connections). An hour's soak
/// gained 4 router descriptors and no files from minute 10 to 60; a leak of
/// one per churn cycle (30 in the second minute) does not pass.
const SLACK: u64 = 16;

#[test]
#[ignore = "minutes long; run with --run-ignored only (NERVE_SOAK_MINUTES, default 2)"]
fn the_exploration_robot_under_churn_keeps_its_agents_and_leaks_nothing() {
    let minutes: f64 = std::env::var("NERVE_SOAK_MINUTES").ok().and_then(|m| m.parse().ok()).unwrap_or(2.0);
    let robot = Robot::new("soak");
    let options = SoakOptions {
        duration: Duration::from_secs_f64(minutes * 60.0),
        every: Duration::from_secs(5),
        churn_every: Duration::from_secs(2),
        launch: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../launch/explore.toml"),
        verbose: false,
    };
    let soaked = soak::run(&robot, &options).unwrap_or_else(|e| panic!("the soak did not run: {e}"));
    reap();
    // the robot after its first half (settled), and at the end
    let (mid, last) = match (soaked.samples.get(soaked.samples.len() / 2), soaked.samples.last()) {
        (Some(m), Some(l)) => (*m, *l),
        _ => panic!("no samples"),
    };
    eprintln!("soak: {} cycles ({} failed), at half time {mid:?}, at the end {last:?}", soaked.cycles, soaked.failures);
    // every churn cycle worked, and there were many
    assert_eq!(soaked.failures, 0, "churn cycles failed (see the lines above)");
    let expected = (minutes * 60.0 / 2.0 / 2.0) as u64;
    assert!(soaked.cycles >= expected, "only {} churn cycles in {minutes} min (expected {expected}+)", soaked.cycles);
    // the robot's own agents all still run: none died under the churn
    let first = soaked.samples[0];
    assert_eq!(last.processes, first.processes, "the robot lost or gained processes");
    // nothing grows in the second half by more than the slack
    let grown = |what: &str, f: fn(&soak::Sample) -> u64| {
        let (at_half, at_end) = (f(&mid), f(&last));
        assert!(at_end <= at_half + SLACK, "{what} grew from {at_half} to {at_end} in the second half");
    };
    grown("router descriptors", |s| s.router_fds);
    grown("the robot's descriptors", |s| s.robot_fds);
    grown("the robot's files", |s| s.shm_files + s.iox2_files);
    // memory: the router's within 4 MiB of where it was at half time (an hour: +0.5 MiB from minute 10 to 60)
    assert!(
        last.router_rss_kib <= mid.router_rss_kib + 4 * 1024,
        "router memory grew from {} to {} KiB in the second half",
        mid.router_rss_kib,
        last.router_rss_kib
    );
    robot.down_and_check_clean();
}
