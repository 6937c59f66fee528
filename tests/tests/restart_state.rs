//! What survives a restart, end to end with real processes: run-time state
//! (suspend, period, parameters) set through the router comes back to an
//! agent restarted by hand or by the supervisor (R12), also after the router
//! itself restarted (the decision maker sends its mode again); a restarted
//! agent does not inherit the router's real-time policy (R13); and the
//! decision maker goes on deciding while the router waits for an agent
//! (R26).

use nerve_tests::{Robot, alive, bin_dir, sigkill, wait_until};
use std::os::unix::fs::PermissionsExt;
use std::time::Duration;

fn cycles(r: &Robot, name: &str) -> u64 {
    r.agent(name).and_then(|a| a["stats"]["cycles"].as_u64()).unwrap_or(0)
}

fn rate_of(r: &Robot, name: &str) -> f64 {
    r.agent(name).and_then(|a| a["stats"]["rate_hz"].as_f64()).unwrap_or(0.0)
}

fn log_of(r: &Robot, agent: &str) -> String {
    std::fs::read_to_string(r.home.join(&r.name).join("logs").join(format!("{agent}.log"))).unwrap_or_default()
}

/// Whether the agent itself (not the router's view) makes no progress.
fn really_suspended(r: &Robot, name: &str) -> bool {
    let before = cycles(r, name);
    std::thread::sleep(Duration::from_millis(300));
    cycles(r, name) <= before + 1
}

/// The router's pid, from its pid file.
fn router_pid(r: &Robot) -> u32 {
    r.pid_file("router").expect("the router's pid file")
}

/// Kills agent `name` and waits until the router has noticed.
fn kill_and_wait(r: &Robot, name: &str) -> u32 {
    let pid = r.pid(name);
    sigkill(pid);
    assert!(wait_until(Duration::from_secs(5), || !alive(pid) && r.agent(name).is_none()), "{name} still listed");
    pid
}

/// R12: suspend, period and parameters set through the router come back
/// when an agent of the same name is started again by hand, after a crash
/// or after `nerve stop`.
#[test]
fn run_time_state_comes_back_to_an_agent_restarted_by_hand() {
    let r = Robot::new("byhand");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "ticker", "--name", "t2", "--period", "10ms"]);
    r.ok(&["param", "set", "t1", "step", "1000"]);
    r.ok(&["rate", "t1", "50ms"]);
    r.ok(&["suspend", "t2"]);

    kill_and_wait(&r, "t1");
    kill_and_wait(&r, "t2");
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "ticker", "--name", "t2", "--period", "10ms"]);

    assert!(
        wait_until(Duration::from_secs(5), || r.ok(&["param", "get", "t1", "step"]).trim() == "1000"),
        "t1's step was not re-applied; router log:\n{}",
        log_of(&r, "router")
    );
    assert!(
        wait_until(Duration::from_secs(8), || (10.0..30.0).contains(&rate_of(&r, "t1"))),
        "t1 should run every 50 ms again, it runs at {} Hz",
        rate_of(&r, "t1")
    );
    assert!(wait_until(Duration::from_secs(5), || r.agent("t2").is_some_and(|a| a["state"] == "suspended")));
    assert!(really_suspended(&r, "t2"), "t2 runs although it was suspended before its restart");

    // stopped and started again by hand: the same
    r.ok(&["stop", "t2"]);
    assert!(wait_until(Duration::from_secs(5), || r.agent("t2").is_none()));
    r.ok(&["start", "ticker", "--name", "t2", "--period", "10ms"]);
    assert!(wait_until(Duration::from_secs(5), || r.agent("t2").is_some_and(|a| a["state"] == "suspended")));
    assert!(really_suspended(&r, "t2"), "t2 runs although it was suspended before it was stopped");
    // resumed by hand, it stays resumed through the next restart
    r.ok(&["resume", "t2"]);
    kill_and_wait(&r, "t2");
    r.ok(&["start", "ticker", "--name", "t2", "--period", "10ms", "--suspended"]);
    assert!(
        wait_until(Duration::from_secs(5), || r.agent("t2").is_some_and(|a| a["state"] == "running")),
        "the last request (resume) wins over --suspended"
    );
    r.down_and_check_clean();
}

/// R12: the same for an agent the supervisor restarts after a crash.
#[test]
fn run_time_state_comes_back_after_a_supervisor_restart() {
    let r = Robot::new("supst");
    let file = r.launch_file(
        "sup.toml",
        "robot = \"x\"\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nperiod = \"10ms\"\nrestart = \"on-failure\"\nbackoff = \"100ms\"\n",
    );
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    r.ok(&["param", "set", "t1", "step", "7"]);
    r.ok(&["suspend", "t1"]);
    let old = r.pid("t1");
    sigkill(old);
    assert!(
        wait_until(Duration::from_secs(10), || r
            .agent("t1")
            .is_some_and(|a| a["pid"].as_u64().unwrap_or(0) as u32 != old && a["pid"] != 0)),
        "t1 was not restarted: {:?}",
        r.ps()
    );
    assert!(wait_until(Duration::from_secs(5), || r.ok(&["param", "get", "t1", "step"]).trim() == "7"));
    assert!(wait_until(Duration::from_secs(5), || r.agent("t1").is_some_and(|a| a["state"] == "suspended")));
    assert!(really_suspended(&r, "t1"), "the restarted t1 runs although it was suspended");
    r.down_and_check_clean();
}

/// A knowledge base with one mode, entered at once, that suspends `wander`.
const HOLD_KB: &str = r#"
[decision]
retry = "200ms"

[[rule]]
mode = "hold"

[modes.hold]
suspend = ["wander"]
"#;

/// R12: a restarted router starts with no memory; the decision maker sees
/// its new epoch and sends the current mode's actions again, so that an
/// agent restarted afterwards still gets them.
#[test]
fn the_decision_maker_sends_its_mode_again_to_a_restarted_router() {
    let r = Robot::new("epoch");
    r.router();
    let kb = nerve_tests::write_file(&r.home, "hold.toml", HOLD_KB);
    r.ok(&["start", "ticker", "--name", "wander", "--period", "10ms"]);
    r.ok(&["start", "decision", "--name", "dm", "--", "--kb", kb.to_str().expect("utf-8 path")]);
    assert!(wait_until(Duration::from_secs(10), || r.agent("wander").is_some_and(|a| a["state"] == "suspended")));

    // a new router: the agents re-register; the decision maker re-sends
    let old_router = router_pid(&r);
    sigkill(old_router);
    assert!(wait_until(Duration::from_secs(5), || !alive(old_router)));
    r.router();
    let new_router = format!("registered with the router (pid {})", router_pid(&r));
    assert!(
        wait_until(Duration::from_secs(10), || log_of(&r, "dm").contains(&new_router)
            && log_of(&r, "wander").contains(&new_router)),
        "dm and wander did not register with the new router:\n{}",
        log_of(&r, "dm")
    );
    // the decision maker sees the new epoch and sends its mode again
    std::thread::sleep(Duration::from_millis(1500));

    // wander restarts by hand: the new router re-applies the suspend it got from the decision maker
    kill_and_wait(&r, "wander");
    r.ok(&["start", "ticker", "--name", "wander", "--period", "10ms"]);
    assert!(
        wait_until(Duration::from_secs(5), || r.agent("wander").is_some_and(|a| a["state"] == "suspended")),
        "router log:\n{}",
        log_of(&r, "router")
    );
    assert!(really_suspended(&r, "wander"), "the restarted wander runs in mode hold");
    r.down_and_check_clean();
}

/// The scheduling policy of every thread of `pid` (field 41 of its stat).
fn policies(pid: u32) -> Vec<u32> {
    let Ok(rd) = std::fs::read_dir(format!("/proc/{pid}/task")) else { return vec![] };
    rd.filter_map(|e| e.ok())
        .filter_map(|e| std::fs::read_to_string(e.path().join("stat")).ok())
        .filter_map(|s| s.rsplit_once(')').and_then(|(_, r)| r.split_whitespace().nth(38)?.parse().ok()))
        .collect()
}

/// R13: an agent restarted by a real-time router runs under SCHED_OTHER,
/// as the same agent started by `nerve launch` does. (Where the router
/// cannot get SCHED_FIFO, both are SCHED_OTHER anyway.)
#[test]
fn a_supervisor_restarted_agent_does_not_inherit_the_routers_real_time_policy() {
    let r = Robot::new("sched");
    r.router();
    eprintln!("the router's threads run under policies {:?} (1: SCHED_FIFO)", policies(router_pid(&r)));
    // the ticker without real-time requests of its own
    let wrapper = r.home.join("ticker-no-rt");
    std::fs::write(
        &wrapper,
        format!(
            "#!/bin/sh\ncase \" $* \" in *\" --no-realtime \"*) exec {t} \"$@\";; *) exec {t} --no-realtime \"$@\";; esac\n",
            t = bin_dir().join("nerve-ticker").display()
        ),
    )
    .expect("write the wrapper");
    std::fs::set_permissions(&wrapper, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    let file = r.launch_file(
        "sched.toml",
        &format!(
            "robot = \"x\"\n[[agent]]\nname = \"t1\"\nexe = \"{}\"\nrestart = \"on-failure\"\nbackoff = \"100ms\"\n",
            wrapper.display()
        ),
    );
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    let first = r.pid("t1");
    assert!(policies(first).iter().all(|p| *p == 0), "launched: {:?}", policies(first));
    sigkill(first);
    let mut restarted = 0;
    assert!(wait_until(Duration::from_secs(10), || {
        restarted = r.agent("t1").and_then(|a| a["pid"].as_u64()).unwrap_or(0) as u32;
        restarted != 0 && restarted != first
    }));
    let p = policies(restarted);
    assert!(!p.is_empty() && p.iter().all(|p| *p == 0), "the restarted agent's threads run under policies {p:?}");
    r.down_and_check_clean();
}

/// A knowledge base whose one mode commands an agent that will not answer.
const FROZEN_KB: &str = r#"
[decision]
retry = "100ms"

[[rule]]
mode = "m"

[modes.m]
weights = { frozen = { a = 1 } }
periods = { frozen = "50ms" }
suspend = ["frozen"]
"#;

/// R26: while the router waits for an agent that does not answer (stopped
/// with SIGSTOP: each command waits for the router's time-out), the
/// decision maker goes on deciding and publishing its mode every cycle.
#[test]
fn the_decision_maker_keeps_deciding_while_the_router_waits_for_an_agent() {
    let r = Robot::new("block");
    r.router();
    let kb = nerve_tests::write_file(&r.home, "frozen.toml", FROZEN_KB);
    r.ok(&["start", "ticker", "--name", "frozen", "--period", "100ms"]);
    let frozen = r.pid("frozen");
    // SAFETY: kill has no memory-safety preconditions.
    unsafe { libc::kill(frozen as i32, libc::SIGSTOP) };
    r.ok(&["start", "decision", "--name", "dm", "--", "--kb", kb.to_str().expect("utf-8 path")]);
    // each of the mode's three actions holds the router for a second (its
    // wait for the frozen agent), again every 100 ms: a decision task that
    // waited for them would publish nothing for three seconds at a time
    let out = r.nerve(&["echo", "dm/mode", "--count", "15", "--json", "--timeout", "8"]);
    let stamps: Vec<u64> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| v["data"]["stamp_ns"].as_u64())
        .collect();
    assert_eq!(stamps.len(), 15, "{}", String::from_utf8_lossy(&out.stderr));
    let longest = stamps.windows(2).map(|w| w[1].saturating_sub(w[0])).max().unwrap_or(0);
    assert!(
        longest < 1_500_000_000,
        "the decision maker published nothing for {} ms (its period is 100 ms); its log:\n{}",
        longest / 1_000_000,
        log_of(&r, "dm")
    );
    // the worker met the frozen agent meanwhile
    assert!(wait_until(Duration::from_secs(15), || log_of(&r, "dm").contains("not done yet")), "{}", log_of(&r, "dm"));
    // SAFETY: as above.
    unsafe { libc::kill(frozen as i32, libc::SIGCONT) };
    r.down_and_check_clean();
}
