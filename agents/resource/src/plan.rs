//! The resource manager's policy, free of any I/O: the load level from the
//! measures (with hysteresis), and whom to slow down, suspend or restore.
//!
//! **Level.** Each measure the knowledge base gives thresholds for (machine
//! CPU, the robot's agents' CPU, machine memory) says `critical` at or over
//! its critical threshold, `high` at or over its high one. The level is the
//! worst of them; it rises at once, and falls back to `normal` only once
//! every measure is below its `low` threshold (until then it stays `high`).
//!
//! **Actions** (at most one per `settle`, so that the effect of one is seen
//! before the next):
//!
//! 1. level `high` or `critical`: lengthen the period of the least important
//!    periodic, running, unprotected agent that is not yet at `max_slow`
//!    times its original period (ties: the busiest first) by `slow_factor`;
//! 2. when nobody can be slowed any more: suspend the least important
//!    running agent of `may_suspend`;
//! 3. level `normal` for `settle`: undo the most recent action still in
//!    force (resume, or give back the period before the slow-down) — last
//!    done, first undone, so the most important agents get their rate back
//!    first.
//!
//! An action someone else has overridden meanwhile (the agent's period is
//! not the one set, the agent was resumed, or it is gone) is forgotten, not
//! undone: the resource manager never fights the decision maker or a person.

use nerve_decision::{ResourcePolicy, Thresholds};
use shm_schemas::payloads::LoadLevel;

/// One measurement of the machine.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measures {
    /// Machine CPU, percent of all cores.
    pub machine_cpu: f64,
    /// The robot's agents together, percent of one core.
    pub agents_cpu: f64,
    /// Machine memory in use, percent.
    pub memory: f64,
}

/// The load level after `m`, given the level before.
pub fn level(policy: &ResourcePolicy, m: &Measures, before: LoadLevel) -> LoadLevel {
    let pairs: Vec<(f64, Thresholds)> =
        [(m.machine_cpu, policy.machine_cpu), (m.agents_cpu, policy.agents_cpu), (m.memory, policy.memory)]
            .into_iter()
            .filter_map(|(v, t)| t.map(|t| (v, t)))
            .collect();
    let raw = pairs
        .iter()
        .map(|(v, t)| {
            if *v >= t.critical {
                LoadLevel::Critical
            } else if *v >= t.high {
                LoadLevel::High
            } else {
                LoadLevel::Normal
            }
        })
        .max()
        .unwrap_or(LoadLevel::Normal);
    if raw >= before {
        raw
    } else if pairs.iter().any(|(v, t)| *v >= t.low) {
        // falling, but not yet below every `low`: hold at high
        raw.max(LoadLevel::High).min(before)
    } else {
        raw
    }
}

/// What the resource manager knows of one agent.
#[derive(Debug, Clone, PartialEq)]
pub struct AgentObs {
    /// Name.
    pub name: String,
    /// Importance, 1 … 10, as the policy applies it.
    pub importance: u8,
    /// Current period of a periodic agent.
    pub period_ns: Option<u64>,
    /// Whether its task is suspended.
    pub suspended: bool,
    /// CPU, percent of one core.
    pub cpu_percent: f64,
}

/// One thing to ask the router.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Action {
    /// Lengthen a period.
    Slow {
        /// agent
        name: String,
        /// period now
        from_ns: u64,
        /// new period
        to_ns: u64,
    },
    /// Suspend an agent.
    Suspend {
        /// agent
        name: String,
    },
    /// Give a period back.
    Restore {
        /// agent
        name: String,
        /// period now
        from_ns: u64,
        /// period given back
        to_ns: u64,
    },
    /// Resume an agent the resource manager suspended.
    Resume {
        /// agent
        name: String,
    },
}

impl std::fmt::Display for Action {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ms = |ns: &u64| *ns as f64 / 1e6;
        match self {
            Action::Slow { name, from_ns, to_ns } => {
                write!(f, "slow down {name}: period {}ms -> {}ms", ms(from_ns), ms(to_ns))
            }
            Action::Suspend { name } => write!(f, "suspend {name}"),
            Action::Restore { name, from_ns, to_ns } => {
                write!(f, "restore {name}: period {}ms -> {}ms", ms(from_ns), ms(to_ns))
            }
            Action::Resume { name } => write!(f, "resume {name}"),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Done {
    Slowed { name: String, original_ns: u64, before_ns: u64, set_ns: u64 },
    Suspended { name: String },
}

impl Done {
    fn name(&self) -> &str {
        match self {
            Done::Slowed { name, .. } | Done::Suspended { name } => name,
        }
    }
}

/// The resource manager's memory of what it did, and its next move.
#[derive(Debug, Clone)]
pub struct Planner {
    policy: ResourcePolicy,
    me: String,
    done: Vec<Done>,
    last_action_ns: Option<u64>,
    normal_since_ns: Option<u64>,
}

impl Planner {
    /// A planner for the resource manager named `me` (never touched itself).
    pub fn new(policy: ResourcePolicy, me: &str) -> Self {
        Planner { policy, me: me.to_owned(), done: Vec::new(), last_action_ns: None, normal_since_ns: None }
    }

    /// The policy.
    pub fn policy(&self) -> &ResourcePolicy {
        &self.policy
    }

    /// Agents whose period the planner has lengthened and not given back.
    pub fn slowed(&self) -> Vec<&str> {
        let mut v: Vec<&str> = self.done.iter().filter(|d| matches!(d, Done::Slowed { .. })).map(Done::name).collect();
        v.dedup();
        v
    }

    /// Agents the planner suspended and has not resumed.
    pub fn suspended(&self) -> Vec<&str> {
        self.done.iter().filter(|d| matches!(d, Done::Suspended { .. })).map(Done::name).collect()
    }

    fn untouchable(&self, a: &AgentObs) -> bool {
        a.name == self.me || self.policy.protected(&a.name, a.importance)
    }

    /// Forgets actions someone else has overridden (see the module
    /// documentation): an agent's newest entry must still hold (its period
    /// is the one set, or it is still suspended), else every entry of that
    /// agent goes.
    fn forget_overridden(&mut self, agents: &[AgentObs]) {
        let mut names: Vec<String> = self.done.iter().map(|d| d.name().to_owned()).collect();
        names.sort();
        names.dedup();
        for n in names {
            let newest = self.done.iter().rev().find(|d| d.name() == n);
            let valid = match (newest, agents.iter().find(|a| a.name == n)) {
                (Some(Done::Slowed { set_ns, .. }), Some(a)) => a.period_ns == Some(*set_ns),
                (Some(Done::Suspended { .. }), Some(a)) => a.suspended,
                _ => false,
            };
            if !valid {
                tracing::info!("{n} was changed or is gone since the resource manager acted on it; forgetting that");
                self.done.retain(|d| d.name() != n);
            }
        }
    }

    /// The next action at `now_ns`, given the level and the agents (from `nerve ps`).
    pub fn plan(&mut self, level: LoadLevel, agents: &[AgentObs], now_ns: u64) -> Option<Action> {
        self.forget_overridden(agents);
        let settle = self.policy.settle.as_nanos() as u64;
        if level == LoadLevel::Normal {
            let since = *self.normal_since_ns.get_or_insert(now_ns);
            if now_ns.saturating_sub(since) < settle || !self.settled(now_ns) {
                return None;
            }
            return match self.done.last()? {
                Done::Suspended { name } => Some(Action::Resume { name: name.clone() }),
                Done::Slowed { name, before_ns, set_ns, .. } => {
                    Some(Action::Restore { name: name.clone(), from_ns: *set_ns, to_ns: *before_ns })
                }
            };
        }
        self.normal_since_ns = None;
        if !self.settled(now_ns) {
            return None;
        }
        if let Some(a) = self.slow_candidate(agents) {
            let from = a.period_ns.unwrap_or(0);
            let original = self.original_period(&a.name).unwrap_or(from);
            let cap = (original as f64 * self.policy.max_slow) as u64;
            let to = ((from as f64 * self.policy.slow_factor) as u64).min(cap);
            return Some(Action::Slow { name: a.name.clone(), from_ns: from, to_ns: to });
        }
        let mut extras: Vec<&AgentObs> = agents
            .iter()
            .filter(|a| !a.suspended && self.policy.may_suspend.contains(&a.name) && !self.untouchable(a))
            .collect();
        extras.sort_by(|a, b| a.importance.cmp(&b.importance).then(b.cpu_percent.total_cmp(&a.cpu_percent)));
        extras.first().map(|a| Action::Suspend { name: a.name.clone() })
    }

    fn settled(&self, now_ns: u64) -> bool {
        self.last_action_ns.is_none_or(|t| now_ns.saturating_sub(t) >= self.policy.settle.as_nanos() as u64)
    }

    fn original_period(&self, name: &str) -> Option<u64> {
        self.done.iter().find_map(|d| match d {
            Done::Slowed { name: n, original_ns, .. } if n == name => Some(*original_ns),
            _ => None,
        })
    }

    fn slow_candidate<'a>(&self, agents: &'a [AgentObs]) -> Option<&'a AgentObs> {
        let mut c: Vec<&AgentObs> = agents
            .iter()
            .filter(|a| !a.suspended && !self.untouchable(a))
            .filter(|a| match a.period_ns {
                None | Some(0) => false,
                Some(p) => {
                    let original = self.original_period(&a.name).unwrap_or(p);
                    (p as f64) < original as f64 * self.policy.max_slow * 0.999
                }
            })
            .collect();
        c.sort_by(|a, b| {
            a.importance.cmp(&b.importance).then(b.cpu_percent.total_cmp(&a.cpu_percent)).then(a.name.cmp(&b.name))
        });
        c.first().copied()
    }

    /// Records the outcome of `action`, done at `now_ns`.
    pub fn done(&mut self, action: &Action, ok: bool, now_ns: u64) {
        self.last_action_ns = Some(now_ns);
        if !ok {
            return;
        }
        match action {
            Action::Slow { name, from_ns, to_ns } => {
                let original_ns = self.original_period(name).unwrap_or(*from_ns);
                self.done.push(Done::Slowed { name: name.clone(), original_ns, before_ns: *from_ns, set_ns: *to_ns });
            }
            Action::Suspend { name } => self.done.push(Done::Suspended { name: name.clone() }),
            Action::Restore { .. } | Action::Resume { .. } => {
                self.done.pop();
            }
        }
    }

    /// The action the planner recorded for `name`, for reports.
    pub fn action_of(&self, name: &str) -> u8 {
        use shm_schemas::payloads::resources::{ACTION_NONE, ACTION_SLOWED, ACTION_SUSPENDED};
        match self.done.iter().rev().find(|d| d.name() == name) {
            Some(Done::Suspended { .. }) => ACTION_SUSPENDED,
            Some(Done::Slowed { .. }) => ACTION_SLOWED,
            None => ACTION_NONE,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    const S: u64 = 1_000_000_000;
    const MS: u64 = 1_000_000;

    fn policy() -> ResourcePolicy {
        ResourcePolicy {
            machine_cpu: None,
            agents_cpu: Some(Thresholds { high: 60.0, critical: 150.0, low: 40.0 }),
            memory: None,
            settle: Duration::from_secs(2),
            slow_factor: 2.0,
            max_slow: 4.0,
            protect: vec!["motor".into()],
            may_suspend: vec!["wall".into()],
            ..ResourcePolicy::default()
        }
    }

    fn obs(name: &str, importance: u8, period_ms: Option<u64>, cpu: f64) -> AgentObs {
        AgentObs {
            name: name.into(),
            importance,
            period_ns: period_ms.map(|p| p * MS),
            suspended: false,
            cpu_percent: cpu,
        }
    }

    fn apply(agents: &mut [AgentObs], a: &Action) {
        for x in agents.iter_mut() {
            match a {
                Action::Slow { name, to_ns, .. } | Action::Restore { name, to_ns, .. } if *name == x.name => {
                    x.period_ns = Some(*to_ns)
                }
                Action::Suspend { name } if *name == x.name => x.suspended = true,
                Action::Resume { name } if *name == x.name => x.suspended = false,
                _ => {}
            }
        }
    }

    #[test]
    fn level_rises_at_once_and_falls_below_low() {
        let p = policy();
        let m = |cpu| Measures { agents_cpu: cpu, ..Default::default() };
        assert_eq!(level(&p, &m(30.0), LoadLevel::Normal), LoadLevel::Normal);
        assert_eq!(level(&p, &m(70.0), LoadLevel::Normal), LoadLevel::High);
        assert_eq!(level(&p, &m(200.0), LoadLevel::High), LoadLevel::Critical);
        assert_eq!(level(&p, &m(50.0), LoadLevel::Critical), LoadLevel::High, "held until below low");
        assert_eq!(level(&p, &m(50.0), LoadLevel::Normal), LoadLevel::Normal);
        assert_eq!(level(&p, &m(39.0), LoadLevel::High), LoadLevel::Normal);
        assert_eq!(
            level(
                &ResourcePolicy { agents_cpu: None, machine_cpu: None, memory: None, ..p },
                &m(500.0),
                LoadLevel::Normal
            ),
            LoadLevel::Normal
        );
    }

    #[test]
    fn slows_the_least_important_first_then_suspends_then_restores_in_reverse() {
        let mut p = Planner::new(policy(), "resource");
        let mut agents = vec![
            obs("hog", 6, Some(20), 75.0),
            obs("low", 1, Some(10), 1.0),
            obs("wall", 3, None, 2.0),           // event-driven: cannot be slowed
            obs("motor", 1, Some(10), 5.0),      // protected by name
            obs("safety", 10, Some(10), 5.0),    // protected by importance
            obs("resource", 1, Some(1000), 1.0), // itself
        ];
        let mut t = 0;
        let mut log = Vec::new();
        for _ in 0..8 {
            t += 2 * S;
            if let Some(a) = p.plan(LoadLevel::High, &agents, t) {
                apply(&mut agents, &a);
                p.done(&a, true, t);
                log.push(a.to_string());
            }
        }
        assert_eq!(
            log,
            [
                "slow down low: period 10ms -> 20ms",
                "slow down low: period 20ms -> 40ms",
                "slow down hog: period 20ms -> 40ms",
                "slow down hog: period 40ms -> 80ms",
                "suspend wall",
            ]
        );
        assert_eq!((p.slowed(), p.suspended()), (vec!["low", "hog"], vec!["wall"]));
        // not settled: nothing 1 s after the last action
        assert_eq!(p.plan(LoadLevel::Normal, &agents, t + S), None);
        let mut log = Vec::new();
        for _ in 0..10 {
            t += 2 * S;
            if let Some(a) = p.plan(LoadLevel::Normal, &agents, t) {
                apply(&mut agents, &a);
                p.done(&a, true, t);
                log.push(a.to_string());
            }
        }
        assert_eq!(
            log,
            [
                "resume wall",
                "restore hog: period 80ms -> 40ms",
                "restore hog: period 40ms -> 20ms",
                "restore low: period 40ms -> 20ms",
                "restore low: period 20ms -> 10ms",
            ]
        );
        assert!(p.slowed().is_empty());
    }

    #[test]
    fn overridden_actions_are_forgotten_not_undone() {
        let mut p = Planner::new(policy(), "resource");
        let mut agents = vec![obs("low", 1, Some(10), 1.0)];
        let a = p.plan(LoadLevel::High, &agents, 0).expect("slow");
        apply(&mut agents, &a);
        p.done(&a, true, 0);
        assert_eq!(p.action_of("low"), shm_schemas::payloads::resources::ACTION_SLOWED);
        // someone sets another period: the slow-down is forgotten
        agents[0].period_ns = Some(15 * MS);
        assert_eq!(p.plan(LoadLevel::Normal, &agents, 3 * S), None);
        assert_eq!(p.plan(LoadLevel::Normal, &agents, 6 * S), None);
        assert!(p.slowed().is_empty());
        // a failed action is not recorded, but still waits for settle
        let a = p.plan(LoadLevel::High, &agents, 10 * S).expect("slow");
        p.done(&a, false, 10 * S);
        assert_eq!(p.plan(LoadLevel::High, &agents, 11 * S), None);
        assert!(p.slowed().is_empty());
    }
}
