//! What was set at run time for each agent name, so that an agent that
//! registers again under that name (restarted by the supervisor, or by hand)
//! gets it back: its suspend state (`nerve suspend` / `nerve resume`), its
//! period (`nerve rate`) and the parameters set through the router
//! (`nerve param set`, the decision maker's weights).
//!
//! Without it a restarted `motor` came back with its default weights and a
//! restarted `wall-follow` ran unsuspended in a mode that suspends it, until
//! the next mode change.
//!
//! Only what the agent accepted is remembered; the last value wins, and it
//! wins over the new agent's command line (`--suspended`, `--period`,
//! `--param`): an agent stopped with `nerve stop` and started again gets it
//! too, since a robot in a mode that sets weights or suspends an agent
//! needs them whatever way the agent came back. The router logs each value
//! it re-applies (`re-applied to NAME: ...`); change it with `nerve resume`,
//! `nerve rate` or `nerve param set` as usual. The memory lives as long as
//! the router: a restarted router starts empty (the decision maker then
//! sends its mode again).
//!
//! Growth is bounded:
//! * at most [`MAX_PARAMS`] parameters per name (later keys are applied to
//!   the running agent but not remembered, with a warning);
//! * at most [`MAX_NAMES`] names: a new name evicts the one gone longest;
//! * a name that has not been live for [`FORGET_AFTER`] is forgotten.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// The most names whose run-time state is remembered.
pub const MAX_NAMES: usize = 1024;
/// The most parameters remembered per name.
pub const MAX_PARAMS: usize = 64;
/// How long the state of a name that is no longer live is kept.
pub const FORGET_AFTER: Duration = Duration::from_secs(7 * 24 * 3600);

/// The run-time state set for one agent name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunState {
    /// `Some(true)`: suspended on request; `Some(false)`: resumed on request.
    pub suspended: Option<bool>,
    /// The period set with `nerve rate`.
    pub period_ns: Option<u64>,
    /// Parameters set through the router, by key.
    pub params: BTreeMap<String, String>,
    /// When an agent of this name was last known live.
    pub last_seen: Instant,
}

impl RunState {
    fn new(now: Instant) -> Self {
        RunState { suspended: None, period_ns: None, params: BTreeMap::new(), last_seen: now }
    }

    /// Whether nothing is remembered.
    pub fn is_empty(&self) -> bool {
        self.suspended.is_none() && self.period_ns.is_none() && self.params.is_empty()
    }
}

/// The run-time state of every name, bounded as the module says.
#[derive(Debug, Default)]
pub struct Remembered {
    names: BTreeMap<String, RunState>,
}

impl Remembered {
    /// The state remembered for `name`.
    pub fn get(&self, name: &str) -> Option<&RunState> {
        self.names.get(name)
    }

    /// How many names have a memory.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Whether no name has a memory.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    fn entry(&mut self, name: &str, now: Instant) -> &mut RunState {
        if !self.names.contains_key(name)
            && self.names.len() >= MAX_NAMES
            && let Some(oldest) = self.names.iter().min_by_key(|(_, s)| s.last_seen).map(|(n, _)| n.clone())
        {
            tracing::info!("forgetting the run-time state of {oldest}: {MAX_NAMES} names are remembered at most");
            self.names.remove(&oldest);
        }
        let s = self.names.entry(name.to_owned()).or_insert_with(|| RunState::new(now));
        s.last_seen = now;
        s
    }

    /// `name` was suspended (`true`) or resumed (`false`) on request.
    pub fn set_suspended(&mut self, name: &str, suspended: bool, now: Instant) {
        self.entry(name, now).suspended = Some(suspended);
    }

    /// `name`'s period was set.
    pub fn set_period(&mut self, name: &str, period_ns: u64, now: Instant) {
        self.entry(name, now).period_ns = Some(period_ns);
    }

    /// `name` accepted `key = value`; `false` when it is not remembered
    /// because `name` has [`MAX_PARAMS`] other parameters remembered.
    pub fn set_param(&mut self, name: &str, key: &str, value: &str, now: Instant) -> bool {
        let s = self.entry(name, now);
        if !s.params.contains_key(key) && s.params.len() >= MAX_PARAMS {
            return false;
        }
        s.params.insert(key.to_owned(), value.to_owned());
        true
    }

    /// An agent of `name` is live at `now`.
    pub fn seen(&mut self, name: &str, now: Instant) {
        if let Some(s) = self.names.get_mut(name) {
            s.last_seen = now;
        }
    }

    /// Forgets the names not live (`live` says which are) and not seen for
    /// [`FORGET_AFTER`] before `now`; returns them.
    pub fn forget_gone(&mut self, now: Instant, live: impl Fn(&str) -> bool) -> Vec<String> {
        let gone: Vec<String> = self
            .names
            .iter()
            .filter(|(n, s)| !live(n) && now.saturating_duration_since(s.last_seen) > FORGET_AFTER)
            .map(|(n, _)| n.clone())
            .collect();
        for n in &gone {
            self.names.remove(n);
        }
        gone
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_last_value_is_remembered_per_name_and_key() {
        let now = Instant::now();
        let mut m = Remembered::default();
        m.set_suspended("wf", true, now);
        m.set_period("wf", 500_000_000, now);
        m.set_param("motor", "weights", "safety:1", now);
        m.set_param("motor", "weights", "safety:4,tracker:0", now);
        m.set_suspended("wf", false, now);
        let wf = m.get("wf").expect("wf remembered");
        assert_eq!((wf.suspended, wf.period_ns), (Some(false), Some(500_000_000)));
        assert_eq!(m.get("motor").map(|s| s.params["weights"].as_str()), Some("safety:4,tracker:0"));
    }

    #[test]
    fn growth_is_bounded_by_names_params_and_age() {
        let t0 = Instant::now();
        let mut m = Remembered::default();
        for i in 0..MAX_NAMES + 10 {
            m.set_suspended(&format!("a{i}"), true, t0 + Duration::from_millis(i as u64));
        }
        assert_eq!(m.len(), MAX_NAMES);
        // the ones gone longest were evicted
        assert!(m.get("a0").is_none() && m.get(&format!("a{}", MAX_NAMES + 9)).is_some());
        for k in 0..MAX_PARAMS {
            assert!(m.set_param("p", &format!("k{k}"), "1", t0));
        }
        assert!(!m.set_param("p", "one-more", "1", t0), "a parameter beyond the cap is not remembered");
        assert!(m.set_param("p", "k0", "2", t0), "a known key is still updated");
        // names gone for long are forgotten, live ones kept however old
        let later = t0 + FORGET_AFTER + Duration::from_secs(3600);
        let gone = m.forget_gone(later, |n| n == "p");
        assert_eq!(gone.len(), MAX_NAMES - 1);
        assert!(m.get("p").is_some() && m.len() == 1);
    }
}
