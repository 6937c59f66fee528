//! The test kit shared by nerve's system tests (`tests/`) and its
//! benchmarks (`bench/`): what both need to run real processes and leave
//! nothing behind.
//!
//! * [`Robot`]: an isolated world for one test or one benchmark run, a
//!   unique robot name (so its own iceoryx2 prefix `nerve_<uid>_<robot>_`)
//!   and its own `NERVE_HOME`; dropping it runs `nerve down`, removes its
//!   shared memory and its home (a failed test's home is kept for reading).
//!   The first test robot of a process sweeps what killed test processes
//!   left ([`sweep_dead_test_robots`]).
//! * [`ChildGuard`]: a child process stopped when dropped (SIGTERM, a short
//!   grace, SIGKILL), which also gets SIGTERM should this process die first.
//! * Bounded waits: [`wait_until`], [`wait_file`], [`wait_file_after`];
//!   every one ends after the time it is given.
//! * [`soak`]: a robot from a launch file under churn for minutes, sampled
//!   (the soak system test and `nerve bench soak`).
//! * Processes: [`alive`], [`exists`], [`process_state`], [`sigkill`],
//!   [`reap`], [`shm_files_with_prefix`].

mod child;
mod error;
mod process;
mod robot;
pub mod soak;
mod sweep;
mod wait;

pub use child::{ChildGuard, READY_WITHIN, spawn_dying_with_us};
pub use error::Error;
pub use process::{alive, exists, process_state, reap, shm_files_with_prefix, sigkill};
pub use robot::{Robot, bin_dir, dump_logs, nerve_bin};
pub use sweep::{KEEP_FOR, KEPT_MARKER, Swept, sweep_dead_test_robots};
pub use wait::{wait_file, wait_file_after, wait_until};
