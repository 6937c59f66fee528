//! Polling mode (`--poll`, `poll = true` in a launch file; issue 42): the
//! task never sleeps. An event-driven task looks at its inputs' shared
//! memory in a loop and steps as soon as a sample waits; a periodic task
//! spins to its deadlines instead of sleeping to them. A hop then costs what
//! iceoryx2's busy-polling costs (about a microsecond here) instead of the
//! kernel's wake-up (15-20 µs a round trip), at the price of the whole CPU.
//!
//! So it is only allowed with a placement (`--cpus`): the poller takes the
//! CPUs it is placed on and no other. Everything else is unchanged: the
//! message checker's changes (stop, suspend, resume, rewiring, the period)
//! are atomics the loop reads every few hundred turns (tens of µs), and
//! a suspend before every step; a suspended poller waits at the
//! suspend gate without spinning; the runaway guard, which demotes a
//! real-time task that keeps its CPU, leaves a poller alone (keeping its CPU
//! is what it was asked to do). `nerve ps` shows its CPU (about 100 %) and
//! the figure `poll` (the CPUs it polls on).
//!
//! The agent's waker ([`crate::Waker`]) is looked at the same way: its
//! flag, without a system call.
//!
//! Inputs whose port can tell from shared memory that a sample waits
//! ([`crate::ports::DynInput::waiting`]: every data input) are looked at
//! without a system call, and their wake-up events are left as they are: an
//! event already notified costs its notifier nothing more (iceoryx2 sends a
//! wake-up only to a listener that has none pending), so the sender's hop
//! is as cheap as the reader's. Other inputs (a service's requests, a
//! client's answers) are looked at through their listeners (`try_wait`).

use super::Shared;
use super::task::{Stepper, run_step_then, wait_while_suspended};
use crate::agent::{Context, Waker};
use crate::clock::now_ns;
use crate::ports::DynInput;
use crate::world::Ipc;
use iceoryx2::port::listener::Listener;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// Why `--poll` was refused.
#[derive(Debug, thiserror::Error)]
pub enum PollError {
    /// `--poll` without `--cpus`.
    #[error(
        "--poll needs a placement: a polling task takes its CPU whole, so say which one with --cpus (e.g. `--poll --cpus 1`; in a launch file `cpus = [1]` beside `poll = true`), ideally a CPU nothing else runs on"
    )]
    NoPlacement,
}

/// What the runtime keeps of a polling task: the CPUs it polls on, as
/// `nerve ps` shows them.
#[derive(Debug, Clone)]
pub(super) struct Polling {
    cpus: String,
}

/// The polling mode the command line asks for: `None` when it does not,
/// refused when it asks without a placement.
pub(super) fn from_args(args: &crate::cli::CommonArgs) -> Result<Option<Polling>, PollError> {
    match (args.poll, &args.cpus) {
        (false, _) => Ok(None),
        (true, None) => Err(PollError::NoPlacement),
        (true, Some(cpus)) => Ok(Some(Polling { cpus: cpus.to_string() })),
    }
}

/// The agent's figures with the polling task's own (`poll` = its CPUs),
/// for `nerve ps` and `nerve ps --json`.
pub(super) fn with_figure(sh: &Shared, mut figures: Vec<(String, String)>) -> Vec<(String, String)> {
    if let Some(p) = &sh.polling {
        figures.push(("poll".into(), format!("cpus {}", p.cpus)));
        figures.sort();
    }
    figures
}

/// Waits, spinning, until `next` (ns, the task's clock) or until the
/// message checker changes something the periodic loop must see (the
/// caller looks again at once).
pub(super) fn spin_toward_ns(next: u64, sh: &Shared) {
    // a bounded number of turns, then the caller looks at stop, suspend and the period
    for _ in 0..SPINS_BETWEEN_LOOKS {
        if now_ns() >= next || sh.stopping() {
            return;
        }
        std::hint::spin_loop();
    }
}

/// Turns of a poller's spin between looks at its shared state (stop,
/// rewiring; a few tens of µs): a turn looks at the inputs only, and a
/// suspend is looked at before every step.
const SPINS_BETWEEN_LOOKS: u32 = 256;

/// One look at every input: marks in `woken` those with something
/// waiting; whether any has.
fn look(inputs: &[Arc<dyn DynInput>], by_listener: &[(usize, Arc<Listener<Ipc>>)], woken: &mut [bool]) -> bool {
    let mut got_input = false;
    for (k, input) in inputs.iter().enumerate() {
        if input.waiting() == Some(true) {
            woken[k] = true;
            got_input = true;
        }
    }
    for (k, l) in by_listener {
        if l.try_wait(|_| {}).is_ok_and(|n| n > 0) {
            woken[*k] = true;
            got_input = true;
        }
    }
    got_input
}

/// The polling event loop: steps whenever an input has something waiting,
/// never sleeps but while suspended.
pub(super) fn event_loop(
    agent: &mut dyn Stepper,
    sh: &Shared,
    inputs: &[Arc<dyn DynInput>],
    waker: Option<&Waker>,
    ctx: &mut Context,
) {
    let mut generation = u64::MAX;
    // the inputs that cannot tell from shared memory, with their listeners
    let mut by_listener: Vec<(usize, Arc<Listener<Ipc>>)> = Vec::new();
    // the inputs with queues of their own to refill ([`refilled`])
    let mut to_refill: Vec<&Arc<dyn DynInput>> = Vec::new();
    let mut was_suspended = sh.suspended.load(Ordering::Acquire);
    tracing::info!(cpus = sh.polling.as_ref().map(|p| p.cpus.as_str()), "polling the inputs");
    loop {
        if sh.stopping() {
            return;
        }
        let now_generation = sh.generation.load(Ordering::Acquire);
        if now_generation != generation {
            // rewired: the sources (and so the listeners) changed
            generation = now_generation;
            by_listener = inputs
                .iter()
                .enumerate()
                .filter(|(_, i)| i.waiting().is_none())
                .flat_map(|(k, i)| i.listeners().into_iter().map(move |l| (k, l)))
                .collect();
            to_refill = refilled(inputs);
            tracing::debug!(listened = by_listener.len(), "inputs changed: polling the new sources");
        }
        // turns of looks at the inputs and the waker only, until something
        // waits or the shared state is due a look (the hop's path: a turn
        // as short as it can be)
        let mut got_input = false;
        for _ in 0..SPINS_BETWEEN_LOOKS {
            got_input = look(inputs, &by_listener, &mut ctx.woken);
            if got_input || waker.is_some_and(Waker::pending) {
                break;
            }
            std::hint::spin_loop();
        }
        if got_input {
            // deep and keep-all inputs take what waits into their own queues, as in the event loop
            to_refill.iter().for_each(|i| i.refill());
        }
        // the agent's waker: its flag, seen without a system call
        if let Some(w) = waker
            && w.pending()
        {
            ctx.waker |= w.take();
        }
        let suspended = sh.suspended.load(Ordering::Acquire);
        if suspended {
            // held without spinning; what woke it counts for the step after resuming
            was_suspended = true;
            wait_while_suspended(sh);
            continue;
        }
        let resumed = std::mem::replace(&mut was_suspended, false);
        if got_input || ctx.waker || resumed {
            let t = now_ns();
            ctx.now_ns = t;
            run_step_then(agent, sh, ctx, |f| {
                f.cycles += 1;
                f.rate.record(t);
                f.last_cycle_ns = t;
            });
            ctx.woken.fill(false);
            ctx.waker = false;
        }
    }
}

/// The inputs whose port keeps queues of its own (deeper than iceoryx2's
/// buffer, or keeping all), which take what waits into them when the poller
/// finds input. The others' `refill` does nothing, but the look costs a lock
/// and an allocation a step: on the hop's path, beside iceoryx2's sub-µs.
fn refilled(inputs: &[Arc<dyn DynInput>]) -> Vec<&Arc<dyn DynInput>> {
    inputs.iter().filter(|i| i.depth().is_some_and(|d| d.options().holds_copies())).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::CommonArgs;
    use clap::Parser;

    #[test]
    fn poll_without_cpus_is_refused_with_what_to_add() {
        let args = CommonArgs::try_parse_from(["agent", "--poll"]).expect("parses");
        let e = from_args(&args).expect_err("refused");
        assert!(e.to_string().contains("--cpus"), "{e}");
    }

    #[test]
    fn poll_with_cpus_is_taken_and_no_poll_is_none() {
        let args = CommonArgs::try_parse_from(["agent", "--poll", "--cpus", "1"]).expect("parses");
        let p = from_args(&args).expect("taken").expect("polling");
        assert_eq!(p.cpus, "1");
        let args = CommonArgs::try_parse_from(["agent", "--cpus", "1"]).expect("parses");
        assert!(from_args(&args).expect("taken").is_none());
    }
}
