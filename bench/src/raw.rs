//! The raw iceoryx2 round trip, written the way a developer would without
//! nerve: `ipc::Service` publish-subscribe of the same payload and user
//! header, paired with an event service, the reader blocked either on a
//! WaitSet (what the SDK uses) or directly on the event listener.
//!
//! One pair, [`Mode::PollThreadsafe`], polls as [`Mode::Poll`] does but on
//! `ipc_threadsafe::Service`, the service type nerve's ports are on (a
//! port is made on the message checker's thread and used on the task's):
//! iceoryx2 then guards every port's state with a pthread mutex and makes a
//! new one per loan. Beside `iox2-poll` it measures what that type costs
//! raw iceoryx2 itself, so `nerve-poll`'s gap splits into the type's share
//! and the SDK's own.
//!
//! The services are sized like the SDK's ports (subscribers, buffer, history,
//! safe overflow), so the comparison isolates the SDK's code path. They live
//! in the benchmark robot's iceoryx2 world, so `nerve down` removes them.
//! The pong side runs as a child process (`nerve-bench __raw-pong`), the
//! ping side in the benchmark process.

use crate::payloads::BenchPayload;
use crate::procs::{exit_status, parse_sub, realtime_like_an_agent};
use crate::with_payload;
use agent_sdk::World;
use agent_sdk::clock::now_ns;
use agent_sdk::ports::{MAX_SUBSCRIBERS, SUBSCRIBER_BUFFER};
use anyhow::{Context as _, Result, anyhow, bail};
use clap::Parser;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::waitset::{WaitSetGuard, WaitSetRunResult};
use shm_schemas::{FixedName, SampleHeader};
use std::io::Write as _;
use std::process::ExitCode;
use std::time::Duration;

/// The service type of the raw pairs (the thread-safe pair's is `ipc_threadsafe::Service`).
type Raw = ipc::Service;

/// How the reader blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Mode {
    /// a WaitSet with the listener attached (as the SDK's event-driven task)
    Waitset,
    /// `Listener::timed_wait` directly
    Listener,
    /// as `Waitset`, but each send first writes `P::default()` into the
    /// sample and then the sequence number, as `Output::send_with` does
    WaitsetFill,
    /// busy polling: both sides spin on `Subscriber::receive` and send no
    /// events, except one to wake the pong at the start of a batch (the pong
    /// blocks on its listener after 20 ms without a sample, so that it does
    /// not hold a core between batches)
    Poll,
    /// as `Poll`, on `ipc_threadsafe::Service` (nerve's ports' service type)
    PollThreadsafe,
}

impl Mode {
    fn as_str(self) -> &'static str {
        match self {
            Mode::Waitset => "waitset",
            Mode::Listener => "listener",
            Mode::WaitsetFill => "waitset-fill",
            Mode::Poll => "poll",
            Mode::PollThreadsafe => "poll-threadsafe",
        }
    }

    /// Whether both sides spin on `receive` instead of sleeping.
    pub(crate) fn polls(self) -> bool {
        matches!(self, Mode::Poll | Mode::PollThreadsafe)
    }
}

/// The ports of one side of a raw round trip, on service type `S`.
pub struct Side<P: BenchPayload, S: Service = Raw> {
    node: Node<S>,
    publisher: Publisher<S, P, SampleHeader>,
    subscriber: Subscriber<S, P, SampleHeader>,
    notifier: Notifier<S>,
    listener: Listener<S>,
    waitset: WaitSet<S>,
    sender: FixedName,
    seq: u64,
    mode: Mode,
}

impl<P: BenchPayload, S: Service> std::fmt::Debug for Side<P, S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Side").field("mode", &self.mode).field("size", &P::SIZE).finish()
    }
}

fn service_name(mode: Mode, size: usize, which: &str) -> String {
    format!("bench/raw/{}/{size}/{which}", mode.as_str())
}

impl<P: BenchPayload, S: Service> Side<P, S>
where
    Listener<S>: SynchronousMultiplexing,
{
    /// Opens the ports: publishes on `bench/raw/<mode>/<size>/<tx>`, reads `.../<rx>`.
    pub fn open(robot: &str, mode: Mode, tx: &str, rx: &str, node_name: &str) -> Result<Self> {
        let world = World::new(robot).context("robot world")?;
        agent_sdk::world::quiet_iceoryx2();
        let node = NodeBuilder::new()
            .name(&node_name.try_into().map_err(|e| anyhow!("node name: {e:?}"))?)
            .config(world.config())
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<S>()
            .map_err(|e| anyhow!("cannot create iceoryx2 node: {e:?}"))?;
        let name = |which: &str| service_name(mode, P::SIZE, which);
        let ps = |which: &str| -> Result<_> {
            let n = name(which);
            let sn: ServiceName = n.as_str().try_into().map_err(|e| anyhow!("service name {n}: {e:?}"))?;
            node.service_builder(&sn)
                .publish_subscribe::<P>()
                .user_header::<SampleHeader>()
                .max_publishers(4)
                .max_subscribers(MAX_SUBSCRIBERS)
                .max_nodes(40)
                .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
                .history_size(0)
                .enable_safe_overflow(true)
                .open_or_create()
                .map_err(|e| anyhow!("cannot open {n}: {e:?}"))
        };
        let ev = |which: &str| -> Result<_> {
            let n = name(which);
            let sn: ServiceName = n.as_str().try_into().map_err(|e| anyhow!("service name {n}: {e:?}"))?;
            node.service_builder(&sn)
                .event()
                .max_listeners(MAX_SUBSCRIBERS + 4)
                .max_notifiers(8)
                .max_nodes(40)
                .open_or_create()
                .map_err(|e| anyhow!("cannot open event {n}: {e:?}"))
        };
        let publisher = ps(tx)?.publisher_builder().create().map_err(|e| anyhow!("publisher: {e:?}"))?;
        let notifier = ev(tx)?.notifier_builder().create().map_err(|e| anyhow!("notifier: {e:?}"))?;
        let subscriber = ps(rx)?
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| anyhow!("subscriber: {e:?}"))?;
        let listener = ev(rx)?.listener_builder().create().map_err(|e| anyhow!("listener: {e:?}"))?;
        let waitset = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<S>()
            .map_err(|e| anyhow!("waitset: {e:?}"))?;
        Ok(Side {
            node,
            publisher,
            subscriber,
            notifier,
            listener,
            waitset,
            sender: FixedName::new(node_name),
            seq: 0,
            mode,
        })
    }

    /// Sends `seq` (only the sequence number is written; the frame stays in place) and notifies.
    fn send(&self, seq: u64) -> Result<()> {
        let mut s = self.publisher.loan_uninit().map_err(|e| anyhow!("loan: {e:?}"))?;
        *s.user_header_mut() = SampleHeader { sender: self.sender, seq, stamp_ns: now_ns() };
        if self.mode == Mode::WaitsetFill {
            let mut s = s.write_payload(P::default());
            s.payload_mut().set_seq(seq);
            s.send().map_err(|e| anyhow!("send: {e:?}"))?;
            self.notifier.notify().map_err(|e| anyhow!("notify: {e:?}"))?;
            return Ok(());
        }
        // SAFETY: the pointer is the loaned sample's payload, valid for writes. The
        // rest of the payload is shared memory the OS zero-filled when the service
        // was created and that earlier samples overwrote: every byte is initialised,
        // and any byte value is valid for the `u8` pixel data.
        let s = unsafe {
            P::write_seq_raw(s.payload_mut().as_mut_ptr(), seq);
            s.assume_init()
        };
        s.send().map_err(|e| anyhow!("send: {e:?}"))?;
        if !self.mode.polls() {
            self.notifier.notify().map_err(|e| anyhow!("notify: {e:?}"))?;
        }
        Ok(())
    }

    /// Blocks until woken or `timeout`; false on a termination request.
    /// `guard` is the listener's WaitSet attachment (WaitSet mode).
    fn wait(&self, guard: Option<&WaitSetGuard<'_, '_, S>>, timeout: Duration) -> Result<bool> {
        match guard {
            Some(guard) => {
                let r = self
                    .waitset
                    .wait_and_process_once_with_timeout(
                        |id| {
                            if id.has_event_from(guard) {
                                let _ = self.listener.try_wait(|_| {});
                            }
                            CallbackProgression::Continue
                        },
                        timeout,
                    )
                    .map_err(|e| anyhow!("wait: {e:?}"))?;
                Ok(!matches!(r, WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt))
            }
            None => {
                self.listener.timed_wait(|_| {}, timeout).map_err(|e| anyhow!("wait: {e:?}"))?;
                Ok(true)
            }
        }
    }

    fn attach(&self) -> Result<Option<WaitSetGuard<'_, '_, S>>> {
        match self.mode {
            Mode::Waitset | Mode::WaitsetFill => {
                Ok(Some(self.waitset.attach_notification(&self.listener).map_err(|e| anyhow!("attach: {e:?}"))?))
            }
            Mode::Listener | Mode::Poll | Mode::PollThreadsafe => Ok(None),
        }
    }

    /// One batch of `count` round trips; returns the round-trip times in ns.
    pub fn ping_batch(&mut self, count: usize) -> Result<Vec<u64>> {
        let mut rtts = Vec::with_capacity(count);
        let mut seq = self.seq;
        {
            // attached once per batch, outside the timed loop, as the SDK attaches once per rewiring
            let guard = self.attach()?;
            while rtts.len() < count {
                seq += 1;
                let t0 = now_ns();
                self.send(seq)?;
                if self.mode.polls() && rtts.is_empty() {
                    // wake the pong from its idle wait; the rest of the batch is pure polling
                    self.notifier.notify().map_err(|e| anyhow!("notify: {e:?}"))?;
                }
                loop {
                    let mut seen = None;
                    while let Some(sample) = self.subscriber.receive().map_err(|e| anyhow!("receive: {e:?}"))? {
                        if sample.payload().seq() == seq {
                            seen = Some(now_ns());
                        }
                    }
                    if let Some(t) = seen {
                        rtts.push(t.saturating_sub(t0));
                        break;
                    }
                    if now_ns().saturating_sub(t0) > 2_000_000_000 {
                        bail!("no echo for 2 s from the raw iceoryx2 pong ({:?}, {} B)", self.mode, P::SIZE);
                    }
                    if self.mode.polls() {
                        std::hint::spin_loop();
                        continue;
                    }
                    if !self.wait(guard.as_ref(), Duration::from_millis(500))? {
                        bail!("interrupted");
                    }
                }
            }
        }
        self.seq = seq;
        Ok(rtts)
    }

    /// The pong loop: echoes every sample until SIGTERM.
    fn pong_loop(&self) -> Result<()> {
        let guard = self.attach()?;
        let mut last_rx = now_ns();
        loop {
            let mut seqs = [0u64; SUBSCRIBER_BUFFER];
            let mut n = 0;
            while let Some(sample) = self.subscriber.receive().map_err(|e| anyhow!("receive: {e:?}"))? {
                if n < seqs.len() {
                    seqs[n] = sample.payload().seq();
                    n += 1;
                }
            }
            for &s in &seqs[..n] {
                self.send(s)?;
            }
            if self.mode.polls() {
                if n > 0 {
                    last_rx = now_ns();
                }
                if now_ns().saturating_sub(last_rx) < 20_000_000 {
                    std::hint::spin_loop();
                    continue;
                }
            }
            if n == 0 && self.node.wait(Duration::ZERO).is_err() {
                return Ok(()); // SIGTERM or SIGINT
            }
            if !self.wait(guard.as_ref(), Duration::from_millis(200))? {
                return Ok(());
            }
        }
    }
}

/// Arguments of `nerve-bench __raw-pong`.
#[derive(Debug, Parser)]
#[command(name = "nerve-bench __raw-pong")]
struct PongArgs {
    #[arg(long)]
    robot: String,
    #[arg(long, value_enum)]
    mode: Mode,
    #[arg(long)]
    size: usize,
}

/// The CPU a polling pong runs on (raw iceoryx2's and nerve's); the ping's is [`crate::hop::PINNED_CPU`].
pub(crate) const POLL_PONG_CPU: usize = 1;

/// Keeps the calling thread on `cpu`; says so when refused (a machine without it).
fn pin_to(cpu: usize) {
    if let Err(e) = agent_sdk::rt::set_affinity(&agent_sdk::rt::CpuList(vec![cpu])) {
        eprintln!("warning: cannot keep the polling pong on CPU {cpu}: {e}");
    }
}

/// Entry of `nerve-bench __raw-pong`: prints `ready` once its ports exist.
pub fn pong_main(args: Vec<String>) -> ExitCode {
    let a: PongArgs = match parse_sub("__raw-pong", args) {
        Ok(a) => a,
        Err(code) => return code,
    };
    exit_status(
        "raw pong",
        with_payload!(a.size, P => pong::<P>(&a), _ => Err(anyhow!("no payload of {} bytes", a.size))),
    )
}

fn pong<P: BenchPayload>(a: &PongArgs) -> Result<()> {
    if a.mode.polls() {
        // as nerve's polling pong (`nerve-poll`): SCHED_OTHER, on CPU 1
        pin_to(POLL_PONG_CPU);
    } else {
        realtime_like_an_agent(20);
    }
    if a.mode == Mode::PollThreadsafe {
        let side = Side::<P, ipc_threadsafe::Service>::open(&a.robot, a.mode, "pong", "ping", "raw-pong")?;
        ready()?;
        return side.pong_loop();
    }
    let side = Side::<P>::open(&a.robot, a.mode, "pong", "ping", "raw-pong")?;
    ready()?;
    side.pong_loop()
}

/// Tells the benchmark that the pong's ports exist.
fn ready() -> Result<()> {
    println!("ready");
    std::io::stdout().flush().context("stdout")
}
