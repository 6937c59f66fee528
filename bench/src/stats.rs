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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary() {
        let s = Summary::of(&[5, 1, 3, 2, 4]);
        assert_eq!((s.n, s.min_ns, s.p50_ns, s.max_ns), (5, 1, 3, 5));
        assert_eq!(median_f64(&[3.0, 1.0, 2.0, 10.0]), 2.5);
    }
}
