//! An isolated robot for one test or one benchmark run.
//!
//! A [`Robot`] has a unique name (so its own iceoryx2 prefix
//! `nerve_<uid>_<robot>_`) and its own `NERVE_HOME` state directory.
//! Dropping it brings everything down and removes its shared memory and
//! state even when the test failed, so parallel runs and leftovers never
//! interfere; a failed test's home is kept for reading ([`KEPT_MARKER`]).
//!
//! Test robots ([`Robot::new`]) are named `t<pid>-<n>-<tag>` and run the
//! binaries cargo built next to the test executable (build them with
//! `cargo build --workspace --bins` first); benchmark robots
//! ([`Robot::for_bench`]) are named `b<pid><tag>` and run the `nerve`
//! found by [`nerve_bin`].

use crate::sweep::sweep_dead_test_robots;
use crate::{Error, KEEP_FOR, KEPT_MARKER, shm_files_with_prefix};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::Once;
use std::sync::atomic::{AtomicU32, Ordering};

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// The sweep of dead test processes' robots, once per test process.
static SWEEP: Once = Once::new();

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

/// Where the `nerve` command is: `$NERVE_BIN`, next to this executable (or
/// its parent, for test executables under `deps/`), or on `PATH`.
pub fn nerve_bin() -> Result<PathBuf, Error> {
    if let Some(p) = std::env::var_os("NERVE_BIN") {
        return Ok(PathBuf::from(p));
    }
    let exe = std::env::current_exe().map_err(Error::CurrentExe)?;
    for dir in exe.ancestors().skip(1).take(2) {
        let cand = dir.join("nerve");
        if cand.is_file() {
            return Ok(cand);
        }
    }
    if let Some(path) = std::env::var_os("PATH") {
        for dir in std::env::split_paths(&path) {
            let cand = dir.join("nerve");
            if cand.is_file() {
                return Ok(cand);
            }
        }
    }
    Err(Error::NoNerve { next_to: exe })
}

/// An isolated robot for one test or one benchmark run.
#[derive(Debug)]
pub struct Robot {
    /// robot name
    pub name: String,
    /// its NERVE_HOME
    pub home: PathBuf,
    /// the folder of the binaries it runs
    bin: PathBuf,
    /// the `nerve` command it runs
    nerve: PathBuf,
    /// whether dropping it removes `home` (not for a [`Robot::sibling`])
    owns_home: bool,
    /// a benchmark's robot: a failed `nerve down` is said on stderr
    bench: bool,
}

impl Robot {
    /// A new robot with a unique name; `tag` (a few letters) helps reading leftovers.
    ///
    /// The test process becomes a child subreaper, as init is on a real
    /// system: daemons whose parents exit are re-parented to it, and
    /// [`crate::reap`] collects them when they die (PID 1 of the build sandbox does
    /// not reap orphans).
    ///
    /// The first robot of a test process sweeps what dead test processes
    /// left ([`sweep_dead_test_robots`]).
    pub fn new(tag: &str) -> Self {
        // SAFETY: prctl with PR_SET_CHILD_SUBREAPER takes no pointers.
        unsafe { libc::prctl(libc::PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) };
        SWEEP.call_once(|| {
            let swept = sweep_dead_test_robots();
            if swept.processes + swept.files > 0 {
                eprintln!(
                    "swept what dead test processes left: {} process(es) killed, {} file(s) and folder(s) removed",
                    swept.processes, swept.files
                );
            }
        });
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let tag: String = tag.chars().filter(|c| c.is_ascii_lowercase()).take(6).collect();
        let name =
            format!("t{}-{}{}", std::process::id(), n, if tag.is_empty() { String::new() } else { format!("-{tag}") });
        assert!(name.len() <= 24, "robot name {name} too long");
        let home = std::env::temp_dir().join(format!("nerve-test-{name}"));
        let _ = std::fs::remove_dir_all(&home);
        std::fs::create_dir_all(&home).expect("create NERVE_HOME");
        let bin = bin_dir();
        Robot { name, home, nerve: bin.join("nerve"), bin, owns_home: true, bench: false }
    }

    /// The name [`Robot::for_bench`] gives the robot of `tag`: `b<pid><tag>`.
    pub fn bench_name(tag: &str) -> String {
        format!("b{}{tag}", std::process::id())
    }

    /// A benchmark's robot, named [`Robot::bench_name`] `tag`, with its
    /// state in a private directory and the `nerve` of [`nerve_bin`].
    pub fn for_bench(tag: &str) -> Result<Self, Error> {
        let nerve = nerve_bin()?;
        let name = Robot::bench_name(tag);
        let home = std::env::temp_dir().join(format!("nerve-bench-{name}"));
        std::fs::create_dir_all(&home).map_err(|source| Error::Home { path: home.clone(), source })?;
        let bin = nerve.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok(Robot { name, home, bin, nerve, owns_home: true, bench: true })
    }

    /// The `nerve` command this robot runs.
    pub fn nerve_path(&self) -> &Path {
        &self.nerve
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
            nerve: std::mem::take(&mut other.nerve),
            owns_home: false,
            bench: other.bench,
        }
    }

    /// A command for binary `exe` (`nerve`, `nerve-ticker`...) in this robot's world.
    pub fn command(&self, exe: &str) -> Command {
        let mut c = Command::new(if exe == "nerve" { self.nerve.clone() } else { self.bin.join(exe) });
        c.env("NERVE_ROBOT", &self.name).env("NERVE_HOME", &self.home).env_remove("RUST_LOG");
        c
    }

    /// The robot's connections as `FROM -> TO` lines, sorted (`nerve graph --json`).
    pub fn edges(&self) -> Vec<String> {
        let g = self.graph();
        let mut v: Vec<String> = g["connections"]
            .as_array()
            .map(|c| {
                c.iter()
                    .map(|e| format!("{} -> {}", e["from"].as_str().unwrap_or("?"), e["to"].as_str().unwrap_or("?")))
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    }

    /// Runs `nerve ARGS`.
    pub fn nerve(&self, args: &[&str]) -> Output {
        self.command("nerve").args(args).output().expect("run nerve")
    }

    /// Runs `nerve ARGS`; its failure (with its stderr) is an error; returns stdout.
    pub fn try_run(&self, args: &[&str]) -> Result<String, Error> {
        let out = self
            .command("nerve")
            .args(args)
            .stdin(Stdio::null())
            .output()
            .map_err(|source| Error::Run { what: format!("nerve {}", args.join(" ")), source })?;
        if !out.status.success() {
            return Err(Error::Nerve {
                robot: self.name.clone(),
                args: args.join(" "),
                status: out.status,
                stderr: String::from_utf8_lossy(&out.stderr).trim().to_owned(),
            });
        }
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
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

    /// The pid in `NAME.pid` of this robot's pid files (`router`, an agent), if it holds one.
    pub fn pid_file(&self, name: &str) -> Option<u32> {
        std::fs::read_to_string(self.home.join(&self.name).join("pids").join(format!("{name}.pid")))
            .ok()?
            .trim()
            .parse()
            .ok()
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
        let prefix = shm_schemas::RobotName::shm_prefix_of(shm_schemas::names::effective_uid(), &self.name);
        shm_files_with_prefix(&prefix)
            .into_iter()
            .filter_map(|p| Some(p.file_name()?.to_string_lossy().into_owned()))
            .collect()
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
        dump_logs(&self.home.join(&self.name));
    }
}

/// Prints the last lines of every log in `STATE_DIR/logs` (a robot's router
/// and agents) on stderr: a failing test's home is removed when it ends.
pub fn dump_logs(state_dir: &Path) {
    let logs = state_dir.join("logs");
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

impl Drop for Robot {
    fn drop(&mut self) {
        let failed = std::thread::panicking();
        if failed {
            self.dump_logs();
        }
        let down = self.command("nerve").args(["down", "--grace", "1"]).stdin(Stdio::null()).output();
        if self.bench {
            match down {
                Ok(o) if o.status.success() => {}
                Ok(o) => eprintln!(
                    "warning: `nerve down` of robot {} failed: {}",
                    self.name,
                    String::from_utf8_lossy(&o.stderr).trim()
                ),
                Err(e) => eprintln!("warning: cannot run `nerve down` of robot {}: {e}", self.name),
            }
        }
        for f in self.shm_files() {
            let _ = std::fs::remove_file(format!("/dev/shm/{f}"));
        }
        // a failed test's home (its logs, a demo's summary and figures) is
        // kept for reading, marked so that later sweeps leave it for a day;
        // a passed test leaves nothing
        if failed && !self.bench {
            let _ = std::fs::write(self.home.join(KEPT_MARKER), b"");
            eprintln!("----- kept for reading ({} h): {}", KEEP_FOR.as_secs() / 3600, self.home.display());
        } else if self.owns_home {
            let _ = std::fs::remove_dir_all(&self.home);
        }
    }
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
