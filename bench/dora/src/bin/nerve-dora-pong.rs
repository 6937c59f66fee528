//! `nerve-dora-pong`: the answering side of the dora peer of `nerve bench
//! hop` (see the crate's doc). For every input on `in` it sends on `out`:
//! in `pingpong`, a sample of the same size with the input's first 8 bytes
//! (the sequence number) written in place, nothing else touched (as nerve's
//! pong does); in `periodic`, a 16-byte reply `[stamp, now - stamp]`: the
//! one-way latency from ping's stamp to this node's event loop. It exits when
//! its input closes (ping is done) or the dataflow stops.

use dora_node_api::dora_core::config::DataId;
use dora_node_api::{DoraNode, Event, MetadataParameters};
use nerve_dora_nodes::{Mode, Result, first_u64, mode, now_ns};
use std::process::ExitCode;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("nerve-dora-pong: error: {e}");
            ExitCode::from(1)
        }
    }
}

fn run() -> Result<()> {
    nerve_dora_nodes::realtime_from_env("nerve-dora-pong")?;
    let mode = mode()?;
    let (mut node, mut events) = DoraNode::init_from_env().map_err(|e| format!("cannot start the dora node: {e}"))?;
    nerve_dora_nodes::write_pid("pong")?;
    let out = DataId::from("out".to_owned());
    while let Some(event) = events.recv() {
        match event {
            Event::Input { data, .. } => {
                let t = now_ns();
                let b: &[u8] = (&data).try_into().map_err(|e| format!("ping's sample is not bytes: {e}"))?;
                let key = first_u64(b);
                let sent = match mode {
                    Mode::PingPong => node.send_output_raw(out.clone(), MetadataParameters::default(), b.len(), |o| {
                        o[..8].copy_from_slice(&key.to_le_bytes())
                    }),
                    Mode::Periodic => {
                        let mut reply = [0u8; 16];
                        reply[..8].copy_from_slice(&key.to_le_bytes());
                        reply[8..].copy_from_slice(&t.saturating_sub(key).to_le_bytes());
                        node.send_output_raw(out.clone(), MetadataParameters::default(), 16, |o| {
                            o.copy_from_slice(&reply)
                        })
                    }
                };
                sent.map_err(|e| format!("cannot answer: {e}"))?;
            }
            Event::Stop(_) => break,
            Event::Error(e) => eprintln!("nerve-dora-pong: dora: {e}"),
            _ => {}
        }
    }
    Ok(())
}
