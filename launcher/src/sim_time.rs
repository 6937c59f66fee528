//! `--sim-time` and `--time-scale` of `nerve launch` and `nerve demo`: the
//! robot's clock becomes the simulator's (`docs/time.md`).
//!
//! Before anything of the robot starts, the launcher writes the clock's page
//! into the robot's state folder ([`agent_sdk::simclock::create`]) and names
//! it in its own environment ([`agent_sdk::simclock::SIM_CLOCK_ENV`]), which
//! every process it starts inherits: the router, every agent, and through
//! the router every agent it restarts. The simulator takes the clock over
//! when it starts.

use agent_sdk::World;
use agent_sdk::simclock::{self, PAGE_FILE, SIM_CLOCK_ENV};
use anyhow::{Context as _, Result, bail};
use std::path::PathBuf;

pub use agent_sdk::simclock::{SimTimeArgs, parse_scale};

/// The flags over a launch file's `sim_time` and `time_scale`: the file's
/// apply where the command line gives none.
pub fn with_file(args: &SimTimeArgs, file: &crate::launch_file::LaunchFile) -> SimTimeArgs {
    SimTimeArgs { sim_time: args.sim_time || file.sim_time, time_scale: args.time_scale.or(file.time_scale) }
}

/// Puts `world`'s robot on simulated time at `scale`: writes the clock's
/// page and names it for every process this command starts from now on.
/// Refuses when this process already runs on another clock (a `nerve` run
/// from a simulated robot's environment). Returns the page's path.
///
/// Call it before this process starts any thread: it sets an environment
/// variable.
pub fn start(world: &World, scale: f64) -> Result<PathBuf> {
    world.ensure_state_dirs()?;
    let page = world.state_dir().join(PAGE_FILE);
    if let Some(other) = std::env::var_os(SIM_CLOCK_ENV).filter(|p| !p.is_empty() && *p != page.as_os_str()) {
        bail!(
            "this shell already names a simulated clock ({SIM_CLOCK_ENV}={}); unset {SIM_CLOCK_ENV} to give robot {} \
             a clock of its own, or launch without --sim-time to join that clock",
            PathBuf::from(other).display(),
            world.robot()
        );
    }
    let running = crate::bring::running_agents(world);
    if !running.is_empty() {
        bail!(
            "robot {} already runs {} agent(s) ({}) on its own clock; bring it down first (`nerve --robot {} down`) \
             to run it on simulated time",
            world.robot(),
            running.len(),
            running.join(", "),
            world.robot()
        );
    }
    simclock::create(&page, scale).with_context(|| format!("robot {} cannot run on simulated time", world.robot()))?;
    let threads = std::fs::read_dir("/proc/self/task").map(Iterator::count).unwrap_or(0);
    if threads != 1 {
        bail!("internal: the simulated clock must be named before the command starts threads ({threads} run)");
    }
    // SAFETY: this process runs one thread (counted just above: the
    // interrupt handler, taps and launch lanes come later), so nothing
    // reads the environment while it changes; the children inherit it.
    unsafe { std::env::set_var(SIM_CLOCK_ENV, &page) };
    tracing::info!(scale, page = %page.display(), "robot {} on simulated time", world.robot());
    Ok(page)
}

/// The `time_scale` of the world the launch file's simulator (`kind =
/// "sim"`, `--world FILE`) runs, if it names one that can be read.
pub fn world_scale(file: &crate::launch_file::LaunchFile) -> Option<f64> {
    let sim = file.agents.iter().find(|a| a.kind == "sim")?;
    let i = sim.args.iter().position(|a| a == "--world")?;
    let path = std::path::Path::new(sim.args.get(i + 1)?);
    // the world file's top-level `time_scale` (the simulator checks the rest)
    let world: toml::Table = toml::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    let scale = world.get("time_scale")?;
    scale.as_float().or_else(|| scale.as_integer().and_then(|k| i32::try_from(k).ok()).map(f64::from))
}

/// `nerve launch --sim-time` (or a launch file's `sim_time = true`): the
/// robot on simulated time, unless this shell names a simulated clock
/// already (another robot's, served by the same simulator), which the launch
/// then joins. Returns the scale.
pub fn for_launch(world: &World, args: &SimTimeArgs, file: &crate::launch_file::LaunchFile) -> Result<Option<f64>> {
    let args = &with_file(args, file);
    let Some(scale) = args.scale(world_scale(file)) else { return Ok(None) };
    if let Some(joined) = std::env::var_os(SIM_CLOCK_ENV).filter(|p| !p.is_empty())
        && args.time_scale.is_none()
        && std::path::Path::new(&joined).exists()
    {
        eprintln!("robot {} joins the simulated clock {}", world.robot(), PathBuf::from(joined).display());
        return Ok(Some(scale));
    }
    let page = start(world, scale)?;
    eprintln!("robot {} runs on simulated time at {scale}x (clock {})", world.robot(), page.display());
    Ok(Some(scale))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flags_win_over_the_launch_files_keys() {
        let file = |sim_time, time_scale| crate::launch_file::LaunchFile {
            path: PathBuf::from("robot.toml"),
            agents: Vec::new(),
            connections: Vec::new(),
            allow_cycle: Vec::new(),
            sim_time,
            time_scale,
        };
        let none = SimTimeArgs::default();
        assert_eq!(
            with_file(&none, &file(false, Some(4.0))).scale(None),
            None,
            "time_scale alone keeps the wall clock"
        );
        assert_eq!(with_file(&none, &file(true, Some(4.0))).scale(Some(2.0)), Some(4.0), "the file's over the world's");
        assert_eq!(with_file(&none, &file(true, None)).scale(Some(2.0)), Some(2.0), "else the world's");
        let flag = SimTimeArgs { sim_time: true, time_scale: None };
        assert_eq!(
            with_file(&flag, &file(false, Some(3.0))).scale(None),
            Some(3.0),
            "--sim-time takes the file's scale"
        );
        let both = SimTimeArgs { sim_time: true, time_scale: Some(8.0) };
        assert_eq!(with_file(&both, &file(true, Some(3.0))).scale(None), Some(8.0), "--time-scale wins");
    }
}
