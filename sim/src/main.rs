//! `nerve-sim`: the simulator as a nerve agent (kind `sim`). It runs a
//! simulated robot in real time, publishes its devices as pseudo-terminals,
//! its ground truth on a port and its camera frames in a short-term-memory
//! ring.
//!
//! ```text
//! nerve start sim --name sim -- --world worlds/test-room.toml --robot-model h1 \
//!     --dev-dir /tmp/nerve/h1/dev [--truth truth.csv] [--seed 7] [--duration 60]
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
//! Parameters: read-only `sim_time` (s), `collisions`.

use agent_sdk::memory::{FrameDesc, MemorySetup, PixelFormat, RingOutput, RingSpec};
use agent_sdk::{Agent, AgentError, Context, Output, Param, Setup, Task};
use nerve_sim::{
    CAMERA_FRAME_BYTES, CAMERA_HEIGHT, CAMERA_WIDTH, DeviceHub, NoiseModel, RobotKind, RobotModel, SimConfig,
    Simulation, TruthLog, World,
};
use shm_schemas::payloads::GroundTruth;
use std::path::PathBuf;
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
}

fn parse_robot(s: &str) -> Result<RobotKind, String> {
    s.parse()
}

struct SimAgent {
    args: SimArgs,
    world: Option<World>,
    sim: Option<Simulation>,
    hub: Option<DeviceHub>,
    truth_log: Option<TruthLog>,
    truth_out: Output<GroundTruth>,
    camera: Option<RingOutput>,
    next_frame: f64,
    sim_time: Param<f64>,
    collisions: Param<u64>,
    camera_errors: u64,
}

impl SimAgent {
    fn config(&self, dt: f64) -> SimConfig {
        let noise = if self.args.no_noise { NoiseModel::none() } else { NoiseModel::default() };
        SimConfig { seed: self.args.seed, dt, noise }
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
        let args: SimArgs = clap::Parser::try_parse_from(
            std::iter::once("nerve-sim --".to_owned()).chain(setup.args().iter().cloned()),
        )
        .map_err(|e| AgentError::Config(format!("simulator arguments (after `--`): {e}")))?;
        let describing = setup.world().robot().as_str().starts_with("describe-");
        let world = match &args.world {
            Some(path) => Some(World::load(path).map_err(|e| AgentError::Config(e.to_string()))?),
            None if describing => None,
            None => {
                return Err(AgentError::Config(
                    "no world: run `nerve start sim -- --world worlds/test-room.toml --dev-dir DIR`".into(),
                ));
            }
        };
        if args.dev_dir.is_none() && !describing {
            return Err(AgentError::Config(
                "no device directory: add `--dev-dir DIR` after `--` (launch files use `{state}/dev`)".into(),
            ));
        }
        if !(args.fps > 0.0 && args.fps <= 100.0) {
            return Err(AgentError::Config(format!("--fps {} must be in (0, 100]", args.fps)));
        }
        if let Some(w) = &world {
            // refuse a blocked start pose now, while `nerve start` reports errors
            Simulation::new(w.clone(), RobotModel::for_kind(args.robot_model), SimConfig::new(args.seed))
                .map_err(|e| AgentError::Config(e.to_string()))?;
        }
        let camera = if args.no_camera {
            None
        } else {
            Some(setup.ring_output("frames", RingSpec::new(8, CAMERA_FRAME_BYTES).named(&args.camera_ring))?)
        };
        let read_only = |_: &u64| Err::<(), String>("read-only: kept by the simulator".into());
        Ok(SimAgent {
            truth_out: setup.output("truth")?,
            camera,
            sim_time: setup.param_checked("sim_time", 0.0, |_: &f64| Err("read-only: kept by the simulator".into())),
            collisions: setup.param_checked("collisions", 0u64, read_only),
            args,
            world,
            sim: None,
            hub: None,
            truth_log: None,
            next_frame: 0.0,
            camera_errors: 0,
        })
    }

    fn start(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let (Some(world), Some(dev_dir)) = (self.world.clone(), self.args.dev_dir.clone()) else {
            return Err(AgentError::Config("--world and --dev-dir are required".into()));
        };
        let dt = ctx.period().map_or(0.01, |p| p.as_secs_f64());
        let sim = Simulation::new(world, RobotModel::for_kind(self.args.robot_model), self.config(dt))
            .map_err(|e| AgentError::Config(e.to_string()))?;
        self.hub = Some(DeviceHub::open(&dev_dir, &sim).map_err(|e| AgentError::Device(e.to_string()))?);
        if let Some(path) = &self.args.truth {
            self.truth_log = Some(TruthLog::create(path).map_err(|e| AgentError::Other(e.to_string()))?);
        }
        if let Some(cam) = self.camera.as_mut() {
            cam.open().map_err(|e| AgentError::Device(format!("camera ring: {e}")))?;
        }
        tracing::info!(
            world = %sim.world().name, robot = %self.args.robot_model, seed = self.args.seed,
            dev_dir = %dev_dir.display(), step_s = dt, "simulator running"
        );
        self.sim = Some(sim);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let (Some(sim), Some(hub)) = (self.sim.as_mut(), self.hub.as_mut()) else { return Ok(()) };
        if self.args.duration.is_some_and(|d| sim.time() >= d - 1e-9) {
            tracing::info!("simulated {} s: stopping", sim.time());
            ctx.request_stop();
            return Ok(());
        }
        hub.step(sim);
        let t = sim.truth();
        if let Some(log) = self.truth_log.as_mut() {
            log.write(&t).map_err(|e| AgentError::Other(e.to_string()))?;
            if sim.steps() % 100 == 0 {
                log.flush().map_err(|e| AgentError::Other(e.to_string()))?;
            }
        }
        self.sim_time.set(t.time);
        self.collisions.set(t.collisions);
        let frame_due = t.time + 1e-9 >= self.next_frame;
        self.truth_out.send(GroundTruth {
            sim_time: t.time,
            x: t.pose.x,
            y: t.pose.y,
            theta: t.pose.theta,
            v: t.v,
            omega: t.omega,
            collisions: t.collisions,
            in_contact: u8::from(t.in_contact),
            reserved: [0; 7],
            stamp_ns: ctx.now_ns(),
        })?;
        if frame_due && self.camera.is_some() {
            self.next_frame += 1.0 / self.args.fps;
            if self.next_frame < t.time {
                self.next_frame = t.time + 1.0 / self.args.fps;
            }
            self.render(ctx.now_ns());
        }
        Ok(())
    }

    fn stop(&mut self, _ctx: &mut Context) {
        if let Some(log) = self.truth_log.as_mut() {
            if let Err(e) = log.flush() {
                tracing::warn!("truth log: {e}");
            }
        }
        if let Some(hub) = self.hub.take() {
            for d in hub.devices() {
                tracing::info!(device = %d.kind(), stats = ?d.stats(), decode = ?d.decode_stats(), "device totals");
            }
        }
        if let Some(path) = self.camera.as_ref().and_then(|c| c.writer()).map(|w| w.path().to_owned()) {
            if let Err(e) = std::fs::remove_file(&path) {
                tracing::warn!("cannot remove the camera ring {}: {e}", path.display());
            }
        }
        if let Some(sim) = &self.sim {
            tracing::info!(
                steps = sim.steps(),
                sim_time = sim.time(),
                collisions = sim.collisions(),
                "simulator stopped"
            );
        }
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<SimAgent>()
}
