//! `ir`: the checkpoint sensor agent.
//!
//! Opens the IR receiver's serial port (`-- --device PATH`) in a device
//! thread and publishes each of its reports (10 Hz) on output `sighting`
//! (`nerve::IrSighting`): whether a checkpoint is seen, its code and which of
//! its four transmitters are received (from which the robot's bearing around
//! the checkpoint follows, `IrSighting::sector`). A change of what is seen
//! is logged at info level.
//!
//! Periodic (default 50 ms). Figures (read-only counters): `frames`,
//! `garbage_bytes`, `bad_headers`, `bad_checksums`, `truncated`,
//! `invalid_payloads`, `device_opens`, `device_losses`,
//! `device_failed_opens`, `stale_frames`. A device that vanishes is logged and reopened with
//! exponential backoff (see `agent_sdk::device`); no sightings are published
//! meanwhile.

use agent_sdk::device::{CounterFigures, DeviceEvent, DeviceLink};
use agent_sdk::{Agent, AgentError, Context, Output, Setup, Task};
use nerve_devices::Message;
use shm_schemas::payloads::IrSighting;
use std::path::PathBuf;
use std::time::Duration;

/// What `start` says when no `--device` was given.
const NO_DEVICE: &str =
    "no device: give the IR receiver's serial port after `--`, e.g. `nerve start ir -- --device /dev/ttyUSB2`";

/// Arguments after `--`.
#[derive(Debug, clap::Parser)]
struct Args {
    /// Serial device of the IR receiver.
    #[arg(long)]
    device: Option<PathBuf>,
}

struct Ir {
    device: Option<PathBuf>,
    link: Option<DeviceLink>,
    out: Output<IrSighting>,
    counters: CounterFigures,
    seq: u64,
    last_seq: Option<u16>,
    last_seen: Option<(u8, u8)>,
}

impl Agent for Ir {
    const KIND: &'static str = "ir";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(50))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        Ok(Ir {
            device: args.device,
            link: None,
            out: setup.output("sighting")?,
            counters: agent_sdk::device::counter_figures(setup, Vec::new),
            seq: 0,
            last_seq: None,
            last_seen: None,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        self.link = Some(agent_sdk::device::open_link(&self.device, "ir", NO_DEVICE)?);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let Some(link) = &self.link else { return Ok(()) };
        let mut result = Ok(());
        while let Some(ev) = link.try_recv() {
            let DeviceEvent::Message(Message::IrReport(r), at) = ev else { continue };
            self.seq += self.last_seq.map_or(1, |l| u64::from(r.seq.wrapping_sub(l).max(1)));
            self.last_seq = Some(r.seq);
            let seen = r.sighting.map(|s| (s.checkpoint_id, s.transmitters));
            if seen != self.last_seen {
                match seen {
                    Some((id, tx)) => tracing::info!("checkpoint {id} seen (transmitters {tx:#06b})"),
                    None => tracing::info!("no checkpoint in sight"),
                }
                self.last_seen = seen;
            }
            let sighting = IrSighting {
                seq: self.seq,
                stamp_ns: ctx.now_ns().saturating_sub(agent_sdk::clock::elapsed_ns(at)),
                seen: u8::from(seen.is_some()),
                checkpoint_id: seen.map_or(0, |s| s.0),
                transmitters: seen.map_or(0, |s| s.1),
                reserved: [0; 5],
            };
            if let Err(e) = self.out.send(sighting) {
                result = Err(e.into());
            }
        }
        self.counters.update(&link.stats(), "ir");
        result
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Ir>()
}
