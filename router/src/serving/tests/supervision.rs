//! The router's core as supervisor: a dead agent restarted with back-off
//! until it is marked failed, a restart whose start fails, a clean exit or
//! a stop (not restarted), a kill, and shutdown.

use super::*;

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
