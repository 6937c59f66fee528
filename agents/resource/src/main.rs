//! `resource`: the resource manager (thesis section 3.2.6), a virtual
//! sensor of the machine's CPU and memory that also acts on them.
//!
//! Periodic (default every second). Each cycle it
//!
//! * asks the router for the live agents (`nerve ps`: pid, importance,
//!   period, state), and measures with `sysinfo` the CPU and memory of each
//!   agent's process and of the machine (per-process CPU is the difference
//!   of two samples at least `sysinfo::MINIMUM_CPU_UPDATE_INTERVAL` apart,
//!   so the first cycle only primes the counters);
//! * judges the load level with the thresholds of the knowledge base's
//!   `[resources]` table (`-- --kb FILE`; without it, built-in defaults:
//!   machine CPU 85 % high, 95 % critical, 70 % back to normal);
//! * acts, at most once per `settle`: lengthens the period of the least
//!   important agent, then suspends extras, and gives everything back in
//!   reverse order once the load is normal (see `plan`); every action is
//!   logged as `resource: ACTION (load LEVEL ...)`;
//! * publishes `nerve::ResourceReport` on output `load` for the decision maker:
//!   the machine's figures in its header, then every agent's load, busiest
//!   first, as many as the robot has (a sequence, `Seq<AgentLoad,
//!   ResourceHeader>`, of at most `MAX_AGENT_LOADS`).
//!
//! ```text
//! nerve start resource --name resource -- --kb kb/explore.toml
//! nerve connect resource/load decision/load
//! ```

use agent_sdk::control::{ControlClient, router_client};
use agent_sdk::world::Ipc;
use agent_sdk::{Agent, AgentError, Context, SeqOutput, Setup, Task, World};
use clap::Parser;
use iceoryx2::prelude::Node;
use nerve_decision::{KnowledgeBase, ResourcePolicy};
use nerve_resource::{Action, AgentObs, Machine, Measures, Planner, level, report};
use shm_schemas::control::agent_to_router::TaskKind;
use shm_schemas::control::cli_to_router::{AgentState, AgentView, CliRequest, RouterReply, RouterRequest};
use shm_schemas::payloads::{AgentLoad, LoadLevel, MAX_AGENT_LOADS, ResourceHeader};
use std::path::PathBuf;
use std::time::{Duration, Instant};
use sysinfo::{MINIMUM_CPU_UPDATE_INTERVAL, Pid, ProcessRefreshKind, ProcessesToUpdate, System};

/// How long one router call may take (`Ps` asks every agent for its figures).
const ROUTER_TIMEOUT: Duration = Duration::from_secs(5);

/// The resource manager's own options (after `--`).
#[derive(Debug, Parser)]
#[command(name = "nerve-resource --", about = "resource manager options")]
struct Args {
    /// The knowledge base whose `[resources]` table is the policy (see docs/decision.md).
    #[arg(long)]
    kb: Option<PathBuf>,
}

type RouterClient = ControlClient<RouterRequest, RouterReply>;

struct Resource {
    planner: Planner,
    world: World,
    node_name: String,
    out: SeqOutput<AgentLoad, ResourceHeader>,
    sys: Option<System>,
    router: Option<(RouterClient, Node<Ipc>)>,
    level: LoadLevel,
    last_refresh: Option<Instant>,
    warm: bool,
    router_warned: bool,
}

impl Resource {
    fn router(&mut self) -> Option<&RouterClient> {
        if self.router.is_none() {
            let r = self
                .world
                .node(&self.node_name)
                .map_err(|e| e.to_string())
                .and_then(|node| router_client(&self.world, &node).map(|c| (c, node)).map_err(|e| e.to_string()));
            match r {
                Ok(r) => self.router = Some(r),
                Err(e) => {
                    if !self.router_warned {
                        tracing::warn!(
                            "cannot reach the router ({e}); measuring the machine only until it runs (`nerve router --daemon`)"
                        );
                        self.router_warned = true;
                    }
                    return None;
                }
            }
        }
        self.router.as_ref().map(|(c, _)| c)
    }

    fn call(&mut self, req: CliRequest) -> Result<RouterReply, String> {
        let Some(client) = self.router() else { return Err("no router".into()) };
        match client.call(&RouterRequest::Cli(req), ROUTER_TIMEOUT) {
            Ok(RouterReply::Error(e)) => Err(e.to_string()),
            Ok(r) => {
                self.router_warned = false;
                Ok(r)
            }
            Err(e) => {
                self.router = None;
                Err(e.to_string())
            }
        }
    }

    fn agents(&mut self) -> Vec<AgentView> {
        match self.call(CliRequest::Ps) {
            Ok(RouterReply::Agents(v)) => v,
            Ok(other) => {
                tracing::warn!("unexpected reply to ps: {other:?}");
                Vec::new()
            }
            Err(e) => {
                tracing::debug!("ps: {e}");
                Vec::new()
            }
        }
    }

    fn act(&mut self, action: &Action) -> bool {
        let req = match action {
            Action::Slow { name, to_ns, .. } | Action::Restore { name, to_ns, .. } => {
                CliRequest::Rate { name: name.clone(), period_ns: *to_ns }
            }
            Action::Suspend { name } => CliRequest::Suspend { name: name.clone() },
            Action::Resume { name } => CliRequest::Resume { name: name.clone() },
        };
        match self.call(req) {
            Ok(_) => true,
            Err(e) => {
                tracing::warn!("resource: could not {action}: {e}");
                false
            }
        }
    }
}

/// On simulated time the machine's CPU is not judged: a busy machine
/// already holds the simulator's clock (docs/time.md), so shedding the
/// robot's work would only make a busy run behave differently, never
/// safer. The agents' CPU (per simulated second) and memory are judged as
/// on the wall clock.
fn on_simulated_time(mut policy: ResourcePolicy, simulated: bool) -> ResourcePolicy {
    if simulated && policy.machine_cpu.take().is_some() {
        tracing::info!(
            "on simulated time: the machine's CPU is not judged (a busy machine holds the simulator's clock); \
             the agents' CPU and memory are"
        );
    }
    policy
}

impl Agent for Resource {
    const KIND: &'static str = "resource";

    fn task() -> Task {
        Task::Periodic(Duration::from_secs(1))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let policy = match &args.kb {
            Some(p) => {
                let path = std::path::absolute(p).unwrap_or_else(|_| p.clone());
                KnowledgeBase::load(&path).map_err(|e| AgentError::Config(e.to_string()))?.resources
            }
            None => ResourcePolicy::default(),
        };
        let policy = on_simulated_time(policy, agent_sdk::simclock::active().is_some());
        Ok(Resource {
            planner: Planner::new(policy, setup.name()),
            world: setup.world().clone(),
            node_name: format!("{}-rm", setup.name()),
            out: setup.output_seq("load", MAX_AGENT_LOADS)?,
            sys: None,
            router: None,
            level: LoadLevel::Normal,
            last_refresh: None,
            warm: false,
            router_warned: false,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        // sysinfo reads /proc and reports nothing when it cannot: say so here
        std::fs::read_to_string("/proc/stat").map_err(|e| {
            AgentError::Other(format!(
                "cannot read the system's figures (/proc/stat: {e}); is /proc mounted and readable?"
            ))
        })?;
        let sys = System::new();
        self.sys = Some(sys);
        let p = self.planner.policy();
        tracing::info!(
            "policy: machine cpu {:?}, agents cpu {:?}, memory {:?}; settle {}, slow x{} up to x{}",
            p.machine_cpu,
            p.agents_cpu,
            p.memory,
            agent_sdk::clock::format_duration(p.settle),
            p.slow_factor,
            p.max_slow
        );
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let views = self.agents();
        let pids: Vec<Pid> = views.iter().map(|v| Pid::from_u32(v.pid)).collect();
        let Some(sys) = self.sys.as_mut() else { return Ok(()) };
        // per-process CPU is the difference of two samples at least MINIMUM_CPU_UPDATE_INTERVAL apart
        if self.last_refresh.is_none_or(|t| t.elapsed() >= MINIMUM_CPU_UPDATE_INTERVAL) {
            sys.refresh_cpu_usage();
            sys.refresh_memory();
            sys.refresh_processes_specifics(
                ProcessesToUpdate::Some(&pids),
                true,
                ProcessRefreshKind::nothing().with_cpu().with_memory(),
            );
            self.warm = self.last_refresh.is_some();
            self.last_refresh = Some(Instant::now());
        }
        let policy = self.planner.policy().clone();
        let obs: Vec<(AgentObs, u64)> = views
            .iter()
            .map(|v| {
                let p = sys.process(Pid::from_u32(v.pid));
                let importance = policy.importance_of(&v.name, v.importance);
                (
                    AgentObs {
                        name: v.name.clone(),
                        importance,
                        period_ns: if v.task == TaskKind::Periodic { v.period_ns } else { None },
                        suspended: v.state == AgentState::Suspended,
                        // per simulated second on simulated time: the policy holds at any scale
                        cpu_percent: p.map_or(0.0, |p| f64::from(p.cpu_usage())) / agent_sdk::simclock::scale(),
                    },
                    p.map_or(0, |p| p.memory()),
                )
            })
            .collect();
        let total_mem = sys.total_memory();
        let m = Measures {
            machine_cpu: f64::from(sys.global_cpu_usage()),
            agents_cpu: obs.iter().map(|(o, _)| o.cpu_percent).sum(),
            memory: if total_mem > 0 { sys.used_memory() as f64 * 100.0 / total_mem as f64 } else { 0.0 },
        };
        let cpus = sys.cpus().len() as u32;
        let (mem_total, mem_used) = (total_mem, sys.used_memory());
        if !self.warm {
            return Ok(()); // the first sample only primes the CPU counters
        }
        let new_level = level(&policy, &m, self.level);
        if new_level != self.level {
            tracing::info!(
                "resource: load level {} -> {} (machine cpu {:.0}%, agents {:.0}% of one core, memory {:.0}%)",
                self.level.name(),
                new_level.name(),
                m.machine_cpu,
                m.agents_cpu,
                m.memory
            );
            self.level = new_level;
        }
        // only agents that answer can be acted on (not restarting, failed or unresponsive ones)
        let agents: Vec<AgentObs> = obs
            .iter()
            .zip(&views)
            .filter(|(_, v)| matches!(v.state, AgentState::Running | AgentState::Suspended))
            .map(|((o, _), _)| o.clone())
            .collect();
        if let Some(action) = self.planner.plan(new_level, &agents, now) {
            let ok = self.act(&action);
            if ok {
                tracing::info!(
                    "resource: {action} (load {}, agents {:.0}% of one core, machine {:.0}%)",
                    new_level.name(),
                    m.agents_cpu,
                    m.machine_cpu
                );
            }
            self.planner.done(&action, ok, now);
        }

        let machine = Machine { stamp_ns: now, cpus, mem_total_bytes: mem_total, mem_used_bytes: mem_used };
        let (header, loads) = report(machine, &m, new_level, &self.planner, &obs);
        self.out.send(&header, &loads)?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Resource>()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_simulated_time_the_machine_cpu_is_not_judged_but_the_rest_is() {
        let p = ResourcePolicy::default();
        assert!(p.machine_cpu.is_some() && p.memory.is_some());
        let sim = on_simulated_time(p.clone(), true);
        assert!(sim.machine_cpu.is_none());
        assert_eq!(sim.memory.map(|t| t.high), p.memory.map(|t| t.high));
        let wall = on_simulated_time(p, false);
        assert!(wall.machine_cpu.is_some());
    }
}
