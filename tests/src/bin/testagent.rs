//! `testagent`: an agent that misbehaves on purpose, for fault tests (as
//! dora's `tests/fault_tolerance` nodes). Periodic; input `in` and output
//! `value`, both `nerve::Scalar` (a type no example agent uses, for
//! type-mismatch tests).
//!
//! `-- --mode MODE`:
//! * `scalar` (default): sends a counter on `value` each period;
//! * `crash`: aborts on its first step (a crash at once);
//! * `panic`: panics in its first step, in the task's thread (the process
//!   must end all the same, in a build that unwinds too);
//! * `stubborn`: ignores SIGTERM and never finishes a step (must be SIGKILLed);
//! * `hang`: its task blocks for ever in the first step (a hung agent; the
//!   message checker still answers, but the watchdog pings stop);
//! * `burn`: burns CPU in every step (for resource tests);
//! * `fail-start`: its `start` fails (a device that cannot be opened);
//! * `panic-start`: its `start` panics (the process ends during its
//!   start-up, before it is ready, with nothing said but its log);
//! * `segv-start`: dies of SIGSEGV in its `start`, without a word (as a
//!   locked main stack that may not grow did, see `agent_sdk::rt`);
//! * `gone-start`: its `new` fails when the agent really starts, though it
//!   worked when a launch file's check described the agent (a device there
//!   when the file was checked and gone a moment later): the agent exits
//!   before it registers, and the router never hears of it;
//! * `burst`: as `scalar`, but once its output has a keep-all reader
//!   (issue 46) it sends 1,000 samples in one step, as fast as the reader
//!   lets it.

use agent_sdk::{Agent, AgentError, Context, Input, Output, Setup, Task};
use shm_schemas::payloads::Scalar;
use std::time::Duration;

/// Samples a `burst` agent sends at once.
const BURST: u32 = 1000;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Scalar,
    Crash,
    Panic,
    Stubborn,
    Hang,
    Burn,
    FailStart,
    PanicStart,
    SegvStart,
    GoneStart,
    Burst,
}

struct TestAgent {
    mode: Mode,
    input: Input<Scalar>,
    out: Output<Scalar>,
    n: f64,
}

impl Agent for TestAgent {
    const KIND: &'static str = "testagent";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(20))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let mode = match setup.raw_args() {
            [] => Mode::Scalar,
            [flag, m] if flag == "--mode" => match m.as_str() {
                "scalar" => Mode::Scalar,
                "crash" => Mode::Crash,
                "panic" => Mode::Panic,
                "stubborn" => Mode::Stubborn,
                "hang" => Mode::Hang,
                "burn" => Mode::Burn,
                "fail-start" => Mode::FailStart,
                "panic-start" => Mode::PanicStart,
                "segv-start" => Mode::SegvStart,
                // a description's world is a private robot's, `describe-PID`
                "gone-start" if !setup.world().robot().as_str().starts_with("describe-") => {
                    return Err(AgentError::Device("/dev/ttyGONE: it was there when the file was checked".into()));
                }
                "gone-start" => Mode::GoneStart,
                "burst" => Mode::Burst,
                other => {
                    return Err(AgentError::Config(format!(
                        "unknown mode {other:?}; use scalar, crash, panic, stubborn, hang, burn, fail-start, \
                         panic-start, segv-start, gone-start or burst"
                    )));
                }
            },
            other => return Err(AgentError::Config(format!("unexpected arguments {other:?}; use `-- --mode MODE`"))),
        };
        Ok(TestAgent { mode, input: setup.input("in")?, out: setup.output("value")?, n: 0.0 })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        match self.mode {
            Mode::FailStart => return Err(AgentError::Device("cannot open /dev/ttyNOPE: no such device".into())),
            Mode::PanicStart => panic!("testagent: a bug in start-up, on purpose"),
            // the default action, not Rust's stack-overflow handler (which
            // returns from a SIGSEGV it did not cause by a fault)
            // SAFETY: restoring a default disposition and raising a signal
            // have no memory-safety preconditions.
            Mode::SegvStart => unsafe {
                libc::signal(libc::SIGSEGV, libc::SIG_DFL);
                libc::raise(libc::SIGSEGV);
            },
            _ => {}
        }
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        match self.mode {
            Mode::Scalar | Mode::FailStart | Mode::PanicStart | Mode::SegvStart | Mode::GoneStart => {}
            Mode::Burst => {
                if self.out.keep_all_counts().readers > 0 {
                    for _ in 0..BURST {
                        self.n += 1.0;
                        self.out.send(Scalar { value: self.n, stamp_ns: ctx.now_ns() })?;
                    }
                    self.mode = Mode::Scalar;
                }
            }
            Mode::Crash => std::process::abort(),
            Mode::Panic => panic!("testagent: a bug in the step, on purpose"),
            Mode::Stubborn => {
                // SAFETY: setting a signal disposition to SIG_IGN is always sound.
                unsafe { libc::signal(libc::SIGTERM, libc::SIG_IGN) };
                loop {
                    std::thread::sleep(Duration::from_secs(3600));
                }
            }
            Mode::Hang => loop {
                std::thread::sleep(Duration::from_secs(3600));
            },
            Mode::Burn => {
                let until = ctx.now_ns() + 15_000_000;
                let mut x = 0u64;
                while agent_sdk::clock::now_ns() < until {
                    x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
                }
                std::hint::black_box(x);
            }
        }
        while self.input.recv().is_some() {}
        self.n += 1.0;
        self.out.send(Scalar { value: self.n, stamp_ns: ctx.now_ns() })?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<TestAgent>()
}
