//! Two users on one host (review R3, F6, F7; reliability issue "per-user
//! isolation"): each runs a robot of the same name side by side, and
//! neither sees, blocks or cleans up the other's. The second user is a
//! throw-away uid the test switches to with `setpriv` (which needs root:
//! elsewhere the test says it did not run, and passes).

use nerve_tests::{Robot, alive, reap, shm_files_with_prefix, wait_until};
use serde_json::Value;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A throw-away user (a uid no account has) running `nerve` on the same
/// robot name as a [`Robot`] of ours, with its own `NERVE_HOME`. Dropping
/// it stops its robot, kills whatever of that uid still runs and removes
/// its files, even when the test fails.
struct OtherUser {
    uid: u32,
    home: PathBuf,
    robot: String,
    bin: PathBuf,
}

impl OtherUser {
    fn new(robot: &Robot) -> Self {
        let uid = 60_000 + std::process::id() % 5_000;
        let home = std::env::temp_dir().join(format!("nerve-test-{}-uid{uid}", robot.name));
        let _ = std::fs::remove_dir_all(&home);
        std::fs::create_dir_all(&home).expect("home of the other user");
        std::os::unix::fs::chown(&home, Some(uid), Some(uid)).expect("chown the other user's home");
        std::fs::set_permissions(&home, std::fs::Permissions::from_mode(0o700)).expect("chmod");
        let bin = nerve_tests::bin_dir();
        OtherUser { uid, home, robot: robot.name.clone(), bin }
    }

    fn nerve(&self, args: &[&str]) -> Output {
        Command::new("setpriv")
            .args(["--reuid", &self.uid.to_string(), "--regid", &self.uid.to_string(), "--clear-groups", "--"])
            .arg(self.bin.join("nerve"))
            .args(args)
            .env("NERVE_ROBOT", &self.robot)
            .env("NERVE_HOME", &self.home)
            .env("HOME", &self.home)
            .env_remove("XDG_RUNTIME_DIR")
            .env_remove("NERVE_IOX2_ROOT")
            .env_remove("RUST_LOG")
            .output()
            .expect("run nerve as the other user")
    }

    fn ok(&self, args: &[&str]) -> String {
        let out = self.nerve(args);
        assert!(
            out.status.success(),
            "`nerve {}` as uid {} failed: {}",
            args.join(" "),
            self.uid,
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    fn ps(&self) -> Vec<Value> {
        match serde_json::from_str::<Value>(&self.ok(&["ps", "--json"])) {
            Ok(Value::Array(v)) => v,
            other => panic!("ps --json gave {other:?}"),
        }
    }

    fn prefix(&self) -> String {
        shm_schemas::RobotName::shm_prefix_of(self.uid, &self.robot)
    }

    fn iox2_root(&self) -> PathBuf {
        PathBuf::from(format!("/dev/shm/nerve-iox2-{}", self.uid))
    }

    /// Pids of every process of this uid.
    fn processes(&self) -> Vec<u32> {
        let Ok(rd) = std::fs::read_dir("/proc") else { return vec![] };
        rd.filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
            .filter(|p| uid_of(*p) == Some(self.uid) && alive(*p))
            .collect()
    }
}

impl Drop for OtherUser {
    fn drop(&mut self) {
        if std::thread::panicking() {
            nerve_tests::dump_logs(&self.home.join(&self.robot));
        }
        let _ = self.nerve(&["down", "--grace", "1"]);
        for p in self.processes() {
            nerve_tests::sigkill(p);
        }
        wait_until(Duration::from_secs(3), || {
            reap();
            self.processes().is_empty()
        });
        for f in shm_files_with_prefix(&self.prefix()) {
            let _ = std::fs::remove_file(f);
        }
        let _ = std::fs::remove_dir_all(self.iox2_root());
        let _ = std::fs::remove_dir_all(&self.home);
    }
}

/// The real uid of process `pid`.
fn uid_of(pid: u32) -> Option<u32> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status.lines().find_map(|l| l.strip_prefix("Uid:")).and_then(|v| v.split_whitespace().next()?.parse().ok())
}

/// Files in /dev/shm starting with `prefix`.
fn pids(ps: &[Value]) -> Vec<u32> {
    ps.iter().filter_map(|a| a["pid"].as_u64()).map(|p| p as u32).collect()
}

/// Permission bits and owner of `p`, or None if it is gone (an agent's
/// connection files come and go while the test lists them).
fn mode_and_owner(p: &Path) -> Option<(u32, u32)> {
    match std::fs::symlink_metadata(p) {
        Ok(m) => Some((m.mode() & 0o777, m.uid())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => panic!("{}: {e}", p.display()),
    }
}

/// Two users launch `launch/pipeline.toml` on the same robot name: both
/// robots run with their own agents, data and files; every file is its
/// owner's and private where nerve controls it; one user's `nerve down`
/// leaves the other's robot running; each cleans up only its own.
#[test]
fn two_users_run_a_robot_of_the_same_name_side_by_side() {
    if !nix::unistd::geteuid().is_root() || Command::new("setpriv").arg("--version").output().is_err() {
        eprintln!("not run: switching to a throw-away uid needs root and setpriv");
        return;
    }
    let me = Robot::new("users");
    let other = OtherUser::new(&me);
    let file = other.home.join("pipeline.toml");
    std::fs::copy(repo().join("launch/pipeline.toml"), &file).expect("copy the launch file");
    std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o644)).expect("chmod");

    // the other user first, so that a shared root or prefix would be theirs
    other.ok(&["launch", file.to_str().expect("utf-8 path")]);
    me.ok(&["launch", file.to_str().expect("utf-8 path")]);

    let (mine, theirs) = (me.ps(), other.ps());
    assert_eq!(mine.len(), 3, "my robot: {mine:?}");
    assert_eq!(theirs.len(), 3, "their robot: {theirs:?}");
    // Without CAP_IPC_LOCK and under a small finite RLIMIT_MEMLOCK (8 MiB
    // by default), their agents lock nothing rather than their pages of now:
    // a locked main stack left no room by the limit killed their ticker
    // with SIGSEGV in CI, whenever its build mapped a few pages less
    let small_memlock = nix::sys::resource::getrlimit(nix::sys::resource::Resource::RLIMIT_MEMLOCK)
        .is_ok_and(|(soft, _)| soft != nix::sys::resource::RLIM_INFINITY && soft < 16 << 20);
    if small_memlock {
        let t1 = std::fs::read_to_string(other.home.join(&other.robot).join("logs/t1.log")).unwrap_or_default();
        assert!(t1.contains("memory not locked: RLIMIT_MEMLOCK") && t1.contains("main thread's stack"), "{t1}");
    }
    let (my_pids, their_pids) = (pids(&mine), pids(&theirs));
    assert!(my_pids.iter().all(|p| !their_pids.contains(p)), "one router sees the other's agents");
    let my_uid = shm_schemas::names::effective_uid();
    assert!(my_pids.iter().all(|p| uid_of(*p) == Some(my_uid)), "my agents run as me");
    assert!(their_pids.iter().all(|p| uid_of(*p) == Some(other.uid)), "their agents run as them");

    // data flows on both, each on its own files
    assert_eq!(me.echo("r1/out", 3).len(), 3);
    let their_echo = other.ok(&["echo", "r1/out", "--count", "3", "--json", "--timeout", "5"]);
    assert_eq!(their_echo.lines().count(), 3, "{their_echo}");

    let my_prefix = shm_schemas::RobotName::shm_prefix_of(my_uid, &me.name);
    let (my_files, their_files) = (shm_files_with_prefix(&my_prefix), shm_files_with_prefix(&other.prefix()));
    assert!(!my_files.is_empty() && !their_files.is_empty(), "{my_files:?} {their_files:?}");
    for (files, uid) in [(&my_files, my_uid), (&their_files, other.uid)] {
        for f in files.iter() {
            let Some((mode, owner)) = mode_and_owner(f) else { continue };
            assert_eq!(owner, uid, "{} belongs to uid {owner}", f.display());
            // iceoryx2's management segment was 0666 (review F6)
            assert_eq!(mode & 0o002, 0, "{} is world-writable ({mode:o})", f.display());
        }
    }
    assert_eq!(mode_and_owner(&other.iox2_root()), Some((0o700, other.uid)), "their iceoryx2 root");
    let mine = agent_sdk::world::default_iox2_root();
    assert_eq!(mode_and_owner(Path::new(&mine)), Some((0o700, my_uid)), "my iceoryx2 root");

    // their `down` stops theirs only
    other.ok(&["down", "--grace", "2"]);
    assert!(other.processes().is_empty(), "their processes left: {:?}", other.processes());
    assert!(
        shm_files_with_prefix(&other.prefix()).is_empty(),
        "their files left: {:?}",
        shm_files_with_prefix(&other.prefix())
    );
    assert_eq!(me.ps().len(), 3, "my robot survives their down");
    assert_eq!(me.echo("r1/out", 2).len(), 2, "and my data still flows");
    me.down_and_check_clean();
}

/// A command on a robot that nobody runs (a mistyped name) leaves nothing
/// in /dev/shm: iceoryx2 created a world-writable management file per
/// robot name tried, and it stayed (review F7).
#[test]
fn a_command_on_a_robot_nobody_runs_leaves_no_file() {
    let r = Robot::new("nobody");
    let err = r.fails(&["ps"]);
    assert!(err.contains("no router runs"), "{err}");
    let _ = r.nerve(&["graph"]);
    let _ = r.nerve(&["param", "get", "t1", "step"]);
    assert!(r.shm_files().is_empty(), "left: {:?}", r.shm_files());
}
