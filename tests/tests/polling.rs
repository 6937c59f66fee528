//! Polling mode (issue 42): an agent that polls its inputs instead of
//! sleeping, on the CPU it is placed on. A real relay polling on CPU 1
//! relays a real ticker's samples, is rewired to another ticker and relays
//! its samples, is suspended (steps no more) and resumed (steps again),
//! shows in `nerve ps` as polling with its CPU, and stops promptly when
//! told. Asking to poll without a placement is refused, on the command line
//! and in a launch file (at FILE:LINE), saying what to add.
//!
//! The poller runs without SCHED_FIFO (`--no-realtime`) and as a child of
//! the test (killed when the guard drops, even when the test fails): on the
//! two shared CPUs of CI a real-time spinner would take CPU 1 from every
//! other test for the seconds this one runs.

use nerve_tests::{ChildGuard, Robot, alive, wait_until};
use serde_json::Value;
use std::time::Duration;

/// Generous bounds for a loaded machine; they turn a hang into a failure.
const WITHIN: Duration = Duration::from_secs(10);

/// Samples input `in` of agent `name` received from agent `from` (0 when unknown).
fn received_from(r: &Robot, name: &str, from: &str) -> u64 {
    r.agent(name)
        .and_then(|a| {
            a["stats"]["inputs"]
                .as_array()?
                .iter()
                .find(|i| i["from_agent"] == from)
                .and_then(|i| i["received"].as_u64())
        })
        .unwrap_or(0)
}

fn cycles(r: &Robot, name: &str) -> u64 {
    r.agent(name).and_then(|a| a["stats"]["cycles"].as_u64()).unwrap_or(0)
}

#[test]
fn a_polling_relay_relays_is_rewired_suspended_and_stopped_promptly() {
    let r = Robot::new("poll");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "ticker", "--name", "t2", "--period", "10ms"]);
    let mut cmd = r.command("nerve-relay");
    cmd.args(["--name", "p", "--poll", "--cpus", "1", "--no-realtime"]);
    let poller = ChildGuard::spawn("polling relay", cmd).expect("start the polling relay");
    assert!(wait_until(WITHIN, || r.agent("p").is_some()), "the polling relay did not register");

    // it polls, on CPU 1, and says so
    assert_eq!(r.figure("p", "poll"), "cpus 1");
    let table = r.ok(&["ps"]);
    assert!(table.contains("event-driven+poll"), "{table}");

    // relays t1's samples
    r.ok(&["connect", "t1/tick", "p/in"]);
    let out = r.echo("p/out", 3);
    assert_eq!(out.len(), 3, "{out:?}");
    assert!(wait_until(WITHIN, || received_from(&r, "p", "t1") >= 3));

    // rewired to t2 while polling: relays t2's samples, no more of t1's
    r.ok(&["disconnect", "t1/tick", "p/in"]);
    r.ok(&["connect", "t2/tick", "p/in"]);
    assert!(wait_until(WITHIN, || received_from(&r, "p", "t2") >= 3), "the rewired poller reads nothing of t2");
    assert_eq!(r.echo("p/out", 2).len(), 2);
    assert_eq!(received_from(&r, "p", "t1"), 0, "t1 is no longer a source");

    // the input's figures, which a poller counts at its step's start
    // (`runtime::step_clock`): t2's rate (a tick every 10 ms, so about 100
    // Hz; bounds wide for a loaded machine) and a recent last sample
    let t2_input = || {
        r.agent("p").and_then(|a| {
            let i = a["stats"]["inputs"].as_array()?.iter().find(|i| i["from_agent"] == "t2")?.clone();
            Some((i["rate_hz"].as_f64()?, i["last_age_ns"].as_u64()?))
        })
    };
    assert!(
        wait_until(WITHIN, || t2_input().is_some_and(|(hz, age)| (20.0..500.0).contains(&hz) && age < 2_000_000_000)),
        "the poller's input figures are off: {:?}",
        t2_input()
    );

    // its CPU is reported: a spinning task uses a good share of its CPU
    // (not asserted whole: CI's CPUs are shared with other tests)
    let cpu = || r.agent("p").and_then(|a| a["stats"]["cpu_percent"].as_f64()).unwrap_or(0.0);
    assert!(wait_until(WITHIN, || cpu() > 5.0), "nerve ps shows no CPU for a poller: {}", cpu());

    // suspended: no step while samples keep coming; resumed: steps again
    r.ok(&["suspend", "p"]);
    let held = cycles(&r, "p");
    let t2_before = received_from(&r, "p", "t2");
    assert!(
        wait_until(WITHIN, || r.agent("t2").and_then(|a| a["stats"]["cycles"].as_u64()).unwrap_or(0) > t2_before + 10)
    );
    assert_eq!(cycles(&r, "p"), held, "a suspended poller stepped");
    r.ok(&["resume", "p"]);
    assert!(wait_until(WITHIN, || cycles(&r, "p") > held + 3), "the resumed poller does not step");

    // stopped promptly while polling
    let pid = poller.id();
    r.ok(&["stop", "p"]);
    assert!(wait_until(WITHIN, || !alive(pid)), "the poller did not stop");
    drop(poller);
    r.down_and_check_clean();
}

#[test]
fn polling_without_a_placement_is_refused_saying_what_to_add() {
    let r = Robot::new("pollno");
    // the agent's own command line
    let out = r.command("nerve-relay").args(["--name", "p", "--poll"]).output().expect("run nerve-relay");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "started without a placement: {err}");
    assert!(err.contains("--poll needs a placement") && err.contains("--cpus"), "{err}");
    // nerve start passes it on, and says why the agent did not start
    r.router();
    let err = r.fails(&["start", "relay", "--name", "q", "--poll"]);
    assert!(err.contains("--cpus"), "{err}");
    // a launch file: refused before anything starts, at the poll line
    let lf = r.launch_file("poll.toml", "robot = \"x\"\n[[agent]]\nname = \"p\"\nkind = \"relay\"\npoll = true\n");
    let err = r.fails(&["launch", &lf.display().to_string()]);
    assert!(err.contains("poll.toml:5") && err.contains("cpus = [1]"), "{err}");
    assert!(r.agent("p").is_none() && r.agent("q").is_none());
    r.down_and_check_clean();
}

#[test]
fn a_launch_file_with_poll_and_cpus_starts_a_poller() {
    let r = Robot::new("polllf");
    let lf = r.launch_file(
        "poll.toml",
        "robot = \"x\"\n[[agent]]\nname = \"p\"\nkind = \"relay\"\ncpus = [1]\npoll = true\n",
    );
    r.ok(&["launch", &lf.display().to_string()]);
    let p: Value = r.agent("p").expect("p runs");
    let pid = p["pid"].as_u64().expect("pid") as u32;
    assert_eq!(r.figure("p", "poll"), "cpus 1");
    // a real-time poller: stopped at once, so that it spins no longer than needed
    r.ok(&["stop", "p"]);
    assert!(wait_until(WITHIN, || !alive(pid)), "the poller did not stop");
    r.down_and_check_clean();
}

/// A poller refills the queues of its deep and keep-all inputs as the
/// event loop does (and only theirs: `runtime::poll`): a relay polling with
/// `--input in:depth=64,keep=all` (a queue of its own past iceoryx2's
/// buffer) relays a ticker's samples, and stops promptly.
#[test]
fn a_polling_relay_with_a_deep_keep_all_input_relays() {
    let r = Robot::new("polldeep");
    r.router();
    r.ok(&["start", "ticker", "--name", "t", "--period", "10ms"]);
    let mut cmd = r.command("nerve-relay");
    cmd.args(["--name", "p", "--poll", "--cpus", "1", "--no-realtime", "--input", "in:depth=64,keep=all"]);
    let poller = ChildGuard::spawn("polling relay", cmd).expect("start the polling relay");
    assert!(wait_until(WITHIN, || r.agent("p").is_some()), "the polling relay did not register");
    assert_eq!(r.figure("p", "poll"), "cpus 1");
    r.ok(&["connect", "t/tick", "p/in"]);
    let out = r.echo("p/out", 3);
    assert_eq!(out.len(), 3, "relayed through the deep keep-all input while polling: {out:?}");
    assert!(wait_until(WITHIN, || received_from(&r, "p", "t") >= 3));
    let pid = poller.id();
    r.ok(&["stop", "p"]);
    assert!(wait_until(WITHIN, || !alive(pid)), "the poller did not stop");
    drop(poller);
    r.down_and_check_clean();
}
