//! The simulation core: world, robots, fixed-step physics.
//!
//! [`Simulation`] is deterministic for a given world, models and seed: every
//! random draw of a robot comes from that robot's own ChaCha generator in a
//! fixed order (the first robot's is seeded exactly as when the simulator
//! had one robot, so single-robot runs are unchanged; robot `i` draws from
//! stream `i` of the same seed). It knows
//! nothing about pseudo-terminals or wall-clock time, so tests (and other
//! crates) drive it step by step; `crate::run` paces it in real time.
//!
//! Differential drive: each wheel follows its velocity command under an
//! acceleration limit. The encoders count the wheel's own rotation; the
//! ground moves by that travel times `(1 + bias) · (1 + slip)`, where the
//! bias is drawn once per wheel and the slip every step. Odometry from the
//! counts therefore drifts from the truth, as on the real robot.
//!
//! Collisions: a robot is a disc. A step that would make it overlap a wall,
//! a box, a checkpoint tube, an object lower than its body or another robot
//! is cut short at the contact (bisection), so it never passes through; the
//! heading still turns and the wheels still spin (and count). Each new
//! contact increments that robot's collision counter once. Robots move one
//! after the other within a step, in the order they were added.
//!
//! Several robots: [`Simulation::new`] places the first robot at the world's
//! first start; [`Simulation::add_robot`] adds the next ones at the world's
//! next `[[robot]]` starts. [`Simulation::robot`] and
//! [`Simulation::robot_mut`] give a view of one robot with the same methods
//! the simulation has for its first robot (`pose`, `command_wheels`,
//! `sonar_scan`, `render_camera`, ...).
//!
//! The gripper (H2): [`RobotMut::command_grasp`] closes the fingers; when
//! they are closed the grasp holds the nearest target tube if its axis is
//! within the arm's `grasp_tolerance` of the gripper's tip, else it missed.
//! The tube is not carried (it stays on its stand).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use nerve_devices::{
    ArmCommand, GRASP_NOTHING, GraspAction, GraspState, GripperPhase, HeadCommand, Pose2, WheelCommand, wrap_angle,
};

use crate::geom::{Segment, Vec2, ray_circle, ray_segment};
use crate::robot::{NoiseModel, RobotModel};
use crate::world::World;

/// Errors of the simulation library.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The robot's start pose overlaps an obstacle.
    #[error(
        "world {world}: the robot start ({x:.2}, {y:.2}) with radius {radius:.2} m overlaps an \
         obstacle; move [robot] in the world file"
    )]
    StartBlocked {
        /// World file.
        world: String,
        /// Start x.
        x: f64,
        /// Start y.
        y: f64,
        /// Robot radius.
        radius: f64,
    },
    /// The caller's camera buffer has the wrong size.
    #[error("camera buffer holds {got} bytes; a {width}x{height} RGB frame needs {expected}")]
    CameraBuffer {
        /// Needed bytes.
        expected: usize,
        /// Given bytes.
        got: usize,
        /// Frame width.
        width: usize,
        /// Frame height.
        height: usize,
    },
    /// The step length is not a positive finite number.
    #[error("simulation step {0} s is invalid; it must be > 0 and finite")]
    BadStep(f64),
    /// A robot was added for which the world file has no start.
    #[error(
        "world {world} has {starts} robot start(s); robot {index} ({name}) needs one more: add a \
         [[robot]] table with its x and y (use [[robot]] tables instead of [robot])"
    )]
    NoStart {
        /// World file.
        world: String,
        /// The robot's label.
        name: String,
        /// Its position among the robots, from 1.
        index: usize,
        /// How many starts the world has.
        starts: usize,
    },
}

/// How to run a simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimConfig {
    /// Seed of every random draw.
    pub seed: u64,
    /// Step length, seconds (default 0.01, i.e. 100 Hz).
    pub dt: f64,
    /// Noise levels.
    pub noise: NoiseModel,
}

impl SimConfig {
    /// 100 Hz with default noise.
    pub fn new(seed: u64) -> Self {
        Self { seed, dt: 0.01, noise: NoiseModel::default() }
    }
    /// Same, with `noise`.
    pub fn with_noise(mut self, noise: NoiseModel) -> Self {
        self.noise = noise;
        self
    }
}

/// One step's ground truth (a row of the truth log).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// Simulated time, s.
    pub time: f64,
    /// True pose.
    pub pose: Pose2,
    /// True forward speed, m/s.
    pub v: f64,
    /// True turn rate, rad/s.
    pub omega: f64,
    /// Wheel surface speeds (what the encoders see), m/s.
    pub wheel_speeds: (f64, f64),
    /// Encoder counts.
    pub encoders: (i32, i32),
    /// Collisions so far.
    pub collisions: u64,
    /// Touching an obstacle now.
    pub in_contact: bool,
    /// Head pan and tilt, radians.
    pub head: (f64, f64),
    /// Arm joints (shoulder, elbow, gripper), radians; zero without an arm.
    pub arm: [f64; 3],
    /// The gripper's phase (always open without an arm).
    pub gripper: GripperPhase,
    /// The checkpoint id of the tube held, while holding.
    pub held: Option<u8>,
}

/// Identifies one robot of a [`Simulation`]: the order in which it was
/// added (the first robot is [`RobotId::FIRST`]). An id is only meaningful
/// for the simulation that handed it out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RobotId(usize);

impl RobotId {
    /// The simulation's first robot (the one [`Simulation::new`] places).
    pub const FIRST: RobotId = RobotId(0);

    /// Position among the robots, from 0.
    pub fn index(self) -> usize {
        self.0
    }
}

/// An obstacle the robot can bump into or a sensor can see.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Shape {
    Seg(Segment),
    Circle(Vec2, f64),
}

/// A surface for sensors: shape, vertical extent, colour(s).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Surface {
    pub shape: Shape,
    pub z: [f64; 2],
    pub color: [u8; 3],
    /// Wall texture (panel seams) for walls.
    pub textured: bool,
    /// Blocks IR light (walls, boxes, robots).
    pub opaque: bool,
}

/// One robot's state.
#[derive(Debug)]
pub(crate) struct Robot {
    pub(crate) name: String,
    pub(crate) model: RobotModel,
    pub(crate) rng: ChaCha8Rng,
    pub(crate) pose: Pose2,
    wheel_cmd: (f64, f64),
    wheel_vel: (f64, f64),
    wheel_bias: (f64, f64),
    enc: (f64, f64),
    v: f64,
    omega: f64,
    pub(crate) head: (f64, f64),
    head_cmd: (f64, f64),
    arm: [f64; 3],
    arm_cmd: [f64; 3],
    gripper: GripperPhase,
    held: Option<u8>,
    collisions: u64,
    in_contact: bool,
}

/// The simulated world with its robots in it.
#[derive(Debug)]
pub struct Simulation {
    pub(crate) world: World,
    pub(crate) cfg: SimConfig,
    steps: u64,
    pub(crate) object_pos: Vec<Vec2>,
    pub(crate) robots: Vec<Robot>,
}

pub(crate) fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

fn approach(x: f64, target: f64, max_step: f64) -> f64 {
    x + (target - x).clamp(-max_step, max_step)
}

/// Below this gripper angle the fingers count as closed, radians.
const GRIPPER_CLOSED: f64 = 1e-3;

impl Simulation {
    /// A simulation of `model` at the world's (first) start pose.
    pub fn new(world: World, model: RobotModel, cfg: SimConfig) -> Result<Self, SimError> {
        if !(cfg.dt > 0.0 && cfg.dt.is_finite()) {
            return Err(SimError::BadStep(cfg.dt));
        }
        let object_pos = world.objects.iter().map(|o| o.position_at(0.0)).collect();
        let mut sim = Self { world, cfg, steps: 0, object_pos, robots: Vec::new() };
        sim.add_robot("robot 1", model)?;
        Ok(sim)
    }

    /// Adds a robot at the world's next start (the world file's `[[robot]]`
    /// tables, in order), with its own noise stream. `name` labels it in
    /// logs and errors.
    pub fn add_robot(&mut self, name: &str, model: RobotModel) -> Result<RobotId, SimError> {
        let i = self.robots.len();
        let Some(start) = self.world.robots.get(i).cloned() else {
            return Err(SimError::NoStart {
                world: self.world.source.display().to_string(),
                name: name.to_owned(),
                index: i + 1,
                starts: self.world.robots.len(),
            });
        };
        self.add_robot_at(name, model, start.pose, start.wheel_bias)
    }

    /// Adds a robot at `pose` (not a start of the world file), with an
    /// optional fixed wheel bias `[left, right]`.
    pub fn add_robot_at(
        &mut self,
        name: &str,
        model: RobotModel,
        pose: Pose2,
        wheel_bias: Option<[f64; 2]>,
    ) -> Result<RobotId, SimError> {
        let i = self.robots.len();
        let mut rng = ChaCha8Rng::seed_from_u64(self.cfg.seed);
        if i > 0 {
            rng.set_stream(i as u64);
        }
        // always drawn, so the rest of this robot's stream does not depend
        // on whether the world fixes the bias
        let drawn = (gauss(&mut rng) * self.cfg.noise.wheel_bias_sd, gauss(&mut rng) * self.cfg.noise.wheel_bias_sd);
        let wheel_bias = match wheel_bias {
            Some([l, r]) if self.cfg.noise != NoiseModel::none() => (l, r),
            _ => drawn,
        };
        let robot = Robot {
            name: name.to_owned(),
            model,
            rng,
            pose,
            wheel_cmd: (0.0, 0.0),
            wheel_vel: (0.0, 0.0),
            wheel_bias,
            enc: (0.0, 0.0),
            v: 0.0,
            omega: 0.0,
            head: (0.0, 0.0),
            head_cmd: (0.0, 0.0),
            arm: [0.0; 3],
            arm_cmd: [0.0; 3],
            gripper: GripperPhase::Open,
            held: None,
            collisions: 0,
            in_contact: false,
        };
        let p = Vec2::new(pose.x, pose.y);
        let radius = robot.model.radius;
        if self.clearance_with(i, robot.model.body_height, p) < radius || self.inside_box(p) {
            return Err(SimError::StartBlocked {
                world: self.world.source.display().to_string(),
                x: pose.x,
                y: pose.y,
                radius,
            });
        }
        self.robots.push(robot);
        tracing::debug!(robot = name, x = pose.x, y = pose.y, "robot placed");
        Ok(RobotId(i))
    }

    /// How many robots there are.
    pub fn robot_count(&self) -> usize {
        self.robots.len()
    }

    /// Every robot's id, in order.
    pub fn robot_ids(&self) -> impl Iterator<Item = RobotId> + use<> {
        (0..self.robots.len()).map(RobotId)
    }

    /// A view of robot `id`.
    ///
    /// # Panics
    /// If `id` was handed out by another simulation with more robots.
    pub fn robot(&self, id: RobotId) -> RobotRef<'_> {
        assert!(id.0 < self.robots.len(), "robot id {} of another simulation", id.0);
        RobotRef { sim: self, i: id.0 }
    }

    /// A view of robot `id` that commands it and reads its noisy sensors.
    ///
    /// # Panics
    /// If `id` was handed out by another simulation with more robots.
    pub fn robot_mut(&mut self, id: RobotId) -> RobotMut<'_> {
        assert!(id.0 < self.robots.len(), "robot id {} of another simulation", id.0);
        RobotMut { sim: self, i: id.0 }
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
    }
    /// The first robot's model.
    pub fn model(&self) -> &RobotModel {
        &self.robots[0].model
    }
    /// Step length, s.
    pub fn dt(&self) -> f64 {
        self.cfg.dt
    }
    /// Simulated time, s.
    pub fn time(&self) -> f64 {
        self.steps as f64 * self.cfg.dt
    }
    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }
    /// The first robot's true pose.
    pub fn pose(&self) -> Pose2 {
        self.robots[0].pose
    }
    /// Puts the first robot somewhere (tests, scenario set-up). No collision check.
    pub fn set_pose(&mut self, pose: Pose2) {
        self.robots[0].pose = pose;
    }
    /// The first robot's collisions so far (each new contact counts once).
    pub fn collisions(&self) -> u64 {
        self.robots[0].collisions
    }
    /// Whether the first robot touches an obstacle now.
    pub fn in_contact(&self) -> bool {
        self.robots[0].in_contact
    }
    /// Where each world object is now, in world-file order.
    pub fn object_positions(&self) -> &[Vec2] {
        &self.object_pos
    }

    /// Sets the first robot's wheel velocity set-point (clamped to the
    /// motors' top speed).
    pub fn command_wheels(&mut self, cmd: &WheelCommand) {
        self.robot_mut(RobotId::FIRST).command_wheels(cmd);
    }

    /// Sets the first robot's pan-tilt set-point (clamped to the head's
    /// range). Ignored by a robot without a head.
    pub fn command_head(&mut self, cmd: &HeadCommand) {
        self.robot_mut(RobotId::FIRST).command_head(cmd);
    }

    /// Sets the first robot's arm joint set-points (clamped). Ignored
    /// without an arm.
    pub fn command_arm(&mut self, cmd: &ArmCommand) {
        self.robot_mut(RobotId::FIRST).command_arm(cmd);
    }

    /// The first robot's cumulative encoder counts (wrapping like the
    /// board's 32-bit counters).
    pub fn encoder_counts(&self) -> (i32, i32) {
        self.robot(RobotId::FIRST).encoder_counts()
    }

    /// The first robot's head pan and tilt, radians.
    pub fn head_position(&self) -> (f64, f64) {
        self.robots[0].head
    }

    /// The first robot's arm joint positions, radians.
    pub fn arm_position(&self) -> [f64; 3] {
        self.robots[0].arm
    }

    /// This step's ground truth of the first robot.
    pub fn truth(&self) -> Truth {
        self.robot(RobotId::FIRST).truth()
    }

    /// Advances the world by one step: objects, then each robot in turn.
    pub fn step(&mut self) {
        self.steps += 1;
        let t = self.time();
        for (i, o) in self.world.objects.iter().enumerate() {
            self.object_pos[i] = o.position_at(t);
        }
        for i in 0..self.robots.len() {
            self.step_robot(i, t);
        }
    }

    fn step_robot(&mut self, i: usize, t: f64) {
        let dt = self.cfg.dt;
        let slip = self.cfg.noise.slip_sd;
        let r = &mut self.robots[i];

        // Actuators: wheels, head, arm.
        let dv = r.model.max_wheel_accel * dt;
        r.wheel_vel = (approach(r.wheel_vel.0, r.wheel_cmd.0, dv), approach(r.wheel_vel.1, r.wheel_cmd.1, dv));
        if let Some(h) = r.model.head {
            r.head = (approach(r.head.0, r.head_cmd.0, h.speed * dt), approach(r.head.1, r.head_cmd.1, h.speed * dt));
        }
        if let Some(a) = r.model.arm {
            for j in 0..3 {
                r.arm[j] = approach(r.arm[j], r.arm_cmd[j], a.speed * dt);
            }
        }

        // Wheel travel as counted, and as done on the ground.
        let (wl, wr) = (r.wheel_vel.0 * dt, r.wheel_vel.1 * dt);
        r.enc.0 += wl;
        r.enc.1 += wr;
        let gl = wl * (1.0 + r.wheel_bias.0) * (1.0 + slip * gauss(&mut r.rng));
        let gr = wr * (1.0 + r.wheel_bias.1) * (1.0 + slip * gauss(&mut r.rng));
        let base = r.model.geometry.wheel_base_mm / 1000.0;
        let ds = 0.5 * (gl + gr);
        let dth = (gr - gl) / base;
        let pose = r.pose;
        let radius = r.model.radius;
        let mid = pose.theta + 0.5 * dth;
        let from = Vec2::new(pose.x, pose.y);
        let to = from + Vec2::from_angle(mid) * ds;

        // Collision: move as far as possible towards `to`.
        let c0 = self.clearance_for(i, from);
        let ok = |p: Vec2, s: &Self| {
            let c = s.clearance_for(i, p);
            c >= radius || (c >= c0 - 1e-12 && c0 < radius)
        };
        let mut blocked = false;
        let reached = if ds == 0.0 || ok(to, self) {
            to
        } else {
            blocked = true;
            let (mut lo, mut hi) = (0.0f64, 1.0f64);
            for _ in 0..20 {
                let m = 0.5 * (lo + hi);
                if ok(from + (to - from) * m, self) {
                    lo = m;
                } else {
                    hi = m;
                }
            }
            from + (to - from) * lo
        };
        let contact = blocked || self.clearance_for(i, reached) < radius + 1e-3;
        let r = &mut self.robots[i];
        r.pose = Pose2 { x: reached.x, y: reached.y, theta: wrap_angle(pose.theta + dth) };
        r.v = reached.dist(from) / dt * ds.signum();
        r.omega = dth / dt;
        if contact && !r.in_contact {
            r.collisions += 1;
            tracing::debug!(t, robot = %r.name, x = reached.x, y = reached.y, "collision");
        }
        r.in_contact = contact;

        // The gripper: a closing grasp is decided when the fingers meet;
        // opening the fingers (an arm command) lets go.
        if r.model.arm.is_some() {
            match r.gripper {
                GripperPhase::Closing if r.arm[2] <= GRIPPER_CLOSED => {
                    let grasped = self.robot(RobotId(i)).graspable().filter(|g| g.within_reach).map(|g| g.id);
                    let r = &mut self.robots[i];
                    r.held = grasped;
                    r.gripper = if grasped.is_some() { GripperPhase::Holding } else { GripperPhase::Missed };
                    tracing::info!(t, robot = %r.name, held = ?grasped, "gripper closed");
                }
                GripperPhase::Holding | GripperPhase::Missed if r.arm[2] > GRIPPER_CLOSED => {
                    r.gripper = GripperPhase::Open;
                    r.held = None;
                }
                _ => {}
            }
        }
    }

    /// Everything solid at floor level, for collisions, except robots.
    pub(crate) fn solid_shapes(&self, body_height: f64) -> impl Iterator<Item = Shape> + '_ {
        let walls = self.world.walls.iter().map(|w| Shape::Seg(w.seg));
        let boxes = self.world.boxes.iter().flat_map(|b| b.edges.iter().map(|e| Shape::Seg(*e)));
        let tubes = self.world.checkpoints.iter().map(|c| Shape::Circle(c.position, c.radius));
        let objects = self
            .world
            .objects
            .iter()
            .zip(&self.object_pos)
            .filter(move |(o, _)| o.z[0] < body_height)
            .map(|(o, p)| Shape::Circle(*p, o.radius));
        walls.chain(boxes).chain(tubes).chain(objects)
    }

    /// Distance from `p` to the nearest solid thing robot `i` can bump
    /// into (including the other robots' bodies, but not its own).
    pub(crate) fn clearance_for(&self, i: usize, p: Vec2) -> f64 {
        let body = self.robots.get(i).map_or(f64::INFINITY, |r| r.model.body_height);
        self.clearance_with(i, body, p)
    }

    /// [`Self::clearance_for`] for a body `body_height` high; for a robot
    /// not added yet (`i` = the robot count), every robot counts.
    fn clearance_with(&self, i: usize, body: f64, p: Vec2) -> f64 {
        let world = self
            .solid_shapes(body)
            .map(|s| match s {
                Shape::Seg(seg) => seg.distance_to(p),
                Shape::Circle(c, r) => c.dist(p) - r,
            })
            .fold(f64::INFINITY, f64::min);
        self.robots
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, o)| Vec2::new(o.pose.x, o.pose.y).dist(p) - o.model.radius)
            .fold(world, f64::min)
    }

    fn inside_box(&self, p: Vec2) -> bool {
        self.world.boxes.iter().any(|b| b.edges.iter().all(|e| (e.b - e.a).cross(p - e.a) >= 0.0))
    }

    /// Every surface sensors can see, with the objects where they are now
    /// and every robot's body but the viewer's (`viewer`: a robot index).
    pub(crate) fn surfaces(&self, viewer: Option<usize>) -> Vec<Surface> {
        let mut out = Vec::new();
        for w in &self.world.walls {
            out.push(Surface {
                shape: Shape::Seg(w.seg),
                z: [0.0, w.height],
                color: w.color,
                textured: true,
                opaque: true,
            });
        }
        for b in &self.world.boxes {
            for e in &b.edges {
                out.push(Surface {
                    shape: Shape::Seg(*e),
                    z: [0.0, b.height],
                    color: b.color,
                    textured: false,
                    opaque: true,
                });
            }
        }
        for c in &self.world.checkpoints {
            let mid = 0.5 * (c.z[0] + c.z[1]);
            let shape = Shape::Circle(c.position, c.radius);
            // the stand the tube sits on: as wide as the tube (the disc that
            // collisions use), so that the sonar sees what the robot would hit
            out.push(Surface {
                shape: Shape::Circle(c.position, c.radius),
                z: [0.0, c.z[0]],
                color: [90, 90, 90],
                textured: false,
                opaque: false,
            });
            out.push(Surface { shape, z: [c.z[0], mid], color: c.lower_color, textured: false, opaque: false });
            out.push(Surface { shape, z: [mid, c.z[1]], color: c.upper_color, textured: false, opaque: false });
        }
        for (o, p) in self.world.objects.iter().zip(&self.object_pos) {
            out.push(Surface {
                shape: Shape::Circle(*p, o.radius),
                z: o.z,
                color: o.color,
                textured: false,
                opaque: false,
            });
        }
        for (j, r) in self.robots.iter().enumerate() {
            if Some(j) == viewer {
                continue;
            }
            out.push(Surface {
                shape: Shape::Circle(Vec2::new(r.pose.x, r.pose.y), r.model.radius),
                z: [0.0, r.model.body_height],
                color: r.model.body_color,
                textured: false,
                opaque: true,
            });
        }
        out
    }
}

/// A graspable tube (a target) as the gripper sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Graspable {
    /// The tube's checkpoint id.
    pub id: u8,
    /// Distance from the gripper's tip to the tube's axis, metres.
    pub distance: f64,
    /// Whether closing the gripper now would hold it.
    pub within_reach: bool,
}

/// A read-only view of one robot of a [`Simulation`].
#[derive(Debug, Clone, Copy)]
pub struct RobotRef<'a> {
    pub(crate) sim: &'a Simulation,
    pub(crate) i: usize,
}

impl<'a> RobotRef<'a> {
    pub(crate) fn r(&self) -> &'a Robot {
        &self.sim.robots[self.i]
    }
    /// Its id.
    pub fn id(&self) -> RobotId {
        RobotId(self.i)
    }
    /// Its label.
    pub fn name(&self) -> &'a str {
        &self.r().name
    }
    /// Its model.
    pub fn model(&self) -> &'a RobotModel {
        &self.r().model
    }
    /// True pose.
    pub fn pose(&self) -> Pose2 {
        self.r().pose
    }
    /// Collisions so far (each new contact counts once).
    pub fn collisions(&self) -> u64 {
        self.r().collisions
    }
    /// Whether it touches an obstacle now.
    pub fn in_contact(&self) -> bool {
        self.r().in_contact
    }
    /// The wheel bias in effect, `(left, right)`, relative.
    pub fn wheel_bias(&self) -> (f64, f64) {
        self.r().wheel_bias
    }
    /// Cumulative encoder counts (wrapping like the board's 32-bit counters).
    pub fn encoder_counts(&self) -> (i32, i32) {
        let r = self.r();
        let k = 1000.0 / r.model.geometry.mm_per_count();
        // `as i64 as i32` wraps like the board's counter.
        ((r.enc.0 * k).round() as i64 as i32, (r.enc.1 * k).round() as i64 as i32)
    }
    /// Head pan and tilt, radians.
    pub fn head_position(&self) -> (f64, f64) {
        self.r().head
    }
    /// Arm joint positions, radians.
    pub fn arm_position(&self) -> [f64; 3] {
        self.r().arm
    }
    /// The gripper's phase and the id of the tube held.
    pub fn gripper(&self) -> (GripperPhase, Option<u8>) {
        (self.r().gripper, self.r().held)
    }
    /// Where the gripper's tip is in the world, if the robot has an arm.
    pub fn gripper_tip(&self) -> Option<Vec2> {
        let r = self.r();
        let arm = r.model.arm?;
        let (x, y) = arm.tip(r.arm);
        let (s, c) = r.pose.theta.sin_cos();
        Some(Vec2::new(r.pose.x + c * x - s * y, r.pose.y + s * x + c * y))
    }
    /// The target tube nearest to the gripper's tip, if the robot has an
    /// arm and the world a target.
    pub fn graspable(&self) -> Option<Graspable> {
        let tip = self.gripper_tip()?;
        let tol = self.r().model.arm?.grasp_tolerance;
        self.sim
            .world
            .checkpoints
            .iter()
            .filter(|c| c.target)
            .map(|c| (c.id, c.position.dist(tip)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(id, distance)| Graspable { id, distance, within_reach: distance <= tol })
    }
    /// The gripper's report as the arm controller sends it, with sequence
    /// number `seq`.
    pub fn grasp_state(&self, seq: u16) -> GraspState {
        let (phase, held) = self.gripper();
        let nearest_mm = self.graspable().map_or(u16::MAX, |g| (g.distance * 1000.0).round().min(65535.0) as u16);
        GraspState { seq, phase, held_id: held.unwrap_or(GRASP_NOTHING), nearest_mm }
    }
    /// This step's ground truth.
    pub fn truth(&self) -> Truth {
        let r = self.r();
        Truth {
            time: self.sim.time(),
            pose: r.pose,
            v: r.v,
            omega: r.omega,
            wheel_speeds: r.wheel_vel,
            encoders: self.encoder_counts(),
            collisions: r.collisions,
            in_contact: r.in_contact,
            head: r.head,
            arm: r.arm,
            gripper: r.gripper,
            held: r.held,
        }
    }
}

/// A view of one robot of a [`Simulation`] that commands it and reads its
/// noisy sensors (which draw from its noise stream).
#[derive(Debug)]
pub struct RobotMut<'a> {
    pub(crate) sim: &'a mut Simulation,
    pub(crate) i: usize,
}

impl RobotMut<'_> {
    pub(crate) fn r(&mut self) -> &mut Robot {
        &mut self.sim.robots[self.i]
    }
    /// The read-only view.
    pub fn as_ref(&self) -> RobotRef<'_> {
        RobotRef { sim: self.sim, i: self.i }
    }
    /// Puts the robot somewhere (tests, scenario set-up). No collision check.
    pub fn set_pose(&mut self, pose: Pose2) {
        self.r().pose = pose;
    }
    /// Sets the wheel velocity set-point (clamped to the motors' top speed).
    pub fn command_wheels(&mut self, cmd: &WheelCommand) {
        let r = self.r();
        let max = r.model.max_wheel_speed;
        r.wheel_cmd = (
            (f64::from(cmd.left_mm_s) / 1000.0).clamp(-max, max),
            (f64::from(cmd.right_mm_s) / 1000.0).clamp(-max, max),
        );
    }
    /// Sets the pan-tilt set-point (clamped to the head's range). Ignored by
    /// a robot without a head.
    pub fn command_head(&mut self, cmd: &HeadCommand) {
        let r = self.r();
        if let Some(h) = r.model.head {
            r.head_cmd = (
                (f64::from(cmd.pan_cdeg) / 100.0).to_radians().clamp(-h.pan_limit, h.pan_limit),
                (f64::from(cmd.tilt_cdeg) / 100.0).to_radians().clamp(h.tilt_min, h.tilt_max),
            );
        }
    }
    /// Sets the arm joint set-points (clamped). Ignored without an arm.
    /// Opening the gripper during a grasp abandons it.
    pub fn command_arm(&mut self, cmd: &ArmCommand) {
        let r = self.r();
        if let Some(a) = r.model.arm {
            for j in 0..3 {
                let (lo, hi) = a.limits[j];
                r.arm_cmd[j] = (f64::from(cmd.joints_cdeg[j]) / 100.0).to_radians().clamp(lo, hi);
            }
            if r.gripper == GripperPhase::Closing && r.arm_cmd[2] > GRIPPER_CLOSED {
                r.gripper = GripperPhase::Open;
            }
        }
    }
    /// Grasp (close the fingers; the outcome is decided when they meet) or
    /// release (open them fully). Ignored without an arm.
    pub fn command_grasp(&mut self, action: GraspAction) {
        let r = self.r();
        let Some(a) = r.model.arm else { return };
        match action {
            GraspAction::Grasp => {
                r.arm_cmd[2] = 0.0;
                r.gripper = GripperPhase::Closing;
                r.held = None;
            }
            GraspAction::Release => {
                r.arm_cmd[2] = a.limits[2].1;
                r.gripper = GripperPhase::Open;
                r.held = None;
            }
        }
    }
}

/// A ray hit on a surface.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hit {
    pub dist: f64,
    /// Unit normal of the surface at the hit.
    pub normal: Vec2,
    /// Metres along a segment (texture coordinate); 0 for circles.
    pub u: f64,
}

pub(crate) fn ray_hit(origin: Vec2, dir: Vec2, shape: &Shape) -> Option<Hit> {
    match shape {
        Shape::Seg(s) => ray_segment(origin, dir, s).map(|(t, u)| Hit { dist: t, normal: s.normal(), u }),
        Shape::Circle(c, r) => ray_circle(origin, dir, *c, *r).map(|t| {
            let p = origin + dir * t;
            let n = p - *c;
            Hit { dist: t, normal: n * (1.0 / n.norm().max(1e-12)), u: 0.0 }
        }),
    }
}
