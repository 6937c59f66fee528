//! Test harness for nerve's multi-process tests.
//!
//! Each [`Robot`] is an isolated world: a unique robot name (so its own
//! iceoryx2 prefix `nerve_<uid>_<robot>_`) and its own `NERVE_HOME` state
//! directory. Dropping it brings everything down and removes its shared
//! memory and state even when the test failed, so parallel tests and
//! leftovers never interfere.
//!
//! The binaries under test are the ones cargo built next to the test
//! executable (`target/<profile>/nerve`, `nerve-ticker`, ...): build them
//! with `cargo build --workspace --bins` before running the tests.
//!
//! A test process killed before its robots are dropped (the nextest
//! watchdog's SIGKILL) leaves their daemons running, in sessions of their
//! own, and their files. So the first [`Robot`] of every test process first
//! sweeps the robots of test processes that are gone
//! ([`sweep_dead_test_robots`]): robot names start with `t<pid>-`, so what
//! belongs to a dead test process is known by its pid.

pub mod browser;
pub mod device;
pub mod py;

use serde_json::Value;
use std::path::PathBuf;
use std::process::{Command, Output};
use std::sync::Once;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// The sweep of dead test processes' robots, once per test process.
static SWEEP: Once = Once::new();

/// Prefix of a test robot's `NERVE_HOME` under the temporary directory.
const HOME_PREFIX: &str = "nerve-test-t";

/// A failed test's home holds this file: the sweep then leaves the home (its
/// logs, a demo's summary and figures) for reading, for [`KEEP_FOR`].
pub const KEPT_MARKER: &str = "KEPT-FOR-READING";

/// How long a failed test's home is kept; the first sweep after that removes it.
pub const KEEP_FOR: Duration = Duration::from_secs(24 * 3600);

/// Prefix of this user's test robots' files in /dev/shm (and under the
/// iceoryx2 root): `nerve_<uid>_t`.
fn shm_test_prefix() -> String {
    shm_schemas::RobotName::shm_prefix_of(shm_schemas::names::effective_uid(), "t").trim_end_matches('_').to_owned()
}

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
pub fn dump_logs(state_dir: &std::path::Path) {
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
        let _ = self.command("nerve").args(["down", "--grace", "1"]).output();
        for f in self.shm_files() {
            let _ = std::fs::remove_file(format!("/dev/shm/{f}"));
        }
        // a failed test's home (its logs, a demo's summary and figures) is
        // kept for reading, marked so that later sweeps leave it for a day;
        // a passed test leaves nothing
        if failed {
            let _ = std::fs::write(self.home.join(KEPT_MARKER), b"");
            eprintln!("----- kept for reading ({} h): {}", KEEP_FOR.as_secs() / 3600, self.home.display());
        } else if self.owns_home {
            let _ = std::fs::remove_dir_all(&self.home);
        }
    }
}

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

/// Collects the exited daemons re-parented to this process (its subreaper).
///
/// Only those: zombie children in another session than ours. A daemon runs
/// in a session of its own (it called `setsid`), while the children a test
/// starts with `Command` stay in the test's session, and `waitpid(-1)`
/// could collect one of those that another test thread is about to wait
/// for (its `Command::output()` would then fail with ECHILD).
pub fn reap() {
    let me = std::process::id();
    let Some((_, _, my_session)) = proc_stat(me) else { return };
    let Ok(rd) = std::fs::read_dir("/proc") else { return };
    for pid in rd.filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok()) {
        if let Some(("Z", ppid, session)) = proc_stat(pid).as_ref().map(|(s, p, sid)| (s.as_str(), *p, *sid))
            && ppid == me
            && session != my_session
        {
            let mut status = 0;
            // SAFETY: waitpid on one pid with WNOHANG and a valid status pointer.
            unsafe { libc::waitpid(pid as i32, &mut status, libc::WNOHANG) };
        }
    }
}

/// State, parent pid and session of `pid`, from `/proc/<pid>/stat`.
fn proc_stat(pid: u32) -> Option<(String, u32, u32)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let mut f = stat.rsplit_once(')')?.1.split_whitespace();
    let state = f.next()?.to_owned();
    let ppid = f.next()?.parse().ok()?;
    let _pgrp = f.next()?;
    let session = f.next()?.parse().ok()?;
    Some((state, ppid, session))
}

/// Whether `home` holds a [`KEPT_MARKER`] younger than [`KEEP_FOR`] (a
/// marker of unknown age counts as young).
fn kept_for_reading(home: &std::path::Path) -> bool {
    std::fs::metadata(home.join(KEPT_MARKER))
        .is_ok_and(|m| m.modified().ok().and_then(|t| t.elapsed().ok()).is_none_or(|age| age < KEEP_FOR))
}

/// What [`sweep_dead_test_robots`] did.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Swept {
    /// Daemons killed.
    pub processes: usize,
    /// Files and state folders removed.
    pub files: usize,
}

/// The test pid in a name `<prefix><pid>-...` (`nerve-test-t123-0-x`,
/// `nerve_t123-0-x_...`).
fn test_pid_of(name: &str, prefix: &str) -> Option<u32> {
    let rest = name.strip_prefix(prefix)?;
    let (digits, _) = rest.split_once('-')?;
    digits.parse().ok()
}

/// Whether a test process that left something behind is gone. Our own pid
/// is never gone; a pid reused since by another process counts as alive
/// (the leftovers then wait for a later sweep).
fn test_pid_dead(pid: u32) -> bool {
    pid != std::process::id() && !alive(pid)
}

/// Whether live process `pid` is a nerve process started in test home
/// `home` (its command name starts with `nerve`, and `NERVE_HOME` in its
/// environment is `home`): nothing else is ever killed.
fn nerve_process_of(pid: u32, home: &std::path::Path) -> bool {
    let comm = std::fs::read_to_string(format!("/proc/{pid}/comm")).unwrap_or_default();
    if !comm.starts_with("nerve") || !alive(pid) {
        return false;
    }
    let mut want = b"NERVE_HOME=".to_vec();
    want.extend_from_slice(home.as_os_str().as_encoded_bytes());
    std::fs::read(format!("/proc/{pid}/environ")).is_ok_and(|env| env.split(|&b| b == 0).any(|v| v == want))
}

/// Kills the daemons and removes the files of robots whose test process is
/// gone: state folders `$TMPDIR/nerve-test-t<pid>-...` (the processes
/// whose pid files are there, and any other nerve process whose
/// `NERVE_HOME` is that folder, are killed first), and files
/// `/dev/shm/nerve_<uid>_t<pid>-...` and under the iceoryx2 root
/// `/dev/shm/nerve-iox2-<uid>/`. Robots of live test processes are left alone.
/// A home a failed test kept for reading ([`KEPT_MARKER`]) stays, its
/// processes killed, until its marker is [`KEEP_FOR`] old: the next test run
/// must not erase the evidence of the last failure (it did: a CI failure's
/// kept home was gone by the time it was read).
/// Called once per test process by the first [`Robot::new`]; safe to call
/// again.
pub fn sweep_dead_test_robots() -> Swept {
    let mut swept = Swept::default();
    let tmp = std::env::temp_dir();
    let homes: Vec<PathBuf> = std::fs::read_dir(&tmp)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter(|e| {
                    let name = e.file_name();
                    let pid = name.to_str().and_then(|n| test_pid_of(n, HOME_PREFIX));
                    pid.is_some_and(test_pid_dead) && e.file_type().is_ok_and(|t| t.is_dir())
                })
                .map(|e| e.path())
                .collect()
        })
        .unwrap_or_default();
    if !homes.is_empty() {
        // the daemons of those homes: by pid file, then by environment
        let mut victims: Vec<u32> = Vec::new();
        for home in &homes {
            let robots = std::fs::read_dir(home).map(|rd| rd.filter_map(|e| e.ok()).collect()).unwrap_or(Vec::new());
            for robot in robots {
                let pids = std::fs::read_dir(robot.path().join("pids"))
                    .map(|rd| rd.filter_map(|e| e.ok()).collect())
                    .unwrap_or(Vec::new());
                for f in pids {
                    let pid = std::fs::read_to_string(f.path()).ok().and_then(|s| s.trim().parse::<u32>().ok());
                    if let Some(pid) = pid.filter(|p| nerve_process_of(*p, home)) {
                        victims.push(pid);
                    }
                }
            }
        }
        if let Ok(rd) = std::fs::read_dir("/proc") {
            for pid in rd.filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok()) {
                if homes.iter().any(|h| nerve_process_of(pid, h)) {
                    victims.push(pid);
                }
            }
        }
        victims.sort_unstable();
        victims.dedup();
        for &pid in &victims {
            sigkill(pid);
        }
        swept.processes = victims.len();
        // let them die before their files go (they may still be writing)
        wait_until(Duration::from_secs(2), || {
            reap();
            victims.iter().all(|&p| !alive(p))
        });
        for home in homes.iter().filter(|h| !kept_for_reading(h)) {
            if std::fs::remove_dir_all(home).is_ok() {
                swept.files += 1;
            }
        }
    }
    // shared memory of dead test processes, whether their home is gone or not
    fn remove_dead(dir: &std::path::Path, depth: u32, shm_prefix: &str, swept: &mut Swept) {
        let Ok(rd) = std::fs::read_dir(dir) else { return };
        for e in rd.filter_map(|e| e.ok()) {
            let name = e.file_name();
            let is_dir = e.file_type().is_ok_and(|t| t.is_dir());
            let dead = name.to_str().and_then(|n| test_pid_of(n, shm_prefix)).is_some_and(test_pid_dead);
            if dead && !is_dir {
                if std::fs::remove_file(e.path()).is_ok() {
                    swept.files += 1;
                }
            } else if is_dir && depth > 0 {
                // in /dev/shm only the iceoryx2 root; inside it, every folder
                let in_iox_root = dir != std::path::Path::new("/dev/shm");
                if in_iox_root || name.to_str().is_some_and(|n| n.starts_with("nerve-iox2")) {
                    remove_dead(&e.path(), depth - 1, shm_prefix, swept);
                }
            }
        }
    }
    let shm_prefix = shm_test_prefix();
    remove_dead(std::path::Path::new("/dev/shm"), 4, &shm_prefix, &mut swept);
    swept
}

/// Whether `pid` exists at all (a zombie counts).
pub fn exists(pid: u32) -> bool {
    std::path::Path::new(&format!("/proc/{pid}")).exists()
}

/// Whether process `pid` is alive and not a zombie.
pub fn alive(pid: u32) -> bool {
    !matches!(process_state(pid).as_deref(), Some("Z") | None)
}

/// The state letter of `pid` in `/proc/PID/stat` (`R`, `S`, `T` stopped,
/// `Z`...), `None` when there is no such process.
pub fn process_state(pid: u32) -> Option<String> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    stat.rsplit_once(')')?.1.split_whitespace().next().map(str::to_owned)
}

/// Sends SIGKILL to `pid`.
pub fn sigkill(pid: u32) {
    // SAFETY: kill has no memory-safety preconditions.
    unsafe { libc::kill(pid as i32, libc::SIGKILL) };
}

/// The files in /dev/shm whose names start with `prefix` (a robot's files
/// are `nerve_<uid>_<robot>_*`).
pub fn shm_files_with_prefix(prefix: &str) -> Vec<std::path::PathBuf> {
    std::fs::read_dir("/dev/shm")
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter(|e| e.file_name().to_string_lossy().starts_with(prefix))
                .map(|e| e.path())
                .collect()
        })
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_a_killed_test_process_left_is_swept_and_a_live_ones_is_not() {
        // a test process that is gone: a child that exited and was waited for
        let mut gone = Command::new("true").spawn().expect("run true");
        gone.wait().expect("wait for true");
        let dead = gone.id();
        assert!(!alive(dead));

        // its robot's home, with a daemon still running (a nerve process
        // with NERVE_HOME set to the home, as the harness starts them) and
        // its pid file, and its files in /dev/shm and the iceoryx2 root.
        // The home is made under another name and renamed into place whole:
        // other test processes sweep too (each one's first Robot::new), and
        // one that found a half-made home could remove it with the pid file
        // but miss the daemon, which nobody would then kill.
        let robot = format!("t{dead}-0-swept");
        let home = std::env::temp_dir().join(format!("nerve-test-{robot}"));
        let staging = std::env::temp_dir().join(format!("nerve-staging-{robot}"));
        let pids = staging.join(&robot).join("pids");
        std::fs::create_dir_all(&pids).expect("pids dir");
        let fake = std::env::temp_dir().join(format!("nerve-sweeptest-{}", std::process::id()));
        std::fs::copy("/bin/sleep", &fake).expect("copy sleep");
        // (short sleeps: a daemon the sweep misses ends the test with a
        // message instead of hanging it)
        let mut daemon = Command::new(&fake).arg("30").env("NERVE_HOME", &home).spawn().expect("fake daemon");
        std::fs::write(pids.join("agent.pid"), format!("{}\n", daemon.id())).expect("pid file");
        std::fs::rename(&staging, &home).expect("the home into place");
        let uid = shm_schemas::names::effective_uid();
        let shm = PathBuf::from(format!("/dev/shm/{}ring", shm_schemas::RobotName::shm_prefix_of(uid, &robot)));
        std::fs::write(&shm, b"").expect("shm file");
        let iox_dir = PathBuf::from(agent_sdk::world::default_iox2_root());
        let iox = agent_sdk::world::secure_dir(&iox_dir)
            .ok()
            .map(|()| iox_dir.join(format!("{}node", shm_schemas::RobotName::shm_prefix_of(uid, &robot))));
        if let Some(p) = &iox {
            std::fs::write(p, b"").expect("iox file");
        }
        // a live test process's robot (ours), which must stay
        let mine = PathBuf::from(format!("/dev/shm/{}{}-999-mine_ring", shm_test_prefix(), std::process::id()));
        std::fs::write(&mine, b"").expect("own shm file");
        let bystander = Command::new(&fake).arg("30").spawn().expect("bystander");
        let seen = (nerve_process_of(daemon.id(), &home), proc_stat(daemon.id()));
        // two homes the dead test process kept for reading: one failed
        // today (stays), one two days ago (goes)
        let kept = std::env::temp_dir().join(format!("nerve-test-t{dead}-1-kept"));
        let old = std::env::temp_dir().join(format!("nerve-test-t{dead}-2-old"));
        for h in [&kept, &old] {
            std::fs::create_dir_all(h.join("logs")).expect("kept home");
            std::fs::write(h.join(KEPT_MARKER), b"").expect("marker");
        }
        std::fs::File::options()
            .write(true)
            .open(old.join(KEPT_MARKER))
            .and_then(|f| f.set_modified(std::time::SystemTime::now() - 2 * KEEP_FOR))
            .expect("an old marker");

        let swept = sweep_dead_test_robots();
        let _ = std::fs::remove_file(&fake);
        let status = daemon.wait().expect("wait for the fake daemon");
        assert!(
            !status.success(),
            "the daemon was not killed: {status}; swept {swept:?}; before the sweep it was a nerve process of the home: {seen:?}; the test pid {dead} alive: {}",
            alive(dead)
        );
        assert!(!home.exists() && !shm.exists(), "left: {home:?} {shm:?}");
        assert!(iox.is_none_or(|p| !p.exists()));
        // this sweep did it, unless another test process's sweep came first
        // (the end state above is the same either way)
        assert!(swept.processes >= 1 && swept.files >= 2 || swept.processes == 0, "{swept:?}");
        assert!(mine.exists(), "a live test process's file was removed");
        assert!(kept.join("logs").is_dir(), "a home kept for reading today was removed");
        assert!(!old.exists(), "a home kept for reading past KEEP_FOR was left");
        let _ = std::fs::remove_dir_all(&kept);
        assert!(alive(bystander.id()), "a process of no test home was killed");
        let _ = std::fs::remove_file(&mine);
        sigkill(bystander.id());
        let mut bystander = bystander;
        let _ = bystander.wait();
    }

    #[test]
    fn reap_collects_exited_daemons_but_never_a_child_someone_waits_for() {
        // a child of ours in our session, exited: reap() must leave it to its owner
        let mut child = Command::new("true").spawn().expect("run true");
        wait_until(Duration::from_secs(5), || proc_stat(child.id()).is_some_and(|(s, _, _)| s == "Z"));
        reap();
        assert!(child.wait().is_ok(), "reap() took a child that its owner waits for");
        // a daemon (its own session) re-parented to us, exited: reaped
        // SAFETY: prctl with PR_SET_CHILD_SUBREAPER takes no pointers.
        unsafe { libc::prctl(libc::PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) };
        let out = Command::new("setsid").args(["-f", "sh", "-c", "echo $$; sleep 0.2"]).output().expect("setsid");
        let pid: u32 = String::from_utf8_lossy(&out.stdout).trim().parse().expect("daemon pid");
        assert!(wait_until(Duration::from_secs(5), || {
            reap();
            !exists(pid)
        }));
    }
}
