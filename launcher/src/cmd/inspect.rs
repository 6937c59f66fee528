//! `nerve ps` and `nerve graph`: what runs, and what feeds what.

use crate::client::RouterSession;
use agent_sdk::World;
use agent_sdk::clock::format_duration;
use anyhow::{Result, bail};
use shm_schemas::control::cli_to_router::{AgentView, CliRequest, GraphView, RouterReply};
use std::fmt::Write as _;
use std::io::Write as _;
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

/// Writes `text` to standard output in one go: a table of 100 agents was
/// 100 `write`s, one per `println!`. A closed pipe (`nerve ps | head`) is
/// not an error.
pub fn emit(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// The TASK column: the task's kind, `+poll` for a task that polls
/// instead of sleeping (the figure `poll` its agent reports; its CPU% is
/// then about a whole core's, by design).
fn task_column(a: &AgentView) -> String {
    let polls = a.stats.as_ref().is_some_and(|s| s.figures.iter().any(|(k, _)| k == "poll"));
    if polls { format!("{}+poll", a.task) } else { a.task.to_string() }
}

/// The `nerve ps` table, with the figures agents report below it.
pub fn agents_table(agents: &[AgentView]) -> String {
    let mut out = String::new();
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
    let _ = writeln!(
        out,
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
        let _ = writeln!(
            out,
            "{:<16} {:>8} {:<10} {:<12} {:<13} {:>8} {:>9} {:>24} {:>5} {:>6} {:>7} {:>4}  {:<24} {}",
            a.name,
            a.pid,
            a.kind,
            a.state.to_string(),
            task_column(a),
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
            let _ = writeln!(out, "{}: {}", a.name, figures.join(" "));
        }
    }
    out
}

pub fn ps(world: &World, a: PsArgs) -> Result<ExitCode> {
    let s = RouterSession::open(world)?;
    let RouterReply::Agents(agents) = s.call(CliRequest::Ps)? else { bail!("unexpected reply from the router") };
    // the reply is in: let the router's client go before printing
    drop(s);
    if a.json {
        emit(&format!("{}\n", serde_json::to_string_pretty(&agents)?))?;
    } else if agents.is_empty() {
        emit(&format!("no agents run on robot {} (start one with `nerve start KIND --name NAME`)\n", world.robot()))?;
    } else {
        emit(&agents_table(&agents))?;
    }
    Ok(ExitCode::SUCCESS)
}

pub fn graph(world: &World, a: GraphArgs) -> Result<ExitCode> {
    let s = RouterSession::open(world)?;
    let RouterReply::Graph(g) = s.call(CliRequest::Graph)? else { bail!("unexpected reply from the router") };
    drop(s);
    if a.json {
        emit(&format!("{}\n", serde_json::to_string_pretty(&g)?))?;
    } else if a.dot {
        emit(&to_dot(world.robot().as_str(), &g))?;
    } else {
        emit(&graph_table(&g))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The `nerve graph` table.
fn graph_table(g: &GraphView) -> String {
    if g.connections.is_empty() {
        return "no connections (make one with `nerve connect AGENT/PORT AGENT/PORT`)\n".into();
    }
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<24} {:<24} {:<18} {:<8} {:>9} {:>10} {:>9} {:>8}",
        "FROM", "TO", "TYPE", "ACTIVE", "RATE", "LAST AGE", "RECEIVED", "DROPPED"
    );
    for c in &g.connections {
        let _ = writeln!(
            out,
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
    let queues = input_queues(g);
    if !queues.is_empty() {
        let _ = write!(out, "\ninputs that are not the default (16, latest):\n{queues}");
    }
    out
}

/// One line per connection into an input that is not the default (depth
/// 16, keep latest, issue 46): its depth and policy, whether the source
/// sends to it losslessly, and what was overwritten, waited for and lost.
fn input_queues(g: &GraphView) -> String {
    let mut out = String::new();
    for c in g.connections.iter().filter(|c| c.depth != 16 || c.keep != "latest") {
        let how = match (c.keep.as_str(), c.lossless) {
            ("all", true) => " (lossless: the sender waits)",
            ("all", false) => " (copies: the sender does not wait)",
            _ => "",
        };
        let _ = writeln!(
            out,
            "  {} <- {}: depth {}, keep {}{how}; overwritten {}, back-pressure {}, lost {}",
            c.to, c.from, c.depth, c.keep, c.overwritten, c.back_pressure, c.lost
        );
    }
    out
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

#[cfg(test)]
mod tests {
    use super::*;

    fn view(name: &str, figures: &[(&str, &str)]) -> AgentView {
        let mut v: AgentView = serde_json::from_value(serde_json::json!({
            "name": name, "pid": 42, "kind": "relay", "state": "running", "task": "event-driven",
            "period_ns": null,
            "inputs": [{"name": "in", "type_name": "nerve::Tick", "fingerprint": 1}],
            "outputs": [{"name": "out", "type_name": "nerve::Tick", "fingerprint": 1}],
            "log_file": null,
            "stats": {"cycles": 7, "rate_hz": 10.0, "jitter_p50_ns": 0, "jitter_p99_ns": 0, "jitter_max_ns": 0,
                "overruns": 0, "cpu_percent": 0.5, "rss_bytes": 1, "realtime": true,
                "cpu_latency": {"held": {"us": 0}}, "inputs": [], "figures": []},
            "restarts": 1
        }))
        .expect("a view");
        if let Some(s) = v.stats.as_mut() {
            s.figures = figures.iter().map(|(k, v)| ((*k).to_owned(), (*v).to_owned())).collect();
        }
        v
    }

    #[test]
    fn the_ps_table_has_a_header_a_line_per_agent_and_their_figures() {
        let text = agents_table(&[view("r0", &[]), view("b", &[("peers", "2"), ("empty", "")])]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4, "{text}");
        assert!(lines[0].starts_with("NAME") && lines[0].ends_with("OUTPUTS"), "{text}");
        assert!(lines[1].starts_with("r0 ") && lines[1].contains("10.0Hz") && lines[1].contains("in:Tick"), "{text}");
        assert!(lines[2].starts_with("b "), "{text}");
        assert_eq!(lines[3], "b: peers=2", "empty figures are left out");
        assert!(text.ends_with('\n'));
    }

    #[test]
    fn the_graph_names_inputs_that_are_not_the_default_with_their_counts() {
        let edge = |to: &str, depth: u32, keep: &str| -> shm_schemas::control::cli_to_router::ConnectionView {
            serde_json::from_value(serde_json::json!({
                "from": "b/out", "to": to, "type_name": "nerve::Tick", "active": true, "rate_hz": 1.0,
                "last_age_ms": null, "received": 1000, "dropped": 0, "depth": depth, "keep": keep,
                "lossless": keep == "all", "overwritten": 0, "back_pressure": 12, "lost": 0
            }))
            .expect("an edge")
        };
        let g = GraphView { agents: vec![], connections: vec![edge("r1/in", 32, "all"), edge("r2/in", 16, "latest")] };
        let text = graph_table(&g);
        assert!(
            text.contains("  r1/in <- b/out: depth 32, keep all (lossless: the sender waits); overwritten 0, back-pressure 12, lost 0"),
            "{text}"
        );
        assert!(!text.contains("r2/in <-"), "the default is not repeated: {text}");
    }
}
