//! `nerve record` and `nerve replay`, end to end: a robot with a built-in
//! type and a type nerve was not built with (`acme::Gripper`) is recorded to
//! MCAP; the file is read by the `mcap` package from PyPI (a reader nobody
//! here wrote, installed by this test into a virtual environment) and its
//! channels, schemas, message count and decoded contents are checked; then
//! the recording is replayed into the robot under the recorded agent's name
//! and recorded again: every sample comes back bit-exact and in order, with
//! the recorded spacing.

use nerve_tests::{Robot, wait_until};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// A Python with the `mcap` package: the workspace's `target/nerve-py`
/// virtual environment, made and filled here when it lacks it.
fn python_with_mcap() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("target").join("nerve-py");
    let python = dir.join("bin").join("python");
    let has_mcap =
        |p: &Path| Command::new(p).args(["-c", "import mcap.reader"]).output().is_ok_and(|o| o.status.success());
    if !has_mcap(&python) {
        let st = Command::new("python3").arg("-m").arg("venv").arg(&dir).status().expect("python3");
        assert!(
            st.success(),
            "python3 -m venv failed (Debian: apt-get install python3-venv; scripts/setup.sh does it)"
        );
        let st = Command::new(dir.join("bin").join("pip"))
            .args(["install", "--quiet", "--disable-pip-version-check", "mcap==1.6.0"])
            .status()
            .expect("pip");
        assert!(st.success(), "pip install mcap failed (PyPI must be reachable)");
    }
    assert!(has_mcap(&python), "the mcap package does not import");
    python
}

/// What `tests/py/read_mcap.py` finds in `file`.
fn read_with_python(file: &Path) -> Value {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("py").join("read_mcap.py");
    let out = Command::new(python_with_mcap()).arg(script).arg(file).output().expect("python");
    assert!(out.status.success(), "the reader failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("reader json")
}

/// The messages of `topic` in the reader's answer.
fn messages<'a>(got: &'a Value, topic: &str) -> &'a Vec<Value> {
    got["channels"][topic]["messages"].as_array().unwrap_or_else(|| panic!("no channel {topic}"))
}

/// Log-time gaps between consecutive messages, ms.
fn gaps_ms(msgs: &[Value]) -> Vec<f64> {
    msgs.windows(2)
        .map(|w| (w[1]["log_time"].as_u64().unwrap_or(0) as f64 - w[0]["log_time"].as_u64().unwrap_or(0) as f64) / 1e6)
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

#[test]
fn a_recording_reads_in_an_independent_reader_and_replays_bit_exact() {
    let r = Robot::new("rec");
    r.router();
    r.ok(&["start", "gripper", "--name", "g"]);
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    let fp = r.agent("g").expect("g")["outputs"][0]["fingerprint"].as_u64().expect("fingerprint");
    let file = r.home.join("run.mcap");
    let file_s = file.display().to_string();
    let out = r.ok(&["record", "--all", "-o", &file_s, "--duration", "2", "-q"]);
    let total: u64 = out
        .split_whitespace()
        .zip(out.split_whitespace().skip(1))
        .find(|(_, w)| *w == "messages,")
        .and_then(|(n, _)| n.parse().ok())
        .unwrap_or_else(|| panic!("no message count in {out:?}"));
    assert!(out.contains(", 0 dropped"), "{out}");

    // the independent reader: channels, schemas, count, contents
    let got = read_with_python(&file);
    assert_eq!(got["message_count"].as_u64(), Some(total), "{out}");
    assert_eq!(got["channel_count"], 2);
    let g = &got["channels"]["g/state"];
    assert_eq!(g["message_encoding"], "nerve.raw");
    assert_eq!(g["schema_name"], "acme::Gripper");
    assert_eq!(g["schema_encoding"], "nerve.schema+json");
    assert_eq!(g["metadata"]["fingerprint"], format!("{fp:#018x}"));
    assert_eq!(g["metadata"]["agent"], "g");
    assert_eq!(got["channels"]["t1/tick"]["schema_name"], "nerve::Tick");
    let recorded = messages(&got, "g/state");
    assert!(recorded.len() >= 50, "2 s of a 20 ms agent: {}", recorded.len());
    for w in recorded.windows(2) {
        // in order, none lost: the agent counts each sample
        assert_eq!(w[1]["data"]["count"].as_u64(), w[0]["data"]["count"].as_u64().map(|c| c + 1));
        assert_eq!(w[1]["sequence"].as_u64(), w[0]["sequence"].as_u64().map(|s| s + 1));
    }
    assert_eq!(recorded[0]["data"]["tool"], "screwdriver");
    assert_eq!(recorded[0]["data"]["fingers"].as_array().map(Vec::len), Some(3));
    let ticks = messages(&got, "t1/tick");
    assert!(ticks.windows(2).all(|w| w[1]["data"]["seq"].as_u64() > w[0]["data"]["seq"].as_u64()));

    // the replay, recorded again
    r.ok(&["stop", "g"]);
    assert!(wait_until(Duration::from_secs(5), || r.agent("g").is_none()), "g did not stop");
    let again = r.home.join("again.mcap");
    let again_s = again.display().to_string();
    let mut recorder = r
        .command("nerve")
        .args(["record", "--all", "-o", &again_s, "--duration", "7", "-q"])
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("recorder");
    std::thread::sleep(Duration::from_millis(300));
    let mut replay =
        r.command("nerve").args(["replay", &file_s, "--as", "g", "--delay", "2.5", "-q"]).spawn().expect("replay");
    // the replayed agent is in the robot under its recorded name
    assert!(
        wait_until(Duration::from_secs(5), || r.agent("g").is_some_and(|a| a["kind"] == "replay")),
        "ps does not list the replayed agent: {:?}",
        r.ps()
    );
    let e = r.fails(&["start", "gripper", "--name", "g"]);
    assert!(e.contains("g"), "a second g while the replay runs: {e}");
    assert!(replay.wait().expect("replay").success(), "the replay failed");
    assert!(recorder.wait().expect("recorder").success(), "the second recording failed");
    assert!(wait_until(Duration::from_secs(5), || r.agent("g").is_none()), "the replayed agent stayed registered");

    let back = read_with_python(&again);
    let replayed = messages(&back, "g/state");
    assert_eq!(replayed.len(), recorded.len(), "every sample, once");
    for (i, (a, b)) in recorded.iter().zip(replayed).enumerate() {
        assert_eq!(a["hex"], b["hex"], "sample {i} differs");
    }
    // the recorded spacing (20 ms), within what a loaded machine keeps
    let (orig, rep) = (gaps_ms(recorded), gaps_ms(replayed));
    let deviation = median(orig.iter().zip(&rep).map(|(a, b)| (a - b).abs()).collect());
    assert!(deviation < 5.0, "median spacing deviation {deviation:.2} ms: {orig:?} vs {rep:?}");
    let (span_o, span_r): (f64, f64) = (orig.iter().sum(), rep.iter().sum());
    assert!((span_r - span_o).abs() < 0.2 * span_o, "span {span_r:.0} ms vs recorded {span_o:.0} ms");
    r.down_and_check_clean();
}

#[test]
fn replay_refuses_what_it_cannot_do() {
    let r = Robot::new("recbad");
    let junk = nerve_tests::write_file(&r.home, "junk.mcap", "not an mcap file");
    let e = r.fails(&["replay", &junk.display().to_string()]);
    assert!(e.contains("junk.mcap") && e.contains("not a readable MCAP file"), "{e}");
    let e = r.fails(&["replay", "/nonexistent.mcap"]);
    assert!(e.contains("cannot read /nonexistent.mcap"), "{e}");
    let e = r.fails(&["record", "--all", "--duration", "1"]);
    assert!(e.contains("recording needs the router"), "{e}");
    let e = r.fails(&["record"]);
    assert!(e.contains("--all"), "{e}");
}
