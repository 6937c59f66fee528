//! Loops in the wiring (reliability review F3c, F3d): a connection that
//! closes a loop of event-driven agents is refused with the loop named, by
//! the router (`nerve connect`) and by the launch-file check (before
//! anything starts), unless it is allowed explicitly. A periodic agent on
//! the way breaks the loop and is no reason to refuse.

use nerve_tests::Robot;

fn relays(n: usize) -> String {
    let mut s = String::from("robot = \"x\"\n");
    for i in 1..=n {
        s.push_str(&format!("\n[[agent]]\nname = \"r{i}\"\nkind = \"relay\"\n"));
    }
    s
}

#[test]
fn connect_refuses_a_loop_of_event_driven_agents_unless_allowed() {
    let r = Robot::new("loops");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "100ms"]);
    for n in ["r1", "r2"] {
        r.ok(&["start", "relay", "--name", n]);
    }
    let e = r.fails(&["connect", "r1/out", "r1/in"]);
    assert!(e.contains("closes a loop of event-driven agents (r1 -> r1)") && e.contains("--allow-cycle"), "{e}");
    r.ok(&["connect", "r1/out", "r2/in"]);
    let e = r.fails(&["connect", "r2/out", "r1/in"]);
    assert!(e.contains("(r2 -> r1 -> r2)"), "{e}");
    // nothing feeds the two relays: allowing the loop spins nothing here
    r.ok(&["connect", "--allow-cycle", "r2/out", "r1/in"]);
    assert_eq!(r.graph()["connections"].as_array().map(|c| c.len()), Some(2));
    // a loop through an allowed edge is allowed, whichever edge comes last
    r.ok(&["disconnect", "r2/out", "r1/in"]);
    r.ok(&["disconnect", "r1/out", "r2/in"]);
    r.ok(&["connect", "--allow-cycle", "r1/out", "r2/in"]);
    r.ok(&["connect", "r2/out", "r1/in"]);
    // but not a second loop beside it
    r.ok(&["start", "relay", "--name", "r3"]);
    r.ok(&["connect", "r1/out", "r3/in"]);
    let e = r.fails(&["connect", "r3/out", "r1/in"]);
    assert!(e.contains("(r3 -> r1 -> r3)"), "{e}");
    r.down_and_check_clean();
}

#[test]
fn a_launch_file_with_a_loop_is_refused_before_anything_starts_unless_allowed() {
    let r = Robot::new("loopslf");
    let body = format!(
        "{}\n[[connect]]\nfrom = \"r1/out\"\nto = \"r2/in\"\n\n[[connect]]\nfrom = \"r2/out\"\nto = \"r1/in\"\n",
        relays(2)
    );
    let file = r.launch_file("loop.toml", &body);
    let e = r.fails(&["launch", file.to_str().expect("utf-8 path")]);
    assert!(e.contains("loop.toml:16:") && e.contains("closes a loop of event-driven agents (r2 -> r1 -> r2)"), "{e}");
    assert!(e.contains("allow_cycle = true"), "{e}");
    assert!(!r.nerve(&["ps"]).status.success(), "nothing started, not even the router");

    let allowed = body.replacen("to = \"r1/in\"\n", "to = \"r1/in\"\nallow_cycle = true\n", 1);
    let file = r.launch_file("loop-allowed.toml", &allowed);
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    assert_eq!(r.graph()["connections"].as_array().map(|c| c.len()), Some(2));
    r.down_and_check_clean();
}
