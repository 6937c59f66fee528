//! Commands that change the running graph: connect, disconnect, rate,
//! suspend, resume, parameters, stop and kill. Each is one request to the
//! router, which commands the agents.

use crate::client::RouterSession;
use agent_sdk::World;
use anyhow::{Context as _, Result, bail};
use shm_schemas::PortRef;
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply};
use shm_schemas::control::router_to_agent::ParamInfo;
use std::process::ExitCode;

/// `nerve connect` / `nerve disconnect`
#[derive(Debug, clap::Args)]
pub struct WireArgs {
    /// Output port, AGENT/PORT.
    pub from: String,
    /// Input port, AGENT/PORT.
    pub to: String,
}

/// `nerve connect`
#[derive(Debug, clap::Args)]
pub struct ConnectArgs {
    /// The two ports.
    #[command(flatten)]
    pub ports: WireArgs,
    /// Connect even if it closes a loop of event-driven agents (an agent on
    /// the loop breaks it itself: it drops or thins what it forwards).
    #[arg(long)]
    pub allow_cycle: bool,
}

/// `nerve param`
#[derive(Debug, clap::Subcommand)]
pub enum ParamCmd {
    /// List an agent's parameters (type, value, default, bounds) and its read-only figures.
    List {
        /// agent name
        name: String,
        /// Print JSON (one object per parameter) instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Print a parameter's value.
    Get {
        /// agent name
        name: String,
        /// parameter
        key: String,
    },
    /// Change a parameter.
    Set {
        /// agent name
        name: String,
        /// parameter
        key: String,
        /// new value
        value: String,
    },
}

/// `nerve param list` as a table: parameters, then figures.
fn param_table(agent: &str, list: &[ParamInfo]) -> String {
    if list.is_empty() {
        return format!("{agent} has no parameters\n");
    }
    let rows: Vec<[String; 5]> = list
        .iter()
        .map(|p| {
            let bounds = match (&p.bounds, p.read_only) {
                (_, true) => "read-only figure".to_owned(),
                (Some(b), false) => b.clone(),
                (None, false) => "any".to_owned(),
            };
            let default = if p.read_only { "-".to_owned() } else { p.default.clone() };
            [p.key.clone(), p.type_name.clone(), p.value.clone(), default, bounds]
        })
        .collect();
    let head = ["KEY", "TYPE", "VALUE", "DEFAULT", "BOUNDS"];
    let mut w = head.map(str::len);
    for r in &rows {
        for (i, c) in r.iter().enumerate() {
            w[i] = w[i].max(c.chars().count());
        }
    }
    let line = |c: [&str; 5]| {
        let mut l = String::new();
        for (i, x) in c.iter().enumerate() {
            if i + 1 == c.len() {
                l.push_str(x);
            } else {
                l.push_str(&format!("{x:<width$}  ", width = w[i]));
            }
        }
        l.trim_end().to_owned() + "\n"
    };
    let mut out = line(head);
    for r in &rows {
        out.push_str(&line([&r[0], &r[1], &r[2], &r[3], &r[4]]));
    }
    out
}

fn refs(a: &WireArgs) -> Result<(PortRef, PortRef)> {
    let from: PortRef = a.from.parse().context("FROM")?;
    let to: PortRef = a.to.parse().context("TO")?;
    Ok((from, to))
}

pub fn connect(world: &World, a: ConnectArgs) -> Result<ExitCode> {
    let (from, to) = refs(&a.ports)?;
    RouterSession::open(world)?.ok(CliRequest::Connect {
        from: from.clone(),
        to: to.clone(),
        allow_cycle: a.allow_cycle,
    })?;
    println!("connected {from} -> {to}");
    Ok(ExitCode::SUCCESS)
}

pub fn disconnect(world: &World, a: WireArgs) -> Result<ExitCode> {
    let (from, to) = refs(&a)?;
    RouterSession::open(world)?.ok(CliRequest::Disconnect { from: from.clone(), to: to.clone() })?;
    println!("disconnected {from} -> {to}");
    Ok(ExitCode::SUCCESS)
}

pub fn rate(world: &World, name: &str, period: &str) -> Result<ExitCode> {
    let d = agent_sdk::clock::parse_duration(period).map_err(anyhow::Error::msg)?;
    RouterSession::open(world)?.ok(CliRequest::Rate { name: name.into(), period_ns: agent_sdk::clock::nanos(d) })?;
    println!("{name}: period {}", agent_sdk::clock::format_duration(d));
    Ok(ExitCode::SUCCESS)
}

#[derive(Debug, Clone, Copy)]
pub enum Simple {
    Suspend,
    Resume,
    Stop,
    Kill,
}

pub fn simple(world: &World, what: Simple, name: &str) -> Result<ExitCode> {
    let s = RouterSession::open(world)?;
    let (req, done) = match what {
        Simple::Suspend => (CliRequest::Suspend { name: name.into() }, "suspended"),
        Simple::Resume => (CliRequest::Resume { name: name.into() }, "resumed"),
        Simple::Stop => (CliRequest::Stop { name: name.into() }, "stopped"),
        Simple::Kill => (CliRequest::Kill { name: name.into() }, "killed"),
    };
    s.ok(req)?;
    println!("{name}: {done}");
    if matches!(what, Simple::Stop | Simple::Kill) {
        // what a restart by hand brings back, said where it happens
        // rather than only in docs/reliability.md
        println!(
            "  a start under the name {name} gets back its connections, and the parameters, rate and suspension \
             set at run time (the router remembers them until it stops)"
        );
    }
    Ok(ExitCode::SUCCESS)
}

pub fn param(world: &World, p: ParamCmd) -> Result<ExitCode> {
    let s = RouterSession::open(world)?;
    match p {
        ParamCmd::List { name, json } => match s.call(CliRequest::ParamList { name: name.clone() })? {
            RouterReply::Params(list) if json => println!("{}", serde_json::to_string_pretty(&list)?),
            RouterReply::Params(list) => print!("{}", param_table(&name, &list)),
            other => bail!("unexpected reply from the router: {other:?}"),
        },
        ParamCmd::Get { name, key } => match s.call(CliRequest::ParamGet { name, key })? {
            RouterReply::Param(v) => println!("{v}"),
            other => bail!("unexpected reply from the router: {other:?}"),
        },
        ParamCmd::Set { name, key, value } => {
            s.ok(CliRequest::ParamSet { name: name.clone(), key: key.clone(), value: value.clone() })?;
            println!("{name}: {key} = {value}");
        }
    }
    Ok(ExitCode::SUCCESS)
}
