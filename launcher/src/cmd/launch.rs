//! `nerve launch FILE [NAME=VALUE ...]`: a robot from a launch file and its
//! arguments (docs/launch.md). Validates the whole file
//! first (nothing starts on any error), starts the router if none runs,
//! has the router supervise and start every agent as a daemon in parallel
//! (one request; a progress line per agent), waits until each has
//! registered, applies the connections, and returns — or, with
//! `--foreground`, streams every agent's log and stops everything on Ctrl-C.
//! The bring-up itself is [`crate::bring::up`].

use crate::agent_logs::{Tail, tails_from_now};
use crate::bring;
use crate::interrupt;
use crate::launch_file;
use agent_sdk::World;
use anyhow::Result;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// `nerve launch`
#[derive(Debug, clap::Args)]
pub struct LaunchArgs {
    /// The launch file (TOML).
    pub file: std::path::PathBuf,
    /// The file's arguments, `NAME=VALUE` (each one declared in its `[args]`).
    #[arg(value_name = "NAME=VALUE")]
    pub args: Vec<String>,
    /// Stay attached: stream the agents' logs, stop everything on Ctrl-C.
    #[arg(long)]
    pub foreground: bool,
    /// `--sim-time [--time-scale K]`: the robot on the simulator's clock (docs/time.md).
    #[command(flatten)]
    pub time: crate::sim_time::SimTimeArgs,
}

pub fn launch(cli_robot: &str, explicit: bool, a: LaunchArgs) -> Result<ExitCode> {
    let t0 = Instant::now();
    let cli_args = match launch_file::parse_cli_args(&a.args) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("error: {e}; nothing was started");
            return Ok(ExitCode::from(2));
        }
    };
    let (file, world) = match launch_file::load_with_args(&a.file, cli_robot, explicit, &cli_args) {
        Ok(x) => x,
        Err(e) => {
            eprintln!("{e}");
            return Ok(ExitCode::from(1));
        }
    };
    super::shm_space::ensure_shm_space("launch")?;
    world.ensure_state_dirs()?;
    crate::sim_time::for_launch(&world, &a.time, &file)?;
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
    let up = bring::up(&world, &file)?;
    let (failed, wiring_failed) = (up.failed, up.wiring_failed);
    let hint = if a.foreground { "" } else { " (`nerve ps`, `nerve graph`, `nerve logs NAME`, `nerve down`)" };
    let (links, secs) = (file.connections.len(), t0.elapsed().as_secs_f64());
    if failed > 0 || wiring_failed > 0 {
        // not "up": the launch exits 1, and says what is missing
        eprintln!(
            "robot {} is up in part: {} of {n} agent(s) running ({failed} failed to start, above), {} of {links} \
             connection(s), in {secs:.2} s{hint}",
            world.robot(),
            n - failed,
            links - wiring_failed,
        );
    } else {
        eprintln!("robot {} is up: {n} agent(s) running, {links} connection(s), in {secs:.2} s{hint}", world.robot());
    }
    if let Some(tails) = tails {
        follow(&world, tails)?;
        return Ok(ExitCode::SUCCESS);
    }
    Ok(if failed > 0 || wiring_failed > 0 { ExitCode::from(1) } else { ExitCode::SUCCESS })
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
    let (stopped, killed) = bring::down_and_clean(world);
    eprintln!("{}", bring::stopped_line(stopped, killed));
    Ok(())
}
