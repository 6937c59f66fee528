//! The core runtime, end to end: real processes, real shared memory.
//! Data flows, rewiring, rates, suspend/resume, hot add, crashes of agents and
//! of the router, refusals with clear errors, and nothing left behind.

use nerve_tests::{Robot, alive, process_state, sigkill, wait_until};
use serde_json::Value;
use std::time::Duration;

/// UTC seconds since midnight, as the log lines print them.
fn seconds_of_day() -> f64 {
    let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    (t.as_secs() % 86_400) as f64 + t.subsec_nanos() as f64 / 1e9
}

/// The time stamp `HH:MM:SS.mmm` at the start of a log line, in seconds since midnight.
fn log_seconds_of_day(line: &str) -> f64 {
    let stamp = line.split_whitespace().next().unwrap_or("");
    let parts: Vec<f64> = stamp.split(':').filter_map(|p| p.parse().ok()).collect();
    assert_eq!(parts.len(), 3, "no time stamp in {line:?}");
    parts[0] * 3600.0 + parts[1] * 60.0 + parts[2]
}

fn rate_of(r: &Robot, name: &str) -> f64 {
    r.agent(name).and_then(|a| a["stats"]["rate_hz"].as_f64()).unwrap_or(0.0)
}

fn connection<'a>(g: &'a Value, from: &str, to: &str) -> Option<&'a Value> {
    g["connections"].as_array()?.iter().find(|c| c["from"] == from && c["to"] == to)
}

/// ticker → relay → echo, and `nerve down` leaves nothing.
#[test]
fn data_flows_ticker_relay_echo() {
    let r = Robot::new("flow");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "relay", "--name", "r1"]);
    r.ok(&["connect", "t1/tick", "r1/in"]);
    let samples = r.echo("r1/out", 5);
    assert_eq!(samples.len(), 5);
    let mut last = 0;
    for s in &samples {
        assert_eq!(s["from"], "r1", "sample header names the relay as sender: {s}");
        assert_eq!(s["type"], "nerve::Tick");
        let seq = s["data"]["seq"].as_u64().expect("tick seq");
        assert!(seq > last, "ticks arrive in order: {samples:?}");
        last = seq;
    }
    // the graph shows the live connection with figures
    assert!(wait_until(Duration::from_secs(3), || {
        let g = r.graph();
        connection(&g, "t1/tick", "r1/in")
            .is_some_and(|c| c["active"] == true && c["received"].as_u64().unwrap_or(0) > 0)
    }));
    let dot = r.ok(&["graph", "--dot"]);
    assert!(dot.contains("\"t1\" -> \"r1\""), "{dot}");
    r.down_and_check_clean();
}

/// Rewiring at run time switches the source without restarting either agent.
#[test]
fn rewire_switches_source_without_restart() {
    let r = Robot::new("rewire");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "ticker", "--name", "t2", "--period", "10ms"]);
    r.ok(&["param", "set", "t2", "step", "1000"]);
    r.ok(&["start", "relay", "--name", "r1"]);
    r.ok(&["connect", "t1/tick", "r1/in"]);
    r.echo("r1/out", 2);
    let (pid_r1, pid_t1) = (r.pid("r1"), r.pid("t1"));

    r.ok(&["disconnect", "t1/tick", "r1/in"]);
    r.ok(&["connect", "t2/tick", "r1/in"]);
    // after the switch, ticks come in steps of 1000 (t2's `step`)
    assert!(wait_until(Duration::from_secs(5), || {
        let s = r.echo("r1/out", 3);
        s.windows(2)
            .all(|w| w[1]["data"]["seq"].as_u64().unwrap_or(0) - w[0]["data"]["seq"].as_u64().unwrap_or(0) == 1000)
    }));
    assert_eq!(r.pid("r1"), pid_r1, "the relay was not restarted");
    assert_eq!(r.pid("t1"), pid_t1, "the old source was not restarted");
    let g = r.graph();
    assert!(connection(&g, "t1/tick", "r1/in").is_none());
    assert!(connection(&g, "t2/tick", "r1/in").is_some());
    r.down_and_check_clean();
}

/// `connect` and `disconnect` answer once the connection list is on disk
/// (in its journal, the file itself right after), and say so when it could
/// not be saved (review R11a: both were answered before the save, and a
/// failed save was only logged).
#[test]
fn rewiring_is_acknowledged_once_saved_and_a_failed_save_is_reported() {
    let r = Robot::new("durable");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "relay", "--name", "r1"]);
    let list = r.home.join(&r.name).join("connections.json");
    let journal = r.home.join(&r.name).join("connections.json.journal");
    // what a router started now would load: the journal's last record, else the file
    let on_disk = || {
        let j = std::fs::read(&journal).unwrap_or_default();
        let f = std::fs::read(&list).unwrap_or_default();
        (String::from_utf8_lossy(&j).into_owned(), String::from_utf8_lossy(&f).into_owned())
    };
    r.ok(&["connect", "t1/tick", "r1/in"]);
    let (j, f) = on_disk();
    assert!(
        (j.contains("t1/tick") && j.contains("r1/in")) || (f.contains("t1/tick") && f.contains("r1/in")),
        "the list is on disk once connect answered: journal {j:?}, file {f:?}"
    );
    // and the file follows
    assert!(
        wait_until(Duration::from_secs(5), || std::fs::read_to_string(&list).is_ok_and(|s| s.contains("r1/in"))),
        "the file never got the list"
    );
    // the journal cannot be written any more, nor removed: a folder stands in its place
    let _ = std::fs::remove_file(&journal);
    std::fs::create_dir(&journal).expect("mkdir");
    let err = r.fails(&["disconnect", "t1/tick", "r1/in"]);
    assert!(
        err.contains("disconnected t1/tick -> r1/in, but the connection list") && err.contains("could not be saved"),
        "{err}"
    );
    // the change itself holds
    assert!(connection(&r.graph(), "t1/tick", "r1/in").is_none());
    std::fs::remove_dir(&journal).expect("rmdir");
    r.ok(&["connect", "t1/tick", "r1/in"]);
    assert!(
        wait_until(Duration::from_secs(5), || std::fs::read_to_string(&list).is_ok_and(|s| s.contains("t1/tick"))),
        "saved again once the journal could be written"
    );
    r.down_and_check_clean();
}

/// A period change shows in the measured rate; suspend stops output, resume restarts it.
#[test]
fn period_change_and_suspend_resume() {
    let r = Robot::new("rate");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    assert!(
        wait_until(Duration::from_secs(5), || (80.0..120.0).contains(&rate_of(&r, "t1"))),
        "rate {}",
        rate_of(&r, "t1")
    );
    r.ok(&["rate", "t1", "50ms"]);
    assert!(
        wait_until(Duration::from_secs(6), || (16.0..24.0).contains(&rate_of(&r, "t1"))),
        "rate {}",
        rate_of(&r, "t1")
    );
    assert_eq!(r.agent("t1").and_then(|a| a["period_ns"].as_u64()), Some(50_000_000));

    r.ok(&["suspend", "t1"]);
    assert_eq!(r.agent("t1").map(|a| a["state"].clone()), Some("suspended".into()));
    let err = r.fails(&["echo", "t1/tick", "--count", "1", "--timeout", "1"]);
    assert!(err.contains("no sample"), "{err}");
    r.ok(&["resume", "t1"]);
    assert_eq!(r.echo("t1/tick", 1).len(), 1);
    assert_eq!(r.agent("t1").map(|a| a["state"].clone()), Some("running".into()));
    r.down_and_check_clean();
}

/// `nerve rate` takes effect at once: a shorter period does not wait for
/// the long sleep in force to end, and an absurd period is refused, not
/// wrapped (review F3a, R7).
#[test]
fn a_new_period_takes_effect_at_once_and_absurd_ones_are_refused() {
    let r = Robot::new("ratebig");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    assert!(!r.echo("t1/tick", 1).is_empty());
    r.ok(&["rate", "t1", "30s"]);
    std::thread::sleep(Duration::from_millis(300));
    let cycles = |r: &Robot| r.agent("t1").and_then(|a| a["stats"]["cycles"].as_u64()).unwrap_or(0);
    let before = cycles(&r);
    r.ok(&["rate", "t1", "10ms"]);
    assert!(
        wait_until(Duration::from_secs(3), || cycles(&r) > before + 20),
        "the 10 ms period waited for the 30 s sleep (cycles {} -> {})",
        before,
        cycles(&r)
    );
    for bad in ["18446744074s", "99999999999999999999ms", "2days"] {
        let err = r.fails(&["rate", "t1", bad]);
        assert!(err.contains("1 day") || err.contains("unknown unit"), "{bad}: {err}");
    }
    assert_eq!(r.agent("t1").and_then(|a| a["period_ns"].as_u64()), Some(10_000_000));
    for (args, what) in [
        (vec!["echo", "t1/tick", "--timeout", "nan"], "nan"),
        (vec!["echo", "t1/tick", "--timeout", "-1"], "-1"),
        (vec!["down", "--grace", "inf"], "inf"),
    ] {
        let out = r.nerve(&args);
        assert_eq!(out.status.code(), Some(2), "{what}: {}", String::from_utf8_lossy(&out.stderr));
    }
    r.down_and_check_clean();
}

/// `nerve start --param` sets a parameter before the task starts, and
/// `nerve param list` shows every parameter with its type, value, default and
/// what the agent allows (issue 15: what a new user tripped on).
#[test]
fn parameters_are_set_at_start_and_listed() {
    let r = Robot::new("params");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms", "--param", "step=3"]);
    let ticks = r.echo("t1/tick", 3);
    let seqs: Vec<u64> = ticks.iter().filter_map(|t| t["data"]["seq"].as_u64()).collect();
    assert!(seqs.len() == 3 && seqs.windows(2).all(|w| w[1] == w[0] + 3), "step 3 from the start: {seqs:?}");
    let table = r.ok(&["param", "list", "t1"]);
    let row = table.lines().find(|l| l.starts_with("step ")).unwrap_or_else(|| panic!("no step row:\n{table}"));
    let cells: Vec<&str> = row.split_whitespace().collect();
    assert_eq!(&cells[..4], ["step", "u64", "3", "1"], "key, type, value, default:\n{table}");
    assert!(row.contains("step is in [1, 1000000]"), "the allowed range:\n{table}");
    let json: Value = serde_json::from_str(&r.ok(&["param", "list", "t1", "--json"])).expect("param list --json");
    let step = json.as_array().and_then(|a| a.iter().find(|p| p["key"] == "step")).expect("step in the JSON");
    assert_eq!(
        (&step["value"], &step["default"], &step["read_only"]),
        (&Value::from("3"), &Value::from("1"), &Value::from(false))
    );
    r.ok(&["param", "set", "t1", "step", "7"]);
    assert!(r.ok(&["param", "list", "t1"]).lines().any(|l| l.split_whitespace().take(4).eq(["step", "u64", "7", "1"])));
    // refused values and keys, with what to do
    let err = r.fails(&["start", "ticker", "--name", "t2", "--param", "step=0"]);
    assert!(err.contains("step is in [1, 1000000]"), "{err}");
    let err = r.fails(&["start", "ticker", "--name", "t2", "--param", "step"]);
    assert!(err.contains("KEY=VALUE"), "{err}");
    let err = r.fails(&["param", "list", "nobody"]);
    assert!(err.contains("nobody"), "{err}");
    r.down_and_check_clean();
}

/// A rejected duplicate leaves the live agent's pid file alone, so `nerve
/// down` still stops the agent with the router gone (review R15, F3f).
#[test]
fn a_rejected_duplicate_keeps_the_live_agents_pid_file() {
    let r = Robot::new("dup");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    let pid = r.pid("t1");
    kill_and_wait(pid_file(&r, "router").expect("router pid file"));
    let err = r.fails(&["start", "ticker", "--name", "t1"]);
    assert!(err.contains("already running"), "{err}");
    assert_eq!(pid_file(&r, "t1"), Some(pid), "the duplicate removed or replaced the live agent's pid file");
    r.down_and_check_clean();
    assert!(
        wait_until(Duration::from_secs(5), || {
            nerve_tests::reap();
            !nerve_tests::alive(pid)
        }),
        "nerve down left t1 running"
    );
}

/// An agent killed while no router runs (nobody cleans up after it) starts
/// again under its name: the control server its killed run left in shared
/// memory is cleaned, not taken for a live duplicate (iceoryx2 no longer
/// scans a service's nodes on every open, `World::new`). `nerve start`
/// has the router start the agent, so it starts a router first, which
/// cleans up after the dead at its start.
#[test]
fn an_agent_killed_with_no_router_starts_again_under_its_name() {
    let r = Robot::new("relive");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    let pid = r.pid("t1");
    for victim in [pid_file(&r, "router").expect("router pid file"), pid] {
        kill_and_wait(victim);
    }
    let out = r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    assert!(out.contains("t1 started"), "{out}");
    assert_ne!(r.pid("t1"), pid, "a new t1");
    // and it works: the new router lists it, and it publishes
    assert!(wait_until(Duration::from_secs(5), || r.agent("t1").is_some()), "the new router does not list t1");
    assert_eq!(r.echo("t1/tick", 1).len(), 1);
    r.down_and_check_clean();
}

/// A command sent to a killed router says that no router runs, instead of
/// sending its request to the server port the killed router left in shared
/// memory and waiting out its time-out: a client that finds only dead
/// servers cleans up after them first (`ControlClient::open`).
#[test]
fn a_killed_router_is_reported_as_no_router() {
    let r = Robot::new("deadrt");
    r.router();
    // a live agent keeps the router's services in shared memory
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    kill_and_wait(pid_file(&r, "router").expect("router pid file"));
    let e = r.fails(&["ps"]);
    assert!(e.contains("no router runs"), "{e}");
    r.down_and_check_clean();
}

/// The pid in `r`'s pid file of `name`.
fn pid_file(r: &Robot, name: &str) -> Option<u32> {
    let f = r.home.join(&r.name).join("pids").join(format!("{name}.pid"));
    std::fs::read_to_string(f).ok().and_then(|s| s.trim().parse().ok())
}

/// SIGKILL, then waits (5 s at most) until `pid` is gone.
fn kill_and_wait(pid: u32) {
    sigkill(pid);
    assert!(
        wait_until(Duration::from_secs(5), || {
            nerve_tests::reap();
            !alive(pid)
        }),
        "process {pid} survived SIGKILL"
    );
}

/// A SIGTERM that other signals follow at once still stops agents and the
/// router. systemd stops a unit with SIGTERM and then SIGCONT; iceoryx2's
/// handler kept only the last signal it caught, so the SIGCONT (or a
/// SIGURG) could hide the SIGTERM and the process ran on until SIGKILL:
/// the router every time it was stopped as they came, three agents in
/// eight, seven in eight with a SIGURG between (see
/// `agent_sdk::termination`). The signals are sent while the process is
/// stopped (SIGSTOP), so that they all arrive together when SIGCONT
/// resumes it.
#[test]
fn a_sigterm_that_other_signals_follow_still_stops_agents_and_the_router() {
    let r = Robot::new("sigterm");
    r.router();
    let names = ["s1", "s2", "s3", "s4", "s5", "s6"];
    for n in names {
        r.ok(&["start", "relay", "--name", n]);
    }
    for (i, n) in names.iter().enumerate() {
        let pid = r.pid(n);
        let between: &[i32] = if i % 2 == 0 { &[libc::SIGURG] } else { &[] };
        signal_while_stopped(pid, libc::SIGTERM, between);
        let stopped = wait_until(Duration::from_secs(3), || {
            nerve_tests::reap();
            !alive(pid)
        });
        let log = r.ok(&["logs", n]);
        assert!(stopped, "{n} ran on after SIGTERM: {log}");
        assert!(log.contains("termination requested by signal"), "{n} did not stop cleanly: {log}");
    }
    let router = pid_file(&r, "router").expect("router pid file");
    signal_while_stopped(router, libc::SIGTERM, &[]);
    let stopped = wait_until(Duration::from_secs(3), || {
        nerve_tests::reap();
        !alive(router)
    });
    if !stopped {
        sigkill(router);
    }
    assert!(stopped, "the router ran on after SIGTERM");
    r.down_and_check_clean();

    // the same flag ends a command on Ctrl-C, and job control is left to
    // the shell: iceoryx2's handler, installed first, would swallow Ctrl-Z
    let r = Robot::new("sigtstp");
    r.router();
    let mut follow = r
        .command("nerve")
        .args(["logs", "router", "--follow"])
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("start nerve logs --follow");
    let pid = follow.id();
    let state = || process_state(pid);
    // it has caught Ctrl-C once its first lines are out; give it a moment
    std::thread::sleep(Duration::from_millis(300));
    // SAFETY: kill has no memory-safety preconditions.
    unsafe { libc::kill(pid as i32, libc::SIGTSTP) };
    let suspended = wait_until(Duration::from_secs(2), || state().as_deref() == Some("T"));
    // SAFETY: as above.
    unsafe {
        libc::kill(pid as i32, libc::SIGCONT);
        libc::kill(pid as i32, libc::SIGINT);
    }
    let ended = wait_until(Duration::from_secs(3), || follow.try_wait().ok().flatten().is_some());
    if !ended {
        let _ = follow.kill();
        let _ = follow.wait();
    }
    assert!(suspended, "Ctrl-Z (SIGTSTP) did not suspend `nerve logs --follow`: state {:?}", state());
    assert!(ended, "Ctrl-C (SIGINT) did not end `nerve logs --follow`");
    r.down_and_check_clean();
}

/// Stops `pid`, sends it `first` and then `between`, and resumes it with
/// SIGCONT: the process finds them all pending at once.
fn signal_while_stopped(pid: u32, first: i32, between: &[i32]) {
    // SAFETY: kill has no memory-safety preconditions.
    unsafe { libc::kill(pid as i32, libc::SIGSTOP) };
    assert!(
        wait_until(Duration::from_secs(2), || process_state(pid).as_deref() == Some("T")),
        "process {pid} did not stop"
    );
    for sig in std::iter::once(&first).chain(between).chain(std::iter::once(&libc::SIGCONT)) {
        // SAFETY: as above.
        unsafe { libc::kill(pid as i32, *sig) };
    }
}

/// An agent whose own `start` fails makes `nerve start` fail with its
/// reason, instead of saying "started" and vanishing (review R19).
#[test]
fn a_failed_start_is_a_failed_nerve_start() {
    let r = Robot::new("failst");
    r.router();
    let err = r.fails(&["start", "testagent", "--name", "bad", "--", "--mode", "fail-start"]);
    assert!(err.contains("could not start") && err.contains("/dev/ttyNOPE"), "{err}");
    assert!(r.agent("bad").is_none_or(|a| a["state"] != "running"), "listed as running");
    r.down_and_check_clean();
}

/// An agent added while others run joins the graph.
#[test]
fn hot_added_agent_joins_graph() {
    let r = Robot::new("hotadd");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "relay", "--name", "r1"]);
    r.ok(&["connect", "t1/tick", "r1/in"]);
    r.echo("r1/out", 1);
    r.ok(&["start", "relay", "--name", "r2"]);
    r.ok(&["connect", "r1/out", "r2/in"]);
    let s = r.echo("r2/out", 3);
    assert!(s.iter().all(|x| x["from"] == "r2"));
    let names: Vec<String> = r.ps().iter().map(|a| a["name"].as_str().unwrap_or("").to_owned()).collect();
    assert_eq!(names, ["r1", "r2", "t1"]);
    r.down_and_check_clean();
}

/// SIGKILL of an agent: others run on, the router reports it gone within 1 s,
/// and restarting it under the same name restores its connections.
#[test]
fn killed_agent_is_noticed_and_rewired_on_restart() {
    let r = Robot::new("kill");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "relay", "--name", "r1"]);
    r.ok(&["start", "relay", "--name", "r2"]);
    r.ok(&["connect", "t1/tick", "r1/in"]);
    r.ok(&["connect", "r1/out", "r2/in"]);
    r.echo("r2/out", 1);
    let victim = r.pid("r1");
    let t1 = r.pid("t1");
    let killed_at = seconds_of_day();
    sigkill(victim);
    assert!(wait_until(Duration::from_secs(10), || r.agent("r1").is_none()), "router still lists r1");
    // the router's own detection time, from its log (the CLI's latency under load is not the router's)
    let log = r.ok(&["logs", "router"]);
    let line =
        log.lines().find(|l| l.contains(&format!("agent r1 (pid {victim}) died"))).expect("router logs the death");
    let noticed = log_seconds_of_day(line) - killed_at;
    assert!(noticed < 1.0, "the router took {noticed:.3} s to notice the dead agent: {line}");
    assert!(alive(t1), "the ticker survives");
    assert_eq!(r.echo("t1/tick", 1).len(), 1, "the ticker still publishes");
    // connections are kept and restored for the restarted agent: t1 -> r1 -> r2
    r.ok(&["start", "relay", "--name", "r1"]);
    let s = r.echo("r2/out", 3);
    assert_eq!(s.len(), 3);
    let g = r.graph();
    assert!(connection(&g, "t1/tick", "r1/in").is_some_and(|c| c["active"] == true));
    // r1's own input came in the reply to its registration (protocol 7),
    // r2's as a command the router sent r2
    let log = r.ok(&["logs", "router"]);
    assert!(
        log.contains("rewiring t1/tick -> r1/in: handed to r1 with its registration"),
        "the router did not hand r1 its input's connection: {log}"
    );
    assert!(log.contains("rewired r1/out -> r2/in"), "the router did not send r2 its connection: {log}");
    let r1_log = r.ok(&["logs", "r1"]);
    assert_eq!(
        r1_log.matches("input in now reads t1/tick").count(),
        2,
        "r1 (twice started) did not connect its input each time: {r1_log}"
    );
    r.down_and_check_clean();
}

/// SIGKILL of the router leaves data flowing; a restarted router lists the
/// same agents and connections.
#[test]
fn router_crash_keeps_data_flowing_and_restart_restores() {
    let r = Robot::new("router");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "relay", "--name", "r1"]);
    r.ok(&["connect", "t1/tick", "r1/in"]);
    r.echo("r1/out", 1);
    let router_pid = r.pid_file("router").expect("router pid file");
    sigkill(router_pid);
    assert!(wait_until(Duration::from_secs(2), || !alive(router_pid)));
    // data keeps flowing with no router
    let s = r.echo("r1/out", 5);
    assert_eq!(s.len(), 5);
    // a new router: agents re-register by themselves, the connection list is back
    r.router();
    assert!(wait_until(Duration::from_secs(5), || r.ps().len() == 2), "agents did not re-register: {:?}", r.ps());
    let g = r.graph();
    assert!(connection(&g, "t1/tick", "r1/in").is_some(), "{g}");
    assert!(wait_until(Duration::from_secs(3), || connection(&r.graph(), "t1/tick", "r1/in")
        .is_some_and(|c| c["active"] == true)));
    r.down_and_check_clean();
}

/// A router started again at once after the old one was killed waits for
/// the old one to be gone instead of taking it for a second router: killed
/// while a thread is still busy (most likely finishing a write to disk), a
/// process shows as a zombie while that thread still holds its files, and
/// with them its server (the chaos test in a fresh-clone CI run of
/// 2026-11-27: "a router already runs"). Here a stand-in leaves that way
/// for 400 ms, then for longer than the router waits.
#[test]
fn a_router_started_while_the_killed_one_is_still_leaving_waits_for_it() {
    let r = Robot::new("leaver");
    let (mut leaver, pid) = leaving(&r, 400);
    // its main thread has ended: dead, as a test or `kill -0` loop sees it
    assert!(wait_until(Duration::from_secs(2), || !alive(pid)), "the leaver's main thread did not end");
    let t0 = std::time::Instant::now();
    r.router();
    let waited = t0.elapsed();
    let _ = leaver.wait();
    let log = r.ok(&["logs", "router"]);
    assert!(log.contains("belongs to a process that is exiting; waiting"), "{log}");
    assert!(waited >= Duration::from_millis(100), "the router started after {waited:?}, beside the leaver: {log}");
    r.ok(&["start", "ticker", "--name", "t1"]);
    assert!(wait_until(Duration::from_secs(3), || r.ps().len() == 1), "{:?}", r.ps());
    r.down_and_check_clean();

    // one that takes longer than the router waits is named for what it is
    let r = Robot::new("leaver");
    let (mut leaver, pid) = leaving(&r, 3000);
    assert!(wait_until(Duration::from_secs(2), || !alive(pid)), "the leaver's main thread did not end");
    let e = r.fails(&["router", "--daemon"]);
    assert!(e.contains("the router killed before is still exiting") && e.contains("in a moment"), "{e}");
    let _ = leaver.wait();
    r.router();
    r.down_and_check_clean();
}

/// Starts `test-leaver HOLD_MS` on `r`'s robot; returns it, serving, and its pid.
fn leaving(r: &Robot, hold_ms: u64) -> (std::process::Child, u32) {
    use std::io::BufRead as _;
    let mut leaver = r
        .command("test-leaver")
        .arg(hold_ms.to_string())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("start test-leaver");
    let mut first = String::new();
    let out = leaver.stdout.take().expect("its stdout");
    std::io::BufReader::new(out).read_line(&mut first).expect("its first line");
    assert_eq!(first.trim(), "serving");
    let pid = leaver.id();
    (leaver, pid)
}

/// Duplicate names, unknown agents or ports and mismatched types are refused with clear errors.
#[test]
fn bad_requests_are_refused_clearly() {
    let r = Robot::new("refuse");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1"]);
    r.ok(&["start", "relay", "--name", "r1"]);
    r.ok(&["start", "testagent", "--name", "s1"]);

    let e = r.fails(&["start", "ticker", "--name", "t1"]);
    assert!(e.contains("already running") && e.contains("t1"), "{e}");
    assert_eq!(r.ps().len(), 3, "the duplicate did not disturb the original");

    let e = r.fails(&["connect", "ghost/tick", "r1/in"]);
    assert!(e.contains("no agent named \"ghost\""), "{e}");
    let e = r.fails(&["connect", "t1/tock", "r1/in"]);
    assert!(e.contains("no output port \"tock\"") && e.contains("tick"), "{e}");
    let e = r.fails(&["connect", "t1/tick", "r1/input"]);
    assert!(e.contains("no input port \"input\""), "{e}");
    let e = r.fails(&["connect", "s1/value", "r1/in"]);
    assert!(e.contains("nerve::Scalar") && e.contains("nerve::Tick"), "both type names in: {e}");
    let e = r.fails(&["connect", "t1-tick", "r1/in"]);
    assert!(e.contains("AGENT/PORT"), "{e}");
    let e = r.fails(&["rate", "r1", "10ms"]);
    assert!(e.contains("event-driven"), "{e}");
    let e = r.fails(&["rate", "t1", "fast"]);
    assert!(e.contains("not a duration"), "{e}");
    let e = r.fails(&["param", "set", "t1", "nope", "1"]);
    assert!(e.contains("no parameter \"nope\"") && e.contains("step"), "{e}");
    let e = r.fails(&["start", "nosuchkind", "--name", "x1"]);
    assert!(e.contains("unknown agent kind"), "{e}");
    let e = r.fails(&["start", "ticker", "--name", "Bad Name"]);
    assert!(e.contains("lowercase"), "{e}");
    // programs that are not agents say so (review F3c): rc 0 and silence before
    let e = r.fails(&["start", "/bin/true", "--name", "zz"]);
    assert!(e.contains("not a nerve agent"), "{e}");
    let e = r.fails(&["start", "/bin/false", "--name", "zz"]);
    assert!(e.contains("is it a nerve agent?"), "{e}");
    let e = r.fails(&["disconnect", "t1/tick", "r1/in"]);
    assert!(e.contains("not connected"), "{e}");
    r.down_and_check_clean();
}

/// Without a router, commands say how to start one.
#[test]
fn no_router_is_reported_with_advice() {
    let r = Robot::new("norouter");
    let e = r.fails(&["ps"]);
    assert!(e.contains("no router runs") && e.contains("nerve --robot"), "{e}");
    r.down_and_check_clean();
}

/// Commands that create shared memory refuse to begin when /dev/shm has
/// less free space than the margin (here an absurd one), instead of dying
/// of SIGBUS in iceoryx2 (review R14); `echo` and `hz` map a connection
/// segment too.
#[test]
fn commands_that_map_shared_memory_check_the_free_space_first() {
    let r = Robot::new("shmfull");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    for args in
        [&["echo", "t1/tick", "--count", "1"][..], &["hz", "t1/tick"][..], &["start", "relay", "--name", "r1"][..]]
    {
        let out = r.command("nerve").args(args).env("NERVE_SHM_MIN_FREE", "100000G").output().expect("nerve");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains("/dev/shm"), "{args:?}: {err}");
    }
    assert_eq!(r.echo("t1/tick", 1).len(), 1, "with the default margin, echo works");
    r.down_and_check_clean();
}

/// `nerve stop` stops an agent cleanly: it leaves the registry, its pid file goes.
#[test]
fn stop_is_clean() {
    let r = Robot::new("stop");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1"]);
    let pid = r.pid("t1");
    r.ok(&["stop", "t1"]);
    assert!(wait_until(Duration::from_secs(3), || !alive(pid)), "agent did not exit");
    assert!(r.agent("t1").is_none());
    assert!(!r.home.join(&r.name).join("pids/t1.pid").exists());
    r.down_and_check_clean();
}

/// An agent takes `Connect` from anyone who can open its control service
/// (reliability review R10): a source no agent has, and names that are not
/// names, are refused with the reason, and nothing is created for them in
/// /dev/shm or under iceoryx2's root (it used to create a service, its
/// files and a subscriber for each).
#[test]
fn connect_to_a_source_that_does_not_exist_is_refused_and_creates_nothing() {
    use agent_sdk::World;
    use agent_sdk::control::{ControlClient, ControlSize};
    use shm_schemas::AgentName;
    use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};

    let r = Robot::new("ghost");
    r.router();
    r.ok(&["start", "relay", "--name", "r1"]);
    let world = World::new(&r.name).expect("world");
    let node = world.node(&format!("test-ghost-{}", std::process::id())).expect("node");
    let ctl = world.robot().ctl_service(&AgentName::new("r1").expect("name"));
    let client: ControlClient<AgentCommand, AgentReply> =
        ControlClient::open(&node, &ctl, ControlSize::AGENT).expect("r1's control service");
    let connect = |from_agent: &str, from_port: &str| {
        let cmd = AgentCommand::Connect {
            input: "in".into(),
            from_agent: from_agent.into(),
            from_port: from_port.into(),
            type_name: "nerve::Tick".into(),
        };
        match client.call(&cmd, Duration::from_secs(5)).expect("r1 answers") {
            AgentReply::Error(e) => e,
            other => panic!("r1 accepted {from_agent}/{from_port}: {other:?}"),
        }
    };
    let files = || {
        let mut f = world.shm_files();
        f.extend(world.iox2_files());
        f.sort();
        f
    };
    // names that are not names: refused before anything is opened
    for (agent, port) in [("../x", "out"), ("Ghost", "out"), ("ghost", "a/b"), ("", "out")] {
        let e = connect(agent, port);
        assert!(e.contains("cannot read"), "{agent}/{port}: {e}");
    }
    let before = files();
    for i in 0..20 {
        let e = connect(&format!("ghost{i}"), "out");
        assert!(e.contains("does not exist"), "{e}");
    }
    assert_eq!(files(), before, "refused sources left files");
    let r1 = r.agent("r1").expect("r1 runs");
    assert!(r1["stats"]["inputs"].as_array().is_none_or(|i| i.is_empty()), "{r1}");
    // a real source is still taken
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["connect", "t1/tick", "r1/in"]);
    assert_eq!(r.echo("r1/out", 2).len(), 2);
    drop(client);
    drop(node);
    r.down_and_check_clean();
}

/// `nerve hz --duration` ends by itself after the time given, its last
/// report covering what was left of its window (as `record` and `plot`
/// take `--duration`).
#[test]
fn hz_stops_after_its_duration() {
    let r = Robot::new("hzdur");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    let out = r.ok(&["hz", "t1/tick", "--json", "--window", "10", "--duration", "0.6"]);
    let reports: Vec<serde_json::Value> =
        out.lines().map(|l| serde_json::from_str(l).expect("one JSON report a line")).collect();
    assert_eq!(reports.len(), 1, "one report, cut short by the duration: {out}");
    let window = reports[0]["window_s"].as_f64().unwrap_or(0.0);
    assert!(window > 0.5 && window < 5.0, "the report covers the duration, not the 10 s window: {out}");
    assert!(reports[0]["rate_hz"].as_f64().unwrap_or(0.0) > 10.0, "{out}");
    let e = r.fails(&["hz", "t1/tick", "--duration", "soon"]);
    assert!(e.contains("--duration"), "{e}");
    r.down_and_check_clean();
}

/// `nerve types` lists the built-in payloads and the types the robot's
/// agents registered (a team's own `acme::Gripper`), and shows one type's
/// fields with offsets, units and fingerprint; an unknown name is refused
/// with the close ones (issue 46).
#[test]
fn types_lists_built_in_and_registered_types_and_shows_one() {
    let r = Robot::new("types");
    // without a router: the built-in types, and a note saying so
    let out = r.command("nerve").args(["types"]).output().expect("types");
    let (list, note) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{note}");
    assert!(list.contains("nerve::Odometry") && list.contains("built-in"), "{list}");
    assert!(note.contains("no router runs"), "{note}");
    r.router();
    r.ok(&["start", "gripper", "--name", "g"]);
    let list = r.ok(&["types"]);
    assert!(list.contains("acme::Gripper") && list.contains("g/state"), "a registered type and where: {list}");
    let one = r.ok(&["types", "Odometry"]);
    assert!(one.contains("theta: f64  [rad]") && one.contains("stamp_ns: u64  [ns]"), "{one}");
    let json: Value = serde_json::from_str(&r.ok(&["types", "acme::Gripper", "--json"])).expect("json");
    let fields: Vec<&str> =
        json[0]["fields"].as_array().expect("fields").iter().filter_map(|f| f["name"].as_str()).collect();
    assert_eq!(fields, ["count", "opening_m", "fingers", "tool", "temp_cdeg"], "{json}");
    assert!(json[0]["fingerprint"].as_str().is_some_and(|f| f.starts_with("0x")), "{json}");
    let e = r.fails(&["types", "odometr"]);
    assert!(e.contains("did you mean nerve::Odometry"), "{e}");
    r.down_and_check_clean();
}

/// `nerve pub` sends any type into an input port, laid out by the input's
/// schema from the router: a relay forwards what was published; a missing or
/// unknown field, an input that does not exist and text that is not JSON are
/// refused before anything is attached, and nothing stays attached after
/// (issue 46).
#[test]
fn pub_sends_json_into_an_input_and_refuses_what_does_not_fit() {
    let r = Robot::new("pub");
    r.router();
    r.ok(&["start", "relay", "--name", "r1"]);
    // a steady stream, so that an echo started beside it sees a sample
    let publisher = r
        .command("nerve")
        .args(["pub", "r1/in", r#"{"seq": 4242}"#, "--rate", "20", "--count", "60"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("pub");
    let seen = r.echo("r1/out", 1);
    let published = publisher.wait_with_output().expect("pub ends");
    assert!(
        published.status.success(),
        "{}{}",
        String::from_utf8_lossy(&published.stdout),
        String::from_utf8_lossy(&published.stderr)
    );
    assert!(String::from_utf8_lossy(&published.stdout).contains("r1/in <- nerve::Tick x60"), "{published:?}");
    assert_eq!(seen[0]["data"]["seq"], 4242, "the relay forwarded what was published: {seen:?}");
    assert!(seen[0]["data"]["stamp_ns"].as_u64().unwrap_or(0) > 0, "a missing stamp is the send time: {seen:?}");

    let e = r.fails(&["pub", "r1/in", "{}"]);
    assert!(e.contains("field `seq` is missing"), "{e}");
    let e = r.fails(&["pub", "r1/in", r#"{"seq": 1, "speed": 2}"#]);
    assert!(e.contains("has no field `speed`; its fields: seq, stamp_ns"), "{e}");
    let e = r.fails(&["pub", "r1/nope", r#"{"seq": 1}"#]);
    assert!(e.contains("has no input \"nope\"; its inputs: in"), "{e}");
    let e = r.fails(&["pub", "r1/in", "seq=1"]);
    assert!(e.contains("not JSON"), "{e}");
    let g = r.graph();
    assert_eq!(g["connections"].as_array().map(|c| c.len()), Some(0), "nothing stays attached: {g}");
    r.down_and_check_clean();
}
