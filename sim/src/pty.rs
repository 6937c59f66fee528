//! Devices over pseudo-terminals.
//!
//! Each emulated device gets its own pty pair from `openpty`. The slave side
//! is put in raw mode (no echo, no line editing, 8-bit clean) and published
//! as a symlink, e.g. `DIR/sonar -> /dev/pts/7`, so an agent opens it with
//! `serialport` exactly as it would open `/dev/ttyUSB0`. The simulator keeps
//! only the master side, non-blocking.
//!
//! The simulator closes its own slave descriptor right away, so the master
//! reports `POLLHUP` whenever no host has the port open. While nobody
//! listens, nothing is written (a reopening host would otherwise read stale
//! frames); when a host opens the port the device starts talking at its next
//! period, and when the host closes it, the half-received command is dropped
//! (counted as truncated). The host may close and reopen as often as it likes.

use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::AsFd;
use std::path::{Path, PathBuf};

use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::pty::openpty;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

use nerve_devices::{DecodeStats, FrameDecoder, Message};

use crate::robot::RobotModel;

/// The emulated devices.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DeviceKind {
    /// Sonar ring module (H1).
    Sonar,
    /// Motor DSP board (wheels).
    Motor,
    /// Head DSP board (pan-tilt, H1).
    Head,
    /// IR receiver.
    Ir,
    /// Arm controller (H2).
    Arm,
}

impl DeviceKind {
    /// File name of the published link: `sonar`, `motor`, `head`, `ir`, `arm`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Sonar => "sonar",
            Self::Motor => "motor",
            Self::Head => "head",
            Self::Ir => "ir",
            Self::Arm => "arm",
        }
    }

    /// The devices a robot model carries.
    pub fn for_model(model: &RobotModel) -> Vec<DeviceKind> {
        let mut v = Vec::new();
        if model.sonar.is_some() {
            v.push(Self::Sonar);
        }
        v.push(Self::Motor);
        if model.head.is_some() {
            v.push(Self::Head);
        }
        v.push(Self::Ir);
        if model.arm.is_some() {
            v.push(Self::Arm);
        }
        v
    }
}

impl std::fmt::Display for DeviceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a device could not be published.
#[derive(Debug, thiserror::Error)]
pub enum PtyError {
    /// `openpty` or the terminal set-up failed.
    #[error("cannot create a pseudo-terminal for the {device} device ({step}): {source}")]
    Pty {
        /// Device.
        device: DeviceKind,
        /// What was being done.
        step: &'static str,
        /// OS error.
        source: nix::Error,
    },
    /// The device directory could not be created.
    #[error("cannot create the device directory {dir}: {source}")]
    Dir {
        /// Directory.
        dir: PathBuf,
        /// OS error.
        source: io::Error,
    },
    /// Something that is not a symlink is in the way.
    #[error(
        "cannot publish the {device} device at {link}: a file that is not a symlink is there; \
         remove it or choose another --dev-dir"
    )]
    Occupied {
        /// Device.
        device: DeviceKind,
        /// Link path.
        link: PathBuf,
    },
    /// Creating the symlink failed.
    #[error("cannot publish the {device} device at {link}: {source}")]
    Link {
        /// Device.
        device: DeviceKind,
        /// Link path.
        link: PathBuf,
        /// OS error.
        source: io::Error,
    },
}

/// Traffic counters of one device.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PtyStats {
    /// Frames written to a connected host.
    pub sent: u64,
    /// Frames not written because the host's buffer was full or it vanished.
    pub dropped: u64,
    /// Frames produced while no host had the port open (not written).
    pub unheard: u64,
    /// Times a host opened the port.
    pub connects: u64,
}

/// One emulated device on a pseudo-terminal.
#[derive(Debug)]
pub struct PtyDevice {
    kind: DeviceKind,
    master: File,
    slave_path: PathBuf,
    link: PathBuf,
    decoder: FrameDecoder,
    connected: bool,
    stats: PtyStats,
    buf: Vec<u8>,
}

impl PtyDevice {
    /// Creates the pty and publishes its slave at `link`. A stale symlink
    /// (from a simulator that was killed) is replaced.
    pub fn open(kind: DeviceKind, link: &Path) -> Result<Self, PtyError> {
        let err = |step, source| PtyError::Pty { device: kind, step, source };
        let pair = openpty(None, None).map_err(|e| err("openpty", e))?;
        let mut t = tcgetattr(&pair.slave).map_err(|e| err("tcgetattr", e))?;
        cfmakeraw(&mut t);
        tcsetattr(&pair.slave, SetArg::TCSANOW, &t).map_err(|e| err("raw mode", e))?;
        let slave_path = nix::unistd::ttyname(&pair.slave).map_err(|e| err("ttyname", e))?;
        fcntl(&pair.master, FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).map_err(|e| err("non-blocking master", e))?;
        drop(pair.slave);

        match std::fs::symlink_metadata(link) {
            Ok(m) if m.file_type().is_symlink() => {
                tracing::warn!(link = %link.display(), "replacing a stale device link");
                std::fs::remove_file(link).map_err(|source| PtyError::Link {
                    device: kind,
                    link: link.to_path_buf(),
                    source,
                })?;
            }
            Ok(_) => {
                return Err(PtyError::Occupied { device: kind, link: link.to_path_buf() });
            }
            Err(_) => {}
        }
        std::os::unix::fs::symlink(&slave_path, link).map_err(|source| PtyError::Link {
            device: kind,
            link: link.to_path_buf(),
            source,
        })?;
        tracing::info!(device = %kind, link = %link.display(), tty = %slave_path.display(), "device published");
        Ok(Self {
            kind,
            master: File::from(pair.master),
            slave_path,
            link: link.to_path_buf(),
            decoder: FrameDecoder::new(),
            connected: false,
            stats: PtyStats::default(),
            buf: vec![0; 1024],
        })
    }

    /// Which device.
    pub fn kind(&self) -> DeviceKind {
        self.kind
    }
    /// The published link.
    pub fn link(&self) -> &Path {
        &self.link
    }
    /// The pty slave the link points to.
    pub fn slave_path(&self) -> &Path {
        &self.slave_path
    }
    /// Whether a host has the port open (as of the last [`Self::poll`]).
    pub fn connected(&self) -> bool {
        self.connected
    }
    /// Traffic counters.
    pub fn stats(&self) -> PtyStats {
        self.stats
    }
    /// Counters of the decoder of host commands.
    pub fn decode_stats(&self) -> DecodeStats {
        self.decoder.stats()
    }

    fn set_connected(&mut self, now: bool) {
        if now && !self.connected {
            self.stats.connects += 1;
            tracing::info!(device = %self.kind, "host opened the port");
        } else if !now && self.connected {
            tracing::info!(device = %self.kind, "host closed the port");
            self.decoder.reset_stream();
        }
        self.connected = now;
    }

    /// Notes whether a host is connected and returns the commands it sent.
    pub fn poll(&mut self) -> Vec<Message> {
        let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
        let hup = match poll(&mut fds, PollTimeout::ZERO) {
            Ok(_) => fds[0].revents().is_some_and(|r| r.contains(PollFlags::POLLHUP)),
            Err(e) => {
                tracing::warn!(device = %self.kind, error = %e, "poll failed");
                true
            }
        };
        self.set_connected(!hup);
        let mut out = Vec::new();
        while self.connected {
            match self.master.read(&mut self.buf) {
                Ok(0) => break,
                Ok(n) => out.extend(self.decoder.push(&self.buf[..n])),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(_) => {
                    // EIO: the host went away between poll and read.
                    self.set_connected(false);
                }
            }
        }
        out
    }

    /// Writes one message if a host is listening. Returns whether it was
    /// written whole.
    pub fn send(&mut self, msg: &Message) -> bool {
        if !self.connected {
            self.stats.unheard += 1;
            return false;
        }
        let bytes = msg.encode();
        match self.master.write(&bytes) {
            Ok(n) if n == bytes.len() => {
                self.stats.sent += 1;
                true
            }
            Ok(_) | Err(_) => {
                // A partial write leaves a truncated frame, which the host's
                // decoder counts and skips.
                self.stats.dropped += 1;
                if self.stats.dropped.is_power_of_two() {
                    tracing::warn!(device = %self.kind, dropped = self.stats.dropped,
                        "host is not reading; frames dropped");
                }
                false
            }
        }
    }
}

impl Drop for PtyDevice {
    fn drop(&mut self) {
        // Remove the link only if it is still ours.
        if std::fs::read_link(&self.link).is_ok_and(|t| t == self.slave_path)
            && let Err(e) = std::fs::remove_file(&self.link)
        {
            tracing::warn!(link = %self.link.display(), error = %e, "cannot remove device link");
        }
    }
}
