//! `control`: the control plane, as users feel it.
//!
//! * **hot-add**: `nerve start relay --name h` (the router already holds the
//!   connection `t1/tick -> h/in` from an earlier run of `h`) until the first
//!   sample of `h/out` leaves `h` (its header stamp, seen by a subscriber
//!   in this process), and until the command returns;
//! * **rewire**: `nerve connect t2/tick r/in` until the first sample from the
//!   new source leaves `r/out` — once through the `nerve` command (a process
//!   per command, as a user types it) and once as a direct request to the
//!   router (what a program such as the decision maker pays);
//! * **launch**: `nerve launch` of 10 and 50 agents (a ticker and a chain of
//!   relays), from the command to all registered and connected, router start
//!   included.

use crate::machine::Machine;
use crate::procs::Robot;
use crate::report::Report;
use crate::stats::Summary;
use agent_sdk::World;
use agent_sdk::clock::now_ns;
use agent_sdk::control::router_client;
use agent_sdk::ports::{port_event, port_service};
use anyhow::{Context as _, Result, anyhow, bail};
use serde::Serialize;
use shm_schemas::PortRef;
use shm_schemas::control::cli_to_router::{CliRequest, RouterReply, RouterRequest};
use shm_schemas::payloads::Tick;
use std::time::{Duration, Instant};

/// Hot-add, `nerve start` → the first sample downstream (issue 18).
const HOT_ADD_TARGET_NS: f64 = 10e6;
/// Rewire, the caller's request → the reply once the agent subscribed (issue 18).
const REWIRE_TARGET_NS: f64 = 2e6;
/// `nerve launch` of 50 agents (issue 18).
const LAUNCH_50_TARGET_NS: f64 = 500e6;

/// The robots' tags ([`Robot::new`]): hot-add, rewire, and each launch.
const HOT_ADD_TAG: &str = "ch";
const REWIRE_TAG: &str = "cr";
fn launch_tag(agents: usize, round: usize) -> String {
    format!("l{agents}x{round}")
}

/// Options of the control scenario.
#[derive(Debug)]
pub struct ControlOpts {
    /// hot-add and rewire repetitions
    pub rounds: usize,
    /// launch sizes
    pub launch_sizes: Vec<usize>,
    /// launches per size
    pub launch_rounds: usize,
    /// show child output
    pub verbose: bool,
    /// another relay executable hot-added in alternate rounds beside `relay`
    pub hot_add_beside: Option<std::path::PathBuf>,
}

/// Hot-adds of another relay executable, alternately with `relay`'s.
#[derive(Debug, Serialize)]
pub struct BesideRow {
    /// the executable
    pub executable: String,
    /// `nerve start` to the first sample downstream, ns
    pub hot_add: Summary,
    /// `nerve start` to the command's exit, ns
    pub hot_add_command: Summary,
    /// its median over `relay`'s, same rounds
    pub ratio_to_relay: f64,
}

/// Launch time for one size.
#[derive(Debug, Serialize)]
pub struct LaunchRow {
    /// agents in the file
    pub agents: usize,
    /// wall time of `nerve launch`, ns
    pub launch: Summary,
}

/// The control report: the [`Head`](crate::report::Head) and [`ControlResults`].
pub type ControlReport = Report<ControlResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Serialize)]
pub struct ControlResults {
    /// `nerve start` to the first sample downstream, ns
    pub hot_add: Summary,
    /// `nerve start` to the command's exit (the agent registered and ready), ns
    pub hot_add_command: Summary,
    /// `nerve connect` (the command) to the first sample from the new source, ns
    pub rewire_cli: Summary,
    /// a connect request to the router to the first sample from the new source, ns
    pub rewire_request: Summary,
    /// a connect request to the router to its reply (the agent has subscribed), ns
    pub rewire_reply: Summary,
    /// hot-adds of `--hot-add-beside`, alternately with `relay`'s
    pub hot_add_beside: Option<BesideRow>,
    /// launch times
    pub launch: Vec<LaunchRow>,
    /// hot-add median / 10 ms (issue 18's target; issue 7's was 20 ms)
    pub hot_add_vs_target: f64,
    /// rewire (request → first sample) median / 5 ms (issue 7's target)
    pub rewire_vs_target: f64,
    /// rewire (request → the router's reply) median / 2 ms (issue 18's target)
    pub rewire_reply_vs_target: f64,
    /// wall time of the whole scenario, s
    pub seconds: f64,
}

/// A subscriber on an output port, in this process.
struct Watch {
    _node: iceoryx2::prelude::Node<agent_sdk::Ipc>,
    sub: iceoryx2::port::subscriber::Subscriber<agent_sdk::Ipc, Tick, shm_schemas::SampleHeader>,
    listener: iceoryx2::port::listener::Listener<agent_sdk::Ipc>,
}

impl Watch {
    fn new(robot: &Robot, agent: &str, port: &str) -> Result<Self> {
        let world = World::new(&robot.name)?;
        let node = world.node(&format!("bench-{}", std::process::id()))?;
        let service = world.robot().port_service(agent, port);
        let sub = port_service::<Tick>(&node, &service)?
            .subscriber_builder()
            .buffer_size(agent_sdk::ports::SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| anyhow!("{e:?}"))?;
        let listener = port_event(&node, &service)?.listener_builder().create().map_err(|e| anyhow!("{e:?}"))?;
        Ok(Watch { _node: node, sub, listener })
    }

    fn drain(&self) {
        let _ = self.listener.try_wait(|_| {});
        while let Ok(Some(_)) = self.sub.receive() {}
    }

    /// Waits for a sample sent after `after_ns` that satisfies `pred`;
    /// returns the time it left the agent (its header stamp, taken by
    /// `Output::send` on the shared monotonic clock). Taking the stamp rather
    /// than the time this process received it keeps out of the figure how
    /// long the command that caused it took to exit and this process to look.
    fn wait_for(&self, after_ns: u64, timeout: Duration, pred: impl Fn(&Tick) -> bool) -> Result<u64> {
        let t0 = Instant::now();
        loop {
            while let Some(s) = self.sub.receive().map_err(|e| anyhow!("{e:?}"))? {
                let stamp = s.user_header().stamp_ns;
                if stamp >= after_ns && pred(s.payload()) {
                    return Ok(stamp);
                }
            }
            let left = timeout.checked_sub(t0.elapsed()).ok_or_else(|| anyhow!("no sample within {timeout:?}"))?;
            let _ = self.listener.timed_wait(|_| {}, left.min(Duration::from_millis(2)));
        }
    }
}

fn wait_gone(robot: &Robot, name: &str) -> Result<()> {
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(10) {
        let ps = robot.ps()?;
        if !ps.as_array().is_some_and(|a| a.iter().any(|x| x["name"] == name)) {
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    bail!("{name} did not leave")
}

/// `nerve start` → first sample downstream and `nerve start` → the command
/// returned, ns, of each round.
#[derive(Default)]
struct HotAdds {
    first_sample: Vec<u64>,
    command: Vec<u64>,
}

/// Hot-adds of `relay` and, in alternate rounds (each round in turn first),
/// of `opts.hot_add_beside`.
fn hot_add(opts: &ControlOpts) -> Result<(HotAdds, HotAdds)> {
    let robot = Robot::new(HOT_ADD_TAG, opts.verbose)?;
    let _router = robot.start_router()?;
    robot.run(&["start", "ticker", "--name", "t1", "--period", "1ms"])?;
    robot.run(&["start", "relay", "--name", "h"])?;
    robot.run(&["connect", "t1/tick", "h/in"])?;
    robot.run(&["stop", "h"])?;
    wait_gone(&robot, "h")?;
    let watch = Watch::new(&robot, "h", "out")?;
    let beside = opts.hot_add_beside.as_ref().map(|p| p.display().to_string());
    let (mut relay, mut other) = (HotAdds::default(), HotAdds::default());
    for i in 0..opts.rounds {
        eprintln!("control: hot-add {}/{}", i + 1, opts.rounds);
        let mut kinds = vec![("relay", &mut relay)];
        if let Some(b) = &beside {
            kinds.push((b.as_str(), &mut other));
            if i % 2 == 1 {
                kinds.reverse();
            }
        }
        for (kind, into) in kinds {
            watch.drain();
            let t0 = now_ns();
            robot.run(&["start", kind, "--name", "h"])?;
            into.command.push(now_ns() - t0);
            let t1 = watch.wait_for(t0, Duration::from_secs(5), |_| true)?;
            into.first_sample.push(t1 - t0);
            robot.run(&["stop", "h"])?;
            wait_gone(&robot, "h")?;
        }
    }
    Ok((relay, other))
}

/// Rewires: (`nerve connect` → first sample, request → first sample, request → the router's reply), ns.
fn rewire(opts: &ControlOpts) -> Result<(Vec<u64>, Vec<u64>, Vec<u64>)> {
    let robot = Robot::new(REWIRE_TAG, opts.verbose)?;
    let _router = robot.start_router()?;
    robot.run(&["start", "ticker", "--name", "t1", "--period", "1ms"])?;
    robot.run(&["start", "ticker", "--name", "t2", "--period", "1ms"])?;
    robot.run(&["param", "set", "t2", "step", "1000000"])?;
    robot.run(&["start", "relay", "--name", "r"])?;
    robot.run(&["connect", "t1/tick", "r/in"])?;
    let watch = Watch::new(&robot, "r", "out")?;
    let world = World::new(&robot.name)?;
    let node = world.node(&format!("bench-rq-{}", std::process::id()))?;
    let client = router_client::<RouterRequest, RouterReply>(&world, &node)?;
    let (from, to): (PortRef, PortRef) = ("t2/tick".parse()?, "r/in".parse()?);
    // t1 counts by 1 at 1 kHz: it reaches a million only after 17 minutes
    let from_t2 = |t: &Tick| t.seq >= 1_000_000;
    let (mut cli, mut req, mut reply) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..opts.rounds {
        eprintln!("control: rewire {}/{}", i + 1, opts.rounds);
        for via_cli in [true, false] {
            watch.drain();
            let t0 = now_ns();
            if via_cli {
                robot.run(&["connect", "t2/tick", "r/in"])?;
            } else {
                match client.call(
                    &RouterRequest::Cli(CliRequest::Connect { from: from.clone(), to: to.clone(), allow_cycle: false }),
                    Duration::from_secs(5),
                ) {
                    Ok(RouterReply::Ok) => reply.push(now_ns() - t0),
                    other => bail!("connect refused: {other:?}"),
                }
            }
            let t1 = watch.wait_for(t0, Duration::from_secs(5), from_t2)?;
            if via_cli {
                cli.push(t1 - t0)
            } else {
                req.push(t1 - t0)
            }
            // undone the same way: a `nerve` process that has just come and
            // gone leaves the router a departed client to clean up (about
            // 5 ms) on the next caller's time, which a program rewiring
            // through its own connection does not meet
            if via_cli {
                robot.run(&["disconnect", "t2/tick", "r/in"])?;
            } else {
                match client.call(
                    &RouterRequest::Cli(CliRequest::Disconnect { from: from.clone(), to: to.clone() }),
                    Duration::from_secs(5),
                ) {
                    Ok(RouterReply::Ok) => {}
                    other => bail!("disconnect refused: {other:?}"),
                }
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    Ok((cli, req, reply))
}

fn launch_file(robot: &str, agents: usize) -> String {
    let mut s = format!("robot = \"{robot}\"\n\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nperiod = \"100ms\"\n");
    for i in 1..agents {
        s += &format!("\n[[agent]]\nname = \"r{i}\"\nkind = \"relay\"\n");
    }
    for i in 1..agents {
        let from = if i == 1 { "t1/tick".to_string() } else { format!("r{}/out", i - 1) };
        s += &format!("\n[[connect]]\nfrom = \"{from}\"\nto = \"r{i}/in\"\n");
    }
    s
}

fn launch(opts: &ControlOpts, agents: usize) -> Result<Vec<u64>> {
    let mut v = Vec::new();
    for i in 0..opts.launch_rounds {
        eprintln!("control: launch of {agents} agents {}/{}", i + 1, opts.launch_rounds);
        let robot = Robot::new(&launch_tag(agents, i), opts.verbose)?;
        let file = robot.home.join("launch.toml");
        std::fs::write(&file, launch_file(&robot.name, agents)).context("cannot write the launch file")?;
        let t0 = now_ns();
        robot.run(&["launch", &file.display().to_string()])?;
        v.push(now_ns() - t0);
        let ps = robot.ps()?;
        let n = ps.as_array().map(|a| a.len()).unwrap_or(0);
        if n != agents {
            bail!("launch of {agents} agents left {n} running");
        }
        drop(robot); // nerve down
    }
    Ok(v)
}

/// Runs the scenario.
pub fn run(opts: &ControlOpts) -> Result<ControlReport> {
    let t0 = Instant::now();
    let machine = Machine::probe();
    // the robots this run makes (a check of what is left in /dev/shm
    // afterwards reads them from this line)
    let launches: Vec<String> = opts
        .launch_sizes
        .iter()
        .flat_map(|&n| (0..opts.launch_rounds).map(move |i| format!(", robot {}", Robot::name_of(&launch_tag(n, i)))))
        .collect();
    eprintln!(
        "control: robot {} (hot-add), robot {} (rewire){}",
        Robot::name_of(HOT_ADD_TAG),
        Robot::name_of(REWIRE_TAG),
        launches.concat()
    );
    let (hot, beside) = hot_add(opts)?;
    let (cli, req, reply) = rewire(opts)?;
    let mut rows = Vec::new();
    for &n in &opts.launch_sizes {
        rows.push(LaunchRow { agents: n, launch: Summary::of(&launch(opts, n)?) });
    }
    let hot_add = Summary::of(&hot.first_sample);
    let hot_add_beside = opts.hot_add_beside.as_ref().map(|p| {
        let first = Summary::of(&beside.first_sample);
        BesideRow {
            executable: p.display().to_string(),
            ratio_to_relay: first.p50_ns as f64 / hot_add.p50_ns.max(1) as f64,
            hot_add: first,
            hot_add_command: Summary::of(&beside.command),
        }
    });
    let rewire_request = Summary::of(&req);
    Ok(Report::unnamed(
        machine,
        ControlResults {
            hot_add_vs_target: hot_add.p50_ns as f64 / HOT_ADD_TARGET_NS,
            rewire_vs_target: rewire_request.p50_ns as f64 / 5e6,
            rewire_reply_vs_target: Summary::of(&reply).p50_ns as f64 / REWIRE_TARGET_NS,
            hot_add,
            hot_add_command: Summary::of(&hot.command),
            hot_add_beside,
            rewire_cli: Summary::of(&cli),
            rewire_request,
            rewire_reply: Summary::of(&reply),
            launch: rows,
            seconds: t0.elapsed().as_secs_f64(),
        },
    ))
}

fn ms(ns: u64) -> String {
    format!("{:.2}", ns as f64 / 1e6)
}

/// Prints the tables as markdown.
pub fn print_tables(r: &ControlReport) {
    println!("| measure | n | median ms | p99 ms | max ms | target | median / target |");
    println!("|---|---:|---:|---:|---:|---|---:|");
    let row = |name: &str, s: &Summary, target: &str, ratio: Option<f64>| {
        println!(
            "| {name} | {} | {} | {} | {} | {target} | {} |",
            s.n,
            ms(s.p50_ns),
            ms(s.p99_ns),
            ms(s.max_ns),
            ratio.map(|x| format!("{x:.2}")).unwrap_or_else(|| "-".into())
        )
    };
    row("hot-add (`nerve start` → first sample downstream)", &r.hot_add, "≤ 10 ms", Some(r.hot_add_vs_target));
    row("hot-add, `nerve start` → the command returns", &r.hot_add_command, "-", None);
    if let Some(b) = &r.hot_add_beside {
        let ratio = b.hot_add.p50_ns as f64 / HOT_ADD_TARGET_NS;
        row(
            &format!("hot-add of `{}`, alternately (→ first sample)", b.executable),
            &b.hot_add,
            "≤ 10 ms",
            Some(ratio),
        );
        row(&format!("hot-add of `{}`, the command returns", b.executable), &b.hot_add_command, "-", None);
    }
    row(
        "rewire, request to the router → first sample from the new source",
        &r.rewire_request,
        "≤ 5 ms",
        Some(r.rewire_vs_target),
    );
    row(
        "rewire, request to the router → its reply (the agent has subscribed)",
        &r.rewire_reply,
        "≤ 2 ms",
        Some(r.rewire_reply_vs_target),
    );
    row("rewire, `nerve connect` command → first sample", &r.rewire_cli, "-", None);
    for l in &r.launch {
        let (target, ratio) = if l.agents == 50 {
            ("≤ 500 ms", Some(l.launch.p50_ns as f64 / LAUNCH_50_TARGET_NS))
        } else {
            ("-", None)
        };
        row(&format!("`nerve launch` of {} agents → all registered and connected", l.agents), &l.launch, target, ratio);
    }
    if let Some(b) = &r.hot_add_beside {
        println!();
        println!("`{}` / `relay`, hot-add medians of the same rounds: {:.2}", b.executable, b.ratio_to_relay);
    }
}
