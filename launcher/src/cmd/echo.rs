//! `nerve echo` and `nerve hz`: watch an output port from the terminal.
//!
//! The port's payload type comes from the router's registry, or, with no
//! router, by probing the types this build knows. Tools subscribe like any
//! agent (zero copy) and never disturb the publisher.

use crate::client::{RouterSession, cli_node};
use agent_sdk::World;
use agent_sdk::clock::now_ns;
use agent_sdk::meters::percentile;
use agent_sdk::ports::{existing_port_service, port_event};
use agent_sdk::world::Ipc;
use anyhow::{Context as _, Result, anyhow, bail};
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use shm_schemas::control::cli_to_router::{CliRequest, RouterError, RouterReply};
use shm_schemas::payloads::known_type_names;
use shm_schemas::{Payload, PortRef, SampleHeader, for_each_payload};
use std::io::Write;
use std::process::ExitCode;
use std::time::Duration;

/// `nerve echo`
#[derive(Debug, clap::Args)]
pub struct EchoArgs {
    /// Output port, AGENT/PORT.
    pub port: String,
    /// Exit after this many samples.
    #[arg(long)]
    pub count: Option<u64>,
    /// One JSON object per line.
    #[arg(long)]
    pub json: bool,
    /// Give up after this many seconds without a sample (default: wait for ever).
    #[arg(long, value_parser = agent_sdk::clock::parse_seconds)]
    pub timeout: Option<f64>,
}

/// `nerve hz`
#[derive(Debug, clap::Args)]
pub struct HzArgs {
    /// Output port, AGENT/PORT.
    pub port: String,
    /// Seconds per report.
    #[arg(long, default_value_t = 1.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub window: f64,
    /// Exit after this many reports.
    #[arg(long)]
    pub count: Option<u64>,
    /// One JSON object per report.
    #[arg(long)]
    pub json: bool,
}

/// The payload type of `port`: from the router, else by probing known types.
fn port_type(world: &World, node: &Node<Ipc>, port: &PortRef) -> Result<String> {
    if let Ok(s) = RouterSession::open(world) {
        // a router that does not answer (killed, restarting) is no reason to fail: probe instead
        if let Ok(RouterReply::Agents(agents)) = s.call(CliRequest::Ps) {
            let Some(a) = agents.iter().find(|a| a.name == port.agent.as_str()) else {
                return Err(anyhow!(RouterError::UnknownAgent {
                    name: port.agent.to_string(),
                    running: agents.iter().map(|a| a.name.clone()).collect(),
                }));
            };
            return a.outputs.iter().find(|o| o.name == port.port).map(|o| o.type_name.clone()).ok_or_else(|| {
                anyhow!(RouterError::UnknownPort {
                    agent: port.agent.to_string(),
                    port: port.port.clone(),
                    direction: "output".into(),
                    available: a.outputs.iter().map(|o| o.name.clone()).collect(),
                })
            });
        }
    }
    let service = world.robot().port_service(port.agent.as_str(), &port.port);
    let mut found = None;
    macro_rules! probe {
        ($t:ty) => {
            if found.is_none() && existing_port_service::<$t>(node, &service).is_some() {
                found = Some(<$t as Payload>::stable_type_name().to_string());
            }
        };
    }
    for_each_payload!(probe);
    found.ok_or_else(|| anyhow!("no output port {port} exists on robot {} (and no router runs to ask)", world.robot()))
}

enum Event<'a, T> {
    Sample(&'a SampleHeader, &'a T),
    Tick,
}

/// Subscribes to `port` and calls `f` for each sample and every `tick`;
/// stops when `f` returns false, on Ctrl-C, or after `idle` without samples.
fn watch<T: Payload>(
    node: &Node<Ipc>,
    service: &str,
    tick: Duration,
    idle: Option<Duration>,
    mut f: impl FnMut(Event<'_, T>) -> bool,
) -> Result<bool> {
    let ps = existing_port_service::<T>(node, service).ok_or_else(|| anyhow!("the port {service} does not exist"))?;
    let sub = ps
        .subscriber_builder()
        .buffer_size(agent_sdk::ports::SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| anyhow!("{e:?}"))?;
    let listener = port_event(node, service)?.listener_builder().create().map_err(|e| anyhow!("{e:?}"))?;
    let ws = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<Ipc>()
        .map_err(|e| anyhow!("{e:?}"))?;
    let _l = ws.attach_notification(&listener).map_err(|e| anyhow!("{e:?}"))?;
    let _t = ws.attach_interval(tick).map_err(|e| anyhow!("{e:?}"))?;
    let mut last_sample = now_ns();
    loop {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest) => return Ok(true),
            Ok(_) => {}
            Err(e) => bail!("wait failed: {e:?}"),
        }
        let _ = listener.try_wait(|_| {});
        while let Some(sample) = sub.receive().map_err(|e| anyhow!("{e:?}"))? {
            last_sample = now_ns();
            if !f(Event::Sample(sample.user_header(), sample.payload())) {
                return Ok(true);
            }
        }
        if !f(Event::Tick) {
            return Ok(true);
        }
        if let Some(idle) = idle
            && now_ns().saturating_sub(last_sample) > idle.as_nanos() as u64
        {
            return Ok(false);
        }
    }
}

pub fn echo(world: &World, a: EchoArgs) -> Result<ExitCode> {
    let port: PortRef = a.port.parse().context("PORT")?;
    let node = cli_node(world)?;
    let type_name = port_type(world, &node, &port)?;
    macro_rules! dispatch {
        ($t:ty) => {
            if <$t as Payload>::stable_type_name() == type_name {
                return echo_typed::<$t>(world, &node, &port, &a);
            }
        };
    }
    for_each_payload!(dispatch);
    bail!(
        "port {port} carries {type_name}, which this build of nerve cannot print (it knows {})",
        known_type_names().join(", ")
    )
}

fn echo_typed<T: Payload>(world: &World, node: &Node<Ipc>, port: &PortRef, a: &EchoArgs) -> Result<ExitCode> {
    let service = world.robot().port_service(port.agent.as_str(), &port.port);
    let mut n = 0u64;
    let stdout = std::io::stdout();
    let idle = a.timeout.map(Duration::from_secs_f64);
    let mut failed = None;
    let finished = watch::<T>(node, &service, Duration::from_millis(200), idle, |ev| {
        let Event::Sample(h, v) = ev else { return true };
        let mut out = stdout.lock();
        let r = if a.json {
            let line = serde_json::json!({
                "from": h.sender.as_str(),
                "seq": h.seq,
                "stamp_ns": h.stamp_ns,
                "type": T::stable_type_name(),
                "data": v,
            });
            writeln!(out, "{line}")
        } else {
            writeln!(out, "[{} #{}] {:?}", h.sender, h.seq, v)
        };
        if let Err(e) = r.and_then(|_| out.flush()) {
            // a closed pipe (e.g. `| head`) ends echo quietly
            if e.kind() != std::io::ErrorKind::BrokenPipe {
                failed = Some(e);
            }
            return false;
        }
        n += 1;
        a.count.is_none_or(|c| n < c)
    })?;
    if let Some(e) = failed {
        return Err(e.into());
    }
    if !finished {
        bail!("no sample on {port} for {:.1} s", a.timeout.unwrap_or_default());
    }
    Ok(ExitCode::SUCCESS)
}

pub fn hz(world: &World, a: HzArgs) -> Result<ExitCode> {
    let port: PortRef = a.port.parse().context("PORT")?;
    let node = cli_node(world)?;
    let type_name = port_type(world, &node, &port)?;
    macro_rules! dispatch {
        ($t:ty) => {
            if <$t as Payload>::stable_type_name() == type_name {
                return hz_typed::<$t>(world, &node, &port, &a);
            }
        };
    }
    for_each_payload!(dispatch);
    bail!("port {port} carries {type_name}, unknown to this build of nerve")
}

fn hz_typed<T: Payload>(world: &World, node: &Node<Ipc>, port: &PortRef, a: &HzArgs) -> Result<ExitCode> {
    if !(a.window.is_finite() && a.window > 0.0) {
        bail!("--window must be a positive number of seconds");
    }
    let service = world.robot().port_service(port.agent.as_str(), &port.port);
    let window_ns = (a.window * 1e9) as u64;
    let mut start = now_ns();
    let mut arrivals: Vec<u64> = Vec::new();
    let mut reports = 0u64;
    watch::<T>(node, &service, Duration::from_millis(50), None, |ev| {
        if let Event::Sample(..) = ev {
            arrivals.push(now_ns());
        }
        let now = now_ns();
        if now.saturating_sub(start) < window_ns {
            return true;
        }
        let elapsed = (now - start) as f64 / 1e9;
        let rate = arrivals.len() as f64 / elapsed;
        let mut gaps: Vec<u64> = arrivals.windows(2).map(|w| w[1] - w[0]).collect();
        gaps.sort_unstable();
        let mean = if gaps.is_empty() { 0.0 } else { gaps.iter().sum::<u64>() as f64 / gaps.len() as f64 };
        let std = if gaps.is_empty() {
            0.0
        } else {
            (gaps.iter().map(|g| (*g as f64 - mean).powi(2)).sum::<f64>() / gaps.len() as f64).sqrt()
        };
        let (min, max) = (gaps.first().copied().unwrap_or(0), gaps.last().copied().unwrap_or(0));
        if a.json {
            println!(
                "{}",
                serde_json::json!({
                    "port": port.to_string(), "rate_hz": rate, "samples": arrivals.len(),
                    "window_s": elapsed, "min_ms": min as f64 / 1e6, "max_ms": max as f64 / 1e6,
                    "p50_ms": percentile(&gaps, 0.5) as f64 / 1e6, "std_ms": std / 1e6,
                })
            );
        } else {
            println!(
                "{port}: {rate:.2} Hz  ({} samples in {elapsed:.2} s; interval min {:.2} ms, max {:.2} ms, std {:.2} ms)",
                arrivals.len(),
                min as f64 / 1e6,
                max as f64 / 1e6,
                std / 1e6
            );
        }
        arrivals.clear();
        start = now;
        reports += 1;
        a.count.is_none_or(|c| reports < c)
    })?;
    Ok(ExitCode::SUCCESS)
}
