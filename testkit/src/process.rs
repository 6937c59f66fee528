//! Processes seen through `/proc`: alive or not, their state, the daemons
//! re-parented to a test process, and the shared-memory files of a robot.

use std::path::PathBuf;

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
            && let Ok(pid) = libc::pid_t::try_from(pid)
        {
            let mut status = 0;
            // SAFETY: waitpid on one pid with WNOHANG and a valid status pointer.
            unsafe { libc::waitpid(pid, &mut status, libc::WNOHANG) };
        }
    }
}

/// State, parent pid and session of `pid`, from `/proc/<pid>/stat`.
pub(crate) fn proc_stat(pid: u32) -> Option<(String, u32, u32)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let mut f = stat.rsplit_once(')')?.1.split_whitespace();
    let state = f.next()?.to_owned();
    let ppid = f.next()?.parse().ok()?;
    let _pgrp = f.next()?;
    let session = f.next()?.parse().ok()?;
    Some((state, ppid, session))
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

/// Sends SIGKILL to `pid` (nothing when it is not a valid pid).
pub fn sigkill(pid: u32) {
    if let Ok(pid) = libc::pid_t::try_from(pid) {
        // SAFETY: kill has no memory-safety preconditions.
        unsafe { libc::kill(pid, libc::SIGKILL) };
    }
}

/// The files in /dev/shm whose names start with `prefix` (a robot's files
/// are `nerve_<uid>_<robot>_*`).
pub fn shm_files_with_prefix(prefix: &str) -> Vec<PathBuf> {
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
    use crate::wait_until;
    use std::process::Command;
    use std::time::Duration;

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
