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
    r.down_and_check_clean();
}
