//! End to end: `nerve-bench hop --quick --payloads 8 --json` starts a router,
//! the SDK ping/pong agents, the raw iceoryx2 and socket pongs, and produces
//! results for every transport. Only that results exist is checked, never
//! their values (no timed assertions).
//!
//! Needs the `nerve` command built into the same target dir first, e.g.
//! `CARGO_TARGET_DIR=/work/target-bench cargo build --release -p nerve -p nerve-bench`.

use std::process::Command;

#[test]
fn hop_quick_8_bytes_produces_results() {
    let out_dir = std::env::temp_dir().join(format!("nerve-bench-test-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_nerve-bench"))
        .args(["hop", "--quick", "--json", "--payloads", "8", "--count", "50", "--out"])
        .arg(&out_dir)
        .output()
        .expect("nerve-bench runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "nerve-bench hop failed: {stderr}");
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is JSON");
    let results = report["results"].as_array().expect("results");
    for t in ["nerve", "iox2-waitset", "iox2-listener", "uds", "nerve-poll", "iox2-poll"] {
        let r = results.iter().find(|r| r["transport"] == t && r["size"] == 8).expect("a result per transport");
        assert!(r["rtt"]["n"].as_u64().unwrap_or(0) > 0, "{t}: no samples");
    }
    let ratios = report["ratios"].as_array().expect("ratios");
    assert!(ratios[0]["nerve_vs_waitset_p50"].as_f64().is_some());
    assert!(out_dir.join("hop.json").is_file());
    // the robot was taken down: nothing of it is left in /dev/shm
    let pid_tag = stderr
        .split_whitespace()
        .skip_while(|w| *w != "robot")
        .nth(1)
        .map(|r| format!("nerve_{r}_"))
        .expect("the robot name is reported");
    let left: Vec<_> = std::fs::read_dir("/dev/shm")
        .map(|rd| rd.filter_map(|e| e.ok()).filter(|e| e.file_name().to_string_lossy().starts_with(&pid_tag)).count())
        .into_iter()
        .collect();
    assert_eq!(left, vec![0], "shared memory of robot left behind ({pid_tag})");
    let _ = std::fs::remove_dir_all(&out_dir);
}
