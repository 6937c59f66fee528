//! Per-input depth and policy from a launch file (issue 46, docs/inputs.md):
//! bad settings refused with FILE:LINE before anything starts; good ones
//! reach the agent (`--input NAME:depth=N,keep=WORD`), which runs with them.
//! The burst behaviour itself is tested on real iceoryx2 in agent-sdk
//! (`port::depth::tests`).

use nerve_tests::Robot;

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
