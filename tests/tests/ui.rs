//! `nerve ui` in a real browser (issue 16): headless Chromium loads the page
//! of a robot started from `launch/pipeline.toml`, finds its agents and
//! edges, disconnects and connects by page actions (checked with `nerve
//! graph --json`), is refused a connection of the wrong type with the
//! router's message, hot-adds and kills an agent, watches a supervised
//! agent being killed and restarted, and reads a port's samples. A
//! read-only server offers no action, and an action without the token is
//! refused.
//!
//! And the page closed to everyone else (issue 40, review findings B3, B4,
//! B10, B11), over real HTTP on loopback: every `/api/*` route needs a
//! token (the read token watches, the edit token acts), a wrong `Host` or
//! a foreign `Origin` is refused, hot add takes only known kinds, another
//! uid gets nothing, no token is on any command line, and oversized,
//! idle and surplus connections are refused while the server stays up.

use nerve_tests::browser::{Browser, http};
use nerve_tests::{Robot, wait_until};
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Stdio};
use std::time::Duration;

const TOKEN: &str = "test-token-0123456789abcdef";
const READ: &str = "test-read-token-0123456789";
const WAIT: Duration = Duration::from_secs(20);

/// A running `nerve ui`; stopped with Ctrl-C (SIGINT) when dropped.
struct Ui {
    child: Child,
    addr: String,
}

impl Ui {
    /// Started with the tokens [`TOKEN`] and [`READ`] in its environment.
    fn start(r: &Robot, extra: &[&str]) -> Ui {
        let mut cmd = r.command("nerve");
        cmd.env("NERVE_UI_TOKEN", TOKEN).env("NERVE_UI_READ_TOKEN", READ);
        Ui::start_with(cmd, extra)
    }

    fn start_with(mut cmd: std::process::Command, extra: &[&str]) -> Ui {
        let mut child = cmd
            .args(["ui", "--bind", "127.0.0.1:0", "--interval", "0.25"])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("run nerve ui");
        let mut stdout = BufReader::new(child.stdout.take().expect("stdout"));
        let mut first = String::new();
        stdout.read_line(&mut first).expect("read the address");
        // the rest of what it says goes to the test's output
        std::thread::spawn(move || stdout.lines().map_while(Result::ok).for_each(|l| eprintln!("nerve ui: {l}")));
        let addr = first
            .split("http://")
            .nth(1)
            .and_then(|rest| rest.split('/').next())
            .unwrap_or_else(|| panic!("nerve ui printed no address: {first:?}"))
            .to_owned();
        Ui { child, addr }
    }

    fn url(&self, token: Option<&str>) -> String {
        match token {
            Some(t) => format!("http://{}/?token={t}", self.addr),
            None => format!("http://{}/", self.addr),
        }
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Stops it with SIGINT and checks that it ended cleanly.
    fn stop(mut self) {
        let pid = nix::unistd::Pid::from_raw(i32::try_from(self.child.id()).expect("pid"));
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).expect("SIGINT");
        let ok = wait_until(Duration::from_secs(10), || self.child.try_wait().ok().flatten().is_some());
        assert!(ok, "nerve ui did not stop within 10 s of Ctrl-C");
        let status = self.child.try_wait().ok().flatten().expect("status");
        assert!(status.success(), "nerve ui ended with {status} after Ctrl-C");
    }
}

impl Drop for Ui {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn edges(r: &Robot) -> Vec<(String, String)> {
    r.graph()["connections"]
        .as_array()
        .cloned()
        .unwrap_or_default()
        .iter()
        .map(|c| (c["from"].as_str().unwrap_or("").to_owned(), c["to"].as_str().unwrap_or("").to_owned()))
        .collect()
}

fn has_edge(r: &Robot, from: &str, to: &str) -> bool {
    edges(r).iter().any(|(f, t)| f == from && t == to)
}

const PAGE_AGENTS: &str = "[...document.querySelectorAll('.node')].map(n => n.dataset.agent).sort().join(',')";
const PAGE_EDGES: &str =
    "[...document.querySelectorAll('.edge')].map(e => e.dataset.from + '->' + e.dataset.to).sort().join(',')";

fn node_state(b: &Browser, agent: &str) -> Value {
    b.eval(&format!(
        "const n = document.querySelector('.node[data-agent=\"{agent}\"]'); return n ? n.querySelector('text.state').textContent : null"
    ))
}

fn toast(b: &Browser) -> String {
    b.eval("const t = document.getElementById('toast'); return t.hidden ? '' : t.textContent")
        .as_str()
        .unwrap_or("")
        .to_owned()
}

fn pipeline() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("launch").join("pipeline.toml")
}

#[test]
fn the_page_shows_and_rewires_a_running_robot() {
    let r = Robot::new("ui");
    r.ok(&["launch", pipeline().to_str().expect("path")]);
    let ui = Ui::start(&r, &[]);
    let b = Browser::start();
    b.open(&ui.url(Some(TOKEN)));

    // the agents and edges of launch/pipeline.toml
    b.wait_for("the three agents", WAIT, &format!("const a = {PAGE_AGENTS}; return a === 'r1,r2,t1' && a"));
    b.wait_for(
        "the two edges",
        WAIT,
        &format!("const e = {PAGE_EDGES}; return e === 't1/tick->r1/in,t1/tick->r2/in' && e"),
    );
    assert_eq!(b.eval("return nerveUi.editable"), Value::Bool(true));
    // the edges carry their live figures
    b.wait_for("a live rate on an edge", WAIT, "const t = document.querySelector('.edge-label[data-to=\"r1/in\"]').textContent; return /^(9\\d|10\\d)\\.\\d Hz/.test(t) && t");

    // disconnect: select the edge, press Delete
    b.click(".edge[data-to=\"r1/in\"] path.hit");
    b.wait_for("the edge selected", WAIT, "return !document.getElementById('edge-panel').hidden");
    b.key("\u{E017}");
    assert!(wait_until(WAIT, || !has_edge(&r, "t1/tick", "r1/in")), "the router still has t1/tick -> r1/in");
    b.wait_for("the edge gone", WAIT, "return !document.querySelector('.edge[data-to=\"r1/in\"]')");

    // connect: drag the output port onto the input port
    b.drag(".port[data-port=\"t1/tick\"] circle", ".port[data-port=\"r1/in\"] circle");
    assert!(
        wait_until(WAIT, || has_edge(&r, "t1/tick", "r1/in")),
        "the router did not connect t1/tick -> r1/in; page said {:?}",
        toast(&b)
    );
    b.wait_for("the edge back", WAIT, "return !!document.querySelector('.edge[data-to=\"r1/in\"]')");

    // a node dragged by its name moves, and stays where it was put
    let at =
        |b: &Browser| b.eval("return document.querySelector('.node[data-agent=\"r2\"]').getAttribute('transform')");
    let before = at(&b);
    b.drag_by(".node[data-agent=\"r2\"] text.name", 0, 160); // down, into empty space
    let moved = at(&b);
    assert_ne!(moved, before, "r2 did not move");
    std::thread::sleep(Duration::from_millis(700));
    assert_eq!(at(&b), moved, "r2 went back to the automatic layout");

    // hot add from the page: an agent with an input of another type
    b.eval("document.getElementById('add-kind').value = 'gripper'; document.getElementById('add-name').value = 'g1'; return 1");
    b.click("#add-go");
    b.wait_for("the added agent", WAIT, "return !!document.querySelector('.port[data-port=\"g1/cmd\"]')");
    assert!(r.agent("g1").is_some(), "the router has no g1");

    // while dragging, ports of another type are dimmed; the router's refusal is shown
    b.press_on(".port[data-port=\"t1/tick\"] circle");
    let dim = b.eval("return [...document.querySelectorAll('.port.in.dim')].map(p => p.dataset.port).sort().join(',')");
    let fit = b.eval("return [...document.querySelectorAll('.port.in.fit')].map(p => p.dataset.port).sort().join(',')");
    assert_eq!(dim, "g1/cmd", "dimmed while dragging t1/tick");
    assert_eq!(fit, "r1/in,r2/in", "offered while dragging t1/tick");
    b.release_on(".port[data-port=\"g1/cmd\"] circle");
    let said = b.wait_for("the router's refusal", WAIT, "const t = document.getElementById('toast'); return !t.hidden && t.classList.contains('error') && t.textContent");
    assert!(
        said.as_str().is_some_and(|s| s.contains("t1/tick sends nerve::Tick but g1/cmd takes acme::Gripper")),
        "the page did not show the router's message: {said}"
    );
    assert!(!has_edge(&r, "t1/tick", "g1/cmd"));

    // kill the added agent from its panel: it disappears
    b.click(".node[data-agent=\"g1\"] text.name");
    b.wait_for("g1's panel", WAIT, "return document.getElementById('agent-title').textContent === 'g1'");
    b.click("#agent-panel [data-action=kill]");
    b.wait_for("g1 gone", WAIT, "return !document.querySelector('.node[data-agent=\"g1\"]')");
    assert!(wait_until(WAIT, || r.agent("g1").is_none()), "the router still lists g1");

    // a supervised agent killed from the command line: shown restarting (or gone), then back with a restart
    let pid = r.pid("r2");
    r.ok(&["kill", "r2"]);
    b.wait_for("r2 killed", WAIT, "const n = document.querySelector('.node[data-agent=\"r2\"]'); return !n || n.classList.contains('restarting') || n.classList.contains('unresponsive')");
    b.wait_for("r2 restarted", WAIT, "const n = document.querySelector('.node[data-agent=\"r2\"]'); return !!n && n.classList.contains('running') && /restarts 1/.test(n.querySelector('text.figures').textContent)");
    assert_ne!(r.pid("r2"), pid);
    assert_eq!(node_state(&b, "r2"), Value::String("running".into()));

    // suspend and a parameter from t1's panel
    b.click(".node[data-agent=\"t1\"] text.name");
    b.wait_for("t1's panel", WAIT, "return document.getElementById('agent-title').textContent === 't1'");
    b.click("#agent-panel [data-action=suspend]");
    b.wait_for(
        "t1 suspended",
        WAIT,
        "return document.querySelector('.node[data-agent=\"t1\"]').classList.contains('suspended')",
    );
    assert_eq!(r.agent("t1").expect("t1")["state"], "suspended");
    b.click("#agent-panel [data-action=resume]");
    b.wait_for(
        "t1 running",
        WAIT,
        "return document.querySelector('.node[data-agent=\"t1\"]').classList.contains('running')",
    );
    b.click("#params-load");
    b.wait_for("t1's parameters", WAIT, "return !!document.querySelector('#params input[data-param=\"step\"]')");
    b.eval("document.querySelector('#params input[data-param=\"step\"]').value = '7'; return 1");
    b.click("#params input[data-param=\"step\"] + button");
    assert!(wait_until(WAIT, || r.ok(&["param", "get", "t1", "step"]).trim() == "7"), "step was not set to 7");

    // looking inside a port: its latest sample field by field, and a plot
    b.click(".port[data-port=\"r1/out\"] circle");
    b.wait_for("a decoded sample", WAIT, "return document.querySelectorAll('#sample tr').length > 1");
    b.wait_for("a plotted field", WAIT, "return document.getElementById('plot-field').options.length > 0");
    assert_eq!(b.eval("return document.getElementById('port-type').textContent"), Value::String("nerve::Tick".into()));

    let png = b.screenshot();
    assert!(png.starts_with(b"\x89PNG"), "the screenshot is not a PNG");
    std::fs::write(PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("nerve-ui.png"), &png).expect("write screenshot");

    // the page drew every update without an error; how long a draw of 100 agents takes
    assert_eq!(b.eval("return nerveUi.errors.join('; ')"), Value::String(String::new()));
    let ms = b.eval(HUNDRED_AGENTS);
    eprintln!("drawing 100 agents and 150 connections: {ms} ms per update (median of 20)");
    assert!(ms.as_f64().is_some(), "no draw time: {ms}");

    drop(b);
    ui.stop();
    r.down_and_check_clean();
}

/// Draws a graph of 100 agents (a ticker and 99 relays in chains, 150
/// connections) 20 times with changing figures; returns the median ms.
const HUNDRED_AGENTS: &str = r#"
nerveUi.source.close();
const port = (name, type_name) => ({ name, type_name, fingerprint: 1 });
const agents = [], connections = [];
for (let i = 0; i < 100; i++) {
  agents.push({ name: `a${i}`, pid: 1000 + i, kind: i ? 'relay' : 'ticker', state: 'running', task: i ? 'event-driven' : 'periodic',
    period_ns: i ? null : 10000000, inputs: i ? [port('in', 'nerve::Tick'), port('aux', 'nerve::Tick')] : [],
    outputs: [port('out', 'nerve::Tick')], restarts: 0, stats: { rate_hz: 100, cpu_percent: 0.5, rss_bytes: 1 << 20, cycles: 1, overruns: 0 } });
  if (i) connections.push({ from: `a${Math.floor((i - 1) / 2)}/out`, to: `a${i}/in`, type_name: 'nerve::Tick', active: true, rate_hz: 100, last_age_ms: 3, received: 1, dropped: 0 });
  if (i > 50) connections.push({ from: `a${i - 50}/out`, to: `a${i}/aux`, type_name: 'nerve::Tick', active: true, rate_hz: 100, last_age_ms: 3, received: 1, dropped: 0 });
}
const times = [];
for (let k = 0; k < 20; k++) {
  for (const c of connections) c.rate_hz = 90 + k;
  const t0 = performance.now();
  update({ seq: 100000 + k, unix_ms: Date.now(), graph: { agents, connections } });
  document.body.getBoundingClientRect();
  times.push(performance.now() - t0);
}
times.sort((a, b) => a - b);
return times[10];
"#;

#[test]
fn read_only_offers_nothing_and_actions_need_the_token() {
    let r = Robot::new("uiro");
    r.ok(&["launch", pipeline().to_str().expect("path")]);
    let ro = Ui::start(&r, &["--read-only"]);
    let rw = Ui::start(&r, &[]);

    // no token: refused, and nothing changed
    let connect = r#"{"op":"disconnect","from":"t1/tick","to":"r1/in"}"#;
    let (status, body) = http(&rw.addr, "POST", "/api/action", &[], Some(connect));
    assert_eq!(status, 401, "{body}");
    assert!(body.contains("token"), "{body}");
    let (status, _) =
        http(&rw.addr, "POST", "/api/action", &[("X-Nerve-Token", "wrong-token-000000000000")], Some(connect));
    assert_eq!(status, 401);
    assert!(has_edge(&r, "t1/tick", "r1/in"));
    // read-only: refused even with the token
    let (status, body) = http(&ro.addr, "POST", "/api/action", &[("X-Nerve-Token", TOKEN)], Some(connect));
    assert_eq!(status, 403, "{body}");
    assert!(has_edge(&r, "t1/tick", "r1/in"));
    // a bad action is refused with what is wrong
    let (status, body) =
        http(&rw.addr, "POST", "/api/action", &[("X-Nerve-Token", TOKEN)], Some(r#"{"op":"explode"}"#));
    assert_eq!(status, 400, "{body}");
    // with the token it is done
    let (status, body) = http(&rw.addr, "POST", "/api/action", &[("X-Nerve-Token", TOKEN)], Some(connect));
    assert_eq!(status, 200, "{body}");
    assert!(!has_edge(&r, "t1/tick", "r1/in"));

    // the read-only page shows the graph and offers no action
    let b = Browser::start();
    b.open(&ro.url(Some(READ)));
    b.wait_for("the agents", WAIT, &format!("const a = {PAGE_AGENTS}; return a === 'r1,r2,t1' && a"));
    assert_eq!(b.eval("return nerveUi.editable"), Value::Bool(false));
    let visible = "return [...document.querySelectorAll('button, input, select')].filter(e => e.offsetParent !== null && e.id !== 'params-load' && e.id !== 'plot-field').map(e => e.textContent || e.id)";
    b.click(".node[data-agent=\"t1\"] text.name");
    b.wait_for("t1's panel", WAIT, "return document.getElementById('agent-title').textContent === 't1'");
    assert_eq!(b.eval(visible), Value::Array(vec![]), "a read-only page offers actions");
    // dragging from an output does not connect
    b.drag(".port[data-port=\"t1/tick\"] circle", ".port[data-port=\"r1/in\"] circle");
    std::thread::sleep(Duration::from_millis(500));
    assert!(!has_edge(&r, "t1/tick", "r1/in"));
    // a port carrying ring notices shows its image (watching needs no token)
    r.ok(&["start", "camera", "--name", "cam", "--", "--source", "test-pattern", "--width", "160", "--height", "120"]);
    b.wait_for("the camera", WAIT, "return !!document.querySelector('.port[data-port=\"cam/frames\"]')");
    b.click(".port[data-port=\"cam/frames\"] circle");
    let size = b.wait_for(
        "the camera's frame",
        WAIT,
        "const i = document.getElementById('port-image'); return !i.hidden && i.complete && i.naturalWidth > 0 && i.naturalWidth + 'x' + i.naturalHeight",
    );
    assert_eq!(size, Value::String("160x120".into()));
    assert_eq!(
        b.eval("return document.getElementById('port-type').textContent"),
        Value::String("nerve::RingNotice".into())
    );
    let (status, _) = http(&ro.addr, "GET", "/api/image?port=cam%2Fframes", &[], None);
    assert_eq!(status, 401, "an image without the token");
    let (status, png) = http(&ro.addr, "GET", "/api/image?port=cam%2Fframes", &[("X-Nerve-Token", READ)], None);
    assert_eq!(status, 200);
    assert!(png.get(1..4) == Some("PNG") || png.starts_with("\u{FFFD}PNG"), "not a PNG");
    let (status, body) = http(&ro.addr, "GET", "/api/image?port=t1%2Ftick", &[("X-Nerve-Token", READ)], None);
    assert_eq!(status, 409, "{body}");
    assert!(body.contains("not ring notices"), "{body}");
    sequence_port(&r, &ro.addr, &b);
    call_edge(&r, &b);
    // the editing server's page opened with the read token watches only; the token left the address bar
    b.open(&rw.url(Some(READ)));
    b.wait_for("the agents", WAIT, &format!("const a = {PAGE_AGENTS}; return a === 'cam,det,r1,r2,t1' && a"));
    assert_eq!(b.eval("return nerveUi.editable"), Value::Bool(false));
    assert_eq!(b.eval("return document.getElementById('mode').textContent"), Value::String("watching".into()));
    assert_eq!(b.eval("return location.search"), Value::String(String::new()));
    // opened without a token, the page gets nothing and says why
    b.eval("sessionStorage.clear(); return 1");
    let other = Ui::start(&r, &[]);
    b.open(&other.url(None));
    let said = b.wait_for(
        "the refusal",
        WAIT,
        "const s = document.getElementById('status').textContent; return /token/.test(s) && s",
    );
    assert!(said.as_str().is_some_and(|s| s.contains("?token=")), "{said}");
    assert_eq!(b.eval("return document.querySelectorAll('.node').length"), Value::from(0));
    other.stop();

    drop(b);
    ro.stop();
    rw.stop();
    r.down_and_check_clean();
}

/// A call on the page (issue 42): a client wired to a service is an edge
/// from the service, drawn on its agent's right among the outputs, to the
/// client, on the left among the inputs, both marked as call ports.
fn call_edge(r: &Robot, b: &Browser) {
    r.ok(&["start", "caller", "--name", "srv", "--", "--serve"]);
    r.ok(&["start", "caller", "--name", "asker"]);
    r.ok(&["connect", "asker/planner", "srv/plan"]);
    b.wait_for(
        "the call's edge",
        WAIT,
        "const e = document.querySelector('.edge[data-from=\"srv/plan\"][data-to=\"asker/planner\"]'); \
         return !!e && e.style.display !== 'none' \
           && !!document.querySelector('.port.out.call.service[data-port=\"srv/plan\"]') \
           && !!document.querySelector('.port.in.call.client[data-port=\"asker/planner\"]')",
    );
    r.ok(&["stop", "asker"]);
    r.ok(&["stop", "srv"]);
}

/// Looking inside a sequence port (issue 42): the `detector` test agent
/// sends 0, 1, 400 and 401 detections in turn (detection `j` at `x = j`,
/// `id = j`). `/api/samples` gives each sample's header, length, at most
/// 50 elements and its last; the page shows the header, the length, the
/// elements as a table of the first 50 rows "and K more", an empty table for
/// a sample of none, and plots the last element's `x`.
fn sequence_port(r: &Robot, addr: &str, b: &Browser) {
    const ROWS: u64 = 50;
    r.ok(&["start", "detector", "--name", "det"]);
    b.wait_for("the detector", WAIT, "return !!document.querySelector('.port[data-port=\"det/dets\"]')");
    b.click(".port[data-port=\"det/dets\"] circle");
    let mut lens = std::collections::BTreeSet::new();
    let t0 = std::time::Instant::now();
    while lens.len() < 4 && t0.elapsed() < WAIT {
        let (status, body) = http(addr, "GET", "/api/samples?port=det%2Fdets", &[("X-Nerve-Token", READ)], None);
        assert_eq!(status, 200, "{body}");
        let v: Value = serde_json::from_str(&body).expect("the answer is JSON");
        assert_eq!(v["sequence"]["rows"], ROWS, "{}", v["sequence"]);
        for s in v["samples"].as_array().expect("samples") {
            let len = s["len"].as_u64().unwrap_or_else(|| panic!("no length: {s}"));
            assert_eq!(s["value"]["header"]["count"].as_u64(), Some(len), "{}", s["value"]["header"]);
            let items = s["value"]["items"].as_array().expect("items");
            assert_eq!(items.len() as u64, len.min(ROWS), "sample of {len}");
            assert!(items.iter().enumerate().all(|(j, d)| d["id"].as_u64() == Some(j as u64)), "{s}");
            match len.checked_sub(1) {
                Some(j) => assert_eq!((s["last"]["id"].as_u64(), s["last"]["x"].as_f64()), (Some(j), Some(j as f64))),
                None => assert_eq!(s["last"], Value::Null, "an empty sample has no last element"),
            }
            lens.insert(len);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(lens.into_iter().collect::<Vec<_>>(), [0, 1, 400, 401], "the lengths seen by the page's API");
    let (_, body) = http(addr, "GET", "/api/samples?port=det%2Fdets", &[("X-Nerve-Token", READ)], None);
    let v: Value = serde_json::from_str(&body).expect("json");
    assert_eq!(v["sequence"]["longest"], 401, "{}", v["sequence"]);

    // the page: the type, the header and the length; 50 rows and how many more; empty, not an error
    assert_eq!(
        b.eval("return document.getElementById('port-type').textContent"),
        Value::String("nerve::Seq<acme::Detection, acme::DetectionsHeader>".into())
    );
    let note = b.wait_for(
        "a table of the first 50 rows",
        WAIT,
        "const n = document.getElementById('items-note').textContent; \
         return document.querySelectorAll('#items tbody tr').length === 50 && /and 35[01] more/.test(n) && n",
    );
    assert!(note.as_str().is_some_and(|n| n.starts_with("elements 0-49 of 40")), "{note}");
    let head = b.eval("return [...document.querySelectorAll('#items thead th')].map(t => t.textContent).join(',')");
    assert_eq!(head, Value::String("#,x,y,id".into()));
    b.wait_for(
        "a sample's header and length",
        WAIT,
        "const t = document.getElementById('sample').textContent; return /header\\.frame/.test(t) && /length/.test(t)",
    );
    b.wait_for(
        "an empty table for a sample of none",
        WAIT,
        "return !document.getElementById('items').hidden && document.querySelectorAll('#items tbody tr').length === 0 \
         && document.getElementById('items-note').textContent === 'no elements in this sample'",
    );
    // the last element's x, plotted as `nerve plot --field items[-1].x` would (no point for an empty sample)
    b.wait_for(
        "items[-1].x offered",
        WAIT,
        "return [...document.getElementById('plot-field').options].some(o => o.textContent === 'items[-1].x')",
    );
    b.eval("const s = document.getElementById('plot-field'); s.value = 'items[-1].x'; s.dispatchEvent(new Event('change')); return 1");
    let ys = b.wait_for(
        "a plot of items[-1].x",
        WAIT,
        "return nerveUi.plotted.length > 3 && nerveUi.plotted.map(p => p[1])",
    );
    let ys: Vec<f64> = ys.as_array().expect("values").iter().filter_map(Value::as_f64).collect();
    assert!(ys.iter().all(|y| [0.0, 399.0, 400.0].contains(y)), "plotted {ys:?}");
    assert_eq!(b.eval("return nerveUi.errors.join('; ')"), Value::String(String::new()));
}

/// Every route of the API, as (method, target, body).
const API: [(&str, &str, Option<&str>); 7] = [
    ("GET", "/api/info", None),
    ("GET", "/api/graph", None),
    ("GET", "/api/events", None),
    ("GET", "/api/kinds", None),
    ("GET", "/api/samples?port=t1%2Ftick", None),
    ("GET", "/api/image?port=t1%2Ftick", None),
    ("POST", "/api/action", Some(r#"{"op":"suspend","name":"t1"}"#)),
];

/// Sends `raw` and returns the status of the answer and whether the
/// connection was then closed (read until EOF, at most 20 s).
fn raw_request(addr: &str, raw: &[u8]) -> (u16, String) {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(20))).expect("timeout");
    let _ = s.write_all(raw);
    let mut got = Vec::new();
    let _ = s.read_to_end(&mut got);
    let text = String::from_utf8_lossy(&got).into_owned();
    let status = text.split_whitespace().nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    (status, text)
}

/// The status of a request whose answer may never end (an event stream):
/// only the head is read.
fn status_of(addr: &str, method: &str, target: &str, headers: &[(&str, &str)], body: Option<&str>) -> u16 {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(20))).expect("timeout");
    let body = body.unwrap_or("");
    let mut req = format!("{method} {target} HTTP/1.1\r\nContent-Length: {}\r\n", body.len());
    if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
        req.push_str(&format!("Host: {addr}\r\n"));
    }
    for (k, v) in headers {
        req.push_str(&format!("{k}: {v}\r\n"));
    }
    req.push_str("\r\n");
    req.push_str(body);
    s.write_all(req.as_bytes()).expect("send");
    let mut head = [0u8; 12];
    s.read_exact(&mut head).expect("the status line");
    String::from_utf8_lossy(&head[9..12]).parse().unwrap_or(0)
}

/// Every `/api/*` route needs a token; the read token watches and cannot
/// act; the edit token acts; hot add takes known kinds only; a wrong
/// `Host` or a foreign `Origin` is refused even with the token; no token
/// is on any command line; another uid cannot read the token file and
/// gets nothing; `--token` and a token file others can read are refused.
#[test]
fn the_api_needs_a_token_and_answers_only_this_host() {
    let r = Robot::new("uitok");
    r.ok(&["launch", pipeline().to_str().expect("path")]);
    // the tokens in a file only we can read
    let file = r.home.join("ui-tokens");
    std::fs::write(&file, format!("{TOKEN}\n{READ}\n")).expect("token file");
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600)).expect("chmod");
    let mut cmd = r.command("nerve");
    cmd.env_remove("NERVE_UI_TOKEN").env_remove("NERVE_UI_READ_TOKEN");
    let ui = Ui::start_with(cmd, &["--token-file", file.to_str().expect("path")]);
    let addr = ui.addr.clone();

    for (method, target, body) in API {
        assert_eq!(status_of(&addr, method, target, &[], body), 401, "{method} {target} without a token");
        let wrong = [("X-Nerve-Token", "wrong-token-000000000000")];
        assert_eq!(status_of(&addr, method, target, &wrong, body), 401, "{method} {target} with a wrong token");
        let cookie = format!("nerve_ui_{}={TOKEN}", addr.rsplit(':').next().expect("port"));
        let edit_cookie = [("Cookie", cookie.as_str())];
        assert_eq!(
            status_of(&addr, method, target, &edit_cookie, body),
            401,
            "{method} {target}: the edit token in a cookie"
        );
        let host = [("Host", "evil.example:80"), ("X-Nerve-Token", TOKEN)];
        assert_eq!(status_of(&addr, method, target, &host, body), 403, "{method} {target} with a foreign Host");
        let origin = [("Origin", "http://evil.example"), ("X-Nerve-Token", TOKEN)];
        assert_eq!(status_of(&addr, method, target, &origin, body), 403, "{method} {target} from a foreign Origin");
    }
    assert!(r.agent("t1").expect("t1")["state"] == "running", "t1 was suspended without the token");
    // watching with the read token, in the header or in the page's cookie
    let read = [("X-Nerve-Token", READ)];
    for (method, target, _) in API.iter().filter(|(m, ..)| *m == "GET") {
        let status = status_of(&addr, method, target, &read, None);
        assert!(
            status == 200 || (status == 409 && target.starts_with("/api/image")),
            "{target} with the read token: {status}"
        );
    }
    let cookie = format!("nerve_ui_{}={READ}", addr.rsplit(':').next().expect("port"));
    assert_eq!(status_of(&addr, "GET", "/api/events", &[("Cookie", cookie.as_str())], None), 200);
    let (status, graph) = http(&addr, "GET", "/api/graph", &read, None);
    assert_eq!(status, 200);
    assert!(graph.contains("\"t1\""), "{graph}");
    let (status, info) = http(&addr, "GET", "/api/info", &read, None);
    assert_eq!((status, info.contains("\"editable\":false")), (200, true), "{info}");
    // ...but not acting
    let suspend = r#"{"op":"suspend","name":"t1"}"#;
    let (status, body) = http(&addr, "POST", "/api/action", &read, Some(suspend));
    assert_eq!(status, 403, "{body}");
    assert_eq!(r.agent("t1").expect("t1")["state"], "running");
    // acting with the edit token, from this page's own origin
    let edit = [("X-Nerve-Token", TOKEN), ("Origin", &format!("http://{addr}"))];
    let (status, body) = http(&addr, "POST", "/api/action", &edit, Some(suspend));
    assert_eq!(status, 200, "{body}");
    assert_eq!(r.agent("t1").expect("t1")["state"], "suspended");
    let (status, _) = http(&addr, "POST", "/api/action", &edit, Some(r#"{"op":"resume","name":"t1"}"#));
    assert_eq!(status, 200);
    // hot add: only kinds the robot knows, never a path
    for (kind, says) in
        [("/bin/true", "not paths"), ("../nerve-ticker", "not paths"), ("no-such-kind", "unknown agent kind")]
    {
        let start = format!(r#"{{"op":"start","kind":"{kind}","name":"x1"}}"#);
        let (status, body) = http(&addr, "POST", "/api/action", &edit, Some(&start));
        assert_eq!(status, 400, "{kind}: {body}");
        assert!(body.contains(says), "{kind}: {body}");
    }
    assert!(r.agent("x1").is_none());
    let (status, body) =
        http(&addr, "POST", "/api/action", &edit, Some(r#"{"op":"start","kind":"ticker","name":"x2"}"#));
    assert_eq!(status, 200, "{body}");
    assert!(r.agent("x2").is_some());

    // no token on any command line (nerve ui's, the agents' it started, anyone's)
    for entry in std::fs::read_dir("/proc").expect("/proc").filter_map(Result::ok) {
        if let Ok(cmdline) = std::fs::read(entry.path().join("cmdline")) {
            let cmdline = String::from_utf8_lossy(&cmdline);
            assert!(!cmdline.contains(TOKEN) && !cmdline.contains(READ), "a token in {:?}: {cmdline}", entry.path());
        }
    }
    // nor in the environment of the agent the page started
    let environ = std::fs::read(format!("/proc/{}/environ", r.pid("x2"))).expect("environ of x2");
    assert!(!String::from_utf8_lossy(&environ).contains(TOKEN), "the agent inherited the token");

    // another uid on the host: cannot read the token file, and without it gets nothing
    other_uid_gets_nothing(&file, &addr, ui.pid());

    // a token on the command line, or in a file others can read, is refused
    let out = r.nerve(&["ui", "--bind", "127.0.0.1:0", "--token", "abcdefghijklmnopqrstuvwxyz"]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && said.contains("NERVE_UI_TOKEN") && said.contains("--token-file"), "{said}");
    std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o644)).expect("chmod");
    let out = r.nerve(&["ui", "--bind", "127.0.0.1:0", "--token-file", file.to_str().expect("path")]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && said.contains("chmod 600"), "{said}");

    ui.stop();
    r.down_and_check_clean();
}

/// A throw-away uid (`setpriv`, as tests/tests/users.rs does; needs root,
/// else it says so and returns): it cannot read the token file, nor `nerve
/// ui`'s environment, and every route of the API answers it 401.
fn other_uid_gets_nothing(token_file: &std::path::Path, addr: &str, ui_pid: u32) {
    let setpriv = std::process::Command::new("setpriv").arg("--version").output().is_ok();
    if !nix::unistd::geteuid().is_root() || !setpriv {
        eprintln!("not run: switching to a throw-away uid needs root and setpriv");
        return;
    }
    let uid = (61_000 + std::process::id() % 4_000).to_string();
    // the system's Python: another uid cannot run one under root's home (pyenv)
    const PYTHON: &str = "/usr/bin/python3";
    if !std::path::Path::new(PYTHON).exists() {
        eprintln!("not run: the second uid's client needs {PYTHON}");
        return;
    }
    let routes: Vec<String> = API.iter().map(|(m, t, b)| format!("{m} {t} {}", b.unwrap_or(""))).collect();
    let script = r#"
import http.client, sys
token_file, environ, addr = sys.argv[1], sys.argv[2], sys.argv[3]
for path in (token_file, environ):
    try:
        open(path).read()
        print("READ", path)
    except OSError as e:
        print("DENIED", path)
host, port = addr.rsplit(":", 1)
for line in sys.argv[4:]:
    method, target, body = (line.split(" ", 2) + [""])[:3]
    c = http.client.HTTPConnection(host, int(port), timeout=20)
    c.request(method, target, body=body or None)
    print("STATUS", c.getresponse().status, method, target)
    c.close()
"#;
    let out = std::process::Command::new("setpriv")
        .args(["--reuid", &uid, "--regid", &uid, "--clear-groups", "--", PYTHON, "-c", script])
        .arg(token_file)
        .arg(format!("/proc/{ui_pid}/environ"))
        .arg(addr)
        .args(&routes)
        .env("HOME", "/")
        .output()
        .expect("run python3 as another uid");
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{said}{}", String::from_utf8_lossy(&out.stderr));
    assert!(!said.contains("READ "), "uid {uid} read a secret: {said}");
    assert_eq!(said.matches("DENIED").count(), 2, "{said}");
    assert_eq!(said.matches("STATUS 401").count(), API.len(), "uid {uid} got more than 401: {said}");
}

/// The server's limits: a header too large is refused (431) and the server
/// stays up; a connection that sends nothing is closed after the idle
/// timeout; connections beyond 32 at once are answered 503; and Ctrl-C
/// ends the server while an event stream's reader has stopped reading.
#[test]
fn oversized_idle_and_surplus_connections_are_refused() {
    use std::io::{Read, Write};
    let r = Robot::new("uilim");
    r.router();
    let ui = Ui::start(&r, &["--idle-timeout", "1"]);
    let addr = ui.addr.clone();
    let read = [("X-Nerve-Token", READ)];

    // a 20 KiB header, and 100 small ones
    let big = format!("GET /api/graph HTTP/1.1\r\nHost: {addr}\r\nX-Big: {}\r\n\r\n", "a".repeat(20 * 1024));
    let (status, _) = raw_request(&addr, big.as_bytes());
    assert_eq!(status, 431);
    let many = format!("GET /api/graph HTTP/1.1\r\nHost: {addr}\r\n{}\r\n", "X-A: b\r\n".repeat(100));
    assert_eq!(raw_request(&addr, many.as_bytes()).0, 431);
    // a header that never ends (no CRLF): cut off at the limit, not grown
    let endless = format!("GET / HTTP/1.1\r\nHost: {addr}\r\nX: {}", "a".repeat(64 * 1024));
    assert_eq!(raw_request(&addr, endless.as_bytes()).0, 431);
    // the server is still up
    assert_eq!(http(&addr, "GET", "/api/info", &read, None).0, 200);

    // a connection that sends nothing, and one that sends half a request, are closed
    let (status, _) = raw_request(&addr, b"");
    assert!(status == 0 || status == 408, "{status}");
    let (status, _) = raw_request(&addr, format!("GET /api/info HTTP/1.1\r\nHost: {addr}\r\n").as_bytes());
    assert_eq!(status, 408);

    // a stream whose reader never reads, held open across Ctrl-C
    let mut stalled = std::net::TcpStream::connect(&addr).expect("connect");
    let head = format!("GET /api/events HTTP/1.1\r\nHost: {addr}\r\nX-Nerve-Token: {READ}\r\n\r\n");
    stalled.write_all(head.as_bytes()).expect("send");
    let mut first = [0u8; 12];
    stalled.set_read_timeout(Some(Duration::from_secs(20))).expect("timeout");
    stalled.read_exact(&mut first).expect("the stream's head");
    assert_eq!(&first[9..12], b"200");
    ui.stop();
    drop(stalled);

    // 32 connections at once (an idle timeout long enough to hold them), the 33rd refused
    let ui = Ui::start(&r, &["--idle-timeout", "60"]);
    let held: Vec<std::net::TcpStream> =
        (0..32).map(|_| std::net::TcpStream::connect(&ui.addr).expect("connect")).collect();
    let (status, body) = raw_request(&ui.addr, b"");
    assert_eq!(status, 503, "{body}");
    drop(held);
    let up = wait_until(WAIT, || {
        nerve_tests::browser::try_http(&ui.addr, "GET", "/api/info", &read, None).is_ok_and(|(s, _)| s == 200)
    });
    assert!(up, "nerve ui did not serve again once the connections were closed");
    ui.stop();
    r.down_and_check_clean();
}
