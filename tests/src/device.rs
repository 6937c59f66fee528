//! Pseudo-terminals standing in for a robot's boards, and the frames of
//! nerve's serial protocol (docs/devices.md), for tests that feed device
//! agents what a real line may carry.

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// CRC-16/CCITT-FALSE, as in docs/devices.md.
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
        }
    }
    crc
}

pub fn frame(msg_type: u8, payload: &[u8]) -> Vec<u8> {
    let mut f = vec![0xA5, 0x5A, msg_type, payload.len() as u8];
    f.extend_from_slice(payload);
    let crc = crc16(&f[2..]);
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

/// A sonar scan frame: every range `mm`, sequence `seq`.
pub fn sonar_frame(seq: u16, mm: u16) -> Vec<u8> {
    let mut p = seq.to_le_bytes().to_vec();
    for _ in 0..12 {
        p.extend_from_slice(&mm.to_le_bytes());
    }
    frame(0x10, &p)
}

/// A pseudo-terminal standing in for a board: the test holds the master,
/// the agent opens the slave through the symlink `link`.
#[derive(Debug)]
pub struct FakeDevice {
    master: File,
    link: PathBuf,
    /// the slave's path, and (until published) its descriptor, held open so
    /// that what the test writes waits on the line
    tty: PathBuf,
    slave: Option<std::os::fd::OwnedFd>,
}

impl FakeDevice {
    pub fn new(link: &Path) -> FakeDevice {
        let mut dev = FakeDevice::unpublished(link);
        dev.publish();
        dev
    }

    /// A line the agent cannot find yet: what the test writes now waits on
    /// it for whoever opens it first (like a cut line that comes back
    /// holding what the board sent meanwhile). [`FakeDevice::publish`] makes
    /// it appear at `link`.
    pub fn unpublished(link: &Path) -> FakeDevice {
        use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
        let pair = nix::pty::openpty(None, None).expect("openpty");
        // not inherited by the agents this test starts: closing it here
        // must close the line
        // SAFETY: fcntl on descriptors we own.
        unsafe {
            libc::fcntl(pair.master.as_raw_fd(), libc::F_SETFD, libc::FD_CLOEXEC);
            libc::fcntl(pair.slave.as_raw_fd(), libc::F_SETFD, libc::FD_CLOEXEC);
        }
        let mut t = tcgetattr(&pair.slave).expect("tcgetattr");
        cfmakeraw(&mut t);
        tcsetattr(&pair.slave, SetArg::TCSANOW, &t).expect("raw mode");
        let tty = nix::unistd::ttyname(&pair.slave).expect("ttyname");
        FakeDevice { master: File::from(pair.master), link: link.to_path_buf(), tty, slave: Some(pair.slave) }
    }

    /// Publishes the line at its link, where the agent finds it.
    pub fn publish(&mut self) {
        if let Some(dir) = self.link.parent() {
            std::fs::create_dir_all(dir).expect("device dir");
        }
        let _ = std::fs::remove_file(&self.link);
        std::os::unix::fs::symlink(&self.tty, &self.link).expect("symlink");
        self.slave = None;
    }

    pub fn write(&mut self, bytes: &[u8]) {
        self.master.write_all(bytes).expect("write to the pty master");
    }

    /// The device vanishes: master closed, link removed.
    pub fn vanish(self) {
        let _ = std::fs::remove_file(&self.link);
        drop(self.master);
    }

    /// Reads what the agent writes, in a thread; returns the bytes so far.
    pub fn reader(self, stop: Arc<AtomicBool>) -> (Arc<Mutex<Vec<u8>>>, std::thread::JoinHandle<()>) {
        let got = Arc::new(Mutex::new(Vec::new()));
        let g = got.clone();
        let mut master = self.master;
        // non-blocking, so that the thread sees `stop`
        // SAFETY: fcntl on a descriptor we own.
        unsafe {
            let fd = master.as_raw_fd();
            let fl = libc::fcntl(fd, libc::F_GETFL);
            libc::fcntl(fd, libc::F_SETFL, fl | libc::O_NONBLOCK);
        }
        let h = std::thread::spawn(move || {
            let mut buf = [0u8; 1024];
            while !stop.load(Ordering::Relaxed) {
                match master.read(&mut buf) {
                    Ok(n) if n > 0 => g.lock().expect("lock").extend_from_slice(&buf[..n]),
                    _ => std::thread::sleep(Duration::from_millis(10)),
                }
            }
            let _ = std::fs::remove_file(&self.link);
        });
        (got, h)
    }
}
