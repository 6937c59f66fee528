//! An idle agent must cost ~nothing: it sleeps until a request comes.
//!
//! Starts the `idle` example agent (built by `cargo test -p agent-sdk`, next
//! to this test under `target/<profile>/examples/`) on a robot of its own
//! with no router, lets it settle, then counts the voluntary context
//! switches of all its threads (`/proc/<pid>/task/*/status`) over 2 s. Each
//! voluntary switch is the thread going to sleep once, so the count is the
//! number of wake-ups.
//!
//! The bound, honestly: a message checker with a 100 ms tick (as before this
//! test) makes 10 wake-ups a second, 20 in the window, and a suspended
//! periodic task polling every 100 ms 20 more. The checker's housekeeping
//! now runs every 2 s, so the window holds at most 2 ticks; the bound
//! leaves room for a little noise (a late start-up write, a tick landing
//! twice in the window) without letting a 100 ms tick pass.

use agent_sdk::World;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

/// At most this many wake-ups of the whole process in [`WINDOW`]; a 100 ms
/// tick alone makes 20.
const MAX_WAKEUPS: u64 = 8;
const WINDOW: Duration = Duration::from_secs(2);
/// Time for the agent to finish starting before the window opens.
const SETTLE: Duration = Duration::from_millis(1500);

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// The idle example agent, next to this test executable.
fn idle_exe() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let mut dir = exe.parent().expect("exe dir").to_path_buf();
    if dir.ends_with("deps") {
        dir.pop();
    }
    let idle = dir.join("examples").join("idle");
    assert!(
        idle.exists(),
        "{} is missing: build it with `cargo build -p agent-sdk --example idle` (cargo test -p agent-sdk does)",
        idle.display()
    );
    idle
}

/// An agent process on a robot of its own; dropping it stops the process and
/// removes the robot's shared memory, iceoryx2 records and state directory,
/// whether the test passed or not.
struct IdleAgent {
    child: Child,
    world: World,
    home: PathBuf,
}

impl IdleAgent {
    fn start(tag: &str, periodic: bool) -> Self {
        let robot = format!("idle{}-{}{}", std::process::id(), tag, COUNTER.fetch_add(1, Ordering::Relaxed));
        let home = std::env::temp_dir().join(format!("nerve-test-{robot}"));
        let world = World::new(&robot).expect("test world");
        let mut cmd = Command::new(idle_exe());
        cmd.args(["--robot", &robot, "--name", "idle", "--no-realtime", "--log-level", "warn"])
            .env("NERVE_HOME", &home)
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        if periodic {
            cmd.arg("--suspended").env("NERVE_IDLE_PERIODIC", "1");
        }
        let child = cmd.spawn().expect("start the idle agent");
        IdleAgent { child, world, home }
    }

    /// Voluntary context switches summed over the process's threads, and how many threads.
    fn wakeups(&self) -> (u64, usize) {
        let dir = format!("/proc/{}/task", self.child.id());
        let mut total = 0;
        let mut threads = 0;
        for e in std::fs::read_dir(&dir).expect("the agent's /proc task directory").flatten() {
            let Ok(status) = std::fs::read_to_string(e.path().join("status")) else { continue };
            threads += 1;
            total += status
                .lines()
                .find_map(|l| l.strip_prefix("voluntary_ctxt_switches:"))
                .and_then(|v| v.trim().parse::<u64>().ok())
                .unwrap_or(0);
        }
        (total, threads)
    }

    fn measure(&mut self) -> u64 {
        std::thread::sleep(SETTLE);
        assert!(self.child.try_wait().expect("wait on the agent").is_none(), "the idle agent exited at start");
        let (before, threads) = self.wakeups();
        std::thread::sleep(WINDOW);
        let (after, _) = self.wakeups();
        let n = after.saturating_sub(before);
        eprintln!("idle agent: {n} wake-ups in {WINDOW:?} over {threads} threads");
        n
    }
}

impl Drop for IdleAgent {
    fn drop(&mut self) {
        // SIGTERM first, so that the agent leaves cleanly; then make sure.
        // SAFETY: kill with a pid of our own child and a valid signal.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        for _ in 0..100 {
            if matches!(self.child.try_wait(), Ok(Some(_))) {
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        for f in self.world.shm_files().into_iter().chain(self.world.iox2_files()) {
            let _ = std::fs::remove_file(f);
        }
        let _ = std::fs::remove_dir_all(&self.home);
    }
}

#[test]
fn an_idle_event_driven_agent_sleeps() {
    let mut agent = IdleAgent::start("e", false);
    let n = agent.measure();
    assert!(n <= MAX_WAKEUPS, "an idle event-driven agent woke {n} times in {WINDOW:?} (at most {MAX_WAKEUPS})");
}

#[test]
fn a_suspended_periodic_agent_sleeps() {
    let mut agent = IdleAgent::start("p", true);
    let n = agent.measure();
    assert!(n <= MAX_WAKEUPS, "a suspended periodic agent woke {n} times in {WINDOW:?} (at most {MAX_WAKEUPS})");
}
