//! The message checker (thesis Fig. 3-4): serves the agent's control service
//! (connect, disconnect, period, suspend, resume, parameters, statistics,
//! stop), answering each command at once, and does the housekeeping
//! (router epoch, CPU meter, systemd watchdog).

use super::Shared;
use super::router_link::RouterLink;
use super::runaway::{Guard, TaskThread, Verdict};
use crate::agent::Task;
use crate::clock::now_ns;
use crate::control::ControlServer;
use crate::daemon::{sd_notify, watchdog_interval};
use crate::meters::CpuMeter;
use crate::params::ParamTable;
use crate::ports::DynInput;
use crate::world::{Ipc, World};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use shm_schemas::control::agent_to_router::Registration;
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use shm_schemas::stats::AgentStats;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// How often an idle message checker wakes up for its housekeeping: read
/// the router's epoch (a restarted router is also noticed at the next
/// command), sample the CPU meter, ping the systemd watchdog. An idle agent
/// costs this many wake-ups and nothing else; a 100 ms tick made 100 idle
/// agents cost about 1000 wake-ups a second.
pub(super) const HOUSEKEEPING: Duration = Duration::from_secs(2);

/// The housekeeping tick: [`HOUSEKEEPING`], or often enough to ping a
/// systemd watchdog of interval `watchdog` at half its interval.
fn housekeeping_interval(watchdog: Option<Duration>) -> Duration {
    match watchdog {
        Some(wd) => HOUSEKEEPING.min(wd / 4).max(Duration::from_millis(1)),
        None => HOUSEKEEPING,
    }
}

pub(super) struct Checker<'a> {
    pub(super) world: &'a World,
    pub(super) node: &'a Node<Ipc>,
    pub(super) shared: &'a Arc<Shared>,
    pub(super) inputs: &'a [Arc<dyn DynInput>],
    pub(super) params: &'a ParamTable,
    pub(super) task_kind: Task,
    /// the task thread, its run-away guard and its real-time priority, when it runs real-time
    pub(super) guard: std::cell::RefCell<Option<(TaskThread, Guard, i32)>>,
    /// the lateness values copied out for a statistics answer, kept between
    /// answers: a fresh 16 KiB copy per `nerve ps` was a large part of an
    /// agent's answer (allocation and the allocator's consolidation)
    pub(super) lateness_scratch: std::cell::RefCell<Vec<u64>>,
}

impl Checker<'_> {
    /// Serves the control service until a stop (a `Stop` command, a
    /// signal, the task's request). Sleeps until a request, the task's
    /// wake-up, a due registration attempt or the [`HOUSEKEEPING`] tick.
    /// With `lock_memory`, locks the process's memory once the router's
    /// first commands are done.
    pub(super) fn run(
        &self,
        server: &ControlServer<AgentCommand, AgentReply>,
        wake: &Listener<Ipc>,
        link: &mut RouterLink,
        reg: &Registration,
        lock_memory: bool,
    ) {
        let ws = match WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<Ipc>()
        {
            Ok(ws) => ws,
            Err(e) => {
                tracing::error!("cannot create the message checker's WaitSet: {e:?}");
                return;
            }
        };
        let (Ok(_ctl), Ok(wake_guard)) = (ws.attach_notification(server.listener()), ws.attach_notification(wake))
        else {
            tracing::error!("cannot attach the control service to the WaitSet");
            return;
        };
        // SIGTERM and SIGINT wake the checker through a pipe and stay
        // recorded (iceoryx2's own record of them can be overwritten, see
        // `termination`); its check of the WaitSet stays as a fallback
        let _term = crate::termination::installed().and_then(|t| ws.attach_notification(t).ok());
        let mut cpu = CpuMeter::default();
        let reply_id = crate::control::reply_event_id(&reg.name);
        // The router hands a hot-added agent its inputs' connections in the
        // registration's reply, and sends the rest (a suspend re-applied,
        // then the connections) as soon as it has registered: all of it is
        // done before the epoch is watched (about 1 ms of iceoryx2 set-up),
        // which is not on that path.
        self.carry_out_first(link, &cpu);
        if self.serve(server, &cpu, link, reply_id) {
            return;
        }
        // Locking walks every page mapped so far (half a millisecond): done
        // once the first connections are made, not on their path.
        if lock_memory {
            match crate::rt::lock_memory() {
                Ok(()) => tracing::debug!("memory locked (mlockall, on fault)"),
                Err(e) => tracing::info!("memory not locked: {e}; page faults may add latency"),
            }
        }
        link.watch_epoch(self.world, self.node);
        // a restarted router wakes the checker at once (its epoch event)
        let epoch_wake = link.take_epoch_wake();
        let epoch_guard = epoch_wake.as_ref().and_then(|l| ws.attach_notification(l).ok());
        let watchdog = watchdog_interval();
        let tick = housekeeping_interval(watchdog);
        let mut guard = self.guard.borrow_mut().take();
        let mut last_cpu = 0u64;
        let mut last_ping = Instant::now();
        let mut next_tick = Instant::now() + tick;
        loop {
            if crate::termination::requested() {
                tracing::info!("termination requested by signal");
                return;
            }
            let now = Instant::now();
            let until = link.next_attempt().map_or(next_tick, |at| at.min(next_tick));
            let result = ws.wait_and_process_once_with_timeout(
                |id| {
                    if id.has_event_from(&wake_guard) {
                        let _ = wake.try_wait(|_| {});
                    }
                    if let (Some(g), Some(l)) = (&epoch_guard, &epoch_wake)
                        && id.has_event_from(g)
                    {
                        let _ = l.try_wait(|_| {});
                    }
                    CallbackProgression::Continue
                },
                until.saturating_duration_since(now),
            );
            match result {
                Ok(WaitSetRunResult::TerminationRequest) => {
                    tracing::info!("termination requested by signal");
                    return;
                }
                Ok(_) => {}
                Err(e) => {
                    tracing::warn!("message checker wait failed: {e:?}");
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
            if self.shared.stopping() {
                return;
            }
            // before serving, so that statistics asked after a quiet while are fresh
            let now_ns = now_ns();
            // on simulated time, CPU per simulated second (what the robot
            // would use in real time: the resource manager's policy holds
            // at any scale), but the guard against a runaway real-time
            // task watches the machine's own time
            if now_ns.saturating_sub(last_cpu) >= 1_000_000_000 {
                cpu.sample(now_ns);
                last_cpu = now_ns;
            }
            if let Some((task, g, priority)) = &mut guard {
                self.guard_task(task, g, *priority, crate::clock::wall_now_ns());
            }
            if self.serve(server, &cpu, link, reply_id) || self.shared.stopping() {
                return;
            }
            // cheap (one receive on the epoch subscriber) unless registering is due
            if !link.poll(self.node, self.world, reg, self.shared) {
                return;
            }
            self.carry_out_first(link, &cpu);
            if Instant::now() >= next_tick {
                next_tick = Instant::now() + tick;
            }
            if let Some(wd) = watchdog {
                // ping at half the interval, and only while the task makes progress
                if last_ping.elapsed() >= wd / 2 && self.task_alive(now_ns, wd) {
                    let _ = sd_notify("WATCHDOG=1");
                    last_ping = Instant::now();
                }
            }
        }
    }

    /// Carries out what the router's registration reply asked for first
    /// (the connections of this agent's inputs), as if each had come as a
    /// request; a refusal is logged, as the router logs one of a request.
    fn carry_out_first(&self, link: &mut RouterLink, cpu: &CpuMeter) {
        for cmd in link.take_first() {
            let what = format!("{cmd:?}");
            if let AgentReply::Error(e) = self.handle(cmd, cpu) {
                tracing::warn!("not done, as the router asked at registration: {what}: {e}");
            }
        }
    }

    /// Answers the commands that came, and wakes the router if any was
    /// answered (its calls wait for that event); whether one was a stop.
    fn serve(
        &self,
        server: &ControlServer<AgentCommand, AgentReply>,
        cpu: &CpuMeter,
        link: &RouterLink,
        reply_id: usize,
    ) -> bool {
        let mut stop_now = false;
        match server.serve(|req| match req {
            Ok(AgentCommand::Stop) => {
                stop_now = true;
                AgentReply::Ok
            }
            Ok(cmd) => self.handle(cmd, cpu),
            Err(e) => AgentReply::Error(e.to_string()),
        }) {
            Ok(0) => {}
            Ok(_) => link.replied(reply_id),
            Err(e) => tracing::warn!("control service failed: {e}"),
        }
        if stop_now {
            tracing::info!("stop requested");
        }
        stop_now
    }

    /// Demotes a real-time task that runs away, and restores it once calm
    /// (see [`super::runaway`]).
    fn guard_task(&self, task: &TaskThread, guard: &mut Guard, priority: i32, now_ns: u64) {
        let Some(cpu_ns) = task.cpu_ns() else { return };
        match guard.observe(now_ns, cpu_ns) {
            Verdict::Keep => {}
            Verdict::Demote { percent, over } => match task.demote() {
                Ok(()) => {
                    self.shared.realtime.store(false, Ordering::Relaxed);
                    tracing::warn!(
                        cpu_percent = percent.round(),
                        seconds = over.as_secs_f64(),
                        demotions = guard.demotions(),
                        "the task used {percent:.0}% of a CPU for {:.1} s under SCHED_FIFO (a step that does not \
                         return, or inputs that never stop: a loop of agents, a flood): demoted to SCHED_OTHER so that \
                         it cannot starve the machine; it gets real-time priority back after {} s below half the limit \
                         (--rt-cpu-limit, 0 never demotes)",
                        over.as_secs_f64(),
                        super::runaway::CALM.as_secs()
                    );
                }
                Err(e) => tracing::warn!("the task runs away ({percent:.0}% of a CPU) but cannot be demoted: {e}"),
            },
            Verdict::Restore { over } => match task.restore(priority) {
                Ok(()) => {
                    self.shared.realtime.store(true, Ordering::Relaxed);
                    tracing::info!(
                        seconds = over.as_secs_f64(),
                        "the task has been calm for {:.0} s: real-time priority {priority} restored",
                        over.as_secs_f64()
                    );
                }
                Err(e) => tracing::warn!("cannot restore the task's real-time priority: {e}"),
            },
        }
    }

    /// Whether the task thread has made progress recently enough to keep the
    /// watchdog happy: no step runs for longer than the watchdog interval, and
    /// a periodic task has completed a cycle recently.
    fn task_alive(&self, now: u64, wd: Duration) -> bool {
        let wd_ns = wd.as_nanos() as u64;
        let last = self.shared.figures().last_cycle_ns;
        let in_step = self.shared.in_step_since_ns.load(Ordering::Acquire);
        if in_step != 0 && now.saturating_sub(in_step) > wd_ns {
            return false;
        }
        if self.shared.suspended.load(Ordering::Acquire) || matches!(self.task_kind, Task::EventDriven) {
            return true;
        }
        let period = self.shared.period_ns.load(Ordering::Acquire);
        now.saturating_sub(last) < wd_ns.max(period * 2)
    }

    fn find_input(&self, name: &str) -> Result<&Arc<dyn DynInput>, String> {
        self.inputs.iter().find(|i| i.name() == name).ok_or_else(|| {
            let names: Vec<&str> = self.inputs.iter().map(|i| i.name()).collect();
            format!(
                "no input port {name:?} (inputs: {})",
                if names.is_empty() { "none".into() } else { names.join(", ") }
            )
        })
    }

    fn changed_inputs(&self) {
        self.shared.generation.fetch_add(1, Ordering::AcqRel);
        self.shared.poke();
    }

    fn handle(&self, cmd: AgentCommand, cpu: &CpuMeter) -> AgentReply {
        match cmd {
            AgentCommand::Connect { input, from_agent, from_port, type_name } => {
                // anyone who can open this service can send a Connect: the
                // names must be valid, and the source must exist (the input
                // opens it, never creates it), review R10
                if let Err(e) = shm_schemas::PortRef::new(&from_agent, &from_port) {
                    return AgentReply::Error(format!("cannot read {from_agent:?}/{from_port:?}: {e}"));
                }
                let inp = match self.find_input(&input) {
                    Ok(i) => i,
                    Err(e) => return AgentReply::Error(e),
                };
                let (from, to) =
                    (format!("{from_agent}/{from_port}"), format!("{}/{input}", self.node.name().as_str()));
                if let Err(e) = connectable(&type_name, None, &inp.spec()) {
                    return AgentReply::Error(e.refusal(&from, &to));
                }
                let _rewire =
                    tracing::info_span!("connect", input = %input, peer = %format_args!("{from_agent}/{from_port}"))
                        .entered();
                let t0 = now_ns();
                match inp.connect(self.node, self.world.robot(), &from_agent, &from_port) {
                    Ok(changed) => {
                        tracing::debug!(us = (now_ns() - t0) / 1000, "subscribed");
                        if changed {
                            tracing::info!("input {input} now reads {from_agent}/{from_port}");
                            self.changed_inputs();
                        }
                        AgentReply::Ok
                    }
                    Err(crate::ports::PortError::LayoutMismatch { type_name, theirs, .. }) => {
                        // the service says the source's layout: the same rule
                        // as the router's, without guessing which is older
                        let refusal = match connectable(&type_name, Some(theirs), &inp.spec()) {
                            Err(e) => e.refusal(&from, &to),
                            Ok(()) => format!("cannot connect {from} to {to}: {type_name} is laid out differently"),
                        };
                        tracing::warn!(%from, %to, "cannot subscribe: {refusal}");
                        AgentReply::Error(refusal)
                    }
                    Err(e) => {
                        tracing::warn!("cannot subscribe: {e}");
                        AgentReply::Error(e.to_string())
                    }
                }
            }
            AgentCommand::Disconnect { input, from_agent, from_port } => {
                let inp = match self.find_input(&input) {
                    Ok(i) => i,
                    Err(e) => return AgentReply::Error(e),
                };
                let _rewire =
                    tracing::info_span!("disconnect", input = %input, peer = %format_args!("{from_agent}/{from_port}"))
                        .entered();
                if inp.disconnect(&from_agent, &from_port) {
                    tracing::info!("input {input} no longer reads {from_agent}/{from_port}");
                    self.changed_inputs();
                    AgentReply::Ok
                } else {
                    AgentReply::Error(format!("input {input:?} does not read {from_agent}/{from_port}"))
                }
            }
            AgentCommand::SetPeriod { period_ns } => match self.task_kind {
                Task::EventDriven => AgentReply::Error("this agent is event-driven; it has no period".into()),
                Task::Periodic(_) if period_ns < 10_000 => AgentReply::Error("a period must be at least 10us".into()),
                Task::Periodic(_) if period_ns > crate::clock::nanos(crate::clock::MAX_DURATION) => {
                    AgentReply::Error("a period must be at most 1 day".into())
                }
                Task::Periodic(_) => {
                    self.shared.period_ns.store(period_ns, Ordering::Release);
                    self.shared.poke();
                    tracing::info!("period set to {}", crate::clock::format_duration(Duration::from_nanos(period_ns)));
                    AgentReply::Ok
                }
            },
            AgentCommand::Suspend => {
                self.shared.suspended.store(true, Ordering::Release);
                self.shared.poke();
                tracing::info!("suspended");
                AgentReply::Ok
            }
            AgentCommand::Resume => {
                self.shared.suspended.store(false, Ordering::Release);
                self.shared.poke();
                tracing::info!("resumed");
                AgentReply::Ok
            }
            AgentCommand::ParamGet { key } => match self.params.get(&key) {
                Ok(v) => AgentReply::Param(v),
                Err(e) => AgentReply::Error(e),
            },
            AgentCommand::ParamSet { key, value } => match self.params.set(&key, &value) {
                Ok(()) => {
                    tracing::info!("parameter {key} = {value}");
                    AgentReply::Ok
                }
                Err(e) => AgentReply::Error(e),
            },
            AgentCommand::ParamList => AgentReply::Params(self.params.list()),
            AgentCommand::Stats => AgentReply::Stats(self.stats(cpu)),
            AgentCommand::Stop => AgentReply::Ok,
        }
    }

    fn stats(&self, cpu: &CpuMeter) -> AgentStats {
        let now = now_ns();
        // copied out, so that the task, which records into them every
        // cycle, does not wait while the percentiles are worked out
        let mut recent = self.lateness_scratch.borrow_mut();
        let (cycles, rate_hz, overruns, max) = {
            let f = self.shared.figures();
            (f.cycles, f.rate.rate(now), f.overruns, f.lateness.copy_recent_into(&mut recent))
        };
        let (p50, p99, max) = crate::meters::summary_of(&mut recent, max);
        AgentStats {
            cycles,
            rate_hz,
            jitter_p50_ns: p50,
            jitter_p99_ns: p99,
            jitter_max_ns: max,
            overruns,
            cpu_percent: cpu.percent(),
            rss_bytes: cpu.rss_bytes(),
            realtime: self.shared.realtime.load(Ordering::Relaxed),
            cpu_latency: self.shared.cpu_latency,
            inputs: self.inputs.iter().flat_map(|i| i.stats(now)).collect(),
            queues: self.inputs.iter().flat_map(|i| i.queue_stats()).collect(),
            outputs: crate::port::keep_all::output_stats(),
            figures: super::poll::with_figure(self.shared, self.params.figures()),
        }
    }
}

/// Whether input `spec` may read a source of `type_name` (the name the
/// router checked) and, when the source's service says it, layout
/// `fingerprint`: the rule of the router and the launch file
/// ([`shm_schemas::schema::compat::check`]). The command carries no schema,
/// so a layout difference is told by fingerprint here; the router, which
/// holds both schemas, lists the fields before it sends the command.
fn connectable(
    type_name: &str,
    fingerprint: Option<u64>,
    spec: &shm_schemas::control::agent_to_router::PortSpec,
) -> Result<(), shm_schemas::schema::compat::Incompatible> {
    use shm_schemas::schema::compat::{Declared, check};
    check(
        Declared { type_name, fingerprint, schema: None },
        Declared { type_name: &spec.type_name, fingerprint: Some(spec.fingerprint), schema: None },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn housekeeping_is_rare_unless_a_watchdog_needs_pings() {
        assert_eq!(housekeeping_interval(None), HOUSEKEEPING);
        assert_eq!(housekeeping_interval(Some(Duration::from_secs(60))), HOUSEKEEPING);
        // pinged at half the interval: ticks at a quarter keep the pings in time
        assert_eq!(housekeeping_interval(Some(Duration::from_secs(4))), Duration::from_secs(1));
        assert!(housekeeping_interval(Some(Duration::ZERO)) > Duration::ZERO);
    }

    /// The agent's check is the router's rule: another type name is
    /// refused naming both ports, another layout too, and neither refusal
    /// guesses which side is older.
    #[test]
    fn a_connect_of_another_type_or_layout_is_refused_by_the_shared_rule() {
        use shm_schemas::control::agent_to_router::PortSpec;
        use shm_schemas::payloads::{Scalar, Tick};
        let spec = PortSpec::of::<Tick>("in");
        assert!(connectable("nerve::Tick", None, &spec).is_ok());
        assert!(connectable("nerve::Tick", Some(spec.fingerprint), &spec).is_ok());
        let e = connectable("nerve::Scalar", None, &spec).expect_err("another type");
        assert_eq!(
            e.refusal("a/out", "b/in"),
            "cannot connect a/out to b/in: a/out sends nerve::Scalar but b/in takes nerve::Tick"
        );
        let theirs = <Scalar as shm_schemas::Payload>::layout_fingerprint();
        let text =
            connectable("nerve::Tick", Some(theirs), &spec).expect_err("another layout").refusal("a/out", "b/in");
        assert!(text.contains("both declare nerve::Tick, but laid out differently"), "{text}");
        assert!(text.contains("make both declare the same layout") && !text.contains("older"), "{text}");
    }
}
