//! The bridge scenario's results: one way across the bridge against raw
//! Zenoh (plain and TLS), throughput, and the local round trip with and
//! without a bridge on the port, each per size; and [`report`], which makes
//! them, with their ratios and targets, from a run's raw measurements.

use super::{BridgeOpts, LOCAL, LOCAL_TARGET, Measured, ONEWAY, ONEWAY_TARGET, TLS_TARGET, TPUT};
use crate::hop::size_tag;
use crate::machine::Machine;
use crate::payloads::label;
use crate::report::Report;
use crate::stats::{Summary, median_f64, ratio};
use serde::Serialize;
use std::time::Instant;

/// One-way latency of one system at one size.
#[derive(Debug, Clone, Serialize)]
pub struct OneWayResult {
    /// `bridge`, `zenoh` or `bridge-tls`
    pub system: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// all measured samples pooled (sender's stamp to arrival)
    pub latency: Summary,
    /// median of each round, ns
    pub round_p50_ns: Vec<u64>,
    /// samples sent in measured batches
    pub sent: u64,
    /// samples that never arrived
    pub lost: u64,
    /// bridges: sender's stamp to bridge B's publication (robot A's hop, bridge A, Zenoh, bridge B)
    pub to_bridge_b: Option<Summary>,
    /// bridges: bridge B's publication to the sink (robot B's hop)
    pub bridge_b_to_sink: Option<Summary>,
    /// bridges: from bridge A taking the sample off its input to bridge B
    /// receiving it, µs: the bridge's own `latency_us` figure at the end of
    /// the run (median of the topic's last 256 samples, so of the last batch
    /// only, CLOCK_REALTIME stamps); not comparable with the pooled medians
    pub bridge_a_to_b_us: Option<u64>,
}

/// Throughput of one system at one size.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputResult {
    /// `bridge` or `zenoh`
    pub system: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// samples delivered per second at the far end, median of the rounds
    pub delivered_per_s: f64,
    /// samples the sender put out per second, median of the rounds
    pub offered_per_s: f64,
    /// delivered / sent, over all measured batches
    pub delivered_fraction: f64,
    /// payload MB/s delivered (10^6 B), median of the rounds
    pub delivered_mb_per_s: f64,
    /// one-way latency of the delivered samples under that load, pooled
    pub latency_loaded: Summary,
    /// delivered per second of each round
    pub round_delivered_per_s: Vec<f64>,
}

/// The bridge against raw Zenoh at one size.
#[derive(Debug, Clone, Serialize)]
pub struct OneWayRatio {
    /// payload bytes
    pub size: usize,
    /// bridge p50 / zenoh p50 (pooled)
    pub bridge_vs_zenoh_p50: f64,
    /// bridge p99 / zenoh p99
    pub bridge_vs_zenoh_p99: f64,
    /// median over rounds of the per-round p50 ratio
    pub bridge_vs_zenoh_p50_round_median: f64,
    /// bridge delivered/s / zenoh delivered/s at full speed
    pub throughput_bridge_vs_zenoh: f64,
    /// what the bridge adds to raw Zenoh at the median, ns
    pub extra_p50_ns: i64,
    /// one local hop (half the `alone` round trip's median), ns; 0 when not measured
    pub local_hop_p50_ns: u64,
    /// whether bridge p50 ≤ target × zenoh p50
    pub target_met: bool,
    /// bridge-tls p50 / bridge p50 (pooled); 0 when not measured
    pub tls_vs_plain_p50: f64,
    /// bridge-tls p99 / bridge p99
    pub tls_vs_plain_p99: f64,
    /// median over rounds of the per-round p50 ratio bridge-tls / bridge
    pub tls_vs_plain_p50_round_median: f64,
    /// what TLS adds to the plain bridge at the median, ns
    pub tls_extra_p50_ns: i64,
    /// whether bridge-tls p50 ≤ TLS target × bridge p50
    pub tls_target_met: bool,
}

/// A local round trip at one size.
#[derive(Debug, Clone, Serialize)]
pub struct LocalResult {
    /// `alone`, `bridged`, `bridged-100hz`
    pub system: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// all measured round trips pooled
    pub rtt: Summary,
    /// median of each round, ns
    pub round_p50_ns: Vec<u64>,
}

/// The local round trip with a bridge against without, at one size.
#[derive(Debug, Clone, Serialize)]
pub struct LocalRatio {
    /// payload bytes
    pub size: usize,
    /// bridged p50 / alone p50 (pooled)
    pub bridged_vs_alone_p50: f64,
    /// bridged p99 / alone p99
    pub bridged_vs_alone_p99: f64,
    /// median over rounds of the per-round p50 ratio
    pub bridged_vs_alone_p50_round_median: f64,
    /// bridged-100hz p50 / alone p50
    pub limited_vs_alone_p50: f64,
    /// bridged-100hz p99 / alone p99
    pub limited_vs_alone_p99: f64,
    /// whether bridged p50 ≤ target × alone p50
    pub target_met: bool,
}

/// The bridge report: the [`Head`](crate::report::Head) and [`BridgeResults`].
pub type BridgeReport = Report<BridgeResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Clone, Serialize)]
pub struct BridgeResults {
    /// measured rounds
    pub rounds: usize,
    /// one-way samples per latency batch
    pub count: usize,
    /// µs between two samples of a latency batch
    pub interval_us: u64,
    /// longest throughput batch, ms
    pub tput_ms: u64,
    /// round trips per local batch
    pub hop_count: usize,
    /// one-way latency, per system and size
    pub oneway: Vec<OneWayResult>,
    /// throughput, per system and size
    pub throughput: Vec<ThroughputResult>,
    /// bridge against raw Zenoh, per size
    pub oneway_ratios: Vec<OneWayRatio>,
    /// local round trips, per system and size
    pub local: Vec<LocalResult>,
    /// bridged against alone, per size
    pub local_ratios: Vec<LocalRatio>,
    /// one-way target (bridge / zenoh, p50)
    pub oneway_target: f64,
    /// local target (bridged / alone, p50)
    pub local_target: f64,
    /// TLS target (bridge-tls / bridge, p50)
    pub tls_target: f64,
    /// bridge-tls p50 / bridge p50 per size, pooled, as top-level fields
    /// `tls_vs_plain_p50_8B`, `tls_vs_plain_p50_4KB`, `tls_vs_plain_p50_230KB`
    #[serde(flatten)]
    pub tls_vs_plain: std::collections::BTreeMap<String, f64>,
    /// `nerve bridge status --json` of robots A and B at the end (figures: messages, drops...)
    pub bridge_status: Vec<serde_json::Value>,
    /// wall time of the run, s
    pub seconds: f64,
}

/// `8B`, `4KB`, `230KB`: a size in a JSON field name (its label without spaces).
fn size_key(size: usize) -> String {
    label(size).replace(' ', "")
}

/// The `latency_us` figure of the import of `<kind>src-<size>` in the bridges' status.
fn link_latency_us(status: &[serde_json::Value], kind: &str, size: usize) -> Option<u64> {
    let suffix = format!("/{kind}src-{}/out", size_tag(size));
    status
        .iter()
        .filter_map(|s| s.as_array())
        .flatten()
        .filter_map(|b| b["imports"].as_array())
        .flatten()
        .find(|t| t["topic"].as_str().is_some_and(|t| t.ends_with(&suffix)))
        .and_then(|t| t["figures"]["latency_us"].as_str())
        .and_then(|v| v.parse().ok())
}

/// The report of a run from its raw measurements `m` and the bridges' status at the end.
pub(super) fn report(
    opts: &BridgeOpts,
    machine: Machine,
    m: Measured,
    bridge_status: Vec<serde_json::Value>,
    started: Instant,
) -> BridgeReport {
    let mut oneway = Vec::new();
    let mut throughput = Vec::new();
    let mut local = Vec::new();
    let mut oneway_ratios = Vec::new();
    let mut local_ratios = Vec::new();
    let mut tls_vs_plain = std::collections::BTreeMap::new();
    for (k, &size) in opts.sizes.iter().enumerate() {
        for (sys, name) in ONEWAY.iter().enumerate() {
            let i = 3 * k + sys;
            let (sent, lost) = m.loss[k][sys];
            let parts = match sys {
                0 => Some(4 * k),
                2 => Some(4 * k + 2),
                _ => None,
            };
            oneway.push(OneWayResult {
                system: (*name).into(),
                size,
                label: label(size).into(),
                latency: Summary::of(&m.oneway.samples[i]),
                round_p50_ns: m.oneway.round_p50[i].clone(),
                sent,
                lost,
                to_bridge_b: parts.map(|p| Summary::of(&m.parts.samples[p])),
                bridge_b_to_sink: parts.map(|p| Summary::of(&m.parts.samples[p + 1])),
                bridge_a_to_b_us: match sys {
                    0 => link_latency_us(&bridge_status, "l", size),
                    2 => link_latency_us(&bridge_status, "k", size),
                    _ => None,
                },
            });
        }
        for (sys, name) in TPUT.iter().enumerate() {
            let t = &m.tput[k][sys];
            let delivered: Vec<f64> = t.per_round.iter().map(|x| x.0).collect();
            let offered: Vec<f64> = t.per_round.iter().map(|x| x.1).collect();
            let d = median_f64(&delivered);
            throughput.push(ThroughputResult {
                system: (*name).into(),
                size,
                label: label(size).into(),
                delivered_per_s: d,
                offered_per_s: median_f64(&offered),
                delivered_fraction: if t.sent == 0 { 0.0 } else { t.received as f64 / t.sent as f64 },
                delivered_mb_per_s: d * size as f64 / 1e6,
                latency_loaded: Summary::of(&t.loaded),
                round_delivered_per_s: delivered,
            });
        }
        for (sys, name) in LOCAL.iter().enumerate() {
            let i = 3 * k + sys;
            local.push(LocalResult {
                system: (*name).into(),
                size,
                label: label(size).into(),
                rtt: Summary::of(&m.local.samples[i]),
                round_p50_ns: m.local.round_p50[i].clone(),
            });
        }
        let ow = |sys: &str| oneway.iter().find(|r| r.system == sys && r.size == size);
        let tp = |sys: &str| throughput.iter().find(|r| r.system == sys && r.size == size);
        let lo = |sys: &str| local.iter().find(|r| r.system == sys && r.size == size);
        if let (Some(b), Some(z), Some(tb), Some(tz), Some(alone)) =
            (ow("bridge"), ow("zenoh"), tp("bridge"), tp("zenoh"), lo("alone"))
        {
            let per_round: Vec<f64> = b.round_p50_ns.iter().zip(&z.round_p50_ns).map(|(x, y)| ratio(*x, *y)).collect();
            let r = ratio(b.latency.p50_ns, z.latency.p50_ns);
            let tls = ow("bridge-tls").filter(|t| t.latency.n > 0);
            let tls_p50 = tls.map_or(0.0, |t| ratio(t.latency.p50_ns, b.latency.p50_ns));
            let tls_rounds: Vec<f64> = tls.map_or_else(Vec::new, |t| {
                t.round_p50_ns.iter().zip(&b.round_p50_ns).map(|(x, y)| ratio(*x, *y)).collect()
            });
            tls_vs_plain.insert(format!("tls_vs_plain_p50_{}", size_key(size)), tls_p50);
            oneway_ratios.push(OneWayRatio {
                size,
                bridge_vs_zenoh_p50: r,
                bridge_vs_zenoh_p99: ratio(b.latency.p99_ns, z.latency.p99_ns),
                bridge_vs_zenoh_p50_round_median: median_f64(&per_round),
                throughput_bridge_vs_zenoh: if tz.delivered_per_s > 0.0 {
                    tb.delivered_per_s / tz.delivered_per_s
                } else {
                    0.0
                },
                extra_p50_ns: b.latency.p50_ns as i64 - z.latency.p50_ns as i64,
                local_hop_p50_ns: alone.rtt.p50_ns / 2,
                target_met: r <= ONEWAY_TARGET,
                tls_vs_plain_p50: tls_p50,
                tls_vs_plain_p99: tls.map_or(0.0, |t| ratio(t.latency.p99_ns, b.latency.p99_ns)),
                tls_vs_plain_p50_round_median: if tls_rounds.is_empty() { 0.0 } else { median_f64(&tls_rounds) },
                tls_extra_p50_ns: tls.map_or(0, |t| t.latency.p50_ns as i64 - b.latency.p50_ns as i64),
                tls_target_met: tls.is_some() && tls_p50 <= TLS_TARGET,
            });
        }
        if let (Some(alone), Some(bridged), Some(limited)) = (lo("alone"), lo("bridged"), lo("bridged-100hz")) {
            let per_round: Vec<f64> =
                bridged.round_p50_ns.iter().zip(&alone.round_p50_ns).map(|(x, y)| ratio(*x, *y)).collect();
            let r = ratio(bridged.rtt.p50_ns, alone.rtt.p50_ns);
            local_ratios.push(LocalRatio {
                size,
                bridged_vs_alone_p50: r,
                bridged_vs_alone_p99: ratio(bridged.rtt.p99_ns, alone.rtt.p99_ns),
                bridged_vs_alone_p50_round_median: median_f64(&per_round),
                limited_vs_alone_p50: ratio(limited.rtt.p50_ns, alone.rtt.p50_ns),
                limited_vs_alone_p99: ratio(limited.rtt.p99_ns, alone.rtt.p99_ns),
                target_met: r <= LOCAL_TARGET,
            });
        }
    }
    Report::new(
        "bridge",
        machine,
        BridgeResults {
            rounds: opts.rounds,
            count: opts.count,
            interval_us: opts.interval_us,
            tput_ms: opts.tput_ms,
            hop_count: opts.hop_count,
            oneway,
            throughput,
            oneway_ratios,
            local,
            local_ratios,
            oneway_target: ONEWAY_TARGET,
            local_target: LOCAL_TARGET,
            tls_target: TLS_TARGET,
            tls_vs_plain,
            bridge_status,
            seconds: started.elapsed().as_secs_f64(),
        },
    )
}
