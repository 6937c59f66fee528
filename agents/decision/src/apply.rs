//! Carrying out a mode's actions through the router, off the decision task.
//!
//! A router call may take seconds: the router waits for the agent it
//! commands (up to its own time-out), and the agent may be slow, stopped or
//! gone. The decision task must not wait for it — while it waited, no
//! situation was read and no mode published. So the task only hands the
//! current mode's actions to an [`Applier`], which returns at once, and a
//! worker thread sends them:
//!
//! * **the latest mode wins**: a mode handed over while the worker is still
//!   busy with an older one replaces it; what was not yet sent of the older
//!   mode is dropped;
//! * what the router refuses (an agent not running yet) is tried again every
//!   `retry`, logged at warn once and at debug while it repeats;
//! * **a restarted router** (a new epoch on `nerve/<robot>/router/epoch`)
//!   gets the current mode's actions again: the router remembers what was
//!   set for each agent and re-applies it when an agent restarts, but a new
//!   router starts with no memory.
//!
//! Why not re-send everything periodically: the resource manager changes
//! periods too (it slows the least important agent under load), and a
//! periodic re-assertion of the mode's periods would undo its work every
//! few seconds. An agent restart is covered by the router; only a router
//! restart loses what was set, and the epoch says exactly when.

use crate::decide::Action;
use agent_sdk::World;
use agent_sdk::control::{ControlClient, router_client};
use agent_sdk::runtime::epoch_service;
use agent_sdk::world::Ipc;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply, RouterRequest};
use shm_schemas::payloads::RouterEpoch;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long one router call may take.
pub const ROUTER_TIMEOUT: Duration = Duration::from_secs(3);
/// How often the worker looks for a new router epoch while idle.
const EPOCH_POLL: Duration = Duration::from_millis(200);

/// The mode to apply, as the decision task hands it over.
#[derive(Debug, Default)]
struct Job {
    mode: String,
    actions: Vec<Action>,
    /// incremented at every hand-over
    generation: u64,
    stop: bool,
}

#[derive(Debug, Default)]
struct Shared {
    job: Mutex<Job>,
    wake: Condvar,
}

impl Shared {
    fn job(&self) -> MutexGuard<'_, Job> {
        self.job.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Applies modes' actions from a worker thread; see the module.
#[derive(Debug)]
pub struct Applier {
    shared: Arc<Shared>,
    handle: Option<JoinHandle<()>>,
}

impl Applier {
    /// Starts the worker; it joins `world` as iceoryx2 node `node_name` and
    /// tries refused actions again every `retry`.
    pub fn start(world: World, node_name: String, retry: Duration) -> Result<Self, String> {
        let shared = Arc::new(Shared::default());
        let worker = Worker::new(world, node_name, retry, shared.clone());
        let handle = std::thread::Builder::new()
            .name("apply".into())
            .spawn(move || worker.run())
            .map_err(|e| format!("cannot start the thread that applies the modes: {e}"))?;
        Ok(Applier { shared, handle: Some(handle) })
    }

    /// Hands the actions of `mode` to the worker and returns at once.
    pub fn post(&self, mode: &str, actions: Vec<Action>) {
        let mut job = self.shared.job();
        job.mode = mode.to_owned();
        job.actions = actions;
        job.generation += 1;
        drop(job);
        self.shared.wake.notify_all();
    }
}

impl Drop for Applier {
    /// Stops the worker; it ends after the router call in flight, if any.
    fn drop(&mut self) {
        self.shared.job().stop = true;
        self.shared.wake.notify_all();
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

struct Worker {
    world: World,
    node_name: String,
    retry: Duration,
    shared: Arc<Shared>,
    node: Option<Node<Ipc>>,
    router: Option<ControlClient<RouterRequest, RouterReply>>,
    epoch: Option<Subscriber<Ipc, RouterEpoch, ()>>,
    last_epoch: Option<u64>,
    /// whether any action was sent (before the first epoch was seen)
    sent_any: bool,
    generation: u64,
    mode: String,
    all: Vec<Action>,
    pending: Vec<Action>,
    next_try: Instant,
    failures_logged: bool,
}

impl Worker {
    fn new(world: World, node_name: String, retry: Duration, shared: Arc<Shared>) -> Self {
        Worker {
            world,
            node_name,
            retry,
            shared,
            node: None,
            router: None,
            epoch: None,
            last_epoch: None,
            sent_any: false,
            generation: 0,
            mode: String::new(),
            all: Vec::new(),
            pending: Vec::new(),
            next_try: Instant::now(),
            failures_logged: false,
        }
    }

    fn run(mut self) {
        loop {
            if !self.take_job() {
                break;
            }
            self.watch_epoch();
            if !self.pending.is_empty() && Instant::now() >= self.next_try {
                self.apply_pending();
            }
            // sleep until a new job, the next try or the next look at the epoch
            let job = self.shared.job();
            if job.stop || job.generation != self.generation {
                continue;
            }
            let mut wait = EPOCH_POLL;
            if !self.pending.is_empty() {
                wait = wait.min(self.next_try.saturating_duration_since(Instant::now()));
            }
            let _ = self.shared.wake.wait_timeout(job, wait);
        }
    }

    /// Takes a newly handed-over mode; `false` when asked to stop.
    fn take_job(&mut self) -> bool {
        let job = self.shared.job();
        if job.stop {
            return false;
        }
        if job.generation != self.generation {
            self.generation = job.generation;
            self.mode = job.mode.clone();
            self.all = job.actions.clone();
            self.pending = job.actions.clone();
            self.next_try = Instant::now();
            self.failures_logged = false;
        }
        true
    }

    /// Whether a newer mode has been handed over (or a stop asked for).
    fn overtaken(&self) -> bool {
        let job = self.shared.job();
        job.stop || job.generation != self.generation
    }

    fn node(&mut self) -> Result<&Node<Ipc>, String> {
        if self.node.is_none() {
            self.node = Some(self.world.node(&self.node_name).map_err(|e| e.to_string())?);
        }
        self.node.as_ref().ok_or_else(|| "no node".to_owned())
    }

    /// Re-sends the current mode's actions when a new router has started.
    fn watch_epoch(&mut self) {
        if self.epoch.is_none() {
            let world = self.world.clone();
            let Ok(node) = self.node() else { return };
            self.epoch = epoch_service(node, &world)
                .ok()
                .and_then(|f| f.subscriber_builder().buffer_size(1).history_request(1).create().ok());
        }
        let Some(sub) = &self.epoch else { return };
        let mut newest = None;
        while let Ok(Some(sample)) = sub.receive() {
            newest = Some(sample.epoch);
        }
        let Some(epoch) = newest else { return };
        if self.last_epoch == Some(epoch) {
            return;
        }
        // The first epoch seen may already be a new router's: the router
        // hands its epoch to a new subscriber only at its next tick, and one
        // killed before that never did. So actions sent before any epoch was
        // seen are sent again too (they are idempotent).
        let restarted = self.last_epoch.is_some();
        self.last_epoch = Some(epoch);
        if restarted {
            // the old client belongs to the router that is gone
            self.router = None;
        }
        if (restarted || self.sent_any) && !self.all.is_empty() {
            if restarted {
                tracing::info!(
                    "the router restarted: sending the {} action(s) of mode {} again",
                    self.all.len(),
                    self.mode
                );
            } else {
                tracing::debug!("first router epoch seen: sending the actions of mode {} again", self.mode);
            }
            self.pending = self.all.clone();
            self.next_try = Instant::now();
            self.failures_logged = false;
        }
    }

    /// Applies the pending actions; keeps those that failed for a later try.
    fn apply_pending(&mut self) {
        self.next_try = Instant::now() + self.retry;
        if self.router.is_none() {
            let world = self.world.clone();
            let client = self.node().and_then(|node| router_client(&world, node).map_err(|e| e.to_string()));
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
        let mut failed = Vec::new();
        let mut messages = Vec::new();
        let mut todo = std::mem::take(&mut self.pending).into_iter();
        for action in todo.by_ref() {
            if self.overtaken() {
                // a newer mode replaces this one: drop the rest
                return;
            }
            let Some(client) = &self.router else { break };
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
            self.sent_any = true;
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
        failed.extend(todo);
        if !failed.is_empty() {
            self.log_failure(&format!(
                "{} action(s) of mode {} not done yet, retrying every {}: {}",
                failed.len(),
                self.mode,
                agent_sdk::clock::format_duration(self.retry),
                messages.join("; ")
            ));
        } else {
            if self.failures_logged {
                tracing::info!("every action of mode {} is done", self.mode);
            }
            self.failures_logged = false;
        }
        self.pending = failed;
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

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::control::{ControlServer, ControlSize};
    use std::sync::atomic::{AtomicBool, Ordering};

    /// Removes the test robot's shared-memory and iceoryx2 files, even when the test fails.
    struct Cleanup(World);

    impl Drop for Cleanup {
        fn drop(&mut self) {
            for f in self.0.shm_files().into_iter().chain(self.0.iox2_files()) {
                let _ = std::fs::remove_file(f);
            }
        }
    }

    /// A router that holds every request until the test lets it go, and
    /// records what it was asked.
    fn slow_router(world: &World, release: Arc<AtomicBool>, seen: Arc<Mutex<Vec<String>>>) -> JoinHandle<()> {
        let world = world.clone();
        std::thread::spawn(move || {
            let node = world.node("fake-router").expect("node");
            let server: ControlServer<RouterRequest, RouterReply> =
                ControlServer::create(&node, &world.robot().router_cli_service(), ControlSize::ROUTER_CLI)
                    .expect("fake router");
            let t0 = Instant::now();
            while t0.elapsed() < Duration::from_secs(20) {
                let _ = server.serve(|req| {
                    seen.lock().unwrap_or_else(|p| p.into_inner()).push(format!("{req:?}"));
                    while !release.load(Ordering::Relaxed) && t0.elapsed() < Duration::from_secs(20) {
                        std::thread::sleep(Duration::from_millis(5));
                    }
                    RouterReply::Ok
                });
                if release.load(Ordering::Relaxed) && seen.lock().map(|s| s.len() >= 3).unwrap_or(false) {
                    break;
                }
                std::thread::sleep(Duration::from_millis(2));
            }
        })
    }

    #[test]
    fn posting_never_waits_for_the_router_and_the_latest_mode_wins() {
        let world = World::new(&format!("apply{}", std::process::id())).expect("world");
        let _cleanup = Cleanup(world.clone());
        let release = Arc::new(AtomicBool::new(false));
        let seen = Arc::new(Mutex::new(Vec::new()));
        let router = slow_router(&world, release.clone(), seen.clone());
        let applier = Applier::start(world.clone(), "dm-apply".into(), Duration::from_millis(50)).expect("applier");
        let first = vec![Action::Suspend("a".into()), Action::Suspend("b".into())];
        applier.post("one", first);
        // the worker's first call is held by the router...
        let held = wait(|| !seen.lock().map(|s| s.is_empty()).unwrap_or(true));
        assert!(held, "the worker never called the router");
        // ...and the decision task goes on handing over modes meanwhile
        applier.post("two", vec![Action::Resume("c".into())]);
        applier.post("three", vec![Action::Resume("d".into()), Action::Resume("e".into())]);
        assert!(!release.load(Ordering::Relaxed));
        release.store(true, Ordering::Relaxed);
        assert!(wait(|| seen.lock().map(|s| s.len() >= 3).unwrap_or(false)), "{:?}", seen.lock());
        drop(applier);
        let _ = router.join();
        let seen = seen.lock().map(|s| s.clone()).unwrap_or_default();
        // mode one's second action and mode two were overtaken: never sent
        assert_eq!(seen.len(), 3, "{seen:?}");
        assert!(seen[0].contains("Suspend") && seen[0].contains("\"a\""), "{seen:?}");
        assert!(seen[1].contains("\"d\"") && seen[2].contains("\"e\""), "{seen:?}");
    }

    fn wait(mut cond: impl FnMut() -> bool) -> bool {
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(10) {
            if cond() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        false
    }
}
