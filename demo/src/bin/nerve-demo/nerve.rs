//! The robot, as `nerve-demo` reaches it: through the `nerve` executable
//! that started it (`nerve --robot R launch FILE`, `nerve --robot R down`,
//! `nerve --robot R cmd ...`, `nerve bridge keys ...`), the router's socket
//! for tools (which agents run, their figures) and taps, its own
//! subscriptions to output ports. It imports nothing of the launcher: what
//! a user can do from a shell, the demos do the same way.

use agent_sdk::World;
use agent_sdk::control::{ToolConnection, router_client};
use agent_sdk::ports::{SUBSCRIBER_BUFFER, existing_port_service};
use agent_sdk::simclock::{self, PAGE_FILE, SIM_CLOCK_ENV};
use agent_sdk::world::Ipc;
use anyhow::{Context as _, Result, anyhow, bail};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;
use shm_schemas::control::cli_to_router::{AgentView, CliRequest, RouterReply, RouterRequest};
use shm_schemas::{Payload, SampleHeader};
use std::collections::BTreeMap;
use std::os::unix::process::CommandExt as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How long a question to the router may take.
const ROUTER_TIMEOUT: Duration = Duration::from_secs(10);

/// The `nerve` executable: `$NERVE_BIN` (set by `nerve demo` and `nerve
/// calibrate`, which run this program), else `nerve` next to this program,
/// else `nerve` on `PATH`.
pub fn nerve_exe() -> PathBuf {
    if let Some(p) = std::env::var_os("NERVE_BIN").filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(|d| d.join("nerve")))
        .filter(|p| p.is_file())
        .unwrap_or_else(|| PathBuf::from("nerve"))
}

/// `nerve --robot ROBOT ARGS...`, as a command to finish and run. It runs
/// in a process group of its own: Ctrl-C in the terminal reaches this
/// program alone, which ends the run and then brings the robot down, so a
/// launch or a `nerve down` under way is never cut short.
pub fn nerve(robot: &str, args: &[&str]) -> Command {
    let mut c = Command::new(nerve_exe());
    c.arg("--robot").arg(robot).args(args).stdin(Stdio::null()).process_group(0);
    c
}

/// Brings robot `robot` up from the launch file `path` with `nerve launch`
/// (its progress lines go to this program's stderr), on the simulated
/// clock whose page is `clock`, if any. Any failure — an invalid file, an
/// agent that did not start or register, a connection refused — is an
/// error.
pub fn launch(robot: &str, path: &Path, clock: Option<&Path>) -> Result<()> {
    let mut c = nerve(robot, &["launch"]);
    c.arg(path);
    if let Some(page) = clock {
        // the router and every agent `nerve launch` starts inherit it
        c.env(SIM_CLOCK_ENV, page);
    }
    let status = c.status().with_context(|| format!("cannot run {}", nerve_exe().display()))?;
    if !status.success() {
        bail!("`nerve --robot {robot} launch {}` failed ({status}; see the lines above)", path.display());
    }
    Ok(())
}

/// Stops everything of robot `robot` and removes what it left, with `nerve
/// down`; returns its line (`robot R: stopped N process(es)...`).
pub fn down(robot: &str) -> String {
    match nerve(robot, &["down"]).stderr(Stdio::inherit()).output() {
        Ok(out) if out.status.success() => String::from_utf8_lossy(&out.stdout).trim().to_owned(),
        Ok(out) => format!(
            "warning: `nerve --robot {robot} down` failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stdout).trim()
        ),
        Err(e) => format!("warning: cannot run `nerve --robot {robot} down`: {e}"),
    }
}

/// Makes the fleet's keys for the bridges' mutual TLS in `dir` (the CA
/// once, then a certificate per robot that has none), with `nerve bridge
/// keys`.
pub fn ensure_bridge_keys(dir: &Path, robots: &[&str]) -> Result<()> {
    let exists = |f: &str| std::fs::symlink_metadata(dir.join(f)).is_ok();
    let dir_s = dir.to_str().ok_or_else(|| anyhow!("the path {} is not UTF-8", dir.display()))?;
    let mut steps: Vec<Vec<&str>> = Vec::new();
    if !exists("ca.key") && !exists("ca.crt") {
        steps.push(vec!["bridge", "keys", "init", "--dir", dir_s]);
    }
    for r in robots {
        if !exists(&format!("{r}.crt")) {
            steps.push(vec!["bridge", "keys", "add", r, "--dir", dir_s]);
        }
    }
    for args in steps {
        let out = Command::new(nerve_exe())
            .args(&args)
            .stdin(Stdio::null())
            .process_group(0)
            .output()
            .with_context(|| format!("cannot run {}", nerve_exe().display()))?;
        if !out.status.success() {
            bail!("`nerve {}` failed: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim());
        }
    }
    Ok(())
}

/// The router's list of agents (`nerve ps`), `None` where no router answers.
pub fn agents(world: &World) -> Option<Vec<AgentView>> {
    let req = RouterRequest::Cli(CliRequest::Ps);
    let reply: RouterReply = match ToolConnection::connect(&world.tool_socket()) {
        Ok(c) => c.call(&req, ROUTER_TIMEOUT).ok()?,
        // a router without its socket: its iceoryx2 service for tools
        Err(_) => {
            let node = cli_node(world).ok()?;
            router_client(world, &node).ok()?.call(&req, ROUTER_TIMEOUT).ok()?
        }
    };
    match reply {
        RouterReply::Agents(v) => Some(v),
        _ => None,
    }
}

/// Names of the agents running on `world` (none when no router answers).
pub fn running_agents(world: &World) -> Vec<String> {
    agents(world).unwrap_or_default().into_iter().filter(|a| a.pid > 0).map(|a| a.name).collect()
}

/// Every figure of every agent of `world`.
pub fn all_figures(world: &World) -> BTreeMap<String, BTreeMap<String, String>> {
    agents(world)
        .unwrap_or_default()
        .into_iter()
        .map(|a| (a.name, a.stats.map(|s| s.figures.into_iter().collect()).unwrap_or_default()))
        .collect()
}

/// Refuses a robot that runs agents already; `why` says what the user
/// would lose, `or` what else to do.
pub fn refuse_busy(world: &World, why: &str, or: &str) -> Result<()> {
    let live = running_agents(world);
    if !live.is_empty() {
        let r = world.robot();
        bail!(
            "robot {r} already runs {} agent(s) ({}){why}; stop them with `nerve --robot {r} down`{or}",
            live.len(),
            live.join(", ")
        );
    }
    Ok(())
}

/// Routes SIGINT and SIGTERM (Ctrl-C) to the flag [`interrupted`] reads, so
/// that a run ends cleanly: robots brought down, what was recorded written.
pub fn catch_interrupts() {
    if let Err(e) = agent_sdk::termination::install() {
        tracing::warn!("{e}; Ctrl-C ends the command at once");
    }
}

/// Whether SIGINT or SIGTERM came since [`catch_interrupts`].
pub fn interrupted() -> bool {
    agent_sdk::termination::requested()
}

/// This program's iceoryx2 node in `world`.
pub fn cli_node(world: &World) -> Result<Node<Ipc>> {
    world.node(&format!("cli-{}", std::process::id())).context("cannot join the robot's shared memory")
}

/// Copies the agents' logs of `world` into `dir`.
pub fn copy_logs(world: &World, dir: &Path) {
    if let Err(e) = std::fs::create_dir_all(dir) {
        tracing::warn!(dir = %dir.display(), "cannot create the logs' copy: {e}");
        return;
    }
    let Ok(rd) = std::fs::read_dir(world.logs_dir()) else { return };
    for e in rd.flatten() {
        let _ = std::fs::copy(e.path(), dir.join(e.file_name()));
    }
}

/// `{state}` and `{robot}` of a launch file's argument, expanded as `nerve launch` does.
pub fn expand(s: &str, world: &World) -> String {
    s.replace("{state}", &world.state_dir().display().to_string()).replace("{robot}", world.robot().as_str())
}

/// A tap: this program's own subscription to an agent's output port, read
/// when it likes (zero copy, like any agent's input; the publisher is never
/// disturbed).
pub struct Tap<T: Payload> {
    port: String,
    sub: Subscriber<Ipc, T, SampleHeader>,
}

impl<T: Payload> Tap<T> {
    /// Subscribes to `agent/port` of `world` if the port exists now.
    pub fn try_open(world: &World, node: &Node<Ipc>, agent: &str, port: &str) -> Result<Option<Self>> {
        let service = world.robot().port_service(agent, port);
        let Some(ps) = existing_port_service::<T>(node, &service) else { return Ok(None) };
        let sub = ps
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| anyhow!("cannot subscribe to {agent}/{port} of robot {}: {e:?}", world.robot()))?;
        Ok(Some(Tap { port: format!("{agent}/{port}"), sub }))
    }

    /// Subscribes to `agent/port`, waiting up to `wait` for it to appear.
    pub fn open(world: &World, node: &Node<Ipc>, agent: &str, port: &str, wait: Duration) -> Result<Self> {
        let t0 = Instant::now();
        loop {
            if let Some(t) = Self::try_open(world, node, agent, port)? {
                return Ok(t);
            }
            if t0.elapsed() > wait {
                bail!("the port {agent}/{port} of robot {} did not appear within {wait:?}", world.robot());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Calls `f` for every sample received since the last call (at most the
    /// subscriber's buffer of them: older ones are gone).
    pub fn drain(&self, mut f: impl FnMut(&SampleHeader, &T)) -> Result<()> {
        while let Some(s) = self.sub.receive().map_err(|e| anyhow!("cannot read {}: {e:?}", self.port))? {
            f(s.user_header(), s.payload());
        }
        Ok(())
    }
}

pub use agent_sdk::simclock::SimTimeArgs;

/// The simulated clock of a run: its page, named to every robot the run
/// launches ([`launch`]), removed when dropped (after the robots are down).
pub struct SimClock {
    page: PathBuf,
}

impl SimClock {
    /// Puts `world`'s robot on simulated time at `scale`: writes the clock's
    /// page into its state folder. Refuses when this program already runs
    /// on another clock, or the robot runs agents (on their own clock).
    pub fn start(world: &World, scale: f64) -> Result<Self> {
        world.ensure_state_dirs()?;
        let page = world.state_dir().join(PAGE_FILE);
        if let Some(other) = std::env::var_os(SIM_CLOCK_ENV).filter(|p| !p.is_empty() && *p != page.as_os_str()) {
            bail!(
                "this shell already names a simulated clock ({SIM_CLOCK_ENV}={}); unset {SIM_CLOCK_ENV} to give robot {} \
                 a clock of its own",
                PathBuf::from(other).display(),
                world.robot()
            );
        }
        refuse_busy(world, " on its own clock", " to run it on simulated time")?;
        simclock::create(&page, scale)
            .with_context(|| format!("robot {} cannot run on simulated time", world.robot()))?;
        tracing::info!(scale, page = %page.display(), robot = %world.robot(), "the run on simulated time");
        Ok(SimClock { page })
    }

    /// The clock's page.
    pub fn page(&self) -> &Path {
        &self.page
    }
}

impl Drop for SimClock {
    fn drop(&mut self) {
        if let Err(e) = std::fs::remove_file(&self.page)
            && e.kind() != std::io::ErrorKind::NotFound
        {
            tracing::warn!(page = %self.page.display(), "cannot remove the simulated clock's page: {e}");
        }
    }
}
