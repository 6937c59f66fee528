//! The simulated robot's hardware path, end to end, with real processes:
//! the simulator agent publishing its boards on pseudo-terminals, the sensor
//! and actuator agents reading and driving them through the same serial
//! code as on the robot.
//!
//! Some tests put a pseudo-terminal of their own in place of a board, so
//! that they can write what a real line may carry (garbage, truncated
//! frames, bad checksums, 64 KiB of noise), close it (the device vanishes)
//! and bring it back. Commands reach the actuators from a temporary port of
//! the test, which the agent's message checker is asked directly to
//! subscribe, with the sender named in the sample header (`nerve cmd` does
//! the same through the router: `nerve_cmd_goes_through_the_router`).
//!
//! No assertion depends on how fast this machine is: rates are checked in
//! sequence numbers, retries in counts, and waits are bounded polls.

use agent_sdk::World;
use agent_sdk::clock::now_ns;
use agent_sdk::control::{ControlClient, ControlSize};
use agent_sdk::ports::{port_event, port_service};
use nerve_tests::device::{FakeDevice, crc16, sonar_frame};
use nerve_tests::{Robot, sigkill, wait_until};
use serde_json::Value;
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use shm_schemas::payloads::{LinguisticCommand, LinguisticTerm, SafetyStop, VelocityCommand};
use shm_schemas::{AgentName, FixedName, Payload, SampleHeader};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

// ---------------------------------------------------------------- helpers

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn world_file() -> String {
    repo().join("worlds/test-room.toml").display().to_string()
}

/// The last wheel command (left, right mm/s) in the bytes a motor agent wrote.
fn last_wheels(bytes: &[u8]) -> Option<(i16, i16)> {
    bytes
        .windows(10)
        .rev()
        .find(|w| w[..4] == [0xA5, 0x5A, 0x20, 4] && crc16(&w[2..8]) == u16::from_le_bytes([w[8], w[9]]))
        .map(|w| (i16::from_le_bytes([w[4], w[5]]), i16::from_le_bytes([w[6], w[7]])))
}

fn param(r: &Robot, agent: &str, key: &str) -> String {
    r.ok(&["param", "get", agent, key]).trim().to_owned()
}

fn param_u64(r: &Robot, agent: &str, key: &str) -> u64 {
    param(r, agent, key).parse().unwrap_or_else(|_| panic!("{agent} {key} is not a number"))
}

fn log_of(r: &Robot, agent: &str) -> String {
    std::fs::read_to_string(r.home.join(&r.name).join("logs").join(format!("{agent}.log"))).unwrap_or_default()
}

/// Sends commands to input `input` of `agent`, the way `nerve cmd` does:
/// a temporary port `test-<pid>/<input>` that the agent's message checker
/// subscribes to. `next(i)` gives the batch to send at round `i` (sender
/// name, value), or `None` to finish; rounds are `every` apart. Returns
/// how many samples were sent.
fn inject<T: Payload>(
    r: &Robot,
    agent: &str,
    input: &str,
    every: Duration,
    mut next: impl FnMut(u64) -> Option<Vec<(&'static str, T)>>,
) -> u64 {
    let world = World::new(&r.name).expect("world");
    let node = world.node(&format!("test-inject-{}-{input}", std::process::id())).expect("node");
    let from = format!("test-{}-{}", std::process::id(), rand_tag());
    let service = world.robot().port_service(&from, input);
    let publisher = port_service::<T>(&node, &service).expect("service").publisher_builder().create().expect("pub");
    let notifier = port_event(&node, &service).expect("event").notifier_builder().create().expect("notifier");
    let name = AgentName::new(agent).expect("agent name");
    let client: ControlClient<AgentCommand, AgentReply> =
        ControlClient::open(&node, &world.robot().ctl_service(&name), ControlSize::AGENT).expect("agent ctl");
    let reply = client
        .call(
            &AgentCommand::Connect {
                input: input.into(),
                from_agent: from.clone(),
                from_port: input.into(),
                type_name: T::stable_type_name().into(),
            },
            Duration::from_secs(5),
        )
        .expect("connect");
    assert!(matches!(reply, AgentReply::Ok), "{agent} refused the test port: {reply:?}");
    let mut seq = 0;
    let t0 = Instant::now();
    let mut round = 0;
    while let Some(batch) = next(round) {
        for (sender, value) in batch {
            loop {
                let mut s = publisher.loan_uninit().expect("loan");
                *s.user_header_mut() =
                    SampleHeader { sender: FixedName::new(sender), seq: seq + 1, stamp_ns: now_ns() };
                let delivered = s.write_payload(value).send().expect("send");
                if delivered > 0 {
                    seq += 1;
                    break;
                }
                // the agent subscribed, but this publisher has not seen it yet
                assert!(round == 0 && t0.elapsed() < Duration::from_secs(5), "{agent}/{input} does not receive");
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        let _ = notifier.notify();
        round += 1;
        std::thread::sleep(every);
    }
    // let the agent take the last ones before it unsubscribes
    std::thread::sleep(Duration::from_millis(200));
    let _ = client.call(
        &AgentCommand::Disconnect { input: input.into(), from_agent: from, from_port: input.into() },
        Duration::from_secs(5),
    );
    seq
}

fn rand_tag() -> u32 {
    static N: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    N.fetch_add(1, Ordering::Relaxed)
}

fn f(v: &Value, k: &str) -> f64 {
    v["data"][k].as_f64().unwrap_or_else(|| panic!("no number {k} in {v}"))
}

fn start_sim(r: &Robot, dev: &Path) {
    let dev = dev.display().to_string();
    r.ok(&[
        "start",
        "sim",
        "--name",
        "sim",
        "--",
        "--world",
        &world_file(),
        "--dev-dir",
        &dev,
        "--seed",
        "5",
        "--no-camera",
    ]);
}

// ---------------------------------------------------------------- tests

/// Every hardware agent describes itself without a device or a world, and
/// describing touches neither a device nor shared memory: with a device
/// path that does not exist and an iceoryx2 root that cannot be made (a
/// path under a regular file), `--describe` still works, and nothing of
/// its private robot appears in /dev/shm.
#[test]
fn hardware_agents_describe_themselves() {
    let r = Robot::new("descr");
    // short: the root's length is checked against Unix socket paths
    let blocked_root = std::path::PathBuf::from(format!("/tmp/nerve-nd-{}", std::process::id()));
    std::fs::write(&blocked_root, b"a file: no iceoryx2 root can be made under it").expect("write");
    struct Remove(std::path::PathBuf);
    impl Drop for Remove {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }
    let _remove = Remove(blocked_root.clone());
    for (kind, port) in [("sim", "truth"), ("sonar", "scan"), ("ir", "sighting"), ("motor", "odom"), ("head", "state")]
    {
        for device_args in [&[][..], &["--", "--device", "/nonexistent/ttyNERVE"][..]] {
            if kind == "sim" && !device_args.is_empty() {
                continue;
            }
            let child = r
                .command(&format!("nerve-{kind}"))
                .arg("--describe")
                .args(device_args)
                .env("NERVE_IOX2_ROOT", blocked_root.join("x"))
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("run");
            let pid = child.id();
            let out = child.wait_with_output().expect("wait");
            assert!(out.status.success(), "nerve-{kind} --describe: {}", String::from_utf8_lossy(&out.stderr));
            let d: Value = serde_json::from_slice(&out.stdout).expect("json");
            assert_eq!(d["kind"], kind);
            assert!(d["outputs"].as_array().expect("outputs").iter().any(|p| p["name"] == port), "{d}");
            let made: Vec<String> = std::fs::read_dir("/dev/shm")
                .into_iter()
                .flatten()
                .flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.contains(&format!("describe-{pid}_")))
                .collect();
            assert!(made.is_empty(), "nerve-{kind} --describe made shared memory: {made:?}");
        }
    }
    // a missing device is refused at start, saying what to do
    r.router();
    let err = r.fails(&["start", "sonar", "--name", "sonar"]);
    assert!(err.contains("--device"), "{err}");
}

/// The sonar agent reads 12 ranges per scan, one scan per 250 ms of
/// simulated time (consecutive sequence numbers), from the simulator.
#[test]
fn sonar_reads_the_simulated_ring() {
    let r = Robot::new("sonar");
    r.router();
    let dev = r.home.join("dev");
    start_sim(&r, &dev);
    r.ok(&["start", "sonar", "--name", "sonar", "--", "--device", &dev.join("sonar").display().to_string()]);
    let scans = r.echo("sonar/scan", 6);
    assert_eq!(scans.len(), 6);
    let mut west = 0;
    for w in scans.windows(2) {
        let (a, b) = (w[0]["data"]["seq"].as_u64().expect("seq"), w[1]["data"]["seq"].as_u64().expect("seq"));
        assert_eq!(b, a + 1, "consecutive scans: {scans:?}");
    }
    for s in &scans {
        assert_eq!(s["type"], "nerve::SonarScan");
        let ranges = s["data"]["ranges_m"].as_array().expect("ranges");
        assert_eq!(ranges.len(), 12);
        assert_eq!(s["data"]["risk"].as_array().expect("risk").len(), 12);
        // sonar 6 looks at the west wall, 0.75 m behind the robot
        let r6 = ranges[6].as_f64().expect("range");
        if (0.7..=0.8).contains(&r6) {
            west += 1;
        }
    }
    assert!(west >= 4, "west wall at ~0.75 m in {west}/6 scans: {scans:?}");
    assert!(param_u64(&r, "sonar", "frames") >= 6);
    assert_eq!(param_u64(&r, "sonar", "garbage_bytes"), 0);
    // the simulator's ground truth is on its port too
    let t = r.echo("sim/truth", 2);
    assert_eq!(t[0]["type"], "nerve::GroundTruth");
    r.down_and_check_clean();
}

/// A motion command moves the simulated robot; the motor agent's odometry
/// follows the ground truth.
#[test]
fn motor_command_moves_the_robot_and_odometry_follows() {
    let r = Robot::new("motor");
    r.router();
    let dev = r.home.join("dev");
    start_sim(&r, &dev);
    r.ok(&["start", "motor", "--name", "motor", "--", "--device", &dev.join("motor").display().to_string()]);
    let odom0 = r.echo("motor/odom", 1).remove(0);
    let truth0 = r.echo("sim/truth", 1).remove(0);
    // drive forward at 0.3 m/s for 2 s (commands repeated: they go stale after 500 ms)
    let sent = inject(&r, "motor", "cmd", Duration::from_millis(100), |i| {
        (i < 20).then(|| vec![("planner", VelocityCommand { v: 0.3, omega: 0.0, stamp_ns: now_ns() })])
    });
    assert_eq!(sent, 20);
    assert!(param_u64(&r, "motor", "accepted") >= 15, "accepted {}", param(&r, "motor", "accepted"));
    // after the commands stop the base stops (dead man); then compare
    assert!(wait_until(Duration::from_secs(10), || {
        r.echo("sim/truth", 1).first().is_some_and(|t| f(t, "v").abs() < 0.01)
    }));
    let odom1 = r.echo("motor/odom", 1).remove(0);
    let truth1 = r.echo("sim/truth", 1).remove(0);
    let true_dist = f(&truth1, "x") - f(&truth0, "x");
    let odo_dist = f(&odom1, "x") - f(&odom0, "x");
    assert!(true_dist > 0.2, "the robot moved forward: {truth0} -> {truth1}");
    assert!(
        (odo_dist - true_dist).abs() < 0.2 * true_dist + 0.02,
        "odometry {odo_dist:.3} m vs truth {true_dist:.3} m"
    );
    r.down_and_check_clean();
}

/// Garbage, truncated frames, bad checksums and 64 KiB of noise on the
/// line are counted and dropped; parsing resynchronises on the next frame.
#[test]
fn serial_noise_is_counted_dropped_and_parsing_resynchronises() {
    let r = Robot::new("noise");
    r.router();
    let link = r.home.join("dev").join("sonar");
    let mut dev = FakeDevice::new(&link);
    r.ok(&["start", "sonar", "--name", "sonar", "--", "--device", &link.display().to_string()]);
    assert!(wait_until(Duration::from_secs(10), || param_u64(&r, "sonar", "device_opens") == 1));

    dev.write(&sonar_frame(1, 1000));
    dev.write(b"hello, this is not a frame");
    let good = sonar_frame(2, 1000);
    dev.write(&good[..12]); // cut mid-frame, then a whole one
    dev.write(&sonar_frame(3, 1000));
    let mut bad = sonar_frame(4, 1000);
    let n = bad.len();
    bad[n - 1] ^= 0xFF; // wrong checksum
    dev.write(&bad);
    // 64 KiB of noise (xorshift), written in pieces as a line would carry it
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    let noise: Vec<u8> = (0..65536)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect();
    for chunk in noise.chunks(4096) {
        dev.write(chunk);
    }
    // then good frames again, while we listen
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let writer = std::thread::spawn(move || {
        let mut seq = 10;
        while !s2.load(Ordering::Relaxed) {
            dev.write(&sonar_frame(seq, 1234));
            seq += 1;
            std::thread::sleep(Duration::from_millis(100));
        }
        dev
    });
    // The agent may still be working through the backlog when the echo
    // subscribes (on a loaded machine it was): a scan of the good frame
    // written before the noise (1.000 m) may come first. Every scan must be
    // a frame that was written, never a misparse of the noise, and the
    // frames after the noise must arrive intact.
    let scans = r.echo("sonar/scan", 6);
    stop.store(true, Ordering::Relaxed);
    let dev = writer.join().expect("writer");
    let ranges: Vec<f64> = scans.iter().map(|s| s["data"]["ranges_m"][0].as_f64().expect("range")).collect();
    for (s, r0) in scans.iter().zip(&ranges) {
        assert!((r0 - 1.234).abs() < 1e-6 || (r0 - 1.0).abs() < 1e-6, "only frames that were written decode: {s}");
    }
    assert!(
        ranges.iter().rev().take(3).all(|r0| (r0 - 1.234).abs() < 1e-6),
        "frames after the noise decode exactly: {ranges:?}"
    );
    let garbage = param_u64(&r, "sonar", "garbage_bytes");
    assert!(garbage >= 60_000, "noise counted as garbage: {garbage}");
    assert!(param_u64(&r, "sonar", "bad_checksums") >= 1);
    assert!(param_u64(&r, "sonar", "truncated") >= 1);
    assert!(param_u64(&r, "sonar", "frames") >= 5);
    // counters are read-only
    let e = r.fails(&["param", "set", "sonar", "garbage_bytes", "0"]);
    assert!(e.contains("read-only"), "{e}");
    assert!(log_of(&r, "sonar").contains("garbage bytes"), "the noise is logged");
    dev.vanish();
    r.down_and_check_clean();
}

/// A device that vanishes is reported, retried with exponential backoff (a
/// handful of attempts, little CPU) and recovered when it reappears.
#[test]
fn vanished_device_is_retried_with_backoff_and_recovered() {
    let r = Robot::new("vanish");
    r.router();
    let link = r.home.join("dev").join("sonar");
    let mut dev = FakeDevice::new(&link);
    r.ok(&["start", "sonar", "--name", "sonar", "--", "--device", &link.display().to_string()]);
    assert!(wait_until(Duration::from_secs(10), || param_u64(&r, "sonar", "device_opens") == 1));
    dev.write(&sonar_frame(1, 900));
    dev.vanish();
    assert!(wait_until(Duration::from_secs(10), || param_u64(&r, "sonar", "device_losses") == 1));
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs(3));
    let attempts = param_u64(&r, "sonar", "device_failed_opens");
    let elapsed = t0.elapsed().as_secs_f64() + 1.0;
    // 100, 200, 400, 800, 1600 ms...: a few attempts, never hundreds
    assert!((2..=12).contains(&attempts), "{attempts} reopen attempts in about {elapsed:.1} s");
    let cpu = r.agent("sonar").and_then(|a| a["stats"]["cpu_percent"].as_f64()).expect("cpu");
    assert!(cpu < 25.0, "no busy loop while the device is away: {cpu}% CPU");
    let log = log_of(&r, "sonar");
    assert!(log.contains("device lost"), "the loss is logged:\n{log}");
    assert!(log.contains("retrying in"), "the retry is logged:\n{log}");
    let warn_lines = log.lines().filter(|l| l.contains("retrying in")).count();
    assert!(warn_lines <= 3, "retries are not logged one line each:\n{log}");

    // the device comes back
    let mut dev = FakeDevice::new(&link);
    assert!(wait_until(Duration::from_secs(15), || param_u64(&r, "sonar", "device_opens") == 2));
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let writer = std::thread::spawn(move || {
        let mut seq = 100;
        while !s2.load(Ordering::Relaxed) {
            dev.write(&sonar_frame(seq, 2000));
            seq += 1;
            std::thread::sleep(Duration::from_millis(100));
        }
        dev
    });
    let scans = r.echo("sonar/scan", 2);
    stop.store(true, Ordering::Relaxed);
    let dev = writer.join().expect("writer");
    assert!((scans[0]["data"]["ranges_m"][3].as_f64().expect("range") - 2.0).abs() < 1e-6);
    assert!(log_of(&r, "sonar").contains("device recovered"));
    dev.vanish();
    r.down_and_check_clean();
}

/// Review fault 4c: after a cut line came back, the sonar published 12 scans
/// in one burst with the same stamp, sent by the module during the outage.
/// What the line holds when it is reopened is discarded unread and counted
/// in `stale_frames`; only scans sent after the reopen are published.
#[test]
fn scans_sent_while_the_line_was_cut_are_not_published_when_it_returns() {
    use std::io::BufRead;
    let r = Robot::new("stale");
    r.router();
    let link = r.home.join("dev").join("sonar");
    let mut dev = FakeDevice::new(&link);
    r.ok(&["start", "sonar", "--name", "sonar", "--", "--device", &link.display().to_string()]);
    assert!(wait_until(Duration::from_secs(10), || param_u64(&r, "sonar", "device_opens") == 1));

    // every scan published from now on, in order
    let mut echo = r
        .command("nerve")
        .args(["echo", "sonar/scan", "--json", "--timeout", "30"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("nerve echo");
    let scans = Arc::new(Mutex::new(Vec::<f64>::new()));
    let lines = std::io::BufReader::new(echo.stdout.take().expect("echo stdout"));
    let seen = scans.clone();
    let reader = std::thread::spawn(move || {
        for line in lines.lines().map_while(Result::ok) {
            let v: Value = serde_json::from_str(&line).expect("echo json line");
            seen.lock().expect("lock").push(v["data"]["ranges_m"][0].as_f64().expect("range"));
        }
    });
    let count = |range: f64| scans.lock().expect("lock").iter().filter(|r0| (**r0 - range).abs() < 1e-6).count();
    // the echo listens once a scan gets through
    let mut seq = 1;
    assert!(wait_until(Duration::from_secs(10), || {
        dev.write(&sonar_frame(seq, 900));
        seq += 1;
        count(0.9) > 0
    }));

    // the cut; the module goes on scanning (0.5 m) into the line meanwhile
    dev.vanish();
    assert!(wait_until(Duration::from_secs(10), || param_u64(&r, "sonar", "device_losses") == 1));
    let mut dev = FakeDevice::unpublished(&link);
    for seq in 50..62 {
        dev.write(&sonar_frame(seq, 500));
    }
    dev.publish();
    assert!(wait_until(Duration::from_secs(15), || param_u64(&r, "sonar", "device_opens") == 2));
    // and after the reopen, fresh scans (2 m)
    let mut seq = 100;
    let fresh = wait_until(Duration::from_secs(10), || {
        dev.write(&sonar_frame(seq, 2000));
        seq += 1;
        std::thread::sleep(Duration::from_millis(50));
        count(2.0) >= 3
    });
    let _ = echo.kill();
    let _ = echo.wait();
    reader.join().expect("echo reader");
    let published = scans.lock().expect("lock").clone();
    assert!(fresh, "scans after the reopen are published: {published:?}");
    assert_eq!(count(0.5), 0, "scans sent while the line was cut were published: {published:?}");
    assert_eq!(param_u64(&r, "sonar", "stale_frames"), 12);
    assert!(log_of(&r, "sonar").contains("discarded 12 frame(s)"), "the discard is logged");
    dev.vanish();
    r.down_and_check_clean();
}

/// Starts a motor agent on a fake board whose output the test reads.
fn motor_on_fake_board(r: &Robot) -> (Arc<Mutex<Vec<u8>>>, Arc<AtomicBool>, std::thread::JoinHandle<()>) {
    let link = r.home.join("dev").join("motor");
    let dev = FakeDevice::new(&link);
    r.ok(&["start", "motor", "--name", "motor", "--", "--device", &link.display().to_string()]);
    let stop = Arc::new(AtomicBool::new(false));
    let (bytes, h) = dev.reader(stop.clone());
    assert!(wait_until(Duration::from_secs(10), || param_u64(r, "motor", "device_opens") == 1));
    (bytes, stop, h)
}

/// Impractical (over the limits, not finite, jumping) and stale commands are
/// refused and never reach the wheels.
#[test]
fn impractical_and_stale_commands_are_refused() {
    let r = Robot::new("refuse");
    r.router();
    let (bytes, stop, h) = motor_on_fake_board(&r);
    let now = now_ns();
    let bad = [
        VelocityCommand { v: 5.0, omega: 0.0, stamp_ns: now },
        VelocityCommand { v: f64::NAN, omega: 0.0, stamp_ns: now },
        VelocityCommand { v: 0.1, omega: 50.0, stamp_ns: now },
        VelocityCommand { v: 0.2, omega: 0.0, stamp_ns: now.saturating_sub(3_000_000_000) },
    ];
    let mut i = 0;
    inject(&r, "motor", "cmd", Duration::from_millis(20), |_| {
        i += 1;
        bad.get(i - 1).map(|c| vec![("rogue", *c)])
    });
    let stale_say = LinguisticCommand::new(LinguisticTerm::IncreaseSpeed, 1.0, now_ns().saturating_sub(2_000_000_000));
    let unknown = LinguisticCommand { term: 77, intensity: 1.0, stamp_ns: now_ns() };
    let mut k = 0;
    inject(&r, "motor", "say", Duration::from_millis(20), |_| {
        k += 1;
        match k {
            1 => Some(vec![("rogue", stale_say)]),
            2 => Some(vec![("rogue", unknown)]),
            _ => None,
        }
    });
    assert!(wait_until(Duration::from_secs(5), || param_u64(&r, "motor", "refused") == 6));
    assert_eq!(param_u64(&r, "motor", "accepted"), 0);
    let applied = r.echo("motor/applied", 3);
    assert!(applied.iter().all(|a| f(a, "v") == 0.0 && f(a, "omega") == 0.0), "{applied:?}");
    assert_eq!(last_wheels(&bytes.lock().expect("lock")), Some((0, 0)), "the wheels never moved");
    let log = log_of(&r, "motor");
    assert!(log.contains("refused command from rogue"), "{log}");
    assert!(log.contains("stale"), "{log}");
    stop.store(true, Ordering::Relaxed);
    let _ = h.join();
    r.down_and_check_clean();
}

/// Two conflicting linguistic commands are fused by the fuzzy rule base with
/// the senders' weights; changing a weight at run time changes the outcome.
#[test]
fn fuzzy_fusion_of_conflicting_linguistic_commands() {
    let r = Robot::new("fuzzy");
    r.router();
    let (_bytes, stop, h) = motor_on_fake_board(&r);
    r.ok(&["param", "set", "motor", "weights", "wall-follow:1,tracker:2"]);
    let omega_for = |r: &Robot| -> f64 {
        let done = AtomicBool::new(false);
        std::thread::scope(|s| {
            // ends the injecting thread when the measurement is done, or failed
            let _finish = Finish(&done);
            s.spawn(|| {
                inject(r, "motor", "say", Duration::from_millis(50), |_| {
                    (!done.load(Ordering::Relaxed)).then(|| {
                        let t = now_ns();
                        vec![
                            ("wall-follow", LinguisticCommand::new(LinguisticTerm::TurnLeftMuch, 1.0, t)),
                            ("tracker", LinguisticCommand::new(LinguisticTerm::TurnRightALittle, 1.0, t)),
                        ]
                    })
                });
            });
            // the ramp (4 rad/s²) reaches the target within a few cycles
            std::thread::sleep(Duration::from_millis(800));
            let a = r.echo("motor/applied", 3);
            f(&a[2], "omega")
        })
    };
    // centre of sums: (1·0.3·0.6 − 2·0.2·0.2) / 0.7 · ω_max (2 rad/s)
    let w = omega_for(&r);
    assert!((w - 0.2857).abs() < 0.01, "fused turn rate {w}");
    r.ok(&["param", "set", "motor", "weights", "wall-follow:1,tracker:8"]);
    let w = omega_for(&r);
    assert!((w - (-0.1474)).abs() < 0.01, "fused turn rate with the tracker weighted 8: {w}");
    stop.store(true, Ordering::Relaxed);
    let _ = h.join();
    r.down_and_check_clean();
}

/// Sets the flag when dropped, also while a panic unwinds.
struct Finish<'a>(&'a AtomicBool);

impl Drop for Finish<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// A safety stop overrides every other source, however heavily weighted, and
/// the base moves again once it is released.
#[test]
fn safety_stop_overrides_every_source() {
    let r = Robot::new("stop");
    r.router();
    let (bytes, stop_reader, h) = motor_on_fake_board(&r);
    r.ok(&["param", "set", "motor", "weights", "planner:100"]);
    let done = AtomicBool::new(false);
    std::thread::scope(|s| {
        // ends the injecting thread at the end, also after a failed assertion
        // (or the scope would never return)
        let _finish = Finish(&done);
        s.spawn(|| {
            inject(&r, "motor", "cmd", Duration::from_millis(50), |_| {
                (!done.load(Ordering::Relaxed))
                    .then(|| vec![("planner", VelocityCommand { v: 0.3, omega: 0.0, stamp_ns: now_ns() })])
            });
        });
        assert!(wait_until(Duration::from_secs(5), || {
            r.echo("motor/applied", 1).first().is_some_and(|a| (f(a, "v") - 0.3).abs() < 1e-9)
        }));
        // the board reads the wheel frame a moment after `applied` is published
        let wheels = || last_wheels(&bytes.lock().expect("lock"));
        assert!(wait_until(Duration::from_secs(2), || wheels() == Some((300, 300))), "wheels: {:?}", wheels());
        let stop = SafetyStop { active: 1, allow_turn: 0, reserved: [0; 2], hold_ms: 0, stamp_ns: now_ns() };
        inject(&r, "motor", "stop", Duration::from_millis(10), |i| (i == 0).then(|| vec![("safety", stop)]));
        let a = r.echo("motor/applied", 3);
        assert!(a.iter().all(|x| f(x, "v") == 0.0), "stopped although the planner still drives: {a:?}");
        assert!(wait_until(Duration::from_secs(2), || wheels() == Some((0, 0))), "wheels: {:?}", wheels());
        assert!(log_of(&r, "motor").contains("safety stop from safety"));
        let release = SafetyStop { active: 0, stamp_ns: now_ns(), ..stop };
        inject(&r, "motor", "stop", Duration::from_millis(10), |i| (i == 0).then(|| vec![("safety", release)]));
        assert!(wait_until(Duration::from_secs(5), || {
            r.echo("motor/applied", 1).first().is_some_and(|a| f(a, "v") > 0.0)
        }));
    });
    stop_reader.store(true, Ordering::Relaxed);
    let _ = h.join();
    r.down_and_check_clean();
}

/// `nerve cmd` goes through the router's wiring like any other source: the
/// router checks the type (a head command to the motor is refused with the
/// router's message), `nerve graph` shows the tool's edge while it sends,
/// nothing of it is saved, and a `nerve cmd` killed mid-way leaves no edge
/// and no subscription behind.
#[test]
fn nerve_cmd_goes_through_the_router() {
    let r = Robot::new("clirt");
    r.router();
    let (_bytes, stop, h) = motor_on_fake_board(&r);
    let tool_edges = |r: &Robot| -> Vec<Value> {
        r.graph()["connections"]
            .as_array()
            .map(|c| c.iter().filter(|c| c["transient"] == true).cloned().collect())
            .unwrap_or_default()
    };
    let err = r.fails(&["cmd", "motor", "--pan", "10", "--input", "cmd"]);
    assert!(err.contains("nerve::HeadCommand") && err.contains("motor/cmd"), "the router's refusal: {err}");

    // while it holds, the edge is in the graph, marked as a tool's
    let mut holding = r
        .command("nerve")
        .args(["cmd", "motor", "--v", "0.1", "--hold", "30s"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("nerve cmd runs");
    let from = format!("cli-{}/cmd", holding.id());
    assert!(
        wait_until(Duration::from_secs(5), || tool_edges(&r).iter().any(|c| c["from"] == from.as_str()
            && c["to"] == "motor/cmd"
            && c["type_name"] == "nerve::VelocityCommand")),
        "the tool's edge in the graph: {}",
        r.graph()
    );

    let saved = std::fs::read_to_string(r.home.join(&r.name).join("connections.json")).unwrap_or_default();
    assert!(!saved.contains("cli-"), "a tool's edge is never saved: {saved}");
    // killed mid-way: the router sees the process gone and has the motor let go
    sigkill(holding.id());
    let _ = holding.wait();
    let subscribed = |r: &Robot| {
        r.agent("motor").is_some_and(|m| {
            let tool = from.split('/').next().unwrap_or("");
            m["stats"]["inputs"].as_array().is_some_and(|i| i.iter().any(|i| i["from_agent"] == tool))
        })
    };
    assert!(
        wait_until(Duration::from_secs(5), || tool_edges(&r).is_empty() && !subscribed(&r)),
        "the killed tool's edge and subscription are gone: {} / {:?}",
        r.graph(),
        r.agent("motor")
    );

    // a command that ends detaches itself
    let out = r.ok(&["cmd", "motor", "--v", "0.1"]);
    assert!(out.contains("motor/cmd"), "{out}");
    assert!(tool_edges(&r).is_empty(), "detached: {}", r.graph());
    stop.store(true, Ordering::Relaxed);
    let _ = h.join();
    r.down_and_check_clean();
}

/// `nerve cmd` sends one command from the terminal; unknown phrases are
/// refused with the known ones. Skipped while the command is not wired in.
#[test]
fn nerve_cmd_from_the_terminal() {
    let r = Robot::new("cli");
    if !r.nerve(&["cmd", "--help"]).status.success() {
        eprintln!("`nerve cmd` is not available in this build; skipping");
        return;
    }
    r.router();
    let (_bytes, stop, h) = motor_on_fake_board(&r);
    let err = r.fails(&["cmd", "motor", "dance a little"]);
    assert!(err.contains("turn right a little") && err.contains("increase speed"), "{err}");
    let out = r.ok(&["cmd", "motor", "turn right a little"]);
    assert!(out.contains("motor/say"), "{out}");
    let out = r.ok(&["cmd", "motor", "--v", "0.2", "--w", "0.0"]);
    assert!(out.contains("motor/cmd"), "{out}");
    assert!(param_u64(&r, "motor", "accepted") >= 2);
    let err = r.fails(&["cmd", "nobody", "--v", "0.1"]);
    assert!(err.contains("nobody"), "{err}");
    stop.store(true, Ordering::Relaxed);
    let _ = h.join();
    r.down_and_check_clean();
}
