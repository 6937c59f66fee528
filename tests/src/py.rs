//! The independent readers of nerve's MCAP files: Python scripts in
//! `tests/py` run with the `mcap` and `protobuf` packages from PyPI (readers
//! nobody here wrote), in the workspace's `target/nerve-py` virtual
//! environment, made and filled here when it lacks them (`.ci/run` makes it
//! too).

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The Python of `target/nerve-py`, with `mcap` and `protobuf`.
pub fn python_with_mcap() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("target").join("nerve-py");
    let python = dir.join("bin").join("python");
    let has_mcap = |p: &Path| {
        Command::new(p).args(["-c", "import mcap.reader, google.protobuf"]).output().is_ok_and(|o| o.status.success())
    };
    if !has_mcap(&python) {
        let st = Command::new("python3").arg("-m").arg("venv").arg(&dir).status().expect("python3");
        assert!(
            st.success(),
            "python3 -m venv failed (Debian: apt-get install python3-venv; scripts/setup.sh --test does it)"
        );
        let st = Command::new(dir.join("bin").join("pip"))
            .args(["install", "--quiet", "--disable-pip-version-check", "mcap==1.6.0", "protobuf==5.29.3"])
            .status()
            .expect("pip");
        assert!(st.success(), "pip install mcap protobuf failed (PyPI must be reachable)");
    }
    assert!(has_mcap(&python), "the mcap package does not import");
    python
}

/// Runs `tests/py/SCRIPT FILE ARGS...` and returns the JSON it prints.
pub fn run_reader(script: &str, file: &Path, args: &[&str]) -> Value {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("py").join(script);
    let out = Command::new(python_with_mcap()).arg(script).arg(file).args(args).output().expect("python");
    assert!(
        out.status.success(),
        "{} failed on {}: {}",
        file.display(),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("reader json")
}

/// What `tests/py/read_mcap.py` finds in `file`: channels with their
/// schemas and metadata, and every message decoded through its nerve schema.
pub fn read_mcap(file: &Path) -> Value {
    run_reader("read_mcap.py", file, &[])
}

/// The messages of `topic` in [`read_mcap`]'s answer.
pub fn messages<'a>(got: &'a Value, topic: &str) -> &'a Vec<Value> {
    got["channels"][topic]["messages"].as_array().unwrap_or_else(|| panic!("no channel {topic} in {got}"))
}

/// The Python of `target/nerve-py` with nerve's own package (`python/`)
/// installed, built here when it is missing (`.ci/run` installs it), and
/// the folder of its programs, to put first on `PATH` so that a Python
/// agent's `#!/usr/bin/env python3` finds it.
pub fn python_with_nerve() -> (PathBuf, PathBuf) {
    let python = python_with_mcap();
    let bin = python.parent().map(Path::to_path_buf).unwrap_or_default();
    let imports = |p: &Path| {
        Command::new(p).args(["-c", "import nerve._native, numpy"]).output().is_ok_and(|o| o.status.success())
    };
    if !imports(&python) {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
        let st = Command::new(bin.join("pip"))
            .args(["install", "--quiet", "--disable-pip-version-check", "maturin>=1.9,<2", "numpy>=1.26,<3"])
            .status()
            .expect("pip");
        assert!(st.success(), "pip install maturin numpy failed (PyPI must be reachable)");
        let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
        let st = Command::new(bin.join("pip"))
            .args(["install", "--quiet", "--disable-pip-version-check", "--no-build-isolation"])
            .arg(root.join("python"))
            .env("PATH", path)
            .env("MATURIN_PEP517_ARGS", "--profile dev")
            .status()
            .expect("pip");
        assert!(st.success(), "pip install ./python failed");
    }
    assert!(imports(&python), "the nerve package does not import in {}", python.display());
    (python, bin)
}
