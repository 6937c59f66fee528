//! The router's driver: it looks at processes, carries out what the core
//! ([`crate::serving::State`]) asks, and tells the core what happened.
//!
//! The core decides; the driver does. It owns what touches the world: the
//! iceoryx2 node and the agents' control clients ([`Calls`]), the writer
//! thread ([`Writer`]), the start-up processes of the agents it starts and
//! restarts ([`Spawner`]), the responders of requests owed an answer, and the
//! processes it waits for after a `nerve kill`. Before a command-line
//! request it runs the liveness check, so that the core answers from a
//! registry without dead agents.

use crate::calls::{Calls, Looks, Ticket};
use crate::serving::{Effect, Input, KILL_WAIT, RequestId, SaveId, State, protocol_error};
use crate::spawner::Spawner;
use crate::store::{Saved, Writer};
use agent_sdk::control::Responder;
use agent_sdk::process::{ProcessError, ProcessHandle};
use agent_sdk::world::{Ipc, World};
use iceoryx2::prelude::Node;
use shm_schemas::control::ProtocolError;
use shm_schemas::control::agent_to_router::AgentToRouter;
use shm_schemas::control::cli_to_router::{CliRequest, RouterError, RouterReply, RouterRequest};
use std::collections::{BTreeMap, VecDeque};
use std::path::PathBuf;
use std::time::Instant;

/// A `nerve kill` waiting for its process to go.
#[derive(Debug)]
struct Killing {
    ticket: Ticket,
    process: ProcessHandle,
    until: Instant,
}

/// The router's hands.
pub struct Driver {
    pub(crate) world: World,
    node: Node<Ipc>,
    pub(crate) core: State,
    pub(crate) writer: Writer,
    calls: Calls,
    spawner: Spawner,
    /// the connection list's file
    list_file: PathBuf,
    responders: BTreeMap<RequestId, Responder<RouterReply>>,
    next_request: RequestId,
    /// saves of the connection list the core waits for
    saves: BTreeMap<SaveId, Saved>,
    kills: Vec<Killing>,
}

impl Driver {
    /// The driver of `core` in `world`.
    pub fn new(
        world: World,
        node: Node<Ipc>,
        core: State,
        writer: Writer,
        spawner: Spawner,
        list_file: PathBuf,
    ) -> Driver {
        Driver {
            world,
            node,
            core,
            writer,
            calls: Calls::default(),
            spawner,
            list_file,
            responders: BTreeMap::new(),
            next_request: 0,
            saves: BTreeMap::new(),
            kills: Vec::new(),
        }
    }

    /// Takes a request: looks at the processes it names and hands it to the core.
    pub fn accept(&mut self, req: Result<RouterRequest, ProtocolError>, responder: Responder<RouterReply>) {
        let req = match req {
            Ok(r) => r,
            Err(e) => return responder.respond_or(&protocol_error(e), protocol_error),
        };
        self.next_request = self.next_request.wrapping_add(1);
        let id = self.next_request;
        self.responders.insert(id, responder);
        let input = match req {
            RouterRequest::Agent(AgentToRouter::Register(reg)) => {
                let process = crate::registry::check_process(&reg, &self.world);
                let holder_alive =
                    self.core.registry.get(&reg.name).is_some_and(|e| e.reg.pid != reg.pid && e.process.is_alive());
                Input::Register { id, reg, process, holder_alive }
            }
            RouterRequest::Agent(AgentToRouter::Unregister { name, pid }) => Input::Unregister { id, name, pid },
            RouterRequest::Cli(req) => {
                // answer from a registry without dead agents (a few /proc reads)
                self.check_liveness();
                let tool = match &req {
                    CliRequest::Attach { pid, .. } => Some(ProcessHandle::take(*pid).map_err(|e| e.to_string())),
                    _ => None,
                };
                Input::Cli { id, req, tool }
            }
        };
        self.feed(input);
    }

    /// Hands `input` to the core and carries out what it asks, and what
    /// follows from that.
    fn feed(&mut self, input: Input) {
        let mut inputs = VecDeque::from([input]);
        while let Some(input) = inputs.pop_front() {
            for effect in self.core.handle(Instant::now(), input) {
                if let Some(next) = self.carry_out(effect) {
                    inputs.push_back(next);
                }
            }
        }
    }

    /// Carries out one effect; what the core must be told at once, if anything.
    fn carry_out(&mut self, effect: Effect) -> Option<Input> {
        match effect {
            Effect::Reply { id, reply } => {
                if let Some(responder) = self.responders.remove(&id) {
                    responder.respond_or(&reply, protocol_error);
                }
            }
            Effect::Send { ticket, agent, cmd, timeout } => self.calls.queue(ticket, &agent, cmd, timeout),
            Effect::Reach { agent } => self.calls.registered(&agent),
            Effect::Release { agent } => self.calls.left(&agent),
            Effect::SaveList { save, body } => {
                let saved = self.writer.journaled(&self.list_file, body);
                self.saves.insert(save, saved);
            }
            Effect::Write { path, body } => {
                self.writer.write(&path, body);
            }
            Effect::Remove { path } => {
                self.writer.remove(&path);
            }
            Effect::Spawn { name, argv, cwd, env, restart } => {
                let log = self.world.log_file(&name);
                self.spawner.spawn(&name, &argv, cwd.as_deref(), env.as_deref(), &log, restart);
            }
            Effect::Start { ticket, name, argv, cwd, env } => {
                return self.spawner.start(ticket, &name, &argv, cwd.as_deref(), env.as_deref()).map(Input::StartEnded);
            }
            Effect::Kill { ticket, name, process } => {
                let pid = process.pid();
                match process.signal(nix::sys::signal::Signal::SIGKILL) {
                    Ok(()) => tracing::info!(agent = %name, pid, "killed agent {name} (pid {pid}) on request"),
                    Err(ProcessError::Gone { .. }) => {
                        tracing::info!(agent = %name, pid, "{name} (pid {pid}) had exited already")
                    }
                    Err(e) => {
                        return Some(Input::Killed { ticket, result: Err(RouterError::Internal(e.to_string())) });
                    }
                }
                self.kills.push(Killing { ticket, process, until: Instant::now() + KILL_WAIT });
            }
            Effect::Sweep => self.sweep(),
        }
        None
    }

    /// Tells the core which agents died and which tools feeding an input
    /// are gone (a few `/proc` reads).
    pub fn check_liveness(&mut self) {
        let dead: Vec<(String, u32)> = self
            .core
            .registry
            .iter()
            .filter(|(_, e)| !e.process.is_alive())
            .map(|(n, e)| (n.clone(), e.reg.pid))
            .collect();
        let mut gone_tools: Vec<u32> = self.core.transient.tools().filter(|p| !p.is_alive()).map(|p| p.pid()).collect();
        gone_tools.dedup();
        if dead.is_empty() && gone_tools.is_empty() {
            return;
        }
        self.feed(Input::Liveness { dead, gone_tools });
    }

    /// Cleans up after dead processes that were not agents (tools, programs).
    pub fn sweep(&mut self) {
        let cleaned = self.world.cleanup_dead_nodes();
        if cleaned > 0 {
            tracing::info!(cleaned, "cleaned the shared-memory resources of {cleaned} dead node(s)");
        }
    }

    /// The liveness tick: deaths, failed restarts, then the core's tick
    /// (restarts due, names gone for long).
    pub fn tick(&mut self) {
        self.check_liveness();
        for name in self.spawner.reap() {
            self.feed(Input::StartFailed { name });
        }
        self.feed(Input::Tick);
    }

    /// Sends what is queued for agents, and tells the core the replies,
    /// the starts, the saves on disk and the kills over.
    pub fn pump(&mut self, looks: &Looks) {
        for end in self.spawner.ended() {
            self.feed(Input::StartEnded(end));
        }
        for o in self.calls.pump(&self.world, &self.node, Instant::now(), looks) {
            self.feed(Input::Outcome(o));
        }
        let done: Vec<(SaveId, Result<(), String>)> =
            self.saves.iter().filter_map(|(id, s)| self.writer.outcome(*s).map(|r| (*id, r))).collect();
        for (save, result) in done {
            self.saves.remove(&save);
            self.feed(Input::Saved { save, result });
        }
        let now = Instant::now();
        let (over, waiting): (Vec<Killing>, Vec<Killing>) =
            std::mem::take(&mut self.kills).into_iter().partition(|k| !k.process.is_alive() || now >= k.until);
        self.kills = waiting;
        if !over.is_empty() {
            self.check_liveness();
        }
        for k in over {
            self.feed(Input::Killed { ticket: k.ticket, result: Ok(k.process.is_alive()) });
        }
    }

    /// Whether requests wait for agents, a kill or the disk.
    pub fn busy(&self) -> bool {
        self.calls.busy() || self.core.busy()
    }

    /// Whether something is awaited that no event announces (a process to
    /// die, the disk writer), so that the serving loop must look again soon
    /// by itself; replies of agents wake it (see [`crate::calls`]).
    pub fn needs_polling(&self) -> bool {
        !self.kills.is_empty()
            || !self.saves.is_empty()
            || (self.calls.busy() && !self.calls.in_flight())
            || self.spawner.needs_polling()
    }
}
