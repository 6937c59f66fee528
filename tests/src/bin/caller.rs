//! `nerve-caller`: the two sides of a call, for the call tests
//! (`tests/tests/calls.rs`). The request is a `nerve::Tick`, the answer a
//! `nerve::Scalar` whose value is twice the request's `seq`.
//!
//! * `-- --serve`: answers service `plan`, event-driven (woken by requests);
//!   figure `answered`;
//! * default: a periodic (10 ms) client `planner` that keeps one call in
//!   flight (`--timeout-ms MS`, default 300; `--max N` calls in flight,
//!   default 4), and checks every answer; `--burst N` sends N calls in its
//!   first wired step instead, counting those refused. Figures: `steps`,
//!   `sent`, `answered`, `wrong`, `timed_out`, `gone`, `unwired`,
//!   `refused`, `no_server`, `not_wired`, `other`.
//!
//! With `--seq` both sides are of a call answered with a sequence
//! (`Seq<Scalar, Tick>`): the server answers a request of `seq` N with N
//! scalars `0, 1, … N-1` after the request as header, at most `--max-len`
//! (default 1000; longer answers are refused, figure `too_long`); the
//! client asks for lengths that cycle through 0 to 399 and checks each
//! answer whole, counting a refusal
//! as `refused_long`.

use agent_sdk::port::{CallError, CallId, CallOptions, Client, SeqClient, SeqServer, Server};
use agent_sdk::{Agent, AgentError, Context, Setup, Task};
use shm_schemas::payloads::{Scalar, Tick};
use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// The figures, shared with the message checker that reports them.
#[derive(Default)]
struct Counts {
    steps: AtomicU64,
    sent: AtomicU64,
    answered: AtomicU64,
    wrong: AtomicU64,
    timed_out: AtomicU64,
    gone: AtomicU64,
    unwired: AtomicU64,
    refused: AtomicU64,
    no_server: AtomicU64,
    not_wired: AtomicU64,
    too_long: AtomicU64,
    refused_long: AtomicU64,
    other: AtomicU64,
}

impl Counts {
    fn figures(&self) -> Vec<(String, String)> {
        [
            ("steps", &self.steps),
            ("sent", &self.sent),
            ("answered", &self.answered),
            ("wrong", &self.wrong),
            ("timed_out", &self.timed_out),
            ("gone", &self.gone),
            ("unwired", &self.unwired),
            ("refused", &self.refused),
            ("no_server", &self.no_server),
            ("not_wired", &self.not_wired),
            ("too_long", &self.too_long),
            ("refused_long", &self.refused_long),
            ("other", &self.other),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_owned(), v.load(Ordering::Relaxed).to_string()))
        .collect()
    }

    fn error(&self, e: &CallError) {
        let c = match e {
            CallError::TimedOut { .. } => &self.timed_out,
            CallError::ServerGone { .. } => &self.gone,
            CallError::Unwired { .. } => &self.unwired,
            CallError::TooManyInFlight { .. } => &self.refused,
            CallError::NoServer { .. } => &self.no_server,
            CallError::NotWired { .. } => &self.not_wired,
            CallError::AnswerTooLong { .. } => &self.too_long,
            CallError::RefusedTooLong { .. } => &self.refused_long,
            _ => &self.other,
        };
        c.fetch_add(1, Ordering::Relaxed);
    }
}

enum Role {
    Serve(Server<Tick, Scalar>),
    Call { client: Client<Tick, Scalar>, burst: Option<u64>, asked: HashMap<CallId, u64>, seq: u64 },
    SeqServe(SeqServer<Tick, Scalar, Tick>),
    SeqCall { client: SeqClient<Tick, Scalar, Tick>, asked: HashMap<CallId, u64>, seq: u64 },
}

/// The answer of a sequence server to a request: `seq` scalars after the request.
fn seq_answer(t: &Tick) -> (Tick, Vec<Scalar>) {
    (*t, (0..t.seq).map(|i| Scalar { value: i as f64, stamp_ns: t.stamp_ns }).collect())
}

struct Caller {
    role: Role,
    counts: Arc<Counts>,
}

/// The value of `--flag N` in `args`, if given.
fn flag(args: &[String], flag: &str) -> Result<Option<u64>, AgentError> {
    match args.iter().position(|a| a == flag) {
        None => Ok(None),
        Some(i) => args
            .get(i + 1)
            .and_then(|v| v.parse().ok())
            .map(Some)
            .ok_or_else(|| AgentError::Config(format!("{flag} takes a number"))),
    }
}

impl Agent for Caller {
    const KIND: &'static str = "caller";

    fn task() -> Task {
        // a server is woken by requests; a client steps every period
        if std::env::args().any(|a| a == "--serve") {
            Task::EventDriven
        } else {
            Task::Periodic(Duration::from_millis(10))
        }
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args = setup.raw_args().to_vec();
        let counts = Arc::new(Counts::default());
        let (serve, seq) = (args.iter().any(|a| a == "--serve"), args.iter().any(|a| a == "--seq"));
        let options = CallOptions {
            timeout: Duration::from_millis(flag(&args, "--timeout-ms")?.unwrap_or(300)),
            max_in_flight: flag(&args, "--max")?.unwrap_or(4) as usize,
        };
        let role = if serve && seq {
            Role::SeqServe(setup.serve_seq("plan", flag(&args, "--max-len")?.unwrap_or(1000) as usize)?)
        } else if seq {
            Role::SeqCall { client: setup.client_seq_with("planner", options)?, asked: HashMap::new(), seq: 0 }
        } else if serve {
            Role::Serve(setup.serve("plan")?)
        } else {
            Role::Call {
                client: setup.client_with("planner", options)?,
                burst: flag(&args, "--burst")?,
                asked: HashMap::new(),
                seq: 0,
            }
        };
        let shown = counts.clone();
        setup.figures(move || shown.figures());
        Ok(Caller { role, counts })
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let c = &self.counts;
        c.steps.fetch_add(1, Ordering::Relaxed);
        match &mut self.role {
            Role::Serve(server) => {
                let n = server.serve(|t| Scalar { value: 2.0 * t.seq as f64, stamp_ns: t.stamp_ns })?;
                c.answered.fetch_add(n as u64, Ordering::Relaxed);
            }
            Role::SeqServe(server) => match server.serve(seq_answer) {
                Ok(n) => {
                    c.answered.fetch_add(n as u64, Ordering::Relaxed);
                }
                // the others were answered; the client was told
                Err(e) => {
                    eprintln!("{e}");
                    c.error(&e);
                }
            },
            Role::SeqCall { client, asked, seq } => {
                while let Some((id, result)) = client.take() {
                    let want = asked.remove(&id);
                    match result {
                        Ok((header, items)) if want == Some(header.seq) && items == seq_answer(&header).1 => {
                            c.answered.fetch_add(1, Ordering::Relaxed);
                        }
                        Ok(_) => {
                            c.wrong.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(e) => {
                            eprintln!("{id}: {e}");
                            c.error(&e);
                        }
                    }
                }
                if client.in_flight() == 0 {
                    let len = (*seq * 37) % 400;
                    *seq += 1;
                    match client.call(&Tick { seq: len, stamp_ns: ctx.now_ns() }) {
                        Ok(id) => {
                            asked.insert(id, len);
                            c.sent.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(e) => c.error(&e),
                    }
                }
            }
            Role::Call { client, burst, asked, seq } => {
                while let Some((id, result)) = client.take() {
                    let want = asked.remove(&id);
                    match result {
                        Ok(answer) if want.is_some_and(|s| answer.value == 2.0 * s as f64) => {
                            c.answered.fetch_add(1, Ordering::Relaxed);
                        }
                        Ok(_) => {
                            c.wrong.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(e) => {
                            eprintln!("{id}: {e}");
                            c.error(&e);
                        }
                    }
                }
                let n = match burst {
                    Some(n) if client.is_wired() => std::mem::replace(n, 0),
                    Some(_) => 0,
                    None if client.in_flight() == 0 => 1,
                    None => 0,
                };
                for _ in 0..n {
                    *seq += 1;
                    match client.call(&Tick { seq: *seq, stamp_ns: ctx.now_ns() }) {
                        Ok(id) => {
                            asked.insert(id, *seq);
                            c.sent.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(e) => c.error(&e),
                    }
                }
            }
        }
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Caller>()
}
