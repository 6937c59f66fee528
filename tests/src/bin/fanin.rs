//! `fanin`: an event-driven agent with eight inputs `in0`..`in7` of
//! `nerve::Tick`, for the tests of what wakes a task. Each step drains every
//! input and counts, as figures (`nerve param get fanin ...`, `nerve ps`):
//! `steps`; `samples_K` drained from `inK`; `new_K` steps where
//! `Context::has_new("inK")` said so; `woken_by_none` steps that no input
//! woke; `only_0`, `only_1` steps woken by that input alone; and `overlap`
//! steps that began while another ran (never, if the task is never
//! re-entered).

use agent_sdk::{Agent, AgentError, Context, Input, Setup, Task};
use shm_schemas::payloads::Tick;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

const INPUTS: usize = 8;

#[derive(Default)]
struct Counts {
    steps: AtomicU64,
    samples: [AtomicU64; INPUTS],
    new: [AtomicU64; INPUTS],
    woken_by_none: AtomicU64,
    only: [AtomicU64; 2],
    overlap: AtomicU64,
    in_step: AtomicBool,
}

struct FanIn {
    inputs: Vec<Input<Tick>>,
    counts: Arc<Counts>,
}

impl Agent for FanIn {
    const KIND: &'static str = "fanin";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let inputs = (0..INPUTS).map(|k| setup.input(&format!("in{k}"))).collect::<Result<Vec<_>, _>>()?;
        let counts = Arc::new(Counts::default());
        let c = counts.clone();
        setup.figures(move || {
            let get = |a: &AtomicU64| a.load(Ordering::Relaxed).to_string();
            let mut f = vec![
                ("steps".to_owned(), get(&c.steps)),
                ("woken_by_none".to_owned(), get(&c.woken_by_none)),
                ("only_0".to_owned(), get(&c.only[0])),
                ("only_1".to_owned(), get(&c.only[1])),
                ("overlap".to_owned(), get(&c.overlap)),
            ];
            for k in 0..INPUTS {
                f.push((format!("samples_{k}"), get(&c.samples[k])));
                f.push((format!("new_{k}"), get(&c.new[k])));
            }
            f
        });
        Ok(FanIn { inputs, counts })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let c = &self.counts;
        if c.in_step.swap(true, Ordering::AcqRel) {
            c.overlap.fetch_add(1, Ordering::Relaxed);
        }
        c.steps.fetch_add(1, Ordering::Relaxed);
        let woken: Vec<bool> = (0..INPUTS).map(|k| ctx.has_new(&format!("in{k}"))).collect();
        if ctx.woken_by().next().is_none() {
            c.woken_by_none.fetch_add(1, Ordering::Relaxed);
        }
        for (k, input) in self.inputs.iter().enumerate() {
            if woken[k] {
                c.new[k].fetch_add(1, Ordering::Relaxed);
            }
            let n = input.drain(|_, _| {});
            c.samples[k].fetch_add(n as u64, Ordering::Relaxed);
        }
        let alone = |k: usize| woken[k] && woken.iter().enumerate().all(|(j, w)| j == k || !w);
        for k in 0..2 {
            if alone(k) {
                c.only[k].fetch_add(1, Ordering::Relaxed);
            }
        }
        c.in_step.store(false, Ordering::Release);
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<FanIn>()
}
