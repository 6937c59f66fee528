//! The decision itself: the situation from the agents' reports, the table
//! look-up in the knowledge base, the hysteresis that keeps a mode from
//! flickering, and the actions a mode asks for.
//!
//! * [`Reports`] keeps the newest [`Situation`] of every sender and the newest
//!   resource manager's report's [`ResourceHeader`] (`nerve::ResourceReport`'s
//!   header; the decision needs its load level, not each agent's load);
//!   [`Reports::facts`] folds the fresh ones into
//!   [`Facts`]: the worst danger any fresh report gives, the best target
//!   state, the load level. A variable no fresh report speaks about is
//!   *unknown*, and the rules say what unknown means (a silent safety monitor
//!   should count as danger).
//! * [`lookup`] is the table look-up of the thesis (section 3.2.5): the first
//!   `[[rule]]` whose every condition holds selects the mode.
//! * [`Arbiter`] applies the mode: a change waits until the current mode has
//!   held `min_dwell`, unless the new mode is `urgent`.
//! * [`actions`] lists what entering a mode does, in the order it is done:
//!   weights first (so that a source resumed next has its weight already),
//!   then resumes, periods and suspends.

use crate::kb::{Condition, KnowledgeBase, ModeSpec, UNKNOWN, Variable};
use shm_schemas::payloads::{DangerLevel, LoadLevel, ResourceHeader, Situation, TargetState};
use std::collections::BTreeMap;
use std::time::Duration;

/// The situation, as the decision maker knows it now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Facts {
    /// The worst fresh danger level; `None`: no fresh danger report.
    pub danger: Option<DangerLevel>,
    /// The best fresh target state; `None`: no fresh target report.
    pub target: Option<TargetState>,
    /// The fresh load level; `None`: no fresh resource report.
    pub load: Option<LoadLevel>,
}

impl Facts {
    /// The value of `v` by name (`unknown` when not known).
    pub fn value(&self, v: Variable) -> &'static str {
        match v {
            Variable::Danger => self.danger.map_or(UNKNOWN, DangerLevel::name),
            Variable::Target => self.target.map_or(UNKNOWN, TargetState::name),
            Variable::Load => self.load.map_or(UNKNOWN, LoadLevel::name),
        }
    }

    fn holds(&self, c: &Condition) -> bool {
        let v = self.value(c.variable);
        c.values.iter().any(|x| x == v)
    }
}

impl std::fmt::Display for Facts {
    /// `target seen, danger low, load normal`
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "target {}, danger {}, load {}",
            self.value(Variable::Target),
            self.value(Variable::Danger),
            self.value(Variable::Load)
        )
    }
}

/// The table look-up: the index and mode of the first rule whose conditions all hold.
pub fn lookup<'a>(kb: &'a KnowledgeBase, facts: &Facts) -> Option<(usize, &'a ModeSpec)> {
    kb.rules
        .iter()
        .enumerate()
        .find(|(_, r)| r.when.iter().all(|c| facts.holds(c)))
        .and_then(|(i, r)| kb.modes.get(&r.mode).map(|m| (i, m)))
}

/// The most senders whose situation is kept at once; a new sender beyond
/// it replaces the one heard from longest ago.
pub const MAX_SENDERS: usize = 256;

/// The newest reports, by sender, with the time they arrived.
///
/// Bounded: a report that is no longer fresh counts for nothing, so
/// [`Reports::forget_stale`] drops it, and at most [`MAX_SENDERS`] senders
/// are kept (a sender renamed at every restart, or many short-lived ones,
/// grew the map without end).
#[derive(Debug, Clone, Default)]
pub struct Reports {
    situations: BTreeMap<String, (u64, Situation)>,
    load: Option<(u64, ResourceHeader)>,
}

impl Reports {
    /// Keeps `s`, received from `sender` at `now_ns`.
    pub fn situation(&mut self, sender: &str, s: Situation, now_ns: u64) {
        if !self.situations.contains_key(sender)
            && self.situations.len() >= MAX_SENDERS
            && let Some(oldest) = self.situations.iter().min_by_key(|(_, (t, _))| *t).map(|(n, _)| n.clone())
        {
            self.situations.remove(&oldest);
        }
        self.situations.insert(sender.to_owned(), (now_ns, s));
    }

    /// Drops the situations older than `timeout` at `now_ns` (they no longer
    /// count in [`Reports::facts`]).
    pub fn forget_stale(&mut self, now_ns: u64, timeout: Duration) {
        let keep = agent_sdk::clock::nanos(timeout);
        self.situations.retain(|_, (t, _)| now_ns.saturating_sub(*t) <= keep);
    }

    /// How many senders' situations are kept.
    pub fn senders(&self) -> usize {
        self.situations.len()
    }

    /// Keeps the header of the resource manager's report, received at `now_ns`.
    pub fn load(&mut self, r: ResourceHeader, now_ns: u64) {
        self.load = Some((now_ns, r));
    }

    /// The facts from the reports received within `timeout` of `now_ns`.
    pub fn facts(&self, now_ns: u64, timeout: Duration) -> Facts {
        let fresh = |t: u64| now_ns.saturating_sub(t) <= agent_sdk::clock::nanos(timeout);
        let live = || self.situations.values().filter(|(t, _)| fresh(*t)).map(|(_, s)| s);
        Facts {
            danger: live().filter_map(Situation::danger_level).max(),
            target: live().filter_map(Situation::target_state).max(),
            load: self.load.as_ref().filter(|(t, _)| fresh(*t)).and_then(|(_, r)| r.level()),
        }
    }
}

/// A mode change the arbiter accepted.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Change {
    /// The mode left (`none` at the first decision).
    pub from: String,
    /// The mode entered.
    pub to: String,
}

/// Keeps the current mode and decides when it may change.
#[derive(Debug, Clone)]
pub struct Arbiter {
    current: Option<String>,
    since_ns: u64,
    changes: u64,
    min_dwell_ns: u64,
}

impl Arbiter {
    /// No mode yet; a mode holds at least `min_dwell` unless an urgent one comes.
    pub fn new(min_dwell: Duration) -> Self {
        Arbiter { current: None, since_ns: 0, changes: 0, min_dwell_ns: agent_sdk::clock::nanos(min_dwell) }
    }

    /// The current mode.
    pub fn current(&self) -> Option<&str> {
        self.current.as_deref()
    }

    /// Since when the current mode holds.
    pub fn since_ns(&self) -> u64 {
        self.since_ns
    }

    /// How many changes were accepted.
    pub fn changes(&self) -> u64 {
        self.changes
    }

    /// Offers the mode the table selects now; returns the change if it is taken.
    pub fn offer(&mut self, mode: &ModeSpec, now_ns: u64) -> Option<Change> {
        if self.current.as_deref() == Some(mode.name.as_str()) {
            return None;
        }
        let held = now_ns.saturating_sub(self.since_ns);
        if self.current.is_some() && !mode.urgent && held < self.min_dwell_ns {
            return None;
        }
        let from = self.current.replace(mode.name.clone()).unwrap_or_else(|| "none".into());
        self.since_ns = now_ns;
        self.changes += 1;
        Some(Change { from, to: mode.name.clone() })
    }
}

/// One thing entering a mode does, through the router.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Set actuator `actuator`'s `weights` parameter to `text` (`safety:4,tracker:0`).
    Weights {
        /// the actuator agent
        actuator: String,
        /// the parameter's new value
        text: String,
    },
    /// Resume agent.
    Resume(String),
    /// Set agent's period.
    Rate {
        /// the agent
        agent: String,
        /// the period
        period: Duration,
    },
    /// Suspend agent.
    Suspend(String),
}

impl std::fmt::Display for Action {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Action::Weights { actuator, text } => write!(f, "weights of {actuator} = {text}"),
            Action::Resume(a) => write!(f, "resume {a}"),
            Action::Rate { agent, period } => {
                write!(f, "period of {agent} = {}", agent_sdk::clock::format_duration(*period))
            }
            Action::Suspend(a) => write!(f, "suspend {a}"),
        }
    }
}

/// What entering `mode` does, in order: weights, resumes, periods, suspends.
pub fn actions(mode: &ModeSpec) -> Vec<Action> {
    let mut v = Vec::new();
    for (actuator, sources) in &mode.weights {
        let text: Vec<String> = sources.iter().map(|(s, w)| format!("{s}:{w}")).collect();
        v.push(Action::Weights { actuator: actuator.clone(), text: text.join(",") });
    }
    v.extend(mode.resume.iter().cloned().map(Action::Resume));
    v.extend(mode.periods.iter().map(|(a, p)| Action::Rate { agent: a.clone(), period: *p }));
    v.extend(mode.suspend.iter().cloned().map(Action::Suspend));
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    const KB: &str = r#"
[decision]
min_dwell = "1s"
[[rule]]
when = { danger = ["high", "stop", "unknown"] }
mode = "avoid"
[[rule]]
when = { target = ["seen", "close"] }
mode = "track"
[[rule]]
when = { load = "critical" }
mode = "lean"
[[rule]]
mode = "explore"
[modes.avoid]
urgent = true
weights = { motor = { safety = 4, tracker = 0, wall-follow = 0 } }
suspend = ["wall-follow"]
[modes.track]
weights = { motor = { safety = 1, tracker = 3, wall-follow = 0 } }
suspend = ["wall-follow"]
[modes.lean]
periods = { wall-follow = "500ms" }
[modes.explore]
weights = { motor = { safety = 1, tracker = 0, wall-follow = 2 } }
resume = ["wall-follow"]
"#;

    fn kb() -> KnowledgeBase {
        KnowledgeBase::parse(KB, Path::new("t.toml")).expect("valid")
    }

    fn facts(danger: Option<DangerLevel>, target: Option<TargetState>) -> Facts {
        Facts { danger, target, load: Some(LoadLevel::Normal) }
    }

    #[test]
    fn table_look_up_first_match_wins() {
        let kb = kb();
        let mode = |f: Facts| lookup(&kb, &f).map(|(_, m)| m.name.clone()).unwrap_or_default();
        use DangerLevel as D;
        use TargetState as T;
        assert_eq!(mode(facts(Some(D::None), Some(T::None))), "explore");
        assert_eq!(mode(facts(Some(D::Low), Some(T::Seen))), "track");
        // danger and target compete: danger wins (first rule)
        assert_eq!(mode(facts(Some(D::High), Some(T::Seen))), "avoid");
        assert_eq!(mode(facts(Some(D::Stop), Some(T::Close))), "avoid");
        // a silent safety monitor counts as danger
        assert_eq!(mode(facts(None, Some(T::Seen))), "avoid");
        // a silent tracker: no target
        assert_eq!(mode(facts(Some(D::None), None)), "explore");
        let lean = Facts { danger: Some(D::Low), target: Some(T::None), load: Some(LoadLevel::Critical) };
        assert_eq!(mode(lean), "lean");
        assert_eq!(lookup(&kb, &lean).map(|(i, _)| i), Some(2));
    }

    #[test]
    fn reports_fold_into_facts_and_expire() {
        let mut r = Reports::default();
        let s = Duration::from_secs(1);
        assert_eq!(r.facts(0, s), Facts::default());
        r.situation("safety", Situation::danger(DangerLevel::Low, 0.3, 0), 1_000);
        r.situation("safety2", Situation::danger(DangerLevel::High, 0.6, 0), 1_000);
        r.situation("tracker", Situation::target(TargetState::Seen, 0.1, 0.0, 0), 500_000_000);
        r.load(ResourceHeader { level: LoadLevel::High as u8, ..Default::default() }, 1_000);
        let f = r.facts(900_000_000, s);
        assert_eq!(
            (f.danger, f.target, f.load),
            (Some(DangerLevel::High), Some(TargetState::Seen), Some(LoadLevel::High))
        );
        assert_eq!(f.to_string(), "target seen, danger high, load high");
        // 1.2 s later only the tracker's report is fresh
        let f = r.facts(1_200_000_000, s);
        assert_eq!((f.danger, f.target, f.load), (None, Some(TargetState::Seen), None));
        assert_eq!(f.to_string(), "target seen, danger unknown, load unknown");
    }

    #[test]
    fn senders_are_bounded_and_stale_ones_forgotten() {
        let mut r = Reports::default();
        let s = Duration::from_secs(1);
        for i in 0..MAX_SENDERS as u64 + 50 {
            r.situation(&format!("s{i}"), Situation::danger(DangerLevel::Low, 0.3, 0), i);
        }
        assert_eq!(r.senders(), MAX_SENDERS);
        // the newest sender is kept, the oldest went
        r.situation("danger", Situation::danger(DangerLevel::High, 0.3, 0), 1_000);
        assert_eq!(r.senders(), MAX_SENDERS);
        assert_eq!(r.facts(2_000, s).danger, Some(DangerLevel::High));
        r.forget_stale(2_000_000_000, s);
        assert_eq!(r.senders(), 0, "every report is older than the timeout");
        r.situation("safety", Situation::danger(DangerLevel::Low, 0.3, 0), 2_000_000_000);
        r.forget_stale(2_500_000_000, s);
        assert_eq!(r.senders(), 1);
    }

    #[test]
    fn arbiter_dwells_unless_urgent() {
        let kb = kb();
        let mut a = Arbiter::new(kb.decision.min_dwell);
        let ms = 1_000_000u64;
        let c = a.offer(&kb.modes["explore"], 0).expect("first decision");
        assert_eq!((c.from.as_str(), c.to.as_str()), ("none", "explore"));
        assert_eq!(a.offer(&kb.modes["explore"], 10 * ms), None);
        // track is not urgent: waits for 1 s of explore
        assert_eq!(a.offer(&kb.modes["track"], 500 * ms), None);
        assert_eq!(a.offer(&kb.modes["track"], 1_000 * ms).map(|c| c.to), Some("track".into()));
        // avoid is urgent: at once
        let c = a.offer(&kb.modes["avoid"], 1_010 * ms).expect("urgent");
        assert_eq!((c.from.as_str(), c.to.as_str()), ("track", "avoid"));
        assert_eq!((a.current(), a.changes(), a.since_ns()), (Some("avoid"), 3, 1_010 * ms));
    }

    #[test]
    fn actions_in_order() {
        let kb = kb();
        let a = actions(&kb.modes["explore"]);
        assert_eq!(
            a,
            vec![
                Action::Weights { actuator: "motor".into(), text: "safety:1,tracker:0,wall-follow:2".into() },
                Action::Resume("wall-follow".into()),
            ]
        );
        let a = actions(&kb.modes["lean"]);
        assert_eq!(a[0].to_string(), "period of wall-follow = 500ms");
        assert_eq!(actions(&kb.modes["avoid"]).last(), Some(&Action::Suspend("wall-follow".into())));
    }

    /// `kb/explore.toml`: danger beats the target; a close target is held
    /// with the tracker alone on the foot (nothing else pushes the robot on
    /// into it); a seen one is tracked with the safety monitor's help.
    #[test]
    fn the_shipped_knowledge_base_lets_danger_and_the_target_compete() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../kb/explore.toml");
        let kb = KnowledgeBase::load(&path).expect("kb/explore.toml is valid");
        let mode = |danger, target| {
            let f = Facts { danger, target, load: Some(LoadLevel::Normal) };
            lookup(&kb, &f).map(|(_, m)| m.name.clone()).unwrap_or_default()
        };
        use DangerLevel as D;
        use TargetState as T;
        assert_eq!(mode(Some(D::None), Some(T::None)), "explore");
        assert_eq!(mode(Some(D::Low), Some(T::Seen)), "track");
        assert_eq!(mode(Some(D::Low), Some(T::Close)), "hold");
        for danger in [Some(D::High), Some(D::Stop), None] {
            for target in [Some(T::Seen), Some(T::Close), None] {
                assert_eq!(mode(danger, target), "avoid", "{danger:?} {target:?}");
            }
        }
        let motor = |m: &str| kb.modes[m].weights["motor"].clone();
        assert_eq!(motor("hold").get("safety"), Some(&0.0));
        assert!(motor("hold").get("tracker").is_some_and(|w| *w > 0.0));
        assert!(motor("track").get("safety").is_some_and(|w| *w > 0.0));
        assert!(kb.modes["avoid"].urgent);
    }
}
