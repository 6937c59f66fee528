//! Processes the benchmarks start, and the robot they run in.
//!
//! Every child is held by the test kit's [`ChildGuard`] (`nerve-testkit`,
//! shared with the system tests), which stops it when dropped (SIGTERM, a
//! short grace, then SIGKILL) and asks the kernel to send it SIGTERM should
//! this process die first. A [`Robot`] is the kit's robot (a unique name
//! `b<pid>...`, `nerve --robot NAME down` when dropped, so nothing is left
//! in `/dev/shm`) with the benchmarks' options.

use anyhow::{Context as _, Result, bail};
use std::process::{Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

pub use nerve_testkit::{ChildGuard, spawn_dying_with_us, wait_file, wait_file_after};

/// One isolated robot for one benchmark run: the test kit's robot (a
/// unique name `b<pid><tag>`, a private home, `nerve down` when dropped)
/// with what the benchmarks add: `--verbose`, the agents' PM QoS bound, and
/// commands that fail with the command's stderr instead of panicking.
#[derive(Debug)]
pub struct Robot {
    kit: nerve_testkit::Robot,
    verbose: bool,
    /// `NERVE_CPU_LATENCY` of every process the robot starts (None: the agents' default)
    cpu_latency: Option<&'static str>,
}

/// The kit's robot: its `name` and `home`.
impl std::ops::Deref for Robot {
    type Target = nerve_testkit::Robot;

    fn deref(&self) -> &nerve_testkit::Robot {
        &self.kit
    }
}

impl Robot {
    /// The name [`Robot::new`] gives the robot of `tag`: `b<pid><tag>`.
    pub fn name_of(tag: &str) -> String {
        nerve_testkit::Robot::bench_name(tag)
    }

    /// A robot named [`Robot::name_of`] `tag`, with its state in a private directory.
    pub fn new(tag: &str, verbose: bool) -> Result<Self> {
        Ok(Robot { kit: nerve_testkit::Robot::for_bench(tag)?, verbose, cpu_latency: None })
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
        let mut c = Command::new(self.kit.nerve_path());
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

/// A command that re-runs this executable with a hidden subcommand.
pub fn self_command(sub: &str) -> Result<Command> {
    let exe = std::env::current_exe().context("cannot find this executable")?;
    let mut c = Command::new(exe);
    c.arg(sub).stdin(Stdio::null());
    Ok(c)
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
