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
/// Environment variable overriding the iceoryx2 root path (default
/// `/dev/shm/nerve-iox2-<uid>/`, see [`default_iox2_root`]).
pub const IOX2_ROOT_ENV: &str = "NERVE_IOX2_ROOT";

/// The iceoryx2 root path when `NERVE_IOX2_ROOT` is not set:
/// `/dev/shm/nerve-iox2-<uid>/`, one per user, private (0700, checked before
/// every use). A root shared by all users (earlier nerve used
/// `/dev/shm/nerve-iox2/`) belonged to whoever ran nerve first: everyone
/// else was locked out, and a planted one let its owner replace other users'
/// node records and sockets (review R3).
///
/// It is short on purpose: iceoryx2 event listeners are Unix datagram
/// sockets under this path, and a socket path may not exceed 108 bytes.
/// Robots of one user sharing it stay isolated by their file prefix.
///
/// It is on tmpfs on purpose: iceoryx2 keeps a file per node and per
/// service there and creates them at every node and port creation. Under
/// `/tmp` on a disk (ext4 on these machines) an agent took 26-46 ms from
/// its first iceoryx2 call to its registration; on tmpfs 7-11 ms.
pub fn default_iox2_root() -> String {
    format!("/dev/shm/nerve-iox2-{}/", shm_schemas::names::effective_uid())
}

/// Longest Unix socket path (`sun_path`, with its terminating zero).
const MAX_SOCKET_PATH: usize = 107;
/// The name of iceoryx2 0.10.0's global management segment after the
/// robot's prefix: the SHA-1 of its state type's name (base64url), `_node`,
/// the version and the suffix. The test
/// `the_iceoryx2_root_is_private_and_the_management_file_ours_alone`
/// fails on an iceoryx2 that names it otherwise: update it then.
const GLOBAL_MGMT_TAIL: &str = "9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_0.global_mgmt";

/// What iceoryx2 adds to root and prefix in an event socket's path:
/// `<root><prefix><id>.event`, the id a u128 whose top 32 bits are a
/// per-process counter (31-32 digits as measured; 34 leave room for 10^4
/// listeners in one process).
const SOCKET_NAME_TAIL: usize = 34 + ".event".len();

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
        "the iceoryx2 root {path} cannot be used ({detail}); set {IOX2_ROOT_ENV} to a short path on tmpfs such as /dev/shm/nerve-iox2-<your uid>/"
    )]
    Path {
        /// the path
        path: String,
        /// what iceoryx2 said
        detail: String,
    },
    /// The iceoryx2 root is not a private directory of this user.
    #[error("cannot use the iceoryx2 root {path}: {detail}")]
    UnsafeIox2Root {
        /// the directory
        path: String,
        /// why
        detail: String,
    },
    /// A shared-memory file of this robot belongs to another user.
    #[error(
        "{path} belongs to uid {owner}, not to you (uid {me}): another user made a file with your robot's prefix; remove it (as root or as that user) and start again"
    )]
    ForeignFile {
        /// the file
        path: String,
        /// its owner
        owner: u32,
        /// the caller
        me: u32,
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
    #[error("cannot create an iceoryx2 node {name:?}: {source:?}")]
    Node {
        /// node name
        name: String,
        /// what iceoryx2 said (its `NodeCreationFailure`, or the error of
        /// an invalid node name)
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
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
        // A relative home would name a different directory in every process
        // that resolves it from its own working directory (daemons and the
        // router's restarts among them): one robot, several state folders.
        if base.is_relative() {
            return Err(WorldError::Path {
                path: base.display().to_string(),
                detail: format!(
                    "{HOME_ENV} is a relative path, which each process would resolve from its own working directory; give an absolute one (e.g. {HOME_ENV}=$PWD/{})",
                    base.display()
                ),
            });
        }
        let state_dir = base.join(robot.as_str());
        let mut iox_root =
            std::env::var(IOX2_ROOT_ENV).ok().filter(|r| !r.is_empty()).unwrap_or_else(default_iox2_root);
        if !iox_root.ends_with('/') {
            iox_root.push('/');
        }
        let socket_path = iox_root.len() + robot.shm_prefix().len() + SOCKET_NAME_TAIL;
        if socket_path > MAX_SOCKET_PATH {
            return Err(WorldError::Path {
                path: iox_root,
                detail: format!(
                    "with robot {robot}'s prefix {}, iceoryx2's socket paths would reach {socket_path} bytes, over the {MAX_SOCKET_PATH} a Unix socket allows; use a shorter root or robot name",
                    robot.shm_prefix()
                ),
            });
        }
        let mut config = Config::default();
        config.global.prefix = FileName::new(robot.shm_prefix().as_bytes())
            .map_err(|e| WorldError::Path { path: robot.shm_prefix(), detail: format!("{e:?}") })?;
        let root = Path::new(iox_root.as_bytes())
            .map_err(|e| WorldError::Path { path: iox_root.clone(), detail: format!("{e:?}") })?;
        config.global.set_root_path(&root);
        // Every node of the robot was scanned (a stat and a lock test of
        // each) whenever any process made or dropped its own: twice per
        // `nerve` command and once per agent start, so launching n agents
        // cost n² looks (a launch of 50 took 0.55 s, 0.46 s without). The
        // router cleans up after dead processes instead, at once for an
        // agent and every few seconds for anything else, as does `nerve
        // down`.
        config.global.node.cleanup_dead_nodes_on_creation = false;
        config.global.node.cleanup_dead_nodes_on_destruction = false;
        // The same scan per service: opening a service looked at every node
        // attached to it (reading each one's record, a TOML file, and
        // formatting iceoryx2's whole configuration three times for log
        // origins), so every agent that opened the router's services paid
        // for every agent before it, and a launch of 50 spent half its time
        // there (1.23 s against 0.68 s without, BENCHMARKS §3). Where a dead
        // process's ports would block an opener (a crashed agent's control
        // server, a source's subscriber slots, a killed router's server),
        // the opener cleans up once and tries again ([`retry_after_cleanup`],
        // docs/router.md). `NERVE_IOX2_CLEANUP_ON_OPEN=on` brings iceoryx2's
        // own scan back (to measure it).
        config.global.service.cleanup_dead_nodes_on_open =
            std::env::var_os(CLEANUP_ON_OPEN_ENV).is_some_and(|v| v == "on");
        // Each subscriber, client and server keeps room for the connections
        // of peers that left with messages still unread: 128 by iceoryx2's
        // default, each a slot built and touched when the port is made. A
        // subscriber here reads one source (a publisher, or its restarted
        // successor), a client one server: a few suffice. The room cost
        // the router about 0.8 ms per agent it first called (its client of
        // the agent; 40 ms of a launch of 50) and every subscribe a share
        // of its millisecond (BENCHMARKS §3). A peer that leaves past this
        // many expired connections loses its unread messages; it has left.
        let expired = expired_connection_buffer();
        config.defaults.publish_subscribe.subscriber_expired_connection_buffer = expired;
        config.defaults.request_response.client_expired_connection_buffer = expired;
        config.defaults.request_response.server_expired_connection_buffer = expired;
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

    /// The router's socket for tools (`nerve` commands), in the private
    /// state directory: see [`crate::control::ToolSocket`].
    pub fn tool_socket(&self) -> PathBuf {
        self.state_dir.join("router.sock")
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
    ///
    /// Before: the iceoryx2 root must be a private directory of this user
    /// (created 0700, never a link or another user's) and no file of this
    /// robot's global management segment may belong to someone else. After:
    /// that segment, which iceoryx2 creates readable and writable by all
    /// (0666), is made 0600 (review R3, F6).
    pub fn node(&self, name: &str) -> Result<Node<Ipc>, WorldError> {
        quiet_iceoryx2();
        let node_name: NodeName =
            name.try_into().map_err(|e| WorldError::Node { name: name.into(), source: Box::new(e) })?;
        self.secure_iox2_root()?;
        let mgmt = self.global_mgmt_files();
        check_own_files(&mgmt)?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&self.config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Ipc>()
            .map_err(|e| WorldError::Node { name: name.into(), source: Box::new(e) })?;
        let mgmt = if mgmt.is_empty() { self.global_mgmt_files() } else { mgmt };
        make_private(&mgmt);
        Ok(node)
    }

    /// Makes the iceoryx2 root a private directory of this user, or says why it is not one.
    pub fn secure_iox2_root(&self) -> Result<(), WorldError> {
        // without the trailing `/`, which would follow a link to a directory
        let root: PathBuf = self.iox_root.components().collect();
        secure_dir(&root)
            .map_err(|detail| WorldError::UnsafeIox2Root { path: self.iox_root.display().to_string(), detail })
    }

    /// This robot's iceoryx2 global management segment in `/dev/shm` (a
    /// node counter, one file per iceoryx2 version).
    ///
    /// The file iceoryx2 opens is looked at first, by its name: every
    /// command makes a node, and listing `/dev/shm` to find it took about
    /// 1 ms beside a 100-agent robot (1900 files). Where it is not there
    /// (no node of the robot yet, or an iceoryx2 whose name differs) the
    /// folder is listed as before.
    fn global_mgmt_files(&self) -> Vec<PathBuf> {
        let expected = PathBuf::from(format!("/dev/shm/{}{GLOBAL_MGMT_TAIL}", self.robot.shm_prefix()));
        if std::fs::symlink_metadata(&expected).is_ok() {
            return vec![expected];
        }
        self.shm_files().into_iter().filter(|f| f.to_string_lossy().ends_with(".global_mgmt")).collect()
    }

    /// Removes what a command leaves of a robot nobody runs: iceoryx2's
    /// global management segment (created by the first node of a robot,
    /// never removed by iceoryx2) and empty node folders of this user's
    /// root, when no node of the robot is alive. A `nerve ps` on a robot
    /// with no router, or with a mistyped name, thus leaves nothing behind
    /// (review F7). Returns how many files and folders were removed.
    pub fn forget_if_unused(&self) -> usize {
        // the quick answer first: a live daemon router keeps the robot in use.
        // Listing the nodes reads the folder every robot of the user shares
        // (12 ms of a 17 ms `nerve param get` beside a 100-agent robot)
        let router_runs =
            crate::daemon::read_pid(&self.pid_file("router")).is_some_and(crate::daemon::nerve_process_alive);
        if router_runs || self.has_live_node() {
            return 0;
        }
        let mut removed = 0;
        for f in self.global_mgmt_files() {
            if std::fs::remove_file(f).is_ok() {
                removed += 1;
            }
        }
        removed + self.remove_empty_node_dirs()
    }

    /// Removes empty node folders (`<root>/nodes/<id>/`) older than a few
    /// seconds: iceoryx2 removes a dead node's files but may leave its
    /// folder. A folder just made by a node being created is left alone.
    pub fn remove_empty_node_dirs(&self) -> usize {
        let Ok(rd) = std::fs::read_dir(self.iox_root.join("nodes")) else { return 0 };
        let young = std::time::Duration::from_secs(5);
        let mut removed = 0;
        for e in rd.filter_map(|e| e.ok()) {
            let old = e.metadata().ok().and_then(|m| m.modified().ok()).and_then(|t| t.elapsed().ok());
            if e.file_type().is_ok_and(|t| t.is_dir()) && old.is_some_and(|age| age > young) {
                // fails, as it should, on a folder that is not empty
                if std::fs::remove_dir(e.path()).is_ok() {
                    removed += 1;
                }
            }
        }
        removed
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

    /// The iceoryx2 root path (this user's; shared by the user's robots, whose files carry their prefix).
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
        cleanup_dead_nodes_of(&self.config)
    }

    /// Whether any iceoryx2 node of this world is alive: the listing stops
    /// at the first one, where [`World::live_node_pids`] reads every node's
    /// record (with 100 agents that was most of a `nerve ps`: each command
    /// asks this as it exits).
    pub fn has_live_node(&self) -> bool {
        let mut alive = false;
        let _ = Node::<Ipc>::list(&self.config, |state| {
            if let NodeState::Alive(_) = state {
                alive = true;
                return CallbackProgression::Stop;
            }
            CallbackProgression::Continue
        });
        alive
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

/// Refuses files another user owns.
fn check_own_files(files: &[PathBuf]) -> Result<(), WorldError> {
    use std::os::unix::fs::MetadataExt;
    let me = shm_schemas::names::effective_uid();
    for f in files {
        if let Ok(m) = std::fs::symlink_metadata(f)
            && m.uid() != me
        {
            return Err(WorldError::ForeignFile { path: f.display().to_string(), owner: m.uid(), me });
        }
    }
    Ok(())
}

/// Makes files of ours readable and writable by us only.
fn make_private(files: &[PathBuf]) {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    for f in files {
        if let Ok(m) = std::fs::symlink_metadata(f)
            && m.file_type().is_file()
            && m.mode() & 0o077 != 0
        {
            let _ = std::fs::set_permissions(f, std::fs::Permissions::from_mode(0o600));
        }
    }
}

/// The environment variable that turns iceoryx2's scan of a service's
/// nodes on every open back on (`on`); see [`World::new`].
pub const CLEANUP_ON_OPEN_ENV: &str = "NERVE_IOX2_CLEANUP_ON_OPEN";

/// `NERVE_IOX2_EXPIRED_CONNECTIONS=N` sets the room every port keeps for
/// the connections of peers that left (iceoryx2's default is 128), to
/// measure it; see [`World::new`].
pub const EXPIRED_CONNECTIONS_ENV: &str = "NERVE_IOX2_EXPIRED_CONNECTIONS";

/// The room for expired connections: [`EXPIRED_CONNECTIONS_ENV`], else 8.
fn expired_connection_buffer() -> usize {
    std::env::var(EXPIRED_CONNECTIONS_ENV).ok().and_then(|v| v.parse().ok()).filter(|n| *n >= 1).unwrap_or(8)
}

/// Removes the resources of every dead node under iceoryx2 configuration
/// `config` (a robot's: [`World::config`], or a node's own); returns how
/// many were cleaned. It reads every node's record: call it when something
/// failed that a dead process's ports could explain, not on every open.
pub fn cleanup_dead_nodes_of(config: &iceoryx2::config::Config) -> usize {
    cleanup_dead_nodes_counted(config).removed
}

/// What one look for dead nodes did.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
struct Cleaned {
    /// dead nodes whose resources this look removed
    removed: usize,
    /// dead nodes another process was cleaning up at the time
    by_another: usize,
}

fn cleanup_dead_nodes_counted(config: &iceoryx2::config::Config) -> Cleaned {
    quiet_iceoryx2();
    // One clean-up at a time in this process: a thread that finds a dead
    // node another thread is still cleaning skips it, and would try again
    // what that node blocks before it is gone (an agent's start-up opens
    // the router's client, which cleans up after a killed router, beside
    // its control service, which cleans up after a killed run of itself).
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut dead = Vec::new();
    let _ = Node::<Ipc>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    });
    let mut c = Cleaned::default();
    for view in dead {
        match view.try_remove_stale_resources() {
            Ok(()) => c.removed += 1,
            Err(iceoryx2::node::NodeCleanupFailure::AnotherInstanceIsCleaningUpTheNode) => c.by_another += 1,
            Err(_) => {}
        }
    }
    c
}

/// How long [`retry_after_cleanup_while`] waits, in turn, for a process
/// that is cleaning up a dead node, or for one that is exiting (under a
/// second in all, and only while either is seen).
const WAITS_FOR_LEAVERS: [std::time::Duration; 7] = [
    std::time::Duration::from_millis(5),
    std::time::Duration::from_millis(10),
    std::time::Duration::from_millis(20),
    std::time::Duration::from_millis(50),
    std::time::Duration::from_millis(100),
    std::time::Duration::from_millis(200),
    std::time::Duration::from_millis(400),
];

/// Runs `attempt`; if it fails in a way `blockable` says a dead process's
/// leftovers could explain, cleans such leftovers under `config` and runs it
/// once more (also when this call found nothing left to clean: another
/// thread or process may have cleaned them between the failure and the
/// look). While another process is still cleaning a dead node up (a killed
/// router's, which every agent looking for the router cleans up after too),
/// it waits for it a little and tries again. For creating a port or server
/// that a crashed process's ports may block (iceoryx2 no longer scans a
/// service's nodes on every open, see [`World::new`]); `what` names it in
/// the log line.
pub fn retry_after_cleanup<T, E>(
    config: &iceoryx2::config::Config,
    what: &str,
    blockable: impl Fn(&E) -> bool,
    attempt: impl FnMut() -> Result<T, E>,
) -> Result<T, E> {
    retry_after_cleanup_while(config, what, blockable, || false, attempt)
}

/// [`retry_after_cleanup`], waiting also while `holder_exiting` says that
/// what blocks the attempt belongs to a process that is exiting
/// ([`crate::control::served_only_by_the_gone`]): killed, but not yet
/// gone, so that its iceoryx2 node still counts as alive. Servers are made
/// through [`crate::control::ControlServer::create_clearing`].
pub(crate) fn retry_after_cleanup_while<T, E>(
    config: &iceoryx2::config::Config,
    what: &str,
    blockable: impl Fn(&E) -> bool,
    holder_exiting: impl Fn() -> bool,
    mut attempt: impl FnMut() -> Result<T, E>,
) -> Result<T, E> {
    match attempt() {
        Err(e) if blockable(&e) => {}
        done => return done,
    }
    let mut waits = WAITS_FOR_LEAVERS.iter();
    loop {
        let cleaned = cleanup_dead_nodes_counted(config);
        if cleaned.removed > 0 {
            let n = cleaned.removed;
            tracing::info!(cleaned = n, "{what}: cleaned the shared memory of {n} dead process(es), trying again");
        } else {
            // another thread of this process (an agent's start-up opens
            // the router's client beside its control service) or another
            // process may have cleaned the same leftovers a moment ago
            tracing::debug!("{what}: nothing left to clean, trying again");
        }
        let done = attempt();
        let blocked = matches!(&done, Err(e) if blockable(e));
        let why = if !blocked {
            None
        } else if cleaned.by_another > 0 {
            Some("another process is cleaning up after a dead one")
        } else if holder_exiting() {
            Some("what blocks it belongs to a process that is exiting")
        } else {
            None
        };
        match (why, waits.next()) {
            (Some(why), Some(wait)) => {
                tracing::info!("{what}: {why}; waiting {wait:?}");
                std::thread::sleep(*wait);
            }
            _ => return done,
        }
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

    /// A world of a throw-away robot whose iceoryx2 root is `root`.
    fn world_at(tag: &str, root: &StdPath) -> World {
        let mut w = World::new(&format!("w{}-{tag}", std::process::id())).expect("world");
        let root = format!("{}/", root.display());
        let path = Path::new(root.as_bytes()).expect("root path");
        w.config.global.set_root_path(&path);
        w.iox_root = PathBuf::from(root);
        w
    }

    #[test]
    fn the_iceoryx2_root_is_private_and_the_management_file_ours_alone() {
        let base = std::env::temp_dir().join(format!("nerve-iox2-root-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        std::fs::create_dir_all(&base).expect("base");
        // a fresh root is made 0700 (iceoryx2 makes its own 0750 or 0755)
        let w = world_at("fresh", &base.join("root"));
        let _clean = test_support::Cleanup(w.clone());
        let node = w.node("probe").expect("node in a fresh root");
        assert_eq!(std::fs::metadata(w.iox2_root()).map(|m| m.mode() & 0o777).ok(), Some(0o700));
        // iceoryx2 makes its global management file 0666 (review F6): ours is 0600
        let mgmt = w.global_mgmt_files();
        assert_eq!(mgmt.len(), 1, "{mgmt:?}");
        // the file is where nerve looks first (GLOBAL_MGMT_TAIL), as a listing finds it
        let listed: Vec<PathBuf> =
            w.shm_files().into_iter().filter(|f| f.to_string_lossy().ends_with(".global_mgmt")).collect();
        assert_eq!(listed, mgmt, "iceoryx2 names its management segment otherwise: update GLOBAL_MGMT_TAIL");
        assert_eq!(std::fs::metadata(&mgmt[0]).map(|m| m.mode() & 0o777).ok(), Some(0o600));
        // with the node gone and no other, a command leaves nothing (review F7)
        drop(node);
        assert!(w.forget_if_unused() >= 1);
        assert!(w.global_mgmt_files().is_empty() && w.shm_files().is_empty(), "{:?}", w.shm_files());

        // a root that is a link is refused (review R3: it could lead anywhere)
        let target = base.join("elsewhere");
        std::fs::create_dir_all(&target).expect("target");
        std::os::unix::fs::symlink(&target, base.join("linked")).expect("symlink");
        let linked = world_at("linked", &base.join("linked"));
        let err = linked.node("probe").expect_err("a linked root");
        assert!(err.to_string().contains("symbolic link"), "{err}");

        if nix::unistd::geteuid().is_root() {
            // a root another user made (as one could in /dev/shm) is refused
            let theirs = base.join("theirs");
            std::fs::create_dir_all(&theirs).expect("dir");
            std::os::unix::fs::chown(&theirs, Some(65534), Some(65534)).expect("chown to nobody");
            let err = world_at("theirs", &theirs).node("probe").expect_err("another user's root");
            assert!(err.to_string().contains("uid 65534"), "{err}");
            // and so is a management file with our prefix that another user planted
            let w = world_at("planted", &base.join("root"));
            let _clean = test_support::Cleanup(w.clone());
            let planted = PathBuf::from(format!("/dev/shm/{}planted.global_mgmt", w.robot().shm_prefix()));
            std::fs::write(&planted, [0u8; 16]).expect("plant");
            std::os::unix::fs::chown(&planted, Some(65534), Some(65534)).expect("chown to nobody");
            let err = w.node("probe").expect_err("a planted management file");
            assert!(err.to_string().contains("belongs to uid 65534"), "{err}");
            let _ = std::fs::remove_file(&planted);
        }
        let _ = std::fs::remove_dir_all(&base);
    }

    #[test]
    fn a_root_and_robot_name_too_long_for_a_socket_path_are_refused() {
        // 24-byte robot names fit the default root of any 5-digit uid
        let long = "r".repeat(RobotName::MAX_LEN);
        assert!(
            default_iox2_root().len() + RobotName::shm_prefix_of(99_999, &long).len() + SOCKET_NAME_TAIL
                <= MAX_SOCKET_PATH
                || shm_schemas::names::effective_uid() > 99_999
        );
        assert!(World::new(&long).is_ok());
    }
}
