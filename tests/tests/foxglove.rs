//! `nerve foxglove` (issue 45) with an outside client: Foxglove's own
//! protocol library (npm `@foxglove/ws-protocol` on `ws`, in
//! `tests/js/foxglove/`, installed by `.ci/run`) against a robot started
//! from `launch/pipeline.toml`, over loopback.
//!
//! The client connects with each subprotocol name, gets the channels of
//! every output port, subscribes, and decodes JSON samples that are the
//! ones `nerve echo` prints; an unknown subprotocol, a foreign `Origin` and
//! a wrong token are refused; a client that stops reading is disconnected
//! while the robot and the other clients go on; parameters are read and
//! set through the router (a refused value refused, no token no change);
//! the connection graph follows `nerve connect` and lists an agent's
//! service with its provider while it runs; a message published into
//! an input comes out of the relay, one of the wrong shape is refused;
//! 100 subscribe/unsubscribe cycles leave the server's memory flat; an
//! odometry agent's pose is also a `foxglove.FrameTransform` channel, and
//! a camera's ring a `foxglove.RawImage` one; and Twists published as the
//! Teleop panel does into the motor's `cmd` move the simulated robot; an
//! agent's service is advertised with its JSON Schemas and called (with
//! the token, not without it nor under `--read-only`), and unadvertised
//! when its agent stops; the map builder's map is also a `foxglove.Grid`
//! channel whose grid holds the cell of a pose published into it.

use nerve_tests::{Robot, bin_dir, wait_until};
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

const TOKEN: &str = "foxglove-test-token-0123456789";

fn pipeline() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("launch").join("pipeline.toml")
}

fn client_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("js").join("foxglove")
}

/// A robot of `launch/pipeline.toml` (t1/tick -> r1/in, r2/in).
fn robot(tag: &str) -> Robot {
    let r = Robot::new(tag);
    r.ok(&["launch", pipeline().to_str().expect("path")]);
    r
}

/// A running `nerve foxglove`; stopped with SIGINT by [`Fox::stop`], killed when dropped.
struct Fox {
    child: Child,
    url: String,
    /// what it printed after its address
    lines: mpsc::Receiver<String>,
}

impl Fox {
    fn start(r: &Robot, extra: &[&str]) -> Fox {
        let mut child = r
            .command("nerve")
            .env("NERVE_FOXGLOVE_TOKEN", TOKEN)
            .args(["foxglove", "--bind", "127.0.0.1:0"])
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("run nerve foxglove");
        let mut stdout = BufReader::new(child.stdout.take().expect("stdout"));
        let mut first = String::new();
        stdout.read_line(&mut first).expect("read the address");
        let url = first
            .split("ws://")
            .nth(1)
            .and_then(|rest| rest.split_whitespace().next())
            .map(|a| format!("ws://{a}"))
            .unwrap_or_else(|| panic!("nerve foxglove printed no address: {first:?}"));
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for l in stdout.lines().map_while(Result::ok) {
                eprintln!("nerve foxglove: {l}");
                let _ = tx.send(l);
            }
        });
        Fox { child, url, lines }
    }

    /// Stops it with SIGINT; returns what it printed (its closing figures).
    fn stop(mut self) -> String {
        let pid = nix::unistd::Pid::from_raw(i32::try_from(self.child.id()).expect("pid"));
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).expect("SIGINT");
        let ok = wait_until(Duration::from_secs(10), || self.child.try_wait().ok().flatten().is_some());
        assert!(ok, "nerve foxglove did not stop within 10 s of Ctrl-C");
        let status = self.child.try_wait().ok().flatten().expect("status");
        assert!(status.success(), "nerve foxglove ended with {status} after Ctrl-C");
        let mut said = Vec::new();
        while let Ok(l) = self.lines.recv_timeout(Duration::from_secs(2)) {
            said.push(l);
        }
        said.join("\n")
    }

    /// How often its threads have gone to sleep so far (voluntary context
    /// switches, summed over its threads): a loop on a timer adds hundreds a second.
    fn sleeps(&self) -> u64 {
        let tasks = std::fs::read_dir(format!("/proc/{}/task", self.child.id())).expect("its threads");
        tasks
            .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("status")).ok())
            .filter_map(|s| {
                s.lines().find_map(|l| l.strip_prefix("voluntary_ctxt_switches:"))?.trim().parse::<u64>().ok()
            })
            .sum()
    }

    /// Its resident memory, kB.
    fn rss_kb(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.child.id())).expect("status");
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.split_whitespace().next()?.parse().ok())
            .expect("VmRSS")
    }
}

impl Drop for Fox {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `node client.js ARGS`, started (its stdout piped).
fn client(args: &[&str]) -> Child {
    let dir = client_dir();
    assert!(
        dir.join("node_modules").join("@foxglove").join("ws-protocol").is_dir(),
        "the test client's packages are missing: run `npm ci --prefix tests/js/foxglove` (.ci/run does)"
    );
    Command::new("node")
        .arg(dir.join("client.js"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("run node (node 20 is on every machine of the project)")
}

/// Runs the client to its end; its JSON lines. Its own 20 s limit bounds it.
fn run_client(args: &[&str]) -> Vec<Value> {
    let out = client(args).wait_with_output().expect("node client");
    let lines = parse(&String::from_utf8_lossy(&out.stdout));
    assert!(out.status.success(), "node client.js {} failed: {lines:?}", args.join(" "));
    lines
}

fn parse(text: &str) -> Vec<Value> {
    text.lines().map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}"))).collect()
}

/// The next JSON line of a running client (at most 20 s).
fn next_line(lines: &mpsc::Receiver<String>) -> Value {
    let l = lines.recv_timeout(Duration::from_secs(20)).expect("a line from the client");
    serde_json::from_str(&l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}"))
}

fn lines_of(child: &mut Child) -> mpsc::Receiver<String> {
    let stdout = child.stdout.take().expect("stdout");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for l in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = tx.send(l);
        }
    });
    rx
}

#[test]
fn foxglove_clients_read_the_pipeline_with_either_subprotocol_as_echo_does() {
    let r = robot("fxread");
    let fox = Fox::start(&r, &[]);
    // `nerve echo` and the Foxglove client read t1/tick at the same time
    let echo = r
        .command("nerve")
        .args(["echo", "t1/tick", "--json", "--count", "300", "--timeout", "5"])
        .stdout(Stdio::piped())
        .spawn()
        .expect("nerve echo");
    let seen = run_client(&["watch", &fox.url, "foxglove.sdk.v1", "/t1/tick", "20"]);
    let echoed = echo.wait_with_output().expect("echo");
    assert!(echoed.status.success(), "nerve echo failed");
    let echoed = parse(&String::from_utf8_lossy(&echoed.stdout));

    let head = &seen[0];
    assert_eq!(head["subprotocol"], "foxglove.sdk.v1");
    assert_eq!(head["serverInfo"]["metadata"]["robot"], r.name.as_str());
    assert_eq!(head["topics"], serde_json::json!(["/r1/out", "/r2/out", "/t1/tick"]), "every output port a channel");
    let ch = &head["channel"];
    assert_eq!((ch["encoding"].as_str(), ch["schemaEncoding"].as_str()), (Some("json"), Some("jsonschema")));
    assert_eq!(ch["schemaName"], "nerve::Tick");
    let schema: Value = serde_json::from_str(ch["schema"].as_str().expect("schema")).expect("schema JSON");
    assert_eq!(schema["properties"]["seq"]["type"], "integer");

    let samples = seen[1]["samples"].as_array().expect("samples");
    assert_eq!(samples.len(), 20);
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).expect("clock").as_nanos();
    let mut common = 0;
    for s in samples {
        // the sample's stamp, on the wall clock as Foxglove's timestamps are
        let ts: u128 = s["timestamp"].as_str().expect("timestamp").parse().expect("ns");
        assert!(now.abs_diff(ts) < 60_000_000_000, "timestamp {ts} is not the wall clock's ({now})");
        if let Some(e) = echoed.iter().find(|e| e["data"]["seq"] == s["data"]["seq"]) {
            assert_eq!(e["data"], s["data"], "Foxglove's sample differs from nerve echo's");
            common += 1;
        }
    }
    assert!(common > 0, "no sample seen by both nerve echo and the Foxglove client");

    // the other name, on a relay's port
    let seen = run_client(&["watch", &fox.url, "foxglove.websocket.v1", "/r1/out", "3"]);
    assert_eq!(seen[0]["subprotocol"], "foxglove.websocket.v1");
    assert_eq!(seen[1]["samples"].as_array().map(Vec::len), Some(3));

    // an agent that leaves takes its channel with it
    r.ok(&["stop", "r1"]);
    let mut topics = Value::Null;
    let gone = wait_until(Duration::from_secs(10), || {
        topics = run_client(&["watch", &fox.url, "foxglove.sdk.v1", "/t1/tick", "1"])[0]["topics"].clone();
        topics == serde_json::json!(["/r2/out", "/t1/tick"])
    });
    assert!(gone, "/r1/out still advertised after r1 stopped: {topics}");
    let stats = fox.stop();
    assert!(stats.contains(" 0 refused"), "{stats}");
}

#[test]
fn unknown_subprotocols_foreign_origins_and_wrong_tokens_are_refused() {
    let r = robot("fxrefuse");
    let fox = Fox::start(&r, &[]);
    let said = run_client(&["refused", &fox.url, "foxglove.websocket.v2"]);
    assert_eq!(said[0]["status"], 400, "{said:?}");
    assert!(said[0]["body"].as_str().is_some_and(|b| b.contains("foxglove.sdk.v1")), "{said:?}");
    let said = run_client(&["refused", &fox.url, "foxglove.sdk.v1", "https://evil.example"]);
    assert_eq!(said[0]["status"], 403, "{said:?}");
    let said = run_client(&["refused", &format!("{}/?token=wrong-token-0123456789", fox.url), "foxglove.sdk.v1"]);
    assert_eq!(said[0]["status"], 401, "{said:?}");
    // a page of this machine is let in
    let said = run_client(&["watch", &fox.url, "foxglove.sdk.v1", "/t1/tick", "1"]);
    assert_eq!(said[1]["samples"].as_array().map(Vec::len), Some(1));
    let stats = fox.stop();
    assert!(stats.contains("1 client(s) served, 3 refused"), "{stats}");
}

#[test]
fn a_client_that_stops_reading_is_dropped_without_harm_to_the_robot() {
    let r = robot("fxstall");
    let fox = Fox::start(&r, &["--stall-timeout", "1", "--queue", "16"]);
    let mut stalled = client(&["stall", &fox.url, "/t1/tick", "4000"]);
    let lines = lines_of(&mut stalled);
    assert_eq!(next_line(&lines)["paused"], true);
    // while it reads nothing: the robot ticks on, and another client is served
    let before = r.echo("t1/tick", 1)[0]["seq"].as_u64().expect("seq");
    let seen = run_client(&["watch", &fox.url, "foxglove.sdk.v1", "/t1/tick", "5"]);
    assert_eq!(seen[1]["samples"].as_array().map(Vec::len), Some(5));
    let after = r.echo("t1/tick", 1)[0]["seq"].as_u64().expect("seq");
    assert!(after > before, "the ticker stopped while a client stalled ({before} -> {after})");
    assert!(r.echo("r1/out", 3).len() == 3, "the relay stopped while a client stalled");
    // once it reads again it finds the server closed it
    let end = next_line(&lines);
    assert_eq!(end["closed"], true, "{end}");
    assert!(stalled.wait().expect("client").success());
    let stats = fox.stop();
    assert!(stats.contains("1 client(s) disconnected for not reading"), "{stats}");
}

#[test]
fn parameters_and_publishing_need_the_token_and_go_through_the_router() {
    let r = robot("fxparam");
    let fox = Fox::start(&r, &["--publish"]);
    let with = format!("{}/?token={TOKEN}", fox.url);

    // without the token: read, not changed
    let said = run_client(&["params", &fox.url, "/t1/step", "3", "0"]);
    let p = &said[0];
    assert_eq!(p["serverInfo"]["metadata"]["edit"], "false");
    assert!(!p["serverInfo"]["capabilities"].as_array().expect("caps").contains(&"clientPublish".into()));
    assert_eq!(p["before"]["value"], 1);
    assert!(p["setRefusal"]["message"].as_str().is_some_and(|m| m.contains("edit token")), "{p}");
    assert_eq!(p["after"][0]["value"], 1, "changed without the token");

    // with it: set, and a value the agent refuses refused with its reason
    let said = run_client(&["params", &with, "/t1/step", "3", "0"]);
    let p = &said[0];
    assert_eq!(p["set"][0]["value"], 3, "{p}");
    assert_eq!(p["refusal"]["level"], 2);
    assert!(p["refusal"]["message"].as_str().is_some_and(|m| m.contains("step is in")), "{p}");
    assert_eq!(p["after"][0]["value"], 3);
    assert_eq!(r.ok(&["param", "get", "t1", "step"]).trim(), "3");
    // the subscriber of updates was told of the change
    assert_eq!(p["update"]["parameters"][0], serde_json::json!({ "name": "/t1/step", "value": 3 }), "{p}");

    // a message into r1's input comes out of r1
    let echo = r
        .command("nerve")
        .args(["echo", "r1/out", "--json", "--count", "400", "--timeout", "5"])
        .stdout(Stdio::piped())
        .spawn()
        .expect("nerve echo");
    let said = run_client(&["publish", &with, "/r1/in", r#"{"seq": 777777}"#, "5"]);
    assert!(said[0]["capabilities"].as_array().expect("caps").contains(&"clientPublish".into()));
    assert!(
        said[1]["refusal"]["message"].as_str().is_some_and(|m| m.contains("has no field `nope`")),
        "a message of the wrong shape was not refused: {said:?}"
    );
    let out = echo.wait_with_output().expect("echo");
    let relayed = parse(&String::from_utf8_lossy(&out.stdout));
    let ours = relayed.iter().filter(|e| e["data"]["seq"] == 777777).count();
    assert!(ours >= 1, "no published message came out of r1");
    // without --publish nobody may
    let stats = fox.stop();
    assert!(stats.contains("0 refused"), "{stats}");
    let fox = Fox::start(&r, &[]);
    let said = run_client(&["publish", &format!("{}/?token={TOKEN}", fox.url), "/r1/in", "{}", "0"]);
    assert!(
        said[1]["statuses"].to_string().contains("does not take publishing"),
        "publishing taken without --publish: {said:?}"
    );
}

/// The Topic Graph panel's graph: who feeds whom, following `nerve
/// connect`; then an agent serving `plan` comes (its service advertised with
/// it as provider) and goes (the service named removed).
#[test]
fn the_connection_graph_follows_nerve_connect() {
    let r = robot("fxgraph");
    let fox = Fox::start(&r, &[]);
    let mut watcher = client(&["graph", &fox.url, "/r1/out", "/s/plan"]);
    let lines = lines_of(&mut watcher);
    let first = next_line(&lines);
    let t1 = first["first"]["subscribedTopics"]
        .as_array()
        .and_then(|t| t.iter().find(|t| t["name"] == "/t1/tick"))
        .map(|t| t["subscriberIds"].clone());
    assert_eq!(t1, Some(serde_json::json!(["r1", "r2"])), "{first}");
    r.ok(&["connect", "r1/out", "r2/in"]);
    let changed = next_line(&lines);
    let r1 = changed["changed"]["subscribedTopics"]
        .as_array()
        .and_then(|t| t.iter().find(|t| t["name"] == "/r1/out"))
        .map(|t| t["subscriberIds"].clone());
    assert_eq!(r1, Some(serde_json::json!(["r2"])), "{changed}");
    assert_eq!(changed["changed"]["advertisedServices"], serde_json::json!([]), "the pipeline serves nothing");
    r.ok(&["start", "caller", "--name", "s", "--", "--serve"]);
    let served = next_line(&lines);
    let plan = served["served"]["advertisedServices"]
        .as_array()
        .and_then(|s| s.iter().find(|s| s["name"] == "/s/plan"))
        .map(|s| s["providerIds"].clone());
    assert_eq!(plan, Some(serde_json::json!(["s"])), "{served}");
    r.ok(&["stop", "s"]);
    let removed = next_line(&lines);
    let still =
        removed["removed"]["advertisedServices"].as_array().is_some_and(|s| s.iter().any(|s| s["name"] == "/s/plan"));
    assert!(!still, "/s/plan both advertised and removed: {removed}");
    assert!(watcher.wait().expect("client").success());
}

#[test]
fn subscribe_cycles_leave_the_servers_memory_flat() {
    let r = robot("fxcycle");
    let fox = Fox::start(&r, &[]);
    // the first hundred warm up allocators and the port's first opening
    run_client(&["cycles", &fox.url, "/t1/tick", "100"]);
    let warm = fox.rss_kb();
    run_client(&["cycles", &fox.url, "/t1/tick", "100"]);
    let after = fox.rss_kb();
    assert!(after <= warm + 2048, "100 subscribe/unsubscribe cycles grew nerve foxglove from {warm} kB to {after} kB");
}

#[test]
fn an_idle_server_sleeps_instead_of_looking_at_its_ports() {
    let r = robot("fxidle");
    let fox = Fox::start(&r, &[]);
    // a client connected and subscribed to nothing, while the ticker publishes: nothing to do
    let mut idle = client(&["idle", &fox.url, "4000"]);
    let lines = lines_of(&mut idle);
    assert_eq!(next_line(&lines)["connected"], true);
    let before = fox.sleeps();
    std::thread::sleep(Duration::from_secs(2));
    let woke = fox.sleeps() - before;
    eprintln!("nerve foxglove, idle with a client: {woke} sleeps in 2 s");
    // asleep: the half-second refresh (a router call or two), the client's pings; a 5 ms loop
    // and a 4 ms socket timeout woke it about 900 times in these 2 s
    assert!(woke < 200, "an idle nerve foxglove woke {woke} times in 2 s: something looks on a timer");
    assert_eq!(next_line(&lines)["done"], true);
    assert!(idle.wait().expect("client").success());
    // and it still serves at once
    let seen = run_client(&["watch", &fox.url, "foxglove.sdk.v1", "/t1/tick", "3"]);
    assert_eq!(seen[1]["samples"].as_array().map(Vec::len), Some(3));
}

#[test]
fn a_pose_is_also_a_foxglove_frame_transform() {
    let r = Robot::new("fxpose");
    let file = r.launch_file(
        "pose.toml",
        "robot = \"x\"\n\n[[agent]]\nname = \"odo\"\nkind = \"odometry\"\nargs = [\"--start\", \"1,2,90\"]\n",
    );
    r.ok(&["launch", file.to_str().expect("path")]);
    let fox = Fox::start(&r, &["--publish"]);
    // the motor's odometry, published from Foxglove into the agent's input, moves the pose
    let odom = r#"{"x": 0.5, "y": 0, "theta": 0, "v": 0, "omega": 0}"#;
    let said = run_client(&["drive", &format!("{}/?token={TOKEN}", fox.url), "/odo/odom", odom, "/odo/pose/tf"]);
    let d = &said[0];
    assert_eq!(d["channel"]["schemaName"], "foxglove.FrameTransform", "{d}");
    let schema: Value = serde_json::from_str(d["channel"]["schema"].as_str().expect("schema")).expect("schema JSON");
    assert!(schema["properties"]["translation"].is_object(), "{schema}");
    let m = &d["message"]["data"];
    assert_eq!((m["parent_frame_id"].as_str(), m["child_frame_id"].as_str()), (Some("world"), Some("base_link")));
    // the start pose 1, 2, 90 degrees: a quarter turn about z
    assert_eq!(m["translation"]["z"], 0.0);
    let (x, y) = (m["translation"]["x"].as_f64().expect("x"), m["translation"]["y"].as_f64().expect("y"));
    assert!((x - 1.0).abs() < 1.0 && (y - 2.0).abs() < 1.0, "not near the start pose: {m}");
    let (z, w) = (m["rotation"]["z"].as_f64().expect("z"), m["rotation"]["w"].as_f64().expect("w"));
    assert!((z - w).abs() < 1e-6, "not a quarter turn: {m}");
    assert!(d["statuses"].as_array().is_some_and(Vec::is_empty), "{d}");
}

fn num(v: &Value, k: &str) -> f64 {
    v[k].as_f64().unwrap_or_else(|| panic!("no number {k} in {v}"))
}

/// The heading change from `a` to `b`, in (-pi, pi].
fn turn(a: &Value, b: &Value) -> f64 {
    use std::f64::consts::{PI, TAU};
    (num(b, "theta") - num(a, "theta") + PI).rem_euclid(TAU) - PI
}

/// Foxglove's Teleop panel on `/motor/cmd`: the client advertises a
/// `geometry_msgs/Twist` channel and publishes Twists (0.15 m/s, 0.4 rad/s,
/// 10 a second for 2.5 s) into the motor's `cmd` input of a simulated
/// robot; the simulator's ground truth and the motor's odometry (read with
/// `nerve echo`, and on the client's own subscription) show it went
/// forward and turned left, and the motor's dead man stopped it after.
#[test]
fn a_teleop_twist_published_from_foxglove_moves_the_simulated_robot() {
    let r = Robot::new("fxteleop");
    let world = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("worlds").join("explore.toml");
    let file = r.launch_file(
        "teleop.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "sim"
kind = "sim"
args = ["--world", "{}", "--dev-dir", "{{state}}/dev", "--no-noise", "--no-camera"]
[[agent]]
name = "motor"
kind = "motor"
device = "{{state}}/dev/motor"
args = ["--robot-model", "h1"]
"#,
            world.display()
        ),
    );
    r.ok(&["launch", file.to_str().expect("path")]);
    let fox = Fox::start(&r, &["--publish"]);
    let truth_before = r.echo("sim/truth", 1)[0]["data"].clone();
    let odom_before = r.echo("motor/odom", 1)[0]["data"].clone();

    let url = format!("{}/?token={TOKEN}", fox.url);
    let said = run_client(&["teleop", &url, "/motor/cmd", "0.15", "0.4", "2.5", "/motor/odom"]);
    let t = &said[0];
    assert!(t["statuses"].as_array().is_some_and(Vec::is_empty), "the server refused a Twist: {t}");
    assert!(t["sent"].as_u64().is_some_and(|n| n >= 10), "{t}");
    // what Foxglove's own subscription to the odometry saw
    let (first, last) = (&t["first"], &t["last"]);
    let moved = (num(last, "x") - num(first, "x")).hypot(num(last, "y") - num(first, "y"));
    assert!(moved > 0.1, "Twists of 0.15 m/s for 2.5 s moved the odometry by {moved} m in Foxglove: {t}");
    assert!(turn(first, last) > 0.3, "Twists of 0.4 rad/s for 2.5 s turned the odometry in Foxglove: {t}");

    // the dead man stops the robot once the Twists end
    let mut odom = Value::Null;
    let stopped = wait_until(Duration::from_secs(5), || {
        odom = r.echo("motor/odom", 1)[0]["data"].clone();
        num(&odom, "v").abs() < 1e-6 && num(&odom, "omega").abs() < 1e-6
    });
    assert!(stopped, "the robot did not stop after the last Twist: {odom}");
    // the simulated robot itself moved forward and turned left, and so did its odometry in nerve
    let truth = r.echo("sim/truth", 1)[0]["data"].clone();
    let moved = (num(&truth, "x") - num(&truth_before, "x")).hypot(num(&truth, "y") - num(&truth_before, "y"));
    assert!(moved > 0.1, "the simulated robot moved by {moved} m: {truth_before} -> {truth}");
    assert!(turn(&truth_before, &truth) > 0.3, "the simulated robot did not turn left: {truth_before} -> {truth}");
    assert_eq!(truth["collisions"], 0, "{truth}");
    let moved = (num(&odom, "x") - num(&odom_before, "x")).hypot(num(&odom, "y") - num(&odom_before, "y"));
    assert!(moved > 0.1, "the odometry moved by {moved} m: {odom_before} -> {odom}");
    let stats = fox.stop();
    assert!(stats.contains(" 0 refused"), "{stats}");
}

#[test]
fn a_camera_ring_is_also_a_foxglove_raw_image() {
    let r = Robot::new("fximage");
    r.router();
    r.ok(&["start", "camera", "--name", "cam", "--", "--source", "test-pattern"]);
    let fox = Fox::start(&r, &[]);
    let said = run_client(&["watch", &fox.url, "foxglove.sdk.v1", "/cam/frames/image", "2"]);
    assert_eq!(said[0]["channel"]["schemaName"], "foxglove.RawImage");
    for s in said[1]["samples"].as_array().expect("samples") {
        let img = &s["data"];
        let (w, h, step) = (img["width"].as_u64(), img["height"].as_u64(), img["step"].as_u64());
        let (w, h, step) = (w.expect("width"), h.expect("height"), step.expect("step"));
        assert!(w > 0 && h > 0, "{}", img["encoding"]);
        let bpp = match img["encoding"].as_str() {
            Some("rgb8") => 3,
            Some("mono8") => 1,
            other => panic!("encoding {other:?}"),
        };
        assert_eq!(step, w * bpp);
        // base64 of step * height bytes
        let data = img["data"].as_str().expect("data");
        let pad = data.bytes().rev().take_while(|b| *b == b'=').count() as u64;
        assert_eq!(data.len() as u64 / 4 * 3 - pad, step * h, "the pixels of a {w}x{h} frame");
    }
}

/// The calls test's server (`nerve-caller --serve`: service `plan`, a
/// `nerve::Tick` answered with a `nerve::Scalar` of twice its `seq`) as a
/// Foxglove service: advertised with both JSON Schemas; called with the
/// token (an answer, an unknown field, text that is not JSON, each ended
/// as it should), refused without it and under `--read-only`; a suspended
/// server's call fails on the timeout; a stopped agent's service is
/// unadvertised.
#[test]
fn an_agents_service_is_a_foxglove_service_called_with_the_token() {
    let r = Robot::new("fxcall");
    r.router();
    r.ok(&["start", "caller", "--name", "s", "--", "--serve"]);
    let fox = Fox::start(&r, &["--call-timeout", "0.5"]);
    let with = format!("{}/?token={TOKEN}", fox.url);
    let said = run_client(&["call", &with, "/s/plan", r#"{"seq": 21}"#, r#"{"seq": 1, "sequence": 2}"#, "seq 3"]);
    assert!(said[0]["capabilities"].as_array().expect("caps").contains(&"services".into()), "{}", said[0]);
    let service = &said[0]["service"];
    assert_eq!(service["type"], "call(nerve::Tick -> nerve::Scalar)", "{service}");
    assert_eq!(service["request"]["schemaName"], "nerve::Tick");
    assert_eq!(service["response"]["schemaName"], "nerve::Scalar");
    assert_eq!(service["request"]["encoding"], "json");
    let schema: Value =
        serde_json::from_str(service["request"]["schema"].as_str().expect("schema")).expect("schema JSON");
    assert_eq!(schema["properties"]["seq"]["type"], "integer", "{schema}");
    let schema: Value =
        serde_json::from_str(service["response"]["schema"].as_str().expect("schema")).expect("schema JSON");
    assert_eq!(schema["properties"]["value"]["type"], "number", "{schema}");
    let calls = &said[1]["calls"];
    assert_eq!(calls[0]["encoding"], "json", "{calls}");
    assert_eq!(calls[0]["response"]["value"].as_f64(), Some(42.0), "{calls}");
    assert!(calls[1]["failure"].as_str().is_some_and(|m| m.contains("sequence")), "an unknown field: {calls}");
    assert!(calls[2]["failure"].as_str().is_some_and(|m| m.contains("not JSON")), "not JSON: {calls}");
    // without the token: refused, nothing called
    let answered = r.figure_u64("s", "answered");
    let said = run_client(&["call", &fox.url, "/s/plan", r#"{"seq": 5}"#]);
    let refusal = &said[1]["calls"][0];
    assert!(refusal["failure"].as_str().is_some_and(|m| m.contains("edit token")), "{refusal}");
    assert_eq!(r.figure_u64("s", "answered"), answered, "a call without the token reached the server");
    // a server that does not answer: the call fails on the timeout, saying so
    r.ok(&["suspend", "s"]);
    let said = run_client(&["call", &with, "/s/plan", r#"{"seq": 6}"#]);
    let end = &said[1]["calls"][0];
    assert!(end["failure"].as_str().is_some_and(|m| m.contains("no answer within 500ms")), "{end}");
    r.ok(&["resume", "s"]);
    // a stopped agent takes its service with it
    r.ok(&["stop", "s"]);
    let mut listed = Value::Null;
    let gone = wait_until(Duration::from_secs(10), || {
        listed = run_client(&["services", &fox.url])[0]["services"].clone();
        listed == serde_json::json!([])
    });
    assert!(gone, "/s/plan still advertised after s stopped: {listed}");
    let stats = fox.stop();
    assert!(stats.contains(" 0 refused"), "{stats}");
    // --read-only: advertised, never called
    r.ok(&["start", "caller", "--name", "s", "--", "--serve"]);
    let fox = Fox::start(&r, &["--read-only"]);
    let said = run_client(&["call", &fox.url, "/s/plan", r#"{"seq": 7}"#]);
    let refusal = &said[1]["calls"][0];
    assert!(refusal["failure"].as_str().is_some_and(|m| m.contains("read-only")), "{refusal}");
}

/// The map builder's map (`nerve::MapCells`) as a `foxglove.Grid` on
/// `/mb/map/grid`: a map builder alone, fed poses published from the
/// client into its `pose` input, sends a map whose grid is the one cell
/// the pose is in, marked seen and entered once.
#[test]
fn the_map_builders_map_is_also_a_foxglove_grid() {
    let r = Robot::new("fxgrid");
    r.router();
    r.ok(&["start", "map-builder", "--name", "mb"]);
    let fox = Fox::start(&r, &["--publish"]);
    let pose = r#"{"x": 1.3, "y": -0.7, "theta": 0, "v": 0, "omega": 0, "corrections": 0, "source": 3,
        "last_checkpoint": 0, "reserved": [0, 0]}"#;
    let said = run_client(&["drive", &format!("{}/?token={TOKEN}", fox.url), "/mb/pose", pose, "/mb/map/grid"]);
    let d = &said[0];
    assert_eq!(d["channel"]["schemaName"], "foxglove.Grid", "{d}");
    assert!(d["statuses"].as_array().is_some_and(Vec::is_empty), "{d}");
    let g = &d["message"]["data"];
    assert_eq!(g["frame_id"], "world");
    assert_eq!(
        (g["column_count"].as_u64(), g["cell_stride"].as_u64(), g["row_stride"].as_u64()),
        (Some(1), Some(2), Some(2))
    );
    let cell = num(&g["cell_size"], "x");
    assert!(cell > 0.0 && cell == num(&g["cell_size"], "y"), "{g}");
    let (x0, y0) = (num(&g["pose"]["position"], "x"), num(&g["pose"]["position"], "y"));
    assert!((x0..x0 + cell).contains(&1.3) && (y0..y0 + cell).contains(&-0.7), "the cell of (1.3, -0.7)? {g}");
    // one cell, seen and entered once: the bytes 1, 1 in base64
    assert_eq!(g["data"], "AQE=", "the one cell is not marked seen, entered once: {g}");
}

/// Every topic a panel of `docs/foxglove/explore.json` reads, without a
/// plot's field path, and every topic one publishes on.
fn layout_topics(v: &Value, out: &mut Vec<String>, publish: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                if k == "topics" {
                    out.extend(x.as_object().into_iter().flat_map(|t| t.keys().cloned()));
                }
                if let ("imageTopic" | "topicPath" | "value", Some(t)) = (k.as_str(), x.as_str()) {
                    out.push(t.split('.').next().unwrap_or(t).to_owned());
                }
                if let ("topic", Some(t)) = (k.as_str(), x.as_str()) {
                    publish.push(t.to_owned());
                }
                layout_topics(x, out, publish);
            }
        }
        Value::Array(a) => a.iter().for_each(|x| layout_topics(x, out, publish)),
        _ => {}
    }
}

#[test]
fn the_explore_layout_names_only_ports_of_the_explore_robot() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let layout: Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("docs/foxglove/explore.json")).expect("layout"))
            .expect("the layout is JSON");
    // the output ports of launch/explore.toml: those its connections start from, and those its
    // agents' kinds declare (the map builder's map, which no agent reads but a viewer)
    let launch = std::fs::read_to_string(root.join("launch/explore.toml")).expect("launch file");
    let mut outputs: Vec<String> = launch
        .lines()
        .filter_map(|l| l.trim().strip_prefix("from = \""))
        .filter_map(|l| l.strip_suffix('"'))
        .map(str::to_owned)
        .collect();
    let declared = |agent: &str| -> Vec<String> {
        let described = Command::new(bin_dir().join(format!("nerve-{agent}"))).arg("--describe").output();
        let described = described.unwrap_or_else(|e| panic!("nerve-{agent} --describe: {e}"));
        let d: Value = serde_json::from_slice(&described.stdout).expect("a description");
        let names = d["outputs"].as_array().into_iter().flatten().filter_map(|o| o["name"].as_str());
        names.map(|o| format!("{agent}/{o}")).collect()
    };
    assert!(launch.contains("kind = \"map-builder\""), "the explore robot has a map builder");
    outputs.extend(declared("map-builder"));
    let inputs: Vec<&str> =
        launch.lines().filter_map(|l| l.trim().strip_prefix("to = \"")).filter_map(|l| l.strip_suffix('"')).collect();
    let (mut topics, mut publish) = (Vec::new(), Vec::new());
    layout_topics(&layout, &mut topics, &mut publish);
    assert_eq!(publish, ["/motor/cmd"], "the Teleop panel drives the motor");
    for t in &publish {
        assert!(inputs.contains(&t.trim_start_matches('/')), "{t} is no input port of launch/explore.toml");
    }
    assert!(topics.len() >= 6, "{topics:?}");
    for t in &topics {
        let parts: Vec<&str> = t.trim_start_matches('/').split('/').collect();
        let port = parts[..2.min(parts.len())].join("/");
        assert!(outputs.contains(&port), "{t}: {port} is no output port of launch/explore.toml");
        if let Some(suffix) = parts.get(2) {
            assert!(
                ["tf", "scan", "image", "grid"].contains(suffix),
                "{t}: no channel of nerve foxglove ends in {suffix}"
            );
        }
    }
}
