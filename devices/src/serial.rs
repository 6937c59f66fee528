//! Host side of a device's serial line: open a port by path with clear
//! errors, and exchange framed messages over it.
//!
//! A real robot's boards appear as `/dev/ttyUSB*`; the simulator publishes a
//! pseudo-terminal per device as a symlink (for example `DIR/sonar`). Both are
//! opened the same way, with [`open_serial`] or [`SerialLink::open`]. Ports are
//! opened exclusively (`TIOCEXCL` + `flock`), so a second agent opening the
//! same device gets [`SerialOpenError::Busy`] instead of silently sharing it.

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

use crate::frame::{DecodeStats, FrameDecoder};
use crate::messages::Message;

/// Line speed requested when opening a port. The boards run at 115200 8N1;
/// a pseudo-terminal ignores it.
pub const BAUD_RATE: u32 = 115_200;

/// Why a serial device could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum SerialOpenError {
    /// Nothing at that path (or a dangling symlink).
    #[error(
        "serial device {path} does not exist: check the path, that the board is plugged in, \
         or that the simulator publishing it is running"
    )]
    NotFound {
        /// The path asked for.
        path: PathBuf,
    },
    /// Another process holds the port.
    #[error(
        "serial device {path} is busy: another process has it open \
         (find it with `fuser {path}` and stop it)"
    )]
    Busy {
        /// The path asked for.
        path: PathBuf,
    },
    /// The caller may not open it.
    #[error(
        "permission denied opening serial device {path}: add the user to the group owning it \
         (usually `dialout`) or run with the needed rights"
    )]
    PermissionDenied {
        /// The path asked for.
        path: PathBuf,
    },
    /// The path is not a terminal device.
    #[error("{path} is not a serial device (it is not a terminal); point to a tty or a simulator link")]
    NotATerminal {
        /// The path asked for.
        path: PathBuf,
    },
    /// Anything else the OS reported.
    #[error("cannot open serial device {path}: {message}")]
    Other {
        /// The path asked for.
        path: PathBuf,
        /// The OS's description.
        message: String,
    },
}

/// Maps a `serialport` error to the kind a user can act on.
fn classify(path: &Path, e: &serialport::Error) -> SerialOpenError {
    let path = path.to_path_buf();
    match e.kind() {
        serialport::ErrorKind::NoDevice => SerialOpenError::Busy { path },
        serialport::ErrorKind::Io(io::ErrorKind::NotFound) => SerialOpenError::NotFound { path },
        serialport::ErrorKind::Io(io::ErrorKind::PermissionDenied) => SerialOpenError::PermissionDenied { path },
        _ if e.description.contains("Inappropriate ioctl") || e.description.contains("Not a typewriter") => {
            SerialOpenError::NotATerminal { path }
        }
        _ => SerialOpenError::Other { path, message: e.description.clone() },
    }
}

/// Opens the serial device at `path` (raw mode, 115200 8N1, exclusive, reads
/// time out after 100 ms).
pub fn open_serial(path: &Path) -> Result<TTYPort, SerialOpenError> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            return Err(SerialOpenError::NotFound { path: path.to_path_buf() });
        }
        Err(e) if e.kind() == io::ErrorKind::PermissionDenied => {
            return Err(SerialOpenError::PermissionDenied { path: path.to_path_buf() });
        }
        Ok(meta) => {
            use std::os::unix::fs::FileTypeExt;
            if !meta.file_type().is_char_device() {
                return Err(SerialOpenError::NotATerminal { path: path.to_path_buf() });
            }
        }
        Err(_) => {}
    }
    let Some(name) = path.to_str() else {
        return Err(SerialOpenError::Other { path: path.to_path_buf(), message: "the path is not valid UTF-8".into() });
    };
    let port = serialport::new(name, BAUD_RATE)
        .timeout(Duration::from_millis(100))
        .open_native()
        .map_err(|e| classify(path, &e))?;
    tracing::debug!(path = %path.display(), "serial device opened");
    Ok(port)
}

/// A framed message link over an open serial port.
#[derive(Debug)]
pub struct SerialLink {
    port: TTYPort,
    decoder: FrameDecoder,
    path: PathBuf,
    buf: Vec<u8>,
}

impl SerialLink {
    /// Opens `path` with [`open_serial`].
    pub fn open(path: &Path) -> Result<Self, SerialOpenError> {
        Ok(Self::from_port(open_serial(path)?, path))
    }

    /// Wraps a port opened elsewhere.
    pub fn from_port(port: TTYPort, path: &Path) -> Self {
        Self { port, decoder: FrameDecoder::new(), path: path.to_path_buf(), buf: vec![0; 512] }
    }

    /// The path the link was opened with.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Frames and writes one message.
    pub fn send(&mut self, msg: &Message) -> io::Result<()> {
        self.port.write_all(&msg.encode())?;
        self.port.flush()
    }

    /// The next message, waiting at most `timeout`; `Ok(None)` on timeout.
    /// `Err` with `BrokenPipe` (or similar) means the device end closed.
    pub fn recv(&mut self, timeout: Duration) -> io::Result<Option<Message>> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(m) = self.decoder.next_message() {
                return Ok(Some(m));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let wait = (deadline - now).max(Duration::from_millis(1));
            self.port.set_timeout(wait).map_err(|e| io::Error::other(e.description))?;
            match self.port.read(&mut self.buf) {
                Ok(0) => return Err(io::Error::from(io::ErrorKind::BrokenPipe)),
                Ok(n) => {
                    // Frames are consumed lazily by next_message above.
                    let _ = self.decoder.push(&self.buf[..n]);
                }
                Err(e) if e.kind() == io::ErrorKind::TimedOut => return Ok(None),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    }

    /// Discards, unread, every byte the line holds now: what the device
    /// sent before the port was opened (while it was cut, or before the
    /// agent started), which the kernel kept for whoever opens the port
    /// next. Call it right after opening. Returns the complete frames
    /// discarded; they count as decoded `frames` too. A frame the device is
    /// sending at this very moment (its start is here, its end not yet)
    /// is kept: it is the freshest there is.
    pub fn discard_waiting(&mut self) -> io::Result<u64> {
        let waiting = self.port.bytes_to_read().map_err(|e| io::Error::other(e.description))?;
        let mut left = usize::try_from(waiting).unwrap_or(usize::MAX);
        let mut discarded = 0u64;
        // the bytes are there already: a read never waits long
        self.port.set_timeout(Duration::from_millis(10)).map_err(|e| io::Error::other(e.description))?;
        while left > 0 {
            let n = left.min(self.buf.len());
            match self.port.read(&mut self.buf[..n]) {
                Ok(0) => return Err(io::Error::from(io::ErrorKind::BrokenPipe)),
                Ok(got) => {
                    left = left.saturating_sub(got);
                    let _ = self.decoder.push(&self.buf[..got]);
                    while self.decoder.next_message().is_some() {
                        discarded = discarded.saturating_add(1);
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::TimedOut => break,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(discarded)
    }

    /// Decoder counters (garbage, bad checksums, truncated frames).
    pub fn stats(&self) -> DecodeStats {
        self.decoder.stats()
    }

    /// The underlying port, e.g. to change its timeout.
    pub fn port_mut(&mut self) -> &mut TTYPort {
        &mut self.port
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classify_kinds() {
        let p = Path::new("/dev/x");
        let e = |k, d: &str| serialport::Error::new(k, d);
        assert!(matches!(classify(p, &e(serialport::ErrorKind::NoDevice, "locked")), SerialOpenError::Busy { .. }));
        assert!(matches!(
            classify(p, &e(serialport::ErrorKind::Io(io::ErrorKind::PermissionDenied), "")),
            SerialOpenError::PermissionDenied { .. }
        ));
        assert!(matches!(
            classify(p, &e(serialport::ErrorKind::Io(io::ErrorKind::NotFound), "")),
            SerialOpenError::NotFound { .. }
        ));
        assert!(matches!(
            classify(p, &e(serialport::ErrorKind::Unknown, "Inappropriate ioctl for device")),
            SerialOpenError::NotATerminal { .. }
        ));
        assert!(matches!(
            classify(p, &e(serialport::ErrorKind::Unknown, "Not a typewriter")),
            SerialOpenError::NotATerminal { .. }
        ));
    }
}
