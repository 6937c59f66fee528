//! The `nerve-python` rows: the SDK ping against a Python pong
//! (`bench/py/pong.py`, the `nerve` package), when the package is installed.

use crate::procs::{ChildGuard, Robot};
use anyhow::{Result, bail};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The Python with nerve's package, or `None` (said on stderr: no
/// `nerve-python` rows).
pub(super) fn find() -> Option<PathBuf> {
    match python_with_nerve() {
        Ok(p) => {
            eprintln!("hop: Python agents with {}", p.display());
            Some(p)
        }
        Err(e) => {
            eprintln!("hop: warning: no nerve-python row ({e:#})");
            None
        }
    }
}

/// The Python that has nerve's package: `NERVE_PYTHON`, else the
/// workspace's `target/nerve-py` (where `.ci/run` installs it).
fn python_with_nerve() -> Result<PathBuf> {
    let python = match std::env::var_os("NERVE_PYTHON") {
        Some(p) => PathBuf::from(p),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/nerve-py/bin/python"),
    };
    let ok = Command::new(&python)
        .args(["-c", "import nerve._native, numpy"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        bail!(
            "{} cannot import the nerve package; install it (docs/python.md) or name a Python that has it with NERVE_PYTHON",
            python.display()
        );
    }
    Ok(python)
}

/// Starts `bench/py/pong.py` as agent `name` with `python`.
pub(super) fn spawn_python_pong(robot: &Robot, python: &Path, name: &str, size: usize) -> Result<ChildGuard> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("py").join("pong.py");
    let mut cmd = Command::new(python);
    cmd.arg(&script).args(["--robot", &robot.name, "--name", name, "--", "--size", &size.to_string()]);
    cmd.env("NERVE_HOME", &robot.home).stdin(Stdio::null());
    robot.quiet(&mut cmd);
    Ok(ChildGuard::spawn(&format!("agent {name}"), cmd)?)
}
