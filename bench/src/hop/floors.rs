//! The floors nerve is measured against, each a pong process and a ping
//! in this process: raw iceoryx2 (WaitSet, listener, with the fill, polling;
//! [`crate::raw`]), a Unix stream socket ([`crate::uds`]) and a futex in
//! shared memory ([`crate::futex`], also with both ends on one CPU).

use super::pinger::{Pinger, Pingers, Pinned};
use super::{HopOpts, PINNED_CPU};
use crate::futex::FutexPing;
use crate::payloads::BenchPayload;
use crate::procs::{ChildGuard, Robot, normal_priority, realtime_like_an_agent, self_command};
use crate::raw::{Mode, Side};
use crate::uds::UdsPing;
use crate::with_payload;
use anyhow::{Result, bail};
use iceoryx2::prelude::ipc_threadsafe;
use std::process::Stdio;

/// The socket and futex pings, per size in the order of the sizes: (uds,
/// futex, futex with both ends on [`PINNED_CPU`]).
pub(super) type Pings = std::vec::IntoIter<(UdsPing, FutexPing, FutexPing)>;

/// Starts the pongs of every floor for every size (the raw iceoryx2 ones
/// answer on the robot's services; the others are paired with their ping).
pub(super) fn start_pongs(robot: &Robot, opts: &HopOpts) -> Result<(Vec<ChildGuard>, Pings)> {
    let (mut children, mut pings) = (Vec::new(), Vec::new());
    for &size in &opts.sizes {
        for mode in ["waitset", "listener", "waitset-fill", "poll", "poll-threadsafe"] {
            let mut cmd = self_command("__raw-pong")?;
            cmd.args(["--robot", &robot.name, "--mode", mode, "--size", &size.to_string()]);
            cmd.env("NERVE_HOME", &robot.home).stdout(Stdio::piped());
            if !opts.verbose {
                cmd.stderr(Stdio::null());
            }
            let mut c = ChildGuard::spawn(&format!("raw pong {mode} {size}"), cmd)?;
            c.await_ready("raw iceoryx2 pong")?;
            children.push(c);
        }
        let (c, uds) = UdsPing::with_pong(&robot.home, size, opts.verbose)?;
        children.push(c);
        let (c, futex) = FutexPing::with_pong(&format!("{size}"), None, opts.verbose)?;
        children.push(c);
        let (c2, pinned) = FutexPing::with_pong(&format!("{size}-pinned"), Some(PINNED_CPU), opts.verbose)?;
        children.push(c2);
        pings.push((uds, futex, pinned));
    }
    Ok((children, pings.into_iter()))
}

/// The rows `uds`, `futex` and `futex-pinned` of the next size.
pub(super) fn push_socket_and_futex(pingers: &mut Pingers, size: usize, pings: &mut Pings) {
    if let Some((u, f, fp)) = pings.next() {
        pingers.push((size, "uds", Box::new(u)));
        pingers.push((size, "futex", Box::new(f)));
        pingers.push((size, "futex-pinned", Box::new(Pinned(Box::new(fp)))));
    }
}

/// The raw iceoryx2 rows of `size`: this process's ping side of each mode.
pub(super) fn push_iox2(pingers: &mut Pingers, size: usize, robot: &Robot) -> Result<()> {
    for (mode, t) in [
        (Mode::Waitset, "iox2-waitset"),
        (Mode::Listener, "iox2-listener"),
        (Mode::WaitsetFill, "iox2-waitset-fill"),
        (Mode::Poll, "iox2-poll"),
    ] {
        let p: Box<dyn Pinger> = with_payload!(size, P => Box::new(Side::<P>::open(&robot.name, mode, "ping", "pong", "raw-ping")?), _ => bail!("size"));
        let p = if mode == Mode::Poll { Box::new(AsPolledAgents(Box::new(Pinned(p)))) } else { p };
        pingers.push((size, t, p));
    }
    // the polling pair on nerve's ports' service type (`crate::raw`'s module doc)
    let ts = Mode::PollThreadsafe;
    let p: Box<dyn Pinger> = with_payload!(size, P => Box::new(Side::<P, ipc_threadsafe::Service>::open(&robot.name, ts, "ping", "pong", "raw-ping")?), _ => bail!("size"));
    pingers.push((size, "iox2-poll-ts", Box::new(AsPolledAgents(Box::new(Pinned(p))))));
    Ok(())
}

/// A raw polling batch run as nerve's polling agents run (`nerve-poll`):
/// SCHED_OTHER (`--no-realtime`, which they need on two CPUs), the ping on
/// CPU 0 ([`Pinned`]) and the pong on CPU 1. Real-time raw pollers against
/// normal-priority nerve ones measured the scheduler as much as the code:
/// on a loaded machine only nerve's were preempted.
struct AsPolledAgents(Box<dyn Pinger>);

impl Pinger for AsPolledAgents {
    fn batch(&mut self, robot: &Robot, count: usize) -> Result<Vec<u64>> {
        normal_priority();
        let r = self.0.batch(robot, count);
        realtime_like_an_agent(20);
        r
    }
}

impl Pinger for FutexPing {
    fn batch(&mut self, _robot: &Robot, count: usize) -> Result<Vec<u64>> {
        self.ping_batch(count)
    }

    fn same_cpu(&self) -> Option<usize> {
        Some(self.same_cpu)
    }
}

impl<P: BenchPayload, S: iceoryx2::service::Service> Pinger for Side<P, S>
where
    iceoryx2::port::listener::Listener<S>: iceoryx2::prelude::SynchronousMultiplexing,
{
    fn batch(&mut self, _robot: &Robot, count: usize) -> Result<Vec<u64>> {
        self.ping_batch(count)
    }
}

impl Pinger for UdsPing {
    fn batch(&mut self, _robot: &Robot, count: usize) -> Result<Vec<u64>> {
        self.ping_batch(count)
    }
}
