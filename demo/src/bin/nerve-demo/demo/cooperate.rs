//! `nerve demo cooperate`: the cooperation experiment of the thesis (section
//! 4.3) from one command.
//!
//! It derives the run's two launch files from `launch/cooperate-r1.toml` and
//! `launch/cooperate-r2.toml` (and their bridge configurations) into the
//! output directory — with the seed, the world, the ground-truth files, the
//! bridge port and, with `--no-checkpoints`, the checkpoint sensors' `correct
//! = false` and robot 2's target achiever's `target_shift_m = 0` — launches robot 1 (the simulator, which owns the world and
//! serves robot 2's boards too) and then robot 2, and follows the run with a
//! progress line, recording from the robots' ports (taps: the simulator's
//! ground truth of both robots, both odometry poses, robot 2's motor
//! odometry, the path, the reports). It ends when robot 2 has reported its
//! arrival and robot 1 was told to resume (plus `--linger` seconds), at
//! `--time-limit` seconds of simulated time, or on Ctrl-C; then it stops both
//! robots as `nerve down` does and writes into `--out` (default
//! `out/cooperate-<seed>/`, `out/cooperate-<seed>-no-checkpoints/` without
//! corrections):
//!
//! * `trajectories.png|svg`: both robots' true and recorded paths, robot 2's
//!   raw dead reckoning, the checkpoints, the via points, the target and the
//!   correction jumps (Fig. 4-10);
//! * `summary.json`: the verdict ([`nerve_demo::cooperate::CoopSummary`]);
//! * `estimates.csv`: the recorded poses; `truth-r1.csv`, `truth-r2.csv`:
//!   the simulator's ground truth; `launch-r1.toml`, `launch-r2.toml` and the
//!   bridge configurations that ran; `logs/r1`, `logs/r2`: every agent's log.
//!
//! With `--sim-time --time-scale 4` both robots run on the simulator's
//! clock, four times as fast as real time (`docs/time.md`); the figures stay
//! in simulated seconds, `wall_time_s` says how long it took.
//!
//! Exit code 0 when the run completed (whatever the robots achieved: read
//! `summary.json`), 1 when it could not be run.

use super::{End, absolutize_args, find_file, set_flag};
use crate::nerve::{self, SimClock, Tap, cli_node, copy_logs};
use agent_sdk::World;
use agent_sdk::port::RawPort;
use agent_sdk::world::Ipc;
use anyhow::{Context as _, Result, bail};
use iceoryx2::prelude::Node;
use nerve_demo::Scene;
use nerve_demo::cooperate::{self, EstPose, PlannedPoint, Reached, Records, TruePose};
use shm_schemas::payloads::{
    CheckpointSighting, GroundTruth, MissionCode, MissionCommand, Odometry, PoseEstimate, ViaKind, ViaPathBuf,
};
use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// `nerve demo cooperate`
#[derive(Debug, clap::Args)]
pub struct CooperateArgs {
    /// Seed of the simulator's noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output directory [default: out/cooperate-<seed>, out/cooperate-<seed>-no-checkpoints].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The same run without pose corrections at the checkpoints (dead reckoning alone).
    #[arg(long)]
    pub no_checkpoints: bool,
    /// World file [default: worlds/cooperate.toml of the nerve source tree].
    #[arg(long)]
    pub world: Option<PathBuf>,
    /// Stop after this many seconds of simulated time.
    #[arg(long, default_value_t = 300.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub time_limit: f64,
    /// Seconds (simulated) to follow the run after robot 1 was told to resume.
    #[arg(long, default_value_t = 3.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub linger: f64,
    /// Robot 2's centre to the target's centre, m, that counts as reaching it.
    #[arg(long, default_value_t = 0.5)]
    pub reach: f64,
    /// The two robots' names [default: those of the launch files, coop-r1,coop-r2].
    #[arg(long, value_delimiter = ',', value_name = "ROBOT1,ROBOT2")]
    pub robots: Option<Vec<String>>,
    /// TCP port of robot 1's bridge on 127.0.0.1.
    #[arg(long, default_value_t = 7451)]
    pub port: u16,
    /// Seconds between progress lines.
    #[arg(long, default_value_t = 3.0, value_parser = agent_sdk::clock::parse_seconds)]
    pub progress: f64,
    /// `--sim-time [--time-scale 4]`: the run on simulated time (both robots on the simulator's clock).
    #[command(flatten)]
    pub time: nerve::SimTimeArgs,
}

/// The launch files and bridge configurations the run derives from.
const TEMPLATES: [&str; 2] = ["launch/cooperate-r1.toml", "launch/cooperate-r2.toml"];
/// The port the shipped bridge configurations use.
const SHIPPED_PORT: &str = "7451";

/// What a derived launch file needs to know.
struct Derive<'a> {
    world: &'a Path,
    seed: u64,
    out: &'a Path,
    /// The templates' robot names and the run's.
    template_names: &'a [String; 2],
    names: &'a [String; 2],
    no_checkpoints: bool,
}

/// The robot a launch file names.
fn robot_of(doc: &toml::Table, path: &Path) -> Result<String> {
    doc.get("robot")
        .and_then(|r| r.as_str())
        .map(str::to_owned)
        .with_context(|| format!("launch file {} names no `robot`; the demo needs both robots named", path.display()))
}

/// `text` with the templates' robot names replaced by the run's.
fn rename(text: &str, from: &[String; 2], to: &[String; 2]) -> String {
    // through placeholders, so that swapped names do not clash
    let mut t = text.to_owned();
    for (i, f) in from.iter().enumerate() {
        t = t.replace(f.as_str(), &format!("\u{1}{i}\u{1}"));
    }
    for (i, n) in to.iter().enumerate() {
        t = t.replace(&format!("\u{1}{i}\u{1}"), n);
    }
    t
}

/// The run's copy of a launch file.
fn derive(template: &Path, d: &Derive<'_>) -> Result<String> {
    let text =
        std::fs::read_to_string(template).with_context(|| format!("cannot read launch file {}", template.display()))?;
    let text = rename(&text, d.template_names, d.names);
    let mut doc: toml::Table =
        toml::from_str(&text).with_context(|| format!("launch file {} is not valid TOML", template.display()))?;
    let base = template.parent().and_then(Path::parent).map(Path::to_path_buf).unwrap_or_default();
    let Some(toml::Value::Array(agents)) = doc.get_mut("agent") else {
        bail!("launch file {} has no [[agent]]", template.display());
    };
    for a in agents.iter_mut() {
        let Some(t) = a.as_table_mut() else { continue };
        let kind = t.get("kind").and_then(|k| k.as_str()).unwrap_or_default().to_owned();
        // without checkpoints: the sensors correct no pose, and robot 2 does
        // not steer to the target its camera sees (dead reckoning alone)
        let off = match kind.as_str() {
            "checkpoint" => Some(("correct", toml::Value::Boolean(false))),
            "target" => Some(("target_shift_m", toml::Value::Float(0.0))),
            _ => None,
        };
        if let (true, Some((key, value))) = (d.no_checkpoints, off) {
            let params = t.entry("params").or_insert_with(|| toml::Value::Table(toml::Table::new()));
            if let Some(p) = params.as_table_mut() {
                p.insert(key.into(), value);
            }
        }
        let args = t.entry("args").or_insert_with(|| toml::Value::Array(vec![]));
        let Some(args) = args.as_array_mut() else { bail!("`args` of an agent must be a list of strings") };
        absolutize_args(args, &base);
        if kind == "sim" {
            set_flag(args, "--world", d.world.display().to_string());
            set_flag(args, "--seed", d.seed.to_string());
            set_flag(args, "--truth", d.out.join("truth-r1.csv").display().to_string());
            let extra = format!("{}:h2::{}", d.names[1], d.out.join("truth-r2.csv").display());
            set_flag(args, "--extra-robot", extra);
        }
    }
    let body = toml::to_string(&doc).context("cannot write the derived launch file")?;
    Ok(format!(
        "# Derived by `nerve demo cooperate` from {} (world {}, seed {}{}).\n{body}",
        template.display(),
        d.world.display(),
        d.seed,
        if d.no_checkpoints { ", no checkpoint corrections" } else { "" }
    ))
}

/// Runs the experiment.
pub fn cooperate(a: CooperateArgs) -> Result<ExitCode> {
    let t_wall = Instant::now();
    if !(a.time_limit > 0.0 && a.time_limit.is_finite()) {
        bail!("--time-limit must be a positive number of seconds");
    }
    if !(a.reach > 0.0 && a.reach.is_finite()) {
        bail!("--reach must be a positive number of metres");
    }
    let world_file = find_file(a.world.as_deref().unwrap_or(Path::new("worlds/cooperate.toml")), "world file")?;
    let scene = Scene::load(&world_file).with_context(|| format!("cannot use world {}", world_file.display()))?;
    let templates =
        [find_file(Path::new(TEMPLATES[0]), "launch file")?, find_file(Path::new(TEMPLATES[1]), "launch file")?];
    let docs: Vec<toml::Table> = templates
        .iter()
        .map(|t| {
            let text = std::fs::read_to_string(t).with_context(|| format!("cannot read {}", t.display()))?;
            toml::from_str(&text).with_context(|| format!("launch file {} is not valid TOML", t.display()))
        })
        .collect::<Result<_>>()?;
    let template_names = [robot_of(&docs[0], &templates[0])?, robot_of(&docs[1], &templates[1])?];
    let names: [String; 2] = match &a.robots {
        Some(v) => match v.as_slice() {
            [r1, r2] if r1 != r2 => [r1.clone(), r2.clone()],
            _ => bail!("--robots takes two different names, ROBOT1,ROBOT2"),
        },
        None => template_names.clone(),
    };
    let default_out = if a.no_checkpoints {
        format!("out/cooperate-{}-no-checkpoints", a.seed)
    } else {
        format!("out/cooperate-{}", a.seed)
    };
    let out = a.out.clone().unwrap_or_else(|| PathBuf::from(default_out));
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create output directory {}", out.display()))?;
    let out = std::fs::canonicalize(&out).with_context(|| format!("cannot use output directory {}", out.display()))?;
    let worlds = [World::new(&names[0])?, World::new(&names[1])?];
    for w in &worlds {
        nerve::refuse_busy(w, "", "")?;
    }
    // one clock for both robots (one simulator serves both), in robot 1's folder
    let scale = a.time.scale(scene.world.time_scale);
    let clock = scale.map(|k| SimClock::start(&worlds[0], k)).transpose()?;
    // the run's launch files and bridge configurations, side by side in `out`
    let d = Derive {
        world: &world_file,
        seed: a.seed,
        out: &out,
        template_names: &template_names,
        names: &names,
        no_checkpoints: a.no_checkpoints,
    };
    // the bridges talk mutual TLS: the run's fleet keys, made once in `out/keys`
    let keys = out.join("keys");
    nerve::ensure_bridge_keys(&keys, &[names[0].as_str(), names[1].as_str()])
        .with_context(|| format!("cannot make the bridges' keys in {}", keys.display()))?;
    let mut launch_paths = Vec::new();
    for (i, t) in templates.iter().enumerate() {
        let name = format!("launch-r{}.toml", i + 1);
        let text = derive(t, &d)?;
        std::fs::write(out.join(&name), text).with_context(|| format!("cannot write {name}"))?;
        launch_paths.push(out.join(name));
        let zenoh = format!("cooperate-r{}.zenoh.toml", i + 1);
        let src = t.with_file_name(&zenoh);
        let text = std::fs::read_to_string(&src).with_context(|| format!("cannot read {}", src.display()))?;
        let text = rename(&text, &template_names, &names).replace(SHIPPED_PORT, &a.port.to_string());
        let text = text.replace("\n[tls]\n", &format!("\n[tls]\nkeys = {:?}\n", keys.display().to_string()));
        std::fs::write(out.join(&zenoh), text).with_context(|| format!("cannot write {zenoh}"))?;
    }
    for f in ["truth-r1.csv", "truth-r2.csv"] {
        let _ = std::fs::remove_file(out.join(f));
    }
    println!(
        "nerve demo cooperate: world {} ({}), seed {}, robots {} and {}, checkpoint corrections {}, time limit {} s{}; output {}",
        scene.world.name,
        world_file.display(),
        a.seed,
        names[0],
        names[1],
        if a.no_checkpoints { "OFF" } else { "on" },
        a.time_limit,
        scale.map(|k| format!(" of simulated time at {k}x")).unwrap_or_default(),
        out.display()
    );
    nerve::catch_interrupts();
    // robot 2 first: robot 1's simulator serves its boards
    let bring_all_down = || names.iter().rev().map(|n| nerve::down(n)).collect::<Vec<_>>();
    for (i, p) in launch_paths.iter().enumerate() {
        if let Err(e) = nerve::launch(&names[i], p, clock.as_ref().map(SimClock::page)) {
            eprintln!("error: robot {} did not come up: {e:#}", names[i]);
            for line in bring_all_down() {
                println!("{line}");
            }
            return Ok(ExitCode::from(1));
        }
    }
    println!("both robots up in {:.1} s; following the run (Ctrl-C ends it early)", t_wall.elapsed().as_secs_f64());

    let followed = follow(&worlds, &names, &a, scale.unwrap_or(1.0));
    let bridge_figures: BTreeMap<String, BTreeMap<String, String>> = worlds
        .iter()
        .zip(&names)
        .map(|(w, n)| (n.clone(), nerve::all_figures(w).remove("bridge").unwrap_or_default()))
        .collect();
    let grasp = nerve::all_figures(&worlds[1]).get("mission").and_then(|m| m.get("grasp").cloned());
    for line in bring_all_down() {
        println!("{line}");
    }
    drop(clock);
    let (end, mut rec) = followed?;
    rec.bridge = bridge_figures;
    rec.grasp = grasp;
    for (i, w) in worlds.iter().enumerate() {
        copy_logs(w, &out.join("logs").join(format!("r{}", i + 1)));
    }
    if rec.r1_truth.is_empty() {
        bail!("the simulator published no ground truth: the world never ran (see {}/logs/r1/sim.log)", out.display());
    }
    let run = cooperate::Run {
        seed: a.seed,
        world: world_file.display().to_string(),
        checkpoints: !a.no_checkpoints,
        end_reason: end.reason(),
        reach_m: a.reach,
        robots: [&names[0], &names[1]],
        started: t_wall,
        time_scale: scale,
    };
    let report = cooperate::report(&out, &scene, &rec, &run)?;
    println!("{}", report.headline());
    println!(
        "wrote {}/summary.json, estimates.csv, truth-r1.csv, truth-r2.csv, launch files, logs/ and",
        out.display()
    );
    Ok(end.finish(&report.figures.files))
}

/// The run's taps, opened as their ports appear.
#[derive(Default)]
struct Taps {
    r1_truth: Option<Tap<GroundTruth>>,
    r2_truth: Option<Tap<GroundTruth>>,
    r1_pose: Option<Tap<PoseEstimate>>,
    r2_pose: Option<Tap<PoseEstimate>>,
    r2_odom: Option<Tap<Odometry>>,
    r1_path: Option<RawPort>,
    r1_sighting: Option<Tap<CheckpointSighting>>,
    r1_mission: Option<Tap<MissionCommand>>,
    r2_path: Option<RawPort>,
    r2_report: Option<Tap<MissionCommand>>,
}

/// Opens `slot` if its port exists now.
fn open<T: shm_schemas::Payload>(slot: &mut Option<Tap<T>>, world: &World, node: &Node<Ipc>, agent: &str, port: &str) {
    if slot.is_none() {
        match Tap::try_open(world, node, agent, port) {
            Ok(t) => *slot = t,
            Err(e) => tracing::debug!("{e:#}"),
        }
    }
}

/// Opens `slot`, a port of a sequence type (read by its bytes), if it exists now.
fn open_seq(slot: &mut Option<RawPort>, world: &World, node: &Node<Ipc>, agent: &str, port: &str) {
    if slot.is_none() {
        match RawPort::open(node, &world.robot().port_service(agent, port)) {
            Ok(t) => *slot = Some(t),
            Err(e) => tracing::debug!("{agent}/{port} not open yet: {e}"),
        }
    }
}

/// Hands every path waiting on `slot` (a `nerve::ViaPath` port) to `f`.
fn drain_paths(slot: &Option<RawPort>, mut f: impl FnMut(&shm_schemas::SampleHeader, &ViaPathBuf)) {
    let Some(port) = slot else { return };
    let read = port.receive(|h, bytes| {
        match ViaPathBuf::from_bytes(bytes) {
            Some(p) => f(h, &p),
            None => tracing::debug!(len = bytes.len(), "a sample that is not a whole path"),
        }
        true
    });
    if let Err(e) = read {
        tracing::debug!("{e}");
    }
}

fn drain<T: shm_schemas::Payload>(slot: &Option<Tap<T>>, f: impl FnMut(&shm_schemas::SampleHeader, &T)) {
    if let Some(t) = slot
        && let Err(e) = t.drain(f)
    {
        tracing::debug!("{e:#}");
    }
}

fn true_pose(t: &GroundTruth) -> TruePose {
    TruePose { stamp_ns: t.stamp_ns, t: t.sim_time, x: t.x, y: t.y, theta: t.theta, collisions: t.collisions }
}

fn est_pose(p: &PoseEstimate) -> EstPose {
    EstPose { stamp_ns: p.stamp_ns, x: p.x, y: p.y, theta: p.theta, corrections: p.corrections }
}

fn planned(p: &ViaPathBuf) -> Vec<PlannedPoint> {
    p.entries()
        .map(|(at, k, id)| PlannedPoint {
            at,
            kind: ViaKind::from_code(k).map_or("?", |k| k.name()).to_owned(),
            checkpoint: id,
        })
        .collect()
}

/// Follows the run until it ends, recording; prints progress.
fn follow(worlds: &[World; 2], names: &[String; 2], a: &CooperateArgs, scale: f64) -> Result<(End, Records)> {
    let nodes = [cli_node(&worlds[0])?, cli_node(&worlds[1])?];
    let mut taps = Taps::default();
    let mut rec = Records::default();
    // robot 2's raw dead reckoning starts where the world puts it
    let mut r2_start: Option<(f64, f64, f64)> = None;
    let t0 = Instant::now();
    let mut last_truth = Instant::now();
    let mut next_progress = Instant::now() + Duration::from_secs(1);
    let mut next_figures = Instant::now();
    let mut phases = (String::from("-"), String::from("-"));
    let mut done_at: Option<Instant> = None;
    let wall_limit = Duration::from_secs_f64(a.time_limit * 1.5 + 60.0);
    let truth2_port = format!("truth-{}", names[1]);
    let end = loop {
        if nerve::interrupted() {
            break End::Interrupted;
        }
        let (w1, w2, n1, n2) = (&worlds[0], &worlds[1], &nodes[0], &nodes[1]);
        open(&mut taps.r1_truth, w1, n1, "sim", "truth");
        open(&mut taps.r2_truth, w1, n1, "sim", &truth2_port);
        open(&mut taps.r1_pose, w1, n1, "odometry", "pose");
        open_seq(&mut taps.r1_path, w1, n1, "map-builder", "path");
        open(&mut taps.r1_sighting, w1, n1, "checkpoint", "sighting");
        open(&mut taps.r1_mission, w1, n1, "map-builder", "mission");
        open(&mut taps.r2_pose, w2, n2, "odometry", "pose");
        open(&mut taps.r2_odom, w2, n2, "motor", "odom");
        open_seq(&mut taps.r2_path, w2, n2, "mission", "path");
        open(&mut taps.r2_report, w2, n2, "mission", "report");
        let before = rec.r1_truth.len();
        drain(&taps.r1_truth, |_, t| rec.r1_truth.push(true_pose(t)));
        drain(&taps.r2_truth, |_, t| rec.r2_truth.push(true_pose(t)));
        if rec.r1_truth.len() > before {
            last_truth = Instant::now();
        }
        if r2_start.is_none() {
            r2_start = rec.r2_truth.first().map(|t| (t.x, t.y, t.theta));
        }
        drain(&taps.r1_pose, |_, p| rec.r1_est.push(est_pose(p)));
        drain(&taps.r2_pose, |_, p| rec.r2_est.push(est_pose(p)));
        if let Some((sx, sy, st)) = r2_start {
            drain(&taps.r2_odom, |_, o| {
                let (c, s) = (st.cos(), st.sin());
                rec.r2_raw.push(EstPose {
                    stamp_ns: o.stamp_ns,
                    x: sx + c * o.x - s * o.y,
                    y: sy + s * o.x + c * o.y,
                    theta: st + o.theta,
                    corrections: 0,
                });
            });
        }
        drain_paths(&taps.r1_path, |h, _| {
            rec.path_sent_ns.get_or_insert(h.stamp_ns);
        });
        drain(&taps.r1_sighting, |h, s| {
            if s.is_target == 1 {
                rec.target_seen_ns.get_or_insert(h.stamp_ns);
            }
        });
        drain(&taps.r1_mission, |h, m| {
            if m.code() == Some(MissionCode::Resume) {
                rec.resumed_ns.get_or_insert(h.stamp_ns);
            }
        });
        drain_paths(&taps.r2_path, |_, p| rec.path = planned(p));
        drain(&taps.r2_report, |h, m| {
            let arrived = m.code() == Some(MissionCode::Arrived);
            if arrived || m.code() == Some(MissionCode::ViaReached) {
                rec.reached.push(Reached { stamp_ns: h.stamp_ns, index: m.index, x: m.x, y: m.y, arrived });
            }
        });
        if Instant::now() >= next_figures {
            next_figures = Instant::now() + Duration::from_secs(2);
            let phase = |w: &World| {
                nerve::all_figures(w).get("mission").and_then(|m| m.get("phase").cloned()).unwrap_or_else(|| "-".into())
            };
            phases = (phase(w1), phase(w2));
        }
        if Instant::now() >= next_progress {
            next_progress = Instant::now() + Duration::from_secs_f64(a.progress.max(0.5));
            progress(&rec, &phases);
        }
        let arrived = rec.reached.iter().any(|r| r.arrived);
        if arrived && (rec.resumed_ns.is_some() || phases.1 == "done") && done_at.is_none() {
            done_at = Some(Instant::now());
        }
        if done_at.is_some_and(|t| t.elapsed().as_secs_f64() * scale >= a.linger) {
            break End::Goal("robot 2 arrived and robot 1 resumed");
        }
        if rec.r1_truth.last().is_some_and(|r| r.t >= a.time_limit) {
            break End::TimeLimit;
        }
        if last_truth.elapsed() > Duration::from_secs(20) {
            break End::Stalled(format!(
                "no ground truth from the simulator for 20 s (see `nerve --robot {} logs sim`)",
                names[0]
            ));
        }
        if t0.elapsed() > wall_limit {
            break End::Stalled(format!(
                "the simulation ran slower than real time; {wall_limit:?} of wall time passed"
            ));
        }
        // a look every 100 ms of simulated time: the taps keep 16 samples of the 100 Hz truth
        std::thread::sleep(Duration::from_secs_f64(0.1 / scale));
    };
    progress(&rec, &phases);
    Ok((end, rec))
}

/// One progress line.
fn progress(rec: &Records, phases: &(String, String)) {
    let pos = |v: &[TruePose]| v.last().map_or_else(|| "-".into(), |t| format!("({:.2}, {:.2})", t.x, t.y));
    let t = rec.r1_truth.last().map_or(0.0, |r| r.t);
    let via = rec.reached.iter().map(|r| r.index + 1).max().unwrap_or(0);
    println!(
        "t {t:6.1} s | robot 1 {} {} | robot 2 {} {}{} | path {}",
        pos(&rec.r1_truth),
        phases.0,
        pos(&rec.r2_truth),
        phases.1,
        if rec.path.is_empty() { String::new() } else { format!(" {via}/{}", rec.path.len()) },
        if rec.path.is_empty() { "not yet" } else { "sent" },
    );
    let _ = std::io::stdout().flush();
}
