//! The simulated robots of the thesis (section 4.1) and the noise model.
//!
//! * **H1**: two driven wheels, a ring of 12 sonars (4 Hz), a webcam on a
//!   pan-tilt head, an IR receiver.
//! * **H2**: two driven wheels, a fixed webcam, an IR receiver, a 3-DOF arm;
//!   no sonar.
//!
//! Both are discs for collisions (and for each other's sensors: a robot
//! is a cylinder of its radius and body height, in its body colour). Dimensions are plausible for the thesis'
//! platforms, not measured: they are constants here so that every consumer
//! (simulator, agents, tests) agrees.

use std::fmt;
use std::str::FromStr;

use nerve_devices::DiffDriveGeometry;

/// Which robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RobotKind {
    /// The explorer: sonar ring, pan-tilt webcam, IR.
    H1,
    /// The grasper: arm, fixed webcam, IR, no sonar.
    H2,
}

impl FromStr for RobotKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "h1" => Ok(Self::H1),
            "h2" => Ok(Self::H2),
            _ => Err(format!("unknown robot model {s:?}; expected h1 or h2")),
        }
    }
}

impl fmt::Display for RobotKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::H1 => "h1",
            Self::H2 => "h2",
        })
    }
}

/// The sonar ring.
#[derive(Debug, Clone, PartialEq)]
pub struct SonarSpec {
    /// Mounting angle of each sonar relative to forward, radians.
    pub angles: Vec<f64>,
    /// Height of the transducers, metres.
    pub height: f64,
    /// Shortest measurable range, metres (closer reads as this).
    pub min_range: f64,
    /// Longest range, metres (farther reads as no echo).
    pub max_range: f64,
    /// Half-width of the beam, radians.
    pub half_beam: f64,
}

/// The pan-tilt head.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadSpec {
    /// Pan range ±, radians.
    pub pan_limit: f64,
    /// Lowest tilt, radians (negative looks down).
    pub tilt_min: f64,
    /// Highest tilt, radians.
    pub tilt_max: f64,
    /// Slew rate of either axis, rad/s.
    pub speed: f64,
}

/// The arm: a shoulder and an elbow that swing in the horizontal plane,
/// and a gripper (joint 2: 0 = closed, the upper limit = open).
///
/// Seen from above, the shoulder sits `base` metres ahead of the robot's
/// centre; the upper arm (`links[0]`) turns by the shoulder angle from the
/// robot's forward axis, the forearm (`links[1]`) by the elbow angle from
/// the upper arm. The gripper's tip is the end of the forearm. A grasp
/// holds a target tube when the tube's axis is within `grasp_tolerance` of
/// the tip as the fingers close.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmSpec {
    /// Joint limits (min, max), radians.
    pub limits: [(f64, f64); 3],
    /// Joint speed, rad/s.
    pub speed: f64,
    /// Shoulder position ahead of the robot's centre, metres.
    pub base: f64,
    /// Upper arm and forearm lengths, metres.
    pub links: [f64; 2],
    /// Largest distance from the tip to a tube's axis that still grasps it, metres.
    pub grasp_tolerance: f64,
}

impl ArmSpec {
    /// Where the gripper's tip is, in the robot's frame (x forward, y left),
    /// for joint angles `joints` (radians).
    pub fn tip(&self, joints: [f64; 3]) -> (f64, f64) {
        let (a, b) = (joints[0], joints[0] + joints[1]);
        (
            self.base + self.links[0] * a.cos() + self.links[1] * b.cos(),
            self.links[0] * a.sin() + self.links[1] * b.sin(),
        )
    }
}

/// Everything the simulator needs to know about a robot.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotModel {
    /// Which robot.
    pub kind: RobotKind,
    /// Collision disc radius, metres.
    pub radius: f64,
    /// Height of the body, metres (objects above it are not bumped into).
    pub body_height: f64,
    /// Wheels and encoders.
    pub geometry: DiffDriveGeometry,
    /// Top wheel speed, m/s.
    pub max_wheel_speed: f64,
    /// Wheel acceleration limit, m/s².
    pub max_wheel_accel: f64,
    /// Sonar ring, if fitted.
    pub sonar: Option<SonarSpec>,
    /// Pan-tilt head, if fitted (otherwise the camera is fixed forward).
    pub head: Option<HeadSpec>,
    /// Arm, if fitted.
    pub arm: Option<ArmSpec>,
    /// Colour of the body, as other robots' cameras see it.
    pub body_color: [u8; 3],
    /// Camera height above the floor, metres.
    pub camera_height: f64,
    /// Camera horizontal field of view, radians.
    pub camera_hfov: f64,
    /// IR receiver range, metres.
    pub ir_range: f64,
    /// Half-angle of each IR transmitter's emission cone, radians.
    pub ir_half_angle: f64,
}

impl RobotModel {
    /// H1.
    pub fn h1() -> Self {
        Self {
            kind: RobotKind::H1,
            radius: 0.25,
            body_height: 0.6,
            geometry: DiffDriveGeometry::H1,
            max_wheel_speed: 0.8,
            max_wheel_accel: 1.0,
            sonar: Some(SonarSpec {
                angles: (0..12).map(|i| f64::from(i) * 30f64.to_radians()).collect(),
                height: 0.3,
                min_range: 0.15,
                max_range: 5.0,
                half_beam: 12.5f64.to_radians(),
            }),
            head: Some(HeadSpec {
                pan_limit: 100f64.to_radians(),
                tilt_min: -30f64.to_radians(),
                tilt_max: 30f64.to_radians(),
                speed: 90f64.to_radians(),
            }),
            arm: None,
            body_color: [60, 62, 70],
            camera_height: 1.0,
            camera_hfov: 60f64.to_radians(),
            ir_range: 2.0,
            ir_half_angle: 50f64.to_radians(),
        }
    }

    /// H2.
    pub fn h2() -> Self {
        Self {
            kind: RobotKind::H2,
            radius: 0.22,
            body_height: 0.7,
            geometry: DiffDriveGeometry::H2,
            max_wheel_speed: 0.6,
            max_wheel_accel: 0.8,
            sonar: None,
            head: None,
            arm: Some(ArmSpec {
                limits: [
                    (-90f64.to_radians(), 90f64.to_radians()),
                    (-120f64.to_radians(), 120f64.to_radians()),
                    (0.0, 60f64.to_radians()),
                ],
                speed: 60f64.to_radians(),
                base: 0.15,
                links: [0.2, 0.15],
                grasp_tolerance: 0.1,
            }),
            body_color: [225, 225, 215],
            camera_height: 0.8,
            camera_hfov: 60f64.to_radians(),
            ir_range: 2.0,
            ir_half_angle: 50f64.to_radians(),
        }
    }

    /// The model of `kind`.
    pub fn for_kind(kind: RobotKind) -> Self {
        match kind {
            RobotKind::H1 => Self::h1(),
            RobotKind::H2 => Self::h2(),
        }
    }
}

/// Seeded noise of the simulation. All standard deviations are of a normal
/// distribution; probabilities per reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseModel {
    /// Per-wheel constant error of the effective wheel radius (drawn once
    /// per run), relative. Makes a straight command curve slightly, like the
    /// thesis' robot "slanting to the right".
    pub wheel_bias_sd: f64,
    /// Per-step wheel slip, relative to the wheel's travel.
    pub slip_sd: f64,
    /// Sonar range noise, metres, constant part.
    pub sonar_sd: f64,
    /// Sonar range noise, relative to the range.
    pub sonar_sd_rel: f64,
    /// Beyond this angle of incidence the echo may be reflected away.
    pub specular_angle: f64,
    /// Probability that a beam beyond `specular_angle` gives a wrong reading
    /// (no echo, or a longer multipath range).
    pub specular_prob: f64,
    /// Probability of a random wrong reading on any sonar.
    pub sonar_spurious_prob: f64,
    /// Probability that the IR receiver misses a visible checkpoint.
    pub ir_dropout_prob: f64,
}

impl Default for NoiseModel {
    fn default() -> Self {
        Self {
            wheel_bias_sd: 0.01,
            slip_sd: 0.03,
            sonar_sd: 0.01,
            sonar_sd_rel: 0.01,
            specular_angle: 50f64.to_radians(),
            specular_prob: 0.3,
            sonar_spurious_prob: 0.005,
            ir_dropout_prob: 0.02,
        }
    }
}

impl NoiseModel {
    /// No noise at all: exact geometry, for tests.
    pub fn none() -> Self {
        Self {
            wheel_bias_sd: 0.0,
            slip_sd: 0.0,
            sonar_sd: 0.0,
            sonar_sd_rel: 0.0,
            specular_angle: std::f64::consts::FRAC_PI_2,
            specular_prob: 0.0,
            sonar_spurious_prob: 0.0,
            ir_dropout_prob: 0.0,
        }
    }
}
