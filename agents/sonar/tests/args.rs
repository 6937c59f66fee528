//! The sonar agent's own arguments (after `--`), as a user types them: the
//! SDK's `Setup::args` lists them with `--help` and refuses a wrong one
//! with the agent's name and what to do. The real program, in a robot of
//! its own whose files are removed whatever happens.

use agent_sdk::World;
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A robot of this test alone: its state folder and shared-memory files go
/// when it is dropped.
struct Robot {
    name: String,
    home: PathBuf,
}

impl Robot {
    fn new(tag: &str) -> Self {
        let name = format!("sonarargs{tag}{}", std::process::id());
        let home = std::env::temp_dir().join(format!("nerve-{name}"));
        std::fs::create_dir_all(&home).expect("the test's state folder");
        Robot { name, home }
    }

    /// Runs `nerve-sonar` with `args` (after `--`), waiting at most 30 s.
    fn sonar(&self, args: &[&str]) -> Output {
        let child = Command::new(env!("CARGO_BIN_EXE_nerve-sonar"))
            .args(["--robot", &self.name, "--no-realtime", "--"])
            .args(args)
            .env("NERVE_HOME", &self.home)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("nerve-sonar starts");
        let id = child.id();
        let began = Instant::now();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(child.wait_with_output());
        });
        match rx.recv_timeout(Duration::from_secs(30)) {
            Ok(out) => out.expect("nerve-sonar's output"),
            Err(_) => {
                // ours and unreaped (its waiter still holds it): the pid is still its own
                let _ = Command::new("kill").args(["-KILL", &id.to_string()]).status();
                panic!("nerve-sonar {args:?} still ran after {:?}", began.elapsed())
            }
        }
    }
}

impl Drop for Robot {
    fn drop(&mut self) {
        if let Ok(w) = World::new(&self.name) {
            w.cleanup_dead_nodes();
            for f in w.shm_files().into_iter().chain(w.iox2_files()) {
                let _ = std::fs::remove_file(f);
            }
        }
        let _ = std::fs::remove_dir_all(&self.home);
    }
}

#[test]
fn help_after_the_dashes_lists_the_agents_own_arguments() {
    let r = Robot::new("help");
    let out = r.sonar(&["--help"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "help ends well: {:?} {}", out.status, String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("Usage: nerve-sonar -- [OPTIONS]"), "{stdout}");
    assert!(stdout.contains("--device") && stdout.contains("Serial device of the sonar ring module"), "{stdout}");
    assert!(!stdout.contains("--robot"), "the common options are not the agent's own: {stdout}");
}

#[test]
fn a_wrong_argument_is_refused_with_the_agent_and_what_to_do() {
    let r = Robot::new("bad");
    let out = r.sonar(&["--devise", "/dev/ttyUSB0"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(i32::from(agent_sdk::runtime::EXIT_STARTUP)), "{stderr}");
    assert!(stderr.contains("agent \"sonar\""), "names the agent: {stderr}");
    assert!(stderr.contains("--devise"), "names the argument: {stderr}");
    assert!(stderr.contains("`nerve-sonar -- --help` lists them"), "says what to do: {stderr}");
}
