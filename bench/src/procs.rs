//! Processes the benchmarks start, and the robot they run in.
//!
//! Every child is held by a [`ChildGuard`] that stops it when dropped
//! (SIGTERM, a short grace, then SIGKILL) and asks the kernel to send it
//! SIGTERM should this process die first. A [`Robot`] has a unique name
//! (`b<pid>`...) and runs `nerve --robot NAME down` when dropped, so nothing
//! is left in `/dev/shm`.

use anyhow::{Context as _, Result, bail};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::os::unix::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

/// How long a child may take to say it is ready.
pub const READY_WITHIN: Duration = Duration::from_secs(60);

/// A child process that is stopped when dropped.
#[derive(Debug)]
pub struct ChildGuard {
    name: String,
    child: Child,
}

/// Spawns `cmd` so that the child gets SIGTERM if this process dies
/// (`PR_SET_PDEATHSIG`): a benchmark killed half-way leaves no process behind.
pub fn spawn_dying_with_us(cmd: &mut Command) -> std::io::Result<Child> {
    // SAFETY: prctl is async-signal-safe and touches no memory of the parent.
    unsafe {
        cmd.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM as libc::c_ulong, 0, 0, 0) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    cmd.spawn()
}

impl ChildGuard {
    /// Spawns `cmd`; the child gets SIGTERM if this process dies.
    pub fn spawn(name: &str, mut cmd: Command) -> Result<Self> {
        let child = spawn_dying_with_us(&mut cmd).with_context(|| format!("cannot start {name} ({cmd:?})"))?;
        Ok(ChildGuard { name: name.into(), child })
    }

    /// The child's stdin, when piped.
    pub fn stdin(&mut self) -> Option<std::process::ChildStdin> {
        self.child.stdin.take()
    }

    /// The child's stdout, when piped.
    pub fn stdout(&mut self) -> Option<std::process::ChildStdout> {
        self.child.stdout.take()
    }

    /// Reads the child's `ready` line (its stdout must be piped); its exit,
    /// any other line, or no line within [`READY_WITHIN`] is an error (a
    /// child stuck in its start would otherwise hold the benchmark forever).
    pub fn await_ready(&mut self, what: &str) -> Result<()> {
        use std::io::BufRead as _;
        let out = self.stdout().with_context(|| format!("{what}: no stdout"))?;
        let (tx, rx) = std::sync::mpsc::channel();
        // the reader ends with the child's stdout: at its line, its exit, or
        // when the guard stops the child after a timeout
        std::thread::spawn(move || {
            let mut line = String::new();
            let r = std::io::BufReader::new(out).read_line(&mut line).map(|_| line);
            let _ = tx.send(r);
        });
        let line = match rx.recv_timeout(READY_WITHIN) {
            Ok(r) => r.with_context(|| format!("{what}: reading readiness"))?,
            Err(_) => {
                self.check_alive()?;
                bail!("{what} did not say it was ready within {READY_WITHIN:?}; run with --verbose to see its log")
            }
        };
        if line.trim() != "ready" {
            self.check_alive()?;
            bail!("{what} did not become ready (said {line:?})");
        }
        Ok(())
    }

    /// Fails when the child has exited already.
    pub fn check_alive(&mut self) -> Result<()> {
        if let Some(status) = self.child.try_wait().with_context(|| format!("cannot wait for {}", self.name))? {
            bail!("{} exited early ({status}); run with --verbose to see its log", self.name);
        }
        Ok(())
    }

    /// Stops the child: SIGTERM, up to `grace`, then SIGKILL.
    pub fn stop(&mut self, grace: Duration) {
        if matches!(self.child.try_wait(), Ok(Some(_))) {
            return;
        }
        let pid = Pid::from_raw(self.child.id() as i32);
        let _ = kill(pid, Signal::SIGTERM);
        let t0 = Instant::now();
        while t0.elapsed() < grace {
            if matches!(self.child.try_wait(), Ok(Some(_))) {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for ChildGuard {
    fn drop(&mut self) {
        self.stop(Duration::from_secs(2));
    }
}

/// Where the `nerve` command is: `$NERVE_BIN`, next to this executable (or
/// its parent, for test executables under `deps/`), or on `PATH`.
pub fn nerve_bin() -> Result<PathBuf> {
    if let Some(p) = std::env::var_os("NERVE_BIN") {
        return Ok(PathBuf::from(p));
    }
    let exe = std::env::current_exe().context("cannot find this executable")?;
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
    bail!(
        "cannot find the `nerve` command next to {} or on PATH; build it into the same target dir \
         (`CARGO_TARGET_DIR=/work/target-bench cargo build --release -p nerve`) or set NERVE_BIN",
        exe.display()
    )
}

/// One isolated robot for one benchmark run, taken down when dropped.
#[derive(Debug)]
pub struct Robot {
    /// the robot's name
    pub name: String,
    nerve: PathBuf,
    /// NERVE_HOME of the run (a private temp dir, removed at the end)
    pub home: PathBuf,
    verbose: bool,
    /// `NERVE_CPU_LATENCY` of every process the robot starts (None: the agents' default)
    cpu_latency: Option<&'static str>,
}

impl Robot {
    /// The name [`Robot::new`] gives the robot of `tag`: `b<pid><tag>`.
    pub fn name_of(tag: &str) -> String {
        format!("b{}{tag}", std::process::id())
    }

    /// A robot named [`Robot::name_of`] `tag`, with its state in a private directory.
    pub fn new(tag: &str, verbose: bool) -> Result<Self> {
        let name = Robot::name_of(tag);
        let home = std::env::temp_dir().join(format!("nerve-bench-{name}"));
        std::fs::create_dir_all(&home).with_context(|| format!("cannot create {}", home.display()))?;
        Ok(Robot { name, nerve: nerve_bin()?, home, verbose, cpu_latency: None })
    }

    /// Every agent of this robot holds `value` (`off`, or µs) as its PM QoS
    /// bound instead of its default: set in the environment of every `nerve`
    /// command and child started through [`Robot::quiet`].
    pub fn with_cpu_latency(mut self, value: &'static str) -> Self {
        self.cpu_latency = Some(value);
        self
    }

    /// A `nerve --robot NAME ...` command.
    pub fn nerve(&self) -> Command {
        let mut c = Command::new(&self.nerve);
        c.arg("--robot").arg(&self.name).env("NERVE_HOME", &self.home);
        if let Some(v) = self.cpu_latency {
            c.env("NERVE_CPU_LATENCY", v);
        }
        c
    }

    /// Runs `nerve --robot NAME args...`, fails with its stderr when it fails; returns stdout.
    pub fn run(&self, args: &[&str]) -> Result<String> {
        let out = self
            .nerve()
            .args(args)
            .stdin(Stdio::null())
            .output()
            .with_context(|| format!("cannot run nerve {}", args.join(" ")))?;
        if !out.status.success() {
            bail!(
                "`nerve --robot {} {}` failed ({}): {}",
                self.name,
                args.join(" "),
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            );
        }
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    }

    /// Starts the router in the foreground as a child and waits until it answers.
    pub fn start_router(&self) -> Result<ChildGuard> {
        let mut cmd = self.nerve();
        cmd.arg("router").stdin(Stdio::null());
        self.quiet(&mut cmd);
        let mut guard = ChildGuard::spawn("nerve router", cmd)?;
        let t0 = Instant::now();
        loop {
            if self.run(&["ps", "--json"]).is_ok() {
                return Ok(guard);
            }
            guard.check_alive()?;
            if t0.elapsed() > Duration::from_secs(10) {
                bail!("the router of robot {} did not answer within 10 s", self.name);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Waits until the router lists every agent of `names`.
    pub fn wait_registered(&self, names: &[&str], timeout: Duration) -> Result<serde_json::Value> {
        let t0 = Instant::now();
        loop {
            let ps = self.ps()?;
            let listed: Vec<&str> =
                ps.as_array().map(|a| a.iter().filter_map(|x| x["name"].as_str()).collect()).unwrap_or_default();
            if names.iter().all(|n| listed.contains(n)) {
                return Ok(ps);
            }
            if t0.elapsed() > timeout {
                bail!("agents {names:?} did not register with the router within {timeout:?} (listed: {listed:?})");
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// `nerve ps --json`, parsed.
    pub fn ps(&self) -> Result<serde_json::Value> {
        let out = self.run(&["ps", "--json"])?;
        serde_json::from_str(&out).context("cannot parse `nerve ps --json`")
    }

    /// Silences a child's output unless `--verbose`, and gives it the
    /// robot's agent environment ([`Robot::with_cpu_latency`]).
    pub fn quiet(&self, cmd: &mut Command) {
        if let Some(v) = self.cpu_latency {
            cmd.env("NERVE_CPU_LATENCY", v);
        }
        if !self.verbose {
            cmd.stdout(Stdio::null()).stderr(Stdio::null());
        }
    }
}

impl Drop for Robot {
    fn drop(&mut self) {
        let out = self.nerve().args(["down", "--grace", "1"]).stdin(Stdio::null()).output();
        match out {
            Ok(o) if o.status.success() => {}
            Ok(o) => eprintln!(
                "warning: `nerve --robot {} down` failed: {}",
                self.name,
                String::from_utf8_lossy(&o.stderr).trim()
            ),
            Err(e) => eprintln!("warning: cannot run `nerve --robot {} down`: {e}", self.name),
        }
        let _ = std::fs::remove_dir_all(&self.home);
    }
}

/// A command that re-runs this executable with a hidden subcommand.
pub fn self_command(sub: &str) -> Result<Command> {
    let exe = std::env::current_exe().context("cannot find this executable")?;
    let mut c = Command::new(exe);
    c.arg(sub).stdin(Stdio::null());
    Ok(c)
}

/// Waits for a file to appear as [`wait_file`] does, after sleeping through
/// `quiet` (at most `timeout`) without a wake-up: for a batch known to take
/// about that long, so that this process's polling does not run on the
/// CPUs beside the batch it measures (every 2 ms at SCHED_FIFO 20, which a
/// woken agent would have to wait for).
pub fn wait_file_after(
    path: &Path,
    quiet: Duration,
    timeout: Duration,
    children: &mut [&mut ChildGuard],
) -> Result<bool> {
    let quiet = quiet.min(timeout);
    std::thread::sleep(quiet);
    wait_file(path, timeout.saturating_sub(quiet), children)
}

/// Waits for a file to appear, watching `children` for early exits.
pub fn wait_file(path: &Path, timeout: Duration, children: &mut [&mut ChildGuard]) -> Result<bool> {
    let t0 = Instant::now();
    while t0.elapsed() < timeout {
        if path.exists() {
            return Ok(true);
        }
        for c in children.iter_mut() {
            c.check_alive()?;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    Ok(false)
}

/// Puts the calling thread under SCHED_FIFO at `prio`, not inherited by
/// children it forks, and locks memory as the SDK does; says so when refused.
pub fn realtime_like_an_agent(prio: i32) -> bool {
    // as the SDK decides it: never a locked stack that cannot grow
    let _ = agent_sdk::rt::lock_memory();
    // SAFETY: plain system calls on the calling thread, valid arguments.
    unsafe {
        let param = libc::sched_param { sched_priority: prio };
        let rc = libc::sched_setscheduler(0, libc::SCHED_FIFO | libc::SCHED_RESET_ON_FORK, &param);
        if rc != 0 {
            eprintln!(
                "warning: SCHED_FIFO refused ({}); comparison runs without real-time priority",
                std::io::Error::last_os_error()
            );
            return false;
        }
    }
    true
}

/// Back to SCHED_OTHER for the calling thread.
pub fn normal_priority() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: plain system call on the calling thread.
    unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &param) };
}

/// Parses the arguments of the hidden subcommand `name` (`args`: what
/// follows it); a usage error is printed and becomes exit status 2.
pub fn parse_sub<A: clap::Parser>(name: &str, args: Vec<String>) -> Result<A, ExitCode> {
    A::try_parse_from(std::iter::once(name.to_owned()).chain(args)).map_err(|e| {
        let _ = e.print();
        ExitCode::from(2)
    })
}

/// The exit status of a child process's work: an error is printed as
/// `error: WHAT: ...` and becomes exit status 1.
pub fn exit_status(what: &str, r: Result<()>) -> ExitCode {
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {what}: {e:#}");
            ExitCode::from(1)
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn wait_file_after_sleeps_through_the_quiet_time_then_finds_the_file() {
        let dir = std::env::temp_dir().join(format!("nerve-bench-wait-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("batch-1.txt");
        std::fs::write(&path, "1\n").unwrap();
        let t0 = Instant::now();
        assert!(wait_file_after(&path, Duration::from_millis(100), Duration::from_secs(5), &mut []).unwrap());
        assert!(t0.elapsed() >= Duration::from_millis(100), "it looked before its quiet time was over");
        // a file that never comes: false once the whole timeout has passed
        let t0 = Instant::now();
        let none = dir.join("batch-2.txt");
        let found = wait_file_after(&none, Duration::from_millis(50), Duration::from_millis(120), &mut []).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        assert!(!found);
        assert!(t0.elapsed() >= Duration::from_millis(120));
    }
}
