//! `nerve pub AGENT/PORT '<json>' [--rate HZ] [--count N]`: publish any
//! type into an input port from the terminal, as `ros2 topic pub` does.
//!
//! The type is the input's own: the router says which type the agent's
//! input takes and hands over its schema (a built-in one, or the one a
//! Python or C agent registered), and the JSON is laid out by that schema
//! (`shm_schemas::encode`), strictly — a missing or unknown field, a
//! number out of range or an array of the wrong length is refused with the
//! field's path before anything is attached. A `stamp_ns` the JSON leaves
//! out is the send time of each sample (actuators drop stale commands).
//!
//! It reaches the agent the way `nerve cmd` does: a port of the command
//! line's own (`cli-<pid>/<input>`) that the router attaches to the input
//! (`CliRequest::Attach`, shown in `nerve graph` as transient, never
//! saved), and detaches once the agent's statistics show it took what was
//! sent.

use crate::client::RouterSession;
use agent_sdk::World;
use agent_sdk::clock::now_ns;
use agent_sdk::raw_port::RawOutput;
use anyhow::{Context as _, Result, anyhow, bail};
use shm_schemas::control::cli_to_router::{AgentView, CliRequest, RouterReply};
use shm_schemas::encode::encode_json;
use shm_schemas::schema::{Kind, Primitive};
use shm_schemas::{PortRef, Schema};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// How long the first sample may wait for the agent to subscribe, and the
/// last ones for the agent to take them.
pub(crate) const DELIVERY_TIMEOUT: Duration = Duration::from_secs(3);

/// `nerve pub`
#[derive(Debug, clap::Args)]
pub struct PubArgs {
    /// The input port, AGENT/INPUT (e.g. motor/cmd).
    pub port: String,
    /// The sample as JSON, every field of the input's type (`nerve types
    /// TYPE` lists them); a missing `stamp_ns` is the send time.
    pub json: String,
    /// Samples a second; without it one sample is sent (or --count, at 10 Hz).
    #[arg(long)]
    pub rate: Option<f64>,
    /// How many samples; default 1 without --rate, until Ctrl-C with it.
    #[arg(long)]
    pub count: Option<u64>,
    /// The sender the samples carry (actuators weigh senders by name).
    #[arg(long, default_value = "cli")]
    pub sender: String,
}

/// The input `port` of the robot's agent, its type's schema and fingerprint.
pub(crate) fn input_schema(session: &RouterSession, port: &PortRef) -> Result<(Schema, u64)> {
    let agent = port.agent.as_str();
    let views = match session.call(CliRequest::Agent { name: agent.to_owned() })? {
        RouterReply::Agents(v) => v,
        _ => bail!("unexpected reply from the router"),
    };
    let view: &AgentView = views.iter().find(|v| v.name == agent).ok_or_else(|| {
        anyhow!("no agent named {agent:?} runs on robot {}; `nerve ps` lists them", session.world.robot())
    })?;
    let Some(spec) = view.inputs.iter().find(|i| i.name == port.port) else {
        let inputs: Vec<&str> = view.inputs.iter().map(|i| i.name.as_str()).collect();
        bail!(
            "agent {agent:?} has no input {:?}; its inputs: {}",
            port.port,
            if inputs.is_empty() { "none".to_owned() } else { inputs.join(", ") }
        );
    };
    let schema = view.schema_for(spec.fingerprint).ok_or_else(|| {
        anyhow!(
            "{port} takes {}, whose layout neither this build nor the agent's registration describes; rebuild nerve or the agent",
            spec.type_name
        )
    })?;
    Ok((schema, spec.fingerprint))
}

/// The offset of a top-level `stamp_ns: u64` the JSON leaves out, to be
/// filled with each sample's send time.
pub(crate) fn auto_stamp(schema: &Schema, json: &serde_json::Value) -> Option<usize> {
    let Kind::Struct { fields } = &schema.kind else { return None };
    let f = fields.iter().find(|f| f.name == "stamp_ns")?;
    let is_u64 = matches!(f.schema.kind, Kind::Primitive { primitive: Primitive::U64 });
    (is_u64 && json.get("stamp_ns").is_none()).then_some(f.offset)
}

/// How many samples from the command line's port `from` agent `to.agent`
/// has taken on input `to.port` (its statistics, through the router).
pub(crate) fn taken(session: &RouterSession, from: &PortRef, to: &PortRef) -> u64 {
    match session.call(CliRequest::Agent { name: to.agent.to_string() }) {
        Ok(RouterReply::Agents(views)) => views
            .iter()
            .filter_map(|v| v.stats.as_ref())
            .flat_map(|s| &s.inputs)
            .filter(|i| i.input == to.port && i.from_agent == from.agent.as_str())
            .map(|i| i.received)
            .sum(),
        _ => 0,
    }
}

/// Waits (at most [`DELIVERY_TIMEOUT`]) until `to` took `sent` samples of
/// `from`, then detaches `from`; returns how many it took.
pub(crate) fn wait_taken_and_detach(session: &RouterSession, from: &PortRef, to: &PortRef, sent: u64) -> u64 {
    let deadline = Instant::now() + DELIVERY_TIMEOUT;
    let mut received = 0;
    while sent > 0 && Instant::now() < deadline {
        received = taken(session, from, to);
        if received >= sent {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    if let Err(e) = session.ok(CliRequest::Detach { from: from.clone(), to: to.clone() }) {
        tracing::warn!(from = %from, to = %to, "could not detach: {e:#}; the router removes the edge when this command has exited");
    }
    received
}

pub fn publish(world: &World, a: PubArgs) -> Result<ExitCode> {
    let to: PortRef = a.port.parse().context("PORT must be AGENT/INPUT")?;
    if let Some(r) = a.rate
        && !(r.is_finite() && r > 0.0 && r <= 10_000.0)
    {
        bail!("--rate must be a number of samples a second in (0, 10000], not {r}");
    }
    if a.count == Some(0) {
        bail!("--count must be at least 1");
    }
    let json: serde_json::Value =
        serde_json::from_str(&a.json).with_context(|| format!("the sample is not JSON: {}", a.json))?;
    let session = RouterSession::open(world)?;
    let (schema, fingerprint) = input_schema(&session, &to)?;
    let stamp_at = auto_stamp(&schema, &json);
    let bytes = encode_json(&schema, &json, &|p| Some(p) == stamp_at.map(|_| "stamp_ns"))
        .with_context(|| format!("{to} takes {}", schema.type_name))?;

    let from = PortRef::new(&format!("cli-{}", std::process::id()), &to.port).context("the command line's port")?;
    let service = world.robot().port_service(from.agent.as_str(), &to.port);
    let mut out = RawOutput::create(session.node()?, &service, &schema, fingerprint, &a.sender)
        .with_context(|| format!("cannot make the command line's port {service}"))?;
    session.ok(CliRequest::Attach {
        from: from.clone(),
        pid: std::process::id(),
        type_name: schema.type_name.clone(),
        fingerprint,
        to: to.clone(),
    })?;
    crate::interrupt::catch();
    let count = a.count.or(if a.rate.is_some() { None } else { Some(1) });
    let period = Duration::from_secs_f64(1.0 / a.rate.unwrap_or(10.0));

    let result = (|| -> Result<u64> {
        let mut send = || -> Result<usize> {
            let mut loan = out.loan_len(bytes.len(), false)?;
            let b = loan.bytes_mut();
            b.copy_from_slice(&bytes);
            if let Some(at) = stamp_at
                && let Some(slot) = b.get_mut(at..at + 8)
            {
                slot.copy_from_slice(&now_ns().to_le_bytes());
            }
            Ok(out.send_loan_counted(loan)?)
        };
        // the agent subscribed when the router answered; this port may see
        // it a moment later, and a sample sent before reaches nobody
        let t0 = Instant::now();
        while send()? == 0 {
            if t0.elapsed() > DELIVERY_TIMEOUT || crate::interrupt::requested() {
                bail!("{to} did not subscribe within {DELIVERY_TIMEOUT:?}");
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let mut sent = 1u64;
        let mut next = Instant::now() + period;
        while count.is_none_or(|c| sent < c) && !crate::interrupt::requested() {
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            }
            next += period;
            send()?;
            sent += 1;
        }
        Ok(sent)
    })();
    let sent = result.as_ref().copied().unwrap_or(0);
    let received = wait_taken_and_detach(&session, &from, &to, sent);
    let sent = result?;
    if received < sent {
        bail!(
            "{to} took {received} of {sent} sample(s) within {DELIVERY_TIMEOUT:?}; is its task running (`nerve ps`)? (an input keeps 16 per source: a faster burst overwrites the oldest)"
        );
    }
    println!("{to} <- {} x{sent} from {:?}", schema.type_name, a.sender);
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::payloads::{Tick, VelocityCommand};
    use shm_schemas::schema::Described;

    #[test]
    fn a_missing_stamp_is_filled_and_a_given_one_kept() {
        let s = <VelocityCommand as Described>::schema();
        let at = auto_stamp(&s, &serde_json::json!({"v": 0.1, "omega": 0.0}));
        assert_eq!(at, s.field("stamp_ns").map(|(o, _)| o));
        assert_eq!(auto_stamp(&s, &serde_json::json!({"v": 0.1, "omega": 0.0, "stamp_ns": 5})), None);
        let t = <Tick as Described>::schema();
        assert!(auto_stamp(&t, &serde_json::json!({"seq": 1})).is_some());
    }
}
