//! A robot's isolated world: its iceoryx2 configuration (own file prefix and
//! root path), its state directory, and the helpers that find and clean what
//! it leaves in shared memory.
//!
//! Every process of robot `R` — router, agents, the `nerve` command — builds
//! the same [`World`] from the robot name, so they all see one another and
//! nothing of any other robot on the host.

use iceoryx2::config::Config;
use iceoryx2::prelude::*;
use shm_schemas::RobotName;
use std::path::{Path as StdPath, PathBuf};

/// The iceoryx2 service variant nerve uses everywhere: ports may move between
/// the message-checker and task threads.
pub type Ipc = ipc_threadsafe::Service;

/// Environment variable naming the robot when `--robot` is not given.
pub const ROBOT_ENV: &str = "NERVE_ROBOT";
/// Environment variable overriding the base of the state directories
/// (default `$XDG_RUNTIME_DIR/nerve`, else `/tmp/nerve-<uid>`).
pub const HOME_ENV: &str = "NERVE_HOME";

/// The base of the state directories when `NERVE_HOME` is not set: the
/// user's runtime directory (private, per user, on tmpfs) where there is
/// one, else `/tmp/nerve-<uid>`. Per user, so that one user's robot named
/// `default` never locks out or reads another's.
pub fn default_home() -> PathBuf {
    match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d).join("nerve"),
        None => PathBuf::from(format!("/tmp/nerve-{}", nix::unistd::geteuid())),
    }
}

/// Makes `dir` a private directory of this user, or says why it cannot be
/// one: created 0700 when missing; refused when it is a symlink, not a
/// directory, or owned by another uid; made 0700 when it is ours but open
/// to others (a state directory of an older nerve, say). Another local user
/// can then neither plant files or symlinks in it nor read its logs.
pub fn secure_dir(dir: &StdPath) -> Result<(), String> {
    use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
    match std::fs::symlink_metadata(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            std::fs::DirBuilder::new()
                .recursive(true)
                .mode(0o700)
                .create(dir)
                .map_err(|e| format!("cannot create it: {e}"))?;
        }
        Err(e) => return Err(e.to_string()),
        Ok(_) => {}
    }
    let m = std::fs::symlink_metadata(dir).map_err(|e| e.to_string())?;
    if m.file_type().is_symlink() {
        return Err("it is a symbolic link; nerve does not follow links for its state (remove it)".into());
    }
    if !m.is_dir() {
        return Err("it is not a directory".into());
    }
    let me = nix::unistd::geteuid().as_raw();
    if m.uid() != me {
        return Err(format!(
            "it belongs to uid {}, not to you (uid {me}); another user may have made it: remove it, or set {HOME_ENV} to a directory of yours",
            m.uid()
        ));
    }
    if m.mode() & 0o077 != 0 {
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))
            .map_err(|e| format!("cannot make it private: {e}"))?;
    }
    Ok(())
}
/// Environment variable overriding the iceoryx2 root path (default `/dev/shm/nerve-iox2/`).
pub const IOX2_ROOT_ENV: &str = "NERVE_IOX2_ROOT";
/// Default iceoryx2 root path. It is short on purpose: iceoryx2 event
/// listeners are Unix datagram sockets under this path, and a socket path may
/// not exceed 108 bytes. Robots sharing it stay isolated by their file prefix.
///
/// It is on tmpfs on purpose: iceoryx2 keeps a file per node and per
/// service there and creates them at every node and port creation. Under
/// `/tmp` on a disk (ext4 on these machines) an agent took 26-46 ms from
/// its first iceoryx2 call to its registration; on tmpfs 7-11 ms.
pub const DEFAULT_IOX2_ROOT: &str = "/dev/shm/nerve-iox2/";
/// Robot name used when neither `--robot` nor `NERVE_ROBOT` is set.
pub const DEFAULT_ROBOT: &str = "default";

/// Why a world could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The robot name is invalid.
    #[error("invalid robot name: {0}")]
    Name(#[from] shm_schemas::NameError),
    /// A path is not accepted by iceoryx2.
    #[error(
        "the iceoryx2 root {path} cannot be used ({detail}); set {IOX2_ROOT_ENV} to a short path on tmpfs such as /dev/shm/nerve-iox2/"
    )]
    Path {
        /// the path
        path: String,
        /// what iceoryx2 said
        detail: String,
    },
    /// The state directory could not be created.
    #[error("cannot use the state directory {path}: {detail}")]
    UnsafeStateDir {
        /// the directory
        path: String,
        /// why
        detail: String,
    },
    /// The state directory could not be created.
    #[error("cannot create the state directory {path}: {source}; set {HOME_ENV} to a writable directory")]
    StateDir {
        /// the path
        path: String,
        /// the cause
        source: std::io::Error,
    },
    /// iceoryx2 refused to create a node.
    #[error("cannot create an iceoryx2 node {name:?}: {detail}")]
    Node {
        /// node name
        name: String,
        /// what iceoryx2 said
        detail: String,
    },
}

/// A base directory named by the user (`NERVE_HOME`): created when missing;
/// it may be shared (0755) but not a link, nor another user's, nor writable
/// by others.
fn check_base(base: &StdPath) -> Result<(), String> {
    use std::os::unix::fs::MetadataExt;
    if std::fs::symlink_metadata(base).is_err() {
        return secure_dir(base);
    }
    let m = std::fs::symlink_metadata(base).map_err(|e| e.to_string())?;
    let me = nix::unistd::geteuid().as_raw();
    if m.file_type().is_symlink() {
        return Err(format!("it is a symbolic link; give {HOME_ENV} the real directory"));
    }
    if m.uid() != me || m.mode() & 0o022 != 0 {
        return Err(format!(
            "it belongs to uid {} with mode {:o}; {HOME_ENV} must name a directory of yours that others cannot write",
            m.uid(),
            m.mode() & 0o7777
        ));
    }
    Ok(())
}

/// One robot's world.
#[derive(Debug, Clone)]
pub struct World {
    robot: RobotName,
    config: Config,
    state_dir: PathBuf,
    iox_root: PathBuf,
}

impl World {
    /// The world of `robot`, with its state under `$NERVE_HOME/<robot>` (default: [`default_home`]).
    pub fn new(robot: &str) -> Result<Self, WorldError> {
        let robot = RobotName::new(robot)?;
        let base = std::env::var_os(HOME_ENV).filter(|h| !h.is_empty()).map(PathBuf::from).unwrap_or_else(default_home);
        let state_dir = base.join(robot.as_str());
        let mut iox_root = std::env::var(IOX2_ROOT_ENV).unwrap_or_else(|_| DEFAULT_IOX2_ROOT.to_owned());
        if !iox_root.ends_with('/') {
            iox_root.push('/');
        }
        if iox_root.len() > 40 {
            return Err(WorldError::Path {
                path: iox_root,
                detail: "longer than 40 bytes, which would overflow Unix socket paths".into(),
            });
        }
        let mut config = Config::default();
        config.global.prefix = FileName::new(robot.shm_prefix().as_bytes())
            .map_err(|e| WorldError::Path { path: robot.shm_prefix(), detail: format!("{e:?}") })?;
        let root = Path::new(iox_root.as_bytes())
            .map_err(|e| WorldError::Path { path: iox_root.clone(), detail: format!("{e:?}") })?;
        config.global.set_root_path(&root);
        Ok(World { robot, config, state_dir, iox_root: PathBuf::from(iox_root) })
    }

    /// The robot's name.
    pub fn robot(&self) -> &RobotName {
        &self.robot
    }

    /// The iceoryx2 configuration of this world.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The robot's state directory (connection list, logs, pid files).
    pub fn state_dir(&self) -> &StdPath {
        &self.state_dir
    }

    /// Creates the state directory and its `logs/` and `pids/` folders,
    /// private to this user (see [`secure_dir`]); the base above it must not
    /// be a link, nor belong to or be writable by another user.
    pub fn ensure_state_dirs(&self) -> Result<(), WorldError> {
        if let Some(base) = self.state_dir.parent() {
            if std::env::var_os(HOME_ENV).is_none() {
                secure_dir(base)
                    .map_err(|detail| WorldError::UnsafeStateDir { path: base.display().to_string(), detail })?;
            } else {
                check_base(base)
                    .map_err(|detail| WorldError::UnsafeStateDir { path: base.display().to_string(), detail })?;
            }
        }
        for d in [self.state_dir.clone(), self.logs_dir(), self.pids_dir()] {
            secure_dir(&d).map_err(|detail| WorldError::UnsafeStateDir { path: d.display().to_string(), detail })?;
        }
        Ok(())
    }

    /// Where agents' daemon logs go.
    pub fn logs_dir(&self) -> PathBuf {
        self.state_dir.join("logs")
    }

    /// Where daemons write their pid files.
    pub fn pids_dir(&self) -> PathBuf {
        self.state_dir.join("pids")
    }

    /// The log file of agent `name`.
    pub fn log_file(&self, name: &str) -> PathBuf {
        self.logs_dir().join(format!("{name}.log"))
    }

    /// The pid file of agent `name` (or `router`).
    pub fn pid_file(&self, name: &str) -> PathBuf {
        self.pids_dir().join(format!("{name}.pid"))
    }

    /// Creates an iceoryx2 node in this world. Creating a node also removes
    /// the stale resources of dead nodes.
    pub fn node(&self, name: &str) -> Result<Node<Ipc>, WorldError> {
        quiet_iceoryx2();
        let node_name: NodeName =
            name.try_into().map_err(|e| WorldError::Node { name: name.into(), detail: format!("{e:?}") })?;
        NodeBuilder::new()
            .name(&node_name)
            .config(&self.config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Ipc>()
            .map_err(|e| WorldError::Node { name: name.into(), detail: format!("{e:?}") })
    }

    /// Files of this robot in `/dev/shm`.
    pub fn shm_files(&self) -> Vec<PathBuf> {
        let prefix = self.robot.shm_prefix();
        let Ok(rd) = std::fs::read_dir("/dev/shm") else { return Vec::new() };
        rd.filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
            .map(|e| e.path())
            .collect()
    }

    /// The iceoryx2 root path (shared by every robot; files carry the robot's prefix).
    pub fn iox2_root(&self) -> &StdPath {
        &self.iox_root
    }

    /// This robot's files under the iceoryx2 root (node and service records, sockets).
    pub fn iox2_files(&self) -> Vec<PathBuf> {
        fn walk(dir: &StdPath, prefix: &str, out: &mut Vec<PathBuf>) {
            let Ok(rd) = std::fs::read_dir(dir) else { return };
            for e in rd.filter_map(|e| e.ok()) {
                let p = e.path();
                if p.is_dir() {
                    walk(&p, prefix, out);
                } else if e.file_name().to_string_lossy().starts_with(prefix) {
                    out.push(p);
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.iox_root, &self.robot.shm_prefix(), &mut out);
        out
    }

    /// Removes the resources of every dead node of this world; returns how many were cleaned.
    pub fn cleanup_dead_nodes(&self) -> usize {
        quiet_iceoryx2();
        let mut dead = Vec::new();
        let _ = Node::<Ipc>::list(&self.config, |state| {
            if let NodeState::Dead(view) = state {
                dead.push(view);
            }
            CallbackProgression::Continue
        });
        let mut n = 0;
        for view in dead {
            if view.try_remove_stale_resources().is_ok() {
                n += 1;
            }
        }
        n
    }

    /// Pids of the live iceoryx2 nodes of this world.
    pub fn live_node_pids(&self) -> Vec<u32> {
        use iceoryx2::node::NodeView;
        let mut pids = Vec::new();
        let _ = Node::<Ipc>::list(&self.config, |state| {
            if let NodeState::Alive(view) = state
                && let Some(d) = view.details()
            {
                pids.push(d.process_id().value() as u32);
            }
            CallbackProgression::Continue
        });
        pids
    }
}

/// Lowers iceoryx2's own logging to errors unless `IOX2_LOG_LEVEL` says otherwise.
pub fn quiet_iceoryx2() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| set_log_level_from_env_or(LogLevel::Error));
}

/// Whether process `pid` is alive (exists and is not a zombie).
pub fn pid_alive(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Ok(stat) => {
            // the state is the first field after the parenthesised command
            let state = stat.rsplit_once(')').and_then(|(_, rest)| rest.split_whitespace().next());
            !matches!(state, Some("Z") | Some("X") | None)
        }
        Err(_) => false,
    }
}

/// Helpers of the SDK's own tests.
#[cfg(test)]
pub(crate) mod test_support {
    use super::World;

    /// Removes a test robot's shared-memory and iceoryx2 files when dropped,
    /// even when the test fails.
    pub(crate) struct Cleanup(pub(crate) World);

    impl Drop for Cleanup {
        fn drop(&mut self) {
            for f in self.0.shm_files().into_iter().chain(self.0.iox2_files()) {
                let _ = std::fs::remove_file(f);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::{MetadataExt, PermissionsExt};

    #[test]
    fn state_directories_are_private_and_never_links() {
        let base = std::env::temp_dir().join(format!("nerve-secure-dir-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        let d = base.join("r1");
        secure_dir(&d).expect("created");
        assert_eq!(std::fs::metadata(&d).map(|m| m.mode() & 0o777).ok(), Some(0o700));
        // an old, world-readable state directory of ours is made private
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o755)).expect("chmod");
        secure_dir(&d).expect("ours");
        assert_eq!(std::fs::metadata(&d).map(|m| m.mode() & 0o777).ok(), Some(0o700));
        // a planted symlink is refused (review F6, R1)
        let target = base.join("elsewhere");
        std::fs::create_dir_all(&target).expect("target");
        let link = base.join("r2");
        std::os::unix::fs::symlink(&target, &link).expect("symlink");
        assert!(secure_dir(&link).expect_err("a link").contains("symbolic link"));
        // a directory of another user is refused (root can make one to test with)
        if nix::unistd::geteuid().is_root() {
            let theirs = base.join("r3");
            std::fs::create_dir_all(&theirs).expect("dir");
            std::os::unix::fs::chown(&theirs, Some(65534), Some(65534)).expect("chown to nobody");
            assert!(secure_dir(&theirs).expect_err("another uid").contains("uid 65534"));
            assert!(check_base(&theirs).is_err());
        }
        let _ = std::fs::remove_dir_all(&base);
    }
}
