//! Free space on `/dev/shm`, checked before commands that make processes
//! create shared memory (`nerve launch`, `nerve start`, `nerve connect`).
//!
//! Rings reserve their pages up front and are refused cleanly when tmpfs is
//! full, but iceoryx2 creates its dynamic segments (service state, the
//! zero-copy connections a `connect` builds) sparse: a process that then
//! touches a page tmpfs cannot supply dies of SIGBUS instead of reporting
//! ENOSPC. So these commands refuse to begin when less than a margin is
//! free: [`DEFAULT_MIN_FREE`] (16 MiB), or the size in
//! `NERVE_SHM_MIN_FREE` (bytes, or with a `K`, `M` or `G` suffix, powers of
//! 1024; `0` turns the check off).

use anyhow::{Result, anyhow};
use std::path::Path;

/// The file system the check looks at.
pub const SHM_DIR: &str = "/dev/shm";

/// Free space required by default: 16 MiB.
pub const DEFAULT_MIN_FREE: u64 = 16 << 20;

/// The environment variable that changes the margin.
pub const MIN_FREE_VAR: &str = "NERVE_SHM_MIN_FREE";

/// Refuses, with what to do, when `/dev/shm` has less free space than the
/// margin; `what` names the command for the message (`"launch"`).
pub fn ensure_shm_space(what: &str) -> Result<()> {
    let margin = match std::env::var(MIN_FREE_VAR) {
        Ok(v) => parse_size(&v).map_err(|e| anyhow!("{MIN_FREE_VAR}={v:?}: {e}"))?,
        Err(_) => DEFAULT_MIN_FREE,
    };
    ensure_space_at(Path::new(SHM_DIR), margin, what)
}

/// [`ensure_shm_space`] for directory `dir` and a margin in bytes.
pub fn ensure_space_at(dir: &Path, margin: u64, what: &str) -> Result<()> {
    if margin == 0 {
        return Ok(());
    }
    let vfs = nix::sys::statvfs::statvfs(dir)
        .map_err(|e| anyhow!("cannot check the free space on {} before {what}: {e}", dir.display()))?;
    let free = vfs.blocks_available().saturating_mul(vfs.fragment_size());
    check_free(free, margin, dir, what).map_err(|e| anyhow!(e))
}

/// The decision: `Ok` when `free` bytes are at least `margin`, else why
/// not and what to do.
pub fn check_free(free: u64, margin: u64, dir: &Path, what: &str) -> Result<(), String> {
    if free >= margin {
        return Ok(());
    }
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    Err(format!(
        "refusing to {what}: only {:.1} MiB free on {} (at least {:.1} MiB needed); iceoryx2 creates its \
         shared memory sparse, and a process that touches a page the file system cannot supply dies of SIGBUS. \
         Free space there (files of robots no longer running: `ls -la {}`, `nerve --robot NAME down`), \
         give it more room (`sudo mount -o remount,size=1G {}`), or set {MIN_FREE_VAR} to change the margin \
         (bytes or K/M/G; 0 turns the check off)",
        mib(free),
        dir.display(),
        mib(margin),
        dir.display(),
        dir.display()
    ))
}

/// A size in bytes: digits, optionally followed by `K`, `M` or `G` (powers
/// of 1024, `KiB`/`MiB`/`GiB` accepted too).
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let split = t.find(|c: char| !c.is_ascii_digit()).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let n: u64 = num.parse().map_err(|_| "expected a size such as 16M, 1G or 16777216".to_string())?;
    let shift = match unit.trim().to_ascii_uppercase().as_str() {
        "" | "B" => 0,
        "K" | "KB" | "KIB" => 10,
        "M" | "MB" | "MIB" => 20,
        "G" | "GB" | "GIB" => 30,
        u => return Err(format!("unknown unit {u:?}; use K, M or G")),
    };
    n.checked_mul(1 << shift).ok_or_else(|| "size too large".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn too_little_free_shared_memory_is_refused_with_what_to_do() {
        let dir = Path::new(SHM_DIR);
        assert!(check_free(16 << 20, DEFAULT_MIN_FREE, dir, "launch").is_ok());
        let e = check_free(3 << 20, DEFAULT_MIN_FREE, dir, "launch").expect_err("refused");
        assert!(e.starts_with("refusing to launch: only 3.0 MiB free on /dev/shm (at least 16.0 MiB"), "{e}");
        assert!(e.contains("SIGBUS") && e.contains(MIN_FREE_VAR) && e.contains("remount"), "{e}");

        // the real /dev/shm: never that much room, and a margin of 0 is no check
        assert!(ensure_space_at(dir, u64::MAX, "connect").is_err());
        assert!(ensure_space_at(dir, 0, "connect").is_ok());
        assert!(ensure_space_at(Path::new("/nonexistent-dir"), 1, "start").is_err());
    }

    #[test]
    fn the_margin_is_a_size_with_an_optional_unit() {
        assert_eq!(parse_size("0"), Ok(0));
        assert_eq!(parse_size("4096"), Ok(4096));
        assert_eq!(parse_size("16M"), Ok(16 << 20));
        assert_eq!(parse_size(" 2 GiB "), Ok(2 << 30));
        assert_eq!(parse_size("512k"), Ok(512 << 10));
        assert!(parse_size("").is_err());
        assert!(parse_size("-1").is_err());
        assert!(parse_size("16T").is_err());
        assert!(parse_size("99999999999999999999G").is_err());
    }
}
