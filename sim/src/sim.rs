//! The simulation core: world, robot state, fixed-step physics.
//!
//! [`Simulation`] is deterministic for a given world, model and seed: every
//! random draw comes from one ChaCha generator in a fixed order. It knows
//! nothing about pseudo-terminals or wall-clock time, so tests (and other
//! crates) drive it step by step; `crate::run` paces it in real time.
//!
//! Differential drive: each wheel follows its velocity command under an
//! acceleration limit. The encoders count the wheel's own rotation; the
//! ground moves by that travel times `(1 + bias) · (1 + slip)`, where the
//! bias is drawn once per wheel and the slip every step. Odometry from the
//! counts therefore drifts from the truth, as on the real robot.
//!
//! Collisions: the robot is a disc. A step that would make it overlap a wall,
//! a box, a checkpoint tube or an object lower than its body is cut short at
//! the contact (bisection), so it never passes through; the heading still
//! turns and the wheels still spin (and count). Each new contact increments
//! the collision counter once.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use nerve_devices::{ArmCommand, HeadCommand, Pose2, WheelCommand, wrap_angle};

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
    /// Blocks IR light (walls, boxes).
    pub opaque: bool,
}

/// The simulated world with one robot in it.
#[derive(Debug)]
pub struct Simulation {
    pub(crate) world: World,
    pub(crate) model: RobotModel,
    pub(crate) cfg: SimConfig,
    pub(crate) rng: ChaCha8Rng,
    steps: u64,
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
    collisions: u64,
    in_contact: bool,
    pub(crate) object_pos: Vec<Vec2>,
}

pub(crate) fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

fn approach(x: f64, target: f64, max_step: f64) -> f64 {
    x + (target - x).clamp(-max_step, max_step)
}

impl Simulation {
    /// A simulation of `model` at the world's start pose.
    pub fn new(world: World, model: RobotModel, cfg: SimConfig) -> Result<Self, SimError> {
        if !(cfg.dt > 0.0 && cfg.dt.is_finite()) {
            return Err(SimError::BadStep(cfg.dt));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        let wheel_bias = (gauss(&mut rng) * cfg.noise.wheel_bias_sd, gauss(&mut rng) * cfg.noise.wheel_bias_sd);
        let object_pos = world.objects.iter().map(|o| o.position_at(0.0)).collect();
        let pose = world.start;
        let sim = Self {
            world,
            model,
            cfg,
            rng,
            steps: 0,
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
            collisions: 0,
            in_contact: false,
            object_pos,
        };
        let p = Vec2::new(pose.x, pose.y);
        if sim.clearance(p) < sim.model.radius || sim.inside_box(p) {
            return Err(SimError::StartBlocked {
                world: sim.world.source.display().to_string(),
                x: pose.x,
                y: pose.y,
                radius: sim.model.radius,
            });
        }
        Ok(sim)
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
    }
    /// The robot model.
    pub fn model(&self) -> &RobotModel {
        &self.model
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
    /// True pose.
    pub fn pose(&self) -> Pose2 {
        self.pose
    }
    /// Puts the robot somewhere (tests, scenario set-up). No collision check.
    pub fn set_pose(&mut self, pose: Pose2) {
        self.pose = pose;
    }
    /// Collisions so far (each new contact counts once).
    pub fn collisions(&self) -> u64 {
        self.collisions
    }
    /// Whether the robot touches an obstacle now.
    pub fn in_contact(&self) -> bool {
        self.in_contact
    }
    /// Where each world object is now, in world-file order.
    pub fn object_positions(&self) -> &[Vec2] {
        &self.object_pos
    }

    /// Sets the wheel velocity set-point (clamped to the motors' top speed).
    pub fn command_wheels(&mut self, cmd: &WheelCommand) {
        let max = self.model.max_wheel_speed;
        self.wheel_cmd = (
            (f64::from(cmd.left_mm_s) / 1000.0).clamp(-max, max),
            (f64::from(cmd.right_mm_s) / 1000.0).clamp(-max, max),
        );
    }

    /// Sets the pan-tilt set-point (clamped to the head's range). Ignored by
    /// a robot without a head.
    pub fn command_head(&mut self, cmd: &HeadCommand) {
        if let Some(h) = self.model.head {
            self.head_cmd = (
                (f64::from(cmd.pan_cdeg) / 100.0).to_radians().clamp(-h.pan_limit, h.pan_limit),
                (f64::from(cmd.tilt_cdeg) / 100.0).to_radians().clamp(h.tilt_min, h.tilt_max),
            );
        }
    }

    /// Sets the arm joint set-points (clamped). Ignored without an arm.
    pub fn command_arm(&mut self, cmd: &ArmCommand) {
        if let Some(a) = self.model.arm {
            for i in 0..3 {
                let (lo, hi) = a.limits[i];
                self.arm_cmd[i] = (f64::from(cmd.joints_cdeg[i]) / 100.0).to_radians().clamp(lo, hi);
            }
        }
    }

    /// Cumulative encoder counts (wrapping like the board's 32-bit counters).
    pub fn encoder_counts(&self) -> (i32, i32) {
        let k = 1000.0 / self.model.geometry.mm_per_count();
        // `as i64 as i32` wraps like the board's counter.
        ((self.enc.0 * k).round() as i64 as i32, (self.enc.1 * k).round() as i64 as i32)
    }

    /// Head pan and tilt, radians.
    pub fn head_position(&self) -> (f64, f64) {
        self.head
    }

    /// Arm joint positions, radians.
    pub fn arm_position(&self) -> [f64; 3] {
        self.arm
    }

    /// This step's ground truth.
    pub fn truth(&self) -> Truth {
        Truth {
            time: self.time(),
            pose: self.pose,
            v: self.v,
            omega: self.omega,
            wheel_speeds: self.wheel_vel,
            encoders: self.encoder_counts(),
            collisions: self.collisions,
            in_contact: self.in_contact,
            head: self.head,
        }
    }

    /// Advances the world by one step.
    pub fn step(&mut self) {
        let dt = self.cfg.dt;
        self.steps += 1;
        let t = self.time();
        for (i, o) in self.world.objects.iter().enumerate() {
            self.object_pos[i] = o.position_at(t);
        }

        // Actuators: wheels, head, arm.
        let dv = self.model.max_wheel_accel * dt;
        self.wheel_vel =
            (approach(self.wheel_vel.0, self.wheel_cmd.0, dv), approach(self.wheel_vel.1, self.wheel_cmd.1, dv));
        if let Some(h) = self.model.head {
            self.head = (
                approach(self.head.0, self.head_cmd.0, h.speed * dt),
                approach(self.head.1, self.head_cmd.1, h.speed * dt),
            );
        }
        if let Some(a) = self.model.arm {
            for i in 0..3 {
                self.arm[i] = approach(self.arm[i], self.arm_cmd[i], a.speed * dt);
            }
        }

        // Wheel travel as counted, and as done on the ground.
        let (wl, wr) = (self.wheel_vel.0 * dt, self.wheel_vel.1 * dt);
        self.enc.0 += wl;
        self.enc.1 += wr;
        let slip = self.cfg.noise.slip_sd;
        let gl = wl * (1.0 + self.wheel_bias.0) * (1.0 + slip * gauss(&mut self.rng));
        let gr = wr * (1.0 + self.wheel_bias.1) * (1.0 + slip * gauss(&mut self.rng));
        let base = self.model.geometry.wheel_base_mm / 1000.0;
        let ds = 0.5 * (gl + gr);
        let dth = (gr - gl) / base;
        let mid = self.pose.theta + 0.5 * dth;
        let from = Vec2::new(self.pose.x, self.pose.y);
        let to = from + Vec2::from_angle(mid) * ds;

        // Collision: move as far as possible towards `to`.
        let r = self.model.radius;
        let c0 = self.clearance(from);
        let ok = |p: Vec2, s: &Self| {
            let c = s.clearance(p);
            c >= r || (c >= c0 - 1e-12 && c0 < r)
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
        self.pose = Pose2 { x: reached.x, y: reached.y, theta: wrap_angle(self.pose.theta + dth) };
        self.v = reached.dist(from) / dt * ds.signum();
        self.omega = dth / dt;

        let contact = blocked || self.clearance(reached) < r + 1e-3;
        if contact && !self.in_contact {
            self.collisions += 1;
            tracing::debug!(t, x = reached.x, y = reached.y, "collision");
        }
        self.in_contact = contact;
    }

    /// Everything solid at floor level, for collisions.
    pub(crate) fn solid_shapes(&self) -> impl Iterator<Item = Shape> + '_ {
        let walls = self.world.walls.iter().map(|w| Shape::Seg(w.seg));
        let boxes = self.world.boxes.iter().flat_map(|b| b.edges.iter().map(|e| Shape::Seg(*e)));
        let tubes = self.world.checkpoints.iter().map(|c| Shape::Circle(c.position, c.radius));
        let body = self.model.body_height;
        let objects = self
            .world
            .objects
            .iter()
            .zip(&self.object_pos)
            .filter(move |(o, _)| o.z[0] < body)
            .map(|(o, p)| Shape::Circle(*p, o.radius));
        walls.chain(boxes).chain(tubes).chain(objects)
    }

    /// Distance from `p` to the nearest solid thing.
    pub(crate) fn clearance(&self, p: Vec2) -> f64 {
        self.solid_shapes()
            .map(|s| match s {
                Shape::Seg(seg) => seg.distance_to(p),
                Shape::Circle(c, r) => c.dist(p) - r,
            })
            .fold(f64::INFINITY, f64::min)
    }

    fn inside_box(&self, p: Vec2) -> bool {
        self.world.boxes.iter().any(|b| b.edges.iter().all(|e| (e.b - e.a).cross(p - e.a) >= 0.0))
    }

    /// Every surface sensors can see, with the objects where they are now.
    pub(crate) fn surfaces(&self) -> Vec<Surface> {
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
            // the stand the tube sits on
            out.push(Surface {
                shape: Shape::Circle(c.position, c.radius * 0.4),
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
        out
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
