//! `nerve calibrate checkpoint`: the Appendix A calibration of the
//! checkpoint sensor (thesis Appendix A, `docs/cooperate.md`) from one
//! command.
//!
//! ```text
//! nerve calibrate checkpoint                          # H1 in the simulator
//! nerve calibrate checkpoint --robot-model h2 --speed 0.3
//! nerve calibrate checkpoint --samples samples.toml   # no simulator
//! nerve calibrate checkpoint --samples s.csv --band-spacing 0.2 --focal 277.128
//! ```
//!
//! **Samples from the simulator** (the default). It writes a world with one
//! checkpoint tube straight ahead of the robot (`DIR/world.toml`) and a
//! launch file with the simulator and the motor agent (`DIR/launch.toml`),
//! launches them on a private robot (`calib-<pid>`, or the robot named with
//! `--robot`/`NERVE_ROBOT`, which must not be running anything) with `nerve
//! launch`, and drives
//! the robot at the tube with `nerve cmd motor --v SPEED --hold ...` from
//! `--far` (3.5 m) to `--near` (0.8 m). Every camera frame the simulator
//! renders into its ring `simcam` is searched by the checkpoint agent's own
//! band finder (`nerve_checkpoint::bands`); the frame's stamp finds the
//! simulator's ground truth of the same step (port `sim/truth`), which gives
//! the true distance `Z` from the camera to the tube's near surface along
//! the optical axis. A frame gives a sample `(d, Z)` when it shows exactly
//! one upright tube not cut by the frame's border and `Z` lies in
//! `near … far`. A progress line per second. Then everything is stopped and
//! removed as `nerve down` does — also on an error and on Ctrl-C — and the
//! logs are kept in `DIR/logs/`.
//!
//! **Samples from a file** (`--samples FILE`): TOML (`band_spacing_m`,
//! `focal_px`, `[[sample]] d_px z_m`) or CSV (`d_px,z_m`, with
//! `--band-spacing` and `--focal`), as `nerve-checkpoint-fit` reads them.
//!
//! Either way `nerve_demo::calibration::report` fits `h` and `α1..α4`
//! (`nerve_checkpoint::appendix_a::fit`) and writes:
//!
//! * `--out FILE` (default `DIR/calibration.toml`): the calibration, checked
//!   with the checkpoint agent's own loader; give it to the agent with
//!   `-- --calibration FILE`;
//! * `DIR/samples.csv`: the samples fitted (`d_px,z_m`; `D` and `f` in its
//!   comment);
//! * `DIR/fit.png`, `DIR/fit.svg`: estimated against true distance for the
//!   pinhole term alone and the fitted model, and their residuals;
//!
//! and prints the RMS error of both. `DIR` is `--dir`, by default
//! `out/calibrate-checkpoint-<model>` for a simulator run and
//! `out/calibrate-checkpoint` for a samples file. Exit code 0 when the
//! calibration was written, 1 when not.

use crate::nerve::{self, Tap, cli_node};
use agent_sdk::World;
use anyhow::{Context as _, Result, anyhow, bail};
use nerve_checkpoint::appendix_a::Sample;
use nerve_checkpoint::bands::{BandColors, Pixels, Tube, TubeFinder};
use nerve_checkpoint::config::SampleFile;
use nerve_demo::calibration::{self, SampleSet};
use nerve_demo::nerve_sim::{RobotKind, RobotModel, focal_length_px};
use nerve_stm::{ReadError, RingName, RingReader};
use shm_schemas::RobotName;
use shm_schemas::payloads::GroundTruth;
use std::collections::VecDeque;
use std::io::{Read as _, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, ExitCode, Stdio};
use std::time::{Duration, Instant};

/// `nerve calibrate ...`
#[derive(Debug, clap::Subcommand)]
pub enum CalibrateCmd {
    /// Appendix A: fit the checkpoint sensor's distance model to samples
    /// taken in the simulator (default) or read from a file, write the
    /// calibration the checkpoint agent reads and plot the fit.
    Checkpoint(CheckpointArgs),
}

/// `nerve calibrate checkpoint`
#[derive(Debug, Clone, clap::Args)]
pub struct CheckpointArgs {
    /// Fit the samples of this file (TOML, or CSV `d_px,z_m`) instead of running the simulator.
    #[arg(long)]
    pub samples: Option<PathBuf>,
    /// D, metres between the band centres (CSV samples only).
    #[arg(long, requires = "samples")]
    pub band_spacing: Option<f64>,
    /// f, the camera's focal length in pixels (CSV samples only).
    #[arg(long, requires = "samples")]
    pub focal: Option<f64>,
    /// Robot driven in the simulator: h1 (camera 1 m high) or h2 (0.8 m).
    #[arg(long, default_value = "h1", value_parser = parse_model)]
    pub robot_model: RobotKind,
    /// Directory of the samples, the figures and the run's records
    /// [default: out/calibrate-checkpoint-<model>, or out/calibrate-checkpoint with --samples].
    #[arg(long)]
    pub dir: Option<PathBuf>,
    /// The calibration file to write [default: DIR/calibration.toml].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Farthest distance sampled, metres (camera to the tube's near surface).
    #[arg(long, default_value_t = 3.5)]
    pub far: f64,
    /// Nearest distance sampled, metres.
    #[arg(long, default_value_t = 0.8)]
    pub near: f64,
    /// Speed of the robot toward the tube, m/s.
    #[arg(long, default_value_t = 0.25)]
    pub speed: f64,
    /// Seed of the simulator's noise (wheel slip).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

fn parse_model(s: &str) -> Result<RobotKind, String> {
    s.parse()
}

/// Runs a calibration.
pub fn calibrate(robot: &str, explicit: bool, cmd: CalibrateCmd) -> Result<ExitCode> {
    match cmd {
        CalibrateCmd::Checkpoint(a) => checkpoint(robot, explicit, &a),
    }
}

/// The checkpoint tube of the calibration world, as the truth needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TubeGeometry {
    x: f64,
    y: f64,
    radius: f64,
    band_spacing: f64,
}

/// The simulator's robot during the run.
const SIM_AGENT: &str = "sim";
/// The ring the simulator renders its camera frames into.
const CAMERA_RING: &str = "simcam";
/// Least pixels of each colour for a tube (the checkpoint agent's default `min_pixels`).
const MIN_PIXELS: usize = 20;
/// The robot starts this far beyond `--far`, to be at speed when sampling begins.
const RUN_UP_M: f64 = 0.15;
/// A frame and a ground-truth row this far apart in time are not of the same step.
const MATCH_NS: u64 = 15_000_000;

fn check_args(a: &CheckpointArgs) -> Result<()> {
    if a.samples.is_some() {
        return Ok(());
    }
    if !(a.near.is_finite() && a.near >= 0.3) {
        bail!("--near {} must be at least 0.3 m (the robot's body would touch the tube)", a.near);
    }
    if !(a.far.is_finite() && a.far >= a.near + 0.5 && a.far <= 8.0) {
        bail!("--far {} must be at least 0.5 m beyond --near ({}) and at most 8 m", a.far, a.near);
    }
    if !(a.speed.is_finite() && a.speed > 0.0 && a.speed <= 0.6) {
        bail!("--speed {} must be in (0, 0.6] m/s (H2's top speed is 0.6)", a.speed);
    }
    Ok(())
}

fn checkpoint(robot: &str, explicit: bool, a: &CheckpointArgs) -> Result<ExitCode> {
    check_args(a)?;
    let default_dir = match a.samples {
        Some(_) => PathBuf::from("out/calibrate-checkpoint"),
        None => PathBuf::from(format!("out/calibrate-checkpoint-{}", a.robot_model)),
    };
    let dir = a.dir.clone().unwrap_or(default_dir);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create output directory {}", dir.display()))?;
    let dir = std::fs::canonicalize(&dir).with_context(|| format!("cannot use output directory {}", dir.display()))?;
    let out = a.out.clone().unwrap_or_else(|| dir.join("calibration.toml"));
    let set = match &a.samples {
        Some(path) => from_file(path, a)?,
        None => simulate(robot, explicit, a, &dir)?,
    };
    let f = calibration::report(&set, &dir, &out)?;
    for line in calibration::describe(&f, &dir, &out) {
        println!("{line}");
    }
    Ok(ExitCode::SUCCESS)
}

/// Reads `--samples`.
fn from_file(path: &Path, a: &CheckpointArgs) -> Result<SampleSet> {
    let sf = SampleFile::load(path, a.band_spacing.zip(a.focal))?;
    Ok(SampleSet {
        samples: sf.samples,
        band_spacing_m: sf.band_spacing_m,
        focal_px: sf.focal_px,
        source: format!("samples of {}", path.display()),
    })
}

/// The calibration world: the robot at the origin facing +x, one checkpoint
/// tube straight ahead with its near surface `far + RUN_UP_M` away, a wall
/// behind it.
fn world_text(far: f64) -> String {
    let radius = 0.05;
    let tube_x = far + RUN_UP_M + radius;
    let wall_x = tube_x + 1.5;
    format!(
        "# Written by `nerve calibrate checkpoint`: one checkpoint tube (yellow over\n\
         # blue, bands 0.2 m apart) straight ahead of the robot, a wall behind it.\n\
         # The robot drives at the tube along the x axis.\n\
         name = \"calibrate-checkpoint\"\n\n\
         [robot]\nx = 0.0\ny = 0.0\nheading_deg = 0.0\n\
         wheel_bias = [0.0, 0.0]   # no drift: it drives straight at the tube\n\n\
         [[checkpoint]]\nid = 1\nposition = [{tube_x}, 0.0]\nheading_deg = 180.0\nradius = {radius}\n\n\
         [[wall]]\nfrom = [{wall_x}, -3.0]\nto = [{wall_x}, 3.0]\n"
    )
}

/// The run's launch file: the simulator and the motor agent, nothing else.
fn launch_text(robot: &str, world: &Path, model: RobotKind, seed: u64) -> Result<String> {
    let s = |v: &str| toml::Value::String(v.to_owned());
    let strings = |v: &[&str]| toml::Value::Array(v.iter().map(|x| s(x)).collect());
    let world = world.to_str().ok_or_else(|| anyhow!("the path {} is not UTF-8", world.display()))?;
    let (model, seed) = (model.to_string(), seed.to_string());
    let mut sim = toml::Table::new();
    sim.insert("name".into(), s(SIM_AGENT));
    sim.insert("kind".into(), s("sim"));
    sim.insert(
        "args".into(),
        strings(&["--world", world, "--robot-model", &model, "--seed", &seed, "--dev-dir", "{state}/dev"]),
    );
    let mut motor = toml::Table::new();
    motor.insert("name".into(), s("motor"));
    motor.insert("kind".into(), s("motor"));
    motor.insert("device".into(), s("{state}/dev/motor"));
    motor.insert("args".into(), strings(&["--robot-model", &model]));
    let mut doc = toml::Table::new();
    doc.insert("robot".into(), s(robot));
    doc.insert("agent".into(), toml::Value::Array(vec![toml::Value::Table(sim), toml::Value::Table(motor)]));
    let body = toml::to_string(&doc).context("cannot write the launch file")?;
    Ok(format!(
        "# Written by `nerve calibrate checkpoint`: the simulator and the motor, driven by `nerve cmd`.\n{body}"
    ))
}

/// The tube of the calibration world (its only checkpoint).
fn tube_of(world: &nerve_demo::nerve_sim::World) -> Result<TubeGeometry> {
    let c = world.checkpoints.first().ok_or_else(|| anyhow!("the calibration world has no checkpoint"))?;
    Ok(TubeGeometry { x: c.position.x, y: c.position.y, radius: c.radius, band_spacing: c.band_spacing() })
}

/// Appendix A's `Z` from the true pose: the depth of the tube's near
/// surface along the camera's optical axis (the camera is at the robot's
/// centre and looks along its heading; no head agent turns it).
fn depth(tube: &TubeGeometry, t: &GroundTruth) -> f64 {
    (tube.x - t.x) * t.theta.cos() + (tube.y - t.y) * t.theta.sin() - tube.radius
}

/// Refuses a robot that already runs agents (they would be stopped at the end).
fn refuse_busy(world: &World) -> Result<()> {
    let live = nerve::running_agents(world);
    if !live.is_empty() {
        bail!(
            "robot {r} already runs {} agent(s) ({}); the calibration brings its robot down at the end: \
             stop them with `nerve --robot {r} down` or leave out --robot (a private robot is used)",
            live.len(),
            live.join(", "),
            r = world.robot()
        );
    }
    Ok(())
}

/// Samples from the simulator: see the module documentation.
fn simulate(robot: &str, explicit: bool, a: &CheckpointArgs, dir: &Path) -> Result<SampleSet> {
    let robot = if explicit { robot.to_owned() } else { format!("calib-{}", std::process::id()) };
    let nworld = World::new(&robot)?;
    refuse_busy(&nworld)?;
    let world_path = dir.join("world.toml");
    std::fs::write(&world_path, world_text(a.far)).with_context(|| format!("cannot write {}", world_path.display()))?;
    let sim_world = nerve_demo::nerve_sim::World::load(&world_path)?;
    let tube = tube_of(&sim_world)?;
    let focal_px = focal_length_px(RobotModel::for_kind(a.robot_model).camera_hfov);
    let launch_path = dir.join("launch.toml");
    std::fs::write(&launch_path, launch_text(&robot, &world_path, a.robot_model, a.seed)?)
        .with_context(|| format!("cannot write {}", launch_path.display()))?;
    println!(
        "nerve calibrate checkpoint: {} in the simulator (robot {robot}, seed {}), tube from {} m to {} m at {} m/s; output {}",
        a.robot_model,
        a.seed,
        a.far,
        a.near,
        a.speed,
        dir.display()
    );
    nerve::catch_interrupts();
    let t0 = Instant::now();
    let result = match nerve::launch(&robot, &launch_path, None) {
        Ok(()) => {
            println!("simulator up in {:.1} s; driving at the tube (Ctrl-C stops)", t0.elapsed().as_secs_f64());
            collect(&nworld, &tube, a)
        }
        Err(e) => Err(e.context("the simulator did not come up")),
    };
    // whatever happened: stop everything and leave nothing behind
    println!("{}", nerve::down(&robot));
    nerve::copy_logs(&nworld, &dir.join("logs"));
    if !explicit && let Err(e) = std::fs::remove_dir_all(nworld.state_dir()) {
        eprintln!("warning: cannot remove {}: {e}", nworld.state_dir().display());
    }
    if result.is_err() {
        eprintln!("the run's logs are in {}", dir.join("logs").display());
    }
    let c = result?;
    println!(
        "{} samples from {} frames ({} lost; {} with the tube cut by the frame's border, {} without one tube, {} out of {} … {} m)",
        c.samples.len(),
        c.frames,
        c.lost,
        c.clipped,
        c.unseen,
        c.out_of_range,
        a.near,
        a.far
    );
    Ok(SampleSet {
        samples: c.samples,
        band_spacing_m: tube.band_spacing,
        focal_px,
        source: format!("{} in the simulator", a.robot_model),
    })
}

/// What the drive toward the tube gave.
#[derive(Debug, Default)]
struct Collected {
    samples: Vec<Sample>,
    frames: u64,
    clipped: u64,
    unseen: u64,
    out_of_range: u64,
    /// frames overwritten in the ring before they were read
    lost: u64,
}

/// What one frame gives.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Seen {
    /// One upright tube, whole: its `d`.
    Tube(f64),
    /// One upright tube touching the border.
    Clipped,
    /// No tube, or several.
    Unseen,
}

fn classify(tubes: &[Tube]) -> Seen {
    let upright: Vec<&Tube> = tubes.iter().filter(|t| t.upright).collect();
    match upright.as_slice() {
        [t] if t.clipped => Seen::Clipped,
        [t] => Seen::Tube(f64::from(t.d_px)),
        _ => Seen::Unseen,
    }
}

/// `nerve cmd motor --v SPEED --hold ...` as a child process; killed when dropped.
#[derive(Debug)]
struct Driver {
    child: Child,
}

impl Driver {
    fn spawn(robot: &RobotName, speed: f64, hold: Duration) -> Result<Self> {
        let child = std::process::Command::new(nerve::nerve_exe())
            .args(["--robot", robot.as_str(), "cmd", "motor", "--sender", "calibrate"])
            .args(["--v", &format!("{speed}"), "--hold", &format!("{}ms", hold.as_millis())])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .context("cannot start `nerve cmd motor`")?;
        Ok(Driver { child })
    }

    /// Whether it has finished (held the command as long as told); an error when it failed.
    fn finished(&mut self) -> Result<bool> {
        match self.child.try_wait().context("cannot wait for `nerve cmd motor`")? {
            None => Ok(false),
            Some(s) if s.success() => Ok(true),
            Some(s) => {
                let mut err = String::new();
                if let Some(mut e) = self.child.stderr.take() {
                    let _ = e.read_to_string(&mut err);
                }
                bail!("`nerve cmd motor` failed ({s}): {}", err.trim())
            }
        }
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

type TruthSubscriber = Tap<GroundTruth>;

/// Opens the simulator's camera ring (retrying while it comes up).
fn open_ring(world: &World) -> Result<RingReader> {
    let name = RingName::text(CAMERA_RING).map_err(|e| anyhow!("ring {CAMERA_RING}: {e}"))?;
    let t0 = Instant::now();
    loop {
        match RingReader::open(world.robot(), &name) {
            Ok(r) => return Ok(r),
            Err(e) if t0.elapsed() > Duration::from_secs(10) => {
                bail!("the simulator's camera ring {CAMERA_RING} did not appear within 10 s: {e}")
            }
            Err(_) => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

/// The ground truth received lately, to find a frame's step in.
#[derive(Debug, Default)]
struct TruthWindow {
    rows: VecDeque<GroundTruth>,
    last_received: Option<Instant>,
}

impl TruthWindow {
    /// Rows kept: 3 s of steps at 100 Hz (the camera ring holds 8 frames, 0.5 s).
    const KEEP: usize = 300;

    fn drain(&mut self, sub: &TruthSubscriber) -> Result<()> {
        sub.drain(|_, t| {
            self.rows.push_back(*t);
            self.last_received = Some(Instant::now());
            if self.rows.len() > Self::KEEP {
                self.rows.pop_front();
            }
        })
    }

    fn newest(&self) -> Option<&GroundTruth> {
        self.rows.back()
    }

    /// The row of the step stamped nearest `stamp_ns`, if within [`MATCH_NS`].
    fn at(&self, stamp_ns: u64) -> Option<&GroundTruth> {
        self.rows
            .iter()
            .min_by_key(|r| r.stamp_ns.abs_diff(stamp_ns))
            .filter(|r| r.stamp_ns.abs_diff(stamp_ns) <= MATCH_NS)
    }
}

/// Drives at the tube and collects samples until the robot passes `--near`
/// (or stops short of it).
fn collect(world: &World, tube: &TubeGeometry, a: &CheckpointArgs) -> Result<Collected> {
    let node = cli_node(world)?;
    let sub: TruthSubscriber = Tap::open(world, &node, SIM_AGENT, "truth", Duration::from_secs(10))?;
    let ring = open_ring(world)?;
    let mut truth = TruthWindow::default();
    let t0 = Instant::now();
    while truth.newest().is_none() {
        truth.drain(&sub)?;
        if t0.elapsed() > Duration::from_secs(10) {
            bail!("no ground truth from the simulator within 10 s");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let start = truth.newest().map_or(a.far + RUN_UP_M, |t| depth(tube, t));
    // the drive takes (start − near)/speed of simulated time; the command is
    // held for three times that (a loaded machine runs the simulator slower
    // than real time) and ends when the robot has passed `near`
    let wall_limit = Duration::from_secs_f64(3.0 * (start - a.near) / a.speed + 10.0);
    let mut driver = Driver::spawn(world.robot(), a.speed, wall_limit)?;
    let (mut finder, colors) = (TubeFinder::default(), BandColors::default());
    let mut next_seq = ring.last_seq().map_or(1, |s| s + 1);
    let mut c = Collected::default();
    let mut next_progress = Instant::now();
    let mut passed_near = false;
    let mut still_since: Option<Instant> = None;
    loop {
        if nerve::interrupted() {
            bail!("interrupted (Ctrl-C): no calibration written");
        }
        truth.drain(&sub)?;
        let newest = truth.newest().copied().ok_or_else(|| anyhow!("no ground truth"))?;
        // frames up to the newest step whose truth is here
        while let Some(last) = ring.last_seq().filter(|l| next_seq <= *l) {
            match frame(&ring, next_seq, &mut finder, &colors, newest.stamp_ns) {
                Ok(Some((stamp, seen))) => {
                    next_seq += 1;
                    c.frames += 1;
                    if let Some(t) = truth.at(stamp) {
                        record(&mut c, seen, depth(tube, t), a);
                    }
                }
                // its step's truth has not come yet, or the simulator is still writing it
                Ok(None) | Err(ReadError::InProgress { .. } | ReadError::NotYet { .. }) => break,
                Err(ReadError::Overwritten { .. }) => {
                    next_seq += 1;
                    c.lost += 1;
                }
                Err(e) => bail!("cannot read frame {next_seq} (of {last}) of ring {CAMERA_RING}: {e}"),
            }
        }
        let z = depth(tube, &newest);
        passed_near |= z < a.near;
        if passed_near && ring.last_seq().is_none_or(|l| next_seq > l) {
            break;
        }
        still_since = if newest.v.abs() < 1e-3 { still_since.or(Some(Instant::now())) } else { None };
        if driver.finished()? && still_since.is_some_and(|s| s.elapsed() > Duration::from_millis(500)) {
            eprintln!("warning: the robot stopped {z:.2} m from the tube, before --near {} m", a.near);
            break;
        }
        if truth.last_received.is_some_and(|t| t.elapsed() > Duration::from_secs(5)) {
            bail!("the simulator has published no ground truth for 5 s (see logs/sim.log)");
        }
        if t0.elapsed() > wall_limit {
            bail!(
                "the robot did not reach {} m from the tube within {wall_limit:?} (now {z:.2} m; see logs/motor.log)",
                a.near
            );
        }
        if Instant::now() >= next_progress {
            next_progress = Instant::now() + Duration::from_secs(1);
            progress(&newest, z, &c);
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    drop(driver); // stops holding the command: the motor stops within its stale_ms
    Ok(c)
}

/// Reads frame `seq` and finds its tubes, unless it is newer than
/// `newest_truth_ns` (then `Ok(None)`: its truth has not been received yet).
fn frame(
    ring: &RingReader,
    seq: u64,
    finder: &mut TubeFinder,
    colors: &BandColors,
    newest_truth_ns: u64,
) -> Result<Option<(u64, Seen)>, ReadError> {
    let meta = ring.meta(seq)?;
    if meta.stamp_ns > newest_truth_ns {
        return Ok(None);
    }
    // the band finder on the frame in place; the result counts only if the read stayed intact
    let found = ring.read_with(seq, |m, px| {
        let (w, h) = (m.width as usize, m.height as usize);
        finder.find(px, Pixels::Rgb8, w, h, colors, MIN_PIXELS).map(|t| (m.stamp_ns, classify(&t)))
    })?;
    Ok(Some(found.unwrap_or((meta.stamp_ns, Seen::Unseen))))
}

/// Adds what a frame showed at true distance `z`.
fn record(c: &mut Collected, seen: Seen, z: f64, a: &CheckpointArgs) {
    if !(a.near..=a.far).contains(&z) {
        c.out_of_range += 1;
        return;
    }
    match seen {
        Seen::Tube(d_px) => c.samples.push(Sample { d_px, z_m: z }),
        Seen::Clipped => c.clipped += 1,
        Seen::Unseen => c.unseen += 1,
    }
}

fn progress(t: &GroundTruth, z: f64, c: &Collected) {
    let d = c.samples.last().map_or_else(|| "-".into(), |s| format!("{:.1} px", s.d_px));
    println!(
        "  t {:5.1} s  distance {z:5.2} m  v {:4.2} m/s  last d {d:>8}  samples {:4}  (clipped {}, not seen {})",
        t.sim_time,
        t.v,
        c.samples.len(),
        c.clipped,
        c.unseen
    );
    let _ = std::io::stdout().flush();
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn truth(x: f64, y: f64, theta: f64) -> GroundTruth {
        GroundTruth {
            sim_time: 0.0,
            x,
            y,
            theta,
            v: 0.0,
            omega: 0.0,
            collisions: 0,
            in_contact: 0,
            reserved: [0; 7],
            stamp_ns: 0,
        }
    }

    #[test]
    fn the_world_parses_and_puts_the_tube_ahead() {
        let dir = std::env::temp_dir().join(format!("nerve-calib-world-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("world.toml");
        std::fs::write(&p, world_text(3.5)).unwrap();
        let w = nerve_demo::nerve_sim::World::load(&p).unwrap();
        let tube = tube_of(&w).unwrap();
        assert!((tube.band_spacing - 0.2).abs() < 1e-12, "the simulator's tubes: bands 0.2 m apart");
        // the robot at its start: the near surface RUN_UP_M beyond --far
        assert!((depth(&tube, &truth(0.0, 0.0, 0.0)) - (3.5 + RUN_UP_M)).abs() < 1e-9);
        // depth is along the optical axis: turned 90° the tube is beside, not ahead
        assert!(depth(&tube, &truth(0.0, 0.0, std::f64::consts::FRAC_PI_2)) < 0.0);
        let launch = launch_text("calib-1", &p, RobotKind::H2, 7).unwrap();
        let doc: toml::Table = toml::from_str(&launch).unwrap();
        assert_eq!(doc["robot"].as_str(), Some("calib-1"));
        let agents = doc["agent"].as_array().unwrap();
        assert_eq!(agents.len(), 2);
        let args: Vec<&str> = agents[0]["args"].as_array().unwrap().iter().filter_map(|v| v.as_str()).collect();
        assert!(args.windows(2).any(|w| w == ["--robot-model", "h2"]) && args.contains(&"7"), "{args:?}");
        assert_eq!(agents[1]["device"].as_str(), Some("{state}/dev/motor"));
        std::fs::remove_dir_all(&dir).ok();
    }

    fn tube(d_px: f32, upright: bool, clipped: bool) -> Tube {
        Tube { col: 160.0, upper_row: 100.0, lower_row: 100.0 + d_px, d_px, upright, pixels: (50, 50), clipped }
    }

    #[test]
    fn frames_are_classified_and_recorded_in_range_only() {
        assert_eq!(classify(&[tube(20.0, true, false)]), Seen::Tube(20.0));
        assert_eq!(classify(&[tube(20.0, true, true)]), Seen::Clipped);
        assert_eq!(classify(&[]), Seen::Unseen);
        assert_eq!(classify(&[tube(20.0, true, false), tube(30.0, true, false)]), Seen::Unseen);
        assert_eq!(classify(&[tube(20.0, false, false)]), Seen::Unseen, "the target is not a checkpoint");
        let a = CheckpointArgs {
            samples: None,
            band_spacing: None,
            focal: None,
            robot_model: RobotKind::H1,
            dir: None,
            out: None,
            far: 3.5,
            near: 0.8,
            speed: 0.25,
            seed: 1,
        };
        let mut c = Collected::default();
        record(&mut c, Seen::Tube(20.0), 2.0, &a);
        record(&mut c, Seen::Tube(15.0), 3.6, &a);
        record(&mut c, Seen::Clipped, 0.9, &a);
        assert_eq!((c.samples.len(), c.out_of_range, c.clipped), (1, 1, 1));
        assert!(check_args(&a).is_ok());
        for (near, far, speed) in [(0.1, 3.5, 0.25), (0.8, 1.0, 0.25), (0.8, 3.5, 0.0), (0.8, 3.5, 2.0)] {
            assert!(check_args(&CheckpointArgs { near, far, speed, ..a.clone() }).is_err());
        }
    }

    #[test]
    fn truth_is_matched_by_stamp() {
        let mut w = TruthWindow::default();
        for i in 0..10u64 {
            let mut t = truth(i as f64, 0.0, 0.0);
            t.stamp_ns = 1_000_000_000 + i * 10_000_000;
            w.rows.push_back(t);
        }
        assert_eq!(w.at(1_030_000_000).map(|t| t.x), Some(3.0));
        assert_eq!(w.at(1_031_000_000).map(|t| t.x), Some(3.0));
        assert!(w.at(1_200_000_000).is_none(), "too far from every step");
    }
}
