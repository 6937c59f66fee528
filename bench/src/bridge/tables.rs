//! The bridge scenario's tables (markdown): one way, throughput, the ratios
//! and their targets, TLS against plain, and the local round trip.

use super::{BridgeReport, LOCAL_TARGET, ONEWAY_TARGET, TLS_TARGET};
use crate::payloads::label;
use crate::stats::{Summary, us};

/// Prints the tables of a bridge report (markdown).
pub fn print_tables(r: &BridgeReport) {
    println!("One way across the bridge vs raw Zenoh, one sample every {} µs:", r.interval_us);
    println!();
    println!(
        "| payload | system | n | lost | median µs | p99 µs | max µs | sender to bridge B, median µs | bridge B to sink, median µs |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|");
    let opt = |s: &Option<Summary>| s.as_ref().map_or_else(|| "-".to_owned(), |s| us(s.p50_ns));
    for x in &r.oneway {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            x.label,
            x.system,
            x.latency.n,
            x.lost,
            us(x.latency.p50_ns),
            us(x.latency.p99_ns),
            us(x.latency.max_ns),
            opt(&x.to_bridge_b),
            opt(&x.bridge_b_to_sink)
        );
    }
    println!();
    println!("Throughput, sent back to back for at most {} ms:", r.tput_ms);
    println!();
    println!(
        "| payload | system | offered /s | delivered /s | delivered MB/s | delivered of sent | one way under load, median µs | p99 µs |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|");
    for x in &r.throughput {
        println!(
            "| {} | {} | {:.0} | {:.0} | {:.1} | {:.1}% | {} | {} |",
            x.label,
            x.system,
            x.offered_per_s,
            x.delivered_per_s,
            x.delivered_mb_per_s,
            100.0 * x.delivered_fraction,
            us(x.latency_loaded.p50_ns),
            us(x.latency_loaded.p99_ns)
        );
    }
    println!();
    println!(
        "| payload | bridge/zenoh p50 | (median of rounds) | p99 | bridge adds, µs | one local hop, µs | delivered/s bridge/zenoh | target ≤{ONEWAY_TARGET} |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---|");
    for x in &r.oneway_ratios {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.1} | {} | {:.2} | {} |",
            label(x.size),
            x.bridge_vs_zenoh_p50,
            x.bridge_vs_zenoh_p50_round_median,
            x.bridge_vs_zenoh_p99,
            x.extra_p50_ns as f64 / 1e3,
            us(x.local_hop_p50_ns),
            x.throughput_bridge_vs_zenoh,
            if x.target_met { "met" } else { "missed" }
        );
    }
    println!();
    println!("The bridge with mutual TLS against without (bridge-tls / bridge, one way):");
    println!();
    println!("| payload | tls/plain p50 | (median of rounds) | p99 | TLS adds, µs | target ≤{TLS_TARGET} |");
    println!("|---|---:|---:|---:|---:|---|");
    for x in &r.oneway_ratios {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.1} | {} |",
            label(x.size),
            x.tls_vs_plain_p50,
            x.tls_vs_plain_p50_round_median,
            x.tls_vs_plain_p99,
            x.tls_extra_p50_ns as f64 / 1e3,
            if x.tls_target_met { "met" } else { "missed" }
        );
    }
    println!();
    println!("One-hop round trip in robot A, with and without a bridge reading the ping's port:");
    println!();
    println!("| payload | system | n | median µs | p99 µs | max µs |");
    println!("|---|---|---:|---:|---:|---:|");
    for x in &r.local {
        println!(
            "| {} | {} | {} | {} | {} | {} |",
            x.label,
            x.system,
            x.rtt.n,
            us(x.rtt.p50_ns),
            us(x.rtt.p99_ns),
            us(x.rtt.max_ns)
        );
    }
    println!();
    println!(
        "| payload | bridged/alone p50 | (median of rounds) | p99 | bridged-100hz/alone p50 | p99 | target ≤{LOCAL_TARGET} |"
    );
    println!("|---|---:|---:|---:|---:|---:|---|");
    for x in &r.local_ratios {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} |",
            label(x.size),
            x.bridged_vs_alone_p50,
            x.bridged_vs_alone_p50_round_median,
            x.bridged_vs_alone_p99,
            x.limited_vs_alone_p50,
            x.limited_vs_alone_p99,
            if x.target_met { "met" } else { "missed" }
        );
    }
}
