//! One hop with an observer running and without it, batch by batch
//! interleaved: what watching the robot costs its data path. The observer
//! is `nerve record --all` (scenario `record`) or `nerve ui` with a browser
//! showing the page (scenario `ui`); both targets are ≤ 1.05x. Both
//! reports write each size as an [`ObservedHop`], which differ only in the
//! name of the observed round trips (`with_recorder`, `with_ui`).

use crate::hop::{NervePing, default_count, size_tag, spawn_bench_agent};
use crate::payloads::label;
use crate::procs::{ChildGuard, Robot};
use crate::stats::{Rounds, Summary, median_f64, ratio, us};
use anyhow::{Context as _, Result};
use serde::Serialize;
use std::path::Path;
use std::time::{Duration, Instant};

/// Samples dropped at the start of every batch.
const DISCARD: usize = 5;

/// One payload size's round trips without and with the observer.
#[derive(Debug, Clone)]
pub struct Observed {
    /// payload bytes
    pub size: usize,
    /// round trips without the observer, ns
    pub without: Summary,
    /// round trips while it runs, ns
    pub with: Summary,
    /// with / without, pooled medians
    pub ratio_p50: f64,
    /// median of the per-round ratios
    pub ratio_p50_round_median: f64,
}

/// Measures the SDK ping-pong at every size in `sizes`, `rounds` rounds
/// (after a warm-up unless `quick`), each round one batch without and one
/// with the processes `observe` starts (in alternating order), which are
/// stopped after their batch. Agents are named `PREFIX-p-SIZE`/`PREFIX-q-SIZE`.
pub fn hop_with_and_without(
    robot: &Robot,
    sizes: &[usize],
    rounds: usize,
    quick: bool,
    work: &Path,
    scenario: &str,
    observe: &mut dyn FnMut() -> Result<Vec<ChildGuard>>,
) -> Result<Vec<Observed>> {
    let mut children: Vec<ChildGuard> = Vec::new();
    let mut pings: Vec<(usize, NervePing)> = Vec::new();
    let mut names = Vec::new();
    for &size in sizes {
        let t = size_tag(size);
        let count = default_count(size, quick);
        let (p, q) = (format!("{scenario}p-{t}"), format!("{scenario}q-{t}"));
        for (role, name) in [("ping", &p), ("pong", &q)] {
            let dir = work.join(name);
            std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
            children.push(spawn_bench_agent(robot, role, name, size, count, &dir)?);
            names.push(name.clone());
        }
        pings.push((size, NervePing::new(p.clone(), work.join(&p))));
        robot.wait_registered(&[p.as_str(), q.as_str()], Duration::from_secs(20))?;
        robot.run(&["connect", "--allow-cycle", &format!("{p}/out"), &format!("{q}/in")])?;
        robot.run(&["connect", "--allow-cycle", &format!("{q}/out"), &format!("{p}/in")])?;
    }
    // system i: ping i / 2 without (even) or with (odd) the observer
    let mut kept = Rounds::new(pings.len() * 2, DISCARD);
    for round in usize::from(quick)..=rounds {
        let t_round = Instant::now();
        for (k, (size, ping)) in pings.iter_mut().enumerate() {
            for i in Rounds::order(&[2 * k, 2 * k + 1], round) {
                let mut observer = if i % 2 == 1 { observe()? } else { Vec::new() };
                let v = ping.run_batch(robot).with_context(|| format!("hop at {size} B, round {round}"))?;
                for g in &mut observer {
                    g.check_alive().context("the observer died during the batch")?;
                }
                for mut g in observer {
                    g.stop(Duration::from_secs(5));
                }
                kept.keep(i, round, &v);
            }
        }
        let what = if round == 0 { "warm-up".to_owned() } else { format!("round {round}/{rounds}") };
        eprintln!("{scenario}: hop {what} done in {:.1} s", t_round.elapsed().as_secs_f64());
    }
    for mut c in children.drain(..) {
        c.stop(Duration::from_secs(2));
    }
    Ok(pings
        .iter()
        .enumerate()
        .map(|(k, (size, _))| {
            let (a, b) = (2 * k, 2 * k + 1);
            let without = Summary::of(&kept.samples[a]);
            let with = Summary::of(&kept.samples[b]);
            let per_round: Vec<f64> =
                kept.round_p50[b].iter().zip(&kept.round_p50[a]).map(|(w, wo)| ratio(*w, *wo)).collect();
            Observed {
                size: *size,
                ratio_p50: ratio(with.p50_ns, without.p50_ns),
                without,
                with,
                ratio_p50_round_median: median_f64(&per_round),
            }
        })
        .collect())
}

/// One payload size as the `record` and `ui` reports write it. `W` holds
/// the round trips with the observer under the report's own JSON name
/// ([`WithObserver`]), the name its results files have always had.
#[derive(Debug, Clone, Serialize)]
pub struct ObservedHop<W> {
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// round trips without the observer, ns
    pub without: Summary,
    /// round trips while it runs, ns, under the observer's name
    #[serde(flatten)]
    pub with: W,
    /// with / without, pooled medians
    pub ratio_p50: f64,
    /// median of the per-round ratios
    pub ratio_p50_round_median: f64,
    /// whether the pooled ratio is within the target
    pub target_met: bool,
}

/// The round trips with an observer, serialized as one field named after
/// the observer (`with_recorder`, `with_ui`).
pub trait WithObserver: Serialize {
    /// Holds `with`.
    fn new(with: Summary) -> Self;
    /// The round trips, ns.
    fn summary(&self) -> &Summary;
}

impl<W: WithObserver> ObservedHop<W> {
    /// The report's row of `m`, judged against `target` (with / without).
    pub fn of(m: Observed, target: f64) -> Self {
        ObservedHop {
            size: m.size,
            label: label(m.size).into(),
            target_met: m.ratio_p50 <= target,
            without: m.without,
            with: W::new(m.with),
            ratio_p50: m.ratio_p50,
            ratio_p50_round_median: m.ratio_p50_round_median,
        }
    }

    /// Its row in the table [`print_table`] prints.
    pub fn row(&self) -> TableRow<'_> {
        TableRow {
            label: &self.label,
            without: &self.without,
            with: self.with.summary(),
            ratio_p50: self.ratio_p50,
            ratio_p50_round_median: self.ratio_p50_round_median,
            target_met: self.target_met,
        }
    }
}

/// One payload size in the table [`print_table`] prints.
#[derive(Debug)]
pub struct TableRow<'a> {
    /// payload label
    pub label: &'a str,
    /// round trips without the observer
    pub without: &'a Summary,
    /// round trips with it
    pub with: &'a Summary,
    /// with / without, pooled medians
    pub ratio_p50: f64,
    /// median of the per-round ratios
    pub ratio_p50_round_median: f64,
    /// whether the pooled ratio is within the target
    pub target_met: bool,
}

/// Prints the hop with and without the observer as a markdown table under `title`.
pub fn print_table<'a>(title: &str, target: f64, rows: impl IntoIterator<Item = TableRow<'a>>) {
    println!("### {title}\n");
    println!(
        "| payload | without p50 | with p50 | without p99 | with p99 | with / without (p50) | per-round median | ≤ {target}x |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for h in rows {
        println!(
            "| {} | {} | {} | {} | {} | {:.3} | {:.3} | {} |",
            h.label,
            us(h.without.p50_ns),
            us(h.with.p50_ns),
            us(h.without.p99_ns),
            us(h.with.p99_ns),
            h.ratio_p50,
            h.ratio_p50_round_median,
            if h.target_met { "yes" } else { "**no**" }
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::HopCost;
    use crate::ui_cost::UiHop;

    /// The keys of `v`, sorted.
    fn keys(v: &serde_json::Value) -> Vec<String> {
        let mut k: Vec<String> = v.as_object().map(|o| o.keys().cloned().collect()).unwrap_or_default();
        k.sort_unstable();
        k
    }

    /// The keys of the first `hop` entry of the results file `name`.
    fn kept_keys(name: &str) -> Vec<String> {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("results").join(name);
        let text = std::fs::read_to_string(&path).expect("the results file is in the tree");
        let v: serde_json::Value = serde_json::from_str(&text).expect("a results file is JSON");
        keys(&v["hop"][0])
    }

    #[test]
    fn the_rows_keep_the_fields_of_the_results_files() {
        let (without, with) = (Summary::of(&[10, 20, 30]), Summary::of(&[11, 21, 31]));
        let m = Observed { size: 8, without, with, ratio_p50: 1.05, ratio_p50_round_median: 1.02 };
        let record = HopCost::of(m.clone(), 1.05);
        assert!(record.target_met, "a ratio at the target meets it");
        assert_eq!(record.row().with.p50_ns, 21);
        let v = serde_json::to_value(&record).expect("a row encodes");
        assert_eq!(keys(&v), kept_keys("record.json"));
        assert_eq!(v["with_recorder"]["p50_ns"], 21);
        let ui = UiHop::of(Observed { ratio_p50: 1.06, ..m }, 1.05);
        assert!(!ui.target_met, "a ratio over the target misses it");
        let v = serde_json::to_value(&ui).expect("a row encodes");
        assert_eq!(keys(&v), kept_keys("ui.json"));
        assert_eq!(v["with_ui"]["p50_ns"], 21);
    }
}
