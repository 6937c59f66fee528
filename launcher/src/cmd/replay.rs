//! `nerve replay`: a recording's ports published into a robot again.
//!
//! Each recorded agent comes back as a replayed agent of the same name (or
//! the one `--as OLD=NEW` gives): its ports are made again with the
//! recorded type, layout and attributes ([`RawOutput`]), so agents built
//! with the type read them as their own, and it registers with the router
//! like any agent (kind `replay`): `nerve ps` lists it, the router wires
//! the connections its launch file or connection list names, and `nerve
//! stop NAME` ends its part of the replay. The samples go out with the
//! recorded spacing of their log times, scaled by `--speed`, or as fast as
//! they can (`--fast`); each carries a fresh sequence number and stamp,
//! and the recorded bytes unchanged.
//!
//! The file is streamed ([`nerve_recording::read`]), never loaded: a first
//! read learns its ports (keeping no message), then each round reads it
//! again a message at a time, in the order it was recorded, and reads past
//! the images without keeping them. Memory stays that of one message,
//! however long the recording. A file cut short (the recorder was killed,
//! or the disk filled) is replayed up to its last whole message, with a
//! warning that says what was lost.

use crate::client::cli_node;
use agent_sdk::World;
use agent_sdk::control::{ControlServer, ControlSize, agent_router_client};
use agent_sdk::raw_port::RawOutput;
use anyhow::{Context as _, Result, anyhow, bail};
use nerve_recording::foxglove;
use nerve_recording::read::{Event, RecordingReader, nerve_schema};
use shm_schemas::control::agent_to_router::{AgentToRouter, PortSpec, Registration, TaskKind};
use shm_schemas::control::cli_to_router::{RouterReply, RouterRequest};
use shm_schemas::control::router_to_agent::{AgentCommand, AgentReply};
use shm_schemas::services::port_attributes::parse_fingerprint;
use shm_schemas::stats::AgentStats;
use shm_schemas::{AgentName, Schema};
use std::collections::BTreeMap;
use std::io::IsTerminal as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// `nerve replay`
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The MCAP file `nerve record` wrote.
    pub file: PathBuf,
    /// Play the recorded timing this many times faster (0.5: half speed).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Ignore the recorded timing: publish as fast as the readers take it.
    #[arg(long)]
    pub fast: bool,
    /// Start again at the end, until Ctrl-C.
    #[arg(long = "loop")]
    pub repeat: bool,
    /// Replay only these recorded agents (`NAME`), or under another name
    /// (`NAME=NEW`); several may follow one `--as` (`--as g t1`), or each
    /// its own. Default: every agent of the recording, under its own name.
    #[arg(long = "as", value_name = "AGENT[=NEW]", num_args = 1..)]
    pub agents: Vec<String>,
    /// Seconds to wait after the replayed agents registered, before the
    /// first sample (time for readers to connect).
    #[arg(long, default_value_t = 0.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub delay: f64,
    /// No progress line.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// A recorded port, as the file describes it.
struct Track {
    /// the recorded agent and port
    agent: String,
    port: String,
    schema: Schema,
    fingerprint: u64,
}

/// The recorded port of channel `ch` of `file`, or what makes it not one
/// of nerve's (its schema is checked before it reaches shared memory).
fn track_of(file: &str, ch: &mcap::Channel<'_>) -> Result<Track> {
    let schema = nerve_schema(file, ch)?;
    let meta = |k: &str| ch.metadata.get(k).cloned();
    let (Some(agent), Some(port)) = (meta("agent"), meta("port")) else {
        bail!("{file}: channel {} does not say its agent and port; is it a file `nerve record` wrote?", ch.topic);
    };
    let fingerprint = meta("fingerprint").and_then(|f| parse_fingerprint(&f)).unwrap_or(schema.fingerprint());
    if fingerprint != schema.fingerprint() {
        bail!("{file}: channel {}'s schema does not match its fingerprint; the file is damaged", ch.topic);
    }
    Ok(Track { agent, port, schema, fingerprint })
}

/// Whether `ch` holds a ring's images (for people and viewers; their
/// notices replay).
fn is_images(ch: &mcap::Channel<'_>) -> bool {
    ch.message_encoding == foxglove::MESSAGE_ENCODING && ch.topic.ends_with(nerve_recording::IMAGE_TOPIC_SUFFIX)
}

/// The recorded ports of `path`, by channel id, from a first read that
/// keeps no message; says once what a file cut short lost.
fn tracks_of(path: &Path) -> Result<BTreeMap<u16, Track>> {
    let file = path.display().to_string();
    let mut reader = RecordingReader::open(path)?;
    reader.skip_messages();
    let mut tracks = BTreeMap::new();
    while let Some(event) = reader.next_event()? {
        if let Event::Channel(ch) = event
            && !is_images(&ch)
        {
            tracks.insert(ch.id, track_of(&file, &ch)?);
        }
    }
    if let Some(cut) = reader.cut() {
        eprintln!("warning: {cut}");
    }
    Ok(tracks)
}

/// A replayed agent: its ports and its place in the robot.
struct Replayed {
    name: String,
    server: ControlServer<AgentCommand, AgentReply>,
    sent: u64,
    stopped: bool,
}

/// The `--as` choices: recorded name → name to replay under.
fn selection(args: &[String]) -> Result<BTreeMap<String, String>> {
    let mut out = BTreeMap::new();
    for a in args {
        let (from, to) = a.split_once('=').unwrap_or((a, a));
        for n in [from, to] {
            AgentName::new(n).with_context(|| format!("--as {a}"))?;
        }
        out.insert(from.to_string(), to.to_string());
    }
    Ok(out)
}

pub fn replay(world: &World, a: ReplayArgs) -> Result<ExitCode> {
    if !(a.fast || (a.speed.is_finite() && a.speed > 0.0)) {
        bail!("--speed must be a positive number (or give --fast)");
    }
    let chosen = selection(&a.agents)?;
    let tracks = tracks_of(&a.file)?;
    let recorded: Vec<String> =
        tracks.values().map(|t| t.agent.clone()).collect::<std::collections::BTreeSet<_>>().into_iter().collect();
    for c in chosen.keys() {
        if !recorded.contains(c) {
            bail!("the recording has no agent {c}; it has {}", recorded.join(", "));
        }
    }
    let name_of = |agent: &str| -> Option<String> {
        if chosen.is_empty() { Some(agent.to_string()) } else { chosen.get(agent).cloned() }
    };

    // the replayed agents: ports, control service, registration
    let node = cli_node(world)?;
    let router = agent_router_client::<RouterRequest, RouterReply>(world, &node).ok();
    if router.is_none() {
        eprintln!(
            "no router runs for robot {}: replaying without registering (nerve ps will not list them)",
            world.robot()
        );
    }
    let mut outputs: BTreeMap<u16, (String, RawOutput)> = BTreeMap::new();
    let mut agents: BTreeMap<String, Replayed> = BTreeMap::new();
    let mut regs: BTreeMap<String, Registration> = BTreeMap::new();
    for (id, t) in &tracks {
        let Some(name) = name_of(&t.agent) else { continue };
        let agent = AgentName::new(&name)?;
        if !agents.contains_key(&name) {
            // one server per name: a running agent of that name holds it already
            let server = ControlServer::create(&node, &world.robot().ctl_service(&agent), ControlSize::AGENT)
                .map_err(|e| anyhow!("{name} cannot be replayed: an agent of that name runs ({e}); stop it or replay under another name (--as {}={name}2)", t.agent))?;
            agents.insert(name.clone(), Replayed { name: name.clone(), server, sent: 0, stopped: false });
        }
        let service = world.robot().port_service(&name, &t.port);
        let out = RawOutput::create(&node, &service, &t.schema, t.fingerprint, &name)
            .with_context(|| format!("cannot make port {name}/{}", t.port))?;
        outputs.insert(*id, (name.clone(), out));
        let reg = regs.entry(name.clone()).or_insert_with(|| Registration {
            name: name.clone(),
            pid: std::process::id(),
            kind: "replay".into(),
            executable: std::env::current_exe().map(|p| p.display().to_string()).unwrap_or_default(),
            task: TaskKind::EventDriven,
            period_ns: None,
            inputs: vec![],
            outputs: vec![],
            log_file: None,
            suspended: false,
            schemas: vec![],
            services: vec![],
            clients: vec![],
        });
        reg.outputs.push(PortSpec {
            name: t.port.clone(),
            type_name: t.schema.type_name.clone(),
            fingerprint: t.fingerprint,
        });
        shm_schemas::control::agent_to_router::add_schema(&mut reg.schemas, t.schema.clone());
    }
    if agents.is_empty() {
        bail!("nothing to replay");
    }
    if let Some(client) = &router {
        for reg in regs.values() {
            match client.call(&RouterRequest::Agent(AgentToRouter::Register(reg.clone())), Duration::from_secs(3)) {
                Ok(RouterReply::Registered { .. }) => {}
                Ok(RouterReply::Error(e)) => bail!("the router refused replayed agent {}: {e}", reg.name),
                Ok(other) => bail!("unexpected answer of the router: {other:?}"),
                Err(e) => bail!("cannot register replayed agent {}: {e}", reg.name),
            }
        }
    }

    // the replay
    crate::interrupt::catch();
    let delay_end = Instant::now() + Duration::from_secs_f64(a.delay.max(0.0));
    while Instant::now() < delay_end && !crate::interrupt::requested() {
        serve(&mut agents, router.as_ref());
        std::thread::sleep(Duration::from_millis(20));
    }
    let tty = std::io::stderr().is_terminal();
    let start = Instant::now();
    let mut next_progress = start + Duration::from_secs(1);
    let mut total = 0u64;
    let mut rounds = 0u64;
    'replay: loop {
        rounds += 1;
        // the file is read again each round, a message at a time, in the
        // order it was recorded; image channels and agents not replayed are
        // read past without being kept
        let mut reader = RecordingReader::open(&a.file)?;
        let mut round: Option<(Instant, u64)> = None;
        while let Some(event) = reader.next_event()? {
            let m = match event {
                Event::Channel(ch) => {
                    if !outputs.contains_key(&ch.id) {
                        reader.skip(ch.id);
                    }
                    continue;
                }
                Event::Message(m) => m,
            };
            let Some((name, out)) = outputs.get_mut(&m.channel.id) else { continue };
            if agents.get(name.as_str()).is_some_and(|r| r.stopped) {
                continue;
            }
            let (round_start, first) = *round.get_or_insert((Instant::now(), m.log_time));
            if !a.fast {
                let due =
                    round_start + Duration::from_secs_f64(m.log_time.saturating_sub(first) as f64 / 1e9 / a.speed);
                while Instant::now() < due {
                    serve(&mut agents, router.as_ref());
                    if crate::interrupt::requested() || agents.values().all(|r| r.stopped) {
                        break 'replay;
                    }
                    std::thread::sleep(due.saturating_duration_since(Instant::now()).min(Duration::from_millis(20)));
                }
            }
            out.send(m.data).with_context(|| format!("cannot publish on {name}"))?;
            if let Some(r) = agents.get_mut(name.as_str()) {
                r.sent += 1;
            }
            total += 1;
            if a.fast && total.is_multiple_of(256) {
                serve(&mut agents, router.as_ref());
            }
            if Instant::now() >= next_progress && !a.quiet {
                next_progress = Instant::now() + Duration::from_secs(1);
                let line = format!("replaying: {total} messages sent (round {rounds})");
                if tty { eprint!("\r{line}   ") } else { eprintln!("{line}") }
            }
            if crate::interrupt::requested() || agents.values().all(|r| r.stopped) {
                break 'replay;
            }
        }
        if !a.repeat || round.is_none() {
            break;
        }
    }
    serve(&mut agents, router.as_ref());
    for r in agents.values().filter(|r| !r.stopped) {
        unregister(router.as_ref(), &r.name);
    }
    if !a.quiet && tty {
        eprintln!();
    }
    println!(
        "replayed {total} messages of {} ports ({} agents) from {} in {:.1} s",
        outputs.len(),
        agents.len(),
        a.file.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}

type RouterClient = agent_sdk::control::ControlClient<RouterRequest, RouterReply>;

/// Answers the router and tools on each replayed agent's control service;
/// an agent told to stop leaves the router at once (the process replays
/// the others on).
fn serve(agents: &mut BTreeMap<String, Replayed>, router: Option<&RouterClient>) {
    for r in agents.values_mut() {
        let was_stopped = r.stopped;
        while let Ok(Some((req, responder))) = r.server.receive() {
            let reply = match req {
                Ok(AgentCommand::Stats) => AgentReply::Stats(AgentStats {
                    cycles: r.sent,
                    figures: vec![("replay.sent".into(), r.sent.to_string())],
                    ..Default::default()
                }),
                Ok(AgentCommand::Stop) => {
                    r.stopped = true;
                    AgentReply::Ok
                }
                Ok(other) => AgentReply::Error(format!("{} is a replayed agent: it cannot {other:?}", r.name)),
                Err(e) => AgentReply::Error(e.to_string()),
            };
            responder.respond_or(&reply, |e| AgentReply::Error(e.to_string()));
        }
        if r.stopped && !was_stopped {
            unregister(router, &r.name);
        }
    }
}

fn unregister(router: Option<&RouterClient>, name: &str) {
    if let Some(client) = router {
        let msg = RouterRequest::Agent(AgentToRouter::Unregister { name: name.into(), pid: std::process::id() });
        if let Err(e) = client.call(&msg, Duration::from_secs(1)) {
            tracing::debug!(agent = name, "could not unregister: {e}");
        }
    }
}
