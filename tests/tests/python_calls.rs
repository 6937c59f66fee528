//! Calls in Python (issue 42): a Python agent (`python/tests/py_caller.py`)
//! serves and calls, on the same iceoryx2 request-response services as
//! the Rust test agent `caller` (`src/bin/caller.rs`), in a real robot:
//! `nerve call` and a Rust client call a Python server, of fixed and of
//! sequence answers (refused past the service's `max_len`); a Python client
//! calls a Rust server, is refused while unwired, sees its calls fail in
//! bounded time when the server is killed and steps on, and is rewired to
//! the restarted server. The same agents under the Python test harness
//! (`python/tests/harness_calls.py`): the test calls and answers them.

use nerve_tests::py::python_with_nerve;
use nerve_tests::{Robot, wait_until};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

fn py_caller() -> String {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("python").join("tests").join("py_caller.py");
    p.display().to_string()
}

/// `nerve ARGS` with the package's Python first on PATH; its stdout.
fn ok(r: &Robot, bin: &Path, args: &[&str]) -> String {
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    let out = r.command("nerve").args(args).env("PATH", path).output().expect("run nerve");
    if !out.status.success() {
        r.dump_logs();
    }
    assert!(
        out.status.success(),
        "nerve {args:?} failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The last report of the Python agent `agent` (its `test::CallReport`).
fn report(r: &Robot, agent: &str) -> Value {
    r.echo(&format!("{agent}/report"), 1).pop().map(|v| v["data"].clone()).unwrap_or_default()
}

fn count(v: &Value, keys: &[&str]) -> u64 {
    keys.iter().map(|k| v[*k].as_u64().unwrap_or(0)).sum()
}

#[test]
fn nerve_call_and_a_rust_client_call_a_python_server() {
    let (_python, bin) = python_with_nerve();
    let r = Robot::new("pycall-srv");
    r.router();
    ok(&r, &bin, &["start", &py_caller(), "--name", "p", "--", "--serve"]);
    // the answer of `nerve call`, printed as JSON: twice the request's seq
    let out = ok(&r, &bin, &["call", "p/plan", r#"{"seq": 21, "stamp_ns": 5}"#]);
    let answer: Value = serde_json::from_str(&out).expect("the answer as JSON");
    assert_eq!((answer["value"].as_f64(), answer["stamp_ns"].as_u64()), (Some(42.0), Some(5)), "{out}");
    let fails = r.fails(&["call", "p/plan", r#"{"seq": 1, "sequence": 2}"#]);
    assert!(fails.contains("sequence"), "an unknown field: {fails}");

    // a Rust client wired to it through the router, which checks both types of the call
    r.ok(&["start", "caller", "--name", "c"]);
    r.ok(&["connect", "c/planner", "p/plan"]);
    assert_eq!(r.edges(), ["p/plan -> c/planner"]);
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("c", "answered") >= 10),
        "the Rust client had no 10 answers from Python: {:?}",
        r.figures("c")
    );
    assert_eq!(r.figure("c", "wrong"), "0", "{:?}", r.figures("c"));
    assert!(report(&r, "p")["answered"].as_u64() >= Some(10), "{}", report(&r, "p"));

    // sequence answers: `nerve call` prints the header and the items ...
    let out = ok(&r, &bin, &["call", "p/plans", r#"{"seq": 3, "stamp_ns": 7}"#]);
    let answer: Value = serde_json::from_str(&out).expect("the answer as JSON");
    assert_eq!(answer["header"]["seq"].as_u64(), Some(3), "{out}");
    let values: Vec<f64> =
        answer["items"].as_array().into_iter().flatten().filter_map(|i| i["value"].as_f64()).collect();
    assert_eq!(values, [0.0, 1.0, 2.0], "{out}");
    // ... an answer past the service's 500 is refused to its caller ...
    let fails = r.fails(&["call", "p/plans", r#"{"seq": 501}"#]);
    assert!(fails.contains("500") || fails.contains("long"), "an answer past max_len: {fails}");
    // ... and a Rust sequence client checks every answer (lengths 0 to 399)
    r.ok(&["start", "caller", "--name", "cs", "--", "--seq"]);
    r.ok(&["connect", "cs/planner", "p/plans"]);
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("cs", "answered") >= 10),
        "the Rust sequence client had no 10 answers from Python: {:?}",
        r.figures("cs")
    );
    assert_eq!(r.figure("cs", "wrong"), "0", "{:?}", r.figures("cs"));
    r.down_and_check_clean();
}

#[test]
fn a_python_client_calls_a_rust_server_and_outlives_it() {
    let (_python, bin) = python_with_nerve();
    let r = Robot::new("pycall-cli");
    r.router();
    ok(&r, &bin, &["start", &py_caller(), "--name", "pc"]);
    // unwired: refused, nothing sent
    assert!(
        wait_until(Duration::from_secs(10), || count(&report(&r, "pc"), &["not_wired"]) >= 3),
        "an unwired client's calls were not refused: {}",
        report(&r, "pc")
    );
    assert_eq!(report(&r, "pc")["sent"], 0);

    r.ok(&["start", "caller", "--name", "s", "--", "--serve"]);
    r.ok(&["connect", "pc/planner", "s/plan"]);
    assert!(
        wait_until(Duration::from_secs(10), || count(&report(&r, "pc"), &["answered"]) >= 10),
        "the Python client had no 10 answers: {}",
        report(&r, "pc")
    );
    assert_eq!(report(&r, "pc")["wrong"], 0, "{}", report(&r, "pc"));

    // the server killed with calls in flight: they end in an error within
    // the client's timeout (400 ms), and the client steps on
    let before = report(&r, "pc");
    let failed = count(&before, &["timed_out", "gone", "no_server"]);
    nerve_tests::sigkill(r.pid("s"));
    assert!(
        wait_until(Duration::from_secs(10), || count(&report(&r, "pc"), &["timed_out", "gone", "no_server"])
            >= failed + 2),
        "calls to a killed server did not fail: {}",
        report(&r, "pc")
    );
    let steps = count(&report(&r, "pc"), &["steps"]);
    assert!(
        wait_until(Duration::from_secs(5), || count(&report(&r, "pc"), &["steps"]) > steps + 10),
        "the client stopped stepping: {}",
        report(&r, "pc")
    );

    // started again under its name: the router wires the client to it again
    r.ok(&["start", "caller", "--name", "s", "--", "--serve"]);
    let answered = count(&report(&r, "pc"), &["answered"]);
    assert!(
        wait_until(Duration::from_secs(10), || count(&report(&r, "pc"), &["answered"]) >= answered + 5),
        "the restarted server did not answer: {}",
        report(&r, "pc")
    );
    assert_eq!(report(&r, "pc")["wrong"], 0);
    r.down_and_check_clean();
}

/// The Python harness (`nerve.testing.Harness`) carries calls, in the
/// test's own process (`python/tests/harness_calls.py`): the test calls
/// the Python server's services (fixed and sequence answers, one refused
/// past `max_len`) and its step answers; the Python client's
/// calls come to the test, which answers one, answers one wrongly, ends
/// one as the server gone and lets one time out on the harness clock.
#[test]
fn the_python_harness_carries_calls_both_ways() {
    let (python, _bin) = python_with_nerve();
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("python").join("tests");
    let out = Command::new(python)
        .args(["-m", "unittest", "-v", "harness_calls"])
        .current_dir(&dir)
        .output()
        .expect("unittest");
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && text.contains("Ran 3 tests") && text.contains("OK"), "{text}");
}
