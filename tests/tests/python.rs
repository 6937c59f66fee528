//! Python agents (`python/`, issue 15): a Python agent between two Rust
//! agents in a real robot, launched from a launch file, rewired, its rate
//! and a parameter changed (and refused outside its bounds) and suspended
//! while it runs, its output read by `nerve echo`; and a payload layout
//! written in Python is the Rust type's.

use nerve_tests::py::python_with_nerve;
use nerve_tests::{Robot, wait_until};
use serde_json::Value;
use std::path::PathBuf;
use std::process::{Command, Output};
use std::time::Duration;

fn loaner_py() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("python").join("tests").join("loaner.py")
}

fn scale_py() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("python").join("examples").join("scale.py")
}

/// `nerve ARGS` with the package's Python first on PATH.
fn nerve(r: &Robot, bin: &std::path::Path, args: &[&str]) -> Output {
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    r.command("nerve").args(args).env("PATH", path).output().expect("run nerve")
}

fn ok(r: &Robot, bin: &std::path::Path, args: &[&str]) -> String {
    let out = nerve(r, bin, args);
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

fn values(r: &Robot, port: &str, n: u32) -> Vec<Value> {
    r.echo(port, n)
}

fn field(v: &Value, name: &str) -> f64 {
    v["data"][name].as_f64().unwrap_or_else(|| panic!("no {name} in {v}"))
}

fn source_of(r: &Robot, agent: &str) -> Vec<String> {
    r.agent(agent)
        .and_then(|a| a["stats"]["inputs"].as_array().cloned())
        .unwrap_or_default()
        .iter()
        .map(|i| i["from_agent"].as_str().unwrap_or("").to_owned())
        .collect()
}

#[test]
fn a_python_agent_between_rust_agents_is_rewired_retimed_and_echoed() {
    let (_python, bin) = python_with_nerve();
    let r = Robot::new("py");
    // described without a robot's shared memory
    let out = Command::new(scale_py())
        .arg("--describe")
        .env("PATH", format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default()))
        .env("NERVE_ROBOT", &r.name)
        .env("NERVE_HOME", &r.home)
        .output()
        .expect("describe");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let d: Value = serde_json::from_slice(&out.stdout).expect("description JSON");
    assert_eq!(d["kind"], "scale");
    assert_eq!(d["task"], "periodic");
    assert_eq!(d["inputs"][0]["type_name"], "nerve::Tick");
    assert!(r.shm_files().is_empty(), "describing made shared memory: {:?}", r.shm_files());

    let file = r.launch_file(
        "py.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "t1"
kind = "ticker"
period = "20ms"

[[agent]]
name = "t2"
kind = "ticker"
period = "20ms"
params = {{ step = 1000 }}

[[agent]]
name = "scale"
exe = "{}"
period = "100ms"

[[agent]]
name = "r"
kind = "relay"

[[connect]]
from = "t1/tick"
to = "scale/tick"

[[connect]]
from = "scale/count"
to = "r/in"
"#,
            scale_py().display()
        ),
    );
    ok(&r, &bin, &["launch", file.to_str().expect("utf-8 path")]);
    let a = r.agent("scale").expect("the Python agent is listed");
    assert_eq!(a["kind"], "scale");
    assert_eq!(a["period_ns"].as_u64(), Some(100_000_000));

    // its output: the newest tick's number times the gain (2)
    for v in values(&r, "scale/value", 3) {
        let x = field(&v, "value");
        assert!(x > 0.0 && x % 2.0 == 0.0, "{v}");
    }
    // a Rust agent reads what it writes in place
    let relayed = values(&r, "r/out", 3);
    let seqs: Vec<f64> = relayed.iter().map(|v| field(v, "seq")).collect();
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "{seqs:?}");

    // a parameter, at run time: three values in a row that are multiples
    // of 3 (with gain 2 they cannot be: the newest tick's number grows by
    // 5 from one 100 ms step to the next)
    ok(&r, &bin, &["param", "set", "scale", "gain", "3"]);
    assert!(ok(&r, &bin, &["param", "get", "scale", "gain"]).contains('3'));
    // its bounds (`min=0.0, max=10.0` in scale.py): listed, and a value
    // outside them refused with the range, the value kept
    let list = ok(&r, &bin, &["param", "list", "scale"]);
    assert!(list.contains("gain is in [0, 10]"), "{list}");
    let refused = nerve(&r, &bin, &["param", "set", "scale", "gain", "11"]);
    let why = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && why.contains("gain is in [0, 10]"), "gain 11 accepted: {why}");
    let kept = ok(&r, &bin, &["param", "get", "scale", "gain"]);
    assert!(kept.contains('3') && !kept.contains("11"), "{kept}");
    assert!(
        wait_until(Duration::from_secs(5), || values(&r, "scale/value", 3)
            .iter()
            .all(|v| field(v, "value") % 3.0 == 0.0)),
        "gain 3 not applied"
    );

    // rewired to the other ticker (its numbers step by 1000)
    assert_eq!(source_of(&r, "scale"), vec!["t1".to_string()]);
    ok(&r, &bin, &["disconnect", "t1/tick", "scale/tick"]);
    ok(&r, &bin, &["connect", "t2/tick", "scale/tick"]);
    assert!(
        wait_until(Duration::from_secs(5), || values(&r, "scale/value", 1).iter().all(|v| field(v, "value") >= 3000.0)),
        "not rewired to t2"
    );
    assert_eq!(source_of(&r, "scale"), vec!["t2".to_string()]);

    // its rate, at run time: 100 ms -> 20 ms
    ok(&r, &bin, &["rate", "scale", "20ms"]);
    assert_eq!(r.agent("scale").and_then(|a| a["period_ns"].as_u64()), Some(20_000_000));
    let rate = |r: &Robot| r.agent("r").and_then(|a| a["stats"]["rate_hz"].as_f64()).unwrap_or(0.0);
    assert!(wait_until(Duration::from_secs(10), || rate(&r) > 30.0), "the relay gets {} Hz", rate(&r));

    // suspended, it sends nothing; resumed, it goes on
    ok(&r, &bin, &["suspend", "scale"]);
    assert_eq!(r.agent("scale").map(|a| a["state"].clone()), Some("suspended".into()));
    let quiet = nerve(&r, &bin, &["echo", "scale/count", "--count", "1", "--json", "--timeout", "1"]);
    assert!(String::from_utf8_lossy(&quiet.stdout).trim().is_empty(), "a suspended agent sent");
    ok(&r, &bin, &["resume", "scale"]);
    assert_eq!(values(&r, "scale/count", 2).len(), 2);

    // a clean stop: its process, ports and pid file go
    let pid = r.pid("scale");
    ok(&r, &bin, &["stop", "scale"]);
    assert!(wait_until(Duration::from_secs(5), || !nerve_tests::alive(pid)), "the Python agent did not stop");
    r.down_and_check_clean();
}

#[test]
fn a_layout_written_in_python_is_the_rust_types() {
    use shm_schemas::Payload as _;
    let (python, _bin) = python_with_nerve();
    let out = Command::new(python)
        .args([
            "-c",
            "import nerve\n\
             p = nerve.payload('nerve::Scalar', [('value', 'f64'), ('stamp_ns', 'u64')])\n\
             t = nerve.payload('nerve::Tick', [('seq', 'u64'), ('stamp_ns', 'u64')])\n\
             print(p.fingerprint, nerve.builtin('nerve::Scalar').fingerprint, t.fingerprint, p.size)\n\
             try:\n    nerve.builtin('nerve::Nope')\nexcept ValueError as e:\n    print(e)",
        ])
        .output()
        .expect("python");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let mut lines = text.lines();
    let nums: Vec<u64> = lines.next().unwrap_or("").split_whitespace().map(|n| n.parse().expect("a number")).collect();
    let scalar = shm_schemas::payloads::Scalar::layout_fingerprint();
    assert_eq!(nums, vec![scalar, scalar, shm_schemas::payloads::Tick::layout_fingerprint(), 16]);
    let refusal = lines.next().unwrap_or("");
    assert!(refusal.contains("nerve::Nope") && refusal.contains("nerve.payload"), "{refusal}");
}

/// The package's own tests (`python/tests`): layouts, and Python agents run
/// by the in-process harness (`nerve.testing.Harness`), among them 1000
/// cycles of a periodic agent (its wall time is printed).
#[test]
fn the_packages_tests_pass_in_the_tests_own_process() {
    let (python, _bin) = python_with_nerve();
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("python").join("tests");
    let out = Command::new(python).args(["-m", "unittest", "-v"]).current_dir(&dir).output().expect("unittest");
    let text = String::from_utf8_lossy(&out.stderr);
    eprintln!("{text}");
    assert!(out.status.success() && text.contains("Ran 17 tests") && text.contains("OK"), "{text}");
    assert!(text.contains("1000 cycles of a Python agent in"), "{text}");
}

/// B5 on a robot: a Python agent (`python/tests/loaner.py`) keeps numpy
/// views of a loan in shared memory across `send` and touches the message
/// after it: every send with a live view raises BufferError and every use
/// after send raises RuntimeError (the agent reports both in what it
/// sends); the samples a reader gets hold what was written while the loan
/// was the agent's, and the agent keeps running.
#[test]
fn a_python_loan_in_shared_memory_is_never_touched_after_send() {
    let (_python, bin) = python_with_nerve();
    let r = Robot::new("pyloan");
    let file = r.launch_file(
        "loan.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "loaner"
exe = "{}"
period = "20ms"
"#,
            loaner_py().display()
        ),
    );
    ok(&r, &bin, &["launch", file.to_str().expect("utf-8 path")]);
    let reports = values(&r, "loaner/report", 4);
    assert_eq!(reports.len(), 4);
    for v in &reports {
        let d = &v["data"];
        assert_eq!(d["kept_view_refused"], 1, "a loan was sent with a live view: {v}");
        assert_eq!(d["array_view_refused"], 1, "a loan was sent with a live array: {v}");
        // the first report cannot say yet: it tells of the send before it
        if d["seq"].as_u64().is_some_and(|s| s >= 2) {
            assert_eq!(d["use_after_send_refused"], 1, "a sent message was touched: {v}");
        }
        let vals: Vec<f64> = d["values"].as_array().expect("values").iter().filter_map(Value::as_f64).collect();
        assert_eq!(vals[..3], [1.5, 2.5, 3.5], "{v}");
        assert_eq!(vals[3], d["seq"].as_f64().expect("seq") - 1.0, "{v}");
    }
    assert_eq!(r.agent("loaner").map(|a| a["state"].clone()), Some("running".into()));
    // review B13: numpy's pool runs before the agent forks into a daemon;
    // the daemon's log says so, and what to do should it ever hang
    let log = std::fs::read_to_string(r.home.join(&r.name).join("logs").join("loaner.log")).unwrap_or_default();
    assert!(
        log.contains("became a daemon (--daemon) by a fork while its interpreter ran")
            && log.contains("OPENBLAS_NUM_THREADS=1"),
        "no word of the threads at the fork in the agent's log:\n{log}"
    );
    r.down_and_check_clean();
}
