//! Summaries of latency samples: count, median, p99, max (nanoseconds).

use serde::Serialize;

/// The summary of one set of samples, in nanoseconds.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Summary {
    /// number of samples
    pub n: usize,
    /// minimum
    pub min_ns: u64,
    /// median
    pub p50_ns: u64,
    /// 99th percentile
    pub p99_ns: u64,
    /// maximum
    pub max_ns: u64,
}

/// The `q` quantile (0..=1) of sorted values, nearest rank.
pub fn percentile(sorted: &[u64], q: f64) -> u64 {
    agent_sdk::meters::percentile(sorted, q)
}

impl Summary {
    /// Summarises `samples` (any order).
    pub fn of(samples: &[u64]) -> Self {
        let mut v = samples.to_vec();
        v.sort_unstable();
        Summary {
            n: v.len(),
            min_ns: v.first().copied().unwrap_or(0),
            p50_ns: percentile(&v, 0.50),
            p99_ns: percentile(&v, 0.99),
            max_ns: v.last().copied().unwrap_or(0),
        }
    }
}

/// Batches of several systems measured in interleaved rounds: the order of
/// the systems rotates every round, the first samples of every batch are
/// dropped (warm-up), and round 0, a warm-up round, is dropped whole.
#[derive(Debug, Clone)]
pub struct Rounds {
    /// samples dropped at the start of every batch
    discard: usize,
    /// the kept samples of each system, pooled
    pub samples: Vec<Vec<u64>>,
    /// the median of each measured round, per system
    pub round_p50: Vec<Vec<u64>>,
}

impl Rounds {
    /// For `systems` systems, dropping the first `discard` samples of every batch.
    pub fn new(systems: usize, discard: usize) -> Self {
        Rounds { discard, samples: vec![Vec::new(); systems], round_p50: vec![Vec::new(); systems] }
    }

    /// The order in which the systems `idx` run in round `round`, rotated
    /// so that none always runs first.
    pub fn order(idx: &[usize], round: usize) -> impl Iterator<Item = usize> + '_ {
        (0..idx.len()).map(move |k| idx[(k + round) % idx.len()])
    }

    /// Keeps the batch `v` of system `i` in round `round`.
    pub fn keep(&mut self, i: usize, round: usize, v: &[u64]) {
        if round == 0 {
            return;
        }
        let kept = &v[self.discard.min(v.len())..];
        self.round_p50[i].push(Summary::of(kept).p50_ns);
        self.samples[i].extend_from_slice(kept);
    }
}

/// `a / b`, or 0 when `b` is 0.
pub fn ratio(a: u64, b: u64) -> f64 {
    if b == 0 { 0.0 } else { a as f64 / b as f64 }
}

/// Formats nanoseconds as microseconds with one decimal (`71.3`).
pub fn us(ns: u64) -> String {
    format!("{:.1}", ns as f64 / 1000.0)
}

/// Median of a few values (the per-round figures).
pub fn median_f64(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n % 2 == 1 { s[n / 2] } else { (s[n / 2 - 1] + s[n / 2]) / 2.0 }
}

/// A table cell of an optional ratio: two decimals, `-` when not measured.
pub fn ratio_cell(x: Option<f64>) -> String {
    x.map(|v| format!("{v:.2}")).unwrap_or_else(|| "-".into())
}

/// A table cell of an optional target check: `met`, `missed`, `-` when not measured.
pub fn verdict(met: Option<bool>) -> &'static str {
    match met {
        Some(true) => "met",
        Some(false) => "missed",
        None => "-",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary() {
        let s = Summary::of(&[5, 1, 3, 2, 4]);
        assert_eq!((s.n, s.min_ns, s.p50_ns, s.max_ns), (5, 1, 3, 5));
        assert_eq!(median_f64(&[3.0, 1.0, 2.0, 10.0]), 2.5);
    }

    #[test]
    fn rounds_rotate_drop_the_warm_up_and_the_first_samples() {
        let order: Vec<usize> = Rounds::order(&[3, 5, 7], 1).collect();
        assert_eq!(order, vec![5, 7, 3]);
        let mut r = Rounds::new(2, 2);
        r.keep(0, 0, &[100, 100, 100]); // warm-up round: dropped
        r.keep(0, 1, &[900, 900, 1, 2, 3]);
        r.keep(1, 1, &[5]); // shorter than the discard: nothing kept
        assert_eq!(r.samples[0], vec![1, 2, 3]);
        assert_eq!(r.round_p50[0], vec![2]);
        assert!(r.samples[1].is_empty());
    }
}
