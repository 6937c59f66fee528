//! The hop report: the results of every row at every size, nerve's ratios
//! to the others, and the cost of filling a payload.

use super::rounds::Measured;
use super::{DORA_TARGET, FUTEX_TARGET, PERIODIC, PYTHON_TARGET, TARGET_RATIO, TRANSPORTS};
use crate::dds;
use crate::idle::IdleShare;
use crate::payloads::label;
use crate::report::Report;
use crate::stats::{Rounds, Summary, median_f64, ratio};
use anyhow::{Result, bail};
use serde::Serialize;

/// Results of one transport at one payload size.
#[derive(Debug, Clone, Serialize)]
pub struct HopResult {
    /// transport
    pub transport: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// all measured round trips pooled
    pub rtt: Summary,
    /// median round trip of each round, ns
    pub round_p50_ns: Vec<u64>,
    /// share of round trips whose two ends ran on the same CPU (the futex rows)
    pub same_cpu_share: Option<f64>,
}

/// Results of one system at one payload size in dora's pattern (a sample every 5 ms).
#[derive(Debug, Clone, Serialize)]
pub struct OneWayResult {
    /// `nerve-5ms` or `dora-5ms`
    pub transport: String,
    /// payload bytes
    pub size: usize,
    /// payload label
    pub label: String,
    /// all measured one-way latencies pooled (sender's stamp to the receiver's code)
    pub one_way: Summary,
    /// median one-way latency of each round, ns
    pub round_p50_ns: Vec<u64>,
}

/// nerve against the others at one payload size.
#[derive(Debug, Clone, Serialize)]
pub struct HopRatio {
    /// payload bytes
    pub size: usize,
    /// nerve p50 / iox2-waitset p50 (pooled)
    pub nerve_vs_waitset_p50: f64,
    /// nerve p99 / iox2-waitset p99
    pub nerve_vs_waitset_p99: f64,
    /// median over rounds of the per-round p50 ratio
    pub nerve_vs_waitset_p50_round_median: f64,
    /// nerve p50 / iox2-listener p50
    pub nerve_vs_listener_p50: f64,
    /// nerve p99 / iox2-listener p99
    pub nerve_vs_listener_p99: f64,
    /// nerve p50 / iox2-waitset-fill p50: the SDK's cost apart from the fill
    pub nerve_vs_waitset_fill_p50: f64,
    /// nerve p99 / iox2-waitset-fill p99
    pub nerve_vs_waitset_fill_p99: f64,
    /// uds p50 / nerve p50
    pub uds_vs_nerve_p50: f64,
    /// ddsperf p50 / nerve p50 (None without ddsperf)
    pub dds_vs_nerve_p50: Option<f64>,
    /// nerve-poll p50 / iox2-poll p50
    pub nerve_poll_vs_iox2_poll_p50: Option<f64>,
    /// dora p50 / nerve p50, ping-pong round trips (None without dora)
    pub dora_vs_nerve_p50: Option<f64>,
    /// dora p99 / nerve p99, ping-pong round trips
    pub dora_vs_nerve_p99: Option<f64>,
    /// dora-5ms p50 / nerve-5ms p50: one way, a sample every 5 ms (None without dora)
    pub dora_5ms_vs_nerve_5ms_p50: Option<f64>,
    /// dora-5ms p99 / nerve-5ms p99
    pub dora_5ms_vs_nerve_5ms_p99: Option<f64>,
    /// whether both dora p50 ratios are at least [`DORA_TARGET`] (None without dora)
    pub dora_target_met: Option<bool>,
    /// dora-pmqos p50 / nerve-pmqos p50: round trips, both under a PM QoS
    /// bound of 0 µs (nerve's default; dora holds none of its own)
    pub dora_pmqos_vs_nerve_pmqos_p50: Option<f64>,
    /// dora-5ms-pmqos p50 / nerve-5ms-pmqos p50: one way every 5 ms, both under the bound
    pub dora_5ms_pmqos_vs_nerve_5ms_pmqos_p50: Option<f64>,
    /// whether both ratios under the bound are at least [`DORA_TARGET`]
    pub dora_target_met_pmqos: Option<bool>,
    /// dora-5ms-pinned p50 / nerve-5ms-pinned p50: one way every 5 ms, each
    /// system's two ends on one CPU, no bound (None without the rows)
    pub dora_5ms_pinned_vs_nerve_5ms_pinned_p50: Option<f64>,
    /// dora-5ms-pinned-pmqos p50 / nerve-5ms-pinned-pmqos p50: the same under the bound
    pub dora_5ms_pinned_pmqos_vs_nerve_5ms_pinned_pmqos_p50: Option<f64>,
    /// nerve-5ms-pmqos p50 / nerve-5ms-pinned-pmqos p50: what one CPU for both ends buys nerve in dora's pattern
    pub pinned_gain_nerve_5ms_pmqos: Option<f64>,
    /// dora p50 / nerve-pmqos p50: each as it runs by default (dora holds no
    /// bound, nerve's agents hold 0 µs); not the same settings
    pub dora_vs_nerve_pmqos_p50: Option<f64>,
    /// whether nerve p50 is within the target of iox2-waitset p50
    pub target_met: bool,
    /// nerve p50 / futex p50, neither holding PM QoS
    pub nerve_vs_futex_p50: Option<f64>,
    /// nerve-pmqos p50 / futex-pmqos p50: both under a bound of 0 µs
    pub nerve_pmqos_vs_futex_pmqos_p50: Option<f64>,
    /// nerve-pmqos p50 / futex p50: nerve as it runs by default against the
    /// floor of a machine left as it idles by default
    pub nerve_pmqos_vs_futex_p50: Option<f64>,
    /// whether nerve-pmqos p50 ≤ [`FUTEX_TARGET`] × futex-pmqos p50 (same settings)
    pub futex_target_met: Option<bool>,
    /// nerve-pmqos p50 / iox2-waitset-pmqos p50
    pub nerve_pmqos_vs_waitset_pmqos_p50: Option<f64>,
    /// nerve p50 / nerve-pmqos p50: what the bound buys nerve
    pub pmqos_gain_nerve: Option<f64>,
    /// nerve p50 / nerve-pinned p50: what one CPU for both ends buys nerve
    pub pinned_gain_nerve: Option<f64>,
    /// nerve-pinned p50 / futex-pinned p50
    pub nerve_pinned_vs_futex_pinned_p50: Option<f64>,
    /// nerve-python p50 / nerve p50: a Python pong against a Rust one (None without the package)
    pub python_vs_nerve_p50: Option<f64>,
    /// nerve-python p99 / nerve p99
    pub python_vs_nerve_p99: Option<f64>,
    /// whether nerve-python p50 ≤ [`PYTHON_TARGET`] × nerve p50
    pub python_target_met: Option<bool>,
    /// nerve-python-pmqos p50 / nerve-pmqos p50: both holding PM QoS, as agents run by default
    pub python_pmqos_vs_nerve_pmqos_p50: Option<f64>,
}

/// Time to write a whole payload once (what `Output::send_with` adds per send).
#[derive(Debug, Clone, Serialize)]
pub struct FillCost {
    /// payload bytes
    pub size: usize,
    /// median time to zero the payload in warm memory (the same buffer again), ns
    pub memset_warm_p50_ns: u64,
    /// median time to zero it in memory not touched recently (64 MiB of buffers in turn), ns
    pub memset_cold_p50_ns: u64,
}

/// The hop report: the [`Head`](crate::report::Head) and [`HopResults`].
pub type HopReport = Report<HopResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Clone, Serialize)]
pub struct HopResults {
    /// measured rounds
    pub rounds: usize,
    /// round trips per batch, by size
    pub batch: Vec<(usize, usize)>,
    /// per transport and size: round trips
    pub results: Vec<HopResult>,
    /// `nerve-5ms` and `dora-5ms` per size: one way, a sample every 5 ms
    pub periodic: Vec<OneWayResult>,
    /// samples per batch of the 5 ms rows
    pub periodic_batch: usize,
    /// what `dora --version` said (None: no dora rows)
    pub dora_version: Option<String>,
    /// per size
    pub ratios: Vec<HopRatio>,
    /// target ratio (nerve / iox2-waitset, p50)
    pub target_ratio: f64,
    /// target ratio dora / nerve (p50, both patterns): at least this
    pub dora_target_ratio: f64,
    /// cost of filling a payload once, by size
    pub fill_cost: Vec<FillCost>,
    /// where the idle robot's CPUs spent their time, without and with PM QoS
    pub idle: Vec<IdleShare>,
    /// nerve-pmqos / futex-pmqos p50 target
    pub futex_target_ratio: f64,
    /// per measured round: the time the hypervisor ran something else while
    /// this guest's CPUs had work, ms, all CPUs (`steal` of /proc/stat, in
    /// steps of USER_HZ ticks, 10 ms here: too coarse for one batch, whose
    /// slow rounds add about 10 ms in all; empty where the kernel does not say)
    pub round_steal_ms: Vec<f64>,
    /// wall time of the run, s
    pub seconds: f64,
}

/// The round-trip rows of every size, in table order ([`TRANSPORTS`]);
/// `keys` names each pinger's (size, row). A row without samples is an
/// error, except the optional peers' (dora, Python, ddsperf) and the rows
/// not `wanted` (`--rows`).
pub(super) fn round_trips(
    sizes: &[usize],
    keys: &[(usize, &'static str)],
    m: &Measured,
    wanted: impl Fn(&str) -> bool,
) -> Result<Vec<HopResult>> {
    let mut results = Vec::new();
    for &size in sizes {
        for t in TRANSPORTS.into_iter().filter(|t| wanted(t)) {
            if t == "ddsperf" {
                if let Some((_, iv, dds_round_p50)) = m.dds.iter().find(|d| d.0 == size && !d.1.is_empty()) {
                    results.push(HopResult {
                        transport: t.into(),
                        size,
                        label: label(size).into(),
                        rtt: dds::summarise(iv),
                        round_p50_ns: dds_round_p50.clone(),
                        same_cpu_share: None,
                    });
                }
                continue;
            }
            let Some(i) = keys.iter().position(|k| *k == (size, t)) else {
                if t.starts_with("dora") || t.starts_with("nerve-python") {
                    continue;
                }
                bail!("internal: no samples for {t} {size}");
            };
            let (same, all) = m.placement[i];
            results.push(HopResult {
                transport: t.into(),
                size,
                label: label(size).into(),
                rtt: Summary::of(&m.rounds.samples[i]),
                round_p50_ns: m.rounds.round_p50[i].clone(),
                same_cpu_share: (all > 0).then(|| same as f64 / all as f64),
            });
        }
    }
    Ok(results)
}

/// The one-way rows in dora's pattern of every size, in table order ([`PERIODIC`]).
pub(super) fn one_way(sizes: &[usize], keys: &[(usize, &'static str)], rounds: &Rounds) -> Vec<OneWayResult> {
    let mut periodic = Vec::new();
    for &size in sizes {
        for t in PERIODIC {
            if let Some(i) = keys.iter().position(|k| *k == (size, t)) {
                periodic.push(OneWayResult {
                    transport: t.into(),
                    size,
                    label: label(size).into(),
                    one_way: Summary::of(&rounds.samples[i]),
                    round_p50_ns: rounds.round_p50[i].clone(),
                });
            }
        }
    }
    periodic
}

/// nerve against the others, per size (a size without nerve's and the raw
/// floors' rows has none).
pub(super) fn ratios(sizes: &[usize], results: &[HopResult], periodic: &[OneWayResult]) -> Vec<HopRatio> {
    sizes.iter().filter_map(|&size| ratios_at(size, results, periodic)).collect()
}

fn ratios_at(size: usize, results: &[HopResult], periodic: &[OneWayResult]) -> Option<HopRatio> {
    let find = |t: &str| results.iter().find(|r| r.transport == t && r.size == size);
    let find_periodic = |t: &str| periodic.iter().find(|r| r.transport == t && r.size == size);
    let (n, w, l, f, u) =
        (find("nerve")?, find("iox2-waitset")?, find("iox2-listener")?, find("iox2-waitset-fill")?, find("uds")?);
    let per_round: Vec<f64> = n.round_p50_ns.iter().zip(&w.round_p50_ns).map(|(a, b)| ratio(*a, *b)).collect();
    let r = ratio(n.rtt.p50_ns, w.rtt.p50_ns);
    let dora = find("dora");
    let dora_5ms = match (find_periodic("dora-5ms"), find_periodic("nerve-5ms")) {
        (Some(d), Some(n5)) => {
            Some((ratio(d.one_way.p50_ns, n5.one_way.p50_ns), ratio(d.one_way.p99_ns, n5.one_way.p99_ns)))
        }
        _ => None,
    };
    let dora_p50 = dora.map(|d| ratio(d.rtt.p50_ns, n.rtt.p50_ns));
    let p50 = |t: &str| find(t).map(|x| x.rtt.p50_ns);
    let both = |a: Option<u64>, b: Option<u64>| a.zip(b).map(|(a, b)| ratio(a, b));
    let one_way_p50 = |t: &str| find_periodic(t).map(|x| x.one_way.p50_ns);
    let dora_pmqos = both(p50("dora-pmqos"), p50("nerve-pmqos"));
    let dora_5ms_pmqos = both(one_way_p50("dora-5ms-pmqos"), one_way_p50("nerve-5ms-pmqos"));
    let nerve_pmqos_vs_futex_pmqos = both(p50("nerve-pmqos"), p50("futex-pmqos"));
    Some(HopRatio {
        size,
        nerve_vs_waitset_p50: r,
        nerve_vs_waitset_p99: ratio(n.rtt.p99_ns, w.rtt.p99_ns),
        nerve_vs_waitset_p50_round_median: median_f64(&per_round),
        nerve_vs_listener_p50: ratio(n.rtt.p50_ns, l.rtt.p50_ns),
        nerve_vs_listener_p99: ratio(n.rtt.p99_ns, l.rtt.p99_ns),
        nerve_vs_waitset_fill_p50: ratio(n.rtt.p50_ns, f.rtt.p50_ns),
        nerve_vs_waitset_fill_p99: ratio(n.rtt.p99_ns, f.rtt.p99_ns),
        uds_vs_nerve_p50: ratio(u.rtt.p50_ns, n.rtt.p50_ns),
        dds_vs_nerve_p50: find("ddsperf").map(|d| ratio(d.rtt.p50_ns, n.rtt.p50_ns)),
        nerve_poll_vs_iox2_poll_p50: both(p50("nerve-poll"), p50("iox2-poll")),
        dora_vs_nerve_p50: dora_p50,
        dora_vs_nerve_p99: dora.map(|d| ratio(d.rtt.p99_ns, n.rtt.p99_ns)),
        dora_5ms_vs_nerve_5ms_p50: dora_5ms.map(|x| x.0),
        dora_5ms_vs_nerve_5ms_p99: dora_5ms.map(|x| x.1),
        dora_target_met: match (dora_p50, dora_5ms) {
            (Some(a), Some((b, _))) => Some(a >= DORA_TARGET && b >= DORA_TARGET),
            _ => None,
        },
        dora_pmqos_vs_nerve_pmqos_p50: dora_pmqos,
        dora_5ms_pmqos_vs_nerve_5ms_pmqos_p50: dora_5ms_pmqos,
        dora_target_met_pmqos: dora_pmqos.zip(dora_5ms_pmqos).map(|(a, b)| a >= DORA_TARGET && b >= DORA_TARGET),
        dora_5ms_pinned_vs_nerve_5ms_pinned_p50: both(one_way_p50("dora-5ms-pinned"), one_way_p50("nerve-5ms-pinned")),
        dora_5ms_pinned_pmqos_vs_nerve_5ms_pinned_pmqos_p50: both(
            one_way_p50("dora-5ms-pinned-pmqos"),
            one_way_p50("nerve-5ms-pinned-pmqos"),
        ),
        pinned_gain_nerve_5ms_pmqos: both(one_way_p50("nerve-5ms-pmqos"), one_way_p50("nerve-5ms-pinned-pmqos")),
        dora_vs_nerve_pmqos_p50: both(p50("dora"), p50("nerve-pmqos")),
        target_met: r <= TARGET_RATIO,
        nerve_vs_futex_p50: both(p50("nerve"), p50("futex")),
        nerve_pmqos_vs_futex_pmqos_p50: nerve_pmqos_vs_futex_pmqos,
        nerve_pmqos_vs_futex_p50: both(p50("nerve-pmqos"), p50("futex")),
        futex_target_met: nerve_pmqos_vs_futex_pmqos.map(|x| x <= FUTEX_TARGET),
        nerve_pmqos_vs_waitset_pmqos_p50: both(p50("nerve-pmqos"), p50("iox2-waitset-pmqos")),
        pmqos_gain_nerve: both(p50("nerve"), p50("nerve-pmqos")),
        pinned_gain_nerve: both(p50("nerve"), p50("nerve-pinned")),
        nerve_pinned_vs_futex_pinned_p50: both(p50("nerve-pinned"), p50("futex-pinned")),
        python_vs_nerve_p50: both(p50("nerve-python"), p50("nerve")),
        python_vs_nerve_p99: find("nerve-python").map(|x| ratio(x.rtt.p99_ns, n.rtt.p99_ns)),
        python_target_met: both(p50("nerve-python"), p50("nerve")).map(|x| x <= PYTHON_TARGET),
        python_pmqos_vs_nerve_pmqos_p50: both(p50("nerve-python-pmqos"), p50("nerve-pmqos")),
    })
}

pub(super) fn measure_fill(size: usize) -> FillCost {
    let time = |buf: &mut [u8]| {
        let t0 = agent_sdk::clock::now_ns();
        // SAFETY: `buf` is valid for `buf.len()` bytes.
        unsafe { std::ptr::write_bytes(std::hint::black_box(buf.as_mut_ptr()), 0, buf.len()) };
        std::hint::black_box(&buf);
        agent_sdk::clock::now_ns() - t0
    };
    let mut one = vec![1u8; size];
    let warm: Vec<u64> = (0..21).map(|_| time(&mut one)).collect();
    let n = ((64usize << 20) / size.max(1)).clamp(2, 4096);
    let mut many: Vec<Vec<u8>> = (0..n).map(|_| vec![1u8; size]).collect();
    let cold: Vec<u64> = (0..(3 * n).min(300)).map(|i| time(&mut many[i % n])).collect();
    FillCost { size, memset_warm_p50_ns: Summary::of(&warm).p50_ns, memset_cold_p50_ns: Summary::of(&cold).p50_ns }
}
