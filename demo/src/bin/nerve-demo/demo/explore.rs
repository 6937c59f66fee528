//! `nerve demo explore`: the exploration experiment of the thesis (section
//! 4.2) from one command.
//!
//! It builds nothing: it takes `launch/explore.toml`, writes a derived copy
//! into the output directory with the chosen world and seed (and every
//! relative path made absolute), launches the router, the simulator and
//! every agent from it as daemons, follows the run (a progress line every
//! few seconds: simulated time, true pose, the decision maker's mode, the
//! distance to the target), and ends when the robot has followed the target
//! (reached it, as defined in `docs/demo.md`, and stayed there for
//! `--hold` seconds), at `--time-limit` seconds of simulated time, or on
//! Ctrl-C. With `--sim-time --time-scale 4` the simulator owns the robot's
//! clock and runs four times as fast as real time (`docs/time.md`); the
//! figures stay in simulated seconds, `wall_time_s` says how long it took. Then it stops everything as `nerve down` does and writes into
//! `--out` (default `out/explore-<seed>/`):
//!
//! * `trajectory.png|svg`: the map with the robot's and the person's paths (Fig. 4-4);
//! * `motion.png|svg`: velocity, angular speed and heading against time (Fig. 4-6);
//! * `truth.csv`: the simulator's ground truth as written;
//! * `log.csv`: the ground truth with clearance, target position and
//!   distance, and the decision maker's mode per row;
//! * `summary.json`: the verdict ([`nerve_demo::Summary`]), the mode changes
//!   and the CPU used by each agent;
//! * `launch.toml`: the launch file that ran; `logs/`: every agent's log.
//!
//! Exit code 0 when the run completed (whatever the robot achieved: read
//! `summary.json`), 1 when it could not be run.

use super::{End, find_file, set_flag};
use crate::nerve::{self, SimClock, Tap, cli_node, copy_logs};
use agent_sdk::World;
use anyhow::{Context as _, Result, bail};
use nerve_demo::analysis::{DoorwayWatch, ModeChange, at_target};
use nerve_demo::cpu::CpuTable;
use nerve_demo::{Criteria, Scene, TruthRow, explore};
use shm_schemas::payloads::{GroundTruth, Mode};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// `nerve demo explore`
#[derive(Debug, clap::Args)]
pub struct ExploreArgs {
    /// World file [default: worlds/explore.toml of the nerve source tree].
    #[arg(long)]
    pub world: Option<PathBuf>,
    /// Seed of the simulator's noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output directory [default: out/explore-<seed>].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Stop after this many seconds of simulated time.
    #[arg(long, default_value_t = 140.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub time_limit: f64,
    /// Launch file to derive the run's from [default: launch/explore.toml].
    #[arg(long)]
    pub launch: Option<PathBuf>,
    /// Robot centre to target centre, m, that counts as reaching the target.
    #[arg(long, default_value_t = Criteria::default().target_reach_m)]
    pub reach: f64,
    /// Seconds the robot must stay at the target before the run ends.
    #[arg(long, default_value_t = 2.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub hold: f64,
    /// Seconds between progress lines.
    #[arg(long, default_value_t = 3.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub progress: f64,
    /// `--sim-time [--time-scale 4]`: the run on simulated time.
    #[command(flatten)]
    pub time: nerve::SimTimeArgs,
}

/// The run's launch file: the template with this robot, world and seed, and
/// relative paths that exist under the source tree made absolute (daemons
/// may run from any directory).
fn derive_launch(template: &Path, robot: &str, world: &Path, seed: u64) -> Result<String> {
    let text =
        std::fs::read_to_string(template).with_context(|| format!("cannot read launch file {}", template.display()))?;
    let mut doc: toml::Table =
        toml::from_str(&text).with_context(|| format!("launch file {} is not valid TOML", template.display()))?;
    let base = template.parent().and_then(Path::parent).map(Path::to_path_buf).unwrap_or_default();
    doc.insert("robot".into(), toml::Value::String(robot.to_owned()));
    let Some(toml::Value::Array(agents)) = doc.get_mut("agent") else {
        bail!("launch file {} has no [[agent]]", template.display());
    };
    let mut found_sim = false;
    for a in agents.iter_mut() {
        let Some(t) = a.as_table_mut() else { continue };
        let is_sim = t.get("kind").and_then(|k| k.as_str()) == Some("sim");
        let args = t.entry("args").or_insert_with(|| toml::Value::Array(vec![]));
        let Some(args) = args.as_array_mut() else { bail!("`args` of an agent must be a list of strings") };
        super::absolutize_args(args, &base);
        if is_sim {
            found_sim = true;
            set_flag(args, "--world", world.display().to_string());
            set_flag(args, "--seed", seed.to_string());
        }
    }
    if !found_sim {
        bail!("launch file {} has no agent of kind \"sim\"; the demo needs the simulator", template.display());
    }
    let body = toml::to_string(&doc).context("cannot write the derived launch file")?;
    Ok(format!(
        "# Derived by `nerve demo explore` from {} (robot {robot}, world {}, seed {seed}).\n{body}",
        template.display(),
        world.display()
    ))
}

/// The value after `--truth` of the simulator, expanded.
fn truth_path(launch_text: &str, world: &World) -> Option<PathBuf> {
    let doc: toml::Table = toml::from_str(launch_text).ok()?;
    let agents = doc.get("agent")?.as_array()?;
    let sim = agents.iter().find(|a| a.get("kind").and_then(|k| k.as_str()) == Some("sim"))?;
    let args = sim.get("args")?.as_array()?;
    let i = args.iter().position(|a| a.as_str() == Some("--truth"))?;
    Some(PathBuf::from(nerve::expand(args.get(i + 1)?.as_str()?, world)))
}

/// Agents running on `world`: (name, kind, pid, cpu percent, restarts).
fn sample_agents(world: &World) -> Vec<(String, String, u32, Option<f64>, u32)> {
    nerve::agents(world)
        .unwrap_or_default()
        .into_iter()
        .map(|a| (a.name, a.kind, a.pid, a.stats.map(|s| s.cpu_percent), a.restarts))
        .collect()
}

pub(super) fn explore(robot: &str, a: ExploreArgs) -> Result<ExitCode> {
    let t_wall = Instant::now();
    if !(a.time_limit > 0.0 && a.time_limit.is_finite()) {
        bail!("--time-limit must be a positive number of seconds");
    }
    let world_file = find_file(a.world.as_deref().unwrap_or(Path::new("worlds/explore.toml")), "world file")?;
    let template = find_file(a.launch.as_deref().unwrap_or(Path::new("launch/explore.toml")), "launch file")?;
    let scene = Scene::load(&world_file).with_context(|| format!("cannot use world {}", world_file.display()))?;
    let out = a.out.clone().unwrap_or_else(|| PathBuf::from(format!("out/explore-{}", a.seed)));
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create output directory {}", out.display()))?;
    let out = std::fs::canonicalize(&out).with_context(|| format!("cannot use output directory {}", out.display()))?;

    let nworld = World::new(robot)?;
    nerve::refuse_busy(&nworld, "", " or pick another --robot")?;
    // the clock's page, named to everything `nerve launch` starts for the run
    let scale = a.time.scale(scene.world.time_scale);
    let clock = scale.map(|k| SimClock::start(&nworld, k)).transpose()?;
    let derived = derive_launch(&template, robot, &world_file, a.seed)?;
    let launch_path = out.join("launch.toml");
    std::fs::write(&launch_path, &derived).with_context(|| format!("cannot write {}", launch_path.display()))?;
    let truth = truth_path(&derived, &nworld).unwrap_or_else(|| nworld.state_dir().join("truth.csv"));
    let _ = std::fs::remove_file(&truth);

    println!(
        "nerve demo explore: world {} ({}), seed {}, robot {robot}, time limit {} s{}; output {}",
        scene.world.name,
        world_file.display(),
        a.seed,
        a.time_limit,
        scale.map(|k| format!(" of simulated time at {k}x")).unwrap_or_default(),
        out.display()
    );
    nerve::catch_interrupts();
    if let Err(e) = nerve::launch(robot, &launch_path, clock.as_ref().map(SimClock::page)) {
        eprintln!("error: the robot did not come up: {e:#}");
        println!("{}", nerve::down(robot));
        return Ok(ExitCode::from(1));
    }
    let world = nworld;
    println!("robot up in {:.1} s; following the run (Ctrl-C ends it early)", t_wall.elapsed().as_secs_f64());

    let outcome = follow(&world, &scene, &a, scale.unwrap_or(1.0));
    // whatever happened, stop everything and leave nothing behind
    println!("{}", nerve::down(robot));
    drop(clock);
    let Followed { end, rec } = outcome?;

    // the records: what the demo received on `sim/truth` and `decision/mode`
    // (the simulator's own truth.csv is kept beside them)
    if rec.rows.is_empty() {
        bail!("no ground truth came on sim/truth: the simulator never ran (see {}/logs/sim.log)", out.display());
    }
    if let Err(e) = std::fs::copy(&truth, out.join("truth.csv")) {
        eprintln!("warning: cannot copy the simulator's {}: {e}", truth.display());
    }
    copy_logs(&world, &out.join("logs"));
    let run = explore::Run {
        seed: a.seed,
        robot,
        end_reason: end.reason(),
        criteria: Criteria { target_reach_m: a.reach },
        started: t_wall,
        time_scale: scale,
    };
    let report = explore::report(&out, &scene, &rec, &run)?;
    println!("{}", report.headline());
    println!("wrote {}/summary.json, log.csv, truth.csv, launch.toml, logs/ and", out.display());
    Ok(end.finish(&report.figures.files))
}

/// What `follow` hands back.
struct Followed {
    end: End,
    /// The ground truth, the mode changes and the CPU use, for the report.
    rec: explore::Recorded,
}

fn truth_row(t: &GroundTruth) -> TruthRow {
    TruthRow {
        t: t.sim_time,
        x: t.x,
        y: t.y,
        theta: t.theta,
        v: t.v,
        omega: t.omega,
        collisions: t.collisions,
        in_contact: t.in_contact != 0,
    }
}

/// `HH:MM:SS.mmm` (UTC) of the wall clock now.
fn clock_now() -> String {
    let d = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    let s = d.as_secs() % 86_400;
    format!("{:02}:{:02}:{:02}.{:03}", s / 3600, s / 60 % 60, s % 60, d.subsec_millis())
}

/// Follows the run until it ends, observing the robot through nerve: the
/// simulator's `sim/truth` and the decision maker's `decision/mode`, each
/// through a tap (the demo's own subscription); prints progress.
fn follow(world: &World, scene: &Scene, a: &ExploreArgs, scale: f64) -> Result<Followed> {
    let criteria = Criteria { target_reach_m: a.reach };
    let node = cli_node(world)?;
    let mut truth_tap: Option<Tap<GroundTruth>> = None;
    let mut mode_tap: Option<Tap<Mode>> = None;
    let mut rows: Vec<TruthRow> = Vec::new();
    // (stamp_ns, sim time) of the newest truth sample: a mode's instant in simulated time
    let mut clock: Option<(u64, f64)> = None;
    let mut modes: Vec<ModeChange> = Vec::new();
    let mut watch = DoorwayWatch::default();
    let mut cpu = CpuTable::default();
    let mut mode = String::from("-");
    let mut at_since: Option<f64> = None;
    let mut missed = 0u64;
    let mut last_seq: Option<u64> = None;
    let t0 = Instant::now();
    let mut last_rows = Instant::now();
    let mut next_progress = Instant::now();
    let mut next_sample = Instant::now();
    let wall_limit = Duration::from_secs_f64(a.time_limit * 1.5 + 30.0);
    let end = loop {
        if nerve::interrupted() {
            break End::Interrupted;
        }
        if truth_tap.is_none() {
            truth_tap = Tap::try_open(world, &node, "sim", "truth")?;
        }
        if mode_tap.is_none() {
            mode_tap = Tap::try_open(world, &node, "decision", "mode")?;
        }
        let before = rows.len();
        if let Some(t) = &truth_tap {
            t.drain(|h, g| {
                if let Some(l) = last_seq {
                    missed += h.seq.saturating_sub(l.saturating_add(1));
                }
                last_seq = Some(h.seq);
                clock = Some((g.stamp_ns, g.sim_time));
                rows.push(truth_row(g));
            })?;
        }
        if rows.len() > before {
            last_rows = Instant::now();
        }
        let mut followed = false;
        for r in &rows[before..] {
            watch.push(scene, r);
            if at_target(scene, &criteria, watch.crossed.map(|c| c.0), r) {
                let since = *at_since.get_or_insert(r.t);
                followed |= r.t - since >= a.hold;
            } else {
                at_since = None;
            }
        }
        if let Some(t) = &mode_tap {
            t.drain(|_, m| {
                let name = m.name.as_str().to_owned();
                if name != mode {
                    let from = (mode != "-").then(|| mode.clone());
                    // the change's instant, in simulated time through the newest truth sample
                    let t_s = clock.map(|(stamp, sim)| {
                        sim - (stamp.saturating_sub(m.since_ns) as f64 - m.since_ns.saturating_sub(stamp) as f64) / 1e9
                    });
                    modes.push(ModeChange {
                        t_s,
                        clock: clock_now(),
                        line: format!(
                            "decision/mode: {} -> {name} (change {})",
                            from.as_deref().unwrap_or("-"),
                            m.changes
                        ),
                        mode: name.clone(),
                        from,
                    });
                    mode = name;
                }
            })?;
        }
        if Instant::now() >= next_sample {
            next_sample = Instant::now() + Duration::from_secs(2);
            for (name, kind, pid, pct, restarts) in sample_agents(world) {
                cpu.record(&name, &kind, pct, restarts, pid);
            }
        }
        if Instant::now() >= next_progress {
            next_progress = Instant::now() + Duration::from_secs_f64(a.progress.max(0.5));
            progress(scene, rows.last(), &mode, watch.crossed.is_some());
        }
        if followed {
            break End::Goal("target followed");
        }
        if rows.last().is_some_and(|r| r.t >= a.time_limit) {
            break End::TimeLimit;
        }
        if last_rows.elapsed() > Duration::from_secs(20) {
            break End::Stalled(format!(
                "no ground truth on sim/truth for 20 s (see `nerve --robot {} logs sim`)",
                world.robot()
            ));
        }
        if t0.elapsed() > wall_limit {
            break End::Stalled(format!(
                "the simulation ran slower than real time; {wall_limit:?} of wall time passed"
            ));
        }
        // a look every 50 ms of simulated time: the tap keeps 16 samples of the 100 Hz truth
        std::thread::sleep(Duration::from_secs_f64(0.05 / scale));
    };
    progress(scene, rows.last(), &mode, watch.crossed.is_some());
    if missed > 0 {
        tracing::warn!(missed, received = rows.len(), "ground-truth samples overwritten before the demo read them");
    }
    for (name, kind, pid, pct, restarts) in sample_agents(world) {
        cpu.record(&name, &kind, pct, restarts, pid);
    }
    Ok(Followed { end, rec: explore::Recorded { rows, modes, cpu: cpu.finish() } })
}

/// One progress line: simulated time, true pose, the mode, the target's distance.
fn progress(scene: &Scene, r: Option<&TruthRow>, mode: &str, doorway: bool) {
    let Some(r) = r else {
        println!("  waiting for the simulator's first step...");
        return;
    };
    let target = scene
        .target_at(r.t)
        .map(|p| format!("{:5.2} m", p.dist(nerve_sim_vec(r.x, r.y))))
        .unwrap_or_else(|| "-".into());
    println!(
        "  t {:6.1} s  pose ({:6.2}, {:6.2}, {:5.0}°)  v {:5.2} m/s  mode {:<10} target {}  doorway {}  collisions {}",
        r.t,
        r.x,
        r.y,
        r.theta.to_degrees(),
        r.v,
        mode,
        target,
        if doorway { "passed" } else { "not yet" },
        r.collisions
    );
    let _ = std::io::stdout().flush();
}

fn nerve_sim_vec(x: f64, y: f64) -> nerve_demo::nerve_sim::Vec2 {
    nerve_demo::nerve_sim::Vec2::new(x, y)
}
