//! The measurement: rounds of one batch per row, the rows of each size in
//! an order that changes every round ([`Rounds::order`]), a warm-up round
//! first (none with `--quick`), and Cyclone DDS's batch after each size.

use super::pinger::Pingers;
use super::{DISCARD, HopOpts, count_of};
use crate::dds::{self, DdsPeer};
use crate::machine::steal_ms;
use crate::payloads::label;
use crate::procs::Robot;
use crate::stats::Rounds;
use anyhow::{Context as _, Result};
use std::time::Instant;

/// What the rounds measured.
#[derive(Debug)]
pub(super) struct Measured {
    /// the samples of each pinger, pooled and per round
    pub(super) rounds: Rounds,
    /// (round trips on one CPU, round trips) per pinger, measured rounds
    pub(super) placement: Vec<(usize, usize)>,
    /// per measured round: the time the hypervisor took, ms
    pub(super) round_steal_ms: Vec<f64>,
    /// Cyclone DDS per size: its intervals and the median of each round
    pub(super) dds: Vec<(usize, Vec<dds::Interval>, Vec<u64>)>,
}

impl Measured {
    /// Nothing measured yet, for `pingers` rows and `sizes`.
    pub(super) fn new(pingers: usize, sizes: &[usize]) -> Self {
        Measured {
            rounds: Rounds::new(pingers, DISCARD),
            placement: vec![(0, 0); pingers],
            round_steal_ms: Vec::new(),
            dds: sizes.iter().map(|&s| (s, Vec::new(), Vec::new())).collect(),
        }
    }
}

/// Runs every round, keeping what each batch measured in `into` (which
/// holds what was measured when a batch fails).
pub(super) fn measure(
    robot: &Robot,
    opts: &HopOpts,
    counts: &[(usize, usize)],
    pingers: &mut Pingers,
    dds_peer: Option<&DdsPeer>,
    into: &mut Measured,
) -> Result<()> {
    // a quick run has no warm-up round (the first samples of each batch are still dropped)
    for round in usize::from(opts.quick)..=opts.rounds {
        let t_round = Instant::now();
        let steal0 = steal_ms();
        for &size in &opts.sizes {
            let idx: Vec<usize> = (0..pingers.len()).filter(|&i| pingers[i].0 == size).collect();
            for i in Rounds::order(&idx, round) {
                let v = pingers[i]
                    .2
                    .batch(robot, count_of(counts, size))
                    .with_context(|| format!("{} at {} B, round {round}", pingers[i].1, size))?;
                into.rounds.keep(i, round, &v);
                if round > 0
                    && let Some(same) = pingers[i].2.same_cpu()
                {
                    into.placement[i].0 += same;
                    into.placement[i].1 += v.len();
                }
            }
            if let Some(peer) = dds_peer {
                dds_batch(peer, opts, size, round, into)?;
            }
        }
        let what = if round == 0 { "warm-up".to_owned() } else { format!("round {round}/{}", opts.rounds) };
        let stolen = steal0.zip(steal_ms()).map(|(a, b)| b - a);
        let stolen_note = stolen.map(|s| format!(" (time stolen by the host: {s:.0} ms)")).unwrap_or_default();
        eprintln!("hop: {what} done in {:.1} s{stolen_note}", t_round.elapsed().as_secs_f64());
        if let (Some(s), true) = (stolen, round > 0) {
            into.round_steal_ms.push(s);
        }
        if round > 0 {
            print_round(opts, pingers, &into.rounds);
        }
    }
    Ok(())
}

/// One Cyclone DDS batch at `size` (a few seconds of `ddsperf`).
fn dds_batch(peer: &DdsPeer, opts: &HopOpts, size: usize, round: usize, into: &mut Measured) -> Result<()> {
    let secs = if opts.quick {
        1
    } else if size > 1_000_000 {
        4
    } else {
        2
    };
    let v = peer.batch(size, secs).with_context(|| format!("ddsperf at {size} B, round {round}"))?;
    if round > 0
        && let Some(d) = into.dds.iter_mut().find(|d| d.0 == size)
    {
        d.2.push(dds::summarise(&v).p50_ns);
        d.1.extend(v);
    }
    Ok(())
}

/// The medians of the round just measured, one line per size (stderr).
fn print_round(opts: &HopOpts, pingers: &Pingers, rounds: &Rounds) {
    for &size in &opts.sizes {
        let line: Vec<String> = pingers
            .iter()
            .enumerate()
            .filter(|(_, p)| p.0 == size)
            .map(|(i, p)| format!("{} {:.1}us", p.1, rounds.round_p50[i].last().copied().unwrap_or(0) as f64 / 1e3))
            .collect();
        eprintln!("  {:>7}: {}", label(size), line.join(", "));
    }
}
