//! The kit's errors: each says what failed, for which process or file, and
//! what to do about it.

use std::path::PathBuf;
use std::time::Duration;

/// What went wrong with a process the kit started or looked for.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A child could not be started.
    #[error("cannot start {name} ({command}): is it built and on the path given?")]
    Spawn {
        /// the child's name, as given to [`crate::ChildGuard::spawn`]
        name: String,
        /// the command line
        command: String,
        /// why the spawn failed
        #[source]
        source: std::io::Error,
    },
    /// A child's state could not be read.
    #[error("cannot wait for {name}")]
    Wait {
        /// the child's name
        name: String,
        /// why waiting failed
        #[source]
        source: std::io::Error,
    },
    /// A child exited while it was expected to run.
    #[error("{name} exited early ({status}); run with --verbose to see its log")]
    ExitedEarly {
        /// the child's name
        name: String,
        /// its exit status
        status: std::process::ExitStatus,
    },
    /// A child's stdout was not piped, so its `ready` line cannot be read.
    #[error("{what}: no stdout to read its `ready` line from (pipe it)")]
    NoStdout {
        /// what was awaited
        what: String,
    },
    /// Reading a child's `ready` line failed.
    #[error("{what}: reading its `ready` line")]
    ReadReady {
        /// what was awaited
        what: String,
        /// why reading failed
        #[source]
        source: std::io::Error,
    },
    /// A child said something else than `ready`.
    #[error("{what} did not become ready (said {said:?})")]
    NotReady {
        /// what was awaited
        what: String,
        /// the line it wrote instead
        said: String,
    },
    /// A child said nothing within the time it had.
    #[error("{what} did not say it was ready within {within:?}; run with --verbose to see its log")]
    ReadyTimeout {
        /// what was awaited
        what: String,
        /// the time it had
        within: Duration,
    },
    /// The `nerve` command is nowhere to be found.
    #[error(
        "cannot find the `nerve` command next to {} or on PATH; build it into the same target dir \
         (`cargo build -p nerve`, or with --release for the benchmarks) or set NERVE_BIN",
        next_to.display()
    )]
    NoNerve {
        /// the executable it was looked for beside
        next_to: PathBuf,
    },
    /// This executable's path is unknown.
    #[error("cannot find this executable's path")]
    CurrentExe(#[source] std::io::Error),
    /// A robot's home could not be made.
    #[error("cannot create the robot's home {}: is the temporary directory writable?", path.display())]
    Home {
        /// the home
        path: PathBuf,
        /// why
        #[source]
        source: std::io::Error,
    },
    /// A `nerve` command of a robot failed.
    #[error("`nerve {args}` of robot {robot} failed ({status}): {stderr}")]
    Nerve {
        /// the robot
        robot: String,
        /// the command's arguments
        args: String,
        /// its exit status
        status: std::process::ExitStatus,
        /// what it said on stderr
        stderr: String,
    },
    /// A command could not be run at all.
    #[error("cannot run {what}: is it built?")]
    Run {
        /// the command
        what: String,
        /// why
        #[source]
        source: std::io::Error,
    },
    /// The soak's launch file is not there.
    #[error("no launch file {}", path.display())]
    LaunchFile {
        /// the file
        path: PathBuf,
        /// why it could not be read
        #[source]
        source: std::io::Error,
    },
    /// The soak's launch file is not in a folder of a repository.
    #[error("{} has no repository folder above its own (its paths are relative to it)", path.display())]
    NoRepository {
        /// the file
        path: PathBuf,
    },
    /// `nerve launch` failed.
    #[error("`nerve launch {}` failed ({status}); run with --verbose to see why", path.display())]
    Launch {
        /// the launch file
        path: PathBuf,
        /// its exit status
        status: std::process::ExitStatus,
    },
    /// The robot's world could not be opened.
    #[error("cannot open the world of robot {robot}")]
    World {
        /// the robot
        robot: String,
        /// why
        #[source]
        source: agent_sdk::world::WorldError,
    },
    /// The router left no pid file.
    #[error("the router of robot {robot} left no pid file: did `nerve launch` start it?")]
    NoRouterPid {
        /// the robot
        robot: String,
    },
    /// A soak too short to say anything.
    #[error("too short a soak to say anything: {samples} sample(s); run it longer")]
    TooShort {
        /// samples taken
        samples: usize,
    },
}
