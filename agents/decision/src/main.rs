//! `decision`: the global decision maker (thesis sections 3.2.5 and
//! 4.2.2.4). A periodic agent (default every 100 ms) that
//!
//! * reads the functional agents' reports on input `situation`
//!   (`nerve::Situation`, any number of senders) and the resource manager's
//!   on input `load` (`nerve::ResourceReport`, a header and every agent's
//!   load: the decision reads the header's load level);
//! * looks the situation up in its knowledge base (`-- --kb FILE`, see
//!   `docs/decision.md`): the first matching rule names the mode;
//! * on a mode change logs `mode change: FROM -> TO (target .., danger ..,
//!   load ..)` and acts through the router: the actuators' `weights`
//!   parameters, suspend, resume and periods of agents. A worker thread
//!   sends them ([`nerve_decision::apply`]), so that a slow router never
//!   holds up the decision; what the router refuses (an agent not running
//!   yet) is tried again every `retry`, and a restarted router gets the
//!   current mode's actions again;
//! * publishes the current mode every cycle on output `mode` (`nerve::Mode`).
//!
//! ```text
//! nerve start decision --name decision -- --kb kb/explore.toml
//! nerve connect safety/situation decision/situation
//! nerve connect tracker/situation decision/situation
//! nerve connect resource/load decision/load
//! ```

use agent_sdk::{Agent, AgentError, Context, Input, Output, SeqInput, Setup, Task, World};
use clap::Parser;
use nerve_decision::apply::Applier;
use nerve_decision::{Arbiter, Facts, KnowledgeBase, Reports, actions, lookup};
use shm_schemas::FixedName;
use shm_schemas::payloads::situation::UNKNOWN_LEVEL;
use shm_schemas::payloads::{AgentLoad, Mode, ResourceHeader, Situation};
use std::path::PathBuf;
use std::time::Duration;

/// The decision maker's own options (after `--`).
#[derive(Debug, Parser)]
#[command(name = "nerve-decision --", about = "decision maker options")]
struct Args {
    /// The knowledge base (TOML; see docs/decision.md).
    #[arg(long)]
    kb: PathBuf,
}

struct Decision {
    kb: KnowledgeBase,
    world: World,
    situation: Input<Situation>,
    load: SeqInput<AgentLoad, ResourceHeader>,
    out: Output<Mode>,
    reports: Reports,
    arbiter: Arbiter,
    facts: Facts,
    node_name: String,
    /// sends the modes' actions to the router; started by `start`
    applier: Option<Applier>,
}

impl Agent for Decision {
    const KIND: &'static str = "decision";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(100))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let path = std::path::absolute(&args.kb).unwrap_or(args.kb);
        let kb = KnowledgeBase::load(&path).map_err(|e| AgentError::Config(e.to_string()))?;
        let arbiter = Arbiter::new(kb.decision.min_dwell);
        Ok(Decision {
            world: setup.world().clone(),
            situation: setup.input("situation")?,
            load: setup.input_seq("load")?,
            out: setup.output("mode")?,
            reports: Reports::default(),
            arbiter,
            facts: Facts::default(),
            node_name: format!("{}-decide", setup.name()),
            applier: None,
            kb,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        tracing::info!(
            "knowledge base {}: {} rules, modes {}",
            self.kb.path.display(),
            self.kb.rules.len(),
            self.kb.modes.keys().cloned().collect::<Vec<_>>().join(", ")
        );
        let applier = Applier::start(self.world.clone(), self.node_name.clone(), self.kb.decision.retry)
            .map_err(AgentError::Other)?;
        self.applier = Some(applier);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let reports = &mut self.reports;
        self.situation.drain(|m, s| reports.situation(m.sender.as_str(), *s, now));
        // the newest report (by stamp) of those waiting: its header says the level
        let mut newest: Option<(u64, ResourceHeader)> = None;
        self.load.drain(|m, header, _| {
            if newest.is_none_or(|(t, _)| m.stamp_ns >= t) {
                newest = Some((m.stamp_ns, *header));
            }
        });
        if let Some((_, header)) = newest {
            self.reports.load(header, now);
        }
        self.reports.forget_stale(now, self.kb.decision.report_timeout);
        let facts = self.reports.facts(now, self.kb.decision.report_timeout);
        if facts != self.facts {
            tracing::debug!("situation: {facts}");
            self.facts = facts;
        }
        if let Some((rule, mode)) = lookup(&self.kb, &facts)
            && let Some(change) = self.arbiter.offer(mode, now)
        {
            tracing::info!("mode change: {} -> {} ({facts}; rule {})", change.from, change.to, rule + 1);
            if let Some(applier) = &self.applier {
                applier.post(&mode.name, actions(mode));
            }
        }
        let current = self.arbiter.current().unwrap_or("none");
        self.out.send(Mode {
            name: FixedName::new(current),
            index: self.kb.mode_index(current).map_or(u32::MAX, |i| i as u32),
            since_ns: self.arbiter.since_ns(),
            changes: self.arbiter.changes(),
            stamp_ns: now,
            danger_level: facts.danger.map_or(UNKNOWN_LEVEL, |l| l as u8),
            target: facts.target.map_or(UNKNOWN_LEVEL, |l| l as u8),
            load_level: facts.load.map_or(UNKNOWN_LEVEL, |l| l as u8),
            reserved: [0; 5],
        })?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Decision>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::testing::Harness;
    use shm_schemas::payloads::{DangerLevel, TargetState};

    fn decision() -> Harness<Decision> {
        let kb = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../kb/explore.toml");
        Harness::<Decision>::builder()
            .args(["--kb".to_owned(), kb.display().to_string()])
            .start()
            .expect("the decision maker starts with kb/explore.toml")
    }

    /// Runs `steps` cycles with the safety monitor and the tracker reporting
    /// `danger` and `target` every cycle; returns the mode of the last one.
    fn report(h: &mut Harness<Decision>, steps: u32, danger: DangerLevel, target: TargetState) -> String {
        for _ in 0..steps {
            let now = h.now_ns();
            h.send_from("situation", "safety", Situation::danger(danger, 0.5, now)).expect("danger");
            h.send_from("situation", "tracker", Situation::target(target, 0.1, 0.0, now)).expect("target");
            h.step().expect("step");
        }
        let modes = h.output::<Mode>("mode").expect("mode");
        assert_eq!(modes.len(), steps as usize, "one mode report per cycle");
        modes.last().map(|m| m.name.as_str().to_owned()).unwrap_or_default()
    }

    /// The decision maker as it runs on kb/explore.toml, on the test clock:
    /// the table picks the mode, a new mode waits out the dwell time unless
    /// urgent, and a silent reporter becomes "unknown" after the report
    /// timeout, which the table treats as danger.
    #[test]
    fn modes_follow_the_reports_with_dwell_urgency_and_timeouts() {
        let mut h = decision();
        assert_eq!(report(&mut h, 3, DangerLevel::None, TargetState::None), "explore");
        let m = h.output::<Mode>("mode").expect("mode");
        assert!(m.is_empty());

        // a seen target: tracking, but only once explore held its dwell (750 ms)
        let since = h.now_ns();
        let mut switched_after = None;
        for k in 1..=20u64 {
            if report(&mut h, 1, DangerLevel::Low, TargetState::Seen) == "track" {
                switched_after = Some(k);
                break;
            }
        }
        let waited_ms = (h.now_ns() - since) / 1_000_000;
        assert!(switched_after.is_some(), "never switched to track");
        assert!(waited_ms <= 800, "switched after {waited_ms} ms");

        // danger is urgent: avoid at the very next cycle
        assert_eq!(report(&mut h, 1, DangerLevel::High, TargetState::Seen), "avoid");

        // both reporters fall silent: after the report timeout (1 s) danger
        // is unknown, and unknown danger is avoided
        h.advance(Duration::from_secs(3)).expect("silence");
        let modes = h.output::<Mode>("mode").expect("mode");
        assert_eq!(modes.len(), 30);
        let last = modes.last().expect("a mode");
        assert_eq!(last.name.as_str(), "avoid");
        assert_eq!(last.danger_level, UNKNOWN_LEVEL, "the silent monitor's danger is unknown");
    }

    /// The resource manager's report of a robot of 40 agents (more than the
    /// 16 its fixed array held before issue 42), on the sequence input
    /// `load`: read whole, its header's level counts — kb/explore.toml's
    /// `load = "critical"` rule selects `lean`, and the mode says the level —
    /// and a report without agents is read as well.
    #[test]
    fn a_resource_report_of_forty_agents_sets_the_load_level() {
        use shm_schemas::payloads::resources::report_bytes;
        use shm_schemas::payloads::{AgentLoad, LoadLevel, ResourceHeader};
        let mut h = decision();
        let loads: Vec<AgentLoad> = (0..40)
            .map(|i| AgentLoad { name: FixedName::new(&format!("agent{i}")), cpu_percent: 2.5, ..Default::default() })
            .collect();
        let header =
            |level: LoadLevel| ResourceHeader { cpus: 2, agents: 40, level: level as u8, ..Default::default() };
        let mut mode = String::new();
        for _ in 0..20 {
            let now = h.now_ns();
            h.send_from("situation", "safety", Situation::danger(DangerLevel::None, 2.0, now)).expect("danger");
            h.send_bytes_from("load", "rm", &report_bytes(&header(LoadLevel::Critical), &loads)).expect("40 loads");
            h.step().expect("step");
            mode =
                h.output::<Mode>("mode").expect("mode").last().map(|m| m.name.as_str().to_owned()).unwrap_or_default();
            if mode == "lean" {
                break;
            }
        }
        assert_eq!(mode, "lean", "a critical load selects lean");
        // an empty report (no agents yet) is read too: back to normal
        let now = h.now_ns();
        h.send_from("situation", "safety", Situation::danger(DangerLevel::None, 2.0, now)).expect("danger");
        h.send_bytes_from("load", "rm", &report_bytes(&header(LoadLevel::Normal), &[])).expect("no loads");
        h.step().expect("step");
        let last = h.output::<Mode>("mode").expect("mode").pop().expect("a mode");
        assert_eq!(last.load_level, LoadLevel::Normal as u8, "the newest report's level");
        assert_eq!(h.errors(), 0);
    }

    /// A knowledge base that does not load fails `new`, naming the file.
    #[test]
    fn a_missing_knowledge_base_is_refused_by_name() {
        let e = Harness::<Decision>::builder()
            .args(["--kb", "/nonexistent/kb.toml"])
            .start()
            .expect_err("no such file")
            .to_string();
        assert!(e.contains("/nonexistent/kb.toml"), "{e}");
    }
}
