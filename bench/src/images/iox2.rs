//! The `iox2-slice` transport of the `images` scenario: raw iceoryx2 0.10
//! publish-subscribe of `[u8]` slices with a `SampleHeader` user header, one
//! service `bench/img/<res key>/<n>` per reader count `n`, each paired with
//! an event service. The writer (in the benchmark process) loans a slice of
//! one frame (`loan_slice_uninit`), fills it in place, stamps the header,
//! sends and notifies; each reader (`nerve-bench __img-iox2-reader`, one
//! process per reader) blocks on a WaitSet with the listeners of its
//! services attached, and reads the frame in place.
//!
//! Services: 1 publisher, 8 subscribers, a subscriber buffer of 4 frames,
//! no history, safe overflow (a camera's newest frames matter), in the
//! benchmark robot's iceoryx2 world, so that `nerve down` removes them.

use super::frame::{self, FrameHead, FramePub, Recorder, Res};
use crate::procs::{exit_status, parse_sub, realtime_like_an_agent};
use agent_sdk::World;
use agent_sdk::clock::now_ns;
use anyhow::{Context as _, Result, anyhow};
use clap::Parser;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use iceoryx2::waitset::WaitSetRunResult;
use shm_schemas::{FixedName, SampleHeader};
use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

type Raw = ipc::Service;
/// The frame service and its event service.
type Services = (publish_subscribe::PortFactory<Raw, [u8], SampleHeader>, event::PortFactory<Raw>);
/// A publisher and a notifier, per reader count.
type Ports = Vec<(usize, Publisher<Raw, [u8], SampleHeader>, Notifier<Raw>)>;

/// Most readers of one service.
pub const MAX_READERS: usize = 8;
/// Frames a subscriber buffers.
const BUFFER: usize = 4;

fn node(robot: &str, name: &str) -> Result<Node<Raw>> {
    let world = World::new(robot).context("robot world")?;
    agent_sdk::world::quiet_iceoryx2();
    NodeBuilder::new()
        .name(&name.try_into().map_err(|e| anyhow!("node name: {e:?}"))?)
        .config(world.config())
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<Raw>()
        .map_err(|e| anyhow!("cannot create iceoryx2 node: {e:?}"))
}

fn service_name(res: Res, n: usize) -> Result<ServiceName> {
    let s = format!("bench/img/{}/{n}", res.key);
    s.as_str().try_into().map_err(|e| anyhow!("service name {s}: {e:?}"))
}

fn services(node: &Node<Raw>, res: Res, n: usize) -> Result<Services> {
    let name = service_name(res, n)?;
    let ps = node
        .service_builder(&name)
        .publish_subscribe::<[u8]>()
        .user_header::<SampleHeader>()
        .max_publishers(1)
        .max_subscribers(MAX_READERS)
        .max_nodes(MAX_READERS + 4)
        .subscriber_max_buffer_size(BUFFER)
        .history_size(0)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| anyhow!("cannot open {name}: {e:?}"))?;
    let ev = node
        .service_builder(&name)
        .event()
        .max_listeners(MAX_READERS + 2)
        .max_notifiers(2)
        .max_nodes(MAX_READERS + 4)
        .open_or_create()
        .map_err(|e| anyhow!("cannot open event {name}: {e:?}"))?;
    Ok((ps, ev))
}

/// The writer: a publisher and a notifier per reader count.
pub struct Iox2Writer {
    _node: Node<Raw>,
    ports: Ports,
    len: usize,
    sender: FixedName,
}

impl std::fmt::Debug for Iox2Writer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Iox2Writer").field("len", &self.len).finish()
    }
}

impl Iox2Writer {
    /// Opens the services of `res` for every count of `counts`.
    pub fn open(robot: &str, res: Res, counts: &[usize]) -> Result<Self> {
        let node = node(robot, &format!("img-writer-{}", res.key))?;
        let mut ports = Vec::new();
        for &n in counts {
            let (ps, ev) = services(&node, res, n)?;
            let p = ps
                .publisher_builder()
                .initial_max_slice_len(res.bytes())
                .create()
                .map_err(|e| anyhow!("publisher: {e:?}"))?;
            let nt = ev.notifier_builder().create().map_err(|e| anyhow!("notifier: {e:?}"))?;
            ports.push((n, p, nt));
        }
        Ok(Iox2Writer { _node: node, ports, len: res.bytes(), sender: FixedName::new("img-writer") })
    }
}

impl FramePub for Iox2Writer {
    fn publish(&mut self, n: usize, h: &FrameHead) -> Result<(u64, u64)> {
        let (_, p, nt) =
            self.ports.iter().find(|(k, _, _)| *k == n).ok_or_else(|| anyhow!("no service for {n} readers"))?;
        let t0 = now_ns();
        let mut s = p.loan_slice_uninit(self.len).map_err(|e| anyhow!("loan: {e:?}"))?;
        let t1 = now_ns();
        // SAFETY: the pointer is the loaned slice's, valid for `len` bytes of writes.
        unsafe { frame::fill_raw(s.payload_mut().as_mut_ptr().cast::<u8>(), self.len, h) };
        let t2 = now_ns();
        *s.user_header_mut() = SampleHeader { sender: self.sender, seq: h.seq, stamp_ns: t2 };
        // SAFETY: the rest of the slice is shared memory the OS zero-filled when
        // the service was created and that earlier frames overwrote: every byte is
        // initialised, and any byte value is a valid `u8`.
        let s = unsafe { s.assume_init() };
        s.send().map_err(|e| anyhow!("send: {e:?}"))?;
        nt.notify().map_err(|e| anyhow!("notify: {e:?}"))?;
        let t3 = now_ns();
        Ok((t2, (t1 - t0) + (t3 - t2)))
    }
}

/// Arguments of `nerve-bench __img-iox2-reader`.
#[derive(Debug, Parser)]
#[command(name = "nerve-bench __img-iox2-reader")]
struct ReaderArgs {
    #[arg(long)]
    robot: String,
    #[arg(long)]
    res: String,
    #[arg(long)]
    index: usize,
    #[arg(long, value_delimiter = ',')]
    counts: Vec<usize>,
    #[arg(long)]
    dir: PathBuf,
    #[arg(long)]
    acks: PathBuf,
}

/// Entry of `nerve-bench __img-iox2-reader`: prints `ready` once subscribed.
pub fn reader_main(args: Vec<String>) -> ExitCode {
    match parse_sub::<ReaderArgs>("__img-iox2-reader", args) {
        Ok(a) => exit_status("iox2 image reader", reader(&a)),
        Err(code) => code,
    }
}

fn reader(a: &ReaderArgs) -> Result<()> {
    realtime_like_an_agent(20);
    let res = Res::parse(&a.res)?;
    let node = node(&a.robot, &format!("img-reader-{}-{}", res.key, a.index))?;
    let mut subs: Vec<Subscriber<Raw, [u8], SampleHeader>> = Vec::new();
    let mut listeners: Vec<Listener<Raw>> = Vec::new();
    for &n in a.counts.iter().filter(|&&n| a.index < n) {
        let (ps, ev) = services(&node, res, n)?;
        subs.push(ps.subscriber_builder().buffer_size(BUFFER).create().map_err(|e| anyhow!("subscriber: {e:?}"))?);
        listeners.push(ev.listener_builder().create().map_err(|e| anyhow!("listener: {e:?}"))?);
    }
    let mut rec = Recorder::new(a.dir.clone(), a.index, &a.acks)?;
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<Raw>()
        .map_err(|e| anyhow!("waitset: {e:?}"))?;
    let guards = listeners
        .iter()
        .map(|l| waitset.attach_notification(l).map_err(|e| anyhow!("attach: {e:?}")))
        .collect::<Result<Vec<_>>>()?;
    println!("ready");
    std::io::stdout().flush().context("stdout")?;
    loop {
        let r = waitset
            .wait_and_process_once_with_timeout(
                |id| {
                    for (g, l) in guards.iter().zip(&listeners) {
                        if id.has_event_from(g) {
                            let _ = l.try_wait(|_| {});
                        }
                    }
                    CallbackProgression::Continue
                },
                Duration::from_millis(500),
            )
            .map_err(|e| anyhow!("wait: {e:?}"))?;
        if matches!(r, WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) {
            return Ok(());
        }
        let mut begin = now_ns();
        for s in &subs {
            while let Some(sample) = s.receive().map_err(|e| anyhow!("receive: {e:?}"))? {
                let (h, bad) = frame::check(sample.payload());
                let h = FrameHead { stamp_ns: sample.user_header().stamp_ns, ..h };
                drop(sample);
                let done = now_ns();
                rec.frame(&h, bad, begin, done)?;
                begin = done;
            }
        }
    }
}
