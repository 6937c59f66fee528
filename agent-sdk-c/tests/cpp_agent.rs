//! The C++ example agent (`examples/cpp/relay.cpp`, on `include/nerve.hpp`)
//! built with g++ against libnerve.so and run in a real robot, as the C
//! relay is (`c_agent.rs`): a ticker feeds it through the router, `nerve
//! echo` reads what it republishes, `nerve param set` changes its parameter
//! within its bounds and is refused outside them, and `nerve stop` stops it
//! cleanly. An exception thrown in its `init` is a failed start with
//! nerve's message, not a crash. Killed, it is restarted with its run-time
//! connection back. Needs `cargo build --workspace --lib
//! --bins` first, and g++.

mod common;

use nerve_testkit::{Robot, wait_until};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::Duration;

fn build_relay(dir: &Path, extra: &[&str]) -> PathBuf {
    let source = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples").join("cpp").join("relay.cpp");
    let mut flags = vec!["-std=c++17", "-pedantic"];
    flags.extend_from_slice(extra);
    common::compile("g++", &flags, &source, dir, "cpprelay")
}

#[test]
fn the_cpp_relay_runs_under_the_router_takes_its_parameter_and_stops_cleanly() {
    let r = Robot::new("cpprelay");
    let exe = build_relay(&r.home, &[]);

    let out = r.command(exe.to_str().expect("utf-8 path")).arg("--describe").output().expect("describe");
    assert!(out.status.success(), "--describe failed: {}", String::from_utf8_lossy(&out.stderr));
    let d: Value = serde_json::from_slice(&out.stdout).expect("description JSON");
    assert_eq!(d["kind"], "cpprelay", "{d}");
    assert_eq!(d["inputs"][0]["type_name"], "nerve::Tick", "{d}");
    assert_eq!(d["outputs"][0]["type_name"], "nerve::Tick", "{d}");

    let file = r.launch_file(
        "cpp.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "t"
kind = "ticker"
period = "10ms"

[[agent]]
name = "cpprelay"
exe = "{}"

[[connect]]
from = "t/tick"
to = "cpprelay/in"
"#,
            exe.display()
        ),
    );
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    assert_eq!(r.agent("cpprelay").expect("the C++ agent is listed")["kind"], "cpprelay");

    let seqs = common::relayed(&r, "cpprelay", 3);
    assert_eq!(seqs.len(), 3, "three ticks: {seqs:?}");
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "in order: {seqs:?}");

    // the parameter's bounds, declared through nerve.hpp, hold at run time
    let why = r.fails(&["param", "set", "cpprelay", "every", "0"]);
    assert!(why.contains("[1, 1000]"), "{why}");
    // one tick of every three: relayed seqs three apart
    r.ok(&["param", "set", "cpprelay", "every", "3"]);
    let thirds = |s: &[u64]| s.len() == 3 && s.windows(2).all(|w| w[1] == w[0] + 3);
    assert!(
        wait_until(Duration::from_secs(5), || thirds(&common::relayed(&r, "cpprelay", 3))),
        "every = 3 does not relay one tick in three: {:?}",
        common::relayed(&r, "cpprelay", 3)
    );

    // it stops, and its on_stop lambda ran: it says so in its log
    common::stops_and_says(&r, "cpprelay", "cpprelay: stopping after");
    r.down_and_check_clean();
}

/// `nerve::setup::param` throws `nerve::error` for a default outside the
/// bounds; the wrapper catches it at the callback's edge, so the agent
/// fails to start with an exit status and both messages, and no C++
/// exception unwinds into nerve's Rust runtime (that would abort).
#[test]
fn a_cpp_exception_in_init_is_a_failed_start_not_a_crash() {
    let r = Robot::new("cppthrow");
    let exe = build_relay(&r.home, &["-DCPPRELAY_EVERY_DEFAULT=0"]);
    let out = r.command(exe.to_str().expect("utf-8 path")).arg("--describe").output().expect("run cpprelay");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.code().is_some_and(|c| c != 0),
        "an exit status, not a signal or success: {:?} {stderr}",
        out.status
    );
    assert!(stderr.contains("cpprelay: init: nerve_setup_param_f64:"), "the wrapper names the call: {stderr}");
    assert!(stderr.contains("out of its bounds"), "nerve's message is kept: {stderr}");
}

/// The C++ relay rewired at run time to another ticker, then killed with
/// SIGKILL: the supervisor restarts it (`restart = "on-failure"`) and it
/// gets its run-time connection back, not the launch file's; stopped, it
/// stays stopped.
#[test]
fn the_cpp_relay_killed_is_restarted_with_its_connections_back() {
    let r = Robot::new("cppkill");
    let exe = build_relay(&r.home, &[]);
    let file = r.launch_file(
        "cpp.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "t1"
kind = "ticker"
period = "10ms"

[[agent]]
name = "t2"
kind = "ticker"
period = "10ms"
params = {{ step = 1000000 }}

[[agent]]
name = "cpprelay"
exe = "{}"
restart = "on-failure"
backoff = "100ms"

[[connect]]
from = "t1/tick"
to = "cpprelay/in"
"#,
            exe.display()
        ),
    );
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    common::rewired_to_t2(&r, "cpprelay");
    common::killed_and_restarted_with_t2(&r, "cpprelay");

    let pid = r.pid("cpprelay");
    r.ok(&["stop", "cpprelay"]);
    assert!(wait_until(Duration::from_secs(10), || r.agent("cpprelay").is_none()), "cpprelay did not stop");
    assert!(wait_until(Duration::from_secs(10), || !nerve_testkit::alive(pid)), "cpprelay's process {pid} lives on");
    r.down_and_check_clean();
}
