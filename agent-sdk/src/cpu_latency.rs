//! PM QoS: a real-time agent keeps the CPUs from sleeping deeply while it runs.
//!
//! Most of a hop's time on an idle machine is not nerve's code but the
//! wake-up of a CPU that the idle driver has halted (issue 17, BENCHMARKS.md
//! §1: 46 µs round trip by default, 14 µs while `/dev/cpu_dma_latency` is
//! held at 0). Linux's PM QoS interface lets a process bound the exit
//! latency of the idle states the CPUs may enter: open
//! `/dev/cpu_dma_latency`, write the bound in microseconds, and keep the
//! file open. The kernel honours the smallest bound of all open requests and
//! drops a request when its file is closed, so a crashed or killed agent
//! never leaves the machine pinned: the hold lives exactly as long as the
//! process.
//!
//! Every real-time agent (one without `--no-realtime`) holds a bound of
//! 0 µs by default; `--cpu-latency US` sets another bound and
//! `--cpu-latency off` (or `NERVE_CPU_LATENCY=off` for a whole robot, or
//! `cpu_latency = "off"` in a launch file) holds nothing. Where the process
//! may not write the file, the agent says so once, plainly, and runs on.
//! `nerve ps` shows each agent's hold.
//!
//! The trade: a CPU kept out of deep idle states answers a wake-up in a few
//! microseconds but does not save the power a halted CPU saves (on this
//! machine's `haltpoll` driver, an idle vCPU polls instead of halting).

use shm_schemas::stats::CpuLatency;
use std::fs::File;
use std::io::Write as _;
use std::path::PathBuf;
use std::str::FromStr;

/// The PM QoS device of the CPUs' wake-up latency.
pub const DEVICE: &str = "/dev/cpu_dma_latency";
/// Environment variable naming another device file (for tests, and kernels
/// that name it differently).
pub const DEVICE_ENV: &str = "NERVE_CPU_LATENCY_DEVICE";
/// The largest bound accepted, µs (one second: anything above is no bound).
pub const MAX_US: u32 = 1_000_000;

/// What an agent asks of PM QoS: `--cpu-latency`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CpuLatencySetting {
    /// Hold nothing.
    Off,
    /// Hold a bound of this many microseconds.
    Bound(u32),
}

impl FromStr for CpuLatencySetting {
    type Err = String;

    /// `off`, or a number of microseconds with an optional `us`/`µs`.
    fn from_str(s: &str) -> Result<Self, String> {
        let t = s.trim();
        if t.eq_ignore_ascii_case("off") || t.eq_ignore_ascii_case("none") {
            return Ok(CpuLatencySetting::Off);
        }
        let digits = t.strip_suffix("us").or_else(|| t.strip_suffix("µs")).unwrap_or(t).trim();
        match digits.parse::<u32>() {
            Ok(us) if us <= MAX_US => Ok(CpuLatencySetting::Bound(us)),
            Ok(_) => Err(format!("{s:?} is above {MAX_US} µs; write `off` to hold nothing")),
            Err(_) => Err(format!("{s:?} is neither `off` nor a number of microseconds (0, 20us)")),
        }
    }
}

impl std::fmt::Display for CpuLatencySetting {
    /// As `--cpu-latency` reads it: `off` or the microseconds.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CpuLatencySetting::Off => f.write_str("off"),
            CpuLatencySetting::Bound(us) => write!(f, "{us}"),
        }
    }
}

/// Why a bound could not be held.
#[derive(Debug, thiserror::Error)]
pub enum CpuLatencyError {
    /// The device could not be opened for writing.
    #[error(
        "cannot open {path} ({source}): an idle CPU may take tens of µs to wake this agent; run the robot as root, \
         give its user write access to {path} (a udev rule: KERNEL==\"cpu_dma_latency\", GROUP=\"nerve\", MODE=\"0660\"), \
         or pass --cpu-latency off to silence this"
    )]
    Open {
        /// the device
        path: String,
        /// the cause
        #[source]
        source: std::io::Error,
    },
    /// The bound could not be written.
    #[error("cannot write a bound of {us} µs to {path}: {source}")]
    Write {
        /// the device
        path: String,
        /// the bound
        us: u32,
        /// the cause
        #[source]
        source: std::io::Error,
    },
}

/// A held bound: the kernel honours it until this is dropped (or the process ends).
#[derive(Debug)]
pub struct CpuLatencyHold {
    _file: File,
}

/// The device file: [`DEVICE_ENV`] when set, else [`DEVICE`].
pub fn device() -> PathBuf {
    std::env::var_os(DEVICE_ENV).map(PathBuf::from).unwrap_or_else(|| PathBuf::from(DEVICE))
}

/// Holds a wake-up latency bound of `us` microseconds until the returned
/// hold is dropped. The file is opened close-on-exec: a child the agent
/// starts does not inherit the request.
pub fn hold(us: u32) -> Result<CpuLatencyHold, CpuLatencyError> {
    let path = device();
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .map_err(|source| CpuLatencyError::Open { path: path.display().to_string(), source })?;
    // the kernel reads four bytes as a binary s32 (anything else as a hex string)
    let value = i32::try_from(us).unwrap_or(i32::MAX);
    file.write_all(&value.to_ne_bytes()).map_err(|source| CpuLatencyError::Write {
        path: path.display().to_string(),
        us,
        source,
    })?;
    Ok(CpuLatencyHold { _file: file })
}

/// Applies `setting` for a real-time agent and says what came of it: the
/// hold to keep for the agent's life (if any) and the state `nerve ps`
/// reports. A refusal is logged once, as a warning that says what to do.
pub fn apply(setting: CpuLatencySetting) -> (Option<CpuLatencyHold>, CpuLatency) {
    match setting {
        CpuLatencySetting::Off => (None, CpuLatency::Off),
        CpuLatencySetting::Bound(us) => match hold(us) {
            Ok(h) => {
                tracing::debug!(us, device = %device().display(), "holding the CPUs' wake-up latency (PM QoS)");
                (Some(h), CpuLatency::Held { us })
            }
            Err(e) => {
                tracing::warn!("{e}");
                (None, CpuLatency::Refused)
            }
        },
    }
}

/// The bound the kernel honours now (the smallest open request, or its
/// default of 2000 s), µs; `None` when the device cannot be read.
pub fn current_bound_us() -> Option<u32> {
    let bytes = std::fs::read(device()).ok()?;
    let raw: [u8; 4] = bytes.get(..4)?.try_into().ok()?;
    u32::try_from(i32::from_ne_bytes(raw)).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_read_as_users_write_them() {
        assert_eq!("off".parse(), Ok(CpuLatencySetting::Off));
        assert_eq!("OFF".parse(), Ok(CpuLatencySetting::Off));
        assert_eq!("0".parse(), Ok(CpuLatencySetting::Bound(0)));
        assert_eq!("20us".parse(), Ok(CpuLatencySetting::Bound(20)));
        assert_eq!("20 µs".parse(), Ok(CpuLatencySetting::Bound(20)));
        assert!("2000000".parse::<CpuLatencySetting>().expect_err("above the limit").contains("above"));
        assert!("-1".parse::<CpuLatencySetting>().is_err());
        assert!("fast".parse::<CpuLatencySetting>().expect_err("not a number").contains("neither"));
        for s in [CpuLatencySetting::Off, CpuLatencySetting::Bound(0), CpuLatencySetting::Bound(50)] {
            assert_eq!(s.to_string().parse(), Ok(s), "the command line reads back what it writes");
        }
    }
}
