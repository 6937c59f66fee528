//! Four languages in one robot (issue 43, "a real port"): `launch/polyglot.toml`
//! runs the simulated H1 with its Rust agents (simulator, sonar, motor), a
//! plain C library that knows nothing of nerve made an agent by its glue
//! (`agent-sdk-c/examples/polyglot/risk.c` around `sonar_risk/`), a C++
//! agent (`smooth.cpp`, nerve.hpp) and a Python agent (`cautious.py`) that
//! drives the robot from the smoothed risk. The C and C++ agents are built
//! with the example's own CMakeLists.txt, as a user builds them; the robot
//! is launched with the file as it is in the tree, with `build=` pointing
//! at this test's build folder. Needs cmake, gcc and g++ (`scripts/setup.sh
//! --test`), libnerve.so beside the binaries (`cargo build --workspace
//! --lib --bins`) and the Python package (`.ci/run` installs it).

use nerve_tests::py::python_with_nerve;
use nerve_tests::{Robot, bin_dir, wait_until};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Runs `cmd`, panicking with its output when it fails.
fn run(what: &str, cmd: &mut Command) -> Output {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e} (scripts/setup.sh --test installs cmake, g++)"));
    assert!(
        out.status.success(),
        "{what} failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Builds the example's C and C++ agents with cmake into `dir`.
fn build_examples(dir: &Path) {
    let lib = bin_dir();
    assert!(lib.join("libnerve.so").exists(), "no libnerve.so in {}: cargo build --workspace --lib", lib.display());
    let src = repo().join("agent-sdk-c/examples/polyglot");
    run(
        "cmake (configure)",
        Command::new("cmake").arg("-S").arg(&src).arg("-B").arg(dir).arg(format!("-DNERVE_LIB_DIR={}", lib.display())),
    );
    run("cmake --build", Command::new("cmake").arg("--build").arg(dir));
    for exe in ["crisk", "smooth"] {
        assert!(dir.join(exe).exists(), "cmake built no {exe} in {}", dir.display());
    }
}

/// The position of the robot's newest odometry.
fn position(r: &Robot, path: &str) -> Option<(f64, f64)> {
    let out = r
        .command("nerve")
        .args(["echo", "motor/odom", "--count", "1", "--json", "--timeout", "5"])
        .env("PATH", path)
        .output()
        .ok()?;
    let v: Value = serde_json::from_slice(out.stdout.split(|b| *b == b'\n').next()?).ok()?;
    Some((v["data"]["x"].as_f64()?, v["data"]["y"].as_f64()?))
}

#[test]
fn rust_c_cpp_and_python_agents_drive_one_robot() {
    let r = Robot::new("poly");
    let build = r.home.join("polyglot-build");
    build_examples(&build);
    let (_python, py_bin) = python_with_nerve();
    // the Python agent's `#!/usr/bin/env python3` finds the package's Python
    // (the router, which starts the agents, inherits this PATH)
    let path = format!("{}:{}", py_bin.display(), std::env::var("PATH").unwrap_or_default());
    let arg = format!("build={}", build.display());
    let launch = r
        .command("nerve")
        .current_dir(repo())
        .args(["launch", "launch/polyglot.toml", &arg])
        .env("PATH", &path)
        .output()
        .expect("nerve launch");
    if !launch.status.success() {
        r.dump_logs();
    }
    assert!(
        launch.status.success(),
        "nerve launch launch/polyglot.toml failed:\n{}{}",
        String::from_utf8_lossy(&launch.stdout),
        String::from_utf8_lossy(&launch.stderr)
    );
    for (name, kind) in [("risk", "crisk"), ("smooth", "smooth"), ("cautious", "cautious")] {
        let a = r.agent(name).unwrap_or_else(|| panic!("{name} is not running"));
        assert_eq!(a["kind"], kind, "{a}");
    }

    // the C++ agent's output: the C library's risk, smoothed, in [0, 1]
    let smoothed = r.echo("smooth/out", 3);
    for s in &smoothed {
        let v = s["data"]["value"].as_f64().expect("a value");
        assert!((0.0..=1.0).contains(&v), "a risk out of [0, 1]: {s}");
    }
    // the Python agent drives the Rust motor: the simulated robot moves
    let start = position(&r, &path).expect("odometry");
    let moved = wait_until(Duration::from_secs(20), || {
        position(&r, &path).is_some_and(|(x, y)| ((x - start.0).powi(2) + (y - start.1).powi(2)).sqrt() > 0.3)
    });
    if !moved {
        r.dump_logs();
    }
    assert!(moved, "the robot did not move 0.3 m from {start:?} in 20 s");

    // the C++ agent's parameter, with its bounds, at run time
    r.ok(&["param", "set", "smooth", "alpha", "0.9"]);
    let refused = r.fails(&["param", "set", "smooth", "alpha", "2"]);
    assert!(refused.contains("alpha"), "{refused}");
    r.down_and_check_clean();
}
