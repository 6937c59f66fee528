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

/// A connect still waiting for its agent counts: `nerve launch` asks for a
/// file's connections side by side, and two of them must not close a loop
/// between them unseen. Here the first waits because its agent is stopped
/// (SIGSTOP) until the second has been refused.
#[test]
fn a_loop_closed_with_a_connect_still_in_flight_is_refused() {
    let r = Robot::new("loopsfl");
    r.router();
    for n in ["r1", "r2"] {
        r.ok(&["start", "relay", "--name", n]);
    }
    let r2 = r.pid("r2");
    // SAFETY: kill has no memory-safety preconditions.
    unsafe { libc::kill(r2 as i32, libc::SIGSTOP) };
    let first = std::thread::scope(|s| {
        let pending = s.spawn(|| r.command("nerve").args(["connect", "r1/out", "r2/in"]).output());
        // the first is in flight (its agent cannot answer) for all of this
        std::thread::sleep(std::time::Duration::from_millis(200));
        let e = r.fails(&["connect", "r2/out", "r1/in"]);
        // SAFETY: as above
        unsafe { libc::kill(r2 as i32, libc::SIGCONT) };
        assert!(e.contains("closes a loop of event-driven agents (r2 -> r1 -> r2)"), "{e}");
        pending.join().expect("the first connect")
    });
    let first = first.expect("run nerve connect");
    assert!(first.status.success(), "the first connect: {}", String::from_utf8_lossy(&first.stderr));
    assert_eq!(r.graph()["connections"].as_array().map(|c| c.len()), Some(1));
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

/// The scheduling policy of the thread named `task` of process `pid`
/// (0 SCHED_OTHER, 1 SCHED_FIFO; field 41 of its stat).
fn task_policy(pid: u32) -> Option<u32> {
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).ok()?;
    for t in tasks.filter_map(|e| e.ok()) {
        let comm = std::fs::read_to_string(t.path().join("comm")).unwrap_or_default();
        if comm.trim() == "task" {
            let stat = std::fs::read_to_string(t.path().join("stat")).ok()?;
            let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
            // fields after the command start at field 3
            return fields.get(41 - 3)?.parse().ok();
        }
    }
    None
}

/// An allowed loop fed from outside is an event storm: the relays' tasks,
/// under SCHED_FIFO, would take the CPUs from everything else (review F3c:
/// load 10.6 on two cores, `ps` 7 s, `down` 25 s). The guard demotes a
/// task that holds a whole CPU for 2 s to SCHED_OTHER, says so in its log,
/// and the robot stays usable.
#[test]
fn a_real_time_task_in_an_event_storm_is_demoted() {
    let r = Robot::new("storm");
    r.router();
    // real-time is what this is about: without the permission, nothing to test
    r.ok(&["start", "relay", "--name", "r1"]);
    let pid = r.pid("r1");
    if task_policy(pid) != Some(1) {
        eprintln!("not run: the relay's task did not get SCHED_FIFO here");
        return;
    }
    r.ok(&["start", "ticker", "--name", "t1", "--period", "50ms"]);
    r.ok(&["connect", "t1/tick", "r1/in"]);
    r.ok(&["connect", "--allow-cycle", "r1/out", "r1/in"]);
    let log = r.home.join(&r.name).join("logs").join("r1.log");
    let demoted = nerve_tests::wait_until(std::time::Duration::from_secs(20), || {
        std::fs::read_to_string(&log).is_ok_and(|l| l.contains("demoted to SCHED_OTHER"))
    });
    assert!(demoted, "no demotion in {}", log.display());
    assert_eq!(task_policy(pid), Some(0), "the task thread runs under SCHED_OTHER");
    assert_eq!(
        r.agent("r1").map(|a| a["stats"]["realtime"].clone()),
        Some(serde_json::Value::Bool(false)),
        "ps says so"
    );
    // the robot is still usable: undo the loop, and the storm ends
    r.ok(&["disconnect", "r1/out", "r1/in"]);
    r.down_and_check_clean();
}
