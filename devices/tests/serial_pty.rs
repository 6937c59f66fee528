//! The host-side serial helper against a real pseudo-terminal pair
//! (`openpty`): message exchange both ways, and the error kinds a user sees.

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsRawFd, OwnedFd};
use std::path::PathBuf;
use std::time::Duration;

use nerve_devices::{FrameDecoder, Message, SerialLink, SerialOpenError, SonarScan, WheelCommand, open_serial};
use nix::pty::openpty;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

/// A raw pty pair: (device end = master, slave path, slave fd kept open).
fn pty() -> (File, PathBuf, OwnedFd) {
    let p = openpty(None, None).expect("openpty");
    let mut t = tcgetattr(&p.slave).expect("tcgetattr");
    cfmakeraw(&mut t);
    tcsetattr(&p.slave, SetArg::TCSANOW, &t).expect("tcsetattr");
    let path = nix::unistd::ttyname(&p.slave).expect("ttyname");
    (File::from(p.master), path, p.slave)
}

#[test]
fn messages_flow_both_ways_over_a_pty() {
    let (mut dev, path, _slave) = pty();
    let mut host = SerialLink::open(&path).expect("open pty slave");

    let scan = SonarScan { seq: 42, ranges_mm: [1234; 12] };
    for seq in 0..3u16 {
        dev.write_all(&Message::from(SonarScan { seq, ..scan }).encode()).expect("write");
    }
    for seq in 0..3u16 {
        let m = host.recv(Duration::from_secs(5)).expect("recv");
        assert_eq!(m, Some(Message::from(SonarScan { seq, ..scan })));
    }
    assert_eq!(host.recv(Duration::from_millis(50)).expect("recv"), None);

    let cmd = WheelCommand { left_mm_s: 200, right_mm_s: -200 };
    host.send(&cmd.into()).expect("send");
    let mut dec = FrameDecoder::new();
    let mut buf = [0u8; 64];
    let mut got = Vec::new();
    while got.is_empty() {
        let n = dev.read(&mut buf).expect("read master");
        got.extend(dec.push(&buf[..n]));
    }
    assert_eq!(got, vec![Message::from(cmd)]);
    assert_eq!(host.stats().garbage_bytes, 0);
}

#[test]
fn device_closing_is_reported_to_the_host() {
    let (dev, path, slave) = pty();
    let mut host = SerialLink::open(&path).expect("open");
    drop(slave);
    drop(dev);
    assert!(host.recv(Duration::from_secs(1)).is_err());
}

#[test]
fn second_open_is_busy() {
    let (_dev, path, _slave) = pty();
    let _first = open_serial(&path).expect("first open");
    match open_serial(&path) {
        Err(SerialOpenError::Busy { path: p }) => assert_eq!(p, path),
        other => panic!("expected Busy, got {other:?}"),
    }
}

#[test]
fn missing_and_non_tty_paths_have_clear_errors() {
    let missing = PathBuf::from("/nonexistent/nerve/sonar");
    let err = open_serial(&missing).expect_err("must fail");
    assert!(matches!(err, SerialOpenError::NotFound { .. }), "{err:?}");
    assert!(err.to_string().contains("/nonexistent/nerve/sonar"));

    let dir = std::env::temp_dir().join(format!("nerve-dev-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    let dangling = dir.join("sonar");
    let _ = std::fs::remove_file(&dangling);
    std::os::unix::fs::symlink("/dev/pts/999999", &dangling).expect("symlink");
    assert!(matches!(open_serial(&dangling), Err(SerialOpenError::NotFound { .. })));

    let plain = dir.join("plain-file");
    std::fs::write(&plain, b"x").expect("write");
    let err = open_serial(&plain).expect_err("a regular file is no tty");
    assert!(matches!(err, SerialOpenError::NotATerminal { .. }), "{err:?}");
    let _ = std::fs::remove_dir_all(&dir);

    // a character device that is not a terminal
    let err = open_serial(std::path::Path::new("/dev/null")).expect_err("/dev/null is no tty");
    assert!(matches!(err, SerialOpenError::NotATerminal { .. }), "{err:?}");

    // keep the fd helper honest about what it returns
    let (dev, _, _s) = pty();
    assert!(dev.as_raw_fd() >= 0);
}
