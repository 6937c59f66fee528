//! One compatibility rule for a connection, everywhere (issue 41): a Python
//! agent that declares `nerve::Tick` with one field more than the Rust
//! ticker's is refused by `nerve launch` at the connection's line before
//! anything starts, and by the router on `nerve connect` on a running
//! robot; both refusals list the field that differs and never guess which
//! side is "the older build" (a Python agent's executable is the
//! interpreter).

use nerve_tests::py::python_with_nerve;
use nerve_tests::{Robot, wait_until};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

/// The line every refusal must carry: the Python side's extra field.
const EXTRA: &str = "field `spread` (f64, 8 bytes at offset 16): only in wide/tick";

/// Writes the Python agent `widetick` into the robot's home: one input
/// `tick` of `nerve::Tick` laid out with a third field.
fn wide_agent(r: &Robot) -> PathBuf {
    let path = r.home.join("widetick.py");
    std::fs::write(
        &path,
        r#"#!/usr/bin/env python3
"""An agent whose nerve::Tick has one field more than the Rust one's."""
import nerve

WIDE = nerve.payload("nerve::Tick", [("seq", "u64"), ("stamp_ns", "u64"), ("spread", "f64")])


class WideTick(nerve.Agent):
    kind = "widetick"
    period = 0.1

    def new(self, setup):
        self.tick = setup.input("tick", WIDE)

    def step(self, ctx):
        self.tick.latest()


if __name__ == "__main__":
    nerve.run(WideTick)
"#,
    )
    .expect("write the Python agent");
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    path
}

/// `nerve ARGS` with the package's Python first on PATH (for `#!/usr/bin/env python3`).
fn nerve(r: &Robot, bin: &Path, args: &[&str]) -> Output {
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    r.command("nerve").args(args).env("PATH", path).output().expect("run nerve")
}

/// The processes whose command line or environment names robot `name`
/// (an agent, the router), besides this test.
fn processes_of(name: &str) -> Vec<String> {
    let me = std::process::id().to_string();
    let robot_env = format!("NERVE_ROBOT={name}");
    let Ok(dir) = std::fs::read_dir("/proc") else { return vec![] };
    dir.filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|pid| pid.bytes().all(|b| b.is_ascii_digit()) && *pid != me)
        .filter_map(|pid| {
            let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
            let environ = std::fs::read(format!("/proc/{pid}/environ")).unwrap_or_default();
            let has = |hay: &[u8], needle: &str| hay.split(|b| *b == 0).any(|part| part == needle.as_bytes());
            let cmd = String::from_utf8_lossy(&cmdline).replace('\0', " ");
            (has(&environ, &robot_env) || cmd.contains(name)).then(|| format!("{pid}: {cmd}"))
        })
        .collect()
}

#[test]
fn a_launch_with_one_type_of_two_layouts_is_refused_at_the_connection_before_anything_starts() {
    let (_python, bin) = python_with_nerve();
    let r = Robot::new("compat");
    let wide = wide_agent(&r);
    let body = format!(
        r#"robot = "x"
[[agent]]
name = "t1"
kind = "ticker"
period = "20ms"

[[agent]]
name = "wide"
exe = "{}"

[[connect]]
from = "t1/tick"
to = "wide/tick"
"#,
        wide.display()
    );
    let line = body.lines().position(|l| l.starts_with("from = \"t1/tick\"")).expect("the connection's line") + 1;
    let file = r.launch_file("compat.toml", &body);
    let out = nerve(&r, &bin, &["launch", file.to_str().expect("utf-8 path")]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "launched: {err}");
    let at = format!(
        "{}:{line}: cannot connect t1/tick to wide/tick: both declare nerve::Tick, but laid out differently:",
        file.display()
    );
    assert!(err.contains(&at), "no refusal at the connection's line ({at}):\n{err}");
    assert!(err.contains(EXTRA), "the extra field is not listed:\n{err}");
    assert!(err.contains("size of the payload: 16 bytes in t1/tick, 24 bytes in wide/tick"), "{err}");
    assert!(err.contains("make both declare the same layout of nerve::Tick"), "{err}");
    assert!(err.contains("nothing was started") && !err.contains("older"), "{err}");
    // nothing started: no router, no agent, no shared memory, no pid file
    assert_eq!(r.pid_file("router"), None, "a router was started");
    assert!(r.shm_files().is_empty(), "shared memory was made: {:?}", r.shm_files());
    let left = processes_of(&r.name);
    assert!(left.is_empty(), "processes of the robot run: {left:?}");
    let ps = nerve(&r, &bin, &["ps", "--json"]);
    assert!(!ps.status.success(), "a router answers `nerve ps`: {}", String::from_utf8_lossy(&ps.stdout));
}

#[test]
fn connecting_one_type_of_two_layouts_on_a_running_robot_is_refused_with_the_fields() {
    let (_python, bin) = python_with_nerve();
    let r = Robot::new("compatc");
    let wide = wide_agent(&r);
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "20ms"]);
    let started = nerve(&r, &bin, &["start", wide.to_str().expect("utf-8 path"), "--name", "wide"]);
    if !started.status.success() {
        r.dump_logs();
    }
    assert!(started.status.success(), "the Python agent did not start: {}", String::from_utf8_lossy(&started.stderr));
    assert!(wait_until(Duration::from_secs(10), || r.ps().len() == 2), "the two agents did not register");

    let err = r.fails(&["connect", "t1/tick", "wide/tick"]);
    assert!(err.contains("cannot connect t1/tick to wide/tick") && err.contains("nerve::Tick"), "{err}");
    assert!(err.contains(EXTRA), "the extra field is not listed:\n{err}");
    assert!(err.contains("make both declare the same layout of nerve::Tick"), "{err}");
    assert!(!err.contains("older"), "the refusal guesses which side is older: {err}");
    assert!(r.edges().is_empty(), "connected: {:?}", r.edges());
    r.down_and_check_clean();
}
