//! The knowledge base: a strict TOML file read by the decision maker (its
//! `[decision]`, `[[rule]]` and `[modes.*]` tables) and by the resource
//! manager (its `[resources]` table). The format is described, with an
//! example, in `docs/decision.md`; `kb/explore.toml` is the exploration
//! experiment of the thesis (section 4.2.2.4).
//!
//! "Strict" means: unknown keys, unknown level names, rules naming a mode
//! that does not exist, modes no rule selects, a last rule that does not
//! match everything, an agent both suspended and resumed by one mode, bad
//! durations and out-of-range numbers are all refused when the file is
//! loaded, with the file name and what to write instead. A knowledge base
//! that loads is one the agents can follow without further checks.

use serde::Deserialize;
use shm_schemas::payloads::{DangerLevel, LoadLevel, TargetState};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;
use toml::Spanned;

/// Why a knowledge base could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum KbError {
    /// The file could not be read.
    #[error("cannot read the knowledge base {path}: {source}; give an existing file with `-- --kb FILE`")]
    Read {
        /// the file
        path: PathBuf,
        /// the cause
        source: std::io::Error,
    },
    /// The file is not valid TOML for a knowledge base (syntax, unknown key, wrong type).
    #[error("knowledge base {path}: {detail}(see docs/decision.md for the format)")]
    Syntax {
        /// the file
        path: PathBuf,
        /// what the TOML reader said, with the line
        detail: String,
    },
    /// The file parses but says something inconsistent.
    #[error("knowledge base {path}: {detail}")]
    Invalid {
        /// the file
        path: PathBuf,
        /// what is wrong and what to write instead
        detail: String,
    },
}

/// A variable of the situation a rule tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variable {
    /// The danger level the safety monitor reports.
    Danger,
    /// What the tracker sees.
    Target,
    /// The load level the resource manager reports.
    Load,
}

impl Variable {
    /// The key in a rule's `when` table.
    pub fn key(self) -> &'static str {
        match self {
            Variable::Danger => "danger",
            Variable::Target => "target",
            Variable::Load => "load",
        }
    }

    /// The values a rule may test, `unknown` included (no fresh report).
    pub fn values(self) -> Vec<&'static str> {
        let mut v: Vec<&'static str> = match self {
            Variable::Danger => DangerLevel::ALL.iter().map(|l| l.name()).collect(),
            Variable::Target => TargetState::ALL.iter().map(|l| l.name()).collect(),
            Variable::Load => LoadLevel::ALL.iter().map(|l| l.name()).collect(),
        };
        v.push(UNKNOWN);
        v
    }
}

/// The value of a variable when no fresh report says it.
pub const UNKNOWN: &str = "unknown";

/// One or several values in a `when` table.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum OneOrMany {
    One(String),
    Many(Vec<String>),
}

impl OneOrMany {
    fn into_vec(self) -> Vec<String> {
        match self {
            OneOrMany::One(s) => vec![s],
            OneOrMany::Many(v) => v,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawKb {
    decision: Option<RawDecision>,
    #[serde(default)]
    rule: Vec<RawRule>,
    #[serde(default)]
    modes: BTreeMap<String, RawMode>,
    resources: Option<RawResources>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDecision {
    report_timeout: Option<Spanned<String>>,
    min_dwell: Option<Spanned<String>>,
    retry: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWhen {
    danger: Option<OneOrMany>,
    target: Option<OneOrMany>,
    load: Option<OneOrMany>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRule {
    when: Option<RawWhen>,
    mode: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMode {
    #[serde(default)]
    urgent: bool,
    #[serde(default)]
    weights: BTreeMap<String, BTreeMap<String, f64>>,
    #[serde(default)]
    suspend: Vec<String>,
    #[serde(default)]
    resume: Vec<String>,
    #[serde(default)]
    periods: BTreeMap<String, Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawThresholds {
    high: f64,
    critical: f64,
    low: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawResources {
    machine_cpu: Option<RawThresholds>,
    agents_cpu: Option<RawThresholds>,
    memory: Option<RawThresholds>,
    settle: Option<Spanned<String>>,
    slow_factor: Option<f64>,
    max_slow: Option<f64>,
    default_importance: Option<u8>,
    protect_importance: Option<u8>,
    #[serde(default)]
    importance: BTreeMap<String, u8>,
    #[serde(default)]
    protect: Vec<String>,
    #[serde(default)]
    may_suspend: Vec<String>,
}

/// The longest duration a knowledge base may give (`retry`, `report_timeout`,
/// `min_dwell`, mode periods, `resources.settle`): one hour. Longer ones are
/// typos, and deadlines such as `now + retry` must stay far from overflowing.
pub const MAX_KB_DURATION: Duration = Duration::from_secs(3600);

/// The 1-based line of byte `at` of `text`.
fn line_of(text: &str, at: usize) -> usize {
    text.get(..at).map_or(0, |t| t.matches('\n').count()) + 1
}

/// Parses duration `what` of the knowledge base, at most [`MAX_KB_DURATION`];
/// a refusal names the line.
fn kb_duration(text: &str, what: &str, s: &Spanned<String>) -> Result<Duration, String> {
    let line = line_of(text, s.span().start);
    let v = s.get_ref();
    let d = agent_sdk::clock::parse_duration(v)
        .map_err(|e| format!("line {line}: {what} = {v:?}: {e} (write e.g. \"500ms\" or \"2s\")"))?;
    if d > MAX_KB_DURATION {
        return Err(format!(
            "line {line}: {what} = {v:?} is longer than the {} a knowledge base allows; write a shorter duration",
            agent_sdk::clock::format_duration(MAX_KB_DURATION)
        ));
    }
    Ok(d)
}

/// The `[decision]` table.
#[derive(Debug, Clone, PartialEq)]
pub struct DecisionSettings {
    /// A report older than this no longer counts: its variable becomes `unknown`.
    pub report_timeout: Duration,
    /// A mode holds at least this long before a non-urgent mode replaces it.
    pub min_dwell: Duration,
    /// Actions the router refused are tried again after this long.
    pub retry: Duration,
}

impl Default for DecisionSettings {
    fn default() -> Self {
        DecisionSettings {
            report_timeout: Duration::from_secs(1),
            min_dwell: Duration::from_millis(500),
            retry: Duration::from_secs(1),
        }
    }
}

/// A rule's condition on one variable: the values it accepts.
#[derive(Debug, Clone, PartialEq)]
pub struct Condition {
    /// The variable.
    pub variable: Variable,
    /// Accepted values (names, `unknown` included).
    pub values: Vec<String>,
}

/// A row of the table: when every condition holds, the mode.
#[derive(Debug, Clone, PartialEq)]
pub struct Rule {
    /// The conditions; empty matches everything.
    pub when: Vec<Condition>,
    /// The mode it selects.
    pub mode: String,
}

/// What a mode does.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ModeSpec {
    /// The mode's name.
    pub name: String,
    /// Entered at once, whatever `min_dwell` says (danger).
    pub urgent: bool,
    /// Per actuator agent, the weight of each source agent.
    pub weights: BTreeMap<String, BTreeMap<String, f64>>,
    /// Agents suspended on entering the mode.
    pub suspend: Vec<String>,
    /// Agents resumed on entering the mode.
    pub resume: Vec<String>,
    /// Agents whose period is set on entering the mode.
    pub periods: BTreeMap<String, Duration>,
}

/// Thresholds of one load measure; the level is `critical` at or over
/// `critical`, `high` at or over `high`, and drops back to `normal` only
/// below `low` (hysteresis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thresholds {
    /// Level `high` from here.
    pub high: f64,
    /// Level `critical` from here.
    pub critical: f64,
    /// Back to `normal` below this.
    pub low: f64,
}

/// The `[resources]` table: the resource manager's policy.
#[derive(Debug, Clone, PartialEq)]
pub struct ResourcePolicy {
    /// Machine CPU, percent of all cores (0 … 100).
    pub machine_cpu: Option<Thresholds>,
    /// The robot's agents together, percent of one core.
    pub agents_cpu: Option<Thresholds>,
    /// Machine memory in use, percent.
    pub memory: Option<Thresholds>,
    /// Time between two actions, and time the load must stay normal before a restore.
    pub settle: Duration,
    /// Each slow-down multiplies a period by this (> 1).
    pub slow_factor: f64,
    /// A period never grows beyond this many times its original.
    pub max_slow: f64,
    /// Importance of an agent neither this table nor its launch file rates.
    pub default_importance: u8,
    /// Agents at least this important are never touched.
    pub protect_importance: u8,
    /// Importance by agent name (1 least … 10 most); wins over the launch file's.
    pub importance: BTreeMap<String, u8>,
    /// Agents never touched.
    pub protect: Vec<String>,
    /// Agents that may be suspended once slowing down is not enough.
    pub may_suspend: Vec<String>,
}

impl Default for ResourcePolicy {
    fn default() -> Self {
        ResourcePolicy {
            machine_cpu: Some(Thresholds { high: 85.0, critical: 95.0, low: 70.0 }),
            agents_cpu: None,
            memory: Some(Thresholds { high: 90.0, critical: 95.0, low: 85.0 }),
            settle: Duration::from_secs(2),
            slow_factor: 2.0,
            max_slow: 8.0,
            default_importance: 5,
            protect_importance: 10,
            importance: BTreeMap::new(),
            protect: Vec::new(),
            may_suspend: Vec::new(),
        }
    }
}

impl ResourcePolicy {
    /// Whether the policy says agent `name` must never be touched.
    pub fn protected(&self, name: &str, importance: u8) -> bool {
        importance >= self.protect_importance || self.protect.iter().any(|p| p == name)
    }

    /// The importance of `name`: this table, else the launch file's, else the default.
    pub fn importance_of(&self, name: &str, declared: Option<u8>) -> u8 {
        self.importance.get(name).copied().or(declared).unwrap_or(self.default_importance)
    }
}

/// A loaded, checked knowledge base.
#[derive(Debug, Clone, PartialEq)]
pub struct KnowledgeBase {
    /// Where it came from.
    pub path: PathBuf,
    /// `[decision]`.
    pub decision: DecisionSettings,
    /// `[[rule]]`, in file order; the last matches everything.
    pub rules: Vec<Rule>,
    /// `[modes.*]`, by name (their index is their rank in name order).
    pub modes: BTreeMap<String, ModeSpec>,
    /// `[resources]`.
    pub resources: ResourcePolicy,
}

impl KnowledgeBase {
    /// Reads and checks the file at `path`.
    pub fn load(path: &Path) -> Result<Self, KbError> {
        let text = std::fs::read_to_string(path).map_err(|source| KbError::Read { path: path.to_owned(), source })?;
        Self::parse(&text, path)
    }

    /// Checks `text`; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, KbError> {
        let raw: RawKb =
            toml::from_str(text).map_err(|e| KbError::Syntax { path: path.to_owned(), detail: e.to_string() })?;
        let invalid = |detail: String| KbError::Invalid { path: path.to_owned(), detail };
        let dur = |what: &str, s: Option<&Spanned<String>>, default: Duration| -> Result<Duration, KbError> {
            match s {
                None => Ok(default),
                Some(s) => kb_duration(text, what, s).map_err(invalid),
            }
        };

        let d = DecisionSettings::default();
        let decision = match &raw.decision {
            None => d,
            Some(r) => DecisionSettings {
                report_timeout: dur("decision.report_timeout", r.report_timeout.as_ref(), d.report_timeout)?,
                min_dwell: dur("decision.min_dwell", r.min_dwell.as_ref(), d.min_dwell)?,
                retry: dur("decision.retry", r.retry.as_ref(), d.retry)?,
            },
        };
        if decision.report_timeout.is_zero() || decision.retry.is_zero() {
            return Err(invalid("decision.report_timeout and decision.retry must be longer than 0".into()));
        }

        let mut modes = BTreeMap::new();
        for (name, m) in raw.modes {
            check_agent_name(&name).map_err(|e| invalid(format!("[modes.{name}]: {e}")))?;
            for (actuator, sources) in &m.weights {
                for (source, w) in sources {
                    if !w.is_finite() || *w < 0.0 {
                        return Err(invalid(format!(
                            "[modes.{name}] weights.{actuator}.{source} = {w}: a weight is a finite number >= 0"
                        )));
                    }
                    for (what, n) in [("actuator", actuator), ("source", source)] {
                        check_agent_name(n).map_err(|e| invalid(format!("[modes.{name}] weights: {what} {e}")))?;
                    }
                }
            }
            if let Some(both) = m.suspend.iter().find(|a| m.resume.contains(a)) {
                return Err(invalid(format!(
                    "[modes.{name}] both suspends and resumes {both:?}; keep it in one of the two lists"
                )));
            }
            let mut periods = BTreeMap::new();
            for (agent, p) in &m.periods {
                let d = dur(&format!("[modes.{name}] periods.{agent}"), Some(p), Duration::ZERO)?;
                if d < Duration::from_micros(10) {
                    return Err(invalid(format!(
                        "[modes.{name}] periods.{agent} = {:?}: a period is at least 10us",
                        p.get_ref()
                    )));
                }
                periods.insert(agent.clone(), d);
            }
            for a in m.suspend.iter().chain(&m.resume).chain(m.periods.keys()) {
                check_agent_name(a).map_err(|e| invalid(format!("[modes.{name}]: {e}")))?;
            }
            modes.insert(
                name.clone(),
                ModeSpec { name, urgent: m.urgent, weights: m.weights, suspend: m.suspend, resume: m.resume, periods },
            );
        }

        let mut rules = Vec::new();
        let n = raw.rule.len();
        if n == 0 && !modes.is_empty() {
            return Err(invalid("modes are defined but no [[rule]] selects them; add [[rule]] tables".into()));
        }
        for (i, r) in raw.rule.into_iter().enumerate() {
            let at = format!("[[rule]] number {}", i + 1);
            if !modes.contains_key(&r.mode) {
                let known: Vec<&str> = modes.keys().map(String::as_str).collect();
                return Err(invalid(format!(
                    "{at}: mode {:?} is not defined; define [modes.{}] or use one of: {}",
                    r.mode,
                    r.mode,
                    if known.is_empty() { "none".into() } else { known.join(", ") }
                )));
            }
            let mut when = Vec::new();
            if let Some(w) = r.when {
                for (variable, v) in
                    [(Variable::Danger, w.danger), (Variable::Target, w.target), (Variable::Load, w.load)]
                {
                    let Some(v) = v else { continue };
                    let values = v.into_vec();
                    if values.is_empty() {
                        return Err(invalid(format!(
                            "{at}: when.{} = [] can never hold; list values or leave the key out",
                            variable.key()
                        )));
                    }
                    let allowed = variable.values();
                    if let Some(bad) = values.iter().find(|x| !allowed.contains(&x.as_str())) {
                        return Err(invalid(format!(
                            "{at}: when.{} = {bad:?} is not a {} value; use {}",
                            variable.key(),
                            variable.key(),
                            allowed.join(", ")
                        )));
                    }
                    when.push(Condition { variable, values });
                }
            }
            if i + 1 == n && !when.is_empty() {
                return Err(invalid(format!(
                    "{at}, the last rule, has conditions; the last rule must match every situation (leave out `when`) so that there is always a mode"
                )));
            }
            rules.push(Rule { when, mode: r.mode });
        }
        if let Some(unused) = modes.keys().find(|m| !rules.iter().any(|r| &r.mode == *m)) {
            return Err(invalid(format!("mode {unused:?} is selected by no [[rule]]; add a rule or remove the mode")));
        }

        let resources = match raw.resources {
            None => ResourcePolicy::default(),
            Some(r) => resources(r, text).map_err(invalid)?,
        };
        Ok(KnowledgeBase { path: path.to_owned(), decision, rules, modes, resources })
    }

    /// The rank of `mode` in name order (published in `nerve::Mode::index`).
    pub fn mode_index(&self, mode: &str) -> Option<usize> {
        self.modes.keys().position(|m| m == mode)
    }
}

fn resources(r: RawResources, text: &str) -> Result<ResourcePolicy, String> {
    let d = ResourcePolicy::default();
    let th = |what: &str, t: Option<RawThresholds>| -> Result<Option<Thresholds>, String> {
        let Some(t) = t else { return Ok(None) };
        if !(t.low.is_finite() && t.high.is_finite() && t.critical.is_finite()) || t.low < 0.0 {
            return Err(format!("resources.{what}: thresholds are finite numbers >= 0"));
        }
        if !(t.low < t.high && t.high <= t.critical) {
            return Err(format!(
                "resources.{what}: need low < high <= critical (got low {}, high {}, critical {})",
                t.low, t.high, t.critical
            ));
        }
        Ok(Some(Thresholds { high: t.high, critical: t.critical, low: t.low }))
    };
    let settle = match &r.settle {
        None => d.settle,
        Some(s) => kb_duration(text, "resources.settle", s)?,
    };
    let slow_factor = r.slow_factor.unwrap_or(d.slow_factor);
    if !slow_factor.is_finite() || slow_factor <= 1.0 {
        return Err(format!("resources.slow_factor = {slow_factor}: must be a number > 1 (2 doubles a period)"));
    }
    let max_slow = r.max_slow.unwrap_or(d.max_slow);
    if !max_slow.is_finite() || max_slow < slow_factor {
        return Err(format!("resources.max_slow = {max_slow}: must be >= slow_factor ({slow_factor})"));
    }
    let imp = |what: String, v: u8| {
        if (1..=10).contains(&v) { Ok(v) } else { Err(format!("{what} = {v}: importance is 1 (least) to 10 (most)")) }
    };
    let default_importance = imp("resources.default_importance".into(), r.default_importance.unwrap_or(5))?;
    let protect_importance = imp("resources.protect_importance".into(), r.protect_importance.unwrap_or(10))?;
    for (name, v) in &r.importance {
        imp(format!("resources.importance.{name}"), *v)?;
        check_agent_name(name).map_err(|e| format!("resources.importance: {e}"))?;
    }
    for name in r.protect.iter().chain(&r.may_suspend) {
        check_agent_name(name).map_err(|e| format!("resources: {e}"))?;
    }
    if let Some(both) = r.may_suspend.iter().find(|a| r.protect.contains(a)) {
        return Err(format!("resources: {both:?} is both in `protect` and in `may_suspend`; keep it in one"));
    }
    Ok(ResourcePolicy {
        machine_cpu: th("machine_cpu", r.machine_cpu)?,
        agents_cpu: th("agents_cpu", r.agents_cpu)?,
        memory: th("memory", r.memory)?,
        settle,
        slow_factor,
        max_slow,
        default_importance,
        protect_importance,
        importance: r.importance,
        protect: r.protect,
        may_suspend: r.may_suspend,
    })
}

fn check_agent_name(name: &str) -> Result<(), String> {
    shm_schemas::AgentName::new(name).map(|_| ()).map_err(|e| format!("{name:?} is not an agent name: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[decision]
report_timeout = "800ms"
min_dwell = "300ms"

[[rule]]
when = { danger = ["high", "stop", "unknown"] }
mode = "avoid"

[[rule]]
when = { target = "seen", danger = ["none", "low"] }
mode = "track"

[[rule]]
mode = "explore"

[modes.avoid]
urgent = true
weights = { motor = { safety = 4, tracker = 0 } }
suspend = ["wall-follow"]

[modes.track]
weights = { motor = { safety = 1, tracker = 3 }, head = { tracker = 1 } }
suspend = ["wall-follow"]

[modes.explore]
resume = ["wall-follow"]
periods = { wall-follow = "100ms" }

[resources]
agents_cpu = { high = 60, critical = 150, low = 40 }
importance = { hog = 1 }
may_suspend = ["wall-follow"]
"#;

    fn parse(s: &str) -> Result<KnowledgeBase, KbError> {
        KnowledgeBase::parse(s, Path::new("test.toml"))
    }

    #[test]
    fn a_good_file_loads() {
        let kb = parse(GOOD).expect("valid");
        assert_eq!(kb.decision.report_timeout, Duration::from_millis(800));
        assert_eq!(kb.rules.len(), 3);
        assert_eq!(kb.rules[1].when.len(), 2);
        assert!(kb.modes["avoid"].urgent);
        assert_eq!(kb.modes["track"].weights["head"]["tracker"], 1.0);
        assert_eq!(kb.modes["explore"].periods["wall-follow"], Duration::from_millis(100));
        assert_eq!(kb.mode_index("explore"), Some(1));
        assert_eq!(kb.resources.agents_cpu.map(|t| t.high), Some(60.0));
        assert_eq!(kb.resources.machine_cpu, None);
        assert_eq!(kb.resources.importance_of("hog", Some(9)), 1);
        assert_eq!(kb.resources.importance_of("x", Some(9)), 9);
        assert_eq!(kb.resources.importance_of("x", None), 5);
    }

    #[test]
    fn the_shipped_knowledge_base_loads() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../kb/explore.toml");
        let kb = KnowledgeBase::load(&path).expect("kb/explore.toml is valid");
        assert!(kb.modes.contains_key("explore"));
    }

    fn refused(s: &str) -> String {
        parse(s).expect_err("must be refused").to_string()
    }

    #[test]
    fn mistakes_are_refused_with_what_to_do() {
        let e = refused(&GOOD.replace("min_dwell", "min_dwel"));
        assert!(e.contains("min_dwel") && e.contains("unknown field"), "{e}");
        let e = refused(&GOOD.replace("\"seen\"", "\"visible\""));
        assert!(e.contains("visible") && e.contains("none, seen, close, unknown"), "{e}");
        let e = refused(&GOOD.replace("mode = \"track\"", "mode = \"trak\""));
        assert!(e.contains("\"trak\" is not defined"), "{e}");
        let e = refused(
            &GOOD.replace("[[rule]]\nmode = \"explore\"", "[[rule]]\nwhen = { load = \"high\" }\nmode = \"explore\""),
        );
        assert!(e.contains("last rule"), "{e}");
        let e = refused(&GOOD.replace("tracker = 3", "tracker = -3"));
        assert!(e.contains(">= 0"), "{e}");
        let e = refused(
            &GOOD.replace("resume = [\"wall-follow\"]", "resume = [\"wall-follow\"]\nsuspend = [\"wall-follow\"]"),
        );
        assert!(e.contains("both suspends and resumes"), "{e}");
        let e = refused(&GOOD.replace("\"100ms\"", "\"fast\""));
        assert!(e.contains("periods.wall-follow"), "{e}");
        let e = refused(&GOOD.replace("low = 40", "low = 70"));
        assert!(e.contains("low < high"), "{e}");
        let e = refused(&GOOD.replace("hog = 1", "hog = 11"));
        assert!(e.contains("1 (least) to 10"), "{e}");
        let e = refused(&format!("{GOOD}\n[modes.idle]\n"));
        assert!(e.contains("\"idle\" is selected by no"), "{e}");
    }

    #[test]
    fn kb_durations_are_bounded_with_file_and_line() {
        // about 584 years overflowed `now + retry` in the decision agent
        let text = GOOD.replace("min_dwell = \"300ms\"", "min_dwell = \"300ms\"\nretry = \"18446744073s\"");
        let e = refused(&text);
        assert!(e.contains("test.toml") && e.contains("line 5") && e.contains("decision.retry"), "{e}");
        // a day is a valid duration elsewhere, but not in a knowledge base
        let e = refused(&GOOD.replace("min_dwell = \"300ms\"", "min_dwell = \"300ms\"\nretry = \"86400s\""));
        assert!(e.contains("line 5: decision.retry = \"86400s\" is longer than") && e.contains("3600s"), "{e}");
        let e = refused(&GOOD.replace("\"800ms\"", "\"7200s\""));
        assert!(e.contains("line 3: decision.report_timeout") && e.contains("longer than"), "{e}");
        let e = refused(&GOOD.replace("\"100ms\"", "\"7200s\""));
        assert!(e.contains("periods.wall-follow") && e.contains("longer than"), "{e}");
        let e = refused(&GOOD.replace("may_suspend", "settle = \"3601s\"\nmay_suspend"));
        assert!(e.contains("resources.settle") && e.contains("longer than"), "{e}");
        // the longest allowed loads
        let kb = parse(&GOOD.replace("min_dwell = \"300ms\"", "min_dwell = \"300ms\"\nretry = \"3600s\""))
            .expect("an hour is allowed");
        assert_eq!(kb.decision.retry, MAX_KB_DURATION);
    }
}
