//! What wakes an event-driven task, end to end: eight tickers feed one
//! agent (`nerve-fanin`, `tests/src/bin/fanin.rs`) through real processes
//! and shared memory. Nothing is lost, the task is never re-entered, every
//! step was woken by an input, and the step knows which
//! (`Context::has_new`, `Context::woken_by`, filled by the SDK's event loop).

use nerve_tests::{Robot, wait_until};
use std::time::Duration;

const PERIODS: [&str; 8] = ["3ms", "5ms", "7ms", "11ms", "13ms", "17ms", "19ms", "23ms"];

#[test]
fn fan_in_from_eight_sources_loses_nothing_never_reenters_and_knows_what_woke_it() {
    let r = Robot::new("fanin");
    r.router();
    r.ok(&["start", "fanin", "--name", "f"]);
    // the tickers send nothing until every edge is in place: every sample they
    // send has a reader
    for (k, p) in PERIODS.iter().enumerate() {
        r.ok(&["start", "ticker", "--name", &format!("t{k}"), "--period", p, "--suspended"]);
        r.ok(&["connect", &format!("t{k}/tick"), &format!("f/in{k}")]);
    }
    for k in 0..PERIODS.len() {
        r.ok(&["resume", &format!("t{k}")]);
    }
    std::thread::sleep(Duration::from_millis(1500));
    for k in 0..PERIODS.len() {
        r.ok(&["suspend", &format!("t{k}")]);
    }
    // the last samples drained: the step count settles
    let mut last = u64::MAX;
    assert!(
        wait_until(Duration::from_secs(5), || {
            let now = r.figure_u64("f", "steps");
            let settled = now == last;
            last = now;
            std::thread::sleep(Duration::from_millis(150));
            settled
        }),
        "the fan-in agent kept stepping after every source was suspended"
    );
    let f = r.figures("f");
    let get = |k: &str| f.get(k).and_then(|v| v.parse::<u64>().ok()).unwrap_or_else(|| panic!("figure {k}: {f:?}"));
    for (k, period) in PERIODS.iter().enumerate() {
        let sent = r.agent(&format!("t{k}")).and_then(|a| a["stats"]["cycles"].as_u64()).expect("ticker cycles");
        assert!(sent > 30, "t{k} ({period}) sent only {sent} samples");
        assert_eq!(get(&format!("samples_{k}")), sent, "in{k} lost samples of t{k}: {f:?}");
        let new = get(&format!("new_{k}"));
        assert!(new >= 1 && new <= sent, "in{k} was said new in {new} steps for {sent} samples: {f:?}");
    }
    assert_eq!(get("overlap"), 0, "the task was re-entered: {f:?}");
    assert_eq!(get("woken_by_none"), 0, "a step ran that no input woke: {f:?}");
    // the fastest two sources, 3 and 5 ms, each woke steps on their own: the
    // step tells them apart
    assert!(get("only_0") > 0 && get("only_1") > 0, "{f:?}");
    r.down_and_check_clean();
}
