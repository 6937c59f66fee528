//! `nerve launch FILE`: a robot from a launch file. Validates the whole file
//! first (nothing starts on any error), starts the router if none runs,
//! batch-starts every agent as a daemon in parallel with a progress line per
//! agent, waits until each has registered, hands them to the router's
//! supervision, applies the connections, and returns — or, with
//! `--foreground`, streams every agent's log and stops everything on Ctrl-C.

use super::down::{bring_down, clean};
use super::logs::{Tail, tails_from_now};
use crate::client::RouterSession;
use crate::interrupt;
use crate::launch_file::{self, LaunchFile, RestartPolicy};
use agent_sdk::World;
use anyhow::{Context as _, Result, anyhow, bail};
use shm_schemas::control::cli_to_router::{self as proto, CliRequest, RouterReply};
use std::io::Read;
use std::process::{Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

/// `nerve launch`
#[derive(Debug, clap::Args)]
pub struct LaunchArgs {
    /// The launch file (TOML).
    pub file: std::path::PathBuf,
    /// Stay attached: stream the agents' logs, stop everything on Ctrl-C.
    #[arg(long)]
    pub foreground: bool,
}

/// How long `launch` waits for every agent to register.
const REGISTER_TIMEOUT: Duration = Duration::from_secs(20);

fn router_up(world: &World) -> bool {
    RouterSession::open(world).and_then(|s| s.call(CliRequest::Ps)).is_ok()
}

/// Starts the router of `world` as a daemon unless one answers.
pub fn ensure_router(world: &World) -> Result<()> {
    if router_up(world) {
        return Ok(());
    }
    let exe = std::env::current_exe().context("cannot find the nerve executable")?;
    let out = Command::new(exe)
        .args(["--robot", world.robot().as_str(), "router", "--daemon"])
        .stdin(Stdio::null())
        .output()
        .context("cannot start the router")?;
    if !out.status.success() {
        bail!("the router did not start: {}", String::from_utf8_lossy(&out.stderr).trim());
    }
    eprintln!("{}", String::from_utf8_lossy(&out.stdout).trim());
    Ok(())
}

fn policy(p: RestartPolicy) -> proto::RestartPolicy {
    match p {
        RestartPolicy::Never => proto::RestartPolicy::Never,
        RestartPolicy::OnFailure => proto::RestartPolicy::OnFailure,
        RestartPolicy::Always => proto::RestartPolicy::Always,
    }
}

pub fn launch(cli_robot: &str, explicit: bool, a: LaunchArgs) -> Result<ExitCode> {
    let t0 = Instant::now();
    let (file, world) = match launch_file::load(&a.file, cli_robot, explicit) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("{e}");
            return Ok(ExitCode::from(1));
        }
    };
    super::shm_space::ensure_shm_space("launch")?;
    world.ensure_state_dirs()?;
    let n = file.agents.len();
    eprintln!(
        "launching {} on robot {}: {n} agent(s), {} connection(s)",
        file.path.display(),
        world.robot(),
        file.connections.len()
    );
    // taken before anything starts: the foreground stream shows this run's
    // lines from the start, and none of the earlier runs' (R16)
    let tails = a.foreground.then(|| {
        let names = file.agents.iter().map(|a| a.name.as_str()).chain(["router"]);
        tails_from_now(names.map(|n| world.log_file(n)))
    });
    let up = bring_up(&world, &file)?;
    let (failed, wiring_failed) = (up.failed, up.wiring_failed);
    eprintln!(
        "robot {} is up: {} agent(s) running, {} connection(s), in {:.2} s{}",
        world.robot(),
        n - failed,
        file.connections.len() - wiring_failed,
        t0.elapsed().as_secs_f64(),
        if a.foreground { "" } else { " (`nerve ps`, `nerve graph`, `nerve logs NAME`, `nerve down`)" }
    );
    if let Some(tails) = tails {
        follow(&world, tails)?;
        return Ok(ExitCode::SUCCESS);
    }
    Ok(if failed > 0 || wiring_failed > 0 { ExitCode::from(1) } else { ExitCode::SUCCESS })
}

/// Starts every agent not already running, in parallel; returns how many failed.
fn start_agents(world: &World, file: &LaunchFile, running: &[String]) -> Result<usize> {
    let n = file.agents.len();
    let mut children = Vec::new();
    for spec in &file.agents {
        if running.contains(&spec.name) {
            children.push((spec, None));
            continue;
        }
        let argv = spec.argv(world.robot().as_str());
        let child = Command::new(&argv[0])
            .args(&argv[1..])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("cannot start {}", argv[0]))?;
        children.push((spec, Some(child)));
    }
    let mut failed = 0;
    for (i, (spec, child)) in children.into_iter().enumerate() {
        let Some(mut child) = child else {
            eprintln!("  [{}/{n}] {} ({}) already running", i + 1, spec.name, spec.kind);
            continue;
        };
        let status = child.wait()?;
        let mut out = String::new();
        let mut err = String::new();
        if let Some(mut o) = child.stdout.take() {
            let _ = o.read_to_string(&mut out);
        }
        if let Some(mut e) = child.stderr.take() {
            let _ = e.read_to_string(&mut err);
        }
        if status.success() {
            eprintln!(
                "  [{}/{n}] {} ({}) {}",
                i + 1,
                spec.name,
                spec.kind,
                out.trim().trim_start_matches(&format!("{} ", spec.name))
            );
        } else {
            failed += 1;
            eprintln!(
                "  [{}/{n}] {} ({}) FAILED: {} (log: {})",
                i + 1,
                spec.name,
                spec.kind,
                err.trim().trim_start_matches("error: "),
                world.log_file(&spec.name).display()
            );
        }
    }
    Ok(failed)
}

fn wait_registered(session: &RouterSession, file: &LaunchFile) -> Result<()> {
    let t0 = Instant::now();
    loop {
        // registered, or already in the supervisor's hands (restarting, failed)
        let live: Vec<String> = match session.call(CliRequest::Ps)? {
            RouterReply::Agents(v) => v.into_iter().map(|a| a.name).collect(),
            _ => vec![],
        };
        let missing: Vec<&str> =
            file.agents.iter().map(|a| a.name.as_str()).filter(|n| !live.iter().any(|l| l == n)).collect();
        if missing.is_empty() {
            return Ok(());
        }
        if t0.elapsed() > REGISTER_TIMEOUT {
            return Err(anyhow!(
                "not registered after {REGISTER_TIMEOUT:?}: {} (see `nerve logs NAME`)",
                missing.join(", ")
            ));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Streams every agent's log (and the router's) from where `tails` start
/// until Ctrl-C, then brings the robot down.
fn follow(world: &World, mut tails: Vec<Tail>) -> Result<()> {
    interrupt::catch();
    eprintln!("streaming logs; Ctrl-C stops every agent and the router");
    while !interrupt::requested() {
        for t in &mut tails {
            for l in t.poll() {
                println!("{l}");
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    eprintln!("stopping robot {}", world.robot());
    let (stopped, killed) = bring_down(world, Duration::from_secs(3));
    clean(world);
    eprintln!(
        "stopped {stopped} process(es){}",
        if killed > 0 { format!(", {killed} with SIGKILL") } else { String::new() }
    );
    Ok(())
}

/// Launches `path` as `nerve launch` does (without `--foreground`) on robot
/// `robot` unless the file names its own, and returns the robot's world.
/// Unlike [`launch`], any failure — an invalid file, an agent that did not
/// start or register, a connection refused — is an error. Used by `nerve demo`.
pub(crate) fn launch_robot(robot: &str, path: &std::path::Path) -> Result<World> {
    let (file, world) = launch_file::load(path, robot, false).map_err(|e| anyhow!("{e}"))?;
    super::shm_space::ensure_shm_space("launch")?;
    world.ensure_state_dirs()?;
    let up = bring_up(&world, &file)?;
    if up.failed > 0 {
        bail!("{} agent(s) of {} did not start (see the lines above)", up.failed, path.display());
    }
    if up.wiring_failed > 0 {
        bail!("{} connection(s) of {} could not be made (see the lines above)", up.wiring_failed, path.display());
    }
    Ok(world)
}

/// What [`bring_up`] achieved.
struct BroughtUp {
    /// agents that did not start
    failed: usize,
    /// connections that could not be made
    wiring_failed: usize,
}

/// Starts the router if needed, hands every agent to its supervision (first,
/// so that an agent dying right after it starts is restarted), starts the
/// agents not yet running, waits until they have registered, and applies the
/// connections — a progress line for each.
fn bring_up(world: &World, file: &LaunchFile) -> Result<BroughtUp> {
    ensure_router(world)?;
    let session = RouterSession::open(world)?;
    let running: Vec<String> = match session.call(CliRequest::Ps)? {
        RouterReply::Agents(v) => v.into_iter().filter(|a| a.pid > 0).map(|a| a.name).collect(),
        _ => vec![],
    };
    for spec in &file.agents {
        session
            .ok(CliRequest::Supervise(proto::Supervision {
                name: spec.name.clone(),
                argv: spec.argv(world.robot().as_str()),
                policy: policy(spec.restart),
                max_restarts: spec.max_restarts,
                window_ns: agent_sdk::clock::nanos(spec.restart_window),
                backoff_ns: agent_sdk::clock::nanos(spec.backoff),
                importance: spec.importance,
            }))
            .with_context(|| format!("the router refused to supervise {}", spec.name))?;
    }
    let failed = start_agents(world, file, &running)?;
    wait_registered(&session, file)?;
    let mut wiring_failed = 0;
    for (from, to) in &file.connections {
        match session.ok(CliRequest::Connect { from: from.clone(), to: to.clone() }) {
            Ok(()) => eprintln!("  connected {from} -> {to}"),
            Err(e) => {
                wiring_failed += 1;
                eprintln!("  could not connect {from} -> {to}: {e:#}");
            }
        }
    }
    Ok(BroughtUp { failed, wiring_failed })
}
