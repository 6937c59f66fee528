//! The router's core driven directly: every request it serves and every
//! fault the end-to-end tests inject (an agent that dies mid-connect, a
//! refusal, a restart with back-off until it is marked failed, a hung agent,
//! a stale registration, a tool that goes away), with no process, no shared
//! memory and no clock: time is what each input says.

use super::*;
use crate::calls::Outcome;
use shm_schemas::PortRef;
use shm_schemas::control::cli_to_router::{RestartPolicy, Supervision};
use std::path::Path;

const T: &str = "nerve::Tick";

/// A router core and the time, with helpers that play the driver.
struct Bench {
    core: State,
    now: Instant,
    next_id: RequestId,
}

fn port(name: &str) -> PortSpec {
    PortSpec { name: name.into(), type_name: T.into(), fingerprint: 7 }
}

fn registration(name: &str, pid: u32, inputs: &[&str], outputs: &[&str]) -> Registration {
    Registration {
        name: name.into(),
        pid,
        kind: "ticker".into(),
        executable: String::new(),
        task: TaskKind::Periodic,
        period_ns: Some(10_000_000),
        inputs: inputs.iter().map(|p| port(p)).collect(),
        outputs: outputs.iter().map(|p| port(p)).collect(),
        log_file: None,
        suspended: false,
        schemas: vec![],
        services: vec![],
        clients: vec![],
    }
}

fn p(s: &str) -> PortRef {
    s.parse().expect("a port")
}

fn supervision(name: &str, policy: RestartPolicy, max_restarts: u32) -> Supervision {
    Supervision {
        name: name.into(),
        argv: vec![format!("nerve-{name}"), "--robot".into(), "r".into()],
        policy,
        max_restarts,
        window_ns: 10_000_000_000,
        backoff_ns: 100_000_000,
        importance: 5,
        cwd: Some("/launched/here".into()),
    }
}

/// The effects of one kind.
fn sends(effects: &[Effect]) -> Vec<(Ticket, String, AgentCommand)> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::Send { ticket, agent, cmd, .. } => Some((*ticket, agent.clone(), cmd.clone())),
            _ => None,
        })
        .collect()
}

fn saves(effects: &[Effect]) -> Vec<(SaveId, Vec<u8>)> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::SaveList { save, body } => Some((*save, body.clone())),
            _ => None,
        })
        .collect()
}

fn spawns(effects: &[Effect]) -> Vec<(String, Vec<String>, Option<String>)> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::Spawn { name, argv, cwd, .. } => Some((name.clone(), argv.clone(), cwd.clone())),
            _ => None,
        })
        .collect()
}

fn reply(effects: &[Effect], id: RequestId) -> Option<RouterReply> {
    effects.iter().find_map(|e| match e {
        Effect::Reply { id: i, reply } if *i == id => Some(reply.clone()),
        _ => None,
    })
}

fn ok(r: Option<RouterReply>) {
    assert!(matches!(r, Some(RouterReply::Ok)), "not Ok: {r:?}");
}

fn error(r: Option<RouterReply>) -> RouterError {
    match r {
        Some(RouterReply::Error(e)) => e,
        other => panic!("not an error: {other:?}"),
    }
}

impl Bench {
    fn new() -> Bench {
        Bench::with(Vec::new())
    }

    fn with(connections: Vec<Connection>) -> Bench {
        let now = Instant::now();
        let supervisor = Supervisor::new(Path::new("/state/r"));
        let core = State::new(42, connections, supervisor, "/state/r/connections.json".into(), "/logs/r".into(), now);
        Bench { core, now, next_id: 0 }
    }

    fn handle(&mut self, input: Input) -> Vec<Effect> {
        self.core.handle(self.now, input)
    }

    fn id(&mut self) -> RequestId {
        self.next_id += 1;
        self.next_id
    }

    fn after(&mut self, d: Duration) {
        self.now += d;
    }

    /// Registers `name` as the process (pid, start 1); its reply and effects.
    fn register(&mut self, name: &str, pid: u32, inputs: &[&str], outputs: &[&str]) -> (RouterReply, Vec<Effect>) {
        let id = self.id();
        let reg = registration(name, pid, inputs, outputs);
        let process = Ok(ProcessHandle::from_parts(pid, 1));
        let fx = self.handle(Input::Register { id, reg, process, holder_alive: false });
        (reply(&fx, id).expect("a registration is answered at once"), fx)
    }

    fn cli(&mut self, req: CliRequest) -> (RequestId, Vec<Effect>) {
        let id = self.id();
        let tool = match &req {
            CliRequest::Attach { pid, .. } => Some(Ok(ProcessHandle::from_parts(*pid, 1))),
            _ => None,
        };
        let fx = self.handle(Input::Cli { id, req, tool });
        (id, fx)
    }

    fn answer(&mut self, ticket: Ticket, agent: &str, result: Result<AgentReply, RouterError>) -> Vec<Effect> {
        self.handle(Input::Outcome(Outcome { ticket, agent: agent.into(), result }))
    }

    fn saved(&mut self, save: SaveId) -> Vec<Effect> {
        self.handle(Input::Saved { save, result: Ok(()) })
    }

    fn died(&mut self, name: &str, pid: u32) -> Vec<Effect> {
        self.handle(Input::Liveness { dead: vec![(name.into(), pid)], gone_tools: vec![] })
    }

    /// A connect the input agent obeys and whose save is done; its reply.
    fn connect(&mut self, from: &str, to: &str) -> Option<RouterReply> {
        let (id, fx) = self.cli(CliRequest::Connect { from: p(from), to: p(to), allow_cycle: false });
        if let Some(r) = reply(&fx, id) {
            return Some(r);
        }
        let sent = sends(&fx);
        let [(ticket, agent, _)] = &sent[..] else { panic!("one command: {fx:?}") };
        let fx = self.answer(*ticket, agent, Ok(AgentReply::Ok));
        let saved = saves(&fx);
        let [(save, _)] = &saved[..] else { panic!("one save: {fx:?}") };
        reply(&self.saved(*save), id)
    }

    fn events(&mut self) -> Vec<EventKind> {
        let (id, fx) = self.cli(CliRequest::Events { after: 0 });
        match reply(&fx, id) {
            Some(RouterReply::Events { events, .. }) => events.into_iter().map(|e| e.what).collect(),
            other => panic!("events: {other:?}"),
        }
    }

    fn edges(&self) -> Vec<(String, String)> {
        self.core.wiring.list().iter().map(|c| (c.from.to_string(), c.to.to_string())).collect()
    }

    /// `ps`, every agent answering its statistics except those in `silent`.
    fn ps(&mut self, silent: &[&str]) -> Vec<AgentView> {
        let (id, fx) = self.cli(CliRequest::Ps);
        let mut last = fx.clone();
        for (ticket, agent, cmd) in sends(&fx) {
            assert!(matches!(cmd, AgentCommand::Stats));
            let result = if silent.contains(&agent.as_str()) {
                Err(RouterError::AgentUnreachable { name: agent.clone(), detail: "no reply within 300ms".into() })
            } else {
                Ok(AgentReply::Stats(AgentStats::default()))
            };
            last = self.answer(ticket, &agent, result);
        }
        match reply(&last, id) {
            Some(RouterReply::Agents(v)) => v,
            other => panic!("ps: {other:?}"),
        }
    }
}

/// Two agents, `t1` (output `tick`) and `r1` (input `in`, output `out`).
fn two() -> Bench {
    let mut b = Bench::new();
    b.register("t1", 101, &[], &["tick"]);
    b.register("r1", 102, &["in"], &["out"]);
    b
}

#[test]
fn a_registration_is_answered_with_the_epoch_and_recorded() {
    let mut b = Bench::new();
    let (r, fx) = b.register("t1", 101, &[], &["tick"]);
    assert!(matches!(r, RouterReply::Registered { epoch: 42, ref first } if first.is_empty()), "{r:?}");
    assert!(fx.iter().any(|e| matches!(e, Effect::Reach { agent } if agent == "t1")));
    assert!(b.core.registry.contains("t1"));
    assert_eq!(b.events(), vec![EventKind::Registered { agent: "t1".into(), pid: 101 }]);
}

#[test]
fn a_name_held_by_a_live_process_is_refused_and_a_stale_one_is_replaced() {
    let mut b = Bench::new();
    b.register("t1", 101, &[], &["tick"]);
    let id = b.id();
    let process = Ok(ProcessHandle::from_parts(201, 1));
    let fx = b.handle(Input::Register { id, reg: registration("t1", 201, &[], &[]), process, holder_alive: true });
    assert!(matches!(error(reply(&fx, id)), RouterError::DuplicateName { pid: 101, .. }));
    // the holder died and the liveness check has not seen it yet: a stale
    // registration is replaced by the new instance
    let id = b.id();
    let process = Ok(ProcessHandle::from_parts(201, 1));
    let fx = b.handle(Input::Register { id, reg: registration("t1", 201, &[], &[]), process, holder_alive: false });
    assert!(matches!(reply(&fx, id), Some(RouterReply::Registered { .. })));
    assert_eq!(b.core.registry.get("t1").map(|e| e.reg.pid), Some(201));
    // the old pid's death, seen late, does not remove the new instance
    b.died("t1", 101);
    assert!(b.core.registry.contains("t1"));
}

#[test]
fn a_registration_whose_process_is_not_believed_is_refused() {
    let mut b = Bench::new();
    let id = b.id();
    let refused = RouterError::RegistrationRefused { name: "t1".into(), pid: 9, reason: "not a nerve agent".into() };
    let fx = b.handle(Input::Register {
        id,
        reg: registration("t1", 9, &[], &[]),
        process: Err(refused),
        holder_alive: false,
    });
    assert!(matches!(error(reply(&fx, id)), RouterError::RegistrationRefused { .. }));
    assert!(!b.core.registry.contains("t1"));
    assert!(b.events().is_empty());
}

#[test]
fn a_connect_is_saved_once_after_the_agent_subscribed_and_answered_once_on_disk() {
    let mut b = two();
    let (id, fx) = b.cli(CliRequest::Connect { from: p("t1/tick"), to: p("r1/in"), allow_cycle: false });
    assert!(saves(&fx).is_empty(), "nothing is saved before the agent answered");
    assert!(reply(&fx, id).is_none());
    let sent = sends(&fx);
    let [(ticket, agent, cmd)] = &sent[..] else { panic!("{fx:?}") };
    let ticket = *ticket;
    assert_eq!(agent, "r1");
    assert!(
        matches!(cmd, AgentCommand::Connect { input, from_agent, from_port, type_name } if input == "in" && from_agent == "t1" && from_port == "tick" && type_name == T)
    );
    let fx = b.answer(ticket, "r1", Ok(AgentReply::Ok));
    let s = saves(&fx);
    assert_eq!(s.len(), 1, "one save per change");
    assert!(String::from_utf8_lossy(&s[0].1).contains("\"from\": \"t1/tick\""), "the file's format");
    assert!(reply(&fx, id).is_none(), "answered once on disk");
    ok(reply(&b.saved(s[0].0), id));
    assert_eq!(b.edges(), vec![("t1/tick".to_owned(), "r1/in".to_owned())]);
    assert!(b.events().contains(&EventKind::Connected { from: "t1/tick".into(), to: "r1/in".into() }));
    // the same edge again: the agent is asked, the list does not change, nothing is saved
    let (id, fx) = b.cli(CliRequest::Connect { from: p("t1/tick"), to: p("r1/in"), allow_cycle: false });
    let sent = sends(&fx);
    let [(ticket, _, _)] = &sent[..] else { panic!("{fx:?}") };
    let fx = b.answer(*ticket, "r1", Ok(AgentReply::Ok));
    assert!(saves(&fx).is_empty());
    ok(reply(&fx, id));
}

#[test]
fn a_save_that_fails_is_the_answer() {
    let mut b = two();
    let (id, fx) = b.cli(CliRequest::Connect { from: p("t1/tick"), to: p("r1/in"), allow_cycle: false });
    let fx = b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Ok));
    let save = saves(&fx)[0].0;
    let fx = b.handle(Input::Saved { save, result: Err("disk full".into()) });
    match error(reply(&fx, id)) {
        RouterError::NotSaved { what, file, detail } => {
            assert_eq!(what, "connected t1/tick -> r1/in");
            assert_eq!(file, "/state/r/connections.json");
            assert_eq!(detail, "disk full");
        }
        e => panic!("{e:?}"),
    }
}

#[test]
fn a_connect_the_agent_refuses_is_answered_at_once_and_saves_nothing() {
    let mut b = two();
    let (id, fx) = b.cli(CliRequest::Connect { from: p("t1/tick"), to: p("r1/in"), allow_cycle: false });
    let refused = RouterError::AgentRefused { name: "r1".into(), message: "no input in".into() };
    let fx = b.answer(sends(&fx)[0].0, "r1", Err(refused));
    assert!(matches!(error(reply(&fx, id)), RouterError::AgentRefused { .. }));
    assert!(saves(&fx).is_empty());
    assert!(b.edges().is_empty());
}

#[test]
fn an_agent_that_dies_mid_connect_leaves_the_list_as_it_was() {
    let mut b = two();
    let (id, fx) = b.cli(CliRequest::Connect { from: p("t1/tick"), to: p("r1/in"), allow_cycle: false });
    let ticket = sends(&fx)[0].0;
    // it dies before it answers: the liveness check sees it, then its call fails
    let fx = b.died("r1", 102);
    assert!(fx.iter().any(|e| matches!(e, Effect::Release { agent } if agent == "r1")));
    assert!(fx.iter().any(|e| matches!(e, Effect::Sweep)));
    let gone = RouterError::AgentUnreachable { name: "r1".into(), detail: "its control service is missing".into() };
    let fx = b.answer(ticket, "r1", Err(gone));
    assert!(matches!(error(reply(&fx, id)), RouterError::AgentUnreachable { .. }));
    assert!(saves(&fx).is_empty());
    assert!(b.edges().is_empty());
    assert!(b.events().contains(&EventKind::Died { agent: "r1".into(), pid: 102 }));
    // and a connect to it now says it is not running
    let e = error(b.connect("t1/tick", "r1/in"));
    assert!(matches!(e, RouterError::UnknownAgent { ref name, .. } if name == "r1"), "{e:?}");
}

#[test]
fn a_connect_of_other_types_or_unknown_ports_is_refused_without_asking_the_agent() {
    let mut b = two();
    b.core.registry.get_mut("r1").expect("r1").reg.inputs[0].type_name = "nerve::Scalar".into();
    let (id, fx) = b.cli(CliRequest::Connect { from: p("t1/tick"), to: p("r1/in"), allow_cycle: false });
    assert!(matches!(error(reply(&fx, id)), RouterError::TypeMismatch { .. }));
    assert!(sends(&fx).is_empty());
    let (id, fx) = b.cli(CliRequest::Connect { from: p("t1/nope"), to: p("r1/in"), allow_cycle: false });
    assert!(matches!(error(reply(&fx, id)), RouterError::UnknownPort { .. }));
    assert!(sends(&fx).is_empty());
}

#[test]
fn a_loop_of_event_driven_agents_is_refused_unless_allowed() {
    let mut b = Bench::new();
    for (name, pid) in [("a", 1), ("c", 2)] {
        let id = b.id();
        let mut reg = registration(name, pid, &["in"], &["out"]);
        reg.task = TaskKind::EventDriven;
        b.handle(Input::Register { id, reg, process: Ok(ProcessHandle::from_parts(pid, 1)), holder_alive: false });
    }
    ok(b.connect("a/out", "c/in"));
    let e = error(b.connect("c/out", "a/in"));
    assert!(matches!(e, RouterError::Cycle { .. }), "{e:?}");
    let (id, fx) = b.cli(CliRequest::Connect { from: p("c/out"), to: p("a/in"), allow_cycle: true });
    assert!(reply(&fx, id).is_none(), "allowed: the agent is asked");
}

#[test]
fn a_disconnect_is_saved_once_when_the_agent_let_go_and_kept_when_it_did_not_answer() {
    let mut b = two();
    ok(b.connect("t1/tick", "r1/in"));
    // a hung agent: the edge stays, since it may still read
    let (id, fx) = b.cli(CliRequest::Disconnect { from: p("t1/tick"), to: p("r1/in") });
    assert!(saves(&fx).is_empty());
    let hung = RouterError::AgentUnreachable { name: "r1".into(), detail: "no reply within 1s".into() };
    let fx = b.answer(sends(&fx)[0].0, "r1", Err(hung));
    let e = error(reply(&fx, id));
    assert!(e.to_string().contains("stays in the connection list"), "{e}");
    assert!(saves(&fx).is_empty());
    assert_eq!(b.edges().len(), 1);
    // it lets go: removed, saved once, answered once on disk
    let (id, fx) = b.cli(CliRequest::Disconnect { from: p("t1/tick"), to: p("r1/in") });
    let fx = b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Ok));
    let s = saves(&fx);
    assert_eq!(s.len(), 1);
    assert!(b.edges().is_empty());
    ok(reply(&b.saved(s[0].0), id));
    // again: not connected
    let (id, fx) = b.cli(CliRequest::Disconnect { from: p("t1/tick"), to: p("r1/in") });
    assert!(matches!(error(reply(&fx, id)), RouterError::NotConnected { .. }));
}

#[test]
fn a_disconnect_of_an_input_not_running_needs_no_agent() {
    let mut b = two();
    ok(b.connect("t1/tick", "r1/in"));
    b.died("r1", 102);
    assert_eq!(b.edges().len(), 1, "kept for its restart");
    let (id, fx) = b.cli(CliRequest::Disconnect { from: p("t1/tick"), to: p("r1/in") });
    assert!(sends(&fx).is_empty());
    let s = saves(&fx);
    assert_eq!(s.len(), 1);
    ok(reply(&b.saved(s[0].0), id));
    assert!(b.edges().is_empty());
}

#[test]
fn a_restarted_agent_is_rewired_with_its_registration_and_its_sources_are_asked() {
    let mut b = two();
    b.register("r2", 103, &["in"], &[]);
    ok(b.connect("t1/tick", "r1/in"));
    ok(b.connect("r1/out", "r2/in"));
    b.died("r1", 102);
    // back under a new pid: its own input's edge travels in the reply, and
    // r2 is asked to subscribe to it again
    let (r, fx) = b.register("r1", 202, &["in"], &["out"]);
    let RouterReply::Registered { first, .. } = r else { panic!("{r:?}") };
    assert!(
        matches!(&first[..], [AgentCommand::Connect { input, from_agent, .. }] if input == "in" && from_agent == "t1")
    );
    let s = sends(&fx);
    assert!(
        matches!(&s[..], [(_, agent, AgentCommand::Connect { from_agent, .. })] if agent == "r2" && from_agent == "r1"),
        "{s:?}"
    );
}

#[test]
fn what_was_set_at_run_time_is_re_applied_to_a_restarted_agent_suspend_first() {
    let mut b = two();
    ok(b.connect("t1/tick", "r1/in"));
    for (req, what) in [
        (CliRequest::Suspend { name: "r1".into() }, "suspend"),
        (CliRequest::ParamSet { name: "r1".into(), key: "gain".into(), value: "2".into() }, "set"),
        (CliRequest::Rate { name: "r1".into(), period_ns: 20_000_000 }, "rate"),
    ] {
        let (id, fx) = b.cli(req);
        let fx = b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Ok));
        assert!(matches!(reply(&fx, id), Some(RouterReply::Ok)), "{what}");
    }
    assert_eq!(b.core.registry.get("r1").map(|e| e.state), Some(AgentState::Suspended));
    b.died("r1", 102);
    let (r, fx) = b.register("r1", 202, &["in"], &["out"]);
    let RouterReply::Registered { first, .. } = r else { panic!("{r:?}") };
    assert!(first.is_empty(), "its connections wait behind the suspend");
    let cmds: Vec<AgentCommand> = sends(&fx).into_iter().map(|(_, _, c)| c).collect();
    assert!(matches!(cmds[0], AgentCommand::Suspend), "{cmds:?}");
    assert!(matches!(&cmds[1], AgentCommand::ParamSet { key, value } if key == "gain" && value == "2"));
    assert!(matches!(cmds[2], AgentCommand::SetPeriod { period_ns: 20_000_000 }));
    assert!(matches!(cmds[3], AgentCommand::Connect { .. }));
    // the agent obeys the suspend: recorded
    let t = sends(&fx)[0].0;
    b.answer(t, "r1", Ok(AgentReply::Ok));
    assert_eq!(b.core.registry.get("r1").map(|e| e.state), Some(AgentState::Suspended));
}

#[test]
fn commands_are_answered_with_what_the_agent_said() {
    let mut b = two();
    let (id, fx) = b.cli(CliRequest::ParamGet { name: "r1".into(), key: "gain".into() });
    let fx = b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Param("1.5".into())));
    assert!(matches!(reply(&fx, id), Some(RouterReply::Param(v)) if v == "1.5"));
    let (id, fx) = b.cli(CliRequest::ParamList { name: "r1".into() });
    let fx = b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Params(vec![])));
    assert!(matches!(reply(&fx, id), Some(RouterReply::Params(v)) if v.is_empty()));
    let (id, fx) = b.cli(CliRequest::Resume { name: "r1".into() });
    let fx = b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Ok));
    ok(reply(&fx, id));
    // a refused value is the agent's message
    let (id, fx) = b.cli(CliRequest::ParamSet { name: "r1".into(), key: "gain".into(), value: "-1".into() });
    let refused = RouterError::AgentRefused { name: "r1".into(), message: "gain is in (0, 5]".into() };
    let fx = b.answer(sends(&fx)[0].0, "r1", Err(refused));
    assert!(error(reply(&fx, id)).to_string().contains("gain is in (0, 5]"));
    assert!(b.core.remembered.get("r1").is_none_or(|m| m.params.is_empty()), "a refused value is not remembered");
    // an agent that is not running
    let (id, fx) = b.cli(CliRequest::Rate { name: "zz".into(), period_ns: 1 });
    assert!(matches!(error(reply(&fx, id)), RouterError::UnknownAgent { .. }));
    assert!(sends(&fx).is_empty());
}

#[test]
fn a_hung_agent_delays_its_own_commands_only() {
    let mut b = two();
    let (hung_id, fx) = b.cli(CliRequest::Suspend { name: "r1".into() });
    let hung_ticket = sends(&fx)[0].0;
    // meanwhile `ps` is served: the hung agent shows unresponsive
    let (ps_id, fx) = b.cli(CliRequest::Ps);
    let mut last = Vec::new();
    for (ticket, agent, _) in sends(&fx) {
        if agent == "t1" {
            last = b.answer(ticket, "t1", Ok(AgentReply::Stats(AgentStats::default())));
        }
    }
    assert!(reply(&last, ps_id).is_none(), "ps waits for r1's statistics (or their time-out)");
    let stats_ticket = sends(&fx).iter().find(|s| s.1 == "r1").map(|s| s.0).expect("r1 asked");
    let late = RouterError::AgentUnreachable { name: "r1".into(), detail: "no reply within 300ms".into() };
    let fx = b.answer(stats_ticket, "r1", Err(late));
    match reply(&fx, ps_id) {
        Some(RouterReply::Agents(v)) => {
            let states: Vec<(String, AgentState)> = v.into_iter().map(|a| (a.name, a.state)).collect();
            assert_eq!(states, [("r1".into(), AgentState::Unresponsive), ("t1".into(), AgentState::Running)]);
        }
        other => panic!("{other:?}"),
    }
    // the suspend times out: an error, and r1 is not marked suspended
    let late = RouterError::AgentUnreachable { name: "r1".into(), detail: "no reply within 1s".into() };
    let fx = b.answer(hung_ticket, "r1", Err(late));
    assert!(matches!(error(reply(&fx, hung_id)), RouterError::AgentUnreachable { .. }));
    assert_eq!(b.core.registry.get("r1").map(|e| e.state), Some(AgentState::Running));
}

#[test]
fn graph_and_agent_show_the_connections_and_one_agent() {
    let mut b = two();
    ok(b.connect("t1/tick", "r1/in"));
    let (id, fx) = b.cli(CliRequest::Graph);
    let mut last = Vec::new();
    for (ticket, agent, _) in sends(&fx) {
        last = b.answer(ticket, &agent, Ok(AgentReply::Stats(AgentStats::default())));
    }
    match reply(&last, id) {
        Some(RouterReply::Graph(g)) => {
            assert_eq!(g.agents.len(), 2);
            assert_eq!(g.connections.len(), 1);
            assert_eq!((g.connections[0].from.as_str(), g.connections[0].to.as_str()), ("t1/tick", "r1/in"));
        }
        other => panic!("{other:?}"),
    }
    let (id, fx) = b.cli(CliRequest::Agent { name: "t1".into() });
    let fx = b.answer(sends(&fx)[0].0, "t1", Ok(AgentReply::Stats(AgentStats::default())));
    assert!(matches!(reply(&fx, id), Some(RouterReply::Agents(v)) if v.len() == 1 && v[0].name == "t1"));
    // with no agent at all, ps is answered at once
    let mut empty = Bench::new();
    let (id, fx) = empty.cli(CliRequest::Ps);
    assert!(matches!(reply(&fx, id), Some(RouterReply::Agents(v)) if v.is_empty()));
}

#[test]
fn a_dead_agent_is_restarted_with_back_off_then_marked_failed() {
    let mut b = two();
    let (id, fx) = b.cli(CliRequest::Supervise(supervision("r1", RestartPolicy::OnFailure, 2)));
    ok(reply(&fx, id));
    assert!(fx.iter().any(|e| matches!(e, Effect::Write { path, .. } if path.ends_with("supervision.json"))));
    let mut pid = 102;
    for delay_ms in [100, 200] {
        b.died("r1", pid);
        b.after(Duration::from_millis(delay_ms - 1));
        assert!(spawns(&b.handle(Input::Tick)).is_empty(), "not before its back-off");
        b.after(Duration::from_millis(1));
        let s = spawns(&b.handle(Input::Tick));
        assert_eq!(
            s,
            vec![("r1".into(), supervision("r1", RestartPolicy::OnFailure, 2).argv, Some("/launched/here".into()))]
        );
        pid += 100;
        b.register("r1", pid, &["in"], &["out"]);
    }
    // a third death within the window: failed, saved, not restarted
    let fx = b.died("r1", pid);
    assert!(fx.iter().any(|e| matches!(e, Effect::Write { .. })), "the failure is saved");
    b.after(Duration::from_secs(5));
    assert!(spawns(&b.handle(Input::Tick)).is_empty());
    let views = b.ps(&[]);
    let r1 = views.iter().find(|a| a.name == "r1").expect("shown");
    assert_eq!((r1.state, r1.restarts, r1.pid), (AgentState::Failed, 2, 0));
    assert_eq!(r1.log_file.as_deref(), Some("/logs/r/r1.log"));
}

#[test]
fn a_restart_whose_start_fails_counts_as_a_death() {
    let mut b = two();
    b.cli(CliRequest::Supervise(supervision("r1", RestartPolicy::OnFailure, 5)));
    b.died("r1", 102);
    b.after(Duration::from_millis(100));
    assert_eq!(spawns(&b.handle(Input::Tick)).len(), 1);
    b.handle(Input::StartFailed { name: "r1".into() });
    // restarted again, after twice the back-off
    b.after(Duration::from_millis(199));
    assert!(spawns(&b.handle(Input::Tick)).is_empty());
    b.after(Duration::from_millis(1));
    assert_eq!(spawns(&b.handle(Input::Tick)).len(), 1);
}

#[test]
fn a_clean_exit_or_a_stop_is_not_restarted_and_a_stop_cancels_a_pending_restart() {
    let mut b = two();
    b.cli(CliRequest::Supervise(supervision("t1", RestartPolicy::OnFailure, 5)));
    b.cli(CliRequest::Supervise(supervision("r1", RestartPolicy::Always, 5)));
    // t1 leaves cleanly: not a failure
    let id = b.id();
    let fx = b.handle(Input::Unregister { id, name: "t1".into(), pid: 101 });
    ok(reply(&fx, id));
    assert!(b.events().contains(&EventKind::Left { agent: "t1".into(), pid: 101 }));
    // r1 is stopped by the user and obeys
    let (id, fx) = b.cli(CliRequest::Stop { name: "r1".into() });
    let fx = b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Ok));
    ok(reply(&fx, id));
    assert!(fx.iter().any(|e| matches!(e, Effect::Write { .. })), "the stop is saved");
    b.handle(Input::Unregister { id: 999, name: "r1".into(), pid: 102 });
    b.after(Duration::from_secs(20));
    assert!(spawns(&b.handle(Input::Tick)).is_empty());
    // a restart pending: `stop` cancels it, and says the agent is not running
    let mut b = two();
    b.cli(CliRequest::Supervise(supervision("r1", RestartPolicy::Always, 5)));
    b.died("r1", 102);
    let (id, fx) = b.cli(CliRequest::Stop { name: "r1".into() });
    assert!(matches!(error(reply(&fx, id)), RouterError::UnknownAgent { .. }));
    b.after(Duration::from_secs(20));
    assert!(spawns(&b.handle(Input::Tick)).is_empty());
}

#[test]
fn a_kill_is_answered_when_the_process_is_gone() {
    let mut b = two();
    let (id, fx) = b.cli(CliRequest::Kill { name: "r1".into() });
    let Some(ticket) = fx.iter().find_map(|e| match e {
        Effect::Kill { ticket, name, process } if name == "r1" && process.pid() == 102 => Some(*ticket),
        _ => None,
    }) else {
        panic!("{fx:?}")
    };
    assert!(reply(&fx, id).is_none());
    b.died("r1", 102);
    ok(reply(&b.handle(Input::Killed { ticket, result: Ok(false) }), id));
    // one that cannot be signalled
    let (id, fx) = b.cli(CliRequest::Kill { name: "t1".into() });
    let ticket = fx.iter().find_map(|e| if let Effect::Kill { ticket, .. } = e { Some(*ticket) } else { None });
    let fx =
        b.handle(Input::Killed { ticket: ticket.expect("a kill"), result: Err(RouterError::Internal("EPERM".into())) });
    assert!(matches!(error(reply(&fx, id)), RouterError::Internal(m) if m == "EPERM"));
    let (id, fx) = b.cli(CliRequest::Kill { name: "zz".into() });
    assert!(matches!(error(reply(&fx, id)), RouterError::UnknownAgent { .. }));
}

#[test]
fn shutdown_removes_the_supervision_list_and_restarts_nothing_more() {
    let mut b = two();
    b.cli(CliRequest::Supervise(supervision("r1", RestartPolicy::Always, 5)));
    let (id, fx) = b.cli(CliRequest::Shutdown);
    ok(reply(&fx, id));
    assert!(fx.iter().any(|e| matches!(e, Effect::Remove { path } if path.ends_with("supervision.json"))));
    assert!(b.core.stopped());
    b.died("r1", 102);
    b.after(Duration::from_secs(20));
    assert!(spawns(&b.handle(Input::Tick)).is_empty());
}

#[test]
fn a_tools_edge_goes_with_the_tool_and_is_never_saved() {
    let mut b = two();
    let attach =
        CliRequest::Attach { from: p("cli-7/in"), pid: 7, type_name: T.into(), fingerprint: 7, to: p("r1/in") };
    let (id, fx) = b.cli(attach.clone());
    let fx = b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Ok));
    ok(reply(&fx, id));
    assert!(saves(&fx).is_empty());
    assert_eq!(b.core.transient.connections().count(), 1);
    // the tool is killed: r1 is told to let go
    let fx = b.handle(Input::Liveness { dead: vec![], gone_tools: vec![7] });
    let s = sends(&fx);
    assert!(
        matches!(&s[..], [(_, a, AgentCommand::Disconnect { from_agent, .. })] if a == "r1" && from_agent == "cli-7"),
        "{s:?}"
    );
    assert!(b.core.transient.is_empty());
    // a tool whose process is not there
    let id = b.id();
    let fx = b.handle(Input::Cli { id, req: attach, tool: Some(Err("gone".into())) });
    assert!(error(reply(&fx, id)).to_string().contains("is not there"));
    // an agent's port is connected, not attached
    let agent = CliRequest::Attach { from: p("t1/tick"), pid: 7, type_name: T.into(), fingerprint: 7, to: p("r1/in") };
    let (id, fx) = b.cli(agent);
    assert!(error(reply(&fx, id)).to_string().contains("nerve connect"));
    // detach of an edge it made: r1 lets go
    let attach =
        CliRequest::Attach { from: p("cli-8/in"), pid: 8, type_name: T.into(), fingerprint: 7, to: p("r1/in") };
    let (_, fx) = b.cli(attach);
    b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Ok));
    let (id, fx) = b.cli(CliRequest::Detach { from: p("cli-8/in"), to: p("r1/in") });
    let fx = b.answer(sends(&fx)[0].0, "r1", Ok(AgentReply::Ok));
    ok(reply(&fx, id));
    assert!(b.core.transient.is_empty());
}

#[test]
fn the_list_loaded_at_start_is_made_when_its_agents_register() {
    let kept = Connection { from: p("t1/tick"), to: p("r1/in"), type_name: T.into(), allow_cycle: false };
    let mut b = Bench::with(vec![kept]);
    let (_, fx) = b.register("t1", 101, &[], &["tick"]);
    assert!(sends(&fx).is_empty(), "its input agent is not there yet");
    let (r, _) = b.register("r1", 102, &["in"], &["out"]);
    assert!(matches!(r, RouterReply::Registered { first, .. } if first.len() == 1));
}

fn waited(r: Option<RouterReply>) -> Vec<String> {
    match r {
        Some(RouterReply::Waited { missing }) => missing,
        other => panic!("not an answer to a wait: {other:?}"),
    }
}

#[test]
fn a_wait_for_registrations_is_answered_when_all_are_there_or_the_time_is_up() {
    let mut b = Bench::new();
    let names = vec!["t1".to_owned(), "r1".to_owned()];
    let (id, fx) = b.cli(CliRequest::WaitRegistered { names, timeout_ns: 5_000_000_000 });
    assert!(reply(&fx, id).is_none());
    assert!(!b.core.busy(), "nothing to poll for while agents start");
    let (_, fx) = b.register("t1", 101, &[], &["tick"]);
    assert!(reply(&fx, id).is_none(), "r1 is not there yet");
    let (_, fx) = b.register("r1", 102, &["in"], &["out"]);
    assert!(waited(reply(&fx, id)).is_empty());
    // the time is up: those missing are named
    let (id, _) =
        b.cli(CliRequest::WaitRegistered { names: vec!["r1".into(), "zz".into()], timeout_ns: 1_000_000_000 });
    b.after(Duration::from_millis(999));
    assert!(reply(&b.handle(Input::Tick), id).is_none());
    b.after(Duration::from_millis(1));
    assert_eq!(waited(reply(&b.handle(Input::Tick), id)), ["zz"]);
    // an agent that died while starting and is restarting is in its
    // supervisor's hands: not waited for; one that died for good is
    b.cli(CliRequest::Supervise(supervision("r1", RestartPolicy::Always, 5)));
    b.died("r1", 102);
    b.died("t1", 101);
    let (id, fx) = b.cli(CliRequest::WaitRegistered { names: vec!["r1".into()], timeout_ns: u64::MAX });
    assert!(waited(reply(&fx, id)).is_empty());
    let (id, fx) = b.cli(CliRequest::WaitRegistered { names: vec!["t1".into()], timeout_ns: u64::MAX });
    assert!(reply(&fx, id).is_none());
    // a huge time-out is capped
    b.after(MAX_WAIT_REGISTERED);
    assert_eq!(waited(reply(&b.handle(Input::Tick), id)), ["t1"]);
    // a shutdown answers every wait
    let (id, _) = b.cli(CliRequest::WaitRegistered { names: vec!["t1".into()], timeout_ns: 1_000_000_000 });
    let (_, fx) = b.cli(CliRequest::Shutdown);
    assert_eq!(waited(reply(&fx, id)), ["t1"]);
    assert!(b.core.stopped());
}

fn start_spec(name: &str, supervise: bool) -> StartSpec {
    StartSpec {
        agent: supervision(name, RestartPolicy::OnFailure, 3),
        supervise,
        env: Some(vec![("NERVE_SIM_CLOCK".into(), "/state/r/sim-clock".into())]),
    }
}

/// The asked starts among `effects`: (ticket, name, argv, cwd, env).
#[allow(clippy::type_complexity)]
fn starts(effects: &[Effect]) -> Vec<(Ticket, String, Vec<String>, Option<String>, Option<Vec<(String, String)>>)> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::Start { ticket, name, argv, cwd, env } => {
                Some((*ticket, name.clone(), argv.clone(), cwd.clone(), env.clone()))
            }
            _ => None,
        })
        .collect()
}

fn started(r: Option<RouterReply>) -> Vec<(String, StartResult)> {
    match r {
        Some(RouterReply::Started(v)) => v.into_iter().map(|o| (o.name, o.result)).collect(),
        other => panic!("not Started: {other:?}"),
    }
}

fn ended(ticket: Ticket, name: &str, result: StartResult) -> Input {
    Input::StartEnded(StartEnd { ticket, name: name.into(), result })
}

#[test]
fn a_start_spawns_each_agent_supervises_it_and_answers_when_every_start_up_has_ended() {
    let mut b = Bench::new();
    let (id, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("a1", true), start_spec("a2", true)] });
    assert!(reply(&fx, id).is_none(), "answered only once the start-up processes ended");
    let s = starts(&fx);
    assert_eq!(s.len(), 2, "both started at once: {fx:?}");
    assert_eq!((s[0].1.as_str(), s[1].1.as_str()), ("a1", "a2"));
    assert_eq!(s[0].2, supervision("a1", RestartPolicy::OnFailure, 3).argv);
    assert_eq!(s[0].3.as_deref(), Some("/launched/here"));
    assert_eq!(s[0].4, start_spec("a1", true).env, "the caller's environment goes along");
    assert!(fx.iter().any(|e| matches!(e, Effect::Write { path, .. } if path.ends_with("supervision.json"))));
    assert!(b.core.supervisor.get("a1").is_some(), "handed to supervision first");
    assert!(!b.core.busy(), "a start wakes the router itself: no polling");
    // the second ends first: still waiting for the first
    let fx = b.handle(ended(s[1].0, "a2", StartResult::Started { said: "a2 started (pid 12, robot r)".into() }));
    assert!(reply(&fx, id).is_none());
    b.register("a1", 11, &[], &["out"]);
    let fx = b.handle(ended(s[0].0, "a1", StartResult::Started { said: "a1 started (pid 11, robot r)".into() }));
    assert_eq!(
        started(reply(&fx, id)),
        vec![
            ("a1".into(), StartResult::Started { said: "a1 started (pid 11, robot r)".into() }),
            ("a2".into(), StartResult::Started { said: "a2 started (pid 12, robot r)".into() }),
        ],
        "in the request's order"
    );
    // `nerve start` does not touch supervision
    let (_, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("a3", false)] });
    assert_eq!(starts(&fx).len(), 1);
    assert!(b.core.supervisor.get("a3").is_none());
}

#[test]
fn a_start_of_a_running_agent_spawns_nothing_and_says_so() {
    let mut b = two();
    let (id, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("t1", true)] });
    assert!(starts(&fx).is_empty(), "nothing spawned: {fx:?}");
    assert_eq!(started(reply(&fx, id)), vec![("t1".into(), StartResult::Running { pid: 101 })]);
    assert!(b.core.supervisor.get("t1").is_some(), "its supervision is still renewed, as a launch does");
    // a name being started by another request is not started twice
    let (_, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("a1", false)] });
    let ticket = starts(&fx)[0].0;
    let (id, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("a1", false)] });
    assert!(starts(&fx).is_empty());
    assert!(
        matches!(&started(reply(&fx, id))[0].1, StartResult::Failed { said, .. } if said.contains("being started"))
    );
    b.handle(ended(ticket, "a1", StartResult::Started { said: String::new() }));
    let (_, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("a1", false)] });
    assert_eq!(starts(&fx).len(), 1, "once the first start is over it can be started again");
}

#[test]
fn a_start_that_fails_is_reported_with_the_agents_message_and_is_not_restarted() {
    let mut b = Bench::new();
    let (id, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("a1", true), start_spec("ghost", true)] });
    let s = starts(&fx);
    // the program does not exist: the driver says so at once
    let not_run = StartResult::Failed {
        status: "not run".into(),
        said: "cannot run nerve-ghost: no such program (is it built and on the PATH?)".into(),
    };
    b.handle(ended(s[1].0, "ghost", not_run.clone()));
    // the agent's start failed: its start-up process exited with its message
    let refused =
        StartResult::Failed { status: "exit status 1".into(), said: "error: cannot open /dev/ttyUSB0".into() };
    let fx = b.handle(ended(s[0].0, "a1", refused.clone()));
    assert_eq!(started(reply(&fx, id)), vec![("a1".into(), refused), ("ghost".into(), not_run)]);
    // no death for supervision: nothing is restarted later
    b.after(Duration::from_secs(30));
    let fx = b.handle(Input::Tick);
    assert!(spawns(&fx).is_empty() && starts(&fx).is_empty(), "{fx:?}");
    // an invalid spec refuses the whole request before anything starts
    let mut bad = start_spec("../x", true);
    bad.agent.name = "../x".into();
    let (id, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("ok", true), bad] });
    assert!(matches!(error(reply(&fx, id)), RouterError::InvalidName(_)));
    assert!(starts(&fx).is_empty() && b.core.supervisor.get("ok").is_none());
    let (id, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("d", false), start_spec("d", false)] });
    assert!(matches!(error(reply(&fx, id)), RouterError::InvalidName(m) if m.contains("twice")));
    assert!(starts(&fx).is_empty());
}

#[test]
fn a_started_agent_that_dies_before_registering_is_a_failed_start_and_no_launch_waits_for_it() {
    let mut b = Bench::new();
    let (id, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("a1", true)] });
    let ticket = starts(&fx)[0].0;
    // a launch waits for it to register meanwhile
    let (wait, fx) = b.cli(CliRequest::WaitRegistered { names: vec!["a1".into()], timeout_ns: 5_000_000_000 });
    assert!(reply(&fx, wait).is_none());
    // its start-up process saw it die (SIGSEGV in `start`) before it registered
    let crashed = StartResult::Failed {
        status: "exit status 1".into(),
        said: "error: the agent exited during start-up (killed by SIGSEGV); see its log /logs/r/a1.log".into(),
    };
    let fx = b.handle(ended(ticket, "a1", crashed.clone()));
    assert_eq!(started(reply(&fx, id)), vec![("a1".into(), crashed)]);
    assert!(b.core.registry.get("a1").is_none());
    assert!(b.events().is_empty(), "it never registered, so it never died for the router");
    // the wait ends at its time-out naming it (the launch does not ask for a failed start)
    b.after(Duration::from_secs(5));
    let fx = b.handle(Input::Tick);
    assert!(matches!(reply(&fx, wait), Some(RouterReply::Waited { missing }) if missing == vec!["a1".to_owned()]));
    assert!(spawns(&fx).is_empty(), "not restarted: its start failed, it did not die");
}

#[test]
fn a_stopping_router_starts_nothing() {
    let mut b = Bench::new();
    let (id, _) = b.cli(CliRequest::Shutdown);
    let _ = id;
    let (id, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("a1", true)] });
    assert!(matches!(error(reply(&fx, id)), RouterError::NotApplicable(m) if m.contains("stopping")));
    assert!(starts(&fx).is_empty());
}

#[test]
fn a_restart_gets_the_environment_its_launch_started_the_agent_with() {
    let mut b = Bench::new();
    let (_, fx) = b.cli(CliRequest::Start { agents: vec![start_spec("a1", true)] });
    b.register("a1", 11, &[], &["out"]);
    b.handle(ended(starts(&fx)[0].0, "a1", StartResult::Started { said: String::new() }));
    b.died("a1", 11);
    b.after(Duration::from_millis(100));
    let fx = b.handle(Input::Tick);
    let env: Vec<_> = fx
        .iter()
        .filter_map(|e| match e {
            Effect::Spawn { name, env, .. } if name == "a1" => Some(env.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(env, vec![start_spec("a1", true).env], "the restart runs in the launch's environment (its clock...)");
    // supervised again without a start (an older launcher): the router's own
    b.cli(CliRequest::Supervise(supervision("a1", RestartPolicy::OnFailure, 3)));
    assert_eq!(b.core.supervisor.get("a1").and_then(|s| s.env.clone()), None);
}
