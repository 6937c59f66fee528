//! The hop report as markdown tables (stdout), as BENCHMARKS.md shows them.

use super::{DORA_TARGET, FUTEX_TARGET, HopReport, PINNED_CPU, POLL_TARGET, PYTHON_TARGET, TARGET_RATIO};
use crate::dora;
use crate::payloads::label;
use crate::stats::{Summary, ratio_cell, verdict};

/// A markdown table of latencies: payload, `who` (transport or system), n, median, p99, max.
fn latency_table<'a>(who: &str, rows: impl Iterator<Item = (&'a str, &'a str, &'a Summary)>) {
    println!("| payload | {who} | n | median µs | p99 µs | max µs |");
    println!("|---|---|---:|---:|---:|---:|");
    for (label, transport, x) in rows {
        println!(
            "| {label} | {transport} | {} | {} | {} | {} |",
            x.n,
            crate::stats::us(x.p50_ns),
            crate::stats::us(x.p99_ns),
            crate::stats::us(x.max_ns)
        );
    }
}

/// The polling rows' ratios, per size with `nerve-poll` and `iox2-poll`
/// (also in a run of only those rows, `--rows`).
fn polling_ratios(r: &HopReport) {
    let p50 =
        |t: &str, size: usize| r.results.iter().find(|x| x.transport == t && x.size == size).map(|x| x.rtt.p50_ns);
    for size in r.batch.iter().map(|b| b.0) {
        let Some((nerve, raw)) = p50("nerve-poll", size).zip(p50("iox2-poll", size)) else { continue };
        let ts = p50("iox2-poll-ts", size).map(|ts| crate::stats::ratio(nerve, ts));
        let ratio = crate::stats::ratio(nerve, raw);
        println!(
            "polling, {}: nerve-poll/iox2-poll p50 {ratio:.2}, nerve-poll/iox2-poll-ts p50 {}, target ≤{POLL_TARGET}: {}",
            label(size),
            ratio_cell(ts),
            if ratio <= POLL_TARGET { "met" } else { "missed" }
        );
    }
}

/// Prints the tables of a hop report (markdown).
pub fn print_tables(r: &HopReport) {
    latency_table("transport", r.results.iter().map(|x| (x.label.as_str(), x.transport.as_str(), &x.rtt)));
    println!();
    polling_ratios(r);
    println!();
    println!(
        "| payload | nerve/iox2-waitset p50 | (median of rounds) | p99 | nerve/iox2-listener p50 | p99 | nerve/iox2-waitset-fill p50 | p99 | uds/nerve p50 | ddsperf/nerve p50 | nerve-poll/iox2-poll p50 | target ≤{TARGET_RATIO} |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for x in &r.ratios {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} |",
            label(x.size),
            x.nerve_vs_waitset_p50,
            x.nerve_vs_waitset_p50_round_median,
            x.nerve_vs_waitset_p99,
            x.nerve_vs_listener_p50,
            x.nerve_vs_listener_p99,
            x.nerve_vs_waitset_fill_p50,
            x.nerve_vs_waitset_fill_p99,
            x.uds_vs_nerve_p50,
            ratio_cell(x.dds_vs_nerve_p50),
            ratio_cell(x.nerve_poll_vs_iox2_poll_p50),
            if x.target_met { "met" } else { "missed" }
        );
    }
    println!();
    println!("The wake-up floor and PM QoS, same run (nerve-pmqos is nerve as its agents run by default):");
    println!();
    println!(
        "| payload | nerve/futex p50 (no PM QoS) | nerve-pmqos/futex-pmqos | nerve-pmqos/futex | nerve-pmqos/iox2-waitset-pmqos | nerve/nerve-pmqos | nerve/nerve-pinned | nerve-pinned/futex-pinned | target ≤{FUTEX_TARGET} |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---|");
    for x in &r.ratios {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            label(x.size),
            ratio_cell(x.nerve_vs_futex_p50),
            ratio_cell(x.nerve_pmqos_vs_futex_pmqos_p50),
            ratio_cell(x.nerve_pmqos_vs_futex_p50),
            ratio_cell(x.nerve_pmqos_vs_waitset_pmqos_p50),
            ratio_cell(x.pmqos_gain_nerve),
            ratio_cell(x.pinned_gain_nerve),
            ratio_cell(x.nerve_pinned_vs_futex_pinned_p50),
            verdict(x.futex_target_met)
        );
    }
    let placed: Vec<String> = r
        .results
        .iter()
        .filter_map(|x| x.same_cpu_share.map(|s| format!("{} {}: {:.0}%", x.transport, x.label, s * 100.0)))
        .collect();
    if !placed.is_empty() {
        println!();
        println!("round trips whose two ends ran on one CPU: {}", placed.join(", "));
    }
    for i in &r.idle {
        let states: Vec<String> = i.states.iter().map(|(n, v)| format!("{n} {:.1}%", v * 100.0)).collect();
        println!(
            "idle robot, {:.0} s {}: CPUs busy {:.1}%, idle in {}",
            i.seconds,
            if i.pm_qos { "holding PM QoS at 0" } else { "without PM QoS" },
            i.busy * 100.0,
            states.join(", ")
        );
    }
    if !r.periodic.is_empty() {
        println!();
        println!(
            "One way, one sample every {} ms (dora's own pattern), {} samples per batch:",
            dora::PERIOD_US / 1000,
            r.periodic_batch
        );
        println!();
        latency_table("system", r.periodic.iter().map(|x| (x.label.as_str(), x.transport.as_str(), &x.one_way)));
    }
    if r.ratios.iter().any(|x| x.python_vs_nerve_p50.is_some()) {
        println!();
        println!("A Python pong (bench/py/pong.py, the nerve package) against a Rust one, same run:");
        println!();
        println!(
            "| payload | nerve-python/nerve p50 | p99 | target ≤{PYTHON_TARGET} | nerve-python-pmqos/nerve-pmqos p50 |"
        );
        println!("|---|---:|---:|---|---:|");
        for x in &r.ratios {
            println!(
                "| {} | {} | {} | {} | {} |",
                label(x.size),
                ratio_cell(x.python_vs_nerve_p50),
                ratio_cell(x.python_vs_nerve_p99),
                verdict(x.python_target_met),
                ratio_cell(x.python_pmqos_vs_nerve_pmqos_p50)
            );
        }
    }
    if let Some(v) = &r.dora_version {
        println!();
        println!("dora ({v}) against nerve, same run:");
        println!();
        println!(
            "| payload | dora/nerve p50 (round trip) | p99 | dora-5ms/nerve-5ms p50 (one way, 5 ms) | p99 | target ≥{DORA_TARGET} | both under PM QoS 0: round trip | one way, 5 ms | target ≥{DORA_TARGET} | dora/nerve-pmqos (each by default) |"
        );
        println!("|---|---:|---:|---:|---:|---|---:|---:|---|---:|");
        for x in &r.ratios {
            println!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                label(x.size),
                ratio_cell(x.dora_vs_nerve_p50),
                ratio_cell(x.dora_vs_nerve_p99),
                ratio_cell(x.dora_5ms_vs_nerve_5ms_p50),
                ratio_cell(x.dora_5ms_vs_nerve_5ms_p99),
                verdict(x.dora_target_met),
                ratio_cell(x.dora_pmqos_vs_nerve_pmqos_p50),
                ratio_cell(x.dora_5ms_pmqos_vs_nerve_5ms_pmqos_p50),
                verdict(x.dora_target_met_pmqos),
                ratio_cell(x.dora_vs_nerve_pmqos_p50)
            );
        }
        if r.ratios.iter().any(|x| x.dora_5ms_pinned_vs_nerve_5ms_pinned_p50.is_some()) {
            println!();
            println!(
                "dora's pattern with each system's two ends on CPU {PINNED_CPU} (router and dora's daemon free), same run:"
            );
            println!();
            println!(
                "| payload | dora-5ms-pinned/nerve-5ms-pinned p50 | both under PM QoS 0 | target ≥{DORA_TARGET} | nerve-5ms-pmqos/nerve-5ms-pinned-pmqos (what one CPU buys nerve) |"
            );
            println!("|---|---:|---:|---|---:|");
            for x in &r.ratios {
                let met = x.dora_5ms_pinned_pmqos_vs_nerve_5ms_pinned_pmqos_p50.map(|v| v >= DORA_TARGET);
                println!(
                    "| {} | {} | {} | {} | {} |",
                    label(x.size),
                    ratio_cell(x.dora_5ms_pinned_vs_nerve_5ms_pinned_p50),
                    ratio_cell(x.dora_5ms_pinned_pmqos_vs_nerve_5ms_pinned_pmqos_p50),
                    verdict(met),
                    ratio_cell(x.pinned_gain_nerve_5ms_pmqos)
                );
            }
        }
    }
    println!();
    for f in &r.fill_cost {
        println!(
            "fill cost {}: memset of the whole payload {} µs warm, {} µs cold",
            label(f.size),
            crate::stats::us(f.memset_warm_p50_ns),
            crate::stats::us(f.memset_cold_p50_ns)
        );
    }
}
