//! Two robots talking through their bridge agents: real processes, real
//! iceoryx2 shared memory on each side, real Zenoh sessions between them —
//! over loopback, and across a veth pair between two network namespaces
//! that the test creates, cuts and removes.

use nerve_tests::{ChildGuard, Robot, alive, bin_dir, free_port, reap, sigkill, wait_until, write_file};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

/// `nerve launch FILE` for `r`, optionally inside network namespace `netns`.
fn launch(r: &Robot, file: &Path, netns: Option<&str>) {
    let out = match netns {
        None => r.command("nerve").arg("launch").arg(file).output(),
        Some(ns) => Command::new("ip")
            .args(["netns", "exec", ns])
            .arg(bin_dir().join("nerve"))
            .arg("launch")
            .arg(file)
            .env("NERVE_ROBOT", &r.name)
            .env("NERVE_HOME", &r.home)
            .env_remove("RUST_LOG")
            .output(),
    }
    .expect("run nerve launch");
    assert!(out.status.success(), "launch of {} failed: {}", r.name, String::from_utf8_lossy(&out.stderr));
}

/// The sequence type that crosses in `two_robots`: a header and any number of ticks.
const SEQ: &str = "nerve::Seq<nerve::Tick, nerve::Tick>";

/// Robots A and B on loopback: A exports its ticker t1 (best effort) and t3
/// (imported by B with the wrong type), B exports its command ticker
/// (reliable). A's t2 is not listed anywhere; B imports it anyway to show
/// that nothing arrives. A's t5 is exported but starts only later (hot add).
/// A exports a sequence port `seq/ticks` (up to 2000 elements, fed by `nerve
/// pub` into the bridge's input), which B imports as `ticks` (up to 1024).
fn two_robots() -> (Robot, Robot) {
    let (a, b) = (Robot::new("bra"), Robot::new("brb"));
    let port = free_port();
    let a_cfg = write_file(
        &a.home,
        "bridge.toml",
        &format!(
            r#"listen = ["tcp/127.0.0.1:{port}"]
lease = "1s"
[[export]]
port = "t1/tick"
type = "nerve::Tick"
[[export]]
port = "t3/tick"
type = "nerve::Tick"
[[export]]
port = "t5/tick"
type = "nerve::Tick"
[[export]]
port = "seq/ticks"
type = "{SEQ}"
max_len = 2000
[[import]]
port = "{b}/cmd/tick"
type = "nerve::Tick"
as = "cmd"
"#,
            b = b.name
        ),
    );
    let b_cfg = write_file(
        &b.home,
        "bridge.toml",
        &format!(
            r#"connect = ["tcp/127.0.0.1:{port}"]
lease = "1s"
[[export]]
port = "cmd/tick"
type = "nerve::Tick"
reliable = true
queue = 500
[[import]]
port = "{a}/t1/tick"
type = "nerve::Tick"
as = "t1"
[[import]]
port = "{a}/t2/tick"
type = "nerve::Tick"
as = "t2"
[[import]]
port = "{a}/t3/tick"
type = "nerve::Scalar"
as = "t3"
[[import]]
port = "{a}/t5/tick"
type = "nerve::Tick"
as = "t5"
[[import]]
port = "{a}/seq/ticks"
type = "{SEQ}"
as = "ticks"
max_len = 1024
"#,
            a = a.name
        ),
    );
    let a_launch = a.launch_file(
        "a.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "t1"
kind = "ticker"
period = "20ms"
[[agent]]
name = "t2"
kind = "ticker"
period = "20ms"
[[agent]]
name = "t3"
kind = "ticker"
period = "50ms"
[[agent]]
name = "bridge"
kind = "bridge"
args = ["--config", "{}"]
restart = "on-failure"
backoff = "100ms"
[[agent]]
name = "r1"
kind = "relay"
[[connect]]
from = "bridge/cmd"
to = "r1/in"
"#,
            a_cfg.display()
        ),
    );
    let b_launch = b.launch_file(
        "b.toml",
        &format!(
            r#"robot = "x"
[[agent]]
name = "cmd"
kind = "ticker"
period = "100ms"
[[agent]]
name = "bridge"
kind = "bridge"
args = ["--config", "{}"]
restart = "on-failure"
backoff = "100ms"
[[agent]]
name = "r1"
kind = "relay"
[[connect]]
from = "bridge/t1"
to = "r1/in"
"#,
            b_cfg.display()
        ),
    );
    launch(&a, &a_launch, None);
    launch(&b, &b_launch, None);
    (a, b)
}

/// An exported port reaches the other robot's agent through `nerve connect`;
/// an unlisted one does not cross; a type mismatch is refused with both type
/// names; rewiring and hot-adding on either side work while the bridge runs;
/// `nerve bridge status` shows the peer and the topics.
#[test]
fn bridged_robots_exchange_only_what_is_listed() {
    let (a, b) = two_robots();
    // A's ticks arrive at B's relay, through B's bridge output
    let ticks = b.echo("r1/out", 3);
    assert_eq!(ticks.len(), 3, "{ticks:?}");
    // the exports were wired through A's router: nerve graph shows them
    let edges = a.edges();
    assert!(edges.contains(&"t1/tick -> bridge/t1.tick".to_string()), "{edges:?}");
    // B's reliable commands arrive at A
    assert_eq!(a.echo("r1/out", 2).len(), 2);
    assert!(wait_until(Duration::from_secs(10), || b.figure_u64("bridge", "export.cmd/tick.importers") == 1));

    // t2 is not exported by A: nothing arrives on B's import of it
    assert!(wait_until(Duration::from_secs(10), || b
        .figure_u64("bridge", &format!("import.{}/t1/tick.msgs_in", a.name))
        > 50));
    assert_eq!(b.figure_u64("bridge", &format!("import.{}/t2/tick.msgs_in", a.name)), 0, "an unlisted port crossed");

    // t3 crosses as nerve::Tick but B expects nerve::Scalar: refused, counted, both names said
    let key = format!("import.{}/t3/tick", a.name);
    assert!(wait_until(Duration::from_secs(10), || b.figure_u64("bridge", &format!("{key}.refused")) > 0));
    let err = b.figures("bridge").get(&format!("{key}.error")).cloned().unwrap_or_default();
    assert!(err.contains("nerve::Tick") && err.contains("nerve::Scalar"), "{err}");
    assert_eq!(b.figure_u64("bridge", &format!("{key}.msgs_in")), 0);

    sequences_cross_at_their_length(&a, &b);

    // rewiring on B while the bridge runs: a hot-added relay takes A's ticks
    b.ok(&["start", "relay", "--name", "r2"]);
    b.ok(&["connect", "bridge/t1", "r2/in"]);
    assert_eq!(b.echo("r2/out", 2).len(), 2);
    b.ok(&["disconnect", "bridge/t1", "r1/in"]);
    // hot add on A: t5 is exported but was not running; the bridge wires it once it registers
    a.ok(&["start", "ticker", "--name", "t5", "--period", "20ms"]);
    b.ok(&["start", "relay", "--name", "r5"]);
    b.ok(&["connect", "bridge/t5", "r5/in"]);
    assert_eq!(b.echo("r5/out", 2).len(), 2, "a port hot-added on A crosses");

    // the status command names the peer and the topics
    let status = b.ok(&["bridge", "status"]);
    assert!(status.contains(&format!("{}/bridge", a.name)) && status.contains("cmd/tick"), "{status}");
    let json: Value = serde_json::from_str(&b.ok(&["bridge", "status", "--json"])).expect("status json");
    assert_eq!(json[0]["peers"][0], format!("{}/bridge", a.name));
    a.down_and_check_clean();
    b.down_and_check_clean();
}

/// A sample of `n` ticks after a header numbered `n`, as `nerve pub` takes it.
fn ticks_json(n: u64) -> String {
    let items: Vec<Value> = (0..n).map(|i| serde_json::json!({"seq": i, "stamp_ns": 0})).collect();
    serde_json::json!({"header": {"seq": n, "stamp_ns": 0}, "items": items}).to_string()
}

/// Sequence samples of 0, 1 and 1000 elements cross from A to B each at its
/// own length, and `nerve echo` on B decodes them; one of 1025, past B's
/// `max_len` (1024), is refused whole and counted, never cut.
fn sequences_cross_at_their_length(a: &Robot, b: &Robot) {
    let out_path = b.home.join("echo-ticks.jsonl");
    let out = std::fs::File::create(&out_path).expect("echo output file");
    let mut echo = b.command("nerve");
    echo.args(["echo", "bridge/ticks", "--json", "--count", "9", "--timeout", "20"]).stdout(out);
    let mut echo = ChildGuard::spawn("nerve echo", echo).expect("nerve echo");
    // sent in rounds until echo, subscribed some time after it started, has its 9
    for _ in 0..20 {
        if echo.check_alive().is_err() {
            break;
        }
        for n in [0, 1, 1000] {
            a.ok(&["pub", "bridge/seq.ticks", &ticks_json(n)]);
        }
    }
    echo.stop(Duration::from_secs(1));
    let text = std::fs::read_to_string(&out_path).expect("echo output");
    let mut lens = std::collections::BTreeSet::new();
    for line in text.lines() {
        let v: Value = serde_json::from_str(line).expect("echo json line");
        assert_eq!(v["type"], SEQ);
        let items = v["data"]["items"].as_array().expect("items");
        assert_eq!(v["data"]["header"]["seq"].as_u64(), Some(items.len() as u64), "{line:.200}");
        assert!(items.iter().enumerate().all(|(i, t)| t["seq"].as_u64() == Some(i as u64)), "{line:.200}");
        lens.insert(items.len());
    }
    assert_eq!(lens.into_iter().collect::<Vec<_>>(), [0, 1, 1000], "every length crossed as it was: {text:.300}");
    let key = format!("import.{}/seq/ticks", a.name);
    assert_eq!(b.figure_u64("bridge", &format!("{key}.refused")), 0);
    a.ok(&["pub", "bridge/seq.ticks", &ticks_json(1025)]);
    assert!(wait_until(Duration::from_secs(10), || b.figure_u64("bridge", &format!("{key}.refused")) == 1));
    let err = b.figures("bridge").get(&format!("{key}.error")).cloned().unwrap_or_default();
    assert!(err.contains("1025 elements") && err.contains("max_len"), "{err}");
}

/// SIGKILL of a bridge: its robot runs on, the supervisor restarts it, the
/// link comes back, and `nerve down` leaves nothing in /dev/shm.
#[test]
fn a_killed_bridge_is_restarted_and_the_link_comes_back() {
    let (a, b) = two_robots();
    assert_eq!(b.echo("r1/out", 2).len(), 2);
    let old = a.pid("bridge");
    let t1_cycles = |r: &Robot| r.agent("t1").and_then(|v| v["stats"]["cycles"].as_u64()).unwrap_or(0);
    sigkill(old);
    let before = t1_cycles(&a);
    assert!(
        wait_until(Duration::from_secs(10), || {
            reap();
            a.agent("bridge").and_then(|v| v["pid"].as_u64()).is_some_and(|p| p as u32 != old && alive(p as u32))
        }),
        "the bridge was not restarted"
    );
    assert!(t1_cycles(&a) > before, "robot A stopped while its bridge was dead");
    // the restarted bridge is wired again and B receives again
    let n = b.figure_u64("bridge", &format!("import.{}/t1/tick.msgs_in", a.name));
    assert!(
        wait_until(Duration::from_secs(15), || b.figure_u64("bridge", &format!("import.{}/t1/tick.msgs_in", a.name))
            > n + 20),
        "no data across the link after the restart"
    );
    assert_eq!(b.echo("r1/out", 2).len(), 2);
    // and B's reliable commands reach the new bridge of A
    assert_eq!(a.echo("r1/out", 2).len(), 2);
    a.down_and_check_clean();
    b.down_and_check_clean();
}

/// A network namespace pair joined by a veth pair, removed on drop.
struct Netns {
    a: String,
    b: String,
    veth_a: String,
}

impl Netns {
    /// Creates the namespaces and the link, or says why it cannot.
    fn create(tag: u32) -> Result<Netns, String> {
        let id = std::process::id() % 10_000;
        let n = Netns { a: format!("nvb{id}a{tag}"), b: format!("nvb{id}b{tag}"), veth_a: format!("nv{id}a{tag}") };
        let veth_b = format!("nv{id}b{tag}");
        let run = nerve_tests::ip;
        run(&["netns", "add", &n.a])?;
        run(&["netns", "add", &n.b])?;
        run(&["link", "add", &n.veth_a, "type", "veth", "peer", "name", &veth_b])?;
        run(&["link", "set", &n.veth_a, "netns", &n.a])?;
        run(&["link", "set", &veth_b, "netns", &n.b])?;
        run(&["-n", &n.a, "addr", "add", "10.231.7.1/30", "dev", &n.veth_a])?;
        run(&["-n", &n.b, "addr", "add", "10.231.7.2/30", "dev", &veth_b])?;
        for (ns, dev) in [(&n.a, &n.veth_a), (&n.b, &veth_b)] {
            run(&["-n", ns, "link", "set", dev, "up"])?;
            run(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(n)
    }

    fn set_link(&self, up: bool) {
        let st = Command::new("ip")
            .args(["-n", &self.a, "link", "set", &self.veth_a, if up { "up" } else { "down" }])
            .status()
            .expect("ip link set");
        assert!(st.success());
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        // deleting a namespace deletes the veth end in it, and so the pair
        for ns in [&self.a, &self.b] {
            let _ = Command::new("ip").args(["netns", "del", ns]).status();
        }
    }
}

/// A real network link: robots A and B in two network namespaces joined by a
/// veth pair. The test cuts the link for 4 s (longer than the lease) and
/// restores it: each robot keeps running; reliable messages sent during the
/// cut arrive after it, with none lost when the queue holds them and the
/// overflow counted when it does not; the best-effort stream resumes. Where
/// namespaces are not permitted it says so and makes the same checks over
/// loopback by stopping and restarting the importing bridge.
#[test]
fn a_cut_link_loses_nothing_reliable_and_streams_resume() {
    let (a, b) = (Robot::new("cuta"), Robot::new("cutb"));
    let netns = match Netns::create(0) {
        Ok(n) => Some(n),
        Err(e) => {
            eprintln!("network namespaces are not permitted here ({e}); cutting the link by stopping a bridge instead");
            None
        }
    };
    let port = free_port();
    let (listen, connect) = match netns {
        Some(_) => ("tcp/10.231.7.1:7447".to_string(), "tcp/10.231.7.1:7447".to_string()),
        None => (format!("tcp/127.0.0.1:{port}"), format!("tcp/127.0.0.1:{port}")),
    };
    let a_cfg = write_file(
        &a.home,
        "bridge.toml",
        &format!(
            // plain TCP across the veth pair: the test's own namespaces (tests/tests/bridge_security.rs runs TLS)
            "listen = [\"{listen}\"]\ninsecure = true\nlease = \"1s\"\n[[export]]\nport = \"t1/tick\"\ntype = \"nerve::Tick\"\n\
             [[import]]\nport = \"{b}/cmd/tick\"\ntype = \"nerve::Tick\"\nas = \"cmd\"\n\
             [[import]]\nport = \"{b}/small/tick\"\ntype = \"nerve::Tick\"\nas = \"small\"\n",
            b = b.name
        ),
    );
    let b_cfg = write_file(
        &b.home,
        "bridge.toml",
        &format!(
            "connect = [\"{connect}\"]\ninsecure = true\nlease = \"1s\"\n\
             [[export]]\nport = \"cmd/tick\"\ntype = \"nerve::Tick\"\nreliable = true\nqueue = 1000\n\
             [[export]]\nport = \"small/tick\"\ntype = \"nerve::Tick\"\nreliable = true\nqueue = 5\n\
             [[import]]\nport = \"{a}/t1/tick\"\ntype = \"nerve::Tick\"\nas = \"t1\"\n",
            a = a.name
        ),
    );
    let agent =
        |name: &str, kind: &str, extra: &str| format!("[[agent]]\nname = \"{name}\"\nkind = \"{kind}\"\n{extra}\n");
    let a_launch = a.launch_file(
        "a.toml",
        &format!(
            "robot = \"x\"\n{}{}",
            agent("t1", "ticker", "period = \"20ms\""),
            agent(
                "bridge",
                "bridge",
                &format!("args = [\"--config\", \"{}\"]\nrestart = \"on-failure\"", a_cfg.display())
            )
        ),
    );
    let b_launch = b.launch_file(
        "b.toml",
        &format!(
            "robot = \"x\"\n{}{}{}",
            agent("cmd", "ticker", "period = \"100ms\""),
            agent("small", "ticker", "period = \"100ms\""),
            agent(
                "bridge",
                "bridge",
                &format!("args = [\"--config\", \"{}\"]\nrestart = \"on-failure\"", b_cfg.display())
            )
        ),
    );
    launch(&a, &a_launch, netns.as_ref().map(|n| n.a.as_str()));
    launch(&b, &b_launch, netns.as_ref().map(|n| n.b.as_str()));

    let cmd_in = format!("import.{}/cmd/tick", b.name);
    let small_in = format!("import.{}/small/tick", b.name);
    let t1_in = format!("import.{}/t1/tick", a.name);
    assert!(
        wait_until(Duration::from_secs(20), || a.figure_u64("bridge", &format!("{cmd_in}.msgs_in")) >= 5
            && b.figure_u64("bridge", &format!("{t1_in}.msgs_in")) >= 20),
        "the link did not come up: A {:?} / B {:?}",
        a.figures("bridge"),
        b.figures("bridge")
    );
    let cycles = |r: &Robot, n: &str| r.agent(n).and_then(|v| v["stats"]["cycles"].as_u64()).unwrap_or(0);
    let (a_t1, b_cmd) = (cycles(&a, "t1"), cycles(&b, "cmd"));
    let delivered_before = a.figure_u64("bridge", &format!("{cmd_in}.msgs_in"));
    let queued_before = b.figure_u64("bridge", "export.cmd/tick.last_seq");

    // the cut
    match &netns {
        Some(n) => n.set_link(false),
        None => {
            a.ok(&["stop", "bridge"]);
        }
    }
    std::thread::sleep(Duration::from_secs(4));
    assert!(cycles(&a, "t1") > a_t1 + 100 && cycles(&b, "cmd") > b_cmd + 20, "a robot stopped during the cut");
    assert!(
        b.figure_u64("bridge", "export.cmd/tick.queue") >= 20,
        "B queues its commands while the link is down: {:?}",
        b.figures("bridge")
    );
    // the newest command B has taken from its port (read, like every figure
    // here, through `nerve ps`, which may take a while on a loaded machine:
    // the check below compares sequence numbers, never counts read at
    // different moments)
    let queued_by_cut_end = b.figure_u64("bridge", "export.cmd/tick.last_seq");
    assert!(queued_by_cut_end >= queued_before + 20, "B took no commands during the cut: {:?}", b.figures("bridge"));
    match &netns {
        Some(n) => n.set_link(true),
        None => {
            let cfg = a_cfg.display().to_string();
            a.ok(&["start", "bridge", "--name", "bridge", "--", "--config", &cfg]);
        }
    }

    // everything queued arrives, in order (the receiver delivers only in order), nothing reliable lost
    assert!(
        wait_until(Duration::from_secs(20), || b.figure_u64("bridge", "export.cmd/tick.queue") <= 2),
        "B's queue did not drain after the link came back: {:?}",
        b.figures("bridge")
    );
    assert!(
        // every command queued during the cut is delivered, in order
        wait_until(Duration::from_secs(20), || a.figure_u64("bridge", &format!("{cmd_in}.acked")) >= queued_by_cut_end),
        "the commands sent during the cut did not all arrive (B queued up to #{queued_by_cut_end}): A {:?} / B {:?}",
        a.figures("bridge"),
        b.figures("bridge")
    );
    assert_eq!(a.figure_u64("bridge", &format!("{cmd_in}.lost")), 0, "{:?}", a.figures("bridge"));
    // the small queue overflowed: counted on both sides, and said in B's log
    assert!(b.figure_u64("bridge", "export.small/tick.lost") >= 20, "{:?}", b.figures("bridge"));
    assert!(
        wait_until(Duration::from_secs(20), || a.figure_u64("bridge", &format!("{small_in}.lost")) >= 20),
        "the receiver did not count the overflow: {:?}",
        a.figures("bridge")
    );
    let log = b.ok(&["logs", "bridge"]);
    assert!(log.contains("reliable queue full"), "no log line for the overflow");
    // the best-effort stream resumes
    let n = b.figure_u64("bridge", &format!("{t1_in}.msgs_in"));
    assert!(
        wait_until(Duration::from_secs(20), || b.figure_u64("bridge", &format!("{t1_in}.msgs_in")) > n + 20),
        "the stream did not resume: {:?}",
        b.figures("bridge")
    );
    eprintln!(
        "cut of 4 s over {}: commands during the cut {}, delivered after it {} (lost {}); small queue lost {} at B, {} counted at A",
        if netns.is_some() { "a veth pair" } else { "loopback (bridge stopped)" },
        queued_by_cut_end - queued_before,
        a.figure_u64("bridge", &format!("{cmd_in}.msgs_in")).saturating_sub(delivered_before),
        a.figure_u64("bridge", &format!("{cmd_in}.lost")),
        b.figure_u64("bridge", "export.small/tick.lost"),
        a.figure_u64("bridge", &format!("{small_in}.lost")),
    );
    a.down_and_check_clean();
    b.down_and_check_clean();
    drop(netns);
}

/// A fleet's star (issue 44): two robots' bridges in `mode = "client"` meet
/// through one Zenoh router (zenoh's own router mode, `nerve-ros2-router`)
/// instead of linking to each other: A's ticks reach B's agent, B's status
/// names A's bridge as a peer, and neither bridge listens on anything.
#[test]
fn bridges_in_client_mode_meet_through_a_router() {
    let (a, b) = (Robot::new("bca"), Robot::new("bcb"));
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut router = Command::new(bin_dir().join("nerve-ros2-router"));
    router.args(["--listen", &endpoint]).stdout(Stdio::piped());
    let mut router = ChildGuard::spawn("nerve-ros2-router", router).expect("start the zenoh router");
    router.await_ready("nerve-ros2-router").expect("the router listens");
    let bridge = |r: &Robot, body: &str| {
        let cfg = write_file(
            &r.home,
            "bridge.toml",
            &format!("mode = \"client\"\nconnect = [\"{endpoint}\"]\nlease = \"1s\"\n{body}"),
        );
        r.launch_file(
            "fleet.toml",
            &format!(
                "robot = \"x\"\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nperiod = \"20ms\"\n\
                 [[agent]]\nname = \"bridge\"\nkind = \"bridge\"\nargs = [\"--config\", {:?}]\n\
                 [[agent]]\nname = \"r1\"\nkind = \"relay\"\n",
                cfg.display().to_string()
            ),
        )
    };
    let a_launch = bridge(&a, "[[export]]\nport = \"t1/tick\"\ntype = \"nerve::Tick\"\n");
    let b_launch =
        bridge(&b, &format!("[[import]]\nport = \"{}/t1/tick\"\ntype = \"nerve::Tick\"\nas = \"t1\"\n", a.name));
    launch(&a, &a_launch, None);
    launch(&b, &b_launch, None);
    b.ok(&["connect", "bridge/t1", "r1/in"]);
    assert_eq!(b.echo("r1/out", 3).len(), 3, "robot A's ticks reach robot B through the router");
    let json: Value = serde_json::from_str(&b.ok(&["bridge", "status", "--json"])).expect("status json");
    assert_eq!(json[0]["peers"][0], format!("{}/bridge", a.name), "{json}");
    assert_eq!(a.figure("bridge", "mode"), "client");
    assert_eq!(b.figure("bridge", "mode"), "client");
    a.down_and_check_clean();
    b.down_and_check_clean();
    drop(router);
}

/// The example of the README (launch/bridge-a.toml, launch/bridge-b.toml and
/// their bridge configs), with this test's robot names and a free port.
#[test]
fn the_example_pair_of_launch_files_runs() {
    let (a, b) = (Robot::new("exa"), Robot::new("exb"));
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("launch");
    let port = free_port().to_string();
    let dir = a.home.join("example");
    std::fs::create_dir_all(&dir).expect("example dir");
    // the examples speak mutual TLS: the fleet's keys, as the README makes them
    let keys = dir.join("keys");
    for args in [vec!["init"], vec!["add", a.name.as_str()], vec!["add", b.name.as_str()]] {
        let mut full = vec!["bridge", "keys"];
        full.extend(args);
        let keys = keys.display().to_string();
        full.extend(["--dir", keys.as_str()]);
        let out = a.nerve(&full);
        assert!(out.status.success(), "nerve {}: {}", full.join(" "), String::from_utf8_lossy(&out.stderr));
    }
    for f in ["bridge-a.toml", "bridge-b.toml", "bridge-a.zenoh.toml", "bridge-b.zenoh.toml"] {
        let text = std::fs::read_to_string(repo.join(f)).expect("example file");
        let text = text.replace("bridge-a", &a.name).replace("bridge-b", &b.name).replace("7447", &port);
        let text = text.replace("\n[tls]\n", &format!("\n[tls]\nkeys = {:?}\n", keys.display().to_string()));
        // the launch files name their configs through {dir}: rename them alike
        let name = f.replace("bridge-a", &a.name).replace("bridge-b", &b.name);
        std::fs::write(dir.join(name), text).expect("write example");
    }
    launch(&a, &dir.join(format!("{}.toml", a.name)), None);
    launch(&b, &dir.join(format!("{}.toml", b.name)), None);
    assert_eq!(b.echo("r1/out", 3).len(), 3, "robot A's ticks reach robot B");
    assert_eq!(a.echo("r1/out", 1).len(), 1, "robot B's commands reach robot A");
    assert_eq!(a.figure("bridge", "security"), "tls", "the example runs mutual TLS");
    a.down_and_check_clean();
    b.down_and_check_clean();
}

/// A bad bridge configuration stops `nerve launch` before anything starts,
/// with every problem of the configuration file and its line.
#[test]
fn a_bad_bridge_config_is_refused_by_the_launch_check() {
    let r = Robot::new("brbad");
    let cfg = write_file(
        &r.home,
        "bridge.toml",
        "listen = [\"udp/127.0.0.1:1\"]\n[[export]]\nport = \"t1/tick\"\ntype = \"nerve::Tock\"\n",
    );
    let file = r.launch_file(
        "l.toml",
        &format!(
            "robot = \"x\"\n[[agent]]\nname = \"bridge\"\nkind = \"bridge\"\nargs = [\"--config\", \"{}\"]\n",
            cfg.display()
        ),
    );
    // the refused --describe of the agent leaves no file of its private world behind
    let describe_files = || -> std::collections::BTreeSet<String> {
        std::fs::read_dir("/dev/shm")
            .map(|rd| {
                rd.filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| n.starts_with("nerve_describe-"))
                    .collect()
            })
            .unwrap_or_default()
    };
    let before = describe_files();
    let out = r.command("nerve").arg("launch").arg(&file).output().expect("launch");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    let left: Vec<String> = describe_files()
        .difference(&before)
        .filter(|n| {
            let pid = n.trim_start_matches("nerve_describe-").split('_').next().and_then(|p| p.parse::<u32>().ok());
            pid.is_some_and(|p| !alive(p))
        })
        .cloned()
        .collect();
    assert!(left.is_empty(), "a failed --describe left {left:?} in /dev/shm");
    assert!(err.contains("bridge.toml:1: ") && err.contains("TCP and TLS only"), "{err}");
    assert!(err.contains("bridge.toml:4: ") && err.contains("nerve::Tock"), "{err}");
    assert!(err.contains("nothing was started"), "{err}");
    let ps = r.nerve(&["ps", "--json"]);
    let listed = String::from_utf8_lossy(&ps.stdout).trim().to_owned();
    assert!(!ps.status.success() || listed == "[]", "an agent was started: {listed}");
}
