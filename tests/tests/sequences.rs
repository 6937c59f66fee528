//! Variable-size payloads end to end (issue 42): a real agent (`detector`,
//! `src/bin/detector.rs`) publishes detections of lengths 0, 1, 400 and
//! 401 on a sequence port (the third grows the port's memory, the fourth
//! is the largest seen plus one) and is refused past its maximum; `nerve
//! echo` prints each sample at its own length (JSON arrays, `--field
//! items[3].x`, `header.frame`), `nerve plot` draws the last element's field,
//! `nerve hz` counts them, and a second agent,
//! connected through the router (its check of header and element), reads
//! them all in place, the grown ones included; the black box keeps them at
//! their lengths.

use nerve_tests::py::{messages, read_mcap};
use nerve_tests::{Robot, wait_until, write_file};
use serde_json::Value;
use std::time::Duration;

/// The lengths the detector sends in turn (its `LENGTHS`).
const LENGTHS: [usize; 4] = [0, 1, 400, 401];

fn length_of(seq: u64) -> usize {
    LENGTHS[(seq as usize - 1) % LENGTHS.len()]
}

#[test]
fn sequences_of_any_length_are_echoed_counted_read_and_refused_past_their_maximum() {
    let r = Robot::new("seq");
    r.router();
    r.ok(&["start", "detector", "--name", "a"]);
    r.ok(&["start", "detector", "--name", "b"]);
    // a black box keeping a/dets: snapshotted at the end, each sample at its length
    let config = write_file(&r.home, "bb.toml", "seconds = 2\nports = [\"a/dets\"]\ndir = \"snaps\"\n");
    r.ok(&["start", "blackbox", "--name", "blackbox", "--", "--config", &config.display().to_string()]);
    let a = r.agent("a").expect("a in ps");
    let dets = a["outputs"].as_array().expect("outputs").iter().find(|o| o["name"] == "dets").expect("dets").clone();
    assert_eq!(dets["type_name"], "nerve::Seq<acme::Detection, acme::DetectionsHeader>", "{dets}");

    // echo --json: the header and every element, at each sample's own length
    let samples = r.echo("a/dets", 8);
    assert_eq!(samples.len(), 8);
    for s in &samples {
        let seq = s["seq"].as_u64().expect("seq");
        let items = s["data"]["items"].as_array().expect("items");
        assert_eq!(items.len(), length_of(seq), "sample {seq}: {}", s["data"]["header"]);
        assert_eq!(s["data"]["header"]["frame"].as_u64(), Some(seq), "{}", s["data"]["header"]);
        assert_eq!(s["data"]["header"]["count"].as_u64(), Some(items.len() as u64));
        if let Some(last) = items.last() {
            let j = items.len() - 1;
            assert_eq!((last["x"].as_f64(), last["id"].as_u64()), (Some(j as f64), Some(j as u64)), "{last}");
        }
    }

    // one element's field: null where a sample has fewer elements
    let field = r.ok(&["echo", "a/dets", "--field", "items[3].x", "--count", "8", "--json", "--timeout", "5"]);
    let lines: Vec<Value> = field.lines().map(|l| serde_json::from_str(l).expect("json")).collect();
    assert_eq!(lines.len(), 8, "{field}");
    for l in &lines {
        let seq = l["seq"].as_u64().expect("seq");
        let want = if length_of(seq) > 3 { Value::from(3.0) } else { Value::Null };
        assert_eq!(l["data"], want, "{l}");
    }
    let human = r.ok(&["echo", "a/dets", "--field", "header.frame", "--count", "1", "--timeout", "5"]);
    assert!(human.contains("header.frame: "), "{human}");
    let e = r.fails(&["echo", "a/dets", "--field", "items[1].z", "--count", "1", "--timeout", "5"]);
    assert!(e.contains("no field \"items[1].z\"") && e.contains("items.<i>.x"), "{e}");

    // plot: the last element's field and the fourth's, live; samples
    // without that element have no point (not an error)
    let svg = r.home.join("dets.svg");
    let out = r.ok(&[
        "plot",
        "a/dets",
        "--field",
        "items[-1].x",
        "--field",
        "items[3].x",
        "--duration",
        "1.5",
        "--quiet",
        "-o",
        &svg.display().to_string(),
    ]);
    let n: u64 =
        out.strip_prefix("plotted ").and_then(|o| o.split(' ').next()).and_then(|n| n.parse().ok()).unwrap_or(0);
    assert!(n >= 2, "{out}");
    let drawn = std::fs::read_to_string(&svg).expect("the figure");
    assert!(drawn.contains("a/dets items[-1].x") && drawn.contains("a/dets items[3].x"), "the legend: {out}");

    // hz reads a sequence port by its bytes, as any port
    let hz = r.ok(&["hz", "a/dets", "--count", "1", "--json", "--window", "0.5"]);
    let rate: Value = serde_json::from_str(hz.trim()).expect("hz json");
    assert!(rate["samples"].as_u64().is_some_and(|n| n > 0), "{rate}");

    // nerve pub lays out a sequence from JSON at its own length, into an input
    let dets = r#"{"header": {"frame": 7, "count": 3}, "items": [
        {"x": 0.0, "y": 7.0, "id": 0}, {"x": 1.0, "y": 7.0, "id": 1}, {"x": 2.0, "y": 7.0, "id": 2}]}"#;
    r.ok(&["pub", "b/dets_in", dets, "--count", "1"]);
    assert!(wait_until(Duration::from_secs(5), || r.figure_u64("b", "received") == 1), "b read the published sample");
    assert_eq!((r.figure_u64("b", "largest"), r.figure_u64("b", "bad")), (3, 0), "3 detections as published");

    // an agent reads them in place through a connection the router checked
    r.ok(&["connect", "a/dets", "b/dets_in"]);
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("b", "received") >= 8),
        "b read {} samples",
        r.figure("b", "received")
    );
    assert_eq!(r.figure_u64("b", "largest"), 401, "the grown samples were read");
    assert_eq!(r.figure_u64("b", "bad"), 0, "every element as sent");

    // recorded at their own lengths, read by the PyPI `mcap` reader through
    // the schema in the file; exported for JSON viewers with arrays
    let file = r.home.join("dets.mcap");
    let file_s = file.display().to_string();
    let out = r.ok(&["record", "a/dets", "-o", &file_s, "--duration", "1", "-q"]);
    assert!(out.contains(", 0 dropped"), "{out}");
    let got = read_mcap(&file);
    let recorded = messages(&got, "a/dets");
    assert!(recorded.len() >= 8, "1 s of a 20 ms agent: {}", recorded.len());
    for m in recorded {
        let frame = m["data"]["header"]["frame"].as_u64().expect("frame");
        assert_eq!(m["data"]["items"].as_array().map(Vec::len), Some(length_of(frame)), "frame {frame}");
    }
    let json_file = r.home.join("dets-json.mcap");
    r.ok(&["export", &file_s, "-o", &json_file.display().to_string()]);
    let exported = read_mcap(&json_file);
    let c = &exported["channels"]["a/dets"];
    assert_eq!(c["json_schema"]["properties"]["items"]["type"], "array", "{}", c["json_schema"]);
    let js = messages(&exported, "a/dets");
    assert_eq!(js.len(), recorded.len());
    for (raw, j) in recorded.iter().zip(js) {
        assert_eq!(raw["data"]["items"].as_array().map(Vec::len), j["data"]["items"].as_array().map(Vec::len));
        assert_eq!(raw["data"]["header"], j["data"]["header"]);
    }

    // the black box's last seconds, as the recorder's
    let snap = r.home.join("snap.mcap");
    r.ok(&["snapshot", "-o", &snap.display().to_string()]);
    let kept = messages(&read_mcap(&snap), "a/dets").to_vec();
    assert!(kept.len() >= 8, "2 s of a 20 ms agent: {}", kept.len());
    for m in &kept {
        let frame = m["data"]["header"]["frame"].as_u64().expect("frame");
        assert_eq!(m["data"]["items"].as_array().map(Vec::len), Some(length_of(frame)), "kept frame {frame}");
    }

    // past the maximum: refused every step, saying what to do, and never sent
    assert!(r.figure_u64("a", "refused") > 0);
    let refusal = r.figure("a", "refusal");
    assert!(refusal.contains("1001 elements") && refusal.contains("the 1000 the port declared"), "{refusal}");
    r.down_and_check_clean();
}
