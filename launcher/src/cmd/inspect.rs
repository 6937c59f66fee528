//! `nerve ps` and `nerve graph`: what runs, and what feeds what.

use crate::client::RouterSession;
use agent_sdk::World;
use agent_sdk::clock::format_duration;
use anyhow::{Result, bail};
use shm_schemas::control::cli_to_router::{AgentView, CliRequest, GraphView, RouterReply};
use std::process::ExitCode;
use std::time::Duration;

/// `nerve ps`
#[derive(Debug, clap::Args)]
pub struct PsArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// `nerve graph`
#[derive(Debug, clap::Args)]
pub struct GraphArgs {
    /// Print JSON.
    #[arg(long, conflicts_with = "dot")]
    pub json: bool,
    /// Print Graphviz DOT (pipe into `dot -Tsvg`).
    #[arg(long)]
    pub dot: bool,
}

fn us(ns: u64) -> String {
    if ns >= 10_000_000 { format!("{:.0}ms", ns as f64 / 1e6) } else { format!("{:.0}us", ns as f64 / 1e3) }
}

fn ports(p: &[shm_schemas::control::agent_to_router::PortSpec]) -> String {
    if p.is_empty() {
        "-".into()
    } else {
        p.iter()
            .map(|s| format!("{}:{}", s.name, s.type_name.trim_start_matches("nerve::")))
            .collect::<Vec<_>>()
            .join(",")
    }
}

pub fn print_agents(agents: &[AgentView]) {
    const HEADER: [&str; 13] = [
        "NAME",
        "PID",
        "KIND",
        "STATE",
        "TASK",
        "PERIOD",
        "RATE",
        "JITTER p50/p99/max",
        "OVR",
        "CPU%",
        "WAKE",
        "RST",
        "INPUTS",
    ];
    let [n, p, k, st, t, pe, r, j, o, c, w, rs, i] = HEADER;
    println!(
        "{n:<16} {p:>8} {k:<10} {st:<12} {t:<13} {pe:>8} {r:>9} {j:>24} {o:>5} {c:>6} {w:>7} {rs:>4}  {i:<24} OUTPUTS"
    );
    for a in agents {
        // the PM QoS bound the agent holds: `0us`, `off`, `refused`
        let wake = a.stats.as_ref().map(|s| s.cpu_latency.to_string()).unwrap_or_else(|| "?".into());
        let (rate, jitter, ovr, cpu) = match &a.stats {
            Some(s) => (
                format!("{:.1}Hz", s.rate_hz),
                if a.period_ns.is_some() {
                    format!("{}/{}/{}", us(s.jitter_p50_ns), us(s.jitter_p99_ns), us(s.jitter_max_ns))
                } else {
                    "-".into()
                },
                s.overruns.to_string(),
                format!("{:.1}", s.cpu_percent),
            ),
            None => ("?".into(), "?".into(), "?".into(), "?".into()),
        };
        println!(
            "{:<16} {:>8} {:<10} {:<12} {:<13} {:>8} {:>9} {:>24} {:>5} {:>6} {:>7} {:>4}  {:<24} {}",
            a.name,
            a.pid,
            a.kind,
            a.state.to_string(),
            a.task.to_string(),
            a.period_ns.map(|p| format_duration(Duration::from_nanos(p))).unwrap_or_else(|| "-".into()),
            rate,
            jitter,
            ovr,
            cpu,
            wake,
            a.restarts,
            ports(&a.inputs),
            ports(&a.outputs)
        );
    }
    // figures that agents report about their own work (a bridge's peers and topics)
    for a in agents {
        let figures: Vec<String> = a
            .stats
            .iter()
            .flat_map(|s| &s.figures)
            .filter(|(_, v)| !v.is_empty())
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        if !figures.is_empty() {
            println!("{}: {}", a.name, figures.join(" "));
        }
    }
}

pub fn ps(world: &World, a: PsArgs) -> Result<ExitCode> {
    let s = RouterSession::open(world)?;
    let RouterReply::Agents(agents) = s.call(CliRequest::Ps)? else { bail!("unexpected reply from the router") };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&agents)?);
    } else if agents.is_empty() {
        println!("no agents run on robot {} (start one with `nerve start KIND --name NAME`)", world.robot());
    } else {
        print_agents(&agents);
    }
    Ok(ExitCode::SUCCESS)
}

pub fn graph(world: &World, a: GraphArgs) -> Result<ExitCode> {
    let s = RouterSession::open(world)?;
    let RouterReply::Graph(g) = s.call(CliRequest::Graph)? else { bail!("unexpected reply from the router") };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&g)?);
    } else if a.dot {
        print!("{}", to_dot(world.robot().as_str(), &g));
    } else {
        print_graph(&g);
    }
    Ok(ExitCode::SUCCESS)
}

fn print_graph(g: &GraphView) {
    if g.connections.is_empty() {
        println!("no connections (make one with `nerve connect AGENT/PORT AGENT/PORT`)");
        return;
    }
    println!(
        "{:<24} {:<24} {:<18} {:<8} {:>9} {:>10} {:>9} {:>8}",
        "FROM", "TO", "TYPE", "ACTIVE", "RATE", "LAST AGE", "RECEIVED", "DROPPED"
    );
    for c in &g.connections {
        println!(
            "{:<24} {:<24} {:<18} {:<8} {:>9} {:>10} {:>9} {:>8}",
            c.from,
            c.to,
            c.type_name,
            match (c.active, c.transient) {
                (true, true) => "tool",
                (true, false) => "yes",
                (false, _) => "no",
            },
            format!("{:.1}Hz", c.rate_hz),
            c.last_age_ms.map(|a| format!("{a:.1}ms")).unwrap_or_else(|| "-".into()),
            c.received,
            c.dropped
        );
    }
}

fn dot_escape(s: &str) -> String {
    s.replace('\\', "\\\\").replace('"', "\\\"")
}

/// The graph as Graphviz DOT: agents as boxes, connections as labelled edges
/// (dashed when inactive).
pub fn to_dot(robot: &str, g: &GraphView) -> String {
    let mut out = format!("digraph \"{}\" {{\n  rankdir=LR;\n  node [shape=box, style=rounded];\n", dot_escape(robot));
    let mut names: Vec<String> = g.agents.iter().map(|a| a.name.clone()).collect();
    for a in &g.agents {
        out += &format!(
            "  \"{}\" [label=\"{}\\n{} ({})\"];\n",
            dot_escape(&a.name),
            dot_escape(&a.name),
            dot_escape(&a.kind),
            a.state
        );
    }
    for c in &g.connections {
        for end in [&c.from, &c.to] {
            let agent = end.split('/').next().unwrap_or(end).to_string();
            if !names.contains(&agent) {
                out += &format!(
                    "  \"{}\" [label=\"{}\\n(not running)\", style=dashed];\n",
                    dot_escape(&agent),
                    dot_escape(&agent)
                );
                names.push(agent);
            }
        }
        let (fa, fp) = c.from.split_once('/').unwrap_or((&c.from, ""));
        let (ta, tp) = c.to.split_once('/').unwrap_or((&c.to, ""));
        out += &format!(
            "  \"{}\" -> \"{}\" [label=\"{}→{}\\n{:.1} Hz, {} dropped\"{}];\n",
            dot_escape(fa),
            dot_escape(ta),
            dot_escape(fp),
            dot_escape(tp),
            c.rate_hz,
            c.dropped,
            if c.active { "" } else { ", style=dashed" }
        );
    }
    out += "}\n";
    out
}
