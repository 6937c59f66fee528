//! `decision`: the global decision maker (thesis sections 3.2.5 and
//! 4.2.2.4). A periodic agent (default every 100 ms) that
//!
//! * reads the functional agents' reports on input `situation`
//!   (`nerve::Situation`, any number of senders) and the resource manager's
//!   on input `load` (`nerve::ResourceReport`);
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

use agent_sdk::{Agent, AgentError, Context, Input, Output, Setup, Task, World};
use clap::Parser;
use nerve_decision::apply::Applier;
use nerve_decision::{Arbiter, Facts, KnowledgeBase, Reports, actions, lookup};
use shm_schemas::FixedName;
use shm_schemas::payloads::situation::UNKNOWN_LEVEL;
use shm_schemas::payloads::{Mode, ResourceReport, Situation};
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
    load: Input<ResourceReport>,
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
        let args = Args::try_parse_from(std::iter::once("nerve-decision --".to_owned()).chain(setup.args().to_vec()))
            .map_err(|e| AgentError::Config(e.to_string()))?;
        let path = std::path::absolute(&args.kb).unwrap_or(args.kb);
        let kb = KnowledgeBase::load(&path).map_err(|e| AgentError::Config(e.to_string()))?;
        let arbiter = Arbiter::new(kb.decision.min_dwell);
        Ok(Decision {
            world: setup.world().clone(),
            situation: setup.input("situation")?,
            load: setup.input("load")?,
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
        if let Some((_, r)) = self.load.latest() {
            self.reports.load(r, now);
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
