//! Calls between agents, end to end (issue 42; `docs/calls.md`): real
//! processes (`nerve-caller`, `tests/src/bin/caller.rs`, as server and as
//! client), the router wiring a client to a service like a connection, and
//! iceoryx2 request-response in between.

use nerve_tests::{Robot, wait_until};
use std::time::Duration;

/// A robot with a router, server `s` (service `plan`) and client `c`
/// (`planner`, started with `client_args`) wired to it.
fn wired(tag: &str, client_args: &[&str]) -> Robot {
    let r = Robot::new(tag);
    r.router();
    r.ok(&["start", "caller", "--name", "s", "--", "--serve"]);
    let mut start = vec!["start", "caller", "--name", "c", "--"];
    start.extend_from_slice(client_args);
    r.ok(&start);
    r.ok(&["connect", "c/planner", "s/plan"]);
    r
}

#[test]
fn a_call_is_answered_and_the_wire_shows_in_the_graph() {
    let r = wired("call-ok", &[]);
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("c", "answered") >= 20),
        "the client had no 20 answers: {:?}",
        r.figures("c")
    );
    let c = r.figures("c");
    assert_eq!(c.get("wrong").map(String::as_str), Some("0"), "{c:?}");
    assert!(r.figure_u64("s", "answered") >= 20, "{:?}", r.figures("s"));
    let graph = r.graph().to_string();
    assert!(graph.contains("c/planner") && graph.contains("s/plan"), "{graph}");
    assert_eq!(r.edges(), ["s/plan -> c/planner"], "listed service to client");
    // unwired (written client first too): the client's calls are refused, nothing sent
    r.ok(&["disconnect", "c/planner", "s/plan"]);
    assert!(r.edges().is_empty(), "{:?}", r.edges());
    let refused = r.figure_u64("c", "not_wired");
    assert!(
        wait_until(Duration::from_secs(5), || r.figure_u64("c", "not_wired") >= refused + 3),
        "an unwired client's calls were not refused: {:?}",
        r.figures("c")
    );
    r.down_and_check_clean();
}

/// Calls past the client's bound of calls in flight are refused with
/// nothing sent, and every call sent is answered.
#[test]
fn a_thousand_calls_at_once_are_refused_past_the_bound_and_the_rest_answered() {
    let r = wired("call-bound", &["--burst", "1000", "--max", "64", "--timeout-ms", "5000"]);
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("c", "answered") >= 64),
        "the 64 calls in flight were not all answered: {:?}",
        r.figures("c")
    );
    let c = r.figures("c");
    let get = |k: &str| c.get(k).and_then(|v| v.parse::<u64>().ok()).unwrap_or_else(|| panic!("figure {k}: {c:?}"));
    assert_eq!((get("sent"), get("refused"), get("answered"), get("wrong")), (64, 936, 64, 0), "{c:?}");
    assert_eq!(r.figure_u64("s", "answered"), 64, "the server answered calls that were refused: {:?}", r.figures("s"));
    r.down_and_check_clean();
}

/// A server killed with calls in flight: each call ends with an error in
/// bounded time (its timeout at most), the client runs on; the server
/// started again is wired again by the router and answers.
#[test]
fn a_killed_server_ends_the_calls_in_bounded_time_and_a_restarted_one_is_rewired() {
    let r = wired("call-kill", &["--timeout-ms", "400"]);
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("c", "answered") >= 5),
        "no answers before the kill: {:?}",
        r.figures("c")
    );
    let count = |r: &Robot, keys: &[&str]| {
        let c = r.figures("c");
        keys.iter().map(|k| c.get(*k).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0)).sum::<u64>()
    };
    // a server that holds the calls (suspended, it never steps): they time out
    r.ok(&["suspend", "s"]);
    assert!(
        wait_until(Duration::from_secs(10), || count(&r, &["timed_out"]) >= 1),
        "a call to a held server did not time out: {:?}",
        r.figures("c")
    );
    // killed with a call in flight: that call and the next end in an error
    let failed = count(&r, &["timed_out", "gone", "no_server"]);
    nerve_tests::sigkill(r.pid("s"));
    assert!(
        wait_until(Duration::from_secs(10), || count(&r, &["timed_out", "gone", "no_server"]) >= failed + 2),
        "calls to a killed server did not fail: {:?}",
        r.figures("c")
    );
    // the client's task runs on
    let steps = r.figure_u64("c", "steps");
    assert!(
        wait_until(Duration::from_secs(5), || r.figure_u64("c", "steps") > steps + 10),
        "the client stopped stepping: {:?}",
        r.figures("c")
    );
    // started again under its name: the router wires the client to it again
    r.ok(&["start", "caller", "--name", "s", "--", "--serve"]);
    // (the router re-applies the suspend it was last told: resumed by hand)
    r.ok(&["resume", "s"]);
    let answered = r.figure_u64("c", "answered");
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("c", "answered") >= answered + 5),
        "the restarted server did not answer: {:?}",
        r.figures("c")
    );
    assert_eq!(r.figure("c", "wrong"), "0");
    r.down_and_check_clean();
}

/// `[[connect]]` in a launch file wires a client to a service (written
/// client first, as on the command line), checked before anything starts:
/// a client wired to an output (another type) is refused.
#[test]
fn a_launch_file_wires_a_client_and_refuses_one_wired_to_an_output() {
    let r = Robot::new("call-launch");
    let agents = r#"
[[agent]]
name = "s"
kind = "caller"
args = ["--serve"]

[[agent]]
name = "c"
kind = "caller"

[[agent]]
name = "v"
kind = "testagent"
"#;
    let launch = |file: &std::path::Path| r.command("nerve").arg("launch").arg(file).output().expect("nerve launch");
    let bad = r.launch_file("bad.toml", &format!("{agents}\n[[connect]]\nfrom = \"v/value\"\nto = \"c/planner\"\n"));
    let out = launch(&bad);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("nothing was started"), "{err}");
    assert!(err.contains("call(nerve::Tick -> nerve::Scalar)") && err.contains("nerve::Scalar"), "{err}");
    r.ok(&["down"]);
    let good = r.launch_file("good.toml", &format!("{agents}\n[[connect]]\nfrom = \"c/planner\"\nto = \"s/plan\"\n"));
    let out = launch(&good);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(r.edges(), ["s/plan -> c/planner"]);
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("c", "answered") >= 5),
        "no answers through the launch file's wire: {:?}",
        r.figures("c")
    );
    r.down_and_check_clean();
}

/// `nerve call AGENT/SERVICE '<json>'` against a Rust server: the answer
/// printed as JSON; a bad field, an unknown service and a server that does
/// not answer (suspended) each refused with a message that says so.
#[test]
fn nerve_call_prints_the_answer_and_says_why_when_there_is_none() {
    let r = Robot::new("call-cli");
    r.router();
    r.ok(&["start", "caller", "--name", "s", "--", "--serve"]);
    let out = r.ok(&["call", "s/plan", r#"{"seq": 21}"#]);
    let answer: serde_json::Value = serde_json::from_str(&out).expect("the answer as JSON");
    assert_eq!(answer["value"].as_f64(), Some(42.0), "{out}");
    let err = r.fails(&["call", "s/plan", r#"{"seq": 1, "sequence": 2}"#]);
    assert!(err.contains("sequence"), "an unknown field: {err}");
    let err = r.fails(&["call", "s/nonesuch", r#"{"seq": 1}"#]);
    assert!(err.contains("no service \"nonesuch\""), "an unknown service: {err}");
    r.ok(&["suspend", "s"]);
    let err = r.fails(&["call", "s/plan", r#"{"seq": 1}"#, "--timeout", "300ms"]);
    assert!(err.contains("no answer") && err.contains("300ms"), "a server that does not answer: {err}");
    r.down_and_check_clean();
}

/// A robot with a router and a server `s` answering `plan` with sequences
/// (`Seq<Scalar, Tick>`) of at most `max_len` scalars.
fn seq_server(tag: &str, max_len: &str) -> Robot {
    let r = Robot::new(tag);
    r.router();
    r.ok(&["start", "caller", "--name", "s", "--", "--serve", "--seq", "--max-len", max_len]);
    r
}

/// `nerve call` against a server answering with sequences: answers of
/// length 0, 1 and 600 (the maximum, 9.6 kB) printed as JSON arrays, whole,
/// each call by a new client (a new `nerve call` process); one past the maximum refused,
/// saying so on both sides; the next call answered again.
#[test]
fn a_sequence_answer_of_any_length_is_printed_and_one_past_the_maximum_refused() {
    let r = seq_server("call-seq-cli", "600");
    for n in [0u64, 1, 600] {
        let out = r.ok(&["call", "s/plan", &format!(r#"{{"seq": {n}, "stamp_ns": 5}}"#)]);
        let answer: serde_json::Value = serde_json::from_str(&out).expect("the answer as JSON");
        assert_eq!(answer["header"]["seq"].as_u64(), Some(n), "{out}");
        let items = answer["items"].as_array().unwrap_or_else(|| panic!("no array of items: {out}"));
        assert_eq!(items.len() as u64, n, "{out}");
        for (i, item) in items.iter().enumerate() {
            assert_eq!((item["value"].as_f64(), item["stamp_ns"].as_u64()), (Some(i as f64), Some(5)), "{out}");
        }
    }
    let err = r.fails(&["call", "s/plan", r#"{"seq": 601}"#]);
    assert!(err.contains("refused") && err.contains("601") && err.contains("600"), "past the maximum: {err}");
    assert!(
        wait_until(Duration::from_secs(5), || r.figure_u64("s", "too_long") == 1),
        "the server did not count its refusal: {:?}",
        r.figures("s")
    );
    let out = r.ok(&["call", "s/plan", r#"{"seq": 2}"#]);
    assert!(out.contains("items"), "{out}");
    // the refusal is counted apart (`serve` returned it), the four answers as answered
    assert!(wait_until(Duration::from_secs(5), || r.figure_u64("s", "answered") == 4), "{:?}", r.figures("s"));
    r.down_and_check_clean();
}

/// An agent calls a sequence server through the router: answers of
/// lengths 0 to 399 taken whole, the wire and its type in the graph; a
/// client of a fixed answer wired to it is refused, naming both types; the
/// server killed with calls in flight ends them as failed, the client runs on.
#[test]
fn an_agent_takes_sequence_answers_and_a_killed_server_ends_its_calls() {
    let r = seq_server("call-seq", "1000");
    r.ok(&["start", "caller", "--name", "c", "--", "--seq", "--timeout-ms", "400"]);
    r.ok(&["connect", "c/planner", "s/plan"]);
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("c", "answered") >= 20),
        "the client had no 20 answers: {:?}",
        r.figures("c")
    );
    let c = r.figures("c");
    assert_eq!(
        (c.get("wrong").map(String::as_str), c.get("other").map(String::as_str)),
        (Some("0"), Some("0")),
        "{c:?}"
    );
    assert_eq!(r.edges(), ["s/plan -> c/planner"]);
    let graph = r.graph().to_string();
    assert!(graph.contains("call(nerve::Tick -> nerve::Seq<nerve::Scalar, nerve::Tick>)"), "{graph}");
    // a fixed client of the same request: another call, refused
    r.ok(&["start", "caller", "--name", "f"]);
    let err = r.fails(&["connect", "f/planner", "s/plan"]);
    assert!(
        err.contains("call(nerve::Tick -> nerve::Scalar)")
            && err.contains("call(nerve::Tick -> nerve::Seq<nerve::Scalar, nerve::Tick>)"),
        "a fixed client wired to a sequence server: {err}"
    );
    let count = |keys: &[&str]| {
        let c = r.figures("c");
        keys.iter().map(|k| c.get(*k).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0)).sum::<u64>()
    };
    let failed = count(&["timed_out", "gone", "no_server"]);
    nerve_tests::sigkill(r.pid("s"));
    assert!(
        wait_until(Duration::from_secs(10), || count(&["timed_out", "gone", "no_server"]) >= failed + 2),
        "calls to a killed sequence server did not fail: {:?}",
        r.figures("c")
    );
    let steps = r.figure_u64("c", "steps");
    assert!(
        wait_until(Duration::from_secs(5), || r.figure_u64("c", "steps") > steps + 10),
        "the client stopped stepping: {:?}",
        r.figures("c")
    );
    r.down_and_check_clean();
}
