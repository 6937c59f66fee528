//! Test harness for nerve's multi-process tests.
//!
//! The robots, child guards and bounded waits are the test kit's
//! (`nerve-testkit`, shared with the benchmarks), re-exported here so that
//! every test keeps writing `nerve_tests::Robot`: each [`Robot`] is an
//! isolated world (a unique robot name, its own iceoryx2 prefix and
//! `NERVE_HOME`), brought down and removed when dropped, even when the test
//! failed; the first one of a test process sweeps what killed test
//! processes left ([`sweep_dead_test_robots`]).
//!
//! The binaries under test are the ones cargo built next to the test
//! executable (`target/<profile>/nerve`, `nerve-ticker`, ...): build them
//! with `cargo build --workspace --bins` before running the tests.
//!
//! Beside the kit: a browser driver ([`browser`]), serial devices
//! ([`device`]), the Python package ([`py`]), and a few network and file
//! helpers.

pub mod browser;
pub mod device;
pub mod py;

pub use nerve_testkit::*;

use std::path::PathBuf;
use std::process::Command;

/// Runs `ip ARGS` (iproute2: network namespaces, veth pairs), or says
/// what it answered.
pub fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip").args(args).output().map_err(|e| format!("ip: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!("ip {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim()))
    }
}

/// A TCP port free on 127.0.0.1 now (for a test's own Zenoh endpoints).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map(|a| a.port()).expect("a free port")
}

/// Writes `body` to `dir/name` and returns the path.
pub fn write_file(dir: &std::path::Path, name: &str, body: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, body).expect("write file");
    p
}
