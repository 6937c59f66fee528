//! `nerve-dora-ping`: the measuring side of the dora peer of `nerve bench
//! hop` (see the crate's doc for the settings). It sends samples of
//! `NERVE_DORA_SIZE` bytes on its output `out`, one at a time, each answered
//! by `nerve-dora-pong` on its input `echo`: first `NERVE_DORA_WARMUP`
//! dropped, then `NERVE_DORA_COUNT` kept; it writes the kept samples (ns) to
//! `NERVE_DORA_OUT` and exits, which ends the dataflow (pong's input closes,
//! pong exits, `dora run` returns).

use dora_node_api::dora_core::config::DataId;
use dora_node_api::{DoraNode, Event, EventStream, MetadataParameters};
use nerve_dora_nodes::{Mode, Result, env, env_num, first_u64, mode, now_ns, second_u64, sleep_until_ns};
use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("nerve-dora-ping: error: {e}");
            ExitCode::from(1)
        }
    }
}

struct Settings {
    mode: Mode,
    size: usize,
    count: usize,
    warmup: usize,
    period_ns: u64,
    out: PathBuf,
}

fn settings() -> Result<Settings> {
    let size: usize = env_num("NERVE_DORA_SIZE", 8)?;
    if size < 8 {
        return Err(format!("NERVE_DORA_SIZE={size}: at least 8 bytes (the sequence number or stamp)"));
    }
    Ok(Settings {
        mode: mode()?,
        size,
        count: env_num::<usize>("NERVE_DORA_COUNT", 100)?.max(1),
        warmup: env_num("NERVE_DORA_WARMUP", 20)?,
        period_ns: env_num::<u64>("NERVE_DORA_PERIOD_US", 5000)?.max(1) * 1000,
        out: PathBuf::from(env("NERVE_DORA_OUT")?),
    })
}

fn run() -> Result<()> {
    nerve_dora_nodes::realtime_from_env("nerve-dora-ping")?;
    let s = settings()?;
    let (mut node, mut events) = DoraNode::init_from_env().map_err(|e| format!("cannot start the dora node: {e}"))?;
    nerve_dora_nodes::write_pid("ping")?;
    let out = DataId::from("out".to_owned());
    let total = s.warmup + s.count;
    let mut kept = Vec::with_capacity(s.count);
    match s.mode {
        Mode::PingPong => {
            for seq in 1..=total as u64 {
                let t0 = now_ns();
                node.send_output_raw(out.clone(), MetadataParameters::default(), s.size, |o| {
                    o[..8].copy_from_slice(&seq.to_le_bytes())
                })
                .map_err(|e| format!("cannot send sample {seq}: {e}"))?;
                wait_reply(&mut events, seq, kept.len())?;
                let rtt = now_ns().saturating_sub(t0);
                if seq > s.warmup as u64 {
                    kept.push(rtt);
                }
            }
        }
        Mode::Periodic => {
            let mut next = now_ns() + s.period_ns;
            for i in 0..total {
                sleep_until_ns(next);
                let stamp = now_ns();
                node.send_output_raw(out.clone(), MetadataParameters::default(), s.size, |o| {
                    o[..8].copy_from_slice(&stamp.to_le_bytes())
                })
                .map_err(|e| format!("cannot send sample {}: {e}", i + 1))?;
                let one_way = wait_reply(&mut events, stamp, kept.len())?;
                if i >= s.warmup {
                    kept.push(one_way);
                }
                // the next deadline still ahead (the SDK's periodic tasks skip missed ones too)
                let now = now_ns();
                next += s.period_ns;
                while next <= now {
                    next += s.period_ns;
                }
            }
        }
    }
    nerve_dora_nodes::write_values(&s.out, &kept)
}

/// Waits for pong's answer to the sample `key` (its sequence number or
/// stamp); returns the answer's second number (pong's one-way latency in
/// `periodic`, 0 for an echo). Older answers are skipped.
fn wait_reply(events: &mut EventStream, key: u64, done: usize) -> Result<u64> {
    loop {
        match events.recv() {
            Some(Event::Input { data, .. }) => {
                let b: &[u8] = (&data).try_into().map_err(|e| format!("pong's answer is not bytes: {e}"))?;
                if first_u64(b) == key {
                    return Ok(if b.len() == 16 { second_u64(b) } else { 0 });
                }
            }
            Some(Event::Stop(cause)) => {
                return Err(format!("the dataflow was stopped ({cause:?}) after {done} samples"));
            }
            Some(Event::Error(e)) => return Err(format!("dora: {e}")),
            Some(_) => {}
            None => return Err(format!("the event stream closed after {done} samples")),
        }
    }
}
