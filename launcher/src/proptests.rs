//! Property tests of the launch-file reader (`launch_file::load_with_args`) under
//! generated input (issue 40, "every decoder of outside bytes"): arbitrary
//! bytes, arbitrary text, launch files built from the real keys with
//! generated values, and such files with one character changed or cut.
//! `load` returns a launch file or its errors, never panics, and every
//! error names a line of the file (1 ..= its line count, or 1 for an empty
//! file).
//!
//! The agents' kinds are ones no executable has (`zz...`), so no agent is
//! started for `--describe`; each case writes its file in a folder of its
//! own, removed when the case ends (also when it fails).
//!
//! The default case count is proptest's (256, or `PROPTEST_CASES`); the long
//! run is in `docs/robustness.md`.

use crate::launch_file::{LaunchErrors, load_with_args};
use proptest::prelude::*;
use std::path::PathBuf;

/// A folder of this test process, removed when dropped.
struct Folder(PathBuf);

impl Folder {
    fn new() -> Self {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let p = std::env::temp_dir().join(format!("nerve-proptest-launch-{}-{n}", std::process::id()));
        std::fs::create_dir_all(&p).expect("a temporary folder");
        Folder(p)
    }
}

impl Drop for Folder {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Loads `bytes` as a launch file: no panic, and every error on a line of
/// the file.
fn check(bytes: &[u8]) -> Result<(), TestCaseError> {
    let dir = Folder::new();
    let path = dir.0.join("robot.toml");
    std::fs::write(&path, bytes).expect("write the launch file");
    if let Err(e) = load_with_args(&path, "proptest", false, &[])
        && let Some(errors) = e.downcast_ref::<LaunchErrors>()
    {
        let lines = bytes.iter().filter(|b| **b == b'\n').count() + 1;
        for (line, msg) in &errors.errors {
            prop_assert!((1..=lines).contains(line), "line {} of {}: {}", line, lines, msg);
            prop_assert!(!msg.is_empty());
        }
    }
    Ok(())
}

/// A TOML value of a kind a key may or may not take.
fn value() -> impl Strategy<Value = String> {
    prop_oneof![
        "[a-z0-9 _./{}-]{0,12}".prop_map(|s| format!("{s:?}")),
        any::<i64>().prop_map(|i| i.to_string()),
        any::<f64>().prop_map(|f| if f.is_finite() { format!("{f:?}") } else { "nan".into() }),
        any::<bool>().prop_map(|b| b.to_string()),
        Just("\"10ms\"".to_string()),
        Just("\"on-failure\"".to_string()),
        Just("\"0-1\"".to_string()),
        Just("[0, 1]".to_string()),
        Just("{ step = 1 }".to_string()),
        Just("[\"a\", \"b\"]".to_string()),
        Just("\"off\"".to_string()),
    ]
}

const AGENT_KEYS: &[&str] = &[
    "name",
    "kind",
    "exe",
    "period",
    "device",
    "args",
    "params",
    "restart",
    "max_restarts",
    "restart_window",
    "backoff",
    "importance",
    "suspended",
    "log_level",
    "cpu_latency",
    "cpus",
    "unknown_key",
];

/// A launch file from the real keys: a robot, agents (kinds that do not
/// exist), connections, each key with a generated value.
fn launch_text() -> impl Strategy<Value = String> {
    let agent = (
        "[a-z][a-z0-9_]{0,8}",
        "zz[a-z]{0,6}",
        proptest::collection::vec((proptest::sample::select(AGENT_KEYS), value()), 0..6),
    )
        .prop_map(|(name, kind, keys)| {
            let mut s = format!("[[agent]]\nname = {name:?}\nkind = {kind:?}\n");
            for (k, v) in keys {
                s.push_str(&format!("{k} = {v}\n"));
            }
            s
        });
    let connect = ("[a-z0-9/._-]{0,12}", "[a-z0-9/._-]{0,12}", any::<bool>())
        .prop_map(|(from, to, cycle)| format!("[[connect]]\nfrom = {from:?}\nto = {to:?}\nallow_cycle = {cycle}\n"));
    (
        proptest::option::of(value()),
        proptest::option::of(value()),
        proptest::collection::vec(agent, 0..4),
        proptest::collection::vec(connect, 0..4),
    )
        .prop_map(|(robot, latency, agents, connects)| {
            let mut s = String::new();
            if let Some(r) = robot {
                s.push_str(&format!("robot = {r}\n"));
            }
            if let Some(l) = latency {
                s.push_str(&format!("cpu_latency = {l}\n"));
            }
            s.push_str(&agents.concat());
            s.push_str(&connects.concat());
            s
        })
}

proptest! {
    // no regression files in the source tree: a failure prints its input
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::default() })]

    /// Arbitrary bytes, and arbitrary text (multi-byte characters included).
    #[test]
    fn proptest_launch_arbitrary(bytes in proptest::collection::vec(any::<u8>(), 0..512), text in "\\PC{0,256}") {
        check(&bytes)?;
        check(text.as_bytes())?;
    }

    /// Files of the real keys with generated values.
    #[test]
    fn proptest_launch_generated(text in launch_text()) {
        check(text.as_bytes())?;
    }

    /// Such files with one character changed (any character, multi-byte
    /// ones included) or cut short.
    #[test]
    fn proptest_launch_mutated(
        text in launch_text(),
        at in any::<prop::sample::Index>(),
        with in any::<char>(),
        cut in any::<prop::sample::Index>(),
    ) {
        let mut chars: Vec<char> = text.chars().collect();
        if !chars.is_empty() {
            let i = at.index(chars.len());
            chars[i] = with;
        }
        let changed: String = chars.iter().collect();
        check(changed.as_bytes())?;
        let end = text.char_indices().nth(cut.index(text.chars().count().max(1))).map_or(text.len(), |(b, _)| b);
        check(&text.as_bytes()[..end])?;
    }
}
