//! Real-time scheduling and locked memory, asked for where the system
//! permits and reported plainly where it does not.
//!
//! Memory locking and `RLIMIT_MEMLOCK`: `mlockall(MCL_FUTURE)` makes every
//! later mapping (rings, iceoryx2 segments) count against the limit, so
//! under a raised but finite limit a mapping made long after the start
//! fails with EAGAIN ("cannot map"). [`lock_memory`] therefore asks for
//! `MCL_FUTURE` only when the limit is infinite or the process holds
//! `CAP_IPC_LOCK` (which lifts it); under a finite limit it locks the pages
//! mapped so far and warns, naming the limit and how to raise it.
//!
//! Locking the pages mapped now also locks the main thread's stack, and a
//! locked stack grows only within what is left of the limit: past it the
//! kernel refuses the growth and the process dies of SIGSEGV, silently.
//! The kernel lets `mlockall(MCL_CURRENT)` succeed whenever everything
//! mapped fits the limit, and an agent maps about 8.0 MiB when it locks, so
//! under the common 8 MiB default a build a few pages smaller locked with
//! nothing left, and died at its first deeper call (CI saw exactly this).
//! [`lock_plan`] therefore locks the pages mapped now only when the limit
//! also holds the main thread's whole stack (`RLIMIT_STACK`), and otherwise
//! locks nothing and says why.

/// How much of the process [`lock_memory`] locks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LockPlan {
    /// Current and future pages (`MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT`).
    CurrentAndFuture,
    /// Only the pages mapped now (`MCL_CURRENT | MCL_ONFAULT`): the limit is
    /// finite, and locking future mappings would make them fail to map once
    /// the limit is reached. Carries the limit in bytes, for the warning.
    CurrentOnly {
        /// `RLIMIT_MEMLOCK`, bytes
        limit: u64,
    },
    /// Nothing: the limit is finite and would not hold what is mapped now
    /// plus the main thread's whole stack, so a locked stack could not grow
    /// (see the module documentation). Carries the numbers for the message.
    Nothing {
        /// `RLIMIT_MEMLOCK`, bytes
        limit: u64,
        /// what is mapped now, bytes
        mapped: u64,
        /// the main thread's stack limit, bytes (None: unlimited)
        stack: Option<u64>,
    },
}

/// Decides how to lock memory from the soft `RLIMIT_MEMLOCK` (`None` for
/// infinity), whether the process holds `CAP_IPC_LOCK`, the bytes it maps
/// now (`VmSize`; `None` when unknown) and the soft `RLIMIT_STACK` (`None`
/// for infinity).
pub fn lock_plan(memlock_limit: Option<u64>, cap_ipc_lock: bool, mapped: Option<u64>, stack: Option<u64>) -> LockPlan {
    let Some(limit) = memlock_limit else { return LockPlan::CurrentAndFuture };
    if cap_ipc_lock {
        return LockPlan::CurrentAndFuture;
    }
    match (mapped, stack) {
        (Some(m), Some(s)) if m.checked_add(s).is_some_and(|need| need <= limit) => LockPlan::CurrentOnly { limit },
        _ => LockPlan::Nothing { limit, mapped: mapped.unwrap_or(0), stack },
    }
}

/// A soft resource limit in bytes, `None` for infinity (or when it cannot be
/// read).
fn soft_limit(resource: nix::sys::resource::Resource) -> Option<u64> {
    match nix::sys::resource::getrlimit(resource) {
        Ok((soft, _)) if soft != nix::sys::resource::RLIM_INFINITY => Some(soft),
        _ => None,
    }
}

/// The process's own `/proc/self/status`, read once per question.
fn self_status() -> Option<String> {
    std::fs::read_to_string("/proc/self/status").ok()
}

/// The bytes the process maps now (`VmSize` of `/proc/self/status`).
fn mapped_bytes(status: &str) -> Option<u64> {
    let kib: u64 =
        status.lines().find_map(|l| l.strip_prefix("VmSize:"))?.trim().strip_suffix("kB")?.trim().parse().ok()?;
    kib.checked_mul(1024)
}

/// Whether the effective capability set holds `CAP_IPC_LOCK` (`false` when
/// the status cannot be read).
fn has_cap_ipc_lock(status: &str) -> bool {
    const CAP_IPC_LOCK: u32 = 14;
    status
        .lines()
        .find_map(|l| l.strip_prefix("CapEff:"))
        .and_then(|hex| u64::from_str_radix(hex.trim(), 16).ok())
        .is_some_and(|caps| caps & (1 << CAP_IPC_LOCK) != 0)
}

/// Bytes as MiB with one decimal, for messages.
fn mib(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / (1u64 << 20) as f64)
}

/// Locks the pages of the process in RAM as they are touched
/// (`MCL_ONFAULT`, so large sparse shared-memory mappings are not faulted
/// in): current and future pages where `RLIMIT_MEMLOCK` is infinite, only
/// current ones (with a warning) where it is finite but large, nothing
/// where it is too small to do so safely; see [`lock_plan`]. The error
/// says what was not locked and why, for the caller to log.
pub fn lock_memory() -> Result<(), String> {
    let status = self_status().unwrap_or_default();
    let plan = lock_plan(
        soft_limit(nix::sys::resource::Resource::RLIMIT_MEMLOCK),
        has_cap_ipc_lock(&status),
        mapped_bytes(&status),
        soft_limit(nix::sys::resource::Resource::RLIMIT_STACK),
    );
    let flags = match plan {
        LockPlan::CurrentAndFuture => libc::MCL_CURRENT | libc::MCL_FUTURE | libc::MCL_ONFAULT,
        LockPlan::CurrentOnly { limit } => {
            tracing::warn!(
                memlock_limit_bytes = limit,
                "RLIMIT_MEMLOCK is finite ({limit} bytes): locking only the memory mapped now, not later \
                 mappings (rings and iceoryx2 segments would fail to map once the limit is reached); \
                 to lock everything, set LimitMEMLOCK=infinity in the systemd unit or run `ulimit -l unlimited` \
                 before starting"
            );
            libc::MCL_CURRENT | libc::MCL_ONFAULT
        }
        LockPlan::Nothing { limit, mapped, stack } => {
            let stack = stack.map_or_else(|| "unlimited".to_owned(), mib);
            return Err(format!(
                "RLIMIT_MEMLOCK ({}) cannot hold the {} mapped now plus the main thread's stack (RLIMIT_STACK {stack}), \
                 and a locked stack that cannot grow crashes the agent; to lock memory, set LimitMEMLOCK=infinity \
                 in the systemd unit or run `ulimit -l unlimited` before starting",
                mib(limit),
                mib(mapped)
            ));
        }
    };
    // SAFETY: mlockall has no memory-safety preconditions.
    let rc = unsafe { libc::mlockall(flags) };
    if rc == 0 { Ok(()) } else { Err(format!("mlockall refused ({})", std::io::Error::last_os_error())) }
}

/// Puts the calling thread under SCHED_FIFO at `priority` (1-99).
pub fn set_thread_fifo(priority: i32) -> Result<(), String> {
    let param = libc::sched_param { sched_priority: priority };
    // SAFETY: pthread_self is always valid; param is a valid sched_param.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc == 0 { Ok(()) } else { Err(std::io::Error::from_raw_os_error(rc).to_string()) }
}

/// Blocks SIGINT and SIGTERM in the calling thread, so that they are
/// delivered to the message checker, which stops the agent cleanly.
pub fn block_termination_signals() {
    use nix::sys::signal::{SigSet, SigmaskHow, Signal, pthread_sigmask};
    let mut set = SigSet::empty();
    set.add(Signal::SIGINT);
    set.add(Signal::SIGTERM);
    let _ = pthread_sigmask(SigmaskHow::SIG_BLOCK, Some(&set), None);
}

/// Makes the calling thread's timed sleeps wake on time (a timer slack of
/// 1 ns). Linux lets the wake-up of a normal-priority thread slip by up to
/// 50 µs so that timers can be batched; SCHED_FIFO threads have no slack,
/// but a task running without real-time privileges would otherwise wake
/// that much late every cycle (measured: a 100 kHz polling agent pair's
/// round trip was 95-100 µs, where event-driven agents take 36-55 µs).
pub fn tight_timer_slack() {
    // SAFETY: PR_SET_TIMERSLACK takes a plain integer argument.
    let _ = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
}

/// Puts the calling thread back under the normal scheduler (SCHED_OTHER).
/// Threads inherit their creator's policy: an agent that starts a library's
/// own thread pool (a network stack, say) from a real-time thread calls
/// this first in a thread of its own, so the pool never competes with the
/// robot's real-time tasks.
pub fn drop_realtime() {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: pthread_self is always valid; param is a valid sched_param.
    let _ = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_OTHER, &param) };
}

/// A set of CPUs an agent is kept on (`--cpus 0,2-3`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CpuList(pub Vec<usize>);

impl std::str::FromStr for CpuList {
    type Err = String;

    /// Numbers and ranges separated by commas: `1`, `0,1`, `0-3,6`.
    fn from_str(s: &str) -> Result<Self, String> {
        const MAX_CPU: usize = 1023;
        let mut cpus = Vec::new();
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let bad = || format!("{s:?}: write CPU numbers and ranges such as 0,2-3");
            let (a, b) = match part.split_once('-') {
                Some((a, b)) => {
                    (a.trim().parse::<usize>().map_err(|_| bad())?, b.trim().parse::<usize>().map_err(|_| bad())?)
                }
                None => {
                    let n = part.parse::<usize>().map_err(|_| bad())?;
                    (n, n)
                }
            };
            if a > b || b > MAX_CPU {
                return Err(bad());
            }
            cpus.extend(a..=b);
        }
        if cpus.is_empty() {
            return Err(format!("{s:?} names no CPU"));
        }
        cpus.sort_unstable();
        cpus.dedup();
        Ok(CpuList(cpus))
    }
}

impl std::fmt::Display for CpuList {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let parts: Vec<String> = self.0.iter().map(usize::to_string).collect();
        f.write_str(&parts.join(","))
    }
}

/// Keeps the calling process's current thread, and every thread it starts
/// afterwards, on `cpus`. Fails when a CPU does not exist or is not allowed
/// (a cgroup's cpuset), naming the CPUs this process may use.
pub fn set_affinity(cpus: &CpuList) -> Result<(), String> {
    // SAFETY: cpu_set_t is plain data; CPU_ZERO/CPU_SET write within it.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    for &c in &cpus.0 {
        if c >= libc::CPU_SETSIZE as usize {
            return Err(format!("CPU {c} is beyond what this system supports"));
        }
        // SAFETY: c < CPU_SETSIZE, checked above.
        unsafe { libc::CPU_SET(c, &mut set) };
    }
    // SAFETY: a valid cpu_set_t of the size given, for the calling thread (0).
    let rc = unsafe { libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) };
    if rc == 0 {
        return Ok(());
    }
    let e = std::io::Error::last_os_error();
    let allowed = allowed_cpus().map_or_else(|| "?".to_owned(), |c| c.to_string());
    Err(format!(
        "cannot keep the agent on CPUs {cpus} ({e}); this process may use CPUs {allowed}: see `nproc` and `taskset -p $$`"
    ))
}

/// The CPUs the calling thread may run on (its affinity mask, which a
/// cgroup's cpuset or `taskset` narrows), or `None` when the kernel does not
/// say. CPU numbers need not be contiguous: a container may get CPUs 2 and 3.
pub fn allowed_cpus() -> Option<CpuList> {
    // SAFETY: cpu_set_t is plain data, filled by the kernel.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    // SAFETY: a valid cpu_set_t of the size given, for the calling thread (0).
    let rc = unsafe { libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) };
    if rc != 0 {
        return None;
    }
    // SAFETY: c < CPU_SETSIZE; CPU_ISSET reads within the set.
    let cpus: Vec<usize> = (0..libc::CPU_SETSIZE as usize).filter(|&c| unsafe { libc::CPU_ISSET(c, &set) }).collect();
    (!cpus.is_empty()).then_some(CpuList(cpus))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_lists_read_as_taskset_writes_them() {
        assert_eq!("1".parse(), Ok(CpuList(vec![1])));
        assert_eq!("0,1".parse(), Ok(CpuList(vec![0, 1])));
        assert_eq!("0-3,6, 2".parse(), Ok(CpuList(vec![0, 1, 2, 3, 6])));
        assert!("3-1".parse::<CpuList>().is_err());
        assert!("x".parse::<CpuList>().is_err());
        assert!("".parse::<CpuList>().is_err());
        assert!("0-5000".parse::<CpuList>().is_err());
        assert_eq!(CpuList(vec![0, 2]).to_string().parse(), Ok(CpuList(vec![0, 2])));
    }

    #[test]
    fn affinity_to_a_missing_cpu_is_refused_with_what_to_do() {
        // CPU 1023 exists on no machine these tests run on; run in a thread
        // so that a surprise success does not pin the test process
        let e = std::thread::spawn(|| set_affinity(&CpuList(vec![1023]))).join().expect("thread");
        let msg = e.expect_err("no machine here has 1024 CPUs");
        assert!(msg.contains("1023") && msg.contains("nproc"), "{msg}");
    }

    #[test]
    fn the_allowed_cpus_are_this_threads_affinity() {
        let all = allowed_cpus().expect("sched_getaffinity answers on Linux");
        assert_eq!(all.0.len(), std::thread::available_parallelism().map_or(0, |n| n.get()));
        let first = CpuList(vec![all.0[0]]);
        let seen = std::thread::spawn(move || {
            set_affinity(&first).expect("one of our own CPUs");
            allowed_cpus()
        })
        .join()
        .expect("thread");
        assert_eq!(seen, Some(CpuList(vec![all.0[0]])));
    }

    #[test]
    fn a_finite_memlock_limit_never_locks_future_mappings() {
        let (mapped, stack) = (Some(8 << 20), Some(8 << 20));
        assert_eq!(lock_plan(None, false, mapped, stack), LockPlan::CurrentAndFuture);
        assert_eq!(lock_plan(None, true, mapped, stack), LockPlan::CurrentAndFuture);
        assert_eq!(lock_plan(Some(64 << 20), false, mapped, stack), LockPlan::CurrentOnly { limit: 64 << 20 });
        // CAP_IPC_LOCK lifts the limit: future mappings cannot hit it.
        assert_eq!(lock_plan(Some(64 << 20), true, mapped, stack), LockPlan::CurrentAndFuture);
    }

    #[test]
    fn a_limit_that_would_leave_the_stack_no_room_locks_nothing() {
        // what CI met: 8 MiB limit, a little under 8 MiB mapped
        let plan = lock_plan(Some(8 << 20), false, Some((8 << 20) - 4096), Some(8 << 20));
        assert!(matches!(plan, LockPlan::Nothing { limit, .. } if limit == 8 << 20), "{plan:?}");
        // the stack must fit whole, not just what it uses now
        assert!(matches!(
            lock_plan(Some(16 << 20), false, Some((8 << 20) + 1), Some(8 << 20)),
            LockPlan::Nothing { .. }
        ));
        assert_eq!(
            lock_plan(Some(16 << 20), false, Some(8 << 20), Some(8 << 20)),
            LockPlan::CurrentOnly { limit: 16 << 20 }
        );
        // an unlimited stack, an unknown size or a limit of 0: nothing
        assert!(matches!(lock_plan(Some(1 << 40), false, Some(8 << 20), None), LockPlan::Nothing { .. }));
        assert!(matches!(lock_plan(Some(1 << 40), false, None, Some(8 << 20)), LockPlan::Nothing { .. }));
        assert!(matches!(lock_plan(Some(0), false, Some(8 << 20), Some(8 << 20)), LockPlan::Nothing { .. }));
        assert!(matches!(
            lock_plan(Some(u64::MAX - 1), false, Some(u64::MAX), Some(8 << 20)),
            LockPlan::Nothing { .. }
        ));
    }

    #[test]
    fn the_status_file_gives_the_mapped_size_and_the_capability() {
        let status = "Name:\tx\nVmSize:\t    8236 kB\nCapEff:\t0000000000004000\n";
        assert_eq!(mapped_bytes(status), Some(8236 * 1024));
        assert!(has_cap_ipc_lock(status));
        assert!(!has_cap_ipc_lock("CapEff:\t0000000000000000\n"));
        assert_eq!(mapped_bytes("Name:\tx\n"), None);
        let own = self_status().expect("/proc/self/status");
        assert!(mapped_bytes(&own).is_some_and(|b| b > 0), "{own}");
    }
}
