//! The agent's waker ([`crate::Waker`]) in the real task loops: the task
//! thread of a running agent ([`super::task::task_main`]) on a real
//! iceoryx2 wake-up event and WaitSet, woken by another thread, in the
//! event loop and in polling mode.

use super::task::{SuspendGate, Wakes, task_main};
use super::{Shared, TaskFigures};
use crate::agent::{Agent, AgentError, Context, Setup, Task, Waker};
use crate::world::World;
use iceoryx2::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Generous: a lost wake hangs for ever, a loaded machine takes
/// milliseconds; this only turns a hang into a failure.
const HANG: Duration = Duration::from_secs(20);

/// What the test agent and the test share.
#[derive(Debug, Default)]
struct Seen {
    /// the value the waking thread last left
    data: AtomicU64,
    /// the value the last step woken by the waker read
    acked: AtomicU64,
    /// steps woken by the waker
    by_waker: AtomicU64,
    /// all steps
    steps: AtomicU64,
    stopped: AtomicBool,
}

/// Reads what its waking thread left, in steps the waker woke.
struct Woken(Arc<Seen>);

impl Agent for Woken {
    const KIND: &'static str = "woken";
    fn task() -> Task {
        Task::EventDriven
    }
    fn new(_setup: &mut Setup) -> Result<Self, AgentError> {
        Err(AgentError::Other("made by the test".into()))
    }
    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        self.0.steps.fetch_add(1, Ordering::SeqCst);
        if ctx.woken_by_waker() {
            self.0.by_waker.fetch_add(1, Ordering::SeqCst);
            self.0.acked.store(self.0.data.load(Ordering::SeqCst), Ordering::SeqCst);
        }
        Ok(())
    }
    fn stop(&mut self, _ctx: &mut Context) {
        self.0.stopped.store(true, Ordering::SeqCst);
    }
}

/// A task thread of agent [`Woken`] with a waker, on a robot of its own
/// (removed when dropped).
struct Running {
    seen: Arc<Seen>,
    waker: Waker,
    shared: Arc<Shared>,
    task: Option<std::thread::JoinHandle<()>>,
    world: World,
    _node: Node<crate::world::Ipc>,
}

static N: AtomicU64 = AtomicU64::new(0);

impl Running {
    fn start(polling: bool, suspended: bool) -> Running {
        let robot = format!("wk{}-{}", std::process::id(), N.fetch_add(1, Ordering::Relaxed));
        let world = World::new(&robot).expect("test world");
        let node = world.node("woken").expect("node");
        let factory = node
            .service_builder(&format!("nerve/{robot}/woken/_wake").as_str().try_into().expect("name"))
            .event()
            .open_or_create()
            .expect("wake-up event");
        let listener = factory.listener_builder().create().expect("listener");
        let wake = factory.notifier_builder().create().expect("notifier");
        let polling = polling.then(|| {
            let args = <crate::cli::CommonArgs as clap::Parser>::try_parse_from(["t", "--poll", "--cpus", "0-1"]);
            super::poll::from_args(&args.expect("args")).expect("polling").expect("on")
        });
        let shared = Arc::new(Shared {
            period_ns: AtomicU64::new(0),
            suspended: AtomicBool::new(suspended),
            stop: AtomicBool::new(false),
            generation: AtomicU64::new(0),
            realtime: AtomicBool::new(false),
            cpu_latency: Default::default(),
            figures: Mutex::new(TaskFigures::default()),
            in_step_since_ns: AtomicU64::new(0),
            gate: SuspendGate::default(),
            wake,
            polling,
        });
        let seen = Arc::new(Seen::default());
        let waker = Waker::new().expect("waker");
        let (tx, rx) = std::sync::mpsc::channel();
        let task = {
            let (sh, agent, w) = (shared.clone(), Box::new(Woken(seen.clone())), waker.clone());
            std::thread::spawn(move || {
                let wakes = Wakes { listener, waker: Some(w) };
                task_main(agent, "woken", &sh, &[], wakes, Task::EventDriven, tx)
            })
        };
        rx.recv_timeout(HANG).expect("the task started").expect("its start");
        Running { seen, waker, shared, task: Some(task), world, _node: node }
    }

    /// Waits, bounded, until `cond` holds.
    fn wait_for(&self, what: &str, cond: impl Fn(&Seen) -> bool) {
        let until = Instant::now() + HANG;
        while !cond(&self.seen) {
            assert!(Instant::now() < until, "{what}: not within {HANG:?}: {:?}", self.seen);
            std::thread::yield_now();
        }
    }

    /// Stops the task as the message checker does; true when it ended.
    fn stop(&mut self) -> bool {
        self.shared.request_stop();
        let until = Instant::now() + HANG;
        let Some(task) = self.task.take() else { return true };
        while !task.is_finished() && Instant::now() < until {
            std::thread::sleep(Duration::from_millis(1));
        }
        task.is_finished() && task.join().is_ok()
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        if self.task.is_some() {
            self.stop();
        }
        for f in self.world.shm_files().into_iter().chain(self.world.iox2_files()) {
            let _ = std::fs::remove_file(f);
        }
    }
}

/// Round after round, a thread leaves a value and wakes the task; the next
/// round waits until a step read it. A lost wake would hang a round.
fn rounds(polling: bool) {
    const ROUNDS: u64 = 300;
    let mut r = Running::start(polling, false);
    let (seen, waker) = (r.seen.clone(), r.waker.clone());
    let thread = std::thread::spawn(move || {
        for round in 1..=ROUNDS {
            seen.data.store(round, Ordering::SeqCst);
            waker.wake();
            let until = Instant::now() + HANG;
            while seen.acked.load(Ordering::SeqCst) != round {
                if Instant::now() > until {
                    return Err(round);
                }
                std::thread::yield_now();
            }
        }
        Ok(())
    });
    assert_eq!(thread.join().expect("the waking thread"), Ok(()), "a round's wake was lost");
    assert!(r.stop(), "the task ended when stopped");
    let by_waker = r.seen.by_waker.load(Ordering::SeqCst);
    assert!((ROUNDS..=ROUNDS + 1).contains(&by_waker), "{by_waker} steps by the waker for {ROUNDS} rounds");
    assert_eq!(r.seen.steps.load(Ordering::SeqCst), by_waker, "no step without a wake (it has no input)");
    assert!(r.seen.stopped.load(Ordering::SeqCst), "the agent's stop ran");
}

#[test]
fn a_thread_wakes_the_event_driven_task_and_no_wake_is_lost() {
    rounds(false);
}

#[test]
fn a_thread_wakes_a_polling_task_and_no_wake_is_lost() {
    rounds(true);
}

/// A thousand wakes while the agent is suspended make one step when it resumes.
#[test]
fn wakes_coalesce_into_one_step() {
    let mut r = Running::start(false, true);
    let waker = r.waker.clone();
    std::thread::spawn(move || (0..1000).for_each(|_| waker.wake())).join().expect("the waking thread");
    assert_eq!(r.seen.steps.load(Ordering::SeqCst), 0, "no step while suspended");
    r.shared.suspended.store(false, Ordering::Release);
    r.shared.poke();
    r.wait_for("the step after resuming", |s| s.steps.load(Ordering::SeqCst) >= 1);
    assert!(r.stop(), "the task ended when stopped");
    assert_eq!(r.seen.steps.load(Ordering::SeqCst), 1, "one step for the thousand wakes");
    assert_eq!(r.seen.by_waker.load(Ordering::SeqCst), 1, "and it saw them");
}

/// A thread that keeps waking the task does not keep it from stopping, and
/// may wake on after the task ended.
#[test]
fn the_task_stops_while_a_thread_keeps_waking_it() {
    let mut r = Running::start(false, false);
    let (waker, done) = (r.waker.clone(), Arc::new(AtomicBool::new(false)));
    let thread = {
        let done = done.clone();
        std::thread::spawn(move || {
            let mut n = 0u64;
            // bounded in count as well as by the flag
            while !done.load(Ordering::SeqCst) && n < 50_000_000 {
                waker.wake();
                n += 1;
            }
            n
        })
    };
    r.wait_for("steps by the waker", |s| s.by_waker.load(Ordering::SeqCst) >= 10);
    let stopped = r.stop();
    let steps = r.seen.steps.load(Ordering::SeqCst);
    // the thread wakes on after the task ended: nothing steps, nothing fails
    r.waker.wake();
    done.store(true, Ordering::SeqCst);
    let n = thread.join().expect("the waking thread");
    assert!(stopped, "the task ended while a thread was waking it ({n} wakes)");
    assert!(r.seen.stopped.load(Ordering::SeqCst), "the agent's stop ran");
    assert_eq!(r.seen.steps.load(Ordering::SeqCst), steps, "no step after the stop");
}
