//! The nerve router: the registry of live agents and the connection list.
//!
//! It is control plane only. Agents register with it at start
//! ([`AgentToRouter::Register`](shm_schemas::control::agent_to_router::AgentToRouter))
//! and leave on stop; the command line asks it to connect, disconnect,
//! change rates, suspend, resume, set parameters and stop agents, and it
//! carries these out by commanding the agents' message checkers. Data never
//! passes through it: killing the router stops no data flow.
//!
//! Its rooms:
//! * [`registry`]: the live agents;
//! * [`wiring`]: the connection list, persisted through [`store`];
//! * [`supervision`]: restart policies, back-off, failure, persisted;
//! * [`spawner`]: starts every agent (asked by `nerve launch` and `nerve
//!   start`, or a restart) and reaps the start-up processes;
//! * [`remembered`]: run-time state re-applied to a re-registering agent;
//! * [`calls`]: commands to agents, sent without waiting;
//! * `serving`: the core, a state machine without I/O: what each request
//!   does, as jobs that wait for agents, and what to do about it (effects);
//! * `driver`: looks at processes and carries the core's effects out;
//! * this file: start-up and the serving loop.
//!
//! * **Never blocked by an agent**: the loop sleeps until a request comes
//!   or the liveness tick; commands to agents are sent and their replies
//!   picked up on later passes, so a hung agent delays its own commands only
//!   (reliability review R5).
//! * **Liveness**: every 250 ms it checks each agent's pid (and notices
//!   zombies); a dead agent is removed from the live registry and the stale
//!   iceoryx2 resources of dead nodes are cleaned. Its connections are kept,
//!   so that the agent restarted under the same name is rewired.
//! * **Persistence**: the connection list and the supervision list are saved
//!   atomically in the robot's state directory and reloaded at start.
//! * **Restart**: at start the router publishes a new epoch on
//!   `nerve/<robot>/router/epoch`; running agents see it and re-register.
//! * **Bounds**: the registry holds live agents only; the remembered state
//!   and the supervision entries are bounded in number, and those of names
//!   gone for [`remembered::FORGET_AFTER`] are dropped (a supervised agent
//!   still waiting for its restart is kept). The connection list is the
//!   user's wiring, persisted, and is never dropped behind their back.

pub mod calls;
mod driver;
pub mod events;
pub mod journal;
pub mod registry;
pub mod remembered;
mod serving;
pub mod spawner;
pub mod store;
pub mod supervision;
pub mod transient;
pub mod wiring;

use agent_sdk::clock::now_ns;
use agent_sdk::control::{ControlError, ControlServer, ControlSize, ToolSocket};
use agent_sdk::world::{Ipc, World};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use shm_schemas::control::cli_to_router::{RouterReply, RouterRequest};
use shm_schemas::payloads::RouterEpoch;
use std::time::{Duration, Instant};
use store::Store;

pub use supervision::{MAX_BACKOFF, MAX_SUPERVISED};

pub use calls::{AGENT_TIMEOUT, STATS_TIMEOUT};
use calls::{Looks, ReplyIds};
/// How often liveness is checked.
pub const LIVENESS_PERIOD: Duration = Duration::from_millis(250);
/// How often the shared memory of dead processes that are not agents (a
/// killed `nerve echo`, a crashed program) is cleaned up. The router is the
/// robot's janitor: agents and tools no longer scan every node of the robot
/// when they create or drop their own (iceoryx2's
/// `cleanup_dead_nodes_on_creation`/`_on_destruction`, see
/// [`agent_sdk::world::World::new`]); a dead agent's are cleaned at once.
const SWEEP_PERIOD: Duration = Duration::from_secs(5);
/// The longest sleep between two looks for agents' replies while commands
/// are in flight.
const MAX_POLL_INTERVAL: Duration = Duration::from_micros(200);

/// How often the router looks at every call in flight while it waits for
/// agents' replies, which otherwise wake it with their ids (see
/// [`calls`]): time-outs, agents gone and wake-ups lost are found then.
const FULL_LOOK_EVERY: Duration = Duration::from_millis(2);

/// Why the router could not start.
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// Another router serves this robot.
    #[error("a router already runs for robot {robot}; use it, or stop it first with `nerve --robot {robot} down`")]
    AlreadyRunning {
        /// robot
        robot: String,
    },
    /// The router before this one was killed and is still exiting (a
    /// thread of it still writes to disk, say) after this one waited for
    /// it for most of a second.
    #[error(
        "the router killed before is still exiting and holds robot {robot}'s service; start the router again in a moment"
    )]
    PreviousExiting {
        /// robot
        robot: String,
    },
    /// Anything else, with its message.
    #[error("{0}")]
    Other(String),
}

/// The router of one robot.
pub struct Router {
    /// agents register here (many clients, small messages)
    server: ControlServer<RouterRequest, RouterReply>,
    /// tools and programs call here (few clients, replies of any size)
    cli_server: ControlServer<RouterRequest, RouterReply>,
    /// `nerve` commands call here, without iceoryx2 ports of their own
    /// (`None` where the socket could not be made: they fall back to
    /// `cli_server`)
    tool_socket: Option<ToolSocket<RouterRequest, RouterReply>>,
    epoch_pub: Publisher<Ipc, RouterEpoch, ()>,
    /// woken when a start-up process the router started has ended
    start_wake: spawner::Wake,
    state: driver::Driver,
}

impl std::fmt::Debug for Router {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Router").field("robot", self.state.world.robot()).finish()
    }
}

impl Router {
    /// Creates the router of `world`, loading the persisted connection and
    /// supervision lists.
    pub fn new(world: World) -> Result<Self, StartError> {
        world.ensure_state_dirs().map_err(|e| StartError::Other(e.to_string()))?;
        let node = world.node("router").map_err(|e| StartError::Other(e.to_string()))?;
        world.cleanup_dead_nodes();
        // a killed router's server stays until someone cleans up after it:
        // this router did above, and so may every agent looking for a
        // router at the same moment (waited for)
        let serve = |service: String, size: ControlSize| {
            let blockable = |e: &ControlError| matches!(e, ControlError::AlreadyServed { .. });
            ControlServer::create_clearing(&node, &service, size, "the router's service", blockable).map_err(
                |e| match e {
                    ControlError::AlreadyServed { .. }
                        if agent_sdk::control::served_only_by_the_gone(&node, &service, size) =>
                    {
                        StartError::PreviousExiting { robot: world.robot().to_string() }
                    }
                    ControlError::AlreadyServed { .. } => {
                        StartError::AlreadyRunning { robot: world.robot().to_string() }
                    }
                    e => StartError::Other(e.to_string()),
                },
            )
        };
        let server = serve(world.robot().router_service(), ControlSize::ROUTER)?;
        let cli_server = serve(world.robot().router_cli_service(), ControlSize::ROUTER_CLI)?;
        // bound only now that this router is known to be the robot's only
        // one: it replaces the file a dead router left
        let tool_socket = match ToolSocket::bind(&world.tool_socket()) {
            Ok(s) => Some(s),
            Err(e) => {
                tracing::warn!(error = %e, "{e}; `nerve` commands use iceoryx2 instead (slower)");
                None
            }
        };
        let (start_wake, wake_handle) = spawner::wake_pipe().map_err(|e| StartError::Other(e.to_string()))?;
        let store = Store::new(world.state_dir());
        let connections = store.load().map_err(StartError::Other)?;
        let supervisor = supervision::Supervisor::load(world.state_dir(), Instant::now());
        let epoch = now_ns() ^ ((std::process::id() as u64) << 32);
        let epoch_pub = shm_schemas::services::router_epoch(&node, world.robot())
            .map_err(|e| StartError::Other(e.to_string()))?
            .publisher_builder()
            .create()
            .map_err(|e| StartError::Other(format!("cannot publish the router epoch: {e:?}")))?;
        epoch_pub
            .send_copy(RouterEpoch { epoch, pid: std::process::id(), reserved: 0 })
            .map_err(|e| StartError::Other(format!("cannot publish the router epoch: {e:?}")))?;
        // wake the agents' message checkers, which sleep until something happens
        match shm_schemas::services::router_epoch_event(&node, world.robot()).map(|f| f.notifier_builder().create()) {
            Ok(Ok(n)) => {
                if let Err(e) = n.notify() {
                    tracing::warn!("cannot wake the agents for the new epoch: {e:?}; they notice it within 2 s");
                }
            }
            Ok(Err(e)) => tracing::warn!("cannot wake the agents for the new epoch: {e:?}; they notice it within 2 s"),
            Err(e) => tracing::warn!("{e}; the agents notice the new router within 2 s"),
        }
        tracing::info!(
            robot = %world.robot(),
            pid = std::process::id(),
            connections = connections.len(),
            supervised = supervisor.len(),
            "router of robot {} started (pid {}), {} connection(s) loaded from {}",
            world.robot(),
            std::process::id(),
            connections.len(),
            store.path().display()
        );
        Ok(Router {
            server,
            cli_server,
            tool_socket,
            epoch_pub,
            start_wake,
            state: driver::Driver::new(
                world.clone(),
                node,
                serving::State::new(
                    epoch,
                    connections,
                    supervisor,
                    store.path().to_owned(),
                    world.logs_dir(),
                    Instant::now(),
                ),
                store::Writer::start()
                    .map_err(|e| StartError::Other(format!("cannot start the persisting thread: {e}")))?,
                spawner::Spawner::with_wake(wake_handle),
                store.path().to_owned(),
            ),
        })
    }

    /// Serves until SIGTERM, SIGINT or a `Shutdown` request.
    ///
    /// Call it from the thread that set the router's scheduling policy:
    /// that thread's real-time policy is marked not to pass to the agents
    /// the supervisor restarts from it (see [`reset_realtime_on_fork`]).
    pub fn run(mut self) -> Result<(), String> {
        reset_realtime_on_fork();
        let ws = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Ipc>()
            .map_err(|e| format!("cannot create the router's WaitSet: {e:?}"))?;
        let _req = ws.attach_notification(self.server.listener()).map_err(|e| format!("{e:?}"))?;
        let _cli = ws.attach_notification(self.cli_server.listener()).map_err(|e| format!("{e:?}"))?;
        let _tools = match &self.tool_socket {
            Some(s) => Some(ws.attach_notification(s).map_err(|e| format!("{e:?}"))?),
            None => None,
        };
        let _tick = ws.attach_interval(LIVENESS_PERIOD).map_err(|e| format!("{e:?}"))?;
        let _starts = ws.attach_notification(&self.start_wake).map_err(|e| format!("{e:?}"))?;
        // SIGTERM and SIGINT kept and woken through a pipe (iceoryx2's own
        // record of them can be overwritten, see `agent_sdk::termination`)
        let _term = match agent_sdk::termination::install() {
            Ok(t) => Some(ws.attach_notification(t).map_err(|e| format!("{e:?}"))?),
            Err(e) => {
                tracing::warn!("{e}; a SIGTERM may go unseen when another signal follows it");
                None
            }
        };
        let mut last_liveness = Instant::now();
        let mut last_sweep = Instant::now();
        let watchdog = agent_sdk::daemon::watchdog_interval();
        let mut last_ping = Instant::now();
        let mut poll = Duration::from_micros(10);
        let mut tidy = Tidy::default();
        let mut last_full_look = Instant::now();
        // `NERVE_REPLY_WAKE=off`: the router looks at every call on every
        // pass and polls while agents owe replies, as it did before agents
        // woke it (for measuring the two side by side, BENCHMARKS.md §6)
        let reply_wake = std::env::var_os("NERVE_REPLY_WAKE").is_none_or(|v| v != "off");
        loop {
            if agent_sdk::termination::requested() {
                break;
            }
            // While a job waits for what no event announces (a death, the
            // disk) or a tool's request is half read, look again soon; else
            // sleep until a request, an agent's reply or the tick. The
            // WaitSet counts its time-out in whole milliseconds (epoll),
            // which made every stage of a rewire wait 1 ms: a polling router
            // sleeps by itself instead, and a request coming meanwhile is
            // taken at the next look, at most MAX_POLL_INTERVAL later. A
            // SIGTERM meanwhile is kept by `termination` for the next look
            // (a busy spell ends with its jobs' time-outs).
            let awaiting = self.state.busy();
            let polling = self.state.needs_polling()
                || self.tool_socket.as_ref().is_some_and(ToolSocket::busy)
                || (awaiting && !reply_wake);
            if polling {
                std::thread::sleep(poll);
            } else {
                let wait = if awaiting {
                    // agents' replies wake the router; the time-out is for a
                    // full look (time-outs, agents gone, a wake-up lost)
                    FULL_LOOK_EVERY.saturating_sub(last_full_look.elapsed())
                } else {
                    tidy.next().map_or(LIVENESS_PERIOD, |at| at.saturating_duration_since(Instant::now()))
                };
                match ws
                    .wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, wait.min(LIVENESS_PERIOD))
                {
                    Ok(WaitSetRunResult::TerminationRequest) => break,
                    Ok(_) => {}
                    Err(e) => {
                        tracing::warn!("router wait failed: {e:?}");
                        std::thread::sleep(Duration::from_millis(50));
                    }
                }
            }
            // before receiving, so that what comes after wakes the next wait
            self.start_wake.drain();
            let mut replied = ReplyIds::default();
            self.server.take_wakeups(|id| replied.insert(id));
            self.cli_server.drain_wakeups();
            let mut progressed = false;
            for (server, tool) in [(&self.server, false), (&self.cli_server, true)] {
                loop {
                    let t = Instant::now();
                    let got = server.receive();
                    if t.elapsed() > Duration::from_micros(300) {
                        // iceoryx2 connected a new client or cleaned up one that left
                        tracing::debug!(us = t.elapsed().as_micros() as u64, tool, "slow receive");
                    }
                    match got {
                        Ok(Some((req, responder))) => {
                            progressed = true;
                            if tool {
                                tidy.after_request(Instant::now());
                            }
                            self.state.accept(req, responder);
                        }
                        Ok(None) => break,
                        Err(e) => {
                            tracing::warn!("router service failed: {e}");
                            break;
                        }
                    }
                }
            }
            if let Some(tools) = &self.tool_socket {
                while let Some((req, responder)) = tools.receive() {
                    progressed = true;
                    self.state.accept(req, responder);
                }
            }
            // a full look while polling anyway, and every FULL_LOOK_EVERY
            let looks = if polling || last_full_look.elapsed() >= FULL_LOOK_EVERY {
                last_full_look = Instant::now();
                Looks::All
            } else {
                Looks::Replied(replied)
            };
            self.state.pump(&looks);
            poll = if progressed { Duration::from_micros(10) } else { (poll * 2).min(MAX_POLL_INTERVAL) };
            if self.state.core.stopped() {
                break;
            }
            if tidy.due(Instant::now()) {
                let t = Instant::now();
                self.cli_server.tidy();
                tracing::trace!(us = t.elapsed().as_micros() as u64, "tidied the tools' service");
            }
            if last_liveness.elapsed() >= LIVENESS_PERIOD {
                last_liveness = Instant::now();
                if last_sweep.elapsed() >= SWEEP_PERIOD {
                    last_sweep = Instant::now();
                    self.state.sweep();
                }
                self.state.tick();
                self.server.tidy();
                self.cli_server.tidy();
                let _ = self.epoch_pub.update_connections();
            }
            if let Some(wd) = watchdog
                && last_ping.elapsed() >= wd / 2
            {
                let _ = agent_sdk::daemon::sd_notify("WATCHDOG=1");
                last_ping = Instant::now();
            }
        }
        self.state.writer.flush();
        tracing::info!("router stopped");
        Ok(())
    }
}

/// When to tidy the tools' service after a request. A `nerve` command exits
/// a few milliseconds after its reply, and iceoryx2 cleans up a client that
/// left at the server's next `receive`, walking every slot of its connection
/// (about 1 ms, 3.6 ms before [`agent_sdk::control`] trimmed the slots): on
/// the next caller's time, unless the router does it first while idle. It
/// looks every [`Tidy::EVERY`] for [`Tidy::FOR`] after each request (a look
/// that finds nobody gone costs a read of the service's client list); a
/// command still there after that is left for the liveness tick.
#[derive(Debug, Default)]
struct Tidy {
    next: Option<Instant>,
    until: Option<Instant>,
}

impl Tidy {
    const EVERY: Duration = Duration::from_millis(4);
    const FOR: Duration = Duration::from_millis(60);

    fn after_request(&mut self, now: Instant) {
        self.next = Some(now + Self::EVERY);
        self.until = Some(now + Self::FOR);
    }

    /// The next look, if one is due.
    fn next(&self) -> Option<Instant> {
        self.next
    }

    /// Whether a look is due at `now`; takes it and plans the next.
    fn due(&mut self, now: Instant) -> bool {
        match (self.next, self.until) {
            (Some(at), Some(until)) if at <= now => {
                self.next = Some(now + Self::EVERY).filter(|n| *n <= until);
                true
            }
            _ => false,
        }
    }
}

/// Marks the calling thread's real-time policy (SCHED_FIFO or SCHED_RR, set
/// by `nerve router` before it serves) with `SCHED_RESET_ON_FORK`, so that
/// every process and thread it creates starts under SCHED_OTHER.
///
/// Without it an agent restarted by the supervisor inherited the router's
/// SCHED_FIFO 10 through fork and exec: every thread of it, the task of a
/// `--no-realtime` agent, helper threads and a CPU-bound step included, ran
/// real-time and could starve normal work, where the same agent started by
/// `nerve launch` ran them SCHED_OTHER. A normal-priority router has
/// nothing to pass on and is left alone.
pub fn reset_realtime_on_fork() {
    // SAFETY: sched_getscheduler and sched_getparam on the calling thread (0)
    // with a valid sched_param; no other memory is touched.
    let (policy, mut param) = unsafe {
        let mut param = std::mem::zeroed::<libc::sched_param>();
        (libc::sched_getscheduler(0), if libc::sched_getparam(0, &mut param) == 0 { Some(param) } else { None })
    };
    let policy = policy & !libc::SCHED_RESET_ON_FORK;
    if !(policy == libc::SCHED_FIFO || policy == libc::SCHED_RR) {
        return;
    }
    let Some(param) = param.as_mut() else { return };
    // SAFETY: sets the calling thread's own policy to the one it has, plus the flag.
    let rc = unsafe { libc::sched_setscheduler(0, policy | libc::SCHED_RESET_ON_FORK, param) };
    if rc != 0 {
        tracing::warn!(
            "cannot mark the router's real-time policy reset-on-fork ({}); agents the supervisor restarts may run real-time",
            std::io::Error::last_os_error()
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tools_service_is_tidied_for_a_while_after_a_request_and_then_left_alone() {
        let t0 = Instant::now();
        let mut tidy = Tidy::default();
        assert_eq!(tidy.next(), None);
        assert!(!tidy.due(t0));
        tidy.after_request(t0);
        assert_eq!(tidy.next(), Some(t0 + Tidy::EVERY));
        assert!(!tidy.due(t0));
        let mut looks = 0;
        let mut now = t0;
        while let Some(at) = tidy.next() {
            now = at;
            assert!(tidy.due(now));
            looks += 1;
            assert!(looks <= 100, "the looks end");
        }
        assert_eq!(looks, (Tidy::FOR.as_millis() / Tidy::EVERY.as_millis()) as usize);
        assert!(now <= t0 + Tidy::FOR);
        assert!(!tidy.due(t0 + Duration::from_secs(1)));
        // a new request starts the looks again
        tidy.after_request(now);
        assert!(tidy.due(now + Tidy::EVERY));
    }

    #[test]
    fn a_real_time_router_starts_its_children_under_the_normal_policy() {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let param = libc::sched_param { sched_priority: 1 };
            // SAFETY: the calling thread's own policy, a valid sched_param.
            if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
                let _ = tx.send(None);
                return;
            }
            reset_realtime_on_fork();
            let child = std::process::Command::new("sleep").arg("5").spawn();
            let normal = libc::sched_param { sched_priority: 0 };
            // SAFETY: as above; back to normal before the thread ends
            unsafe { libc::sched_setscheduler(0, libc::SCHED_OTHER, &normal) };
            let _ = tx.send(Some(child));
        });
        let Some(child) = rx.recv().expect("the spawning thread answers") else {
            eprintln!(
                "SCHED_FIFO is not permitted here: nothing to reset (tests/tests/restart_state.rs checks the router)"
            );
            return;
        };
        let mut child = child.expect("spawn sleep");
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", child.id())).expect("child stat");
        let _ = child.kill();
        let _ = child.wait();
        let policy = stat.rsplit_once(')').and_then(|(_, r)| r.split_whitespace().nth(38)).unwrap_or("?").to_owned();
        assert_eq!(policy, libc::SCHED_OTHER.to_string(), "the child's policy (field 41 of {stat})");
    }
}
