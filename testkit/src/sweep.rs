//! The sweep of what killed test processes left: a test process killed
//! before its robots are dropped (the nextest watchdog's SIGKILL) leaves
//! their daemons running, in sessions of their own, and their files. Test
//! robot names start with `t<pid>-`, so what belongs to a dead test process
//! is known by its pid; the first [`crate::Robot::new`] of every test
//! process sweeps it.

use crate::{alive, reap, sigkill, wait_until};
use std::path::PathBuf;
use std::time::Duration;

/// Prefix of a test robot's `NERVE_HOME` under the temporary directory.
pub(crate) const HOME_PREFIX: &str = "nerve-test-t";

/// A failed test's home holds this file: the sweep then leaves the home (its
/// logs, a demo's summary and figures) for reading, for [`KEEP_FOR`].
pub const KEPT_MARKER: &str = "KEPT-FOR-READING";

/// How long a failed test's home is kept; the first sweep after that removes it.
pub const KEEP_FOR: Duration = Duration::from_secs(24 * 3600);

/// Prefix of this user's test robots' files in /dev/shm (and under the
/// iceoryx2 root): `nerve_<uid>_t`.
pub(crate) fn shm_test_prefix() -> String {
    shm_schemas::RobotName::shm_prefix_of(shm_schemas::names::effective_uid(), "t").trim_end_matches('_').to_owned()
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::process::proc_stat;
    use std::process::Command;

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
}
