//! The black box end to end: a `blackbox` agent keeps the last seconds of a
//! ticker and of a gripper (a type nerve was not built with); `nerve
//! snapshot` writes them, and the file, read by the `mcap` package from
//! PyPI, holds the last seconds and no more, every sample in order. When
//! the gripper is killed the black box writes a file by itself that holds
//! the seconds before the death and the moment after; a clean stop fires
//! nothing. A configuration with a typo is refused at its line. Fired
//! snapshots are capped by count (the oldest deleted), a stale `.part` is
//! swept at start, and a disk below the free-space margin gets none.

use nerve_tests::py::{messages, read_mcap};
use nerve_tests::{Robot, wait_until, write_file};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::Duration;

fn log_times(msgs: &[Value]) -> Vec<u64> {
    msgs.iter().map(|m| m["log_time"].as_u64().expect("log_time")).collect()
}

fn snapshots(dir: &Path, what: &str) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.to_string_lossy().contains(what) && p.extension().is_some_and(|e| e == "mcap"))
                .collect()
        })
        .unwrap_or_default()
}

fn unix_now_ns() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

#[test]
fn the_black_box_holds_the_last_seconds_and_fires_on_a_death() {
    let r = Robot::new("bbox");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "gripper", "--name", "g"]);
    let config = write_file(
        &r.home,
        "bb.toml",
        "seconds = 3\nports = [\"t1/tick\", \"g/state\"]\nafter = 0.5\ndir = \"snaps\"\n[fire]\non_death = true\nmin_gap = 0\n",
    );
    let config_s = config.display().to_string();
    r.ok(&["start", "blackbox", "--name", "blackbox", "--", "--config", &config_s]);
    assert!(
        wait_until(Duration::from_secs(10), || r.agent("blackbox").is_some() && r.figure_u64("blackbox", "ports") == 2),
        "the black box does not keep both ports: {:?}",
        r.ps()
    );
    // more than the kept seconds go by
    std::thread::sleep(Duration::from_millis(4500));

    // asked: the last 3 s
    let manual = r.home.join("manual.mcap");
    let said = r.ok(&["snapshot", "-o", &manual.display().to_string()]);
    assert!(said.contains("t1/tick") && said.contains("g/state"), "{said}");
    let got = read_mcap(&manual);
    assert_eq!(got["channels"]["g/state"]["schema_name"], "acme::Gripper");
    let ticks = messages(&got, "t1/tick");
    let t = log_times(ticks);
    let span = (t[t.len() - 1] - t[0]) as f64 / 1e9;
    assert!((2.5..=3.05).contains(&span), "the last 3 s and no more: {span:.2} s of ticks");
    assert!(ticks.len() >= 150, "3 s of a 10 ms ticker: {}", ticks.len());
    for w in ticks.windows(2) {
        assert_eq!(w[1]["sequence"].as_u64(), w[0]["sequence"].as_u64().map(|s| s + 1), "every tick, in order");
    }
    let e = r.fails(&["snapshot", "-o", &manual.display().to_string()]);
    assert!(e.contains("exists"), "a snapshot does not overwrite: {e}");

    // fired: g dies
    let killed_at = unix_now_ns();
    r.ok(&["kill", "g"]);
    let dir = r.home.join("snaps");
    assert!(
        wait_until(Duration::from_secs(10), || !snapshots(&dir, "died-g").is_empty()),
        "no snapshot after g's death in {}: {:?}",
        dir.display(),
        std::fs::read_dir(&dir).map(|d| d.filter_map(|e| e.ok()).map(|e| e.file_name()).collect::<Vec<_>>())
    );
    let fired = snapshots(&dir, "died-g").remove(0);
    let got = read_mcap(&fired);
    let g = log_times(messages(&got, "g/state"));
    let ms = |t: u64| (t as f64 - killed_at as f64) / 1e6;
    assert!(ms(g[g.len() - 1]) < 100.0, "g's last sample is from before its death: {:.0} ms", ms(g[g.len() - 1]));
    assert!(ms(g[0]) < -2000.0, "the seconds before the death are there: first g sample {:.0} ms", ms(g[0]));
    let counts: Vec<u64> = messages(&got, "g/state").iter().filter_map(|m| m["data"]["count"].as_u64()).collect();
    assert!(counts.windows(2).all(|w| w[1] == w[0] + 1), "every g sample up to its death, in order");
    let t = log_times(messages(&got, "t1/tick"));
    assert!(ms(t[t.len() - 1]) > 300.0, "and the moment after it: last tick {:.0} ms", ms(t[t.len() - 1]));

    // a clean stop is no death
    r.ok(&["stop", "t1"]);
    assert!(wait_until(Duration::from_secs(5), || r.agent("t1").is_none()), "t1 did not stop");
    std::thread::sleep(Duration::from_millis(1500));
    assert!(snapshots(&dir, "died-t1").is_empty(), "a clean stop fired the black box");
    assert_eq!(snapshots(&dir, "died").len(), 1, "one death, one file");
    r.down_and_check_clean();
}

/// A watched field that changes (here the tool a gripper reports holding,
/// as a safety stop's `active` or a mode would) fires a snapshot that
/// holds the change; samples that repeat the value fire nothing. The
/// gripper starts after the black box, which finds it when it registers.
#[test]
fn a_watched_field_that_changes_fires_the_black_box() {
    let r = Robot::new("bboxchg");
    r.router();
    let config = write_file(
        &r.home,
        "bb.toml",
        "seconds = 2\nports = []\nafter = 0.3\ndir = \"snaps\"\n[[fire.on_change]]\nport = \"g/state\"\nfield = \"tool\"\n",
    );
    r.ok(&["start", "blackbox", "--name", "bb", "--", "--config", &config.display().to_string()]);
    // started after the black box: found when it registers
    r.ok(&["start", "gripper", "--name", "g"]);
    assert!(
        wait_until(Duration::from_secs(10), || r.agent("bb").is_some() && r.figure_u64("bb", "ports") == 1),
        "the black box does not keep g/state: {:?}",
        r.ps()
    );
    let dir = r.home.join("snaps");
    std::thread::sleep(Duration::from_millis(1500));
    assert!(snapshots(&dir, "change").is_empty(), "an unchanged field fired");
    r.ok(&["param", "set", "g", "tool", "hammer"]);
    assert!(wait_until(Duration::from_secs(10), || !snapshots(&dir, "change").is_empty()), "the change did not fire");
    let got = read_mcap(&snapshots(&dir, "change").remove(0));
    let tools: Vec<&str> = messages(&got, "g/state").iter().filter_map(|m| m["data"]["tool"].as_str()).collect();
    let first_hammer = tools.iter().position(|t| *t == "hammer").expect("the change is in the file");
    assert!(first_hammer > 10 && tools[..first_hammer].iter().all(|t| *t == "screwdriver"), "{tools:?}");
    r.down_and_check_clean();
}

#[test]
fn a_bad_configuration_is_refused_at_its_line() {
    let r = Robot::new("bboxcfg");
    r.router();
    let config = write_file(&r.home, "bb.toml", "seconds = 3\nports = [\"t1/tick\"]\nsecnds = 4\n");
    let e = r.fails(&["start", "blackbox", "--name", "bb", "--", "--config", &config.display().to_string()]);
    assert!(e.contains("secnds") && e.contains("line 3"), "{e}");
    let e = r.fails(&["snapshot", "--agent", "nobb"]);
    assert!(e.contains("no black box named \"nobb\""), "{e}");
    r.down_and_check_clean();
}

/// The black box's folder keeps `max_files` fired snapshots, the newest;
/// a `.part` left by an earlier run is swept at start; a black box whose
/// free-space margin the disk cannot give writes nothing, and counts it.
#[test]
fn fired_snapshots_are_capped_and_a_disk_below_the_margin_gets_none() {
    let r = Robot::new("bbcap");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    let dir = r.home.join("snaps");
    std::fs::create_dir_all(&dir).expect("dir");
    let stale = write_file(&dir, "blackbox-20260101-000000.000-died-x.mcap.part", "half a file");
    let body = "seconds = 1\nports = [\"t1/tick\"]\nafter = 0\nmax_mb = 16\nmax_files = 2\nmax_total_mb = 64\n";
    let config =
        write_file(&r.home, "bb.toml", &format!("{body}dir = \"snaps\"\n[fire]\non_death = true\nmin_gap = 0\n"));
    r.ok(&["start", "blackbox", "--name", "bb", "--", "--config", &config.display().to_string()]);
    assert!(
        wait_until(Duration::from_secs(10), || r.agent("bb").is_some() && r.figure_u64("bb", "ports") == 1),
        "the black box does not keep t1/tick: {:?}",
        r.ps()
    );
    assert!(!stale.exists(), "the stale .part was not swept");
    for i in 0..4u64 {
        let name = format!("v{i}");
        r.ok(&["start", "ticker", "--name", &name, "--period", "50ms"]);
        assert!(wait_until(Duration::from_secs(10), || r.agent(&name).is_some()), "{name} did not start");
        r.ok(&["kill", &name]);
        assert!(
            wait_until(Duration::from_secs(10), || r.figure_u64("bb", "snapshots") == i + 1),
            "no snapshot after {name}'s death: {:?}",
            r.figures("bb")
        );
    }
    let mut kept: Vec<String> = snapshots(&dir, "died-")
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    kept.sort();
    assert_eq!(kept.len(), 2, "max_files = 2: {kept:?}");
    assert!(kept[0].ends_with("died-v2.mcap") && kept[1].ends_with("died-v3.mcap"), "the newest stay: {kept:?}");
    assert_eq!(r.figure_u64("bb", "deleted"), 2, "{:?}", r.figures("bb"));
    assert!(snapshots(&dir, ".part").is_empty());

    // a margin no disk has: nothing is written, and it is counted
    let dir2 = r.home.join("snaps2");
    let config2 = write_file(
        &r.home,
        "bb2.toml",
        &format!("{body}dir = \"snaps2\"\nmin_free_mb = 1000000000\n[fire]\non_death = true\nmin_gap = 0\n"),
    );
    r.ok(&["start", "blackbox", "--name", "bb2", "--", "--config", &config2.display().to_string()]);
    assert!(wait_until(Duration::from_secs(10), || r.agent("bb2").is_some() && r.figure_u64("bb2", "ports") == 1));
    r.ok(&["start", "ticker", "--name", "v9", "--period", "50ms"]);
    assert!(wait_until(Duration::from_secs(10), || r.agent("v9").is_some()), "v9 did not start");
    r.ok(&["kill", "v9"]);
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("bb2", "refused") == 1),
        "the low disk was not counted: {:?}",
        r.figures("bb2")
    );
    assert!(snapshots(&dir2, "").is_empty(), "a snapshot below the margin");
    assert_eq!(r.figure_u64("bb2", "snapshots"), 0);
    r.down_and_check_clean();
}
