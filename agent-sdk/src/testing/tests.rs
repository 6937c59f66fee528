//! The harness's own tests: the clock of periodic agents, the inputs that
//! wake an event-driven one, a full input, wrong ports and types, and the
//! harness's private robot.

use super::*;
use crate::{Input, Output, Param};
use shm_schemas::payloads::{Scalar, Tick};

/// Counts its cycles and sends the clock and the period it saw.
struct Clocked {
    out: Output<Tick>,
    last: Option<u64>,
}

impl Agent for Clocked {
    const KIND: &'static str = "clocked";
    fn task() -> Task {
        Task::Periodic(Duration::from_millis(100))
    }
    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        Ok(Clocked { out: setup.output("out")?, last: None })
    }
    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        assert_eq!(ctx.deadline_ns(), Some(ctx.now_ns()), "the harness wakes exactly on time");
        if let Some(last) = self.last {
            let period = ctx.period().map_or(0, crate::clock::nanos);
            assert!(ctx.now_ns() - last >= period, "a period or more after the last step");
        }
        self.last = Some(ctx.now_ns());
        self.out.send(Tick { seq: ctx.cycle(), stamp_ns: ctx.now_ns() })?;
        Ok(())
    }
}

/// The measure: a periodic agent driven through 1000 cycles
/// takes no sleep (a 100 ms agent: 100 s of its time). The wall time is
/// printed; the bound only says that nothing slept through the periods.
#[test]
fn a_thousand_periodic_cycles_run_on_the_test_clock_without_sleeping() {
    let mut h = Harness::<Clocked>::new().expect("start");
    let wall = std::time::Instant::now();
    assert_eq!(h.advance(Duration::from_secs(100)).expect("advance"), 1000);
    let took = wall.elapsed();
    eprintln!("1000 cycles of a 100 ms agent in {took:?} of wall time");
    assert!(took < Duration::from_secs(10), "{took:?}: the harness slept");
    assert_eq!(h.cycles(), 1000);
    assert_eq!(h.now_ns(), START_NS + 100_000_000_000);
    let out = h.output_with_meta::<Tick>("out").expect("out");
    assert_eq!(out.len(), 1000);
    assert_eq!((out[0].0.seq, out[999].0.seq), (1, 1000), "the port numbers its samples");
    assert_eq!(out[0].0.stamp_ns, START_NS + 100_000_000, "stamped by the test clock");
    assert_eq!(out[0].0.sender.as_str(), "clocked");
    assert!(h.output::<Tick>("out").expect("out").is_empty(), "taken once");

    // a new period counts from the last step
    h.set_period(Duration::from_millis(20));
    assert_eq!(h.advance(Duration::from_millis(100)).expect("advance"), 5);
    let stamps: Vec<u64> = h.output::<Tick>("out").expect("out").iter().map(|t| t.stamp_ns).collect();
    assert!(stamps.windows(2).all(|w| w[1] - w[0] == 20_000_000), "{stamps:?}");
    assert_eq!(stamps[0], START_NS + 100_020_000_000);
    // suspended, deadlines pass by; resumed, a period counts from now
    h.suspend();
    assert_eq!(h.advance(Duration::from_secs(1)).expect("advance"), 0);
    h.step().expect("nothing runs while suspended");
    assert_eq!(h.cycles(), 1005);
    h.resume().expect("resume");
    assert_eq!(h.advance(Duration::from_millis(19)).expect("advance"), 0);
    assert_eq!(h.advance(Duration::from_millis(1)).expect("advance"), 1);
}

/// Adds its inputs, reports which woke it, and fails on a negative value.
struct Adder {
    a: Input<Scalar>,
    b: Input<Scalar>,
    sum: Output<Scalar>,
    woken: Vec<String>,
    offset: Param<f64>,
    stopped: bool,
}

impl Agent for Adder {
    const KIND: &'static str = "adder";
    fn task() -> Task {
        Task::EventDriven
    }
    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        Ok(Adder {
            a: setup.input("a")?,
            b: setup.input("b")?,
            sum: setup.output("sum")?,
            woken: Vec::new(),
            offset: setup.param_checked("offset", 0.0, |v: &f64| {
                if v.is_finite() { Ok(()) } else { Err("offset is a finite number".into()) }
            }),
            stopped: false,
        })
    }
    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        self.woken = ctx.woken_by().map(str::to_owned).collect();
        let mut total = self.offset.get();
        for input in [&self.a, &self.b] {
            input.try_drain(|_, s| {
                if s.value < 0.0 {
                    return Err(AgentError::Other(format!("negative: {}", s.value)));
                }
                total += s.value;
                Ok(())
            })?;
        }
        self.sum.send(Scalar { value: total, stamp_ns: ctx.now_ns() })?;
        Ok(())
    }
    fn stop(&mut self, _ctx: &mut Context) {
        self.stopped = true;
    }
}

fn scalar(value: f64) -> Scalar {
    Scalar { value, stamp_ns: 0 }
}

#[test]
fn an_event_driven_agent_is_woken_by_the_inputs_that_have_samples() {
    let mut h = Harness::<Adder>::builder().param("offset", "0.5").start().expect("start");
    h.send("a", scalar(1.0)).expect("a");
    h.send("a", scalar(2.0)).expect("a");
    h.step().expect("step");
    assert_eq!(h.agent().woken, ["a"]);
    assert_eq!(h.output::<Scalar>("sum").expect("sum")[0].value, 3.5);
    h.send_from("b", "left", scalar(1.0)).expect("b");
    h.send_from("b", "right", scalar(2.0)).expect("b");
    h.step().expect("step");
    assert_eq!(h.agent().woken, ["b"]);
    assert_eq!(h.output::<Scalar>("sum").expect("sum")[0].value, 3.5);
    let from: Vec<_> = h.input_stats().into_iter().filter(|s| s.input == "b").map(|s| s.from_agent).collect();
    assert_eq!(from, ["left", "right"], "each sender is a source");

    // the agent's error is the step's, and counted
    h.send("a", scalar(-1.0)).expect("a");
    let e = h.step().expect_err("negative");
    assert!(e.to_string().contains("negative"), "{e}");
    assert_eq!(h.errors(), 1);

    // parameters are checked as `nerve param set` checks them
    assert_eq!(h.set_param("offset", "NaN"), Err("offset is a finite number".into()));
    assert!(h.set_param("offsett", "1").is_err());
    h.set_param("offset", "0").expect("offset");
    assert_eq!(h.param("offset").as_deref(), Ok("0"));

    // samples that come while suspended wake the step run at resume
    h.suspend();
    h.send("b", scalar(4.0)).expect("b");
    h.step().expect("nothing runs");
    assert!(h.output::<Scalar>("sum").expect("sum").is_empty());
    h.resume().expect("resume");
    assert_eq!(h.agent().woken, ["b"]);
    assert_eq!(h.output::<Scalar>("sum").expect("sum")[0].value, 4.0);
    assert!(h.stop().stopped, "stop runs the agent's stop");
}

#[test]
fn a_full_input_overwrites_its_oldest_sample_and_counts_it() {
    let mut h = Harness::<Adder>::new().expect("start");
    // as with iceoryx2, the count starts at the first sample received
    h.send("a", scalar(0.0)).expect("a");
    h.step().expect("step");
    for k in 1..=20 {
        h.send("a", scalar(f64::from(k))).expect("a");
    }
    h.step().expect("step");
    // 16 kept (5..=20), 4 overwritten
    assert_eq!(h.output::<Scalar>("sum").expect("sum")[1].value, (5..=20).sum::<i32>() as f64);
    let a = h.input_stats().into_iter().find(|s| s.input == "a").expect("stats of a");
    assert_eq!((a.received, a.dropped), (17, 4));
}

#[test]
fn a_wrong_port_or_type_is_refused_with_what_there_is() {
    let mut h = Harness::<Adder>::new().expect("start");
    let e = h.send("c", scalar(1.0)).expect_err("no input c").to_string();
    assert!(e.contains("\"c\"") && e.contains("[\"a\", \"b\"]"), "{e}");
    let e = h.send("a", Tick::default()).expect_err("a carries Scalar").to_string();
    assert!(e.contains("nerve::Scalar") && e.contains("nerve::Tick"), "{e}");
    let e = h.output::<Tick>("sum").expect_err("sum carries Scalar").to_string();
    assert!(e.contains("nerve::Scalar"), "{e}");
    assert!(h.output::<Scalar>("total").is_err());
    let e = Harness::<Adder>::builder().param("offset", "x").start().expect_err("not a number").to_string();
    assert!(e.contains("offset=x"), "{e}");
}

/// Ports bound to memory make no iceoryx2 file, and the harness's robot
/// is its own.
#[test]
fn a_harness_makes_no_shared_memory_for_its_ports() {
    let h = Harness::<Adder>::new().expect("start");
    let world = h.world().clone();
    assert!(world.robot().as_str().starts_with(&format!("test-{}-", std::process::id())));
    assert!(world.shm_files().is_empty() && world.iox2_files().is_empty());
    let other = Harness::<Adder>::new().expect("start");
    assert_ne!(other.world().robot(), world.robot());
}
