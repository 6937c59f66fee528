//! The router's core as the one that starts agents: a wait for
//! registrations, starts spawned and supervised and answered when every
//! start-up has ended, a start that fails or whose agent dies before
//! registering, a stopping router, and the environment a restart gets.

use super::*;

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
