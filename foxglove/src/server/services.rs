//! Services (the protocol's `services` capability): every service an agent
//! offers is advertised to every client (`advertiseServices`, and
//! `unadvertiseServices` when its agent goes), with the request's and the
//! answer's JSON Schemas, and a client's `serviceCallRequest` is carried
//! out by the robot ([`Robot::call_service`]) and answered with a
//! `serviceCallResponse` or a `serviceCallFailure` that says why.
//!
//! A call changes the robot as a parameter set does: it needs the edit
//! token, and `--read-only` refuses it. Requests and answers are JSON (the
//! request laid out strictly by the request's schema, as `nerve call`
//! does). The serving thread never waits for a server: the robot hands the
//! end of the call to a callback that queues the answer for the client
//! from whatever thread it runs on. Calls in flight are bounded
//! ([`MAX_IN_FLIGHT`] for the server, [`MAX_IN_FLIGHT_PER_CLIENT`] each).

use super::{Client, Hub, Request, edit_refused, lock};
use crate::{Robot, ServiceSpec};
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::Sender;

/// Binary opcode of a client's service call request.
pub(super) const OP_SERVICE_CALL_REQUEST: u8 = 2;
/// Binary opcode of the server's service call response.
const OP_SERVICE_CALL_RESPONSE: u8 = 3;
/// The one encoding of requests and answers.
const ENCODING: &str = "json";
/// Calls in flight for all clients at once; more are refused.
pub(super) const MAX_IN_FLIGHT: usize = 64;
/// Calls in flight for one client; more are refused.
pub(super) const MAX_IN_FLIGHT_PER_CLIENT: usize = 16;

/// A service as advertised: its id and what the robot said of it.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Advertised {
    id: u32,
    spec: ServiceSpec,
}

/// The services advertised, by name.
#[derive(Default)]
pub(super) struct Services {
    by_name: BTreeMap<String, Advertised>,
    next_id: u32,
    /// calls in flight, for all clients
    in_flight: Arc<AtomicUsize>,
}

/// A client's call, handed to the serving thread.
pub(super) struct Call {
    client: Arc<Client>,
    service_id: u32,
    call_id: u32,
    name: String,
    request: Vec<u8>,
}

/// A client's service call request, parsed: service id, call id,
/// encoding, payload; `None` for a frame too short or of another opcode.
fn parse_call(frame: &[u8]) -> Option<(u32, u32, &str, &[u8])> {
    let (&op, rest) = frame.split_first()?;
    if op != OP_SERVICE_CALL_REQUEST {
        return None;
    }
    let word =
        |at: usize| -> Option<u32> { Some(u32::from_le_bytes(rest.get(at..at.checked_add(4)?)?.try_into().ok()?)) };
    let (service, call, len) = (word(0)?, word(4)?, usize::try_from(word(8)?).ok()?);
    let end = 12usize.checked_add(len)?;
    let encoding = std::str::from_utf8(rest.get(12..end)?).ok()?;
    Some((service, call, encoding, rest.get(end..)?))
}

/// A service call response frame: opcode, service id, call id, encoding
/// length, encoding, payload; integers little-endian.
fn response(service_id: u32, call_id: u32, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(13 + ENCODING.len() + payload.len());
    out.push(OP_SERVICE_CALL_RESPONSE);
    out.extend_from_slice(&service_id.to_le_bytes());
    out.extend_from_slice(&call_id.to_le_bytes());
    out.extend_from_slice(&(ENCODING.len() as u32).to_le_bytes());
    out.extend_from_slice(ENCODING.as_bytes());
    out.extend_from_slice(payload);
    out
}

/// `serviceCallFailure`.
fn failure(service_id: u32, call_id: u32, message: &str) -> String {
    json!({ "op": "serviceCallFailure", "serviceId": service_id, "callId": call_id, "message": message }).to_string()
}

/// `advertiseServices` of `services`: the current form (`request` and
/// `response` definitions) and the older one (`requestSchema`,
/// `responseSchema`) that clients of spec versions before it read.
fn advertise<'a>(services: impl IntoIterator<Item = &'a Advertised>) -> String {
    let list: Vec<Value> = services
        .into_iter()
        .map(|a| {
            let s = &a.spec;
            let def = |name: &str, schema: &str| {
                json!({ "encoding": ENCODING, "schemaName": name, "schemaEncoding": "jsonschema", "schema": schema })
            };
            json!({
                "id": a.id,
                "name": s.name,
                "type": s.type_name,
                "request": def(&s.request_name, &s.request_schema),
                "response": def(&s.response_name, &s.response_schema),
                "requestSchema": s.request_schema,
                "responseSchema": s.response_schema,
            })
        })
        .collect();
    json!({ "op": "advertiseServices", "services": list }).to_string()
}

/// `unadvertiseServices` of service ids.
fn unadvertise(ids: &[u32]) -> String {
    json!({ "op": "unadvertiseServices", "serviceIds": ids }).to_string()
}

/// Brings the services up to date with the robot's and tells every client
/// what came and went.
pub(super) fn refresh(hub: &Hub, robot: &mut dyn Robot) {
    let specs = match robot.services() {
        Ok(s) => s,
        Err(e) => {
            tracing::debug!("no services now: {e}");
            return;
        }
    };
    let mut services = lock(&hub.services);
    let wanted: BTreeMap<&str, &ServiceSpec> = specs.iter().map(|s| (s.name.as_str(), s)).collect();
    let mut removed = Vec::new();
    services.by_name.retain(|name, a| {
        let same = wanted.get(name.as_str()).is_some_and(|s| **s == a.spec);
        if !same {
            removed.push(a.id);
        }
        same
    });
    let mut added = Vec::new();
    for s in specs {
        if services.by_name.contains_key(&s.name) {
            continue;
        }
        services.next_id = services.next_id.wrapping_add(1);
        let a = Advertised { id: services.next_id, spec: s };
        added.push(a.clone());
        services.by_name.insert(a.spec.name.clone(), a);
    }
    if removed.is_empty() && added.is_empty() {
        return;
    }
    tracing::info!(added = added.len(), removed = removed.len(), "services changed");
    for c in lock(&hub.clients).values() {
        if !removed.is_empty() {
            c.say(unadvertise(&removed));
        }
        if !added.is_empty() {
            c.say(advertise(&added));
        }
    }
}

/// The agent that provides service `name` (`/<agent>/<service>`).
fn provider(name: &str) -> &str {
    let bare = name.strip_prefix('/').unwrap_or(name);
    bare.split_once('/').map_or(bare, |(agent, _)| agent)
}

/// Every service advertised with its provider, for the connection graph
/// (`advertisedServices`: the ids are agent names, as its topics' are).
pub(super) fn providers(services: &Services) -> Vec<(String, Vec<String>)> {
    services.by_name.keys().map(|name| (name.clone(), vec![provider(name).to_owned()])).collect()
}

/// Tells a new client every service; the caller holds the lock of the
/// clients' list, or has not added it yet, so that no change falls between.
pub(super) fn advertise_to(services: &Services, client: &Client) {
    if !services.by_name.is_empty() {
        client.say(advertise(services.by_name.values()));
    }
}

/// A client's service call request frame: refused at once (no token, a
/// service not advertised, another encoding, too many in flight) or
/// handed to the serving thread.
pub(super) fn request(hub: &Hub, client: &Arc<Client>, tx: &Sender<Request>, frame: &[u8]) {
    let Some((service_id, call_id, encoding, payload)) = parse_call(frame) else {
        client.error("a binary frame of opcode 2 that is not a service call request was ignored");
        return;
    };
    let refuse = |why: &str| {
        tracing::info!(client = client.id, service_id, call_id, "call refused: {why}");
        client.say(failure(service_id, call_id, why));
    };
    if let Some(why) = edit_refused(hub, client, "call services") {
        return refuse(&why);
    }
    if encoding != ENCODING {
        return refuse(&format!("the request is in {encoding:?}: nerve foxglove takes {ENCODING}"));
    }
    let services = lock(&hub.services);
    let Some(name) = services.by_name.values().find(|a| a.id == service_id).map(|a| a.spec.name.clone()) else {
        return refuse(&format!("no service {service_id} is advertised (any more): its agent may have stopped"));
    };
    let all = Arc::clone(&services.in_flight);
    drop(services);
    if client.calls.load(Ordering::Relaxed) >= MAX_IN_FLIGHT_PER_CLIENT {
        return refuse(&format!(
            "{name}: this client has {MAX_IN_FLIGHT_PER_CLIENT} calls in flight already, the most it may; nothing \
             was sent (wait for their answers)"
        ));
    }
    if all.load(Ordering::Relaxed) >= MAX_IN_FLIGHT {
        return refuse(&format!(
            "{name}: nerve foxglove has {MAX_IN_FLIGHT} calls in flight already, the most it carries; nothing was sent"
        ));
    }
    client.calls.fetch_add(1, Ordering::Relaxed);
    all.fetch_add(1, Ordering::Relaxed);
    let call = Call { client: Arc::clone(client), service_id, call_id, name, request: payload.to_vec() };
    hub.ask(tx, Request::Call(call));
}

/// Carries out `call` through the robot; its end reaches the client from
/// whichever thread ends it.
pub(super) fn call(hub: &Hub, robot: &mut dyn Robot, call: Call) {
    let Call { client, service_id, call_id, name, request } = call;
    let all = Arc::clone(&lock(&hub.services).in_flight);
    tracing::debug!(client = client.id, service = %name, call_id, "calling");
    let service = name.clone();
    let done = Box::new(move |r: Result<Vec<u8>, String>| {
        client.calls.fetch_sub(1, Ordering::Relaxed);
        all.fetch_sub(1, Ordering::Relaxed);
        match r {
            Ok(answer) => client.say_binary(response(service_id, call_id, &answer)),
            Err(why) => {
                tracing::info!(client = client.id, %service, call_id, "call failed: {why}");
                client.say(failure(service_id, call_id, &why));
            }
        }
    });
    robot.call_service(&name, &request, hub.opts.call_timeout, done);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_call_request_frame_is_parsed_or_refused() {
        let mut f = vec![2, 7, 0, 0, 0, 9, 0, 0, 0, 4, 0, 0, 0];
        f.extend_from_slice(b"json{}");
        assert_eq!(parse_call(&f), Some((7, 9, "json", &b"{}"[..])));
        // an encoding longer than the frame, another opcode, too short
        let mut long = f.clone();
        long[9] = 200;
        assert_eq!(parse_call(&long), None);
        let mut other = f.clone();
        other[0] = 1;
        assert_eq!(parse_call(&other), None);
        assert_eq!(parse_call(&f[..8]), None);
        let mut huge = f.clone();
        huge[9..13].copy_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(parse_call(&huge), None);
    }

    #[test]
    fn a_services_provider_is_the_agent_of_its_name() {
        assert_eq!(provider("/map-builder/plan"), "map-builder");
        assert_eq!(provider("/s/a/b"), "s");
        assert_eq!(provider("bare"), "bare");
    }

    #[test]
    fn a_response_frame_is_opcode_ids_encoding_payload() {
        let r = response(7, 9, b"{}");
        assert_eq!(r[0], 3);
        assert_eq!(&r[1..5], &[7, 0, 0, 0]);
        assert_eq!(&r[5..9], &[9, 0, 0, 0]);
        assert_eq!(&r[9..13], &[4, 0, 0, 0]);
        assert_eq!(&r[13..17], b"json");
        assert_eq!(&r[17..], b"{}");
    }

    #[test]
    fn an_advertisement_has_both_forms_of_schema() {
        let a = Advertised {
            id: 3,
            spec: ServiceSpec {
                name: "/s/plan".into(),
                type_name: "call(nerve::Tick -> nerve::Scalar)".into(),
                request_name: "nerve::Tick".into(),
                request_schema: "{\"type\":\"object\"}".into(),
                response_name: "nerve::Scalar".into(),
                response_schema: "{}".into(),
            },
        };
        let v: Value = serde_json::from_str(&advertise([&a])).expect("json");
        assert_eq!(v["op"], "advertiseServices");
        let s = &v["services"][0];
        assert_eq!((s["id"].as_u64(), s["name"].as_str()), (Some(3), Some("/s/plan")));
        assert_eq!(s["request"]["schemaName"], "nerve::Tick");
        assert_eq!(s["request"]["encoding"], "json");
        assert_eq!(s["response"]["schemaEncoding"], "jsonschema");
        assert_eq!(s["requestSchema"], "{\"type\":\"object\"}");
        let f: Value = serde_json::from_str(&failure(3, 4, "why")).expect("json");
        assert_eq!(
            (f["serviceId"].as_u64(), f["callId"].as_u64(), f["message"].as_str()),
            (Some(3), Some(4), Some("why"))
        );
    }
}
