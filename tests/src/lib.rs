//! Test harness for nerve's multi-process tests.
//!
//! Each [`Robot`] is an isolated world: a unique robot name (so its own
//! iceoryx2 prefix `nerve_<robot>_`) and its own `NERVE_HOME` state
//! directory. Dropping it brings everything down and removes its shared
//! memory and state even when the test failed, so parallel tests and
//! leftovers never interfere.
//!
//! The binaries under test are the ones cargo built next to the test
//! executable (`target/<profile>/nerve`, `nerve-ticker`, ...): build them
//! with `cargo build --workspace --bins` before running the tests.

use serde_json::Value;
use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// The directory holding the built binaries.
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let mut dir = exe.parent().expect("exe dir").to_path_buf();
    if dir.ends_with("deps") {
        dir.pop();
    }
    let nerve = dir.join("nerve");
    assert!(
        nerve.exists(),
        "{} is missing: build the binaries first with `cargo build --workspace --bins`",
        nerve.display()
    );
    dir
}

/// An isolated robot for one test.
#[derive(Debug)]
pub struct Robot {
    /// robot name
    pub name: String,
    /// its NERVE_HOME
    pub home: PathBuf,
    bin: PathBuf,
    /// whether dropping it removes `home` (not for a [`Robot::sibling`])
    owns_home: bool,
}

impl Robot {
    /// A new robot with a unique name; `tag` (a few letters) helps reading leftovers.
    ///
    /// The test process becomes a child subreaper, as init is on a real
    /// system: daemons whose parents exit are re-parented to it, and
    /// [`reap`] collects them when they die (PID 1 of the build sandbox does
    /// not reap orphans).
    pub fn new(tag: &str) -> Self {
        // SAFETY: prctl with PR_SET_CHILD_SUBREAPER takes no pointers.
        unsafe { libc::prctl(libc::PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) };
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let tag: String = tag.chars().filter(|c| c.is_ascii_lowercase()).take(6).collect();
        let name =
            format!("t{}-{}{}", std::process::id(), n, if tag.is_empty() { String::new() } else { format!("-{tag}") });
        assert!(name.len() <= 24, "robot name {name} too long");
        let home = std::env::temp_dir().join(format!("nerve-test-{name}"));
        let _ = std::fs::remove_dir_all(&home);
        std::fs::create_dir_all(&home).expect("create NERVE_HOME");
        Robot { name, home, bin: bin_dir(), owns_home: true }
    }

    /// Another robot with a unique name in this robot's NERVE_HOME (two
    /// robots of one machine, e.g. a simulator serving both). Dropping it
    /// stops it and removes its shared memory; the home stays with `self`,
    /// which must be dropped after it (declare it first).
    pub fn sibling(&self, tag: &str) -> Self {
        let other = Robot::new(tag);
        let _ = std::fs::remove_dir_all(&other.home);
        let mut other = std::mem::ManuallyDrop::new(other);
        Robot {
            name: std::mem::take(&mut other.name),
            home: self.home.clone(),
            bin: std::mem::take(&mut other.bin),
            owns_home: false,
        }
    }

    /// A command for binary `exe` (`nerve`, `nerve-ticker`...) in this robot's world.
    pub fn command(&self, exe: &str) -> Command {
        let mut c = Command::new(self.bin.join(exe));
        c.env("NERVE_ROBOT", &self.name).env("NERVE_HOME", &self.home).env_remove("RUST_LOG");
        c
    }

    /// Runs `nerve ARGS`.
    pub fn nerve(&self, args: &[&str]) -> Output {
        self.command("nerve").args(args).output().expect("run nerve")
    }

    /// Runs `nerve ARGS`, panics unless it succeeds; returns stdout.
    pub fn ok(&self, args: &[&str]) -> String {
        let out = self.nerve(args);
        assert!(
            out.status.success(),
            "`nerve {}` failed ({}):\nstdout: {}\nstderr: {}",
            args.join(" "),
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// Runs `nerve ARGS`, panics unless it fails; returns stderr.
    pub fn fails(&self, args: &[&str]) -> String {
        let out = self.nerve(args);
        assert!(
            !out.status.success(),
            "`nerve {}` should have failed:\nstdout: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stdout)
        );
        String::from_utf8_lossy(&out.stderr).into_owned()
    }

    /// Starts the router as a daemon.
    pub fn router(&self) {
        self.ok(&["router", "--daemon"]);
    }

    /// Writes a launch file for this robot (its `robot = ...` line set to this robot) and returns its path.
    pub fn launch_file(&self, file_name: &str, contents: &str) -> PathBuf {
        let body: String = contents
            .lines()
            .map(|l| {
                if l.trim_start().starts_with("robot =") { format!("robot = \"{}\"", self.name) } else { l.to_owned() }
            })
            .collect::<Vec<_>>()
            .join("\n");
        let path = self.home.join(file_name);
        std::fs::write(&path, body + "\n").expect("write launch file");
        path
    }

    /// `nerve ps --json`.
    pub fn ps(&self) -> Vec<Value> {
        let out = self.ok(&["ps", "--json"]);
        match serde_json::from_str::<Value>(&out) {
            Ok(Value::Array(v)) => v,
            other => panic!("ps --json gave {other:?}"),
        }
    }

    /// The agent named `name` in `nerve ps --json`.
    pub fn agent(&self, name: &str) -> Option<Value> {
        self.ps().into_iter().find(|a| a["name"] == name)
    }

    /// The pid of agent `name`.
    pub fn pid(&self, name: &str) -> u32 {
        self.agent(name).and_then(|a| a["pid"].as_u64()).unwrap_or_else(|| panic!("agent {name} not in ps")) as u32
    }

    /// `nerve graph --json`.
    pub fn graph(&self) -> Value {
        serde_json::from_str(&self.ok(&["graph", "--json"])).expect("graph json")
    }

    /// `nerve echo PORT --count N --json --timeout 5`, parsed.
    pub fn echo(&self, port: &str, n: u32) -> Vec<Value> {
        let out = self.ok(&["echo", port, "--count", &n.to_string(), "--json", "--timeout", "5"]);
        out.lines().map(|l| serde_json::from_str(l).expect("echo json line")).collect()
    }

    /// This robot's files in /dev/shm.
    pub fn shm_files(&self) -> Vec<String> {
        let prefix = format!("nerve_{}_", self.name);
        std::fs::read_dir("/dev/shm")
            .map(|rd| {
                rd.filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.starts_with(&prefix))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// `nerve down`, then checks that nothing of the robot is left.
    pub fn down_and_check_clean(&self) {
        self.ok(&["down", "--grace", "2"]);
        let left = self.shm_files();
        assert!(left.is_empty(), "left in /dev/shm after `nerve down`: {left:?}");
        let pids = self.home.join(&self.name).join("pids");
        let pid_files: Vec<_> = std::fs::read_dir(&pids)
            .map(|rd| rd.filter_map(|e| e.ok()).map(|e| e.path()).collect())
            .unwrap_or_default();
        assert!(pid_files.is_empty(), "pid files left: {pid_files:?}");
    }
}

impl Robot {
    /// Prints the last lines of every log of the robot (router and agents) on stderr.
    pub fn dump_logs(&self) {
        let logs = self.home.join(&self.name).join("logs");
        let Ok(rd) = std::fs::read_dir(&logs) else { return };
        for e in rd.filter_map(|e| e.ok()) {
            let text = std::fs::read_to_string(e.path()).unwrap_or_default();
            let lines: Vec<&str> = text.lines().collect();
            eprintln!("----- {} (last {} lines)", e.path().display(), lines.len().min(40));
            for l in &lines[lines.len().saturating_sub(40)..] {
                eprintln!("{l}");
            }
        }
    }
}

impl Drop for Robot {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.dump_logs();
        }
        let _ = self.command("nerve").args(["down", "--grace", "1"]).output();
        for f in self.shm_files() {
            let _ = std::fs::remove_file(format!("/dev/shm/{f}"));
        }
        if self.owns_home {
            let _ = std::fs::remove_dir_all(&self.home);
        }
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

impl Robot {
    /// The read-only figures agent `name` reports (`stats.figures` of `nerve ps --json`), by key.
    pub fn figures(&self, name: &str) -> std::collections::BTreeMap<String, String> {
        let Some(a) = self.agent(name) else { return Default::default() };
        a["stats"]["figures"]
            .as_array()
            .map(|v| v.iter().filter_map(|p| Some((p[0].as_str()?.to_owned(), p[1].as_str()?.to_owned()))).collect())
            .unwrap_or_default()
    }

    /// One figure of agent `name` as text ("" when absent).
    pub fn figure(&self, name: &str, key: &str) -> String {
        self.figures(name).get(key).cloned().unwrap_or_default()
    }

    /// One figure of agent `name` as a number (0 when absent or not a number).
    pub fn figure_u64(&self, name: &str, key: &str) -> u64 {
        self.figure(name, key).parse().unwrap_or(0)
    }
}

/// Polls `cond` every 20 ms until it holds or `timeout` passes; returns whether it held.
pub fn wait_until(timeout: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let t0 = Instant::now();
    loop {
        if cond() {
            return true;
        }
        if t0.elapsed() > timeout {
            return false;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Collects every exited child (re-parented daemons included).
pub fn reap() {
    loop {
        let mut status = 0;
        // SAFETY: waitpid with WNOHANG and a valid status pointer.
        let rc = unsafe { libc::waitpid(-1, &mut status, libc::WNOHANG) };
        if rc <= 0 {
            break;
        }
    }
}

/// Whether `pid` exists at all (a zombie counts).
pub fn exists(pid: u32) -> bool {
    std::path::Path::new(&format!("/proc/{pid}")).exists()
}

/// Whether process `pid` is alive and not a zombie.
pub fn alive(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(s) => !matches!(s.rsplit_once(')').and_then(|(_, r)| r.split_whitespace().next()), Some("Z") | None),
        Err(_) => false,
    }
}

/// Sends SIGKILL to `pid`.
pub fn sigkill(pid: u32) {
    // SAFETY: kill has no memory-safety preconditions.
    unsafe { libc::kill(pid as i32, libc::SIGKILL) };
}
