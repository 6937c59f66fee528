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

/// Descriptors or files the router and the robot may gain over the run:
/// an hour's soak gained 19 router descriptors and 14 files in 719
/// cycles, so a short run stays far below; a leak of one per churn cycle
/// (about 60 in two minutes) does not.
const SLACK: f64 = 32.0;

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
    let (first, last) = match (soaked.samples.first(), soaked.samples.last()) {
        (Some(f), Some(l)) => (*f, *l),
        _ => panic!("no samples"),
    };
    eprintln!("soak: {} cycles ({} failed), first {first:?}, last {last:?}", soaked.cycles, soaked.failures);
    // every churn cycle worked, and there were many
    assert_eq!(soaked.failures, 0, "churn cycles failed (see the lines above)");
    let expected = (minutes * 60.0 / 2.0 / 2.0) as u64;
    assert!(soaked.cycles >= expected, "only {} churn cycles in {minutes} min (expected {expected}+)", soaked.cycles);
    // the robot's own agents all still run: none died under the churn
    assert_eq!(last.processes, first.processes, "the robot lost or gained processes");
    // nothing grows by more than the slack: descriptors and files
    let grown = |what: &str, f: fn(&soak::Sample) -> f64| {
        let g = soak::growth(&soaked.samples, f);
        assert!(g.last <= g.first + SLACK, "{what} grew from {} to {} in {minutes} min", g.first, g.last);
    };
    grown("router descriptors", |s| s.router_fds as f64);
    grown("the robot's descriptors", |s| s.robot_fds as f64);
    grown("the robot's files", |s| (s.shm_files + s.iox2_files) as f64);
    // memory: the router's within 16 MiB of where it started (an hour: +1.9 MiB)
    assert!(
        last.router_rss_kib <= first.router_rss_kib + 16 * 1024,
        "router memory grew from {} to {} KiB",
        first.router_rss_kib,
        last.router_rss_kib
    );
    robot.down_and_check_clean();
}
