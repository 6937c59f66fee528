//! The `nerve-sim` binary (an agent of kind `sim`) as a real process, run
//! alone (no router: it runs unregistered) in a robot world of its own: it
//! publishes the sonar pty, which delivers 12-range frames at 4 Hz of
//! simulated time; it accepts a wheel command after which the encoder counts
//! change; SIGTERM stops it cleanly (links removed, truth log written, no
//! camera ring left); a second robot in the same world is served to its
//! own robot (devices, camera ring, truth).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nerve_devices::{Message, SerialLink, WheelCommand};

struct Sim {
    child: Child,
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Removes a test robot's files from /dev/shm when dropped, even when the
/// test fails (iceoryx2 keeps a management file per robot after a clean exit).
struct ShmGuard(String);

impl Drop for ShmGuard {
    fn drop(&mut self) {
        let prefix = shm_schemas::RobotName::shm_prefix_of(shm_schemas::names::effective_uid(), &self.0);
        if let Ok(rd) = std::fs::read_dir("/dev/shm") {
            for e in rd.filter_map(|e| e.ok()) {
                if e.file_name().to_string_lossy().starts_with(&prefix) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
    }
}

fn world() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/test-room.toml")
}

/// Waits (bounded) for the simulator to publish `link`.
fn wait_for(link: &Path) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while std::fs::symlink_metadata(link).is_err() {
        assert!(Instant::now() < deadline, "{} never appeared", link.display());
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn sim_binary_serves_sonar_and_motor_over_ptys() {
    let robot = format!("simbin-{}", std::process::id());
    let _shm = ShmGuard(robot.clone());
    let dir = std::env::temp_dir().join(format!("nerve-sim-bin-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("tmp dir");
    let dev = dir.join("dev");
    let truth = dir.join("truth.csv");
    let mut sim = Sim {
        child: Command::new(env!("CARGO_BIN_EXE_nerve-sim"))
            .args(["--robot", &robot, "--no-realtime", "--log-level", "warn", "--"])
            .env("NERVE_HOME", &dir)
            .arg("--world")
            .arg(world())
            .args(["--robot-model", "h1", "--seed", "3", "--duration", "600"])
            .arg("--dev-dir")
            .arg(&dev)
            .arg("--truth")
            .arg(&truth)
            .stdin(Stdio::null())
            .spawn()
            .expect("start nerve-sim"),
    };
    for name in ["sonar", "motor", "head", "ir"] {
        wait_for(&dev.join(name));
    }

    // Sonar: 12 ranges per frame, consecutive sequence numbers (one scan per
    // 250 ms of simulated time, none lost).
    let mut sonar = SerialLink::open(&dev.join("sonar")).expect("open sonar");
    let mut started = None;
    let mut seqs = Vec::new();
    let mut west_ok = 0;
    while seqs.len() < 8 {
        match sonar.recv(Duration::from_secs(10)).expect("sonar read") {
            Some(Message::SonarScan(s)) => {
                assert_eq!(s.ranges_mm.len(), 12);
                // sonar 6 faces the west wall, behind the robot standing at
                // x = 1 (radius 0.25): about 750 mm, unless a rare wrong reading
                if (700..=800).contains(&s.ranges_mm[6]) {
                    west_ok += 1;
                }
                started.get_or_insert_with(Instant::now);
                seqs.push(s.seq);
            }
            Some(other) => panic!("unexpected message on sonar: {other:?}"),
            None => panic!("no sonar frame within 10 s"),
        }
    }
    assert!(west_ok >= 6, "west wall at ~750 mm in {west_ok}/8 scans");
    let took = started.map_or(0.0, |t| t.elapsed().as_secs_f64());
    eprintln!("8 sonar frames in {took:.2} s of wall time ({:.1} Hz)", 7.0 / took.max(1e-3));
    for w in seqs.windows(2) {
        assert_eq!(w[1], w[0].wrapping_add(1), "consecutive scans: {seqs:?}");
    }
    assert_eq!(sonar.stats().garbage_bytes, 0);

    // Motor: encoder counts change after a wheel command.
    let mut motor = SerialLink::open(&dev.join("motor")).expect("open motor");
    let first = loop {
        if let Some(Message::EncoderReport(r)) = motor.recv(Duration::from_secs(10)).expect("read") {
            break r;
        }
    };
    motor.send(&WheelCommand { left_mm_s: 200, right_mm_s: 200 }.into()).expect("send");
    let mut moved = None;
    for _ in 0..400 {
        match motor.recv(Duration::from_secs(10)).expect("read") {
            Some(Message::EncoderReport(r)) if r.left > first.left + 100 => {
                moved = Some(r);
                break;
            }
            Some(_) => {}
            None => break,
        }
    }
    let moved = moved.expect("encoder counts increased after the wheel command");
    assert!(moved.right > first.right + 100);
    assert!(moved.time_ms > first.time_ms);

    // Closing and reopening the sonar port works.
    drop(sonar);
    let mut sonar = SerialLink::open(&dev.join("sonar")).expect("reopen sonar");
    assert!(matches!(sonar.recv(Duration::from_secs(10)).expect("read"), Some(Message::SonarScan(_))));
    drop(sonar);
    drop(motor);

    // SIGTERM: clean exit, links removed, truth log complete.
    let pid = nix::unistd::Pid::from_raw(sim.child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).expect("SIGTERM");
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(s) = sim.child.try_wait().expect("wait") {
            break s;
        }
        assert!(Instant::now() < deadline, "nerve-sim did not stop on SIGTERM");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "exit status {status}");
    for name in ["sonar", "motor", "head", "ir"] {
        assert!(std::fs::symlink_metadata(dev.join(name)).is_err(), "{name} link removed");
    }
    let ring = format!(
        "/dev/shm/{}stm_simcam",
        shm_schemas::RobotName::shm_prefix_of(
            shm_schemas::names::effective_uid(),
            &format!("simbin-{}", std::process::id())
        )
    );
    assert!(std::fs::metadata(&ring).is_err(), "{ring} removed at stop");
    let csv = std::fs::read_to_string(&truth).expect("truth log");
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(nerve_sim::TRUTH_HEADER));
    let last = lines.last().expect("rows");
    let x: f64 = last.split(',').nth(1).expect("x column").parse().expect("number");
    assert!(x > 1.0, "the robot drove forward from x = 1: {last}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_world_file_is_reported_with_its_name() {
    let robot = format!("simbad-{}", std::process::id());
    let _shm = ShmGuard(robot.clone());
    let dir = std::env::temp_dir().join(format!("nerve-sim-badworld-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    let w = dir.join("broken.toml");
    std::fs::write(&w, "[robot]\nx = 1\ny = 1\nspeed = 2\n").expect("write");
    let out = Command::new(env!("CARGO_BIN_EXE_nerve-sim"))
        .args(["--robot", &robot, "--no-realtime", "--"])
        .env("NERVE_HOME", &dir)
        .arg("--world")
        .arg(&w)
        .arg("--dev-dir")
        .arg(dir.join("dev"))
        .output()
        .expect("run nerve-sim");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("broken.toml") && err.contains("speed"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The last row's `x` of a truth log, once it has rows.
fn last_x(csv: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(csv).ok()?;
    let last = text.lines().skip(1).filter(|l| l.split(',').count() >= 19).last()?;
    last.split(',').nth(1)?.parse().ok()
}

#[test]
fn two_robots_in_one_world_each_served_to_its_own_robot() {
    let pid = std::process::id();
    let (r1, r2) = (format!("simtwo1-{pid}"), format!("simtwo2-{pid}"));
    let (_shm1, _shm2) = (ShmGuard(r1.clone()), ShmGuard(r2.clone()));
    let dir = std::env::temp_dir().join(format!("nerve-sim-two-{pid}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("tmp dir");
    let (dev1, dev2) = (dir.join("dev1"), dir.join("dev2"));
    let world = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/cooperate.toml");
    let mut sim = Sim {
        child: Command::new(env!("CARGO_BIN_EXE_nerve-sim"))
            .args(["--robot", &r1, "--no-realtime", "--log-level", "warn", "--"])
            .env("NERVE_HOME", &dir)
            .arg("--world")
            .arg(&world)
            .args(["--robot-model", "h1", "--seed", "4", "--duration", "600"])
            .arg("--dev-dir")
            .arg(&dev1)
            .arg("--truth")
            .arg(dir.join("truth.csv"))
            .arg("--extra-robot")
            .arg(format!("{r2}:h2:{}", dev2.display()))
            .stdin(Stdio::null())
            .spawn()
            .expect("start nerve-sim"),
    };
    for name in ["sonar", "motor", "head", "ir"] {
        wait_for(&dev1.join(name));
    }
    for name in ["motor", "ir", "arm"] {
        wait_for(&dev2.join(name));
    }
    assert!(std::fs::symlink_metadata(dev2.join("sonar")).is_err(), "robot 2 (H2) has no sonar");
    let ring2 = format!(
        "/dev/shm/{}stm_simcam",
        shm_schemas::RobotName::shm_prefix_of(shm_schemas::names::effective_uid(), &r2)
    );
    let deadline = Instant::now() + Duration::from_secs(30);
    while std::fs::metadata(&ring2).is_err() {
        assert!(Instant::now() < deadline, "robot 2's camera ring {ring2} never appeared");
        std::thread::sleep(Duration::from_millis(20));
    }

    // robot 2's motor moves robot 2 only
    let mut motor2 = SerialLink::open(&dev2.join("motor")).expect("open robot 2's motor");
    assert!(matches!(motor2.recv(Duration::from_secs(10)).expect("read"), Some(Message::EncoderReport(_))));
    motor2.send(&WheelCommand { left_mm_s: 300, right_mm_s: 300 }.into()).expect("send");
    let (truth1, truth2) = (dir.join("truth.csv"), dir.join(format!("truth-{r2}.csv")));
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if last_x(&truth2).is_some_and(|x| x > -3.5) {
            break;
        }
        assert!(Instant::now() < deadline, "robot 2 never moved: {:?}", last_x(&truth2));
        std::thread::sleep(Duration::from_millis(50));
    }
    drop(motor2);

    let pid = nix::unistd::Pid::from_raw(sim.child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).expect("SIGTERM");
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(s) = sim.child.try_wait().expect("wait") {
            break s;
        }
        assert!(Instant::now() < deadline, "nerve-sim did not stop on SIGTERM");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "exit status {status}");
    let x1 = last_x(&truth1).expect("robot 1's truth");
    assert!(x1.abs() < 1e-3, "robot 1 was not commanded and stayed at x = 0: {x1}");
    assert!(last_x(&truth2).is_some_and(|x| x > -3.5));
    for name in ["motor", "ir", "arm"] {
        assert!(std::fs::symlink_metadata(dev2.join(name)).is_err(), "robot 2's {name} link removed");
    }
    assert!(std::fs::metadata(&ring2).is_err(), "{ring2} removed at stop");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_extra_robot_without_a_start_is_refused() {
    let robot = format!("simnostart-{}", std::process::id());
    let _shm = ShmGuard(robot.clone());
    let dir = std::env::temp_dir().join(format!("nerve-sim-nostart-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    let out = Command::new(env!("CARGO_BIN_EXE_nerve-sim"))
        .args(["--robot", &robot, "--no-realtime", "--"])
        .env("NERVE_HOME", &dir)
        .arg("--world")
        .arg(world())
        .arg("--dev-dir")
        .arg(dir.join("dev"))
        .args(["--extra-robot", "other-robot:h2"])
        .output()
        .expect("run nerve-sim");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("other-robot") && err.contains("[[robot]]") && err.contains("test-room.toml"), "{err}");
    let out = Command::new(env!("CARGO_BIN_EXE_nerve-sim"))
        .args(["--robot", &robot, "--no-realtime", "--"])
        .env("NERVE_HOME", &dir)
        .arg("--world")
        .arg(world())
        .arg("--dev-dir")
        .arg(dir.join("dev"))
        .args(["--extra-robot", "Bad_Name:h2"])
        .output()
        .expect("run nerve-sim");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("Bad_Name"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
