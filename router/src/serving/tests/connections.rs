//! The router's core and connections: a connect saved once after the agent
//! subscribed, refusals (types, unknown ports, loops, the agent's own), an
//! agent that dies mid-connect, disconnects, rewiring a restarted agent and
//! re-applying what was set at run time, a tool's edges, and the list
//! loaded at start.

use super::*;

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
