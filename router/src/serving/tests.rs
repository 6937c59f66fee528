//! The router's core driven directly: every request it serves and every
//! fault the end-to-end tests inject (an agent that dies mid-connect, a
//! refusal, a restart with back-off until it is marked failed, a hung agent,
//! a stale registration, a tool that goes away), with no process, no shared
//! memory and no clock: time is what each input says.
//!
//! Here the driver ([`Bench`]) and registrations; connections in
//! [`connections`], commands in [`commands`], restarts in [`supervision`],
//! waits and starts in [`starts`].

mod commands;
mod connections;
mod starts;
mod supervision;

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
