//! The router's core and the commands it relays to agents: answered with
//! what the agent said, a hung agent delaying only its own commands, and
//! the graph and agent views.

use super::*;

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
