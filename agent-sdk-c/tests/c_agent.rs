//! The C example agent (`examples/c/relay.c`) built with gcc against
//! libnerve.so and run in a real robot: a ticker feeds it through the
//! router, `nerve echo` reads what it republishes, `--describe` lists its
//! ports, and `nerve stop` stops it cleanly. Needs the binaries `nerve`,
//! `nerve-router` and `nerve-ticker` and libnerve.so built beside the test
//! (`cargo build --workspace --lib --bins`, as CI's build step does) and gcc.

use nerve_testkit::{Robot, wait_until};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

mod common;

/// Builds `examples/c/NAME.c` into `dir` with gcc (C11, `extra` flags),
/// against the libnerve.so the workspace's build left beside the binaries
/// (`tests/common`: no cargo run from a test); panics with gcc's message.
fn build_c(name: &str, dir: &Path, extra: &[&str]) -> PathBuf {
    let source = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples").join("c").join(format!("{name}.c"));
    let flags: Vec<&str> = ["-std=c11"].into_iter().chain(extra.iter().copied()).collect();
    common::compile("gcc", &flags, &source, dir, name)
}

#[test]
fn the_c_relay_runs_under_the_router_and_stops_cleanly() {
    let r = Robot::new("crelay");
    let exe = build_c("relay", &r.home, &[]);

    // described without a robot's shared memory
    let out = r.command(exe.to_str().expect("utf-8 path")).arg("--describe").output().expect("describe");
    assert!(out.status.success(), "--describe failed: {}", String::from_utf8_lossy(&out.stderr));
    let d: Value = serde_json::from_slice(&out.stdout).expect("description JSON");
    assert_eq!(d["kind"], "crelay", "{d}");
    assert_eq!(d["inputs"][0]["type_name"], "nerve::Tick", "{d}");
    assert_eq!(d["outputs"][0]["type_name"], "nerve::Tick", "{d}");
    assert!(r.shm_files().is_empty(), "describing made shared memory: {:?}", r.shm_files());

    let file = r.launch_file(
        "c.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "t"
kind = "ticker"
period = "20ms"

[[agent]]
name = "crelay"
exe = "{}"

[[connect]]
from = "t/tick"
to = "crelay/in"
"#,
            exe.display()
        ),
    );
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    let a = r.agent("crelay").expect("the C agent is listed");
    assert_eq!(a["kind"], "crelay", "{a}");

    // what it republishes is the ticker's ticks, in order
    let got = r.echo("crelay/out", 3);
    let seqs: Vec<u64> = got.iter().filter_map(|v| v["data"]["seq"].as_u64()).collect();
    assert_eq!(seqs.len(), 3, "three ticks with a seq: {got:?}");
    assert!(seqs.iter().all(|s| *s > 0), "ticks number from 1: {seqs:?}");
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "in order: {seqs:?}");

    assert!(got.iter().all(|v| v["from"] == "crelay"), "sent by the C agent: {got:?}");
    // an event-driven C agent has no period to change, as a Rust one
    let why = r.fails(&["rate", "crelay", "50ms"]);
    assert!(why.contains("event-driven"), "{why}");
    // it stops, and its stop callback ran: it says so in its log
    common::stops_and_says(&r, "crelay", "crelay: stopping after");
    r.down_and_check_clean();
}

fn cycles(r: &Robot, name: &str) -> u64 {
    r.agent(name).and_then(|a| a["stats"]["cycles"].as_u64()).unwrap_or(0)
}

fn rate_of(r: &Robot, name: &str) -> f64 {
    r.agent(name).and_then(|a| a["stats"]["rate_hz"].as_f64()).unwrap_or(0.0)
}

/// The seqs of the next `n` ticks the relay republishes.
fn relayed(r: &Robot, n: u32) -> Vec<u64> {
    r.echo("crelay/out", n).iter().filter_map(|v| v["data"]["seq"].as_u64()).collect()
}

/// Whether what the relay republishes now comes from t2 (whose seq grows
/// by a million a tick; t1's by one), checked on a few fresh ticks.
fn follows_t2(r: &Robot) -> bool {
    let seqs = relayed(r, 3);
    seqs.len() == 3 && seqs.iter().all(|s| *s >= 1_000_000 && s % 1_000_000 == 0)
}

/// What a Rust agent gets from the runtime, for a C agent under a real
/// router: rewired to another ticker (its output follows), its period
/// changed by `nerve rate`, suspended and resumed, killed with SIGKILL and
/// restarted by the supervisor with its run-time connection and period,
/// then stopped cleanly (not restarted again).
#[test]
fn the_c_relay_is_rewired_rated_suspended_and_restarted_like_a_rust_agent() {
    let r = Robot::new("crelay2");
    // periodic (20 ms), so that `nerve rate` applies
    let exe = build_c("relay", &r.home, &["-DRELAY_PERIOD_NS=20000000"]);
    let file = r.launch_file(
        "c.toml",
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
name = "crelay"
exe = "{}"
restart = "on-failure"
backoff = "100ms"

[[connect]]
from = "t1/tick"
to = "crelay/in"
"#,
            exe.display()
        ),
    );
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    let seqs = relayed(&r, 3);
    assert!(seqs.len() == 3 && seqs.iter().all(|s| *s < 1_000_000), "t1's ticks first: {seqs:?}");

    // rewired: its output follows t2
    r.ok(&["disconnect", "t1/tick", "crelay/in"]);
    r.ok(&["connect", "t2/tick", "crelay/in"]);
    assert!(
        wait_until(Duration::from_secs(5), || follows_t2(&r)),
        "crelay's output does not follow t2: {:?}",
        relayed(&r, 3)
    );

    // rate: from 20 ms (50 Hz) to 100 ms (10 Hz)
    assert!(
        wait_until(Duration::from_secs(8), || (35.0..65.0).contains(&rate_of(&r, "crelay"))),
        "crelay runs at {} Hz, not 50",
        rate_of(&r, "crelay")
    );
    r.ok(&["rate", "crelay", "100ms"]);
    assert!(
        wait_until(Duration::from_secs(8), || (5.0..15.0).contains(&rate_of(&r, "crelay"))),
        "crelay runs at {} Hz after nerve rate 100ms",
        rate_of(&r, "crelay")
    );

    // suspended: no cycles, nothing relayed; resumed: both again
    r.ok(&["suspend", "crelay"]);
    assert!(
        wait_until(Duration::from_secs(5), || r.agent("crelay").is_some_and(|a| a["state"] == "suspended")),
        "{:?}",
        r.agent("crelay")
    );
    // a cycle begun before the suspend may still be counted: let it settle
    std::thread::sleep(Duration::from_millis(300));
    let before = cycles(&r, "crelay");
    let silent = r.nerve(&["echo", "crelay/out", "--count", "1", "--json", "--timeout", "1"]);
    assert!(
        !silent.status.success() || silent.stdout.is_empty(),
        "a suspended crelay relayed: {}",
        String::from_utf8_lossy(&silent.stdout)
    );
    assert!(cycles(&r, "crelay") <= before + 1, "a suspended crelay stepped: {before} -> {}", cycles(&r, "crelay"));
    r.ok(&["resume", "crelay"]);
    assert!(
        wait_until(Duration::from_secs(5), || r.agent("crelay").is_some_and(|a| a["state"] == "running")),
        "{:?}",
        r.agent("crelay")
    );
    assert!(follows_t2(&r), "a resumed crelay relays t2's ticks");
    assert!(wait_until(Duration::from_secs(5), || cycles(&r, "crelay") > before + 1), "a resumed crelay steps");

    // SIGKILL: the supervisor restarts it, with its connection to t2 and its period
    let old = r.pid("crelay");
    nerve_testkit::sigkill(old);
    assert!(
        wait_until(Duration::from_secs(10), || r.agent("crelay").is_some_and(|a| {
            let pid = a["pid"].as_u64().unwrap_or(0);
            pid != 0 && pid != u64::from(old)
        })),
        "crelay was not restarted: {:?}",
        r.ps()
    );
    assert!(
        wait_until(Duration::from_secs(5), || follows_t2(&r)),
        "the restarted crelay does not relay t2: {:?}",
        relayed(&r, 3)
    );
    assert!(
        wait_until(Duration::from_secs(8), || (5.0..15.0).contains(&rate_of(&r, "crelay"))),
        "the restarted crelay runs at {} Hz, not 10",
        rate_of(&r, "crelay")
    );

    // stopped: gone, and not restarted
    let pid = r.pid("crelay");
    r.ok(&["stop", "crelay"]);
    assert!(wait_until(Duration::from_secs(10), || r.agent("crelay").is_none()), "crelay did not stop");
    assert!(wait_until(Duration::from_secs(10), || !nerve_testkit::alive(pid)), "crelay's process {pid} lives on");
    std::thread::sleep(Duration::from_millis(500));
    assert!(r.agent("crelay").is_none(), "a stopped crelay was restarted: {:?}", r.ps());
    r.down_and_check_clean();
}

/// Every call of the header made wrong (NULL handles and out-pointers, no
/// agent) from a C program built with the undefined-behaviour sanitizer:
/// each answers its status and a message, and nothing crashes or reports.
#[test]
fn c_calls_with_null_pointers_are_statuses_not_crashes() {
    let dir = std::env::temp_dir().join(format!("nerve-c-misuse-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("make a folder");
    struct Remove(PathBuf);
    impl Drop for Remove {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
    let _remove = Remove(dir.clone());
    let exe = build_c("misuse", &dir, &["-fsanitize=undefined", "-fno-sanitize-recover=undefined"]);
    let out = Command::new(&exe).output().expect("run misuse");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(stdout.lines().filter(|l| l.starts_with("ok ")).count(), 13, "{stdout}");
    assert!(!stdout.contains("FAIL"), "{stdout}");
}
