//! Calls in the [`Harness`]: the test calls a service the agent serves,
//! and answers the calls the agent makes through its clients.
//!
//! The step model is the running agent's: a request waits for the agent's
//! next step (it wakes an event-driven agent, as a request wakes its task),
//! whose own `serve` answers it; an answer to the agent's call waits for
//! the step after the test gave it, where the agent's `take` finds it. A
//! call's timeout counts on the harness's clock ([`Harness::advance`]).
//!
//! The types are checked at run time: a fixed answer is taken as its
//! payload type `Resp`, a sequence answer as `(H, Vec<T>)`, a call
//! declared by layout (Python's) as bytes, `Vec<u8>`.
//!
//! ```
//! use agent_sdk::port::{CallError, Client, Server};
//! use agent_sdk::testing::Harness;
//! use agent_sdk::{Agent, AgentError, Context, Setup, Task};
//! use shm_schemas::payloads::{Scalar, Tick};
//!
//! /// Doubles what it is asked; asks its `sensor` for a reading at every step.
//! struct Doubler { double: Server<Scalar, Scalar>, sensor: Client<Tick, Scalar>, last: Option<f64> }
//!
//! impl Agent for Doubler {
//!     const KIND: &'static str = "doubler";
//!     fn task() -> Task { Task::EventDriven }
//!     fn new(setup: &mut Setup) -> Result<Self, AgentError> {
//!         Ok(Doubler { double: setup.serve("double")?, sensor: setup.client("sensor")?, last: None })
//!     }
//!     fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
//!         self.double.serve(|s| Scalar { value: 2.0 * s.value, stamp_ns: s.stamp_ns })?;
//!         while let Some((_, answer)) = self.sensor.take() {
//!             self.last = Some(answer?.value);
//!         }
//!         if self.sensor.in_flight() == 0 {
//!             self.sensor.call(&Tick { seq: ctx.cycle(), stamp_ns: ctx.now_ns() })?;
//!         }
//!         Ok(())
//!     }
//! }
//!
//! let mut h = Harness::<Doubler>::new().unwrap();
//! // the agent's handler answers at its step
//! let answer: Scalar = h.ask("double", Scalar { value: 21.0, stamp_ns: 0 }).unwrap();
//! assert_eq!(answer.value, 42.0);
//! // the test answers the agent's call; the agent takes it at its next step
//! let [(id, tick)] = h.requests::<Tick>("sensor").unwrap()[..] else { panic!("one call") };
//! assert_eq!(tick.seq, 0);
//! h.answer("sensor", id, Ok(Scalar { value: 7.0, stamp_ns: 0 })).unwrap();
//! h.step().unwrap();
//! assert_eq!(h.agent().last, Some(7.0));
//! ```

use super::{Harness, HarnessError};
use crate::agent::Agent;
use crate::port::call::memory::{AnyBox, MemCallPort, MemCaller, MemService, Outcome};
use crate::port::{CallError, CallId};
use std::any::{TypeId, type_name};
use std::sync::Arc;

/// The answers a served port gave the test, as its values.
type Answers<V> = Vec<(CallId, Outcome<V>)>;

/// Refuses `given` unless it is `want` (a port's Rust type, its name).
fn check_type<T: 'static>(port: &str, carries: &str, want: (TypeId, &'static str)) -> Result<(), HarnessError> {
    if TypeId::of::<T>() == want.0 {
        return Ok(());
    }
    Err(HarnessError::WrongType {
        port: port.into(),
        carries: format!("{carries} ({})", want.1),
        asked: type_name::<T>(),
    })
}

/// Service `port` among `calls`, or what services there are.
pub(super) fn service_of(calls: &[MemCallPort], port: &str) -> Result<Arc<dyn MemService>, HarnessError> {
    let mut known = Vec::new();
    for c in calls {
        if let MemCallPort::Service(s) = c {
            if s.spec().name == port {
                return Ok(s.clone());
            }
            known.push(s.spec().name.clone());
        }
    }
    Err(HarnessError::NoSuchPort { direction: "service", port: port.into(), known })
}

/// Client `port` among `calls`, or what clients there are.
pub(super) fn client_of(calls: &[MemCallPort], port: &str) -> Result<Arc<dyn MemCaller>, HarnessError> {
    let mut known = Vec::new();
    for c in calls {
        if let MemCallPort::Client(c) = c {
            if c.spec().name == port {
                return Ok(c.clone());
            }
            known.push(c.spec().name.clone());
        }
    }
    Err(HarnessError::NoSuchPort { direction: "client", port: port.into(), known })
}

/// Takes the answers `service` gave the test (of call `only`, if given) as `V`s.
fn take_answers<V: Send + 'static>(service: &dyn MemService, only: Option<CallId>) -> Result<Answers<V>, HarnessError> {
    let spec = service.spec();
    check_type::<V>(&spec.name, &spec.type_name, service.value_type())?;
    let taken: AnyBox = service.take_test_answers(only);
    match taken.downcast::<Answers<V>>() {
        Ok(answers) => Ok(*answers),
        Err(_) => Err(HarnessError::WrongType {
            port: spec.name.clone(),
            carries: spec.type_name.clone(),
            asked: type_name::<V>(),
        }),
    }
}

impl<A: Agent> Harness<A> {
    /// Calls service `service` of the agent with `request` (its request
    /// type `Req`; bytes, `Vec<u8>`, for a service declared by layout).
    /// The request waits for the agent's next step, whose `serve` answers
    /// it; [`Harness::answers`] then has the answer.
    pub fn call<Req: Send + 'static>(&mut self, service: &str, request: Req) -> Result<CallId, HarnessError> {
        let s = service_of(&self.calls, service)?;
        check_type::<Req>(service, &s.spec().type_name, s.request_type())?;
        s.test_call(Box::new(request)).ok_or_else(|| HarnessError::WrongType {
            port: service.into(),
            carries: s.spec().type_name.clone(),
            asked: type_name::<Req>(),
        })
    }

    /// The answers service `service` gave the test's calls since the last
    /// look, oldest first: each call's `V` (the answer type `Resp`, a
    /// sequence answer's `(H, Vec<T>)`, bytes for a service declared by
    /// layout) or why there is none ([`CallError::RefusedTooLong`] past a
    /// sequence's maximum; [`CallError::ServerGone`] when the handler failed).
    pub fn answers<V: Send + 'static>(&mut self, service: &str) -> Result<Answers<V>, HarnessError> {
        take_answers(service_of(&self.calls, service)?.as_ref(), None)
    }

    /// Calls service `service` with `request`, runs one step
    /// ([`Harness::step`]) and returns the answer the agent's handler gave
    /// there. [`HarnessError::NotAnswered`] if it gave none at that step
    /// (the request stays queued), [`HarnessError::Call`] if the call ended
    /// with an error; a failed step is [`HarnessError::Step`].
    pub fn ask<Req: Send + 'static, V: Send + 'static>(
        &mut self,
        service: &str,
        request: Req,
    ) -> Result<V, HarnessError> {
        let id = self.call(service, request)?;
        self.step().map_err(|source| HarnessError::Step { agent: self.ctx.name.clone(), source })?;
        let s = service_of(&self.calls, service)?;
        match take_answers::<V>(s.as_ref(), Some(id))?.pop() {
            Some((_, Ok(v))) => Ok(v),
            Some((_, Err(source))) => Err(HarnessError::Call { port: service.into(), source }),
            None => Err(HarnessError::NotAnswered { port: service.into(), id }),
        }
    }

    /// The calls the agent made through client `client` since the last
    /// look, oldest first, with their ids: the test answers them with
    /// [`Harness::answer`]. A client starts wired to the test; in a
    /// [`super::Wiring`] wired to another agent's service, its calls go there.
    pub fn requests<Req: Send + 'static>(&mut self, client: &str) -> Result<Vec<(CallId, Req)>, HarnessError> {
        let c = client_of(&self.calls, client)?;
        check_type::<Req>(client, &c.spec().type_name, c.request_type())?;
        c.take_requests().downcast::<Vec<(CallId, Req)>>().map(|b| *b).map_err(|_| HarnessError::WrongType {
            port: client.into(),
            carries: c.spec().type_name.clone(),
            asked: type_name::<Req>(),
        })
    }

    /// Answers the agent's call `id` through client `client` with
    /// `answer`: its value (`Resp`, `(H, Vec<T>)`, bytes) or an error the
    /// agent should see (a [`CallError::ServerGone`], say). The agent's
    /// `take` finds it at its next step (which it wakes, if event-driven).
    /// [`HarnessError::NotInFlight`] if the call already ended (it timed
    /// out on the harness clock, say).
    pub fn answer<V: Send + 'static>(
        &mut self,
        client: &str,
        id: CallId,
        answer: Result<V, CallError>,
    ) -> Result<(), HarnessError> {
        let c = client_of(&self.calls, client)?;
        check_type::<V>(client, &c.spec().type_name, c.value_type())?;
        match c.answer(id, Box::new(answer)) {
            Ok(true) => Ok(()),
            Ok(false) => Err(HarnessError::NotInFlight { port: client.into(), id }),
            Err(_) => Err(HarnessError::WrongType {
                port: client.into(),
                carries: c.spec().type_name.clone(),
                asked: type_name::<V>(),
            }),
        }
    }

    /// The agent's call ports, for a wiring.
    pub(super) fn call_ports(&self) -> &[MemCallPort] {
        &self.calls
    }
}

#[cfg(test)]
mod tests {
    use super::super::Wiring;
    use super::*;
    use crate::agent::{AgentError, Context, Setup, Task};
    use crate::port::{CallOptions, Client, SeqClient, SeqServer, Server};
    use shm_schemas::payloads::{Scalar, Tick};
    use std::time::Duration;

    fn scalar(value: f64) -> Scalar {
        Scalar { value, stamp_ns: 0 }
    }

    /// Serves `double` (fixed) and `count` (a sequence of `seq` ticks, at
    /// most 3); calls `sensor` once per step while none is in flight and
    /// keeps what the calls ended with. Event-driven.
    struct Both {
        double: Server<Scalar, Scalar>,
        count: SeqServer<Tick, Tick, Scalar>,
        sensor: Client<Tick, Scalar>,
        ask: bool,
        got: Vec<Result<f64, String>>,
        woken: Vec<String>,
        refused: u32,
    }

    impl Agent for Both {
        const KIND: &'static str = "both";
        fn task() -> Task {
            Task::EventDriven
        }
        fn new(setup: &mut Setup) -> Result<Self, AgentError> {
            let options = CallOptions { timeout: Duration::from_millis(500), max_in_flight: 2 };
            Ok(Both {
                double: setup.serve("double")?,
                count: setup.serve_seq("count", 3)?,
                sensor: setup.client_with("sensor", options)?,
                ask: true,
                got: Vec::new(),
                woken: Vec::new(),
                refused: 0,
            })
        }
        fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
            self.woken = ctx.woken_by().map(str::to_owned).collect();
            self.double.serve(|s| scalar(2.0 * s.value))?;
            let counted = self
                .count
                .serve(|t| (scalar(t.seq as f64), (0..t.seq).map(|i| Tick { seq: i, stamp_ns: t.stamp_ns }).collect()));
            if let Err(CallError::AnswerTooLong { .. }) = counted {
                self.refused += 1;
            }
            while let Some((_, answer)) = self.sensor.take() {
                self.got.push(answer.map(|s| s.value).map_err(|e| e.to_string()));
            }
            if self.ask {
                match self.sensor.call(&Tick { seq: ctx.cycle(), stamp_ns: ctx.now_ns() }) {
                    Ok(_) => {}
                    Err(e @ (CallError::TooManyInFlight { .. } | CallError::NotWired { .. })) => {
                        self.got.push(Err(e.to_string()))
                    }
                    Err(e) => return Err(e.into()),
                }
            }
            Ok(())
        }
    }

    /// The test calls the agent's services; each request wakes it and its
    /// own handler answers at the step: fixed answers, sequences of 0 and
    /// 3 elements, one past the maximum refused on both sides.
    #[test]
    fn the_test_calls_a_service_and_the_agents_step_answers() {
        let mut h = Harness::<Both>::new().expect("start");
        h.agent_mut().ask = false;
        let a = h.call("double", scalar(1.5)).expect("call");
        let b = h.call("double", scalar(-2.0)).expect("call");
        assert!(h.answers::<Scalar>("double").expect("answers").is_empty(), "nothing before the step");
        h.step().expect("step");
        assert_eq!(h.agent().woken, ["double"], "a request wakes the agent");
        let got: Vec<(CallId, f64)> = h
            .answers::<Scalar>("double")
            .expect("answers")
            .into_iter()
            .map(|(id, r)| (id, r.expect("ok").value))
            .collect();
        assert_eq!(got, [(a, 3.0), (b, -4.0)]);
        assert_eq!(h.ask::<Scalar, Scalar>("double", scalar(4.0)).expect("ask").value, 8.0);
        assert_eq!(h.agent().double.answered(), 3);

        // a sequence answer, then one past the maximum: refused, the agent told
        let (header, items) = h.ask::<Tick, (Scalar, Vec<Tick>)>("count", Tick { seq: 3, stamp_ns: 5 }).expect("3");
        assert_eq!((header.value, items.len(), items[2]), (3.0, 3, Tick { seq: 2, stamp_ns: 5 }));
        assert!(h.ask::<Tick, (Scalar, Vec<Tick>)>("count", Tick::default()).expect("0").1.is_empty());
        match h.ask::<Tick, (Scalar, Vec<Tick>)>("count", Tick { seq: 4, stamp_ns: 0 }) {
            Err(HarnessError::Call { source: CallError::RefusedTooLong { len: 4, max: 3, .. }, .. }) => {}
            other => panic!("past the maximum: {other:?}"),
        }
        assert_eq!(h.agent().refused, 1, "serve returned AnswerTooLong");

        // the wrong types, or no such service, are refused naming what there is
        let e = h.call("double", Tick::default()).expect_err("double takes Scalar").to_string();
        assert!(e.contains("call(nerve::Scalar -> nerve::Scalar)") && e.contains("Tick"), "{e}");
        let e = h.answers::<Tick>("double").expect_err("double answers Scalar").to_string();
        assert!(e.contains("Scalar"), "{e}");
        let e = h.call("triple", scalar(1.0)).expect_err("no service triple").to_string();
        assert!(e.contains("\"triple\"") && e.contains("double") && e.contains("count"), "{e}");
        // a step that does not serve leaves the request queued: not answered
        h.suspend();
        let e = h.ask::<Scalar, Scalar>("double", scalar(1.0)).expect_err("suspended");
        assert!(matches!(e, HarnessError::NotAnswered { .. }), "{e}");
    }

    /// The agent's calls come to the test, which answers them or lets them
    /// time out on the harness clock; the bound of calls in flight holds.
    #[test]
    fn the_agents_calls_come_to_the_test_which_answers_them() {
        let mut h = Harness::<Both>::new().expect("start");
        h.step().expect("step");
        let calls = h.requests::<Tick>("sensor").expect("requests");
        assert_eq!(calls.len(), 1);
        let (id, tick) = calls[0];
        assert_eq!(tick.seq, 0);
        h.answer("sensor", id, Ok(scalar(7.0))).expect("answer");
        let e = h.answer("sensor", id, Ok(scalar(7.0))).expect_err("answered once").to_string();
        assert!(e.contains("not in flight"), "{e}");
        h.step().expect("step");
        assert_eq!(h.agent().woken, ["sensor"], "an answer wakes the agent");
        assert_eq!(h.agent().got, [Ok(7.0)]);
        // an error the test gives is the agent's to see
        let (id, _) = h.requests::<Tick>("sensor").expect("requests")[0];
        let gone = CallError::ServerGone { client: "sensor".into(), service: "test".into() };
        h.answer::<Scalar>("sensor", id, Err(gone)).expect("answer");
        h.step().expect("step");
        assert!(h.agent().got[1].as_ref().is_err_and(|e| e.contains("went away")), "{:?}", h.agent().got);

        // unanswered: two in flight, the third refused; past 500 ms both time out
        h.step().expect("step");
        h.step().expect("step");
        assert_eq!(h.agent().sensor.in_flight(), 2);
        assert!(h.agent().got[2].as_ref().is_err_and(|e| e.contains("2 calls are in flight")), "{:?}", h.agent().got);
        h.agent_mut().ask = false;
        h.advance(Duration::from_millis(500)).expect("advance");
        let late = h.requests::<Tick>("sensor").expect("requests");
        assert_eq!(late.len(), 2);
        h.step().expect("step");
        let timed_out = h.agent().got[3..].iter().filter(|g| g.as_ref().is_err_and(|e| e.contains("within 500ms")));
        assert_eq!(timed_out.count(), 2, "{:?}", h.agent().got);
        let e = h.answer("sensor", late[0].0, Ok(scalar(1.0))).expect_err("timed out").to_string();
        assert!(e.contains("not in flight"), "{e}");
        let e = h.answer("sensor", late[0].0, Ok(Tick::default())).expect_err("another type").to_string();
        assert!(e.contains("Scalar") && e.contains("Tick"), "{e}");
    }

    /// Answers `double` in place; calls `sensor` with a request written in
    /// place and `planner` (a sequence service) by value, and reads both
    /// answers in place. Event-driven.
    struct InPlace {
        double: Server<Scalar, Scalar>,
        sensor: Client<Tick, Scalar>,
        planner: SeqClient<Tick, Tick, Scalar>,
        got: Vec<Result<f64, String>>,
        plans: Vec<(f64, Vec<Tick>)>,
    }

    impl Agent for InPlace {
        const KIND: &'static str = "in-place";
        fn task() -> Task {
            Task::EventDriven
        }
        fn new(setup: &mut Setup) -> Result<Self, AgentError> {
            let options = CallOptions { timeout: Duration::from_millis(500), max_in_flight: 2 };
            Ok(InPlace {
                double: setup.serve("double")?,
                sensor: setup.client_with("sensor", options)?,
                planner: setup.client_seq("planner")?,
                got: Vec::new(),
                plans: Vec::new(),
            })
        }
        fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
            self.double.serve_in_place(|s, answer| {
                answer.value = 2.0 * s.value;
                answer.stamp_ns = s.stamp_ns;
            })?;
            while let Some(got) = self.sensor.take_with(|_, answer| answer.map(|s| s.value).map_err(|e| e.to_string()))
            {
                self.got.push(got);
            }
            while let Some(plan) =
                self.planner.take_with(|_, answer| answer.map(|(h, items)| (h.value, items.to_vec())))
            {
                self.plans.push(plan?);
            }
            if self.sensor.in_flight() == 0 {
                self.sensor.call_with(|t| t.seq = ctx.cycle())?;
                self.planner.call(&Tick { seq: ctx.cycle(), stamp_ns: 0 })?;
            }
            Ok(())
        }
    }

    /// The in-place forms in the harness behave as the by-value ones: the
    /// test asks a service answered in place, answers calls made in place
    /// and read in place (a fixed answer and a sequence), and a call
    /// unanswered times out on the harness clock.
    #[test]
    fn calls_answered_and_read_in_place_work_in_the_harness() {
        let mut h = Harness::<InPlace>::new().expect("start");
        assert_eq!(h.ask::<Scalar, Scalar>("double", Scalar { value: 4.0, stamp_ns: 9 }).expect("ask").value, 8.0);
        assert_eq!(h.agent().double.answered(), 1);
        let [(id, tick)] = h.requests::<Tick>("sensor").expect("requests")[..] else { panic!("one call") };
        assert_eq!(tick.seq, 0);
        h.answer("sensor", id, Ok(scalar(7.0))).expect("answer");
        let [(plan, _)] = h.requests::<Tick>("planner").expect("requests")[..] else { panic!("one plan") };
        let items = vec![Tick { seq: 1, stamp_ns: 2 }, Tick { seq: 3, stamp_ns: 4 }];
        h.answer("planner", plan, Ok((scalar(2.0), items.clone()))).expect("answer");
        h.step().expect("step");
        assert_eq!(h.agent().got, [Ok(7.0)]);
        assert_eq!(h.agent().plans, [(2.0, items)]);
        // unanswered: the call times out, read in place as an error
        h.advance(Duration::from_millis(500)).expect("advance");
        h.step().expect("step");
        assert!(h.agent().got[1].as_ref().is_err_and(|e| e.contains("within 500ms")), "{:?}", h.agent().got);
    }

    /// Asks its `planner` (a sequence service) for a plan of `n` points
    /// whenever told to by an input; keeps the lengths it got. Periodic.
    struct Asker {
        planner: SeqClient<Tick, Tick, Scalar>,
        lengths: Vec<Result<usize, String>>,
    }

    impl Agent for Asker {
        const KIND: &'static str = "asker";
        fn task() -> Task {
            Task::Periodic(Duration::from_millis(100))
        }
        fn new(setup: &mut Setup) -> Result<Self, AgentError> {
            Ok(Asker { planner: setup.client_seq("planner")?, lengths: Vec::new() })
        }
        fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
            while let Some((_, answer)) = self.planner.take() {
                self.lengths.push(answer.map(|(_, items)| items.len()).map_err(|e| e.to_string()));
            }
            if let Err(e) = self.planner.call(&Tick { seq: ctx.cycle() % 5, stamp_ns: ctx.now_ns() }) {
                self.lengths.push(Err(e.to_string()));
            }
            Ok(())
        }
    }

    /// In a wiring, a client wired to another agent's service calls it:
    /// the event-driven server answers at the instant of the call, the
    /// periodic client takes the answer at its next step; wired wrongly,
    /// refused as the router refuses it; unwired, its calls refused.
    #[test]
    fn two_agents_of_a_wiring_call_each_other() {
        let mut w = Wiring::new();
        w.add::<Asker>("asker").expect("asker");
        w.add::<Both>("server").expect("server");
        w.harness_mut::<Both>("server").expect("server").agent_mut().ask = false;
        let e = w.connect("asker/planner", "server/double").expect_err("another call type").to_string();
        assert!(e.contains("call(nerve::Tick -> ") && e.contains("call(nerve::Scalar -> nerve::Scalar)"), "{e}");
        let e = w.connect("asker/planner", "server/plan").expect_err("no such service").to_string();
        assert!(e.contains("no service port \"plan\"") && e.contains("count"), "{e}");
        w.connect("asker/planner", "server/count").expect("wired");
        // steps at 100..=500 ms: calls of 0, 1, 2, 3, 4 points; each
        // answered at once by the server, taken at the asker's next step
        assert_eq!(w.advance(Duration::from_millis(500)).expect("advance"), 10, "5 asks, 5 answers");
        assert_eq!(w.agent::<Asker>("asker").expect("asker").lengths.len(), 4);
        w.advance(Duration::from_millis(100)).expect("advance");
        let lengths = &w.agent::<Asker>("asker").expect("asker").lengths;
        assert_eq!(lengths[..4], [Ok(0), Ok(1), Ok(2), Ok(3)]);
        assert!(lengths[4].as_ref().is_err_and(|e| e.contains("refused its answer of 4")), "{lengths:?}");
        assert_eq!(w.agent::<Both>("server").expect("server").refused, 1);
        assert!(w.harness_mut::<Asker>("asker").expect("asker").requests::<Tick>("planner").expect("none").is_empty());

        // unwired with a call in flight (its server suspended): the call
        // ends so, the next ones are refused
        w.suspend("server").expect("suspend");
        w.advance(Duration::from_millis(100)).expect("advance");
        w.disconnect("asker/planner", "server/count").expect("disconnect");
        w.advance(Duration::from_millis(100)).expect("advance");
        let lengths = &w.agent::<Asker>("asker").expect("asker").lengths;
        assert_eq!(lengths[5], Ok(0), "{lengths:?}");
        assert!(lengths[6].as_ref().is_err_and(|e| e.contains("unwired")), "{lengths:?}");
        assert!(lengths[7].as_ref().is_err_and(|e| e.contains("not wired")), "{lengths:?}");
    }
}
