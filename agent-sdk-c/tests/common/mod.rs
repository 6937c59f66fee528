//! What the C and C++ agent tests share: the libnerve.so the workspace's
//! build left beside the binaries, and a compiler run against it. No test
//! runs cargo: CI's build step (`cargo build --workspace --lib --bins
//! --tests`) makes the library, as it makes the binaries the robots run.
//! Each test binary uses a part of it.
#![allow(dead_code)]

use nerve_testkit::{Robot, bin_dir, wait_until};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// The folder of libnerve.so (the binaries' folder), checked to hold it.
pub fn libnerve_dir() -> PathBuf {
    let lib = bin_dir();
    assert!(
        lib.join("libnerve.so").exists(),
        "{} is missing: build it with `cargo build --workspace --lib --bins` (or `cargo build -p nerve-agent-c`)",
        lib.join("libnerve.so").display()
    );
    lib
}

/// The crate's `include/` folder (nerve.h, nerve_types.h, nerve.hpp).
pub fn include_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("include")
}

/// Compiles and links `source` into `dir/name` with `compiler` (gcc, g++)
/// and `flags`, against libnerve.so; panics with the compiler's message.
pub fn compile(compiler: &str, flags: &[&str], source: &Path, dir: &Path, name: &str) -> PathBuf {
    let lib = libnerve_dir();
    let exe = dir.join(name);
    let out = Command::new(compiler)
        .args(["-Wall", "-Wextra", "-Werror"])
        .args(flags)
        .arg("-I")
        .arg(include_dir())
        .arg(source)
        .arg("-L")
        .arg(&lib)
        .arg("-lnerve")
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap_or_else(|e| panic!("run {compiler} (scripts/setup.sh --test installs it): {e}"));
    assert!(
        out.status.success(),
        "{compiler} failed on {}: {}",
        source.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

/// `nerve stop NAME`, then checks that the agent left the router, that its
/// process ended, and that its stop callback ran: some log of the robot
/// holds `said` (the C and C++ examples print `NAME: stopping after ...`).
pub fn stops_and_says(r: &Robot, name: &str, said: &str) {
    let pid = r.pid(name);
    r.ok(&["stop", name]);
    assert!(wait_until(Duration::from_secs(10), || r.agent(name).is_none()), "{name} did not stop");
    assert!(wait_until(Duration::from_secs(10), || !nerve_testkit::alive(pid)), "{name}'s process {pid} lives on");
    let logs = r.home.join(&r.name).join("logs");
    let found = wait_until(Duration::from_secs(5), || {
        std::fs::read_dir(&logs)
            .into_iter()
            .flatten()
            .flatten()
            .any(|e| std::fs::read_to_string(e.path()).is_ok_and(|t| t.contains(said)))
    });
    assert!(found, "no log in {} says {said:?}: {name}'s stop callback did not run", logs.display());
}

/// The seqs of the next `n` ticks relay `name` republishes on `name/out`.
pub fn relayed(r: &Robot, name: &str, n: u32) -> Vec<u64> {
    r.echo(&format!("{name}/out"), n).iter().filter_map(|v| v["data"]["seq"].as_u64()).collect()
}

/// Whether what relay `name` republishes now comes from t2 (whose seq
/// grows by a million a tick; t1's by one), checked on a few fresh ticks.
pub fn follows_t2(r: &Robot, name: &str) -> bool {
    let seqs = relayed(r, name, 3);
    seqs.len() == 3 && seqs.iter().all(|s| *s >= 1_000_000 && s % 1_000_000 == 0)
}

/// Relay `name`, launched fed by ticker t1, relays t1's ticks; rewired at
/// run time (`nerve disconnect`/`connect`) to ticker t2, it relays t2's.
pub fn rewired_to_t2(r: &Robot, name: &str) {
    let seqs = relayed(r, name, 3);
    assert!(seqs.len() == 3 && seqs.iter().all(|s| *s < 1_000_000), "t1's ticks first: {seqs:?}");
    r.ok(&["disconnect", "t1/tick", &format!("{name}/in")]);
    r.ok(&["connect", "t2/tick", &format!("{name}/in")]);
    assert!(
        wait_until(Duration::from_secs(5), || follows_t2(r, name)),
        "{name}'s output does not follow t2: {:?}",
        relayed(r, name, 3)
    );
}

/// Relay `name` killed with SIGKILL is restarted by the supervisor
/// (`restart = "on-failure"`: a new pid) with its run-time connection to
/// t2 back, not the launch file's.
pub fn killed_and_restarted_with_t2(r: &Robot, name: &str) {
    let old = r.pid(name);
    nerve_testkit::sigkill(old);
    assert!(
        wait_until(Duration::from_secs(10), || r.agent(name).is_some_and(|a| {
            let pid = a["pid"].as_u64().unwrap_or(0);
            pid != 0 && pid != u64::from(old)
        })),
        "{name} was not restarted: {:?}",
        r.ps()
    );
    assert!(
        wait_until(Duration::from_secs(5), || follows_t2(r, name)),
        "the restarted {name} does not relay t2: {:?}",
        relayed(r, name, 3)
    );
}
