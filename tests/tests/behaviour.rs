//! Behaviour of the robot's higher agents, end to end with real processes:
//! the decision maker switching modes as danger and target compete (driven
//! by the hand-driven `situation` source), and the resource manager slowing
//! down the least important agent when a CPU-hungry agent loads the machine,
//! then giving the period back once the load is gone; its report lists
//! every agent of a robot of more than 16 (a sequence since issue 42).
//!
//! No assertion is on speed: every wait is a generous `wait_until`.

use nerve_tests::{Robot, wait_until};
use serde_json::Value;
use std::path::PathBuf;
use std::time::Duration;

/// Writes `body` as a knowledge base in the robot's home and returns its path.
fn kb(r: &Robot, body: &str) -> PathBuf {
    let p = r.home.join("kb.toml");
    std::fs::write(&p, body).expect("write the knowledge base");
    p
}

fn log_of(r: &Robot, agent: &str) -> String {
    std::fs::read_to_string(r.home.join(&r.name).join("logs").join(format!("{agent}.log"))).unwrap_or_default()
}

/// The mode the decision maker `dm` publishes now.
fn mode(r: &Robot) -> String {
    let out = r.nerve(&["echo", "dm/mode", "--count", "1", "--json", "--timeout", "3"]);
    let text = String::from_utf8_lossy(&out.stdout);
    text.lines()
        .rev()
        .find_map(|l| serde_json::from_str::<Value>(l).ok())
        .and_then(|v| v["data"]["name"].as_str().map(str::to_owned))
        .unwrap_or_default()
}

fn wait_mode(r: &Robot, want: &str) {
    let mut last = String::new();
    let ok = wait_until(Duration::from_secs(15), || {
        last = mode(r);
        last == want
    });
    assert!(ok, "the decision maker should be in mode {want}, it is in {last:?}; its log:\n{}", log_of(r, "dm"));
}

fn state(r: &Robot, agent: &str) -> String {
    r.agent(agent).and_then(|a| a["state"].as_str().map(str::to_owned)).unwrap_or_default()
}

fn period_ns(r: &Robot, agent: &str) -> u64 {
    r.agent(agent).and_then(|a| a["period_ns"].as_u64()).unwrap_or(0)
}

/// A stand-in for the exploration robot: `wander` (a ticker, like the wall
/// follower) runs while exploring, is suspended while tracking or avoiding,
/// and runs slower while avoiding.
const DECISION_KB: &str = r#"
[decision]
report_timeout = "1s"
min_dwell = "200ms"
retry = "300ms"

[[rule]]
when = { danger = ["high", "stop", "unknown"] }
mode = "avoid"

[[rule]]
when = { target = ["seen", "close"], danger = ["none", "low"] }
mode = "track"

[[rule]]
mode = "explore"

[modes.avoid]
urgent = true
suspend = ["wander"]
periods = { wander = "50ms" }

[modes.track]
suspend = ["wander"]

[modes.explore]
resume = ["wander"]
periods = { wander = "20ms" }
"#;

/// Danger and target compete: the target draws the robot into tracking,
/// danger wins over it, and exploring comes back when both are gone; a
/// silent safety source counts as danger. Every change is logged.
#[test]
fn decision_switches_modes_when_danger_and_target_compete() {
    let r = Robot::new("decide");
    r.router();
    let kb = kb(&r, DECISION_KB);
    r.ok(&["start", "situation", "--name", "fake"]);
    r.ok(&["param", "set", "fake", "danger", "none"]);
    r.ok(&["param", "set", "fake", "target", "none"]);
    r.ok(&["start", "ticker", "--name", "wander", "--period", "20ms"]);
    r.ok(&["start", "decision", "--name", "dm", "--", "--kb", kb.to_str().expect("utf-8 path")]);
    r.ok(&["connect", "fake/situation", "dm/situation"]);

    wait_mode(&r, "explore");
    assert!(wait_until(Duration::from_secs(5), || state(&r, "wander") == "running"));

    // a target appears, nothing dangerous: track, the explorer is suspended
    r.ok(&["param", "set", "fake", "target", "seen"]);
    wait_mode(&r, "track");
    assert!(wait_until(Duration::from_secs(5), || state(&r, "wander") == "suspended"));

    // danger while the target is still seen: danger wins
    r.ok(&["param", "set", "fake", "danger", "high"]);
    wait_mode(&r, "avoid");
    assert!(wait_until(Duration::from_secs(5), || period_ns(&r, "wander") == 50_000_000));

    // the danger passes, the target is still there: back to tracking
    r.ok(&["param", "set", "fake", "danger", "low"]);
    wait_mode(&r, "track");

    // the target is gone: explore again, at the explorer's own rate
    r.ok(&["param", "set", "fake", "target", "none"]);
    wait_mode(&r, "explore");
    assert!(wait_until(Duration::from_secs(5), || state(&r, "wander") == "running"
        && period_ns(&r, "wander") == 20_000_000));

    // the only danger source goes silent: unknown danger counts as danger
    r.ok(&["stop", "fake"]);
    wait_mode(&r, "avoid");

    let log = log_of(&r, "dm");
    for change in [
        "mode change: explore -> track (target seen, danger none",
        "mode change: track -> avoid (target seen, danger high",
        "mode change: avoid -> track (target seen, danger low",
        "mode change: track -> explore (target none, danger low",
        "mode change: explore -> avoid (target unknown, danger unknown",
    ] {
        assert!(log.contains(change), "the log should say {change:?}:\n{log}");
    }
    let published = r.echo("dm/mode", 1);
    assert_eq!(published[0]["type"], "nerve::Mode");
    assert!(published[0]["data"]["changes"].as_u64().unwrap_or(0) >= 6, "{published:?}");
    r.down_and_check_clean();
}

/// Knowledge base of the resource test: the robot's agents together may use
/// 30 % of one core; `low` is the least important agent, `keep` is
/// protected by its importance.
const RESOURCE_KB: &str = r#"
[resources]
agents_cpu = { high = 30, critical = 400, low = 15 }
settle = "1s"
slow_factor = 2.0
max_slow = 4.0
protect_importance = 9
importance = { low = 1, hog = 5, keep = 9 }
"#;

/// A CPU-hungry agent loads the machine: the resource manager lengthens the
/// period of the least important agent (not of the protected one), reports
/// the load, and gives the period back once the hungry agent is gone. Then
/// the robot grows to 17 agents, more than the 16 loads the report's fixed
/// array held before issue 42: `nerve echo` shows every one.
#[test]
fn resource_manager_slows_the_least_important_agent_under_load() {
    let r = Robot::new("rm");
    r.router();
    let kb = kb(&r, RESOURCE_KB);
    r.ok(&["start", "ticker", "--name", "low", "--period", "10ms"]);
    r.ok(&["start", "ticker", "--name", "keep", "--period", "10ms"]);
    r.ok(&["start", "resource", "--name", "rm", "--period", "500ms", "--", "--kb", kb.to_str().expect("utf-8 path")]);
    // the machine report comes before any load
    let report = r.echo("rm/load", 1);
    assert_eq!(report[0]["type"], "nerve::Seq<nerve::AgentLoad, nerve::ResourceHeader>");
    assert!(report[0]["data"]["header"]["cpus"].as_u64().unwrap_or(0) >= 1, "{report:?}");
    assert_eq!(period_ns(&r, "low"), 10_000_000);

    r.ok(&["start", "testagent", "--name", "hog", "--", "--mode", "burn"]);
    let slowed = wait_until(Duration::from_secs(30), || period_ns(&r, "low") > 10_000_000);
    assert!(slowed, "the least important agent was not slowed down; the resource manager's log:\n{}", log_of(&r, "rm"));
    let log = log_of(&r, "rm");
    assert!(log.contains("resource: slow down low: period 10ms -> 20ms"), "{log}");
    assert_eq!(period_ns(&r, "keep"), 10_000_000, "a protected agent is never slowed");
    // the report names the hungry agent and the load level
    let busy = wait_until(Duration::from_secs(10), || {
        r.echo("rm/load", 1).first().is_some_and(|s| {
            s["data"]["header"]["level"].as_u64().unwrap_or(0) >= 1
                && s["data"]["items"].as_array().is_some_and(|a| a.iter().any(|x| x["name"] == "hog"))
        })
    });
    assert!(busy, "the report shows the load and the hog");

    // the load goes away: the periods come back
    r.ok(&["kill", "hog"]);
    let restored = wait_until(Duration::from_secs(40), || period_ns(&r, "low") == 10_000_000);
    assert!(restored, "the period was not given back; the resource manager's log:\n{}", log_of(&r, "rm"));
    assert!(log_of(&r, "rm").contains("resource: restore low"), "{}", log_of(&r, "rm"));

    // 14 more (idle tickers): 17 agents, every one in the report, whose
    // length the header's count agrees with
    let extras: Vec<String> = (0..14).map(|i| format!("extra{i:02}")).collect();
    for name in &extras {
        r.ok(&["start", "ticker", "--name", name, "--period", "1s"]);
    }
    let mut want: Vec<String> = ["low", "keep", "rm"].iter().map(|s| s.to_string()).chain(extras).collect();
    want.sort();
    let mut last = Vec::new();
    let whole = wait_until(Duration::from_secs(15), || {
        last = r.echo("rm/load", 1);
        last.first().is_some_and(|s| {
            let mut names: Vec<String> = s["data"]["items"]
                .as_array()
                .map(|a| a.iter().filter_map(|x| x["name"].as_str().map(str::to_owned)).collect())
                .unwrap_or_default();
            names.sort();
            names == want && s["data"]["header"]["agents"] == 17
        })
    });
    assert!(whole, "the report should list all 17 agents {want:?}: {last:?}");
    r.down_and_check_clean();
}
