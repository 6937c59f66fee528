//! Sequences in Python (issue 42): a Python agent (`python/tests/seq_detector.py`)
//! and the Rust test agent `detector` (`src/bin/detector.rs`) of one
//! sequence type, `Seq<acme::Detection, acme::DetectionsHeader>`, wired
//! both ways through the router (its check of header and element) in a
//! real robot. Each sends lengths 0, 1, 400 and 401 (the third grows the
//! port's memory, the fourth is the largest seen plus one) and is refused
//! past its maximum of 1,000; each reads the other's samples in place at
//! their own length and checks every element.

use nerve_tests::py::python_with_nerve;
use nerve_tests::{Robot, wait_until};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The lengths both agents send in turn.
const LENGTHS: [usize; 4] = [0, 1, 400, 401];

fn seq_detector_py() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("python").join("tests").join("seq_detector.py")
}

/// `nerve ARGS` with the package's Python first on PATH; its stdout.
fn ok(r: &Robot, bin: &Path, args: &[&str]) -> String {
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    let out = r.command("nerve").args(args).env("PATH", path).output().expect("run nerve");
    if !out.status.success() {
        r.dump_logs();
    }
    assert!(
        out.status.success(),
        "nerve {args:?} failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn output_type(r: &Robot, agent: &str, port: &str) -> Value {
    let a = r.agent(agent).unwrap_or_else(|| panic!("{agent} in ps"));
    a["outputs"].as_array().and_then(|o| o.iter().find(|o| o["name"] == port)).map(|o| o["type_name"].clone()).into()
}

#[test]
fn a_python_and_a_rust_agent_of_one_sequence_type_read_each_other_both_ways() {
    let (_python, bin) = python_with_nerve();
    let r = Robot::new("pyseq");
    let file = r.launch_file(
        "seq.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "d"
kind = "detector"

[[agent]]
name = "p"
exe = "{}"

[[connect]]
from = "d/dets"
to = "p/dets_in"

[[connect]]
from = "p/dets"
to = "d/dets_in"
"#,
            seq_detector_py().display()
        ),
    );
    ok(&r, &bin, &["launch", file.to_str().expect("utf-8 path")]);
    // one type, named and laid out alike on both sides (else the router refuses the wires)
    let want = Value::from("nerve::Seq<acme::Detection, acme::DetectionsHeader>");
    assert_eq!(output_type(&r, "p", "dets"), want);
    assert_eq!(output_type(&r, "d", "dets"), want);

    // Rust reads Python's samples in place, every element as sent, the grown ones too
    assert!(
        wait_until(Duration::from_secs(10), || r.figure_u64("d", "received") >= 8
            && r.figure_u64("d", "largest") == 401),
        "the Rust detector read {} samples, the largest of {} elements",
        r.figure("d", "received"),
        r.figure("d", "largest")
    );
    assert_eq!(r.figure_u64("d", "bad"), 0, "every element Python wrote, as written");

    // Python reads Rust's, as numpy views of the samples (not copies)
    let read = |r: &Robot| r.echo("p/report", 1).pop().map(|v| v["data"].clone()).unwrap_or_default();
    assert!(
        wait_until(Duration::from_secs(10), || {
            let d = read(&r);
            d["received"].as_u64() >= Some(8) && d["largest"] == 401
        }),
        "the Python agent read {}",
        read(&r)
    );
    let d = read(&r);
    assert_eq!(d["bad"], 0, "{d}");
    assert!(d["zero_copy"].as_u64() > Some(0), "no sample was read in place: {d}");
    // past its maximum: refused every step, nothing sent (the lengths below have no 1,001)
    assert!(d["refused"].as_u64() > Some(0), "{d}");

    // each sample at its own length, as nerve echo decodes it by the schema Python registered
    for s in r.echo("p/dets", 8) {
        let frame = s["data"]["header"]["frame"].as_u64().expect("frame");
        let items = s["data"]["items"].as_array().expect("items");
        assert_eq!(items.len(), LENGTHS[(frame as usize - 1) % LENGTHS.len()], "frame {frame}");
        assert_eq!(s["data"]["header"]["count"].as_u64(), Some(items.len() as u64));
        if let Some(last) = items.last() {
            let j = (items.len() - 1) as f64;
            assert_eq!((last["x"].as_f64(), last["y"].as_f64()), (Some(j), Some(frame as f64)), "{last}");
        }
    }
    r.down_and_check_clean();
}
