//! The `ros2` agent itself (the `agent` feature, on by default): its ports,
//! the conversions each step, and the Zenoh link thread that owns the
//! session. The task puts small messages itself and hands Images to the
//! link thread ([`crate::route`] says which and why).
//!
//! The task is event-driven: it steps when one of its inputs gets a sample
//! (the nerve side, published at once) or when the link thread's
//! subscribers leave a ROS message in an inbox and wake it through the
//! agent's waker ([`agent_sdk::Waker`]: the ROS side, sent on a port at
//! once). No clock runs on either path.
//! Without the feature the crate is the messages, their CDR and the bag
//! conversions only, with no Zenoh: what `nerve export --ros2` needs, so
//! that the `nerve` command does not build Zenoh (issue 41's first run).

use crate::{cdr, config, convert, link, msgs, route};
use agent_sdk::{Agent, AgentError, Context, Input, Output, Setup, Task, Waker};
use config::{Config, PubMap, SubMap};
use link::{Arrived, Inbox, Outgoing, Stats};
use msgs::RosMessage;
use route::{Put, Route, TaskPublishers};
use shm_schemas::payloads::motion::{GroundTruth, Odometry, VelocityCommand};
use shm_schemas::payloads::sonar::SonarScan;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::thread::JoinHandle;

/// How many samples per input one step converts at most (more wait for
/// the next step, which the agent's waker makes at once).
const BATCH: usize = 64;
/// How many messages (Images) may wait for the link thread.
const OUTGOING: usize = 256;

/// The agent's own arguments (after `--`).
#[derive(Debug, clap::Parser)]
#[command(name = "nerve-ros2")]
struct Ros2Args {
    /// The agent's configuration (TOML; see docs/ros2.md).
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

enum PubInput {
    Odometry(Input<Odometry>),
    Truth(Input<GroundTruth>),
    Velocity(Input<VelocityCommand>),
    Sonar(Input<SonarScan>),
    Frames(agent_sdk::memory::RingInput),
    /// any layout, mapped field by field (`Publish::user`)
    User(agent_sdk::dynamic::SchemaInput),
}

enum SubPort {
    Velocity(Output<VelocityCommand>),
    /// any layout, mapped field by field (`Subscribe::user`)
    User(agent_sdk::dynamic::SchemaOutput),
}

struct SubOutput {
    out: SubPort,
    inbox: Arc<Inbox>,
}

/// The `ros2` agent.
pub struct Ros2 {
    cfg: Config,
    inputs: Vec<PubInput>,
    /// which thread puts each published topic (by `cfg.publish`)
    routes: Vec<Route>,
    outputs: Vec<SubOutput>,
    stats: Arc<Stats>,
    /// the task's own publishers (its [`Route::Task`] topics), lent by the
    /// link thread while its session is open
    direct: Arc<TaskPublishers>,
    tx: Option<SyncSender<Outgoing>>,
    stop: Arc<AtomicBool>,
    link_thread: Option<JoinHandle<()>>,
    /// wakes the task: the inboxes' (the link thread's), and the step's
    /// own when it left samples for the next
    waker: Waker,
}

impl std::fmt::Debug for Ros2 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2").field("node", &self.cfg.node).field("publish", &self.cfg.publish.len()).finish()
    }
}

impl Agent for Ros2 {
    const KIND: &'static str = "ros2";

    fn task() -> Task {
        Task::EventDriven
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let path = setup.args::<Ros2Args>()?.config.ok_or_else(|| {
            AgentError::Config(
                "the ros2 agent needs its configuration: nerve start ros2 --name NAME -- --config FILE (see docs/ros2.md)"
                    .into(),
            )
        })?;
        let cfg = config::load(&path, setup.name()).map_err(|e| AgentError::Config(e.to_string()))?;
        let mut inputs = Vec::new();
        for p in &cfg.publish {
            inputs.push(match p.map {
                PubMap::OdometryToOdometry | PubMap::OdometryToTf => PubInput::Odometry(setup.input(&p.input)?),
                PubMap::TruthToOdometry => PubInput::Truth(setup.input(&p.input)?),
                PubMap::VelocityToTwist => PubInput::Velocity(setup.input(&p.input)?),
                PubMap::SonarToLaserScan | PubMap::SonarToRange => PubInput::Sonar(setup.input(&p.input)?),
                PubMap::FramesToImage => PubInput::Frames(agent_sdk::memory::MemorySetup::ring_input(setup, &p.input)?),
                PubMap::User => match &p.user {
                    Some(m) => PubInput::User(setup.input_of(&p.input, m.schema.clone())?),
                    None => return Err(AgentError::Config(format!("{}: a mapping without its plan", p.topic))),
                },
            });
        }
        let waker = setup.waker()?;
        let mut outputs = Vec::new();
        for s in &cfg.subscribe {
            let out = match (s.map, &s.user) {
                (SubMap::TwistToVelocity, _) => SubPort::Velocity(setup.output(&s.output)?),
                (SubMap::User, Some(m)) => SubPort::User(setup.output_of(&s.output, m.schema.clone())?),
                (SubMap::User, None) => {
                    return Err(AgentError::Config(format!("{}: a mapping without its plan", s.topic)));
                }
            };
            outputs.push(SubOutput { out, inbox: Arc::new(Inbox::waking(waker.clone())) });
        }
        let stats = Arc::new(Stats::new(cfg.publish.len()));
        {
            let stats = stats.clone();
            let inboxes: Vec<Arc<Inbox>> = outputs.iter().map(|o| o.inbox.clone()).collect();
            let topics: Vec<String> = cfg.publish.iter().map(|p| p.topic.clone()).collect();
            let subs: Vec<String> = cfg.subscribe.iter().map(|s| s.topic.clone()).collect();
            setup.figures(move || {
                let mut v = stats.figures(&topics);
                for (t, i) in subs.iter().zip(&inboxes) {
                    v.extend(i.figures(t));
                }
                v
            });
        }
        let routes = cfg.publish.iter().map(Route::of).collect();
        Ok(Ros2 {
            cfg,
            inputs,
            routes,
            outputs,
            stats,
            direct: Arc::new(TaskPublishers::default()),
            tx: None,
            stop: Arc::new(AtomicBool::new(false)),
            link_thread: None,
            waker,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        // a configuration zenoh refuses fails the start; a router that is
        // not up yet does not: the link thread keeps trying
        link::zenoh_config(&self.cfg).map_err(|e| AgentError::Config(e.to_string()))?;
        let (tx, rx) = std::sync::mpsc::sync_channel::<Outgoing>(OUTGOING);
        let cfg = self.cfg.clone();
        let inboxes: Vec<Arc<Inbox>> = self.outputs.iter().map(|o| o.inbox.clone()).collect();
        let (stats, stop, direct) = (self.stats.clone(), self.stop.clone(), self.direct.clone());
        let handle = std::thread::Builder::new()
            .name("ros2-link".into())
            .spawn(move || {
                agent_sdk::rt::drop_realtime();
                if let Some(mut link) = link::Link::open_retrying(&cfg, &inboxes, &direct, &rx, &stats, &stop) {
                    link.run(&rx, &stats, &stop);
                    link.close();
                }
            })
            .map_err(|e| AgentError::Other(format!("cannot start the ros2 link thread: {e}")))?;
        self.link_thread = Some(handle);
        self.tx = Some(tx);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let epoch = convert::epoch_now_ns();
        // an input that had more than a batch waiting: step again at once
        let mut more = false;
        for (i, (input, spec)) in self.inputs.iter_mut().zip(&self.cfg.publish).enumerate() {
            let mut encoded: Vec<Vec<u8>> = Vec::new();
            let mut failed = None;
            let mut push = |r: Result<Vec<u8>, cdr::CdrError>| match r {
                Ok(b) => encoded.push(b),
                Err(e) => failed = Some(e),
            };
            let (frame, child) = (spec.frame_id.as_str(), spec.child_frame_id.as_str());
            // how many samples the input gave (the ring and the layouts' drain: all there are)
            let taken = match input {
                PubInput::Odometry(inp) => inp.drain_up_to(BATCH, |_, o| {
                    let stamp = convert::ros_stamp(o.stamp_ns, now, epoch);
                    push(if spec.map == PubMap::OdometryToTf {
                        convert::odometry_to_tf(o, stamp, frame, child).to_cdr()
                    } else {
                        convert::odometry_to_ros(o, stamp, frame, child).to_cdr()
                    })
                }),
                PubInput::Truth(inp) => inp.drain_up_to(BATCH, |_, t| {
                    let stamp = convert::ros_stamp(t.stamp_ns, now, epoch);
                    push(convert::truth_to_ros(t, stamp, frame, child).to_cdr())
                }),
                PubInput::Velocity(inp) => inp.drain_up_to(BATCH, |_, c| push(convert::velocity_to_twist(c).to_cdr())),
                PubInput::Sonar(inp) => inp.drain_up_to(BATCH, |_, s| {
                    let stamp = convert::ros_stamp(s.stamp_ns, now, epoch);
                    if spec.map == PubMap::SonarToRange {
                        for r in convert::sonar_to_ranges(s, stamp, frame) {
                            push(r.to_cdr());
                        }
                    } else {
                        push(convert::sonar_to_scan(s, stamp, frame).to_cdr())
                    }
                }),
                PubInput::User(inp) => {
                    if let Some(m) = &spec.user {
                        inp.drain(|meta, b| push(m.encode(b, convert::ros_stamp(meta.stamp_ns, now, epoch), frame)));
                    }
                    0
                }
                PubInput::Frames(ring) => {
                    // the newest frame only, read in place from the ring and
                    // written into the message (older notices are skipped)
                    let read = ring.latest_with(|meta, px| {
                        let enc = convert::image_encoding(meta.format());
                        let channels = if enc == Some("rgb8") { 3 } else { 1 };
                        let stamp = convert::ros_stamp(meta.stamp_ns, now, epoch);
                        enc.and_then(|e| convert::image_cdr(stamp, frame, meta.width, meta.height, e, channels, px))
                    });
                    match read {
                        Ok(None) => {}
                        Ok(Some(Some(r))) => push(r),
                        Ok(Some(None)) => self.stats.refused_frame(i),
                        // overwritten before it was read: the next one comes
                        Err(agent_sdk::memory::MemoryError::Read(e)) => tracing::debug!(error = %e, "frame skipped"),
                        Err(e) => return Err(e.into()),
                    }
                    0
                }
            };
            more |= taken >= BATCH;
            if let Some(e) = failed {
                tracing::warn!(topic = %spec.topic, error = %e, "a sample could not be written as CDR");
            }
            match self.routes.get(i) {
                // small messages: put here and now (see crate::route)
                Some(Route::Task) => {
                    for bytes in encoded {
                        match self.direct.put(i, bytes) {
                            Put::Sent => self.stats.published(i),
                            Put::NotOpen => self.stats.dropped(i),
                            Put::Failed(e) => {
                                self.stats.dropped(i);
                                tracing::debug!(topic = %spec.topic, error = %e, "put failed");
                            }
                        }
                    }
                }
                _ => {
                    if let Some(tx) = &self.tx {
                        for bytes in encoded {
                            match tx.try_send(Outgoing { topic: i, bytes }) {
                                Ok(()) => {}
                                Err(TrySendError::Full(_)) => self.stats.dropped(i),
                                Err(TrySendError::Disconnected(_)) => {
                                    return Err(AgentError::Other("the ros2 link thread ended".into()));
                                }
                            }
                        }
                    }
                }
            }
        }
        for o in &mut self.outputs {
            for arrived in o.inbox.take() {
                match (arrived, &mut o.out) {
                    (Arrived::Twist(twist), SubPort::Velocity(out)) => match convert::twist_to_velocity(&twist, now) {
                        Ok(cmd) => out.send(cmd)?,
                        Err(e) => o.inbox.refuse(&e.to_string()),
                    },
                    (Arrived::Sample(bytes), SubPort::User(out)) => out.send_bytes(&bytes)?,
                    // the link decodes by the same configuration: never
                    _ => o.inbox.refuse("a message of another mapping"),
                }
            }
        }
        if more {
            self.waker.wake();
        }
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) {
        // the link thread takes the task's publishers back before it closes
        // the session (Link::close); no step runs any more
        self.stop.store(true, Ordering::Release);
        self.tx = None;
        if let Some(h) = self.link_thread.take() {
            let _ = h.join();
        }
    }
}
