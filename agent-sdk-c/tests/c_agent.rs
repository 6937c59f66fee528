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

/// The lengths the Rust `detector` and `examples/c/seq_call.c` send in turn.
const LENGTHS: [usize; 4] = [0, 1, 400, 401];

/// The agents of the sequence and call checks (`seq_call_cross`), for the
/// relay's launch file: the C agent `cseq` (`examples/c/seq_call.c`, built
/// at `exe`), the Rust `detector` of its sequence type wired to it both
/// ways, a Rust server (`nerve-caller --serve`) its client calls and a Rust
/// client (`nerve-caller`) that calls its service, and the same two of a
/// call answered with a sequence (`--seq`: `Seq<Scalar, Tick>`).
fn seq_call_agents(exe: &Path) -> String {
    format!(
        r#"
[[agent]]
name = "d"
kind = "detector"

[[agent]]
name = "s"
kind = "caller"
args = ["--serve"]

[[agent]]
name = "k"
kind = "caller"

[[agent]]
name = "ss"
kind = "caller"
args = ["--serve", "--seq"]

[[agent]]
name = "ks"
kind = "caller"
args = ["--seq"]

[[agent]]
name = "cseq"
exe = "{}"

[[connect]]
from = "cseq/planner_seq"
to = "ss/plan"

[[connect]]
from = "ks/planner"
to = "cseq/plan_seq"

[[connect]]
from = "d/dets"
to = "cseq/dets_in"

[[connect]]
from = "cseq/dets"
to = "d/dets_in"

[[connect]]
from = "cseq/planner"
to = "s/plan"

[[connect]]
from = "k/planner"
to = "cseq/plan"
"#,
        exe.display()
    )
}

/// Sequences and calls between a C agent and Rust agents (issue 43 over
/// issue 42): the C agent's sequences (lengths 0, 1, 400, 401, read in
/// place by the Rust detector element by element, and decoded by `nerve
/// echo` at their own length), the Rust detector's read in place by the C
/// agent, and its loans past `max_len` refused; its service answers `nerve
/// call` and a Rust client, and its client (one call in flight, and one
/// that waits in the step now and then) is answered by a Rust server.
/// Its sequence service answers a Rust `client_seq` and `nerve call`
/// (past its max_len: refused, the caller told so), and its sequence
/// client reads a Rust `serve_seq`'s answers in place.
fn seq_call_cross(r: &Robot) {
    let want = Value::from("nerve::Seq<acme::Detection, acme::DetectionsHeader>");
    let dets_type = r.agent("cseq").and_then(|a| {
        a["outputs"].as_array().and_then(|o| o.iter().find(|o| o["name"] == "dets")).map(|o| o["type_name"].clone())
    });
    assert_eq!(dets_type, Some(want), "the C sequence is the Rust one's type");
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("d", "received") >= 8
            && r.figure_u64("d", "largest") == 401),
        "the Rust detector read {} samples of the C agent, the largest of {} elements",
        r.figure("d", "received"),
        r.figure("d", "largest")
    );
    assert_eq!(r.figure_u64("d", "bad"), 0, "every element the C agent wrote, as written");

    let report = |r: &Robot| r.echo("cseq/report", 1).pop().map(|v| v["data"].clone()).unwrap_or_default();
    let done = |d: &Value| {
        d["received"].as_u64() >= Some(8)
            && d["largest"] == 401
            && d["answered"].as_u64() >= Some(3)
            && d["replies"].as_u64() >= Some(3)
            && d["waited"].as_u64() >= Some(1)
            && d["seq_answered"].as_u64() >= Some(3)
            && d["seq_replies"].as_u64() >= Some(3)
    };
    assert!(wait_until(Duration::from_secs(10), || done(&report(r))), "the C agent reports {}", report(r));
    let d = report(r);
    assert_eq!((d["bad"].as_u64(), d["wrong"].as_u64(), d["seq_wrong"].as_u64()), (Some(0), Some(0), Some(0)), "{d}");
    assert!(d["seq_largest"].as_u64() > Some(1), "sequence answers of many elements: {d}");
    assert!(d["refused"].as_u64() > Some(0), "a loan past max_len was refused: {d}");

    // the C service, to a Rust client and to `nerve call`
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("k", "answered") >= 3),
        "the Rust client got no answers from the C service: {:?}",
        r.figures("k")
    );
    assert_eq!(r.figure("k", "wrong"), "0", "{:?}", r.figures("k"));
    let out = r.ok(&["call", "cseq/plan", r#"{"seq": 21}"#]);
    let answer: Value = serde_json::from_str(&out).expect("the answer as JSON");
    assert_eq!(answer["value"].as_f64(), Some(42.0), "{out}");

    // the C sequence service, to a Rust client_seq, to `nerve call`, and past its max_len
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("ks", "answered") >= 3),
        "the Rust client_seq got no answers from the C service: {:?}",
        r.figures("ks")
    );
    assert_eq!(r.figure("ks", "wrong"), "0", "{:?}", r.figures("ks"));
    let out = r.ok(&["call", "cseq/plan_seq", r#"{"seq": 3, "stamp_ns": 8}"#]);
    let answer: Value = serde_json::from_str(&out).expect("the answer as JSON");
    assert_eq!(answer["header"]["seq"].as_u64(), Some(3), "{out}");
    let values: Vec<_> = answer["items"].as_array().expect("items").iter().map(|i| i["value"].as_f64()).collect();
    assert_eq!(values, [Some(0.0), Some(1.0), Some(2.0)], "{out}");
    let refused = r.fails(&["call", "cseq/plan_seq", r#"{"seq": 501, "stamp_ns": 8}"#]);
    assert!(refused.contains("refused") && refused.contains("500"), "{refused}");
    assert!(
        wait_until(Duration::from_secs(5), || report(r)["seq_refused"].as_u64() >= Some(1)),
        "the C service counted no refusal: {}",
        report(r)
    );

    // each C sample at its own length, as nerve echo decodes it by the registered schema
    for s in r.echo("cseq/dets", 4) {
        let frame = s["data"]["header"]["frame"].as_u64().expect("frame");
        let items = s["data"]["items"].as_array().expect("items");
        assert_eq!(items.len(), LENGTHS[(frame as usize - 1) % LENGTHS.len()], "frame {frame}");
        assert_eq!(s["data"]["header"]["count"].as_u64(), Some(items.len() as u64));
    }
}

#[test]
fn the_c_relay_runs_under_the_router_and_stops_cleanly() {
    let r = Robot::new("crelay");
    let exe = build_c("relay", &r.home, &[]);
    let cseq = build_c("seq_call", &r.home, &[]);

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
{}"#,
            exe.display(),
            seq_call_agents(&cseq)
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

    seq_call_cross(&r);
    r.down_and_check_clean();
}

fn cycles(r: &Robot, name: &str) -> u64 {
    r.agent(name).and_then(|a| a["stats"]["cycles"].as_u64()).unwrap_or(0)
}

fn rate_of(r: &Robot, name: &str) -> f64 {
    r.agent(name).and_then(|a| a["stats"]["rate_hz"].as_f64()).unwrap_or(0.0)
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
    // rewired: its output follows t2
    common::rewired_to_t2(&r, "crelay");

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
    assert!(common::follows_t2(&r, "crelay"), "a resumed crelay relays t2's ticks");
    assert!(wait_until(Duration::from_secs(5), || cycles(&r, "crelay") > before + 1), "a resumed crelay steps");

    // SIGKILL: the supervisor restarts it, with its connection to t2 and its period
    common::killed_and_restarted_with_t2(&r, "crelay");
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
    assert_eq!(stdout.lines().filter(|l| l.starts_with("ok ")).count(), 25, "{stdout}");
    assert!(!stdout.contains("FAIL"), "{stdout}");
}
