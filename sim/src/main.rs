//! `nerve-sim`: the simulator as a nerve agent (kind `sim`). It runs a
//! simulated robot in real time (or, on simulated time, at the robot
//! clock's scale, owning that clock: `docs/time.md`), publishes its devices as pseudo-terminals,
//! its ground truth on a port and its camera frames in a short-term-memory
//! ring.
//!
//! ```text
//! nerve start sim --name sim -- --world worlds/test-room.toml --robot-model h1 \
//!     --dev-dir $NERVE_HOME/h1/dev [--truth truth.csv] [--seed 7] [--duration 60]
//! ```
//!
//! * **Periodic** at the simulation rate: one step per period (default
//!   10 ms = 100 Hz). The step length is the period at start; `nerve rate
//!   sim 20ms` afterwards runs the world in slow motion (simulated time
//!   per step stays fixed), `nerve suspend sim` pauses it.
//! * **Devices**: the robot's boards as ptys, symlinked in `--dev-dir`
//!   (`sonar`, `motor`, `head`, `ir`; H2: `motor`, `ir`, `arm`), opened in
//!   `Agent::start` (not in `new`, which `--describe` also runs) and removed
//!   at stop. See `docs/devices.md`.
//! * **Output `truth`** (`nerve::GroundTruth`): true pose, speeds, collision
//!   count, every step. `--truth FILE.csv` also logs it as CSV.
//! * **Camera** (unless `--no-camera`): 320x240 RGB8 at `--fps` (15) of
//!   simulated time, rendered in place into the short-term-memory ring
//!   `--camera-ring` (default `simcam`) and announced on output `frames`
//!   (`nerve::RingNotice`). The `camera` agent with `--source sim` reads this
//!   ring and serves it as ring `cam` / port `camera/frames`, exactly like a
//!   webcam; the ring is not named `cam` so that the two never clash. The
//!   ring file is removed when the simulator stops.
//!
//! * **More robots in the same world** (`--extra-robot NAME:MODEL`,
//!   repeatable): each extra robot is another nerve robot `NAME` (its own
//!   router, its own agents) whose boards this simulator serves as ptys in
//!   that robot's state directory (`$NERVE_HOME/NAME/dev`, i.e. what
//!   `{state}/dev` means in `NAME`'s launch file; or the `DEV_DIR` given),
//!   and whose camera frames it renders into ring `--camera-ring` **of robot
//!   `NAME`**, where that robot's `camera --source sim` finds them. It starts
//!   at the world file's next `[[robot]]` start. Its ground truth goes out on
//!   this agent's output `truth-NAME` and, with `--truth FILE.csv`, into
//!   `FILE-NAME.csv` (or the `TRUTH_CSV` given). The robots see and bump
//!   into each other. One process owns the world, so both robots always
//!   live in the same simulated instant; it registers with the router of
//!   the robot it is started for (`--robot`), and robot `NAME` sees only
//!   its devices and its camera ring, as with a real robot.
//!
//!   ```text
//!   nerve --robot coop-r1 start sim --name sim -- --world worlds/cooperate.toml \
//!       --robot-model h1 --dev-dir $NERVE_HOME/coop-r1/dev --extra-robot coop-r2:h2
//!   ```
//!
//! Figures (`nerve param get sim`, read-only): `sim_time` (s) and
//! `collisions` of the simulator's own robot; collisions, gripper phase and
//! wheel bias of every robot.

use agent_sdk::memory::stm::{CreateError, RingWriter};
use agent_sdk::memory::{FrameDesc, MemorySetup, PixelFormat, RingName, RingOutput, RingSpec};
use agent_sdk::{Agent, AgentError, Context, Output, Setup, Task};
use nerve_sim::{
    CAMERA_FRAME_BYTES, CAMERA_HEIGHT, CAMERA_WIDTH, DeviceHub, NoiseModel, RobotId, RobotKind, RobotModel, SimConfig,
    Simulation, Truth, TruthLog, World, gripper_word,
};
use shm_schemas::RobotName;
use shm_schemas::payloads::GroundTruth;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The simulator's own options (after `--`).
#[derive(Debug, clap::Parser)]
#[command(name = "nerve-sim --")]
struct SimArgs {
    /// World file (TOML).
    #[arg(long)]
    world: Option<PathBuf>,
    /// Robot model: h1 (sonar, pan-tilt camera, IR) or h2 (arm, camera, IR).
    #[arg(long, default_value = "h1", value_parser = parse_robot)]
    robot_model: RobotKind,
    /// Directory in which to publish the device links (sonar, motor, head, ir, arm).
    #[arg(long)]
    dev_dir: Option<PathBuf>,
    /// Ground-truth CSV log, one row per step.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Seed of every random draw (slip, sonar, IR).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Stop after this many simulated seconds (default: run until stopped).
    #[arg(long)]
    duration: Option<f64>,
    /// Turn every noise source off (exact geometry).
    #[arg(long)]
    no_noise: bool,
    /// Do not render camera frames.
    #[arg(long)]
    no_camera: bool,
    /// Camera frames per second of simulated time.
    #[arg(long, default_value_t = 15.0)]
    fps: f64,
    /// Short-term-memory ring of the camera frames (read by `camera --source sim`).
    #[arg(long, default_value = "simcam")]
    camera_ring: String,
    /// Another robot in the same world, served to nerve robot NAME (model
    /// h1 or h2): its devices in DEV_DIR (default: NAME's state dir /dev),
    /// its camera in ring --camera-ring of NAME, its truth on output
    /// `truth-NAME` and in TRUTH_CSV (default with --truth: FILE-NAME.csv).
    /// It starts at the world file's next [[robot]]. Repeatable.
    #[arg(long = "extra-robot", value_name = "NAME:MODEL[:DEV_DIR[:TRUTH_CSV]]", value_parser = parse_extra)]
    extra_robot: Vec<ExtraArg>,
}

fn parse_robot(s: &str) -> Result<RobotKind, String> {
    s.parse()
}

/// One `--extra-robot` as written.
#[derive(Debug, Clone)]
struct ExtraArg {
    name: RobotName,
    model: RobotKind,
    dev_dir: Option<PathBuf>,
    truth: Option<PathBuf>,
}

fn parse_extra(s: &str) -> Result<ExtraArg, String> {
    let mut parts = s.splitn(4, ':');
    let (Some(name), Some(model)) = (parts.next(), parts.next()) else {
        return Err(format!("{s:?} is not NAME:MODEL[:DEV_DIR[:TRUTH_CSV]], e.g. coop-r2:h2"));
    };
    let name = RobotName::new(name).map_err(|e| format!("{s:?}: {e}"))?;
    let model = model.parse().map_err(|e| format!("{s:?}: {e}"))?;
    let path = |p: Option<&str>| p.filter(|p| !p.is_empty()).map(PathBuf::from);
    Ok(ExtraArg { name, model, dev_dir: path(parts.next()), truth: path(parts.next()) })
}

/// `dir/stem-NAME.ext` for the truth log `dir/stem.ext` of the first robot.
fn truth_path_for(first: &Path, robot: &RobotName) -> PathBuf {
    let stem = first.file_stem().map_or_else(|| "truth".into(), |s| s.to_string_lossy().into_owned());
    let name = match first.extension() {
        Some(ext) => format!("{stem}-{}.{}", robot.as_str(), ext.to_string_lossy()),
        None => format!("{stem}-{}", robot.as_str()),
    };
    first.with_file_name(name)
}

fn ground_truth(t: &Truth, stamp_ns: u64) -> GroundTruth {
    GroundTruth {
        sim_time: t.time,
        x: t.pose.x,
        y: t.pose.y,
        theta: t.pose.theta,
        v: t.v,
        omega: t.omega,
        collisions: t.collisions,
        in_contact: u8::from(t.in_contact),
        reserved: [0; 7],
        stamp_ns,
    }
}

/// Another robot of the world, served to its own nerve robot.
struct Extra {
    name: RobotName,
    model: RobotKind,
    dev_dir: PathBuf,
    truth_path: Option<PathBuf>,
    truth_out: Output<GroundTruth>,
    id: Option<RobotId>,
    hub: Option<DeviceHub>,
    truth_log: Option<TruthLog>,
    camera: Option<RingWriter>,
    camera_errors: u64,
}

/// Creates (or re-opens) ring `ring` of robot `robot` for camera frames;
/// a leftover ring of another geometry is replaced.
fn open_camera_ring(robot: &RobotName, ring: &RingName) -> Result<RingWriter, AgentError> {
    let create = || RingWriter::create(robot, ring, 8, CAMERA_FRAME_BYTES);
    let err = |e: CreateError| AgentError::Device(format!("camera ring {ring} of robot {robot}: {e}"));
    match create() {
        Err(CreateError::GeometryMismatch { path, .. }) => {
            tracing::warn!(ring = %ring, robot = %robot, "replacing ring {} of another geometry", path.display());
            let _ = std::fs::remove_file(&path);
            create().map_err(err)
        }
        other => other.map_err(err),
    }
}

/// What `nerve param get sim` shows for every robot.
type Figures = Arc<Mutex<Vec<(String, String)>>>;

struct SimAgent {
    args: SimArgs,
    world: Option<World>,
    sim: Option<Simulation>,
    hub: Option<DeviceHub>,
    truth_log: Option<TruthLog>,
    truth_out: Output<GroundTruth>,
    camera: Option<RingOutput>,
    next_frame: f64,
    camera_errors: u64,
    extras: Vec<Extra>,
    figures: Figures,
    next_figures: f64,
}

impl SimAgent {
    fn config(&self, dt: f64) -> SimConfig {
        let noise = if self.args.no_noise { NoiseModel::none() } else { NoiseModel::default() };
        SimConfig { seed: self.args.seed, dt, noise }
    }

    /// The simulation with every robot placed, as the options say.
    fn build(&self, world: World, dt: f64) -> Result<Simulation, AgentError> {
        let mut sim = Simulation::new(world, RobotModel::for_kind(self.args.robot_model), self.config(dt))
            .map_err(|e| AgentError::Config(e.to_string()))?;
        for x in &self.extras {
            sim.add_robot(x.name.as_str(), RobotModel::for_kind(x.model))
                .map_err(|e| AgentError::Config(format!("--extra-robot {}: {e}", x.name)))?;
        }
        Ok(sim)
    }

    fn update_figures(&self) {
        let Some(sim) = &self.sim else { return };
        // the simulator's own robot's totals first, by the names they had
        // as read-only parameters
        let mut figs = vec![
            ("sim_time".to_owned(), format!("{:.3}", sim.time())),
            ("collisions".to_owned(), sim.collisions().to_string()),
        ];
        for id in sim.robot_ids() {
            let r = sim.robot(id);
            let label = if id == RobotId::FIRST {
                "self".to_owned()
            } else {
                self.extras.get(id.index() - 1).map_or_else(|| r.name().to_owned(), |x| x.name.to_string())
            };
            figs.push((format!("{label}.collisions"), r.collisions().to_string()));
            let (phase, held) = r.gripper();
            if r.model().arm.is_some() {
                figs.push((format!("{label}.gripper"), gripper_word(phase).to_owned()));
                figs.push((format!("{label}.held"), held.map_or_else(|| "-".into(), |h| h.to_string())));
            }
            let (bl, br) = r.wheel_bias();
            figs.push((format!("{label}.wheel_bias"), format!("{bl:.4},{br:.4}")));
        }
        if let Ok(mut f) = self.figures.lock() {
            *f = figs;
        }
    }

    fn render_extras(&mut self, stamp_ns: u64) {
        let Some(sim) = self.sim.as_ref() else { return };
        let desc = FrameDesc::image(CAMERA_WIDTH as u32, CAMERA_HEIGHT as u32, PixelFormat::Rgb8).stamped(stamp_ns);
        for x in &mut self.extras {
            let (Some(cam), Some(id)) = (x.camera.as_mut(), x.id) else { continue };
            let mut render_err = None;
            let r = cam.write_with(desc, CAMERA_FRAME_BYTES, |buf| {
                if let Err(e) = sim.robot(id).render_camera(buf) {
                    render_err = Some(e.to_string());
                }
            });
            if let Some(e) = r.err().map(|e| e.to_string()).or(render_err) {
                x.camera_errors += 1;
                if x.camera_errors.is_power_of_two() {
                    tracing::warn!(robot = %x.name, errors = x.camera_errors, "camera frame not published: {e}");
                }
            }
        }
    }

    fn render(&mut self, stamp_ns: u64) {
        let (Some(cam), Some(sim)) = (self.camera.as_mut(), self.sim.as_ref()) else { return };
        let mut render_err = None;
        let desc = FrameDesc::image(CAMERA_WIDTH as u32, CAMERA_HEIGHT as u32, PixelFormat::Rgb8).stamped(stamp_ns);
        let r = cam.write_with(desc, CAMERA_FRAME_BYTES, |buf| {
            if let Err(e) = sim.render_camera(buf) {
                render_err = Some(e.to_string());
            }
        });
        let err = r.err().map(|e| e.to_string()).or(render_err);
        if let Some(e) = err {
            self.camera_errors += 1;
            if self.camera_errors.is_power_of_two() {
                tracing::warn!("camera frame not published ({} so far): {e}", self.camera_errors);
            }
        }
    }
}

impl Agent for SimAgent {
    const KIND: &'static str = "sim";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(10))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: SimArgs = setup.args()?;
        // the world is loaded (and checked) here if given; that it is given,
        // and the device directory, is checked in `start`: describing the
        // simulator, or testing it, needs neither
        let world =
            args.world.as_deref().map(World::load).transpose().map_err(|e| AgentError::Config(e.to_string()))?;
        if !(args.fps > 0.0 && args.fps <= 100.0) {
            return Err(AgentError::Config(format!("--fps {} must be in (0, 100]", args.fps)));
        }
        let own = setup.world().robot().clone();
        let mut extras = Vec::new();
        for x in &args.extra_robot {
            if x.name == own || extras.iter().any(|e: &Extra| e.name == x.name) {
                return Err(AgentError::Config(format!(
                    "--extra-robot {}: robot {} is already in this world; every robot needs its own name",
                    x.name, x.name
                )));
            }
            let dev_dir = match &x.dev_dir {
                Some(d) => d.clone(),
                None => agent_sdk::World::new(x.name.as_str())
                    .map_err(|e| AgentError::Config(format!("--extra-robot {}: {e}", x.name)))?
                    .state_dir()
                    .join("dev"),
            };
            if args.dev_dir.as_ref() == Some(&dev_dir) {
                return Err(AgentError::Config(format!(
                    "--extra-robot {}: its device directory {} is the one of --dev-dir; give it another",
                    x.name,
                    dev_dir.display()
                )));
            }
            let truth_path = x.truth.clone().or_else(|| args.truth.as_deref().map(|t| truth_path_for(t, &x.name)));
            extras.push(Extra {
                truth_out: setup.output(&format!("truth-{}", x.name))?,
                name: x.name.clone(),
                model: x.model,
                dev_dir,
                truth_path,
                id: None,
                hub: None,
                truth_log: None,
                camera: None,
                camera_errors: 0,
            });
        }
        let figures: Figures = Arc::default();
        let source = Arc::clone(&figures);
        setup.figures(move || source.lock().map(|f| f.clone()).unwrap_or_default());
        let camera = if args.no_camera {
            None
        } else {
            Some(setup.ring_output("frames", RingSpec::new(8, CAMERA_FRAME_BYTES).named(&args.camera_ring))?)
        };
        let mut agent = SimAgent {
            truth_out: setup.output("truth")?,
            camera,
            args,
            world: None,
            sim: None,
            hub: None,
            truth_log: None,
            next_frame: 0.0,
            camera_errors: 0,
            extras,
            figures,
            next_figures: 0.0,
        };
        if let Some(w) = world {
            // refuse a blocked or missing start now, while `nerve start` reports errors
            agent.build(w.clone(), 0.01)?;
            agent.world = Some(w);
        }
        Ok(agent)
    }

    fn start(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let Some(world) = self.world.clone() else {
            return Err(AgentError::Config(
                "no world: run `nerve start sim -- --world worlds/test-room.toml --dev-dir DIR`".into(),
            ));
        };
        let Some(dev_dir) = self.args.dev_dir.clone() else {
            return Err(AgentError::Config(
                "no device directory: add `--dev-dir DIR` after `--` (launch files use `{state}/dev`)".into(),
            ));
        };
        let dt = ctx.period().map_or(0.01, |p| p.as_secs_f64());
        let sim = self.build(world, dt)?;
        self.hub = Some(DeviceHub::open(&dev_dir, &sim).map_err(|e| AgentError::Device(e.to_string()))?);
        if let Some(path) = &self.args.truth {
            self.truth_log = Some(TruthLog::create(path).map_err(|e| AgentError::Other(e.to_string()))?);
        }
        if let Some(cam) = self.camera.as_mut() {
            cam.open().map_err(|e| AgentError::Device(format!("camera ring: {e}")))?;
        }
        let ring = RingName::text(&self.args.camera_ring)
            .map_err(|e| AgentError::Config(format!("--camera-ring {}: {e}", self.args.camera_ring)))?;
        for (x, id) in self.extras.iter_mut().zip(sim.robot_ids().skip(1)) {
            x.id = Some(id);
            x.hub = Some(
                DeviceHub::open_robot(&x.dev_dir, &sim, id)
                    .map_err(|e| AgentError::Device(format!("robot {}: {e}", x.name)))?,
            );
            if let Some(path) = &x.truth_path {
                x.truth_log = Some(TruthLog::create(path).map_err(|e| AgentError::Other(e.to_string()))?);
            }
            if !self.args.no_camera {
                x.camera = Some(open_camera_ring(&x.name, &ring)?);
            }
            let p = sim.robot(id).pose();
            tracing::info!(
                robot = %x.name, model = %x.model, dev_dir = %x.dev_dir.display(), x = p.x, y = p.y,
                "serving another robot of the world"
            );
        }
        tracing::info!(
            world = %sim.world().name, robot = %self.args.robot_model, seed = self.args.seed,
            dev_dir = %dev_dir.display(), step_s = dt, "simulator running"
        );
        self.sim = Some(sim);
        // on simulated time the robot's clock is this simulator's: no agent runs past its step
        agent_sdk::simclock::own();
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let (Some(sim), Some(hub)) = (self.sim.as_mut(), self.hub.as_mut()) else { return Ok(()) };
        if self.args.duration.is_some_and(|d| sim.time() >= d - 1e-9) {
            tracing::info!("simulated {} s: stopping", sim.time());
            ctx.request_stop();
            return Ok(());
        }
        hub.apply_commands(sim);
        for x in &mut self.extras {
            if let Some(h) = x.hub.as_mut() {
                h.apply_commands(sim);
            }
        }
        sim.step();
        hub.send_reports(sim);
        let stamp_ns = ctx.now_ns();
        for x in &mut self.extras {
            let (Some(h), Some(id)) = (x.hub.as_mut(), x.id) else { continue };
            h.send_reports(sim);
            let t = sim.robot(id).truth();
            if let Some(log) = x.truth_log.as_mut() {
                log.write(&t).map_err(|e| AgentError::Other(e.to_string()))?;
                if sim.steps() % 100 == 0 {
                    log.flush().map_err(|e| AgentError::Other(e.to_string()))?;
                }
            }
            x.truth_out.send(ground_truth(&t, stamp_ns))?;
        }
        let t = sim.truth();
        if let Some(log) = self.truth_log.as_mut() {
            log.write(&t).map_err(|e| AgentError::Other(e.to_string()))?;
            if sim.steps() % 100 == 0 {
                log.flush().map_err(|e| AgentError::Other(e.to_string()))?;
            }
        }
        let frame_due = t.time + 1e-9 >= self.next_frame;
        self.truth_out.send(ground_truth(&t, stamp_ns))?;
        if frame_due && self.camera.is_some() {
            self.next_frame += 1.0 / self.args.fps;
            if self.next_frame < t.time {
                self.next_frame = t.time + 1.0 / self.args.fps;
            }
            self.render(ctx.now_ns());
            self.render_extras(ctx.now_ns());
        }
        if t.time + 1e-9 >= self.next_figures {
            self.next_figures = t.time + 0.5;
            self.update_figures();
        }
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) {
        if let Some(log) = self.truth_log.as_mut()
            && let Err(e) = log.flush()
        {
            tracing::warn!("truth log: {e}");
        }
        if let Some(hub) = self.hub.take() {
            for d in hub.devices() {
                tracing::info!(device = %d.kind(), stats = ?d.stats(), decode = ?d.decode_stats(), "device totals");
            }
        }
        for x in &mut self.extras {
            if let Some(log) = x.truth_log.as_mut()
                && let Err(e) = log.flush()
            {
                tracing::warn!(robot = %x.name, "truth log: {e}");
            }
            if let Some(hub) = x.hub.take() {
                for d in hub.devices() {
                    tracing::info!(robot = %x.name, device = %d.kind(), stats = ?d.stats(), "device totals");
                }
            }
            if let Some(cam) = x.camera.take() {
                let path = cam.path().to_owned();
                if let Err(e) = cam.remove() {
                    tracing::warn!(robot = %x.name, "cannot remove the camera ring {}: {e}", path.display());
                }
            }
        }
        if let Some(path) = self.camera.as_ref().and_then(|c| c.writer()).map(|w| w.path().to_owned())
            && let Err(e) = std::fs::remove_file(&path)
        {
            tracing::warn!("cannot remove the camera ring {}: {e}", path.display());
        }
        if let Some(sim) = &self.sim {
            tracing::info!(
                steps = sim.steps(),
                sim_time = sim.time(),
                collisions = sim.collisions(),
                "simulator stopped"
            );
            for x in &self.extras {
                if let Some(id) = x.id {
                    let r = sim.robot(id);
                    tracing::info!(robot = %x.name, collisions = r.collisions(), gripper = gripper_word(r.gripper().0), "robot totals");
                }
            }
        }
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<SimAgent>()
}
