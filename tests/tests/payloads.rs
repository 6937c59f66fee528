//! Self-describing payloads, end to end: an agent with a type of its own
//! (`acme::Gripper`, defined in `src/bin/gripper.rs` with one derive, not
//! in nerve's built-in list) registers its schema; `nerve ps --json` shows
//! it; `nerve echo` decodes it (whole, `--json`, `--field`) and `nerve hz`
//! counts it; the port's iceoryx2 service carries nerve's attributes; and a
//! stale build of the same type (same name and size, another layout) is
//! refused by the router and by the data path itself.

use nerve_tests::{Robot, alive, sigkill, wait_until};
use serde_json::Value;
use std::time::Duration;

fn gripper_schema(agent: &Value) -> Value {
    assert!(agent["outputs"][0]["fingerprint"].as_u64().is_some_and(|fp| fp != 0), "{agent}");
    agent["schemas"]
        .as_array()
        .expect("schemas")
        .iter()
        .find(|s| s["type_name"] == "acme::Gripper")
        .cloned()
        .expect("the schema of acme::Gripper")
}

#[test]
fn a_type_nerve_was_not_built_with_is_echoed_by_its_schema() {
    let r = Robot::new("acme");
    r.router();
    r.ok(&["start", "gripper", "--name", "g"]);

    // registration carries the port's fingerprint and the type's schema
    let g = r.agent("g").expect("g in ps");
    assert_eq!(g["outputs"][0]["type_name"], "acme::Gripper");
    let schema = gripper_schema(&g);
    let fields: Vec<&str> = schema["kind"]["struct"]["fields"]
        .as_array()
        .expect("fields")
        .iter()
        .filter_map(|f| f["name"].as_str())
        .collect();
    assert_eq!(fields, ["count", "opening_m", "fingers", "tool", "temp_cdeg"]);
    // a registered schema is a valid one (the router checks), and the
    // explicit padding and the `Bool` a payload needs since B7 left it as
    // it was: no `_pad` fields, a flag whose schema is a bool's
    let parsed: shm_schemas::Schema = serde_json::from_value(schema.clone()).expect("a schema");
    parsed.validate().expect("valid");
    assert!(parsed.field("fingers.0._pad").is_none() && parsed.field("_pad").is_none());
    assert_eq!(parsed.field("fingers.0.contact").map(|(_, s)| s.type_name.as_str()), Some("bool"));
    let graph = r.graph();
    let in_graph = graph["agents"].as_array().expect("agents").iter().find(|a| a["name"] == "g").expect("g");
    assert_eq!(gripper_schema(in_graph), schema, "graph --json shows the same schema");

    // echo --json: every field, nested structs and arrays, the fixed string
    let samples = r.echo("g/state", 3);
    assert_eq!(samples.len(), 3);
    let s = &samples[2];
    assert_eq!(s["type"], "acme::Gripper");
    let n = s["data"]["count"].as_u64().expect("count");
    assert!(n >= 3, "{s}");
    assert_eq!(s["seq"].as_u64(), Some(n), "the n-th sample counts n");
    assert!((s["data"]["opening_m"].as_f64().expect("opening") - n as f64 * 0.001).abs() < 1e-12, "{s}");
    assert_eq!(s["data"]["tool"], "screwdriver");
    assert_eq!(s["data"]["temp_cdeg"], -250);
    let fingers = s["data"]["fingers"].as_array().expect("fingers");
    assert_eq!(fingers.len(), 3);
    assert_eq!(fingers[1]["force_n"].as_f64(), Some((n % 10) as f64), "{s}");
    assert_eq!(fingers[1]["contact"], n.is_multiple_of(2));

    // the human form and one field
    let human = r.ok(&["echo", "g/state", "--count", "1", "--timeout", "5"]);
    assert!(human.contains("acme::Gripper { count: ") && human.contains("tool: \"screwdriver\""), "{human}");
    let field = r.ok(&["echo", "g/state", "--field", "fingers.2.force_n", "--count", "2", "--json", "--timeout", "5"]);
    let lines: Vec<Value> = field.lines().map(|l| serde_json::from_str(l).expect("json")).collect();
    assert_eq!(lines.len(), 2);
    assert!(lines.iter().all(|l| l["field"] == "fingers.2.force_n" && l["data"].is_number()), "{field}");
    let e = r.fails(&["echo", "g/state", "--field", "fingers.9", "--count", "1", "--timeout", "5"]);
    assert!(e.contains("no field \"fingers.9\"") && e.contains("fingers.<i>.force_n"), "{e}");

    // hz needs no decoding
    let hz = r.ok(&["hz", "g/state", "--count", "1", "--json", "--window", "0.5"]);
    let rate: Value = serde_json::from_str(hz.trim()).expect("hz json");
    assert!(rate["rate_hz"].as_f64().unwrap_or(0.0) > 10.0, "{hz}");

    // with no router the port's attributes say the type: a built-in one is
    // decoded with this build's own schema, a foreign one waits for the router
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    let router_pid = r.pid_file("router").expect("router pid file");
    sigkill(router_pid);
    assert!(wait_until(Duration::from_secs(2), || !alive(router_pid)));
    let e = r.fails(&["echo", "g/state", "--count", "1", "--timeout", "3"]);
    assert!(e.contains("acme::Gripper") && e.contains("start the router"), "{e}");
    let ticks = r.echo("t1/tick", 2);
    assert!(ticks.iter().all(|t| t["type"] == "nerve::Tick" && t["data"]["seq"].is_u64()), "{ticks:?}");
    r.router();
    assert!(wait_until(Duration::from_secs(5), || r.ps().len() == 2), "agents did not re-register");
    r.down_and_check_clean();
}

#[test]
fn a_stale_build_of_a_type_is_refused_on_connect() {
    let r = Robot::new("stale");
    r.router();
    r.ok(&["start", "gripper", "--name", "new"]);
    r.ok(&["start", "gripper", "--name", "old", "--", "--layout", "old"]);
    let (new, old) = (r.agent("new").expect("new"), r.agent("old").expect("old"));
    let (fp_new, fp_old) = (
        new["outputs"][0]["fingerprint"].as_u64().expect("fingerprint"),
        old["outputs"][0]["fingerprint"].as_u64().expect("fingerprint"),
    );
    assert_ne!(fp_new, fp_old, "the two builds differ in layout");
    assert_eq!(new["outputs"][0]["type_name"], old["outputs"][0]["type_name"]);

    // the router refuses, naming the type and both fingerprints
    let e = r.fails(&["connect", "old/state", "new/cmd"]);
    assert!(e.contains("acme::Gripper") && e.contains("different definitions"), "{e}");
    assert!(e.contains(&format!("{fp_old:#018x}")) && e.contains(&format!("{fp_new:#018x}")), "{e}");
    // the fields that differ, and what to do, without guessing which side is older
    assert!(e.contains("field `count`: at offset 8 in old/state, at offset 0 in new/cmd"), "{e}");
    assert!(e.contains("make both declare the same layout") && !e.contains("older"), "{e}");
    assert!(r.graph()["connections"].as_array().is_some_and(|c| c.is_empty()), "nothing was connected");
    // the same build connects
    r.ok(&["start", "gripper", "--name", "new2"]);
    r.ok(&["connect", "new2/state", "new/cmd"]);
    // and the other way round (the data path refuses it as well, see
    // agent-sdk's `ports::tests`)
    let e = r.fails(&["connect", "new/state", "old/cmd"]);
    assert!(e.contains("different definitions"), "{e}");
    r.down_and_check_clean();
}

/// An agent whose registration would not fit the router's service with its
/// schemas (`acme::Wide`, 900 nested fields) registers without them: it
/// runs and is listed with its fingerprints, its log says why, `nerve hz`
/// counts its port, and `nerve echo` says why it cannot decode it.
#[test]
fn a_registration_too_large_for_its_schemas_registers_without_them() {
    let r = Robot::new("wide");
    r.router();
    r.ok(&["start", "gripper", "--name", "w", "--", "--layout", "wide"]);
    let w = r.agent("w").expect("w is registered");
    assert_eq!(w["outputs"][0]["type_name"], "acme::Wide");
    assert!(w["outputs"][0]["fingerprint"].as_u64().is_some_and(|fp| fp != 0), "{w}");
    assert!(w["schemas"].as_array().is_some_and(Vec::is_empty), "no schemas: {}", w["schemas"]);
    let log = r.ok(&["logs", "w"]);
    assert!(log.contains("too large") && log.contains("registering without them"), "{log}");
    let hz = r.ok(&["hz", "w/state", "--count", "1", "--json"]);
    assert!(hz.contains("rate_hz") || hz.contains("hz"), "{hz}");
    let e = r.fails(&["echo", "w/state", "--count", "1"]);
    assert!(e.contains("registered no schema") && e.contains("nerve logs w"), "{e}");
    r.down_and_check_clean();
}
