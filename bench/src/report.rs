//! The head every scenario's report starts with, and the report around a
//! scenario's own results: `Report<T>` is written as one flat JSON object
//! (`scenario`, `command`, `machine`, then the fields of `T`), the shape the
//! result files have always had. Beside it, the rows of the scenarios that
//! measure ping-pong pairs of SDK agents (`c`, `messages`): the pairs run
//! batch by batch in interleaved rounds ([`interleaved_rows`], over
//! [`Rounds`]) and each pair becomes a [`PairRow`].

use crate::hop::NervePing;
use crate::machine::{Machine, command_line};
use crate::procs::Robot;
use crate::stats::{Rounds, Summary, median_f64, ratio, us};
use anyhow::{Context as _, Result};
use serde::Serialize;
use std::time::Instant;

/// What every report says first: which scenario, the command that produced
/// it, and the machine it ran on.
#[derive(Debug, Clone, Serialize)]
pub struct Head {
    /// the scenario's name (`hop`, `jitter`...); the control scenario's
    /// files never had one, and still have none
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scenario: Option<&'static str>,
    /// the command that produced it
    pub command: String,
    /// the machine
    pub machine: Machine,
}

/// A scenario's report: the [`Head`], then the scenario's results `T`,
/// flattened into one JSON object. It reads as `T` (`report.rounds`).
#[derive(Debug, Clone, Serialize)]
pub struct Report<T> {
    /// scenario, command, machine
    #[serde(flatten)]
    pub head: Head,
    /// the scenario's own results
    #[serde(flatten)]
    pub body: T,
}

impl<T> Report<T> {
    /// The report of `scenario` run by this process's command line on `machine`.
    pub fn new(scenario: &'static str, machine: Machine, body: T) -> Self {
        Report { head: Head { scenario: Some(scenario), command: command_line(), machine }, body }
    }

    /// A report without a scenario field (the control scenario's shape).
    pub fn unnamed(machine: Machine, body: T) -> Self {
        Report { head: Head { scenario: None, command: command_line(), machine }, body }
    }
}

impl<T> std::ops::Deref for Report<T> {
    type Target = T;

    fn deref(&self) -> &T {
        &self.body
    }
}

/// A row's ping-pong pair at one size, started, wired and waiting for its
/// batches: the ping runs a batch of round trips when asked.
pub struct Pair {
    /// the row (`rust`, `c`, `seq`...)
    pub row: &'static str,
    /// payload bytes
    pub size: usize,
    /// the ping agent, which runs the batches
    pub ping: NervePing,
    /// the pong agent's name
    pub pong: String,
}

impl Pair {
    /// Wires the pair as users wire agents, with `nerve connect`: the
    /// ping's `out` to the pong's `in`, and the pong's `out` back to the
    /// ping's `in` (a cycle on purpose: the pong echoes).
    pub fn wire_echo(&self, robot: &Robot) -> Result<()> {
        let (ping, pong) = (&self.ping.name, &self.pong);
        robot.run(&["connect", &format!("{ping}/out"), &format!("{pong}/in")])?;
        robot.run(&["connect", "--allow-cycle", &format!("{pong}/out"), &format!("{ping}/in")])?;
        Ok(())
    }
}

/// One row at one size: its pooled round trips and the median of each round.
#[derive(Debug, Clone, Serialize)]
pub struct PairRow {
    /// the row (`rust`, `c`, `cpp`; `fixed`, `seq`, `call`)
    pub row: &'static str,
    /// payload bytes
    pub size: usize,
    /// round trips per batch
    pub batch: usize,
    /// the round trips of every measured round, pooled, ns
    pub round_trip: Summary,
    /// the median of each measured round, ns
    pub round_p50_ns: Vec<u64>,
}

impl PairRow {
    /// The table cells `p50 | p99` (µs) of `row` at `size` in `rows`, `- | -` where it did not run.
    pub fn cells(rows: &[PairRow], row: &str, size: usize) -> String {
        rows.iter()
            .find(|x| x.row == row && x.size == size)
            .map(|x| format!("{} | {}", us(x.round_trip.p50_ns), us(x.round_trip.p99_ns)))
            .unwrap_or_else(|| "- | -".into())
    }
}

/// How the pairs are measured: the sizes in their order, the measured
/// rounds, and whether a warm-up round comes first (not with `quick`).
#[derive(Debug, Clone, Copy)]
pub struct Plan<'a> {
    /// the scenario's name, at the start of every progress line
    pub scenario: &'a str,
    /// the sizes, in the order their batches run in a round
    pub sizes: &'a [usize],
    /// measured rounds
    pub rounds: usize,
    /// smoke run: no warm-up round
    pub quick: bool,
    /// samples dropped at the start of every batch
    pub discard: usize,
}

/// Runs every pair's batches in interleaved rounds: in each round, size by
/// size, the pairs of that size run one batch each in an order that rotates
/// every round ([`Rounds::order`]); round 0 is a warm-up (dropped, and not
/// run with `quick`), and the first `discard` samples of every batch are
/// dropped. A line on stderr says when each round is done. Gives one
/// [`PairRow`] per pair, in the pairs' order, `batch(size)` round trips
/// per batch.
pub fn interleaved_rows(
    plan: Plan<'_>,
    robot: &Robot,
    pairs: &mut [Pair],
    batch: impl Fn(usize) -> usize,
) -> Result<Vec<PairRow>> {
    let mut rounds = Rounds::new(pairs.len(), plan.discard);
    for round in usize::from(plan.quick)..=plan.rounds {
        let t0 = Instant::now();
        for &size in plan.sizes {
            let idx: Vec<usize> = (0..pairs.len()).filter(|&i| pairs[i].size == size).collect();
            for i in Rounds::order(&idx, round) {
                let p = &mut pairs[i];
                let v = p.ping.run_batch(robot).with_context(|| format!("{} at {} B, round {round}", p.row, p.size))?;
                rounds.keep(i, round, &v);
            }
        }
        let what = if round == 0 { "warm-up".to_owned() } else { format!("round {round}/{}", plan.rounds) };
        eprintln!("{}: {what} done in {:.1} s", plan.scenario, t0.elapsed().as_secs_f64());
    }
    Ok(pairs
        .iter()
        .enumerate()
        .map(|(i, p)| PairRow {
            row: p.row,
            size: p.size,
            batch: batch(p.size),
            round_trip: Summary::of(&rounds.samples[i]),
            round_p50_ns: rounds.round_p50[i].clone(),
        })
        .collect())
}

/// The median of the per-round ratios `a[k] / b[k]` of two rows' round
/// medians (each round's two batches a few seconds apart).
pub fn round_median(a: &[u64], b: &[u64]) -> f64 {
    let v: Vec<f64> = a.iter().zip(b).map(|(x, y)| ratio(*x, *y)).collect();
    median_f64(&v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Clone, Serialize)]
    struct Body {
        rounds: usize,
        seconds: f64,
    }

    #[test]
    fn a_report_is_one_flat_object_with_the_head_first() {
        let r = Report::new("hop", Machine::probe(), Body { rounds: 3, seconds: 1.5 });
        let text = serde_json::to_string(&r).expect("a report encodes");
        let at: Vec<usize> = ["\"scenario\":", "\"command\":", "\"machine\":", "\"rounds\":", "\"seconds\":"]
            .iter()
            .map(|k| text.find(k).unwrap_or_else(|| panic!("{k} missing in {text}")))
            .collect();
        assert!(at.windows(2).all(|w| w[0] < w[1]), "fields out of order: {text}");
        let v: serde_json::Value = serde_json::from_str(&text).expect("JSON");
        assert_eq!(v["scenario"], "hop");
        assert!(v["machine"]["nproc"].is_u64());
        assert_eq!(r.rounds, 3);
        let unnamed = serde_json::to_value(Report::unnamed(Machine::probe(), Body { rounds: 1, seconds: 0.0 }))
            .expect("a report encodes");
        assert!(unnamed.get("scenario").is_none(), "the control scenario's files have no scenario field");
    }
}
