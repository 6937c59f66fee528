//! Agent kinds: kind `ticker` is the executable `nerve-ticker`, found next to
//! the `nerve` program or on `PATH`; a path names any agent executable (a
//! Python agent is an executable script, `#!/usr/bin/env python3`). Used
//! by `nerve start`, `nerve exec` and the launch-file checks (and, through
//! [`find_program`], by `nerve bench` to find `nerve-bench`).

use anyhow::{Result, bail};
use std::path::{Path, PathBuf};

/// Prefix of agent executables: kind `ticker` is the program `nerve-ticker`.
pub const AGENT_PREFIX: &str = "nerve-";

/// Finds the executable of an agent kind: a path, else `nerve-<kind>` next to
/// this program, else on `PATH`.
pub fn resolve_kind(kind: &str) -> Result<PathBuf> {
    if kind.contains('/') {
        let p = PathBuf::from(kind);
        if !is_executable(&p) && p.is_file() && p.extension().is_some_and(|e| e == "py") {
            bail!(
                "{kind} is a Python agent that is not executable: give it `#!/usr/bin/env python3` as its first \
                 line (the interpreter with the nerve package) and `chmod +x {kind}`"
            );
        }
        if !is_executable(&p) {
            bail!("{kind} is not an executable file; give the path of a built agent, or a kind such as `ticker`");
        }
        return Ok(p);
    }
    let file = format!("{AGENT_PREFIX}{kind}");
    if let Some(p) = find_program(&file) {
        return Ok(p);
    }
    let known = known_kinds();
    bail!(
        "unknown agent kind {kind:?}: no executable {file} next to nerve or on PATH; known kinds: {} (build agents with `cargo build --workspace`)",
        if known.is_empty() { "none found".to_string() } else { known.join(", ") }
    )
}

/// Finds the executable `file` next to this program, else on `PATH`.
pub fn find_program(file: &str) -> Option<PathBuf> {
    let mut dirs: Vec<PathBuf> = Vec::new();
    if let Some(dir) = std::env::current_exe().ok().and_then(|p| p.parent().map(Path::to_path_buf)) {
        dirs.push(dir);
    }
    if let Some(path) = std::env::var_os("PATH") {
        dirs.extend(std::env::split_paths(&path));
    }
    dirs.into_iter().map(|d| d.join(file)).find(|p| is_executable(p))
}

/// Programs named like agents that are not agents: `nerve-bench` runs the
/// benchmarks (`nerve bench`), `nerve-demo` the demos (`nerve demo`),
/// `nerve-ros2-router` a plain Zenoh router for ROS 2 nodes (docs/ros2.md).
const NOT_AGENTS: [&str; 3] = ["bench", "demo", "ros2-router"];

/// Agent kinds installed next to this program.
pub fn known_kinds() -> Vec<String> {
    let Some(dir) = std::env::current_exe().ok().and_then(|p| p.parent().map(Path::to_path_buf)) else { return vec![] };
    let mut kinds: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter_map(|e| e.file_name().to_str().and_then(|n| n.strip_prefix(AGENT_PREFIX)).map(str::to_owned))
                .filter(|k| k.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-'))
                .filter(|k| !NOT_AGENTS.contains(&k.as_str()))
                .collect()
        })
        .unwrap_or_default();
    kinds.sort();
    kinds.dedup();
    kinds
}

fn is_executable(p: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    p.metadata().map(|m| m.is_file() && m.permissions().mode() & 0o111 != 0).unwrap_or(false)
}
