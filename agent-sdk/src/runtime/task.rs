//! The task thread: the agent's `start`, then its periodic loop (absolute
//! deadlines, run-time period, lateness and overruns) or its event loop
//! (a WaitSet of the inputs' listeners and a private wake-up event), each
//! held while the agent is suspended, and the agent's `stop`. On simulated
//! time the deadlines are the simulated clock's, and the simulator's task
//! publishes how far the clock may run ([`crate::simclock`]).

use super::Shared;
use crate::agent::{Agent, AgentError, Context, Task, Waker};
use crate::clock::{now_ns, sleep_toward_ns};
use crate::ports::DynInput;
use crate::world::Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// An agent as the task runs it: its `start`, `step` and `stop` behind one
/// pointer, so that the task loops, and the start-up that drives them, are
/// compiled once in this crate instead of once per agent program. Generic,
/// they were most of each agent's compile time (35 s of CPU for the 70-line
/// ticker at the dev profile, 2026-11-29); a call through the pointer costs
/// a few nanoseconds a step.
pub(crate) trait Stepper: Send {
    /// [`Agent::start`]
    fn start(&mut self, ctx: &mut Context) -> Result<(), AgentError>;
    /// [`Agent::step`]
    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError>;
    /// [`Agent::stop`]
    fn stop(&mut self, ctx: &mut Context);
}

impl<A: Agent> Stepper for A {
    fn start(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        Agent::start(self, ctx)
    }
    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        Agent::step(self, ctx)
    }
    fn stop(&mut self, ctx: &mut Context) {
        Agent::stop(self, ctx);
    }
}

/// What wakes the task besides its inputs: the private wake-up event (the
/// message checker's changes) and the agent's own waker, if it asked for
/// one ([`crate::Setup::waker`]).
pub(super) struct Wakes {
    pub(super) listener: Listener<Ipc>,
    pub(super) waker: Option<Waker>,
}

pub(super) fn task_main(
    mut agent: Box<dyn Stepper>,
    name: &str,
    sh: &Shared,
    inputs: &[Arc<dyn DynInput>],
    Wakes { listener: wake, waker }: Wakes,
    kind: Task,
    started: std::sync::mpsc::Sender<Result<(), AgentError>>,
) {
    let mut ctx = Context {
        name: name.to_owned(),
        cycle: 0,
        now_ns: now_ns(),
        period: None,
        deadline_ns: 0,
        stop: false,
        inputs: inputs.iter().map(|i| i.name().to_owned()).collect(),
        woken: vec![false; inputs.len()],
        waker: false,
    };
    match crate::simclock::check() {
        Ok(None) => {}
        Ok(Some(scale)) => tracing::info!(scale, "on simulated time"),
        Err(e) => {
            tracing::error!("{e}; stopping");
            sh.request_stop();
            let _ = started.send(Err(AgentError::Config(e.to_string())));
            return;
        }
    }
    if let Err(e) = agent.start(&mut ctx) {
        tracing::error!("start failed: {e}; stopping");
        sh.request_stop();
        let _ = started.send(Err(e));
        return;
    }
    let _ = started.send(Ok(()));
    match kind {
        Task::Periodic(_) => periodic_loop(agent.as_mut(), sh, waker.as_ref(), &mut ctx),
        Task::EventDriven if sh.polling.is_some() => {
            super::poll::event_loop(agent.as_mut(), sh, inputs, waker.as_ref(), &mut ctx)
        }
        Task::EventDriven => event_loop(agent.as_mut(), sh, inputs, &wake, waker.as_ref(), &mut ctx),
    }
    agent.stop(&mut ctx);
}

pub(super) fn run_step(agent: &mut dyn Stepper, sh: &Shared, ctx: &mut Context) {
    run_step_then(agent, sh, ctx, |_| {});
}

/// [`run_step`], then `after` on the task's figures under the lock that
/// ends the step (a polling task's bookkeeping: one lock a step less). The
/// step's start takes no lock: the hop's path runs through it. Samples the
/// step takes are counted at its start ([`super::step_clock`]): when the
/// task found them, one clock read a step instead of one a sample.
pub(super) fn run_step_then(
    agent: &mut dyn Stepper,
    sh: &Shared,
    ctx: &mut Context,
    after: impl FnOnce(&mut super::TaskFigures),
) {
    sh.in_step_since_ns.store(ctx.now_ns.max(1), Ordering::Release);
    let result = super::step_clock::during_step(ctx.now_ns, || agent.step(ctx));
    sh.in_step_since_ns.store(0, Ordering::Release);
    {
        let mut f = sh.figures();
        after(&mut f);
        if let Err(e) = result {
            f.errors += 1;
            if f.errors.is_power_of_two() {
                tracing::warn!("step failed ({} failures so far): {e}", f.errors);
            }
        }
    }
    ctx.cycle += 1;
    if ctx.stop {
        sh.request_stop();
    }
}

pub(super) fn wait_while_suspended(sh: &Shared) {
    sh.gate.wait_while(|| sh.suspended.load(Ordering::Acquire) && !sh.stopping());
}

/// Where a suspended periodic task waits, without polling, until the
/// message checker resumes or stops it.
#[derive(Debug, Default)]
pub(super) struct SuspendGate {
    lock: Mutex<()>,
    changed: Condvar,
}

impl SuspendGate {
    /// Blocks while `held()` is true; looks again only when [`SuspendGate::notify`] is called.
    pub(super) fn wait_while(&self, held: impl Fn() -> bool) {
        let mut g = self.lock.lock().unwrap_or_else(|p| p.into_inner());
        while held() {
            g = self.changed.wait(g).unwrap_or_else(|p| p.into_inner());
        }
    }

    /// Wakes the waiters to look at their condition again; call after
    /// changing it. Taking the lock first orders the change before a
    /// waiter's next look, or after its wait began: no wake-up is lost, so
    /// the waiter needs no timeout.
    pub(super) fn notify(&self) {
        drop(self.lock.lock().unwrap_or_else(|p| p.into_inner()));
        self.changed.notify_all();
    }
}

/// Longest single sleep, so that stop and suspend are seen promptly even with long periods.
const SLEEP_CHUNK_NS: u64 = 50_000_000;

fn periodic_loop(agent: &mut dyn Stepper, sh: &Shared, waker: Option<&Waker>, ctx: &mut Context) {
    let mut period = sh.period_ns.load(Ordering::Acquire).max(1);
    let mut last = now_ns();
    let mut next = last.saturating_add(period);
    loop {
        // sleep to the absolute deadline, in chunks, watching stop, suspend
        // and a new period (which counts from the last cycle, at once: a
        // long period in force does not delay a shorter one)
        loop {
            if sh.stopping() {
                return;
            }
            if sh.suspended.load(Ordering::Acquire) {
                break;
            }
            let new_period = sh.period_ns.load(Ordering::Acquire).max(1);
            if new_period != period {
                period = new_period;
                next = last.saturating_add(period);
                sh.figures().lateness.reset();
            }
            let now = now_ns();
            if now >= next {
                break;
            }
            if sh.polling.is_some() {
                super::poll::spin_toward_ns(next, sh);
                continue;
            }
            // at most a chunk of wall time: also when a simulator holds the robot's clock
            sleep_toward_ns(next, now, SLEEP_CHUNK_NS);
        }
        if sh.suspended.load(Ordering::Acquire) {
            wait_while_suspended(sh);
            if sh.stopping() {
                return;
            }
            period = sh.period_ns.load(Ordering::Acquire).max(1);
            last = now_ns();
            next = last.saturating_add(period);
            continue;
        }
        let woke = now_ns();
        last = woke;
        ctx.now_ns = woke;
        ctx.period = Some(Duration::from_nanos(period));
        ctx.deadline_ns = next.max(1);
        if crate::simclock::is_owner() {
            // the simulator's step to `next + period` begins: the robot's clock may run to its end
            if let Some(c) = crate::simclock::active() {
                c.publish_horizon(next.saturating_add(period));
            }
        }
        // not woken early by its waker: the step only hears of the wakes
        ctx.waker = waker.is_some_and(|w| w.pending() && w.take());
        run_step(agent, sh, ctx);
        let done = now_ns();
        {
            let mut f = sh.figures();
            f.cycles += 1;
            f.rate.record(woke);
            f.lateness.record(woke.saturating_sub(next));
            f.last_cycle_ns = woke;
        }
        let new_period = sh.period_ns.load(Ordering::Acquire).max(1);
        if new_period != period {
            period = new_period;
            next = woke.saturating_add(period);
            sh.figures().lateness.reset();
            continue;
        }
        next = next.saturating_add(period);
        if done > next {
            // the work ran past the next deadline: count it and skip the missed deadlines
            sh.figures().overruns += 1;
            let missed = (done - next) / period + 1;
            next = next.saturating_add(missed.saturating_mul(period));
        }
    }
}

fn drain_listener(l: &Listener<Ipc>) {
    let _ = l.try_wait(|_| {});
}

fn event_loop(
    agent: &mut dyn Stepper,
    sh: &Shared,
    inputs: &[Arc<dyn DynInput>],
    wake: &Listener<Ipc>,
    waker: Option<&Waker>,
    ctx: &mut Context,
) {
    let waker_fd = waker.map(Waker::listener);
    loop {
        if sh.stopping() {
            return;
        }
        let generation = sh.generation.load(Ordering::Acquire);
        // every listener with the position of its input, for Context::woken_by
        let listeners: Vec<(usize, Arc<Listener<Ipc>>)> =
            inputs.iter().enumerate().flat_map(|(k, i)| i.listeners().into_iter().map(move |l| (k, l))).collect();
        let ws = match WaitSetBuilder::new().signal_handling_mode(SignalHandlingMode::Disabled).create::<Ipc>() {
            Ok(ws) => ws,
            Err(e) => {
                tracing::error!("cannot create the task's WaitSet: {e:?}; stopping");
                sh.request_stop();
                return;
            }
        };
        let Ok(wake_guard) = ws.attach_notification(wake) else {
            tracing::error!("cannot attach the wake-up event; stopping");
            sh.request_stop();
            return;
        };
        let waker_guard = match waker_fd.as_ref().map(|fd| ws.attach_notification(fd)) {
            None => None,
            Some(Ok(g)) => Some(g),
            Some(Err(e)) => {
                tracing::error!("cannot attach the agent's waker to the task's WaitSet: {e:?}; stopping");
                sh.request_stop();
                return;
            }
        };
        let guards: Vec<_> =
            listeners.iter().filter_map(|(k, l)| ws.attach_notification(l.as_ref()).ok().map(|g| (g, *k, l))).collect();
        let mut was_suspended = sh.suspended.load(Ordering::Acquire);
        loop {
            let mut got_input = false;
            let mut got_wake = false;
            let result = ws.wait_and_process_once(|id| {
                if id.has_event_from(&wake_guard) {
                    drain_listener(wake);
                }
                if waker_guard.as_ref().is_some_and(|g| id.has_event_from(g)) {
                    got_wake = true;
                }
                for (g, k, l) in &guards {
                    if id.has_event_from(g) {
                        drain_listener(l);
                        // kept while suspended: they count for the step after resuming
                        ctx.woken[*k] = true;
                        got_input = true;
                    }
                }
                CallbackProgression::Continue
            });
            if let Err(e) = result {
                tracing::warn!("task wait failed: {e:?}");
                std::thread::sleep(Duration::from_millis(10));
            }
            if got_input {
                // deep and keep-all inputs take what waits into their own queues (port::depth)
                inputs.iter().for_each(|i| i.refill());
            }
            if got_wake && let Some(w) = waker {
                // kept while suspended, as the inputs' wake-ups are; a wake
                // whose eventfd write came after an earlier take finds
                // nothing new (no step for it)
                ctx.waker |= w.take();
            }
            if sh.stopping() {
                return;
            }
            let suspended = sh.suspended.load(Ordering::Acquire);
            let resumed = was_suspended && !suspended;
            was_suspended = suspended;
            if !suspended && (got_input || ctx.waker || resumed) {
                let t = now_ns();
                ctx.now_ns = t;
                run_step(agent, sh, ctx);
                ctx.woken.fill(false);
                ctx.waker = false;
                let mut f = sh.figures();
                f.cycles += 1;
                f.rate.record(t);
                f.last_cycle_ns = t;
            }
            if sh.generation.load(Ordering::Acquire) != generation {
                tracing::debug!("inputs changed: rebuilding the task's WaitSet");
                break; // inputs changed: rebuild the WaitSet
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicBool;
    use std::sync::mpsc;

    /// Generous: a lost wake-up hangs for ever, a slow machine takes
    /// milliseconds; this only turns a hang into a failure.
    const HANG: Duration = Duration::from_secs(20);

    #[test]
    fn the_gate_lets_the_task_go_when_resumed() {
        let gate = Arc::new(SuspendGate::default());
        let held = Arc::new(AtomicBool::new(true));
        let (tx, rx) = mpsc::channel();
        let (g, h) = (gate.clone(), held.clone());
        let waiter = std::thread::spawn(move || {
            g.wait_while(|| h.load(Ordering::Acquire));
            tx.send(()).unwrap();
        });
        std::thread::sleep(Duration::from_millis(20));
        assert!(rx.try_recv().is_err(), "the gate must hold while suspended");
        held.store(false, Ordering::Release);
        gate.notify();
        rx.recv_timeout(HANG).expect("the task was not let go");
        waiter.join().unwrap();
    }

    #[test]
    fn the_gate_loses_no_wake_up_racing_the_resume() {
        for _ in 0..500 {
            let gate = SuspendGate::default();
            let held = AtomicBool::new(true);
            let (tx, rx) = mpsc::channel();
            std::thread::scope(|s| {
                s.spawn(|| {
                    gate.wait_while(|| held.load(Ordering::Acquire));
                    tx.send(()).unwrap();
                });
                // resume at once, racing the waiter's first look
                held.store(false, Ordering::Release);
                gate.notify();
                rx.recv_timeout(HANG).expect("a wake-up was lost");
            });
        }
    }

    #[test]
    fn an_open_gate_does_not_block() {
        SuspendGate::default().wait_while(|| false);
    }
}
