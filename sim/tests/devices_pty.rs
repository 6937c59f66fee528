//! The device hub over real pseudo-terminals, driven step by step: the
//! host side is the `nerve-devices` serial helper, as in an agent.

mod common;

use std::path::{Path, PathBuf};
use std::time::Duration;

use common::{h1, room};
use nerve_devices::{HeadCommand, Message, SerialLink, WheelCommand};
use nerve_sim::{DeviceHub, DeviceKind, NoiseModel};

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("nerve-sim-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Exactly `n` messages (each waited for up to 5 s: the pty layer hands
/// bytes over asynchronously), then checks nothing more is queued.
fn recv_exactly(link: &mut SerialLink, n: usize) -> Vec<Message> {
    let mut out = Vec::new();
    while out.len() < n {
        match link.recv(Duration::from_secs(5)).expect("read") {
            Some(m) => out.push(m),
            None => panic!("only {} of {n} messages arrived: {out:?}", out.len()),
        }
    }
    let extra = link.recv(Duration::from_millis(100)).expect("read");
    assert_eq!(extra, None, "more than {n} messages");
    out
}

/// Everything the host can read now.
fn drain(link: &mut SerialLink) -> Vec<Message> {
    let mut out = Vec::new();
    while let Some(m) = link.recv(Duration::from_millis(100)).expect("read") {
        out.push(m);
    }
    out
}

#[test]
fn hub_publishes_devices_and_answers_protocols() {
    let dir = temp_dir("hub");
    let mut sim = h1(room(6.0, 2.0, 3.0, 0.0, ""), 1, NoiseModel::none());
    let mut hub = DeviceHub::open(&dir, &sim).expect("publish");
    for name in ["sonar", "motor", "head", "ir"] {
        assert!(std::fs::symlink_metadata(dir.join(name)).is_ok(), "{name} published");
    }
    assert!(!dir.join("arm").exists(), "H1 has no arm");

    let mut sonar = SerialLink::open(&dir.join("sonar")).expect("open sonar");
    let mut motor = SerialLink::open(&dir.join("motor")).expect("open motor");
    let mut head = SerialLink::open(&dir.join("head")).expect("open head");

    // one simulated second: exactly 4 sonar scans (4 Hz), 20 encoder reports
    for _ in 0..100 {
        hub.step(&mut sim);
    }
    let scans: Vec<_> = recv_exactly(&mut sonar, 4)
        .into_iter()
        .filter_map(|m| match m {
            Message::SonarScan(s) => Some(s),
            _ => None,
        })
        .collect();
    assert_eq!(scans.len(), 4);
    assert_eq!(scans.iter().map(|s| s.seq).collect::<Vec<_>>(), vec![1, 2, 3, 4]);
    assert_eq!(scans[0].ranges_mm[0], 6_000 - 2_000 - 250);
    let reports = recv_exactly(&mut motor, 20);
    let Some(Message::EncoderReport(first)) = reports.last().copied() else {
        panic!("encoder reports expected, got {reports:?}");
    };
    assert_eq!((first.left, first.right), (0, 0));
    assert_eq!(first.time_ms, 1000);

    // a wheel command makes the encoders count and the robot move
    motor.send(&WheelCommand { left_mm_s: 300, right_mm_s: 300 }.into()).expect("send");
    head.send(&HeadCommand { pan_cdeg: 3000, tilt_cdeg: -1000 }.into()).expect("send");
    // step until the commands arrived and took effect (bounded, not timed)
    for _ in 0..5000 {
        hub.step(&mut sim);
        if sim.pose().x > 2.3 && sim.head_position().0 > 0.5 {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let Some(Message::EncoderReport(later)) = drain(&mut motor).last().copied() else {
        panic!("encoder reports expected");
    };
    assert!(later.left > 1000 && later.right > 1000, "{later:?}");
    assert!(sim.pose().x > 2.2);
    let Some(Message::HeadState(h)) = drain(&mut head).last().copied() else {
        panic!("head state expected");
    };
    assert_eq!((h.pan_cdeg, h.tilt_cdeg), (3000, -1000));
    assert_eq!(hub.device(DeviceKind::Motor).expect("motor").decode_stats().frames, 1);

    drop(hub);
    assert!(std::fs::symlink_metadata(dir.join("sonar")).is_err(), "links removed");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn host_may_close_and_reopen() {
    let dir = temp_dir("reopen");
    let mut sim = h1(room(6.0, 2.0, 3.0, 0.0, ""), 1, NoiseModel::none());
    let mut hub = DeviceHub::open(&dir, &sim).expect("publish");

    // nobody listening: nothing is queued for a later reader
    for _ in 0..100 {
        hub.step(&mut sim);
    }
    let dev = hub.device(DeviceKind::Sonar).expect("sonar");
    assert_eq!(dev.stats().sent, 0);
    assert_eq!(dev.stats().unheard, 4);

    for round in 1..=3u64 {
        let mut sonar = SerialLink::open(&dir.join("sonar")).expect("open");
        for _ in 0..50 {
            hub.step(&mut sim);
        }
        let got = recv_exactly(&mut sonar, 2);
        assert!(got.iter().all(|m| matches!(m, Message::SonarScan(_))), "round {round}: only fresh scans: {got:?}");
        assert_eq!(hub.device(DeviceKind::Sonar).expect("sonar").stats().connects, round);
        drop(sonar);
        for _ in 0..30 {
            hub.step(&mut sim);
        }
    }
    // a second agent on the same device is refused while the first holds it
    let _first = SerialLink::open(&dir.join("motor")).expect("open");
    assert!(matches!(SerialLink::open(&dir.join("motor")), Err(nerve_devices::SerialOpenError::Busy { .. })));
    drop(hub);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_stale_link_is_replaced_and_a_file_in_the_way_is_an_error() {
    let dir = temp_dir("stale");
    std::fs::create_dir_all(&dir).expect("dir");
    std::os::unix::fs::symlink("/dev/pts/999999", dir.join("sonar")).expect("stale link");
    std::fs::write(dir.join("motor"), b"not a link").expect("file");
    let sim = h1(room(6.0, 2.0, 3.0, 0.0, ""), 1, NoiseModel::none());
    let err = DeviceHub::open(&dir, &sim).expect_err("motor is occupied");
    let msg = err.to_string();
    assert!(msg.contains("motor") && msg.contains("not a symlink"), "{msg}");
    std::fs::remove_file(dir.join("motor")).expect("rm");
    let hub = DeviceHub::open(&dir, &sim).expect("stale link replaced");
    let target = std::fs::read_link(dir.join("sonar")).expect("link");
    assert!(target.starts_with("/dev/pts") && target != Path::new("/dev/pts/999999"));
    drop(hub);
    let _ = std::fs::remove_dir_all(&dir);
}
