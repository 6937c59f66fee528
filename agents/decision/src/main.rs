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
//!   parameters, suspend, resume and periods of agents; what the router
//!   refuses (an agent not running yet) is tried again every `retry`;
//! * publishes the current mode every cycle on output `mode` (`nerve::Mode`).
//!
//! ```text
//! nerve start decision --name decision -- --kb kb/explore.toml
//! nerve connect safety/situation decision/situation
//! nerve connect tracker/situation decision/situation
//! nerve connect resource/load decision/load
//! ```

use agent_sdk::control::{ControlClient, router_client};
use agent_sdk::world::Ipc;
use agent_sdk::{Agent, AgentError, Context, Input, Output, Setup, Task, World};
use clap::Parser;
use iceoryx2::prelude::Node;
use nerve_decision::{Action, Arbiter, Facts, KnowledgeBase, Reports, actions, lookup};
use shm_schemas::FixedName;
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply, RouterRequest};
use shm_schemas::payloads::situation::UNKNOWN_LEVEL;
use shm_schemas::payloads::{Mode, ResourceReport, Situation};
use std::path::PathBuf;
use std::time::Duration;

/// How long one router call may take.
const ROUTER_TIMEOUT: Duration = Duration::from_secs(3);

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
    router: Option<(ControlClient<RouterRequest, RouterReply>, Node<Ipc>)>,
    node_name: String,
    pending: Vec<Action>,
    next_try_ns: u64,
    failures_logged: bool,
}

impl Decision {
    /// Applies the pending actions; keeps those that failed for a later try.
    fn apply_pending(&mut self, now_ns: u64) {
        if self.pending.is_empty() || now_ns < self.next_try_ns {
            return;
        }
        self.next_try_ns = now_ns.saturating_add(agent_sdk::clock::nanos(self.kb.decision.retry));
        if self.router.is_none() {
            let client = self
                .world
                .node(&self.node_name)
                .map_err(|e| e.to_string())
                .and_then(|node| router_client(&self.world, &node).map(|c| (c, node)).map_err(|e| e.to_string()));
            match client {
                Ok(c) => self.router = Some(c),
                Err(e) => {
                    self.log_failure(&format!(
                        "cannot reach the router ({e}); {} action(s) wait (start it with `nerve router --daemon`)",
                        self.pending.len()
                    ));
                    return;
                }
            }
        }
        let Some((client, _)) = &self.router else { return };
        let mut failed = Vec::new();
        let mut messages = Vec::new();
        for action in std::mem::take(&mut self.pending) {
            let req = match &action {
                Action::Weights { actuator, text } => {
                    CliRequest::ParamSet { name: actuator.clone(), key: "weights".into(), value: text.clone() }
                }
                Action::Resume(name) => CliRequest::Resume { name: name.clone() },
                Action::Suspend(name) => CliRequest::Suspend { name: name.clone() },
                Action::Rate { agent, period } => {
                    CliRequest::Rate { name: agent.clone(), period_ns: agent_sdk::clock::nanos(*period) }
                }
            };
            match client.call(&RouterRequest::Cli(req), ROUTER_TIMEOUT) {
                Ok(RouterReply::Ok) => tracing::debug!("done: {action}"),
                Ok(RouterReply::Error(e)) => {
                    messages.push(format!("{action}: {e}"));
                    failed.push(action);
                }
                Ok(other) => {
                    messages.push(format!("{action}: unexpected reply {other:?}"));
                    failed.push(action);
                }
                Err(e) => {
                    messages.push(format!("{action}: {e}"));
                    failed.push(action);
                    // the router may have restarted: open a new client next time
                    self.router = None;
                    break;
                }
            }
        }
        if !failed.is_empty() {
            self.log_failure(&format!(
                "{} action(s) of mode {} not done yet, retrying every {}: {}",
                failed.len(),
                self.arbiter.current().unwrap_or("none"),
                agent_sdk::clock::format_duration(self.kb.decision.retry),
                messages.join("; ")
            ));
        } else if self.failures_logged {
            tracing::info!("every action of mode {} is done", self.arbiter.current().unwrap_or("none"));
        }
        if failed.is_empty() {
            self.failures_logged = false;
        }
        self.pending.extend(failed);
    }

    /// Logs a failure at warn the first time, at debug while it repeats.
    fn log_failure(&mut self, msg: &str) {
        if self.failures_logged {
            tracing::debug!("{msg}");
        } else {
            tracing::warn!("{msg}");
            self.failures_logged = true;
        }
    }
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
            router: None,
            node_name: format!("{}-decide", setup.name()),
            pending: Vec::new(),
            next_try_ns: 0,
            failures_logged: false,
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
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let reports = &mut self.reports;
        self.situation.drain(|m, s| reports.situation(m.sender.as_str(), *s, now));
        if let Some((_, r)) = self.load.latest() {
            self.reports.load(r, now);
        }
        let facts = self.reports.facts(now, self.kb.decision.report_timeout);
        if facts != self.facts {
            tracing::debug!("situation: {facts}");
            self.facts = facts;
        }
        if let Some((rule, mode)) = lookup(&self.kb, &facts) {
            if let Some(change) = self.arbiter.offer(mode, now) {
                tracing::info!("mode change: {} -> {} ({facts}; rule {})", change.from, change.to, rule + 1);
                self.pending = actions(mode);
                self.next_try_ns = 0;
                self.failures_logged = false;
            }
        }
        self.apply_pending(now);
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
