//! `nerve call AGENT/SERVICE '<json>' [--timeout 2s]`: call a service of
//! an agent from the terminal and print the answer, as `ros2 service call`
//! does (docs/calls.md).
//!
//! The request and answer types are the service's own: the service says
//! its type (`call(Req -> Resp)`) and layouts, the router hands over the
//! schemas the agent registered, and the JSON is laid out by the request's
//! schema strictly, as `nerve pub` does (a missing or unknown field, a
//! number out of range is refused with the field's path before anything is
//! sent). A `stamp_ns` the JSON leaves out is the time of the call. The
//! answer is printed as JSON; no answer within the timeout, the server gone
//! or not running, is an error that says so. A sequence answer
//! (`serve_seq`) comes as its sample's bytes, printed as `{"header": …,
//! "items": [...]}` with as many items as it has; one the server refused
//! (longer than its maximum) is an error that says so.

use crate::client::RouterSession;
use agent_sdk::World;
use agent_sdk::clock::{now_ns, parse_duration};
use agent_sdk::port::RawCaller;
use anyhow::{Context as _, Result, anyhow, bail};
use shm_schemas::control::call::{call_fingerprint, split_call_type_name};
use shm_schemas::control::cli_to_router::{AgentView, CliRequest, RouterReply};
use shm_schemas::encode::encode_json;
use shm_schemas::{PortRef, Schema};
use std::process::ExitCode;

/// `nerve call`
#[derive(Debug, clap::Args)]
pub struct CallArgs {
    /// The service, AGENT/SERVICE (e.g. map-builder/plan).
    pub service: String,
    /// The request as JSON, every field of the request's type (`nerve
    /// types TYPE` lists them); a missing `stamp_ns` is the time of the call.
    pub json: String,
    /// How long to wait for the answer (e.g. 500ms, 2s).
    #[arg(long, default_value = "2s")]
    pub timeout: String,
}

/// The schema of `type_name` that agent `view` registered (or this build's
/// own), of which one layout `ok` accepts.
fn schema_named(view: &AgentView, type_name: &str) -> Vec<Schema> {
    let mut found: Vec<Schema> = view.schemas.iter().filter(|s| s.type_name == type_name).cloned().collect();
    if let Some(s) = shm_schemas::schema::built_in_named(type_name) {
        found.push(s);
    }
    found
}

/// The request's and answer's schemas of a call of `req_name` answered by
/// `resp_name` that agent `view` serves: the pair whose fingerprints make
/// the service's `fingerprint` (any pair when the service does not say).
/// Also `nerve foxglove`'s, which calls services for its clients.
pub(crate) fn call_schemas(
    view: &AgentView,
    req_name: &str,
    resp_name: &str,
    fingerprint: Option<u64>,
) -> Option<(Schema, Schema)> {
    for req in schema_named(view, req_name) {
        for resp in schema_named(view, resp_name) {
            if fingerprint.is_none_or(|f| f == call_fingerprint(req.fingerprint(), resp.fingerprint())) {
                return Some((req, resp));
            }
        }
    }
    None
}

/// A request's bytes: `json` laid out strictly by `req`'s schema, a
/// top-level `stamp_ns` the JSON leaves out set to now.
pub(crate) fn request_bytes(req: &Schema, json: &serde_json::Value) -> Result<Vec<u8>> {
    let stamp_at = crate::cmd::publish::auto_stamp(req, json);
    let mut bytes = encode_json(req, json, &|p| Some(p) == stamp_at.map(|_| "stamp_ns"))?;
    if let Some(at) = stamp_at
        && let Some(slot) = bytes.get_mut(at..at.saturating_add(8))
    {
        slot.copy_from_slice(&now_ns().to_le_bytes());
    }
    Ok(bytes)
}

pub fn call(world: &World, a: CallArgs) -> Result<ExitCode> {
    let port: PortRef = a.service.parse().context("SERVICE must be AGENT/SERVICE")?;
    let timeout = parse_duration(&a.timeout).map_err(|e| anyhow!("--timeout {:?}: {e}", a.timeout))?;
    let json: serde_json::Value =
        serde_json::from_str(&a.json).with_context(|| format!("the request is not JSON: {}", a.json))?;
    let session = RouterSession::open(world)?;
    let agent = port.agent.as_str();
    let views = match session.call(CliRequest::Agent { name: agent.to_owned() })? {
        RouterReply::Agents(v) => v,
        _ => bail!("unexpected reply from the router"),
    };
    let view: &AgentView = views.iter().find(|v| v.name == agent).ok_or_else(|| {
        anyhow!("no agent named {agent:?} runs on robot {}; `nerve ps` lists them", session.world.robot())
    })?;
    let service = world.robot().port_service(agent, &port.port);
    let caller = RawCaller::open(session.node()?, &service)
        .map_err(|e| anyhow!("agent {agent:?} offers no service {:?} that can be called: {e}", port.port))?;
    let (req_name, resp_name) = split_call_type_name(caller.type_name())
        .ok_or_else(|| anyhow!("{port} carries {}, not a call", caller.type_name()))?;
    let (req, resp) = call_schemas(view, req_name, resp_name, caller.fingerprint()).ok_or_else(|| {
        anyhow!(
            "{port} is a {}, whose layouts neither this build nor the agent's registration describes; rebuild nerve or the agent",
            caller.type_name()
        )
    })?;
    let bytes = request_bytes(&req, &json).with_context(|| format!("{port} takes a {}", req.type_name))?;
    let answer = caller.call(&bytes, timeout).with_context(|| format!("calling {port}"))?;
    let value = resp.decode(&answer).with_context(|| format!("the answer of {port} as a {}", resp.type_name))?;
    println!("{}", serde_json::to_string_pretty(&value)?);
    Ok(ExitCode::SUCCESS)
}
