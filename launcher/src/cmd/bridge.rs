//! `nerve bridge status`: for one robot, which peer robots its bridge agents
//! see and what crosses, per topic. Read from the bridges' own figures
//! (`nerve param get BRIDGE KEY` reads any one of them). Each bridge's
//! security is shown: `tls`, `loopback` or `insecure` (plain TCP beyond
//! this host, allowed by `insecure = true`).
//!
//! `nerve bridge keys init|add ROBOT`: the fleet's certificates (see
//! [`crate::cmd::bridge_keys`]).

use crate::client::RouterSession;
use agent_sdk::World;
use anyhow::{Result, bail};
use clap::Subcommand;
use serde::Serialize;
use shm_schemas::control::cli_to_router::{AgentView, CliRequest, RouterReply};
use std::collections::BTreeMap;
use std::process::ExitCode;

/// `nerve bridge ...`
#[derive(Debug, Subcommand)]
pub enum BridgeCmd {
    /// Which peers each bridge of the robot sees, and per topic what crossed.
    Status {
        /// Print JSON instead of tables.
        #[arg(long)]
        json: bool,
    },
    /// The fleet's keys for the bridge's mutual TLS: `init` makes the CA, `add ROBOT` a robot's certificate.
    #[command(subcommand)]
    Keys(crate::cmd::bridge_keys::KeysCmd),
}

/// One topic's figures, by field (`msgs_out`, `lost`, ...).
#[derive(Debug, Default, Serialize)]
pub struct TopicStatus {
    /// `AGENT/PORT` (export) or `ROBOT/AGENT/PORT` (import)
    pub topic: String,
    /// the figures
    pub figures: BTreeMap<String, String>,
}

/// What one bridge agent reports.
#[derive(Debug, Default, Serialize)]
pub struct BridgeStatus {
    /// agent name
    pub name: String,
    /// process id
    pub pid: u32,
    /// peer bridges seen now, `ROBOT/NAME`
    pub peers: Vec<String>,
    /// `tls`, `loopback` or `insecure`
    pub security: String,
    /// local ports sent to the peers
    pub exports: Vec<TopicStatus>,
    /// remote ports received
    pub imports: Vec<TopicStatus>,
}

/// Groups a bridge's figures (`export.t1/tick.msgs_out`, ...) by topic.
pub fn status_of(a: &AgentView) -> BridgeStatus {
    let mut st = BridgeStatus { name: a.name.clone(), pid: a.pid, ..Default::default() };
    let mut exports: BTreeMap<String, TopicStatus> = BTreeMap::new();
    let mut imports: BTreeMap<String, TopicStatus> = BTreeMap::new();
    for (k, v) in a.stats.iter().flat_map(|s| &s.figures) {
        if k == "peer_names" {
            st.peers = v.split(',').filter(|s| !s.is_empty()).map(str::to_owned).collect();
            continue;
        }
        if k == "security" {
            st.security.clone_from(v);
            continue;
        }
        let (map, rest) = if let Some(r) = k.strip_prefix("export.") {
            (&mut exports, r)
        } else if let Some(r) = k.strip_prefix("import.") {
            (&mut imports, r)
        } else {
            continue;
        };
        // the field never has a dot; the topic may (port names may)
        let Some((topic, field)) = rest.rsplit_once('.') else { continue };
        let t = map
            .entry(topic.to_owned())
            .or_insert_with(|| TopicStatus { topic: topic.to_owned(), ..Default::default() });
        t.figures.insert(field.to_owned(), v.clone());
    }
    st.exports = exports.into_values().collect();
    st.imports = imports.into_values().collect();
    st
}

pub fn bridge(world: &World, cmd: BridgeCmd) -> Result<ExitCode> {
    let json = match cmd {
        BridgeCmd::Status { json } => json,
        BridgeCmd::Keys(k) => return crate::cmd::bridge_keys::keys(k),
    };
    let s = RouterSession::open(world)?;
    let RouterReply::Agents(agents) = s.call(CliRequest::Ps)? else { bail!("unexpected reply from the router") };
    let bridges: Vec<BridgeStatus> = agents.iter().filter(|a| a.kind == "bridge").map(status_of).collect();
    if json {
        println!("{}", serde_json::to_string_pretty(&bridges)?);
        return Ok(ExitCode::SUCCESS);
    }
    if bridges.is_empty() {
        println!(
            "no bridge agent runs on robot {}; start one with `nerve start bridge --name bridge -- --config FILE`",
            world.robot()
        );
        return Ok(ExitCode::SUCCESS);
    }
    for b in &bridges {
        print_status(b);
    }
    Ok(ExitCode::SUCCESS)
}

fn field<'a>(t: &'a TopicStatus, k: &str) -> &'a str {
    t.figures.get(k).map(String::as_str).filter(|s| !s.is_empty()).unwrap_or("-")
}

fn print_status(b: &BridgeStatus) {
    let peers = if b.peers.is_empty() { "none".to_string() } else { b.peers.join(", ") };
    let security = match b.security.as_str() {
        "insecure" => "INSECURE (plain TCP beyond this host: insecure = true)",
        "" => "-",
        s => s,
    };
    println!("bridge {} (pid {}): {} peer(s): {peers}; security {security}", b.name, b.pid, b.peers.len());
    if !b.exports.is_empty() {
        println!(
            "  {:<28} {:<16} {:<8} {:<5} {:>4} {:>9} {:>12} {:>7} {:>5} {:>5} {:>5}",
            "EXPORT", "TYPE", "MODE", "WIRED", "IMP", "MSGS OUT", "BYTES OUT", "DROPPED", "LOST", "QUEUE", "RETX"
        );
        for t in &b.exports {
            let mode = if field(t, "reliable") == "true" { "reliable" } else { "newest" };
            println!(
                "  {:<28} {:<16} {:<8} {:<5} {:>4} {:>9} {:>12} {:>7} {:>5} {:>5} {:>5}",
                t.topic,
                field(t, "type").trim_start_matches("nerve::"),
                mode,
                if field(t, "wired") == "true" { "yes" } else { "no" },
                field(t, "importers"),
                field(t, "msgs_out"),
                field(t, "bytes_out"),
                field(t, "dropped"),
                field(t, "lost"),
                field(t, "queue"),
                field(t, "retransmitted"),
            );
        }
    }
    if !b.imports.is_empty() {
        println!(
            "  {:<28} {:<16} {:<32} {:>9} {:>12} {:>7} {:>5} {:>7} {:>8} {:>9}",
            "IMPORT", "TYPE", "LOCAL PORT", "MSGS IN", "BYTES IN", "DROPPED", "LOST", "REFUSED", "AGE ms", "LAT us"
        );
        for t in &b.imports {
            println!(
                "  {:<28} {:<16} {:<32} {:>9} {:>12} {:>7} {:>5} {:>7} {:>8} {:>9}",
                t.topic,
                field(t, "type").trim_start_matches("nerve::"),
                format!("{}/{}", b.name, field(t, "port")),
                field(t, "msgs_in"),
                field(t, "bytes_in"),
                field(t, "dropped"),
                field(t, "lost"),
                field(t, "refused"),
                field(t, "age_ms"),
                field(t, "latency_us"),
            );
        }
        for t in b.imports.iter().filter(|t| field(t, "error") != "-") {
            println!("  ! {}: {}", t.topic, field(t, "error"));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::control::agent_to_router::TaskKind;
    use shm_schemas::control::cli_to_router::AgentState;
    use shm_schemas::stats::AgentStats;

    #[test]
    fn figures_are_grouped_by_topic() {
        let figures = [
            ("peers", "1"),
            ("peer_names", "r2/bridge"),
            ("security", "insecure"),
            ("export.t1/tick.msgs_out", "5"),
            ("export.t1/tick.lost", "0"),
            ("import.r2/a/p.v2.msgs_in", "3"),
        ];
        let a = AgentView {
            name: "bridge".into(),
            pid: 1,
            kind: "bridge".into(),
            state: AgentState::Running,
            task: TaskKind::EventDriven,
            period_ns: None,
            inputs: vec![],
            outputs: vec![],
            log_file: None,
            stats: Some(AgentStats {
                figures: figures.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect(),
                ..Default::default()
            }),
            restarts: 0,
            importance: None,
            schemas: vec![],
            services: vec![],
            clients: vec![],
        };
        let s = status_of(&a);
        assert_eq!(s.peers, vec!["r2/bridge"]);
        assert_eq!(s.security, "insecure");
        assert_eq!(s.exports[0].topic, "t1/tick");
        assert_eq!(s.exports[0].figures["msgs_out"], "5");
        assert_eq!(s.imports[0].topic, "r2/a/p.v2", "a dotted port name keeps its dots");
        assert_eq!(s.imports[0].figures["msgs_in"], "3");
    }
}
