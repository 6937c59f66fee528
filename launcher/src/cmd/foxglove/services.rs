//! `nerve foxglove`'s services: the calls agents serve, found and called
//! for Foxglove's clients.
//!
//! The router lists no services (its agent views carry inputs and outputs),
//! so they are found where `nerve call` and `iox2 service list` find them:
//! the robot's iceoryx2 request-response services, whose attributes name
//! the agent, the service and the call's type (`docs/calls.md`). They are
//! listed again only when the robot's agents change (and for a few seconds
//! after, while a new agent makes its ports), not at every refresh. The
//! request's and answer's schemas are the ones the agent registered, paired
//! by the call's fingerprint as `nerve call` pairs them
//! ([`crate::cmd::call::call_schemas`]).
//!
//! A call is laid out from its JSON on the serving thread (a bad request
//! is refused at once) and carried out by one calling thread with a node of
//! its own ([`RawCaller`], as `nerve call`), so that the serving thread
//! never waits for a server: calls are answered in the order they came.

use agent_sdk::World;
use agent_sdk::port::{CallError, RawCaller};
use agent_sdk::world::Ipc;
use iceoryx2::prelude::{CallbackProgression, Node};
use iceoryx2::service::attribute::AttributeKey;
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern;
use nerve_foxglove::{CallDone, ServiceSpec};
use serde_json::Value;
use shm_schemas::Schema;
use shm_schemas::control::call::split_call_type_name;
use shm_schemas::control::cli_to_router::AgentView;
use shm_schemas::services::port_attributes;
use std::collections::BTreeMap;
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::time::{Duration, Instant};

/// How long after an agent came its services are looked for again (it
/// registers before all its ports are made).
const SETTLING: Duration = Duration::from_secs(3);
/// Calls waiting for the calling thread; more are refused.
const WAITING: usize = 64;

/// A service as found: what a call of it needs.
#[derive(Debug, Clone)]
struct Found {
    /// `nerve/ROBOT/AGENT/SERVICE`
    service: String,
    req: Schema,
    resp: Schema,
    spec: ServiceSpec,
}

/// A call for the calling thread.
struct Job {
    name: String,
    service: String,
    request: Vec<u8>,
    resp: Schema,
    timeout: Duration,
    done: CallDone,
}

/// The services of the robot, and the thread that calls them.
pub(super) struct Services {
    world: World,
    /// by `/<agent>/<service>`
    found: BTreeMap<String, Found>,
    /// the agents (name -> pid) when the services were last listed
    listed_for: BTreeMap<String, u32>,
    /// when the set of agents last changed
    changed_at: Option<Instant>,
    calls: Option<SyncSender<Job>>,
}

impl Services {
    pub(super) fn new(world: &World) -> Services {
        Services {
            world: world.clone(),
            found: BTreeMap::new(),
            listed_for: BTreeMap::new(),
            changed_at: None,
            calls: None,
        }
    }

    /// Every service of the live `agents` as a Foxglove service.
    pub(super) fn specs(&mut self, node: &Node<Ipc>, agents: &[AgentView]) -> Vec<ServiceSpec> {
        let live: BTreeMap<String, u32> =
            agents.iter().filter(|a| a.pid != 0).map(|a| (a.name.clone(), a.pid)).collect();
        if live != self.listed_for {
            self.changed_at = Some(Instant::now());
        }
        let settling = self.changed_at.is_some_and(|t| t.elapsed() < SETTLING);
        if live != self.listed_for || settling {
            self.found = self.list(node, agents, &live);
            self.listed_for = live;
        }
        self.found.values().map(|f| f.spec.clone()).collect()
    }

    /// The robot's call services, each of a live agent whose schemas say its types.
    fn list(&self, node: &Node<Ipc>, agents: &[AgentView], live: &BTreeMap<String, u32>) -> BTreeMap<String, Found> {
        let prefix = format!("nerve/{}/", self.world.robot().as_str());
        let mut found = BTreeMap::new();
        let r = <Ipc as iceoryx2::service::Service>::list(node.config(), |d| {
            let config = &d.static_details;
            if !matches!(config.messaging_pattern(), MessagingPattern::RequestResponse(_)) {
                return CallbackProgression::Continue;
            }
            let service = config.name().as_str().to_owned();
            if !service.starts_with(&prefix) {
                return CallbackProgression::Continue;
            }
            let attrs = config.attributes();
            let get = |key: &str| {
                let key = AttributeKey::try_from(key).ok()?;
                attrs.key_value(&key, 0).map(|v| v.to_string())
            };
            let (Some(agent), Some(port), Some(type_name)) =
                (get(port_attributes::AGENT), get(port_attributes::PORT), get(port_attributes::TYPE))
            else {
                return CallbackProgression::Continue;
            };
            let fingerprint = get(port_attributes::FINGERPRINT).and_then(|t| port_attributes::parse_fingerprint(&t));
            let (true, Some(view)) = (live.contains_key(&agent), agents.iter().find(|a| a.name == agent)) else {
                // a service its agent left behind: nobody answers it
                return CallbackProgression::Continue;
            };
            let name = format!("/{agent}/{port}");
            match describe(view, &name, &type_name, fingerprint) {
                Some((req, resp, spec)) => {
                    found.insert(name, Found { service, req, resp, spec });
                }
                None => {
                    tracing::debug!(%name, %type_name, "not advertised: its agent registered no schemas for its types")
                }
            }
            CallbackProgression::Continue
        });
        if let Err(e) = r {
            tracing::warn!(error = ?e, "cannot list the robot's services");
        }
        found
    }

    /// Calls `name` with the JSON `request`; `done` gets the end, from the
    /// calling thread (or at once, for a request refused before it is sent).
    pub(super) fn call(&mut self, name: &str, request: &[u8], timeout: Duration, done: CallDone) {
        let Some(f) = self.found.get(name) else {
            return done(Err(format!("{name}: no such service (any more): its agent may have stopped (`nerve ps`)")));
        };
        let json: Value = match serde_json::from_slice(request) {
            Ok(v) => v,
            Err(e) => return done(Err(format!("{name}: the request is not JSON: {e}"))),
        };
        let bytes = match crate::cmd::call::request_bytes(&f.req, &json) {
            Ok(b) => b,
            Err(e) => return done(Err(format!("{name} takes a {}: {e:#}", f.req.type_name))),
        };
        let job = Job {
            name: name.to_owned(),
            service: f.service.clone(),
            request: bytes,
            resp: f.resp.clone(),
            timeout,
            done,
        };
        let calls = match &self.calls {
            Some(c) => c,
            None => {
                let (tx, rx) = mpsc::sync_channel(WAITING);
                let world = self.world.clone();
                let spawned =
                    std::thread::Builder::new().name("foxglove-calls".into()).spawn(move || calling(&world, &rx));
                if let Err(e) = spawned {
                    return (job.done)(Err(format!("{name}: nerve foxglove cannot start its calling thread: {e}")));
                }
                self.calls.insert(tx)
            }
        };
        match calls.try_send(job) {
            Ok(()) => {}
            Err(TrySendError::Full(job)) => {
                (job.done)(Err(format!("{name}: {WAITING} calls wait already; nothing was sent (call again later)")));
            }
            Err(TrySendError::Disconnected(job)) => {
                self.calls = None;
                (job.done)(Err(format!("{name}: nerve foxglove's calling thread stopped; call again")));
            }
        }
    }
}

/// The request's and answer's schemas of service `name` of `view`, and
/// the service as Foxglove is told it.
fn describe(
    view: &AgentView,
    name: &str,
    type_name: &str,
    fingerprint: Option<u64>,
) -> Option<(Schema, Schema, ServiceSpec)> {
    let (req_name, resp_name) = split_call_type_name(type_name)?;
    let (req, resp) = crate::cmd::call::call_schemas(view, req_name, resp_name, fingerprint)?;
    let spec = ServiceSpec {
        name: name.to_owned(),
        type_name: type_name.to_owned(),
        request_name: req.type_name.clone(),
        request_schema: nerve_recording::json::json_schema(&req).to_string(),
        response_name: resp.type_name.clone(),
        response_schema: nerve_recording::json::json_schema(&resp).to_string(),
    };
    Some((req, resp, spec))
}

/// The calling thread: one call at a time, each through a [`RawCaller`]
/// kept per service while it answers.
fn calling(world: &World, jobs: &Receiver<Job>) {
    let node = match world.node(&format!("foxglove-calls-{}", std::process::id())) {
        Ok(n) => n,
        Err(e) => {
            tracing::warn!(error = %e, "nerve foxglove cannot join the robot's shared memory to call services");
            for job in jobs {
                (job.done)(Err(format!("{}: nerve foxglove cannot join the robot's shared memory: {e}", job.name)));
            }
            return;
        }
    };
    let mut callers: BTreeMap<String, RawCaller> = BTreeMap::new();
    for job in jobs {
        let Job { name, service, request, resp, timeout, done } = job;
        done(call_one(&node, &mut callers, &name, &service, &request, &resp, timeout));
    }
}

fn call_one(
    node: &Node<Ipc>,
    callers: &mut BTreeMap<String, RawCaller>,
    name: &str,
    service: &str,
    request: &[u8],
    resp: &Schema,
    timeout: Duration,
) -> Result<Vec<u8>, String> {
    if !callers.contains_key(service) {
        let c = RawCaller::open(node, service).map_err(|e| format!("{name}: cannot call it: {e}"))?;
        callers.insert(service.to_owned(), c);
    }
    let caller = callers.get(service).ok_or_else(|| format!("{name}: cannot call it"))?;
    let answer = match caller.call(request, timeout) {
        Ok(a) => a,
        Err(e) => {
            // a server gone or replaced: the service is opened anew at the next call
            if !matches!(e, CallError::TimedOut { .. }) {
                callers.remove(service);
            }
            return Err(why(name, &e));
        }
    };
    let value = resp.decode(&answer).map_err(|e| format!("{name}: the answer is not a {}: {e}", resp.type_name))?;
    serde_json::to_vec(&value).map_err(|e| format!("{name}: the answer as JSON: {e}"))
}

/// Why a call failed, as a Foxglove user is told it.
fn why(name: &str, e: &CallError) -> String {
    match e {
        CallError::TimedOut { timeout, .. } => format!(
            "{name}: no answer within {timeout:?} (the server may be busy, hung or gone: `nerve ps`; the call may \
             have been carried out)"
        ),
        CallError::ServerGone { .. } => format!(
            "{name}: the server went away before it answered (it may or may not have carried out the call): `nerve ps`"
        ),
        CallError::NoServer { .. } => {
            format!("{name}: no server answers it (its agent is not running); nothing was sent")
        }
        other => format!("{name}: {other}"),
    }
}
