//! `sonar`: the sonar sensor agent (thesis section 4.2.2.1).
//!
//! Opens the sonar ring module's serial port (`-- --device PATH`, a real
//! `/dev/ttyUSB*` or the simulator's `{state}/dev/sonar`) in a device thread,
//! decodes its frames (resynchronising after garbage), estimates the risk
//! in each of the 12 directions from the change of range between samples
//! ([`nerve_sonar::RiskEstimator`]) and publishes every scan on its output
//! `scan` (`nerve::SonarScan`).
//!
//! Periodic (default 50 ms): each cycle takes the scans the device thread
//! received. Parameters: `ttc_horizon` (s), `near` (m), `smoothing`,
//! `max_closing` (m/s). Figures (read-only counters): `frames`, `garbage_bytes`,
//! `bad_headers`, `bad_checksums`, `truncated`, `invalid_payloads`,
//! `device_opens`, `device_losses`, `device_failed_opens`, `stale_frames`,
//! `missed_scans`, `artefacts`. A device that vanishes is logged and reopened
//! with exponential backoff; scans the module sent while the line was cut
//! (waiting on the line when it is reopened) are discarded, not published
//! in a burst stamped "now", and counted in `stale_frames`; see
//! `agent_sdk::device`.

use agent_sdk::device::{Count, CounterFigures, DeviceEvent, DeviceLink};
use agent_sdk::params::positive;
use agent_sdk::{Agent, AgentError, Context, Output, Param, Setup, Task};
use nerve_devices::{Message, SONAR_NO_ECHO};
use nerve_sonar::{DIRECTIONS, RiskEstimator, RiskParams, SeqUnwrapper};
use shm_schemas::payloads::SonarScan;
use std::path::PathBuf;
use std::time::Duration;

/// What `start` says when no `--device` was given.
const NO_DEVICE: &str = "no device: give the sonar module's serial port after `--`, e.g. `nerve start sonar -- --device /dev/ttyUSB0` \
                 (with the simulator: `-- --device <state dir>/dev/sonar`)";

/// Arguments after `--`.
#[derive(Debug, clap::Parser)]
struct Args {
    /// Serial device of the sonar ring module.
    #[arg(long)]
    device: Option<PathBuf>,
}

struct Sonar {
    device: Option<PathBuf>,
    link: Option<DeviceLink>,
    out: Output<SonarScan>,
    ttc_horizon: Param<f64>,
    near: Param<f64>,
    smoothing: Param<f64>,
    max_closing: Param<f64>,
    counters: CounterFigures,
    missed: Count,
    artefacts: Count,
    estimator: RiskEstimator,
    seq: SeqUnwrapper,
    /// The robot clock's ns at start: risk times count from here.
    t0_ns: u64,
}

impl Agent for Sonar {
    const KIND: &'static str = "sonar";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(50))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let d = RiskParams::default();
        // read-only counters: figures, after the device link's
        let (missed, artefacts) = (Count::default(), Count::default());
        let (m, a) = (missed.clone(), artefacts.clone());
        let counters =
            agent_sdk::device::counter_figures(setup, move || vec![m.figure("missed_scans"), a.figure("artefacts")]);
        Ok(Sonar {
            device: args.device,
            link: None,
            out: setup.output("scan")?,
            ttc_horizon: setup.param_checked("ttc_horizon", d.ttc_horizon, positive),
            near: setup.param_checked("near", d.near, positive),
            smoothing: setup.param_checked("smoothing", d.smoothing, |v| {
                if *v > 0.0 && *v <= 1.0 { Ok(()) } else { Err("smoothing must be in (0, 1]".into()) }
            }),
            max_closing: setup.param_checked("max_closing", d.max_closing, positive),
            counters,
            missed,
            artefacts,
            estimator: RiskEstimator::new(),
            seq: SeqUnwrapper::default(),
            t0_ns: agent_sdk::clock::now_ns(),
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        self.link = Some(agent_sdk::device::open_link(&self.device, "sonar", NO_DEVICE)?);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let Some(link) = &self.link else { return Ok(()) };
        let mut result = Ok(());
        while let Some(ev) = link.try_recv() {
            let DeviceEvent::Message(msg, at) = ev else { continue };
            let Message::SonarScan(s) = msg else {
                tracing::debug!("ignoring {:?} on the sonar line", msg.message_type());
                continue;
            };
            let ranges: [Option<f64>; DIRECTIONS] =
                std::array::from_fn(|i| (s.ranges_mm[i] != SONAR_NO_ECHO).then(|| f64::from(s.ranges_mm[i]) / 1000.0));
            let p = RiskParams {
                ttc_horizon: self.ttc_horizon.get(),
                near: self.near.get(),
                smoothing: self.smoothing.get(),
                max_closing: self.max_closing.get(),
            };
            // the stamp: when the device thread read it, on the SDK's clock
            // (the robot's: simulated time when the simulator owns it)
            let stamp_ns = ctx.now_ns().saturating_sub(agent_sdk::clock::elapsed_ns(at));
            let t = stamp_ns.saturating_sub(self.t0_ns) as f64 / 1e9;
            let risk = self.estimator.update(t, &ranges, &p);
            let seq = self.seq.unwrap(s.seq);
            let scan = SonarScan {
                seq,
                stamp_ns,
                ranges_m: std::array::from_fn(|i| ranges[i].unwrap_or(0.0) as f32),
                risk: std::array::from_fn(|i| risk[i] as f32),
                valid: std::array::from_fn(|i| u8::from(ranges[i].is_some())),
                reserved: [0; 4],
            };
            if let Err(e) = self.out.send(scan) {
                result = Err(e.into());
            }
        }
        self.counters.update(&link.stats(), "sonar");
        self.missed.set(self.seq.missed);
        self.artefacts.set(self.estimator.artefacts);
        result
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Sonar>()
}
