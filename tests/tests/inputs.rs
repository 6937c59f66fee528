//! Per-input depth and policy from a launch file (issue 46, docs/inputs.md):
//! bad settings refused with FILE:LINE before anything starts; good ones
//! reach the agent (`--input NAME:depth=N,keep=WORD`), which runs with them;
//! a keep-all input under a burst from another process loses nothing, the
//! sender's waits are counted and shown (`nerve ps --json`, `nerve graph`),
//! and a reader that stops reading holds the sender up once, for the bound.
//! The queues themselves are tested on real iceoryx2 in agent-sdk
//! (`port::depth::tests`, `port::keep_all::tests`).

use nerve_tests::{Robot, wait_until};
use serde_json::Value;
use std::time::Duration;

const HEAD: &str = "robot = \"x\"\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nperiod = \"10ms\"\n[[agent]]\nname = \"r1\"\nkind = \"relay\"\n";

/// Each bad input setting is refused at its line, naming what to write, and nothing starts.
#[test]
fn bad_input_settings_are_refused_with_file_and_line() {
    let r = Robot::new("badinputs");
    let cases: &[(&str, &str, &str)] = &[
        ("depth 0", "inputs = { in = { depth = 0 } }\n", ":9: input \"in\" of agent \"r1\": depth 0 is out of range"),
        ("depth 300", "inputs = { in = { depth = 300, keep = \"all\" } }\n", "give 1 to 256"),
        ("depth text", "inputs = { in = { depth = \"64\" } }\n", ":9: input \"in\" of agent \"r1\": depth must be"),
        ("keep word", "inputs = { in = { keep = \"everything\" } }\n", ":9: input \"in\" of agent \"r1\": keep"),
        ("unknown key", "inputs = { in = { deep = 4 } }\n", ":9: input \"in\" of agent \"r1\": unknown setting"),
        (
            "unknown input",
            "inputs = { inn = { depth = 4 } }\n",
            ":9: agent \"r1\" has no input \"inn\" (its inputs: in)",
        ),
    ];
    for (what, line, expect) in cases {
        let file = r.launch_file("bad.toml", &format!("{HEAD}{line}"));
        let out = r.command("nerve").arg("launch").arg(&file).output().expect("launch");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{what}: accepted");
        assert!(err.contains(&file.display().to_string()), "{what}: names the file: {err}");
        assert!(err.contains(expect), "{what}: expected {expect:?} in:\n{err}");
        assert!(err.contains("nothing was started"), "{what}: {err}");
        assert!(r.shm_files().is_empty(), "{what}: shared memory was created");
        r.ok(&["down"]);
    }
}

/// A keep-all input of depth 64 from the launch file reaches the agent,
/// which relays through it.
#[test]
fn input_settings_from_the_launch_file_reach_the_agent() {
    let r = Robot::new("inputs");
    let body = format!(
        "{HEAD}inputs = {{ in = {{ depth = 64, keep = \"all\" }} }}\n[[connect]]\nfrom = \"t1/tick\"\nto = \"r1/in\"\n"
    );
    let file = r.launch_file("inputs.toml", &body);
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    let cmdline = std::fs::read(format!("/proc/{}/cmdline", r.pid("r1"))).expect("the relay's command line");
    let args: Vec<String> = cmdline.split(|b| *b == 0).map(|a| String::from_utf8_lossy(a).into_owned()).collect();
    let at = args.iter().position(|a| a == "--input").expect("--input passed");
    assert_eq!(args.get(at + 1).map(String::as_str), Some("in:depth=64,keep=all"), "{args:?}");
    let relayed = r.echo("r1/out", 3);
    assert_eq!(relayed.len(), 3, "relayed through the keep-all input: {relayed:?}");
    r.down_and_check_clean();
}

/// The figures of `agent`'s `list` (`inputs`, `queues`, `outputs`) whose
/// `key` is `name`, from `nerve ps --json`.
fn stat(r: &Robot, agent: &str, list: &str, key: &str, name: &str) -> Value {
    let a = r.agent(agent).unwrap_or(Value::Null);
    a["stats"][list].as_array().and_then(|l| l.iter().find(|e| e[key] == name).cloned()).unwrap_or(Value::Null)
}

/// A burst of 1,000 samples from another process into a keep-all input of
/// depth 32 (far past depth + 16) arrives whole: the reader (periodic, 20
/// ms) takes at most its depth a period, so the sender waits for it; its
/// waits are counted as back-pressure, nothing is lost, and `nerve ps
/// --json` and `nerve graph` say so. A default input on the same output
/// keeps its default. Then the reader is suspended: the sender waits once,
/// for the bound, and sends on, counting what the reader lost.
#[test]
fn a_burst_into_a_keep_all_input_arrives_whole_and_the_senders_waits_are_counted() {
    let r = Robot::new("burst");
    let body = r#"robot = "x"
[[agent]]
name = "b"
kind = "testagent"
args = ["--mode", "burst"]
[[agent]]
name = "all"
kind = "testagent"
inputs = { in = { depth = 32, keep = "all" } }
[[agent]]
name = "latest"
kind = "testagent"
[[connect]]
from = "b/value"
to = "all/in"
[[connect]]
from = "b/value"
to = "latest/in"
"#;
    let file = r.launch_file("burst.toml", body);
    r.ok(&["launch", file.to_str().expect("utf-8 path")]);
    let received = || stat(&r, "all", "inputs", "input", "in")["received"].as_u64().unwrap_or(0);
    assert!(
        wait_until(Duration::from_secs(30), || received() >= 1000),
        "the burst did not arrive: {:?}",
        r.agent("all")
    );
    let input = stat(&r, "all", "inputs", "input", "in");
    assert_eq!(input["dropped"], 0, "nothing lost: {input}");
    let queue = stat(&r, "all", "queues", "input", "in");
    assert_eq!((queue["depth"].as_u64(), queue["keep_all"].as_bool()), (Some(32), Some(true)), "{queue}");
    assert_eq!(queue["lossless"], true, "the sender publishes to it losslessly: {queue}");
    let out = stat(&r, "b", "outputs", "output", "value");
    assert_eq!((out["keep_all_readers"].as_u64(), out["lost"].as_u64()), (Some(1), Some(0)), "{out}");
    assert!(out["back_pressure"].as_u64().unwrap_or(0) > 0, "the sender waited for the reader: {out}");
    let latest = stat(&r, "latest", "queues", "input", "in");
    assert_eq!((latest["depth"].as_u64(), latest["keep_all"].as_bool()), (Some(16), Some(false)), "{latest}");

    let edges = r.graph()["connections"].as_array().cloned().unwrap_or_default();
    let edge = edges.iter().find(|c| c["to"] == "all/in").expect("the keep-all edge");
    assert_eq!(
        (edge["depth"].as_u64(), edge["keep"].as_str(), edge["lossless"].as_bool()),
        (Some(32), Some("all"), Some(true)),
        "{edge}"
    );
    assert!(edge["back_pressure"].as_u64().unwrap_or(0) > 0 && edge["lost"] == 0, "{edge}");
    let text = r.ok(&["graph"]);
    assert!(text.contains("all/in <- b/value: depth 32, keep all (lossless: the sender waits)"), "{text}");
    assert!(!text.contains("latest/in <-"), "a default input is not listed: {text}");

    // a reader that stops reading: its buffer fills, the sender waits once
    // for the bound, then sends on (its cycles go on) and counts the lost
    r.ok(&["suspend", "all"]);
    let cycles = || r.agent("b").and_then(|a| a["stats"]["cycles"].as_u64()).unwrap_or(0);
    let lost = || stat(&r, "b", "outputs", "output", "value")["lost"].as_u64().unwrap_or(0);
    let before = cycles();
    assert!(
        wait_until(Duration::from_secs(30), || lost() > 0 && cycles() > before + 50),
        "the sender stalled behind a suspended keep-all reader: {:?}",
        r.agent("b")
    );
    r.down_and_check_clean();
}
