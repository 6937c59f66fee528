//! What survives a restart, end to end with real processes: run-time state
//! (suspend, period, parameters) set through the router comes back to an
//! agent restarted by hand or by the supervisor (R12), also after the router
//! itself restarted (the decision maker sends its mode again); a restarted
//! agent does not inherit the router's real-time policy (R13); and the
//! decision maker goes on deciding while the router waits for an agent
//! (R26).

use nerve_tests::{Robot, bin_dir, sigkill, wait_until};
use std::os::unix::fs::PermissionsExt;
use std::time::Duration;

/// The router's pid, from its pid file.
fn router_pid(r: &Robot) -> u32 {
    std::fs::read_to_string(r.home.join(&r.name).join("pids").join("router.pid"))
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .expect("the router's pid file")
}

/// The scheduling policy of every thread of `pid` (field 41 of its stat).
fn policies(pid: u32) -> Vec<u32> {
    let Ok(rd) = std::fs::read_dir(format!("/proc/{pid}/task")) else { return vec![] };
    rd.filter_map(|e| e.ok())
        .filter_map(|e| std::fs::read_to_string(e.path().join("stat")).ok())
        .filter_map(|s| s.rsplit_once(')').and_then(|(_, r)| r.split_whitespace().nth(38)?.parse().ok()))
        .collect()
}

/// R13: an agent restarted by a real-time router runs under SCHED_OTHER,
/// as the same agent started by `nerve launch` does. (Where the router
/// cannot get SCHED_FIFO, both are SCHED_OTHER anyway.)
#[test]
fn a_supervisor_restarted_agent_does_not_inherit_the_routers_real_time_policy() {
    let r = Robot::new("sched");
    r.router();
    eprintln!("the router's threads run under policies {:?} (1: SCHED_FIFO)", policies(router_pid(&r)));
    // the ticker without real-time requests of its own
    let wrapper = r.home.join("ticker-no-rt");
    std::fs::write(
        &wrapper,
        format!(
            "#!/bin/sh\ncase \" $* \" in *\" --no-realtime \"*) exec {t} \"$@\";; *) exec {t} --no-realtime \"$@\";; esac\n",
            t = bin_dir().join("nerve-ticker").display()
        ),
    )
    .expect("write the wrapper");
    std::fs::set_permissions(&wrapper, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    let file = r.launch_file(
        "sched.toml",
        &format!(
            "robot = \"x\"\n[[agent]]\nname = \"t1\"\nexe = \"{}\"\nrestart = \"on-failure\"\nbackoff = \"100ms\"\n",
            wrapper.display()
        ),
    );
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    let first = r.pid("t1");
    assert!(policies(first).iter().all(|p| *p == 0), "launched: {:?}", policies(first));
    sigkill(first);
    let mut restarted = 0;
    assert!(wait_until(Duration::from_secs(10), || {
        restarted = r.agent("t1").and_then(|a| a["pid"].as_u64()).unwrap_or(0) as u32;
        restarted != 0 && restarted != first
    }));
    let p = policies(restarted);
    assert!(!p.is_empty() && p.iter().all(|p| *p == 0), "the restarted agent's threads run under policies {p:?}");
    r.down_and_check_clean();
}
