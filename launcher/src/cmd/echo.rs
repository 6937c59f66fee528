//! `nerve echo` and `nerve hz`: watch an output port from the terminal.
//!
//! Any port, whatever its type: the tools read a sample's bytes
//! ([`RawPort`]) and decode them through the schema the agent registered
//! with the router (or, with no router, the schema of a type this build
//! knows, found by the layout fingerprint in the port's attributes). `hz`
//! needs no decoding. Tools subscribe like any agent (zero copy) and never
//! disturb the publisher.
//!
//! A sequence port's samples ([`shm_schemas::seq`]) are as long as their
//! elements make them: echo prints `{ header: {...}, items: [...] }` (JSON
//! arrays with `--json`), and `--field` takes `header.frame`, `items` or
//! one element's field, `items[3].x` (`null`, `-` in the human form, when
//! a sample has fewer elements).

use crate::client::{RouterSession, cli_node};
use agent_sdk::World;
use agent_sdk::clock::now_ns;
use agent_sdk::meters::percentile;
use agent_sdk::ports::port_event;
use agent_sdk::raw_port::{RawPort, port_identity};
use agent_sdk::world::Ipc;
use anyhow::{Context as _, Result, anyhow, bail};
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use shm_schemas::control::cli_to_router::{CliRequest, RouterError, RouterReply};
use shm_schemas::services::port_attributes::fingerprint_text;
use shm_schemas::{PortRef, SampleHeader, Schema};
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
    /// Print only this field (`pose.x`, `ranges_m.3` or `ranges_m[3]`; in a
    /// sequence `header.frame`, `items`, `items[3].x`).
    #[arg(long)]
    pub field: Option<String>,
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
    /// Exit after this many seconds (the last report covers what is left of
    /// its window), as `record` and `plot` take it.
    #[arg(long, value_parser = agent_sdk::clock::parse_seconds)]
    pub duration: Option<f64>,
    /// One JSON object per report.
    #[arg(long)]
    pub json: bool,
}

/// What a port carries, as far as this tool can learn it.
pub(crate) struct PortInfo {
    pub(crate) type_name: String,
    /// the layout fingerprint, when known
    pub(crate) fingerprint: Option<u64>,
    /// the schema to decode it with, when known
    pub(crate) schema: Option<Schema>,
    /// whether the router told (else the port's attributes did)
    pub(crate) from_router: bool,
}

impl PortInfo {
    /// The schema to decode `port` with, or why there is none and what to do.
    pub(crate) fn schema_or_why(&self, port: &PortRef) -> Result<&Schema> {
        let layout = self.fingerprint.map_or("unknown".into(), fingerprint_text);
        match &self.schema {
            Some(s) => Ok(s),
            None if self.from_router => bail!(
                "port {port} carries {} (layout {layout}), and {} registered no schema for it (its registration \
                 was too large for the router with its schemas: see `nerve logs {}`); `nerve hz` and `nerve record` \
                 of built-in types still work",
                self.type_name,
                port.agent,
                port.agent
            ),
            None => bail!(
                "port {port} carries {} (layout {layout}), whose schema this build of nerve does not have and no \
                 router runs to give it: start the router (`nerve router --daemon` or `nerve launch`) so that the \
                 agent registers its schema",
                self.type_name
            ),
        }
    }
}

/// What `port` carries: from the router (the agent registered each port's
/// type, fingerprint and schema), else from the port's iceoryx2 attributes
/// and the schemas of the types this build knows.
pub(crate) fn port_info(world: &World, node: &Node<Ipc>, port: &PortRef) -> Result<PortInfo> {
    if let Ok(s) = RouterSession::open(world) {
        // a router that does not answer (killed, restarting) is no reason to fail: look at the port itself
        if let Ok(RouterReply::Agents(agents)) = s.call(CliRequest::Ps) {
            let Some(a) = agents.iter().find(|a| a.name == port.agent.as_str()) else {
                return Err(anyhow!(RouterError::UnknownAgent {
                    name: port.agent.to_string(),
                    running: agents.iter().map(|a| a.name.clone()).collect(),
                }));
            };
            let Some(o) = a.outputs.iter().find(|o| o.name == port.port) else {
                return Err(anyhow!(RouterError::UnknownPort {
                    agent: port.agent.to_string(),
                    port: port.port.clone(),
                    direction: "output".into(),
                    available: a.outputs.iter().map(|o| o.name.clone()).collect(),
                }));
            };
            let schema = a.schema_for(o.fingerprint);
            return Ok(PortInfo {
                type_name: o.type_name.clone(),
                fingerprint: Some(o.fingerprint),
                schema,
                from_router: true,
            });
        }
    }
    let service = world.robot().port_service(port.agent.as_str(), &port.port);
    let (type_name, fingerprint) = port_identity(node, &service).ok_or_else(|| {
        anyhow!("no output port {port} exists on robot {} (and no router runs to ask)", world.robot())
    })?;
    Ok(PortInfo {
        type_name,
        fingerprint,
        schema: fingerprint.and_then(shm_schemas::schema::built_in),
        from_router: false,
    })
}

enum Event<'a> {
    Sample(&'a SampleHeader, &'a [u8]),
    Tick,
}

/// Subscribes to `port` and calls `f` for each sample and every `tick`;
/// stops when `f` returns false, on Ctrl-C, or after `idle` without samples.
fn watch(
    node: &Node<Ipc>,
    service: &str,
    tick: Duration,
    idle: Option<Duration>,
    mut f: impl FnMut(Event<'_>) -> bool,
) -> Result<bool> {
    let raw = RawPort::open(node, service)?;
    let listener = port_event(node, service)?.listener_builder().create().map_err(|e| anyhow!("{e:?}"))?;
    crate::interrupt::catch();
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
            Ok(_) if crate::interrupt::requested() => return Ok(true),
            Ok(_) => {}
            Err(e) => bail!("wait failed: {e:?}"),
        }
        let _ = listener.try_wait(|_| {});
        let mut go_on = true;
        let n = raw.receive(|h, bytes| {
            go_on = f(Event::Sample(h, bytes));
            go_on
        })?;
        if n > 0 {
            last_sample = now_ns();
        }
        if !go_on || !f(Event::Tick) {
            return Ok(true);
        }
        if let Some(idle) = idle
            && now_ns().saturating_sub(last_sample) > idle.as_nanos() as u64
        {
            return Ok(false);
        }
    }
}

/// The part of each sample echo prints: the whole payload, or one field.
fn selection(info: &PortInfo, port: &PortRef, field: Option<&str>) -> Result<(usize, Schema)> {
    let schema = info.schema_or_why(port)?.clone();
    let Some(path) = field else { return Ok((0, schema)) };
    if schema.sequence_shape().is_some() {
        // where an element lies depends on the sample: picked from each (`decode_path`)
        if schema.has_path(path) {
            return Ok((0, schema));
        }
        bail!("{} has no field {path:?}; its fields: {}", info.type_name, field_paths(&schema).join(", "));
    }
    match schema.field(path) {
        Some((offset, s)) => Ok((offset, s.clone())),
        None => bail!("{} has no field {path:?}; its fields: {}", info.type_name, field_paths(&schema).join(", ")),
    }
}

/// Every field path of `schema` (`pose`, `pose.x`, `fingers.<i> (0..3)`
/// for an element of an array, `fingers.<i>.force_n`...).
fn field_paths(schema: &Schema) -> Vec<String> {
    let mut out = Vec::new();
    schema.visit_fields(|path, _, lens| match (path.ends_with("<i>"), lens.last()) {
        (true, Some(len)) => out.push(format!("{path} (0..{len})")),
        _ => out.push(path.to_string()),
    });
    out
}

pub fn echo(world: &World, a: EchoArgs) -> Result<ExitCode> {
    let port: PortRef = a.port.parse().context("PORT")?;
    let node = cli_node(world)?;
    let info = port_info(world, &node, &port)?;
    let (offset, schema) = selection(&info, &port, a.field.as_deref())?;
    // a field of a sequence's sample, picked from each sample
    let seq_field = a.field.as_deref().filter(|_| schema.sequence_shape().is_some());
    let service = world.robot().port_service(port.agent.as_str(), &port.port);
    let mut n = 0u64;
    let stdout = std::io::stdout();
    let idle = a.timeout.map(Duration::from_secs_f64);
    let mut failed = None;
    let finished = watch(&node, &service, Duration::from_millis(200), idle, |ev| {
        let Event::Sample(h, bytes) = ev else { return true };
        let value = match seq_field {
            // an element past this sample's length: nothing to print of it
            Some(path) => Ok(schema.decode_path(path, bytes)),
            None => decoded(&schema, offset, bytes).map(Some),
        };
        let value = match value {
            Ok(v) => v,
            Err(e) => {
                failed = Some(anyhow!("port {port}: {e}"));
                return false;
            }
        };
        let mut out = stdout.lock();
        let r = if a.json {
            let mut line = serde_json::json!({
                "from": h.sender.as_str(),
                "seq": h.seq,
                "stamp_ns": h.stamp_ns,
                "type": info.type_name,
                "data": value,
            });
            if let Some(f) = &a.field {
                line["field"] = serde_json::json!(f);
            }
            writeln!(out, "{line}")
        } else {
            let value = value.map_or_else(|| "-".to_string(), |v| v.to_string());
            match &a.field {
                Some(f) => writeln!(out, "[{} #{}] {f}: {value}", h.sender, h.seq),
                None => writeln!(out, "[{} #{}] {} {value}", h.sender, h.seq, info.type_name),
            }
        };
        if let Err(e) = r.and_then(|_| out.flush()) {
            // a closed pipe (e.g. `| head`) ends echo quietly
            if e.kind() != std::io::ErrorKind::BrokenPipe {
                failed = Some(e.into());
            }
            return false;
        }
        n += 1;
        a.count.is_none_or(|c| n < c)
    })?;
    if let Some(e) = failed {
        return Err(e);
    }
    if !finished {
        bail!("no sample on {port} for {:.1} s", a.timeout.unwrap_or_default());
    }
    Ok(ExitCode::SUCCESS)
}

/// The value `schema` describes at `offset` in a sample's `bytes`.
fn decoded(schema: &Schema, offset: usize, bytes: &[u8]) -> Result<shm_schemas::schema::Value> {
    match bytes.get(offset..).map(|b| schema.decode(b)) {
        Some(Ok(v)) => Ok(v),
        Some(Err(e)) => Err(e.into()),
        None => bail!("a {}-byte sample is shorter than its schema", bytes.len()),
    }
}

pub fn hz(world: &World, a: HzArgs) -> Result<ExitCode> {
    let port: PortRef = a.port.parse().context("PORT")?;
    let node = cli_node(world)?;
    hz_of(world, &node, &port, &a)
}

/// `hz` needs no decoding: it reads any port by its bytes.
fn hz_of(world: &World, node: &Node<Ipc>, port: &PortRef, a: &HzArgs) -> Result<ExitCode> {
    if !(a.window.is_finite() && a.window > 0.0) {
        bail!("--window must be a positive number of seconds");
    }
    let service = world.robot().port_service(port.agent.as_str(), &port.port);
    let window_ns = (a.window * 1e9) as u64;
    let mut start = now_ns();
    let end = a.duration.map(|d| start.saturating_add((d * 1e9) as u64));
    let mut arrivals: Vec<u64> = Vec::new();
    let mut reports = 0u64;
    watch(node, &service, Duration::from_millis(50), None, |ev| {
        if let Event::Sample(..) = ev {
            arrivals.push(now_ns());
        }
        let now = now_ns();
        let over = end.is_some_and(|e| now >= e);
        if now.saturating_sub(start) < window_ns && !over {
            return true;
        }
        let elapsed = (now.saturating_sub(start)) as f64 / 1e9;
        let rate = if elapsed > 0.0 { arrivals.len() as f64 / elapsed } else { 0.0 };
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
        !over && a.count.is_none_or(|c| reports < c)
    })?;
    Ok(ExitCode::SUCCESS)
}
