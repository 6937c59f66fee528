//! The guard against a real-time task that runs away (reliability review
//! F3c/F3d: a loop of event-driven agents under SCHED_FIFO made a load of
//! 10.6 on two cores, `nerve ps` took 7 s and `nerve down` 25 s).
//!
//! A task under SCHED_FIFO that never blocks — a step that never returns,
//! inputs that never stop (an event storm from outside, a loop that was
//! allowed) — takes its CPU from every normal process, the shell and the
//! router included. The message checker, one priority above the task,
//! measures the task thread's own CPU time (its `pthread_getcpuclockid`
//! clock) at each of its wake-ups. When the task used at least the limit
//! (`--rt-cpu-limit`, 90 % of one CPU by default) over [`WINDOW`], it is
//! **demoted** to SCHED_OTHER with a warning naming the figures: it keeps
//! running, but shares the CPU fairly. After [`CALM`] below half the limit
//! it gets its real-time priority back, with a line saying so. A task that
//! runs away again is demoted again; each demotion is counted.
//!
//! The measure and the decision ([`Guard::observe`]) are plain arithmetic,
//! tested without threads; [`TaskThread`] does the system calls.

use std::time::Duration;

/// How long a task must use the CPU above the limit to be demoted.
pub const WINDOW: Duration = Duration::from_secs(2);
/// How long a demoted task must stay below half the limit to get its
/// real-time priority back.
pub const CALM: Duration = Duration::from_secs(10);
/// Shortest stretch between two samples that is judged (the checker may
/// wake much more often while it serves requests).
const MIN_SAMPLE: Duration = Duration::from_millis(500);

/// What the guard tells the checker to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict {
    /// Nothing.
    Keep,
    /// Demote the task: it used `percent` of a CPU for `over`.
    Demote { percent: f64, over: Duration },
    /// Give the task its real-time priority back: calm for `over`.
    Restore { over: Duration },
}

/// The decision, from samples of the task thread's CPU time.
#[derive(Debug, Clone)]
pub struct Guard {
    /// share of one CPU (0-1) that counts as running away; 0 disables
    limit: f64,
    /// the last sample: (wall ns, task CPU ns)
    last: Option<(u64, u64)>,
    /// since when the task has run above the limit (wall ns), and the CPU then
    hot_since: Option<(u64, u64)>,
    /// since when a demoted task has been calm (wall ns)
    calm_since: Option<u64>,
    demoted: bool,
    demotions: u64,
}

impl Guard {
    /// A guard demoting at `limit_percent` of one CPU (0 never demotes).
    pub fn new(limit_percent: u32) -> Self {
        Guard {
            limit: f64::from(limit_percent.min(100)) / 100.0,
            last: None,
            hot_since: None,
            calm_since: None,
            demoted: false,
            demotions: 0,
        }
    }

    /// How many times the task was demoted.
    pub fn demotions(&self) -> u64 {
        self.demotions
    }

    /// Takes a sample (`now_ns` wall clock, `cpu_ns` the task thread's CPU
    /// time) and says what to do.
    pub fn observe(&mut self, now_ns: u64, cpu_ns: u64) -> Verdict {
        if self.limit <= 0.0 {
            return Verdict::Keep;
        }
        let Some((t0, c0)) = self.last else {
            self.last = Some((now_ns, cpu_ns));
            return Verdict::Keep;
        };
        let dt = now_ns.saturating_sub(t0);
        if dt < MIN_SAMPLE.as_nanos() as u64 {
            return Verdict::Keep;
        }
        self.last = Some((now_ns, cpu_ns));
        let share = cpu_ns.saturating_sub(c0) as f64 / dt as f64;
        if self.demoted {
            if share < self.limit / 2.0 {
                let since = *self.calm_since.get_or_insert(t0);
                let over = Duration::from_nanos(now_ns.saturating_sub(since));
                if over >= CALM {
                    self.demoted = false;
                    self.calm_since = None;
                    return Verdict::Restore { over };
                }
            } else {
                self.calm_since = None;
            }
            return Verdict::Keep;
        }
        if share < self.limit {
            self.hot_since = None;
            return Verdict::Keep;
        }
        let (since, cpu_then) = *self.hot_since.get_or_insert((t0, c0));
        let wall = now_ns.saturating_sub(since);
        if wall < WINDOW.as_nanos() as u64 {
            return Verdict::Keep;
        }
        self.hot_since = None;
        self.demoted = true;
        self.demotions += 1;
        let percent = cpu_ns.saturating_sub(cpu_then) as f64 / wall as f64 * 100.0;
        Verdict::Demote { percent, over: Duration::from_nanos(wall) }
    }
}

/// The task thread, seen from the message checker: its CPU clock, and its
/// scheduling policy to change.
#[derive(Debug, Clone, Copy)]
pub struct TaskThread {
    thread: libc::pthread_t,
    clock: libc::clockid_t,
}

impl TaskThread {
    /// The thread `thread` of this process (a live thread's handle: the
    /// caller keeps the `JoinHandle` until it has stopped using this).
    pub fn new(thread: libc::pthread_t) -> Option<Self> {
        let mut clock: libc::clockid_t = 0;
        // SAFETY: `thread` is a live thread of this process; `clock` is a valid out-pointer.
        let rc = unsafe { libc::pthread_getcpuclockid(thread, &mut clock) };
        (rc == 0).then_some(TaskThread { thread, clock })
    }

    /// The thread's CPU time in nanoseconds.
    pub fn cpu_ns(&self) -> Option<u64> {
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: a valid clock id and out-pointer.
        let rc = unsafe { libc::clock_gettime(self.clock, &mut ts) };
        (rc == 0).then(|| (ts.tv_sec as u64).saturating_mul(1_000_000_000).saturating_add(ts.tv_nsec as u64))
    }

    /// Puts the thread under SCHED_OTHER.
    pub fn demote(&self) -> Result<(), String> {
        self.set(libc::SCHED_OTHER, 0)
    }

    /// Puts the thread back under SCHED_FIFO at `priority`.
    pub fn restore(&self, priority: i32) -> Result<(), String> {
        self.set(libc::SCHED_FIFO, priority)
    }

    fn set(&self, policy: i32, priority: i32) -> Result<(), String> {
        let param = libc::sched_param { sched_priority: priority };
        // SAFETY: a live thread of this process and a valid sched_param.
        let rc = unsafe { libc::pthread_setschedparam(self.thread, policy, &param) };
        if rc == 0 { Ok(()) } else { Err(std::io::Error::from_raw_os_error(rc).to_string()) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: u64 = 1_000_000_000;

    /// Feeds the guard one sample per second at `share` of a CPU for `secs`.
    fn run(g: &mut Guard, t: &mut u64, cpu: &mut u64, share: f64, secs: u64) -> Vec<Verdict> {
        (0..secs)
            .map(|_| {
                *t += S;
                *cpu += (share * S as f64) as u64;
                g.observe(*t, *cpu)
            })
            .filter(|v| *v != Verdict::Keep)
            .collect()
    }

    #[test]
    fn a_task_above_the_limit_for_the_window_is_demoted_and_restored_once_calm() {
        let mut g = Guard::new(90);
        let (mut t, mut cpu) = (0, 0);
        g.observe(t, cpu);
        // a busy but legitimate task (80 %) is left alone
        assert!(run(&mut g, &mut t, &mut cpu, 0.8, 30).is_empty());
        // one hot second is not enough
        assert!(run(&mut g, &mut t, &mut cpu, 0.99, 1).is_empty());
        assert!(run(&mut g, &mut t, &mut cpu, 0.5, 1).is_empty());
        // two are
        let v = run(&mut g, &mut t, &mut cpu, 0.99, 2);
        assert!(matches!(v[..], [Verdict::Demote { percent, over }] if percent > 98.0 && over == WINDOW), "{v:?}");
        assert_eq!(g.demotions(), 1);
        // still hot while demoted: nothing more to do
        assert!(run(&mut g, &mut t, &mut cpu, 1.0, 5).is_empty());
        // calm, but not for long enough; then long enough
        assert!(run(&mut g, &mut t, &mut cpu, 0.1, 9).is_empty());
        assert!(run(&mut g, &mut t, &mut cpu, 0.6, 1).is_empty(), "above half the limit resets the calm");
        let v = run(&mut g, &mut t, &mut cpu, 0.1, 10);
        assert!(matches!(v[..], [Verdict::Restore { over }] if over >= CALM), "{v:?}");
        // a second run-away is a second demotion
        assert!(matches!(run(&mut g, &mut t, &mut cpu, 1.0, 3)[..], [Verdict::Demote { .. }]));
        assert_eq!(g.demotions(), 2);
    }

    #[test]
    fn frequent_wake_ups_are_judged_over_half_a_second_or_more_and_zero_disables() {
        let mut g = Guard::new(90);
        g.observe(0, 0);
        // 100 wake-ups 1 ms apart, fully busy: too short a stretch to judge
        for i in 1..=100 {
            assert_eq!(g.observe(i * S / 1000, i * S / 1000), Verdict::Keep);
        }
        let mut off = Guard::new(0);
        let (mut t, mut cpu) = (0, 0);
        off.observe(0, 0);
        assert!(run(&mut off, &mut t, &mut cpu, 1.0, 60).is_empty());
    }

    #[test]
    fn the_task_threads_cpu_clock_counts_only_that_thread() {
        use std::os::unix::thread::JoinHandleExt;
        fn own_cpu_ns() -> u64 {
            let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
            // SAFETY: clock_gettime writes one timespec through a valid pointer.
            unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
            ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
        }
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
        // spins until it has had 150 ms of CPU (on a loaded machine that
        // takes longer than 150 ms), at most 10 s
        let spinner = std::thread::spawn(move || {
            let t0 = std::time::Instant::now();
            while own_cpu_ns() < 150_000_000 && t0.elapsed() < Duration::from_secs(10) {
                std::hint::black_box(own_cpu_ns());
            }
            let _ = done_tx.send(());
            let _ = rx.recv();
        });
        let task = TaskThread::new(spinner.as_pthread_t()).expect("its clock");
        done_rx.recv_timeout(Duration::from_secs(15)).expect("the spinner ends");
        let cpu = task.cpu_ns().expect("cpu time");
        // this thread only slept: the clock is the spinner's
        assert!(cpu >= 150_000_000, "the spinner used {cpu} ns");
        assert!(own_cpu_ns() < 100_000_000, "this thread waited, it did not spin");
        let _ = tx.send(());
        let _ = spinner.join();
    }
}
