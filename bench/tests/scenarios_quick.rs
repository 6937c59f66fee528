//! End to end, one smoke run per scenario (jitter aside: it needs
//! cyclictest): `nerve-bench SCENARIO --quick --json` runs, prints a report
//! with the fields users script against, writes `DIR/<scenario>.json`, and
//! leaves nothing of its robots in /dev/shm. Values are never checked against
//! targets (no timed assertions); only that they were measured.
//!
//! Needs the `nerve`, `nerve-ticker` and `nerve-relay` executables built into
//! the same target dir (`cargo build --workspace --bins`); `fleet` also
//! `nerve-bridge` and `nerve-ros2-router`, and root for its namespaces.

use serde_json::Value;
use std::path::PathBuf;
use std::process::Command;

/// Runs `nerve-bench <args> --quick --json --out DIR`; returns the report.
fn run(scenario: &str, extra: &[&str]) -> Value {
    let out_dir: PathBuf = std::env::temp_dir().join(format!("nerve-bench-{scenario}-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_nerve-bench"))
        .arg(scenario)
        .args(["--quick", "--json", "--out"])
        .arg(&out_dir)
        .args(extra)
        .output()
        .expect("nerve-bench runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "nerve-bench {scenario} failed: {stderr}");
    let report: Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    assert!(out_dir.join(format!("{scenario}.json")).is_file(), "no {scenario}.json");
    // every robot the run names on its first line ("robot b123a and robot b123b")
    let first = stderr.lines().find(|l| l.contains("robot ")).expect("the robot name is reported");
    let words: Vec<&str> = first.split_whitespace().collect();
    let robots: Vec<String> = words
        .windows(2)
        .filter(|w| w[0] == "robot")
        .map(|w| shm_schemas::RobotName::shm_prefix_of(shm_schemas::names::effective_uid(), w[1]))
        .collect();
    assert!(!robots.is_empty(), "the robot name is reported: {first}");
    for robot in &robots {
        let left = std::fs::read_dir("/dev/shm")
            .map(|rd| rd.filter_map(|e| e.ok()).filter(|e| e.file_name().to_string_lossy().starts_with(robot)).count())
            .unwrap_or(0);
        assert_eq!(left, 0, "shared memory of robot left behind ({robot})");
    }
    let _ = std::fs::remove_dir_all(&out_dir);
    report
}

/// The control plane, with a second relay executable (this build's own, by
/// its path) hot-added in alternate rounds: every measure has samples, and
/// the side-by-side row has as many as `relay`'s.
#[test]
fn control_quick_measures_hot_add_rewire_and_launch_side_by_side() {
    let relay = PathBuf::from(env!("CARGO_BIN_EXE_nerve-bench")).with_file_name("nerve-relay");
    assert!(relay.is_file(), "build the agents first: cargo build --workspace --bins ({})", relay.display());
    let r = run("control", &["--launch", "10", "--hot-add-beside", &relay.display().to_string()]);
    for measure in ["hot_add", "hot_add_command", "rewire_cli", "rewire_request", "rewire_reply"] {
        assert!(r[measure]["n"].as_u64().unwrap_or(0) > 0, "{measure}: no samples in {r}");
    }
    let beside = &r["hot_add_beside"];
    assert_eq!(beside["hot_add"]["n"], r["hot_add"]["n"], "{beside}");
    assert_eq!(beside["executable"], relay.display().to_string());
    assert!(beside["ratio_to_relay"].as_f64().is_some_and(|v| v > 0.0), "{beside}");
    assert_eq!(r["launch"][0]["agents"], 10);
    assert!(r["hot_add_vs_target"].as_f64().is_some_and(|v| v > 0.0));
}

/// Whether this process may write the PM QoS device (the `-pmqos` rows need it).
fn may_hold_pm_qos() -> bool {
    std::fs::OpenOptions::new().write(true).open("/dev/cpu_dma_latency").is_ok()
}

#[test]
fn hop_quick_8_bytes_produces_results() {
    let r = run("hop", &["--payloads", "8", "--count", "50"]);
    assert!(may_hold_pm_qos(), "the tests run as root, as CI does: the -pmqos rows need /dev/cpu_dma_latency");
    let results = r["results"].as_array().expect("results");
    for t in [
        "nerve",
        "nerve-pmqos",
        "nerve-pinned",
        "iox2-waitset",
        "iox2-waitset-pmqos",
        "iox2-listener",
        "uds",
        "uds-pmqos",
        "futex",
        "futex-pmqos",
        "futex-pinned",
        "nerve-poll",
        "iox2-poll",
    ] {
        let x = results.iter().find(|x| x["transport"] == t && x["size"] == 8).expect("a result per transport");
        assert!(x["rtt"]["n"].as_u64().unwrap_or(0) > 0, "{t}: no samples");
    }
    // the pinned futex pair ran on one CPU every time; the placement is reported
    let pinned = results.iter().find(|x| x["transport"] == "futex-pinned").expect("futex-pinned");
    assert_eq!(pinned["same_cpu_share"].as_f64(), Some(1.0), "{pinned}");
    let ratios = r["ratios"].as_array().expect("ratios");
    assert!(ratios[0]["nerve_vs_waitset_p50"].as_f64().is_some());
    assert!(ratios[0]["nerve_pmqos_vs_futex_pmqos_p50"].as_f64().is_some_and(|v| v > 0.0));
    assert!(ratios[0]["futex_target_met"].is_boolean());
    let idle = r["idle"].as_array().expect("idle shares");
    assert_eq!(idle.len(), 2, "without and with PM QoS");
    assert_eq!(idle[1]["pm_qos"], true, "the run holds the bound (as root)");
    assert!(r["machine"]["idle_driver"].is_string());
}

#[test]
fn pipeline_quick_measures_one_and_three_hops() {
    let r = run("pipeline", &["--payloads", "8"]);
    let results = r["results"].as_array().expect("results");
    for path in ["one-hop", "three-hop", "one-hop-pmqos", "three-hop-pmqos", "uds", "futex", "futex-pmqos"] {
        let x = results.iter().find(|x| x["path"] == path).expect("a result per path");
        assert!(x["latency"]["n"].as_u64().unwrap_or(0) > 0, "{path}: no samples");
    }
    let ratio = &r["ratios"][0];
    assert!(ratio["three_vs_one_p50"].as_f64().is_some_and(|v| v > 0.0));
    assert!(ratio["target_met"].is_boolean());
    assert!(ratio["three_vs_one_pmqos_p50"].as_f64().is_some_and(|v| v > 0.0));
    assert!(ratio["one_hop_vs_futex_p50"].as_f64().is_some_and(|v| v > 0.0));
}

#[test]
fn scale_quick_measures_cpu_memory_and_ps() {
    let r = run("scale", &["--agents", "10", "--window", "1"]);
    assert_eq!(r["agents"], 10);
    assert!(r["agent_pss_kib_p50"].as_u64().unwrap_or(0) > 0);
    assert!(r["router"]["rss_kib"].as_u64().unwrap_or(0) > 0);
    assert!(r["ps"]["n"].as_u64().unwrap_or(0) > 0);
    assert!(r["idle"]["router_pct"].as_f64().is_some());
    assert!(r["target_met"].is_boolean());
}

#[test]
fn soak_quick_samples_the_exploration_robot_under_churn() {
    let r = run("soak", &["--churn", "3"]);
    let samples = r["samples"].as_array().map_or(0, |s| s.len());
    assert!(samples >= 3, "{samples} samples");
    assert!(r["router_rss_kib"]["last"].as_f64().unwrap_or(0.0) > 0.0);
    assert!(r["files"]["last"].as_f64().unwrap_or(0.0) > 0.0);
    assert!(r["churn_cycles"].as_u64().unwrap_or(0) >= 2, "{}", r["churn_cycles"]);
    assert_eq!(r["churn_failures"], 0, "every churn cycle works");
    assert!(r["hot_add"]["n"].as_u64().unwrap_or(0) >= 2);
}

#[test]
fn images_quick_reads_every_frame_intact() {
    let r = run("images", &["--resolutions", "320x240", "--readers", "1,4"]);
    let results = r["results"].as_array().expect("results");
    for t in ["stm", "iox2-slice", "uds"] {
        for n in [1, 4] {
            let x = results
                .iter()
                .find(|x| x["transport"] == t && x["readers"] == n && x["mode"] == "paced")
                .unwrap_or_else(|| panic!("no paced result for {t} with {n} readers"));
            assert!(x["frames"].as_u64().unwrap_or(0) > 0, "{t}/{n}: no frames");
            assert_eq!(x["bad"], 0, "{t}/{n}: frames read torn or wrong");
        }
    }
    assert!(!r["scaling"].as_array().expect("scaling").is_empty());
}

#[test]
fn bridge_quick_measures_both_paths_and_the_local_cost() {
    let r = run("bridge", &["--payloads", "8,4096", "--count", "20", "--hop-count", "50"]);
    let oneway = r["oneway"].as_array().expect("oneway");
    for size in [8, 4096] {
        for system in ["bridge", "zenoh"] {
            let x = oneway
                .iter()
                .find(|x| x["system"] == system && x["size"] == size)
                .unwrap_or_else(|| panic!("no one-way result for {system} at {size} B"));
            assert!(x["latency"]["n"].as_u64().unwrap_or(0) > 0, "{system} {size}: nothing crossed");
            let t = r["throughput"]
                .as_array()
                .expect("throughput")
                .iter()
                .find(|x| x["system"] == system && x["size"] == size)
                .unwrap_or_else(|| panic!("no throughput for {system} at {size} B"));
            assert!(t["delivered_per_s"].as_f64().unwrap_or(0.0) > 0.0, "{system} {size}: nothing delivered");
        }
        for system in ["alone", "bridged", "bridged-100hz"] {
            let x = r["local"]
                .as_array()
                .expect("local")
                .iter()
                .find(|x| x["system"] == system && x["size"] == size)
                .unwrap_or_else(|| panic!("no round trip for {system} at {size} B"));
            assert!(x["rtt"]["n"].as_u64().unwrap_or(0) > 0, "{system} {size}: no round trips");
        }
    }
    // the pair of bridges over mutual TLS, in the same rounds (issue 40)
    for size in [8, 4096] {
        let x = oneway
            .iter()
            .find(|x| x["system"] == "bridge-tls" && x["size"] == size)
            .unwrap_or_else(|| panic!("no one-way result over TLS at {size} B"));
        assert!(x["latency"]["n"].as_u64().unwrap_or(0) > 0, "TLS {size}: nothing crossed");
    }
    let ow = &r["oneway_ratios"][0];
    assert!(ow["bridge_vs_zenoh_p50"].as_f64().is_some_and(|v| v > 0.0));
    assert!(ow["target_met"].is_boolean());
    assert!(ow["tls_vs_plain_p50"].as_f64().is_some_and(|v| v > 0.0), "no TLS against plain ratio: {ow}");
    assert!(r["tls_vs_plain_p50_8B"].as_f64().is_some_and(|v| v > 0.0) && r["tls_target"] == 1.15);
    let lo = &r["local_ratios"][0];
    assert!(lo["bridged_vs_alone_p50"].as_f64().is_some_and(|v| v > 0.0));
    assert!(lo["target_met"].is_boolean());
    assert_eq!(r["bridge_status"].as_array().map(Vec::len), Some(2), "both bridges reported their figures");
}

/// `nerve foxglove` with Foxglove's client library (npm packages of
/// `tests/js/foxglove`, installed by `.ci/run`): the hop was measured with
/// the client subscribed to the hop's own ports, and the camera's frames
/// reached it at the camera's size (how many were dropped is a number of
/// the report, not checked: the machine may be loaded).
#[test]
fn foxglove_quick_measures_the_hop_beside_a_client_and_the_camera() {
    let r = run("foxglove", &["--payloads", "8", "--seconds", "1"]);
    let hop = &r["hop"][0];
    for k in ["without", "with_foxglove"] {
        assert!(hop[k]["n"].as_u64().unwrap_or(0) > 0, "{k}: no samples in {hop}");
    }
    let channels: Vec<&str> =
        r["hop_channels"].as_array().expect("channels").iter().filter_map(|c| c.as_str()).collect();
    assert!(
        channels.iter().any(|c| c.ends_with("/out")),
        "the client did not subscribe to the hop's ports: {channels:?}"
    );
    let cam = &r["camera"];
    assert_eq!((cam["width"].as_u64(), cam["height"].as_u64()), (Some(640), Some(480)), "{cam}");
    assert!(cam["delivered"].as_u64().unwrap_or(0) > 0, "no frame delivered: {cam}");
    assert!(cam["server_cpu_ms_per_frame"].as_f64().is_some_and(|v| v > 0.0), "{cam}");
}

/// A fleet of two robots, each in its own network namespace, meeting
/// through a Zenoh router: the join time, the latency, what was delivered
/// and the router's CPU are measured, and no namespace is left.
#[test]
fn fleet_quick_joins_two_robots_through_a_router() {
    let r = run("fleet", &["--robots", "2", "--seconds", "1"]);
    let row = &r["rows"][0];
    assert_eq!(row["robots"].as_u64(), Some(2), "{r}");
    for k in ["join_ms_median", "latency_us_median", "delivered"] {
        assert!(row[k].as_f64().is_some_and(|v| v > 0.0), "{k} not measured: {row}");
    }
    assert!(row["router_cpu_pct"].as_f64().is_some_and(|v| v >= 0.0), "{row}");
    assert_eq!(r["netns"].as_bool(), Some(true), "{r}");
    let ns = Command::new("ip").args(["netns", "list"]).output().expect("ip netns list");
    let left = String::from_utf8_lossy(&ns.stdout).into_owned();
    assert!(!left.contains("nerve-fleet-"), "a namespace of the run was left: {left}");
}
