//! `nerve ui` in a real browser (issue 16): headless Chromium loads the page
//! of a robot started from `launch/pipeline.toml`, finds its agents and
//! edges, disconnects and connects by page actions (checked with `nerve
//! graph --json`), is refused a connection of the wrong type with the
//! router's message, hot-adds and kills an agent, watches a supervised
//! agent being killed and restarted, and reads a port's samples. A
//! read-only server offers no action, and an action without the token is
//! refused.

use nerve_tests::browser::{Browser, http};
use nerve_tests::{Robot, wait_until};
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Stdio};
use std::time::Duration;

const TOKEN: &str = "test-token-0123456789abcdef";
const WAIT: Duration = Duration::from_secs(20);

/// A running `nerve ui`; stopped with Ctrl-C (SIGINT) when dropped.
struct Ui {
    child: Child,
    addr: String,
}

impl Ui {
    fn start(r: &Robot, extra: &[&str]) -> Ui {
        let mut child = r
            .command("nerve")
            .args(["ui", "--bind", "127.0.0.1:0", "--token", TOKEN, "--interval", "0.25"])
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

    fn url(&self, token: bool) -> String {
        if token { format!("http://{}/?token={TOKEN}", self.addr) } else { format!("http://{}/", self.addr) }
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
    b.open(&ui.url(true));

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
    b.open(&ro.url(true));
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
    let (status, png) = http(&ro.addr, "GET", "/api/image?port=cam%2Fframes", &[], None);
    assert_eq!(status, 200);
    assert!(png.get(1..4) == Some("PNG") || png.starts_with("\u{FFFD}PNG"), "not a PNG");
    let (status, body) = http(&ro.addr, "GET", "/api/image?port=t1%2Ftick", &[], None);
    assert_eq!(status, 409, "{body}");
    assert!(body.contains("not ring notices"), "{body}");
    // the editing server's page opened without the token watches only
    b.open(&rw.url(false));
    b.wait_for("the agents", WAIT, &format!("const a = {PAGE_AGENTS}; return a === 'cam,r1,r2,t1' && a"));
    assert_eq!(b.eval("return nerveUi.editable"), Value::Bool(false));
    assert_eq!(
        b.eval("return document.getElementById('mode').textContent"),
        Value::String("watching (no token)".into())
    );

    drop(b);
    ro.stop();
    rw.stop();
    r.down_and_check_clean();
}
