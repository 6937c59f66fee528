//! PM QoS and CPU placement, end to end (issue 17). A real-time agent holds
//! `/dev/cpu_dma_latency` for as long as it runs and no longer; `nerve ps`
//! says what each agent holds; `--cpu-latency`, `NERVE_CPU_LATENCY` and a
//! launch file's `cpu_latency` set or turn off the bound; an agent that may
//! not write the device says so and runs on. `--cpus` and a launch file's
//! `cpus` keep every thread of an agent on the CPUs named. Real agent
//! processes, the kernel's own device (the tests run as root, as CI does).

use nerve_tests::{Robot, alive, wait_until};
use serde_json::Value;
use std::time::Duration;

const DEVICE: &str = "/dev/cpu_dma_latency";

/// Whether process `pid` has the PM QoS device open.
fn holds_device(pid: u32) -> bool {
    let Ok(fds) = std::fs::read_dir(format!("/proc/{pid}/fd")) else { return false };
    fds.flatten().any(|fd| std::fs::read_link(fd.path()).is_ok_and(|t| t == std::path::Path::new(DEVICE)))
}

/// The bound the kernel honours now, µs (the smallest open request).
fn current_bound_us() -> u32 {
    let b = std::fs::read(DEVICE).expect("read /dev/cpu_dma_latency (the tests run as root)");
    i32::from_ne_bytes(b[..4].try_into().expect("four bytes")) as u32
}

fn cpu_latency(r: &Robot, name: &str) -> Value {
    r.agent(name).map(|a| a["stats"]["cpu_latency"].clone()).unwrap_or_else(|| panic!("{name} not in ps"))
}

#[test]
fn a_realtime_agent_holds_the_bound_while_it_runs_and_not_after() {
    if !std::path::Path::new(DEVICE).exists() {
        eprintln!("skipped: this kernel has no {DEVICE}");
        return;
    }
    let r = Robot::new("pmqos");
    r.router();
    r.ok(&["start", "ticker", "--name", "t", "--period", "10ms"]);
    r.ok(&["start", "relay", "--name", "b", "--cpu-latency", "30"]);
    r.ok(&["start", "relay", "--name", "off", "--cpu-latency", "off"]);
    let (t, b, off) = (r.pid("t"), r.pid("b"), r.pid("off"));

    assert_eq!(cpu_latency(&r, "t"), serde_json::json!({"held": {"us": 0}}), "the default is a bound of 0 µs");
    assert_eq!(cpu_latency(&r, "b"), serde_json::json!({"held": {"us": 30}}));
    assert_eq!(cpu_latency(&r, "off"), serde_json::json!("off"));
    assert!(holds_device(t) && holds_device(b), "the holding agents have the device open");
    assert!(!holds_device(off), "an agent told `off` holds nothing");
    assert!(!holds_device(r.pid_file("router").expect("router pid")), "the router holds nothing itself");
    assert_eq!(current_bound_us(), 0, "the kernel honours the smallest bound held");
    let table = r.ok(&["ps"]);
    assert!(table.contains("WAKE") && table.contains("0us") && table.contains("30us"), "{table}");

    // suspended, an agent still holds (it may be resumed at any moment)
    r.ok(&["suspend", "t"]);
    assert!(holds_device(t), "a suspended agent keeps its bound");
    // stopped, it holds nothing: the file closed with the process
    r.ok(&["stop", "t"]);
    assert!(wait_until(Duration::from_secs(5), || !alive(t)), "t did not exit");
    assert!(!holds_device(t), "a stopped agent's request is gone with its file");
    assert!(holds_device(b));
    // killed, the kernel drops its request too
    nerve_tests::sigkill(b);
    assert!(wait_until(Duration::from_secs(5), || !alive(b)), "b did not die");
    assert!(!holds_device(b), "a killed agent's request is gone with its file");
    r.down_and_check_clean();
}

#[test]
fn the_bound_comes_from_the_environment_and_the_launch_file() {
    if !std::path::Path::new(DEVICE).exists() {
        eprintln!("skipped: this kernel has no {DEVICE}");
        return;
    }
    let r = Robot::new("pmqlf");
    r.router();
    // a whole robot opts out through the environment of whoever starts its agents
    let out = r
        .command("nerve")
        .args(["start", "relay", "--name", "e"])
        .env("NERVE_CPU_LATENCY", "off")
        .output()
        .expect("nerve start");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(cpu_latency(&r, "e"), serde_json::json!("off"));
    assert!(!holds_device(r.pid("e")));
    // --no-realtime agents are not real-time: they hold nothing
    let out = r
        .command("nerve-relay")
        .args(["--name", "nrt", "--daemon", "--no-realtime"])
        .output()
        .expect("start a --no-realtime relay");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(cpu_latency(&r, "nrt"), serde_json::json!("off"));

    // the file's bound for every agent, one agent's own above it
    let lf = r.launch_file(
        "pmqos.toml",
        r#"robot = "x"
cpu_latency = "40us"
[[agent]]
name = "l1"
kind = "relay"
[[agent]]
name = "l2"
kind = "relay"
cpu_latency = "off"
[[agent]]
name = "l3"
kind = "relay"
cpu_latency = 7
"#,
    );
    r.ok(&["launch", lf.to_str().expect("utf-8 path")]);
    assert_eq!(cpu_latency(&r, "l1"), serde_json::json!({"held": {"us": 40}}));
    assert_eq!(cpu_latency(&r, "l2"), serde_json::json!("off"));
    assert_eq!(cpu_latency(&r, "l3"), serde_json::json!({"held": {"us": 7}}));
    assert!(!holds_device(r.pid("l2")) && holds_device(r.pid("l3")));

    // a bad value is refused with its line, before anything starts
    let bad =
        r.launch_file("bad.toml", "robot = \"x\"\n[[agent]]\nname = \"z\"\nkind = \"relay\"\ncpu_latency = \"fast\"\n");
    let err = r.fails(&["launch", bad.to_str().expect("utf-8 path")]);
    assert!(err.contains("bad.toml:5:") && err.contains("cpu_latency"), "{err}");
    assert!(r.agent("z").is_none());
    r.down_and_check_clean();
}

#[test]
fn an_agent_that_may_not_hold_the_bound_says_so_and_runs_on() {
    let r = Robot::new("pmqno");
    r.router();
    // a device this process cannot open, as for a user without write access
    let out = r
        .command("nerve")
        .args(["start", "relay", "--name", "d"])
        .env("NERVE_CPU_LATENCY_DEVICE", r.home.join("no-such-dir").join("cpu_dma_latency"))
        .output()
        .expect("nerve start");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(cpu_latency(&r, "d"), serde_json::json!("refused"));
    let log = std::fs::read_to_string(r.home.join(&r.name).join("logs").join("d.log")).unwrap_or_default();
    assert!(log.contains("--cpu-latency off") && log.contains("WARN"), "the refusal is logged with what to do:\n{log}");
    // and it works: a sample through it
    r.ok(&["start", "ticker", "--name", "t", "--period", "10ms"]);
    r.ok(&["connect", "t/tick", "d/in"]);
    assert!(
        wait_until(Duration::from_secs(5), || r.agent("d").and_then(|a| a["stats"]["cycles"].as_u64()) > Some(3)),
        "the refused agent does not run"
    );
    r.down_and_check_clean();
}

/// The `Cpus_allowed_list` of every thread of `pid`.
fn thread_cpus(pid: u32) -> Vec<String> {
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).expect("the agent's threads");
    tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("status")).ok())
        .filter_map(|s| s.lines().find_map(|l| l.strip_prefix("Cpus_allowed_list:")).map(|v| v.trim().to_owned()))
        .collect()
}

#[test]
fn cpus_keep_every_thread_of_an_agent_where_they_are_told() {
    let r = Robot::new("cpus");
    r.router();
    r.ok(&["start", "relay", "--name", "a", "--cpus", "0"]);
    let threads = thread_cpus(r.pid("a"));
    assert!(threads.len() >= 2, "the checker and the task at least: {threads:?}");
    assert!(threads.iter().all(|c| c == "0"), "every thread on CPU 0: {threads:?}");

    let lf = r.launch_file("cpus.toml", "robot = \"x\"\n[[agent]]\nname = \"b\"\nkind = \"relay\"\ncpus = [0]\n");
    r.ok(&["launch", lf.to_str().expect("utf-8 path")]);
    assert!(thread_cpus(r.pid("b")).iter().all(|c| c == "0"));

    // a CPU the machine lacks: refused with its line before anything starts,
    // and by the agent itself when started by hand
    let bad = r.launch_file("bad.toml", "robot = \"x\"\n[[agent]]\nname = \"z\"\nkind = \"relay\"\ncpus = [1000]\n");
    let err = r.fails(&["launch", bad.to_str().expect("utf-8 path")]);
    assert!(err.contains("bad.toml:5:") && err.contains("nproc"), "{err}");
    let out = r.nerve(&["start", "relay", "--name", "y", "--cpus", "1000"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--cpus") && err.contains("1000"), "{err}");
    assert!(r.agent("y").is_none() && r.agent("z").is_none());
    r.down_and_check_clean();
}
