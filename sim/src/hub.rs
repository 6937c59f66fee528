//! The device hub: one robot's boards, answering their protocols over ptys.
//!
//! Once per simulation step, [`DeviceHub::step`] reads the hosts' commands
//! (wheel, head, arm set-points, grasp) and applies them, advances the
//! simulation one step, and sends each device's periodic report when its
//! period is due (sonar 4 Hz, encoders 20 Hz, head 10 Hz, IR 10 Hz, arm and
//! gripper 10 Hz; counted in simulation steps, so the rates are exact in
//! simulated time). Sensor readings are drawn every period whether or not a
//! host listens, so a run is reproducible from its seed however agents come
//! and go.
//!
//! With several robots in one simulation there is one hub per robot
//! ([`DeviceHub::open_robot`]), and the owner of the loop calls
//! [`DeviceHub::apply_commands`] on every hub, steps the simulation once,
//! then [`DeviceHub::send_reports`] on every hub.

use std::path::{Path, PathBuf};

use nerve_devices::{
    ARM_RATE_HZ, ArmState, ENCODER_RATE_HZ, EncoderReport, HEAD_RATE_HZ, HeadState, IR_RATE_HZ, IrReport, Message,
    SONAR_RATE_HZ, SonarScan,
};

use crate::pty::{DeviceKind, PtyDevice, PtyError};
use crate::sim::{RobotId, Simulation};

fn cdeg(rad: f64) -> i16 {
    (rad.to_degrees() * 100.0).round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

/// All devices of one robot, published in one directory.
#[derive(Debug)]
pub struct DeviceHub {
    dir: PathBuf,
    robot: RobotId,
    devices: Vec<PtyDevice>,
}

impl DeviceHub {
    /// Publishes every device of the simulation's first robot as
    /// `dir/<name>`, creating `dir` if needed.
    pub fn open(dir: &Path, sim: &Simulation) -> Result<Self, PtyError> {
        Self::open_robot(dir, sim, RobotId::FIRST)
    }

    /// Publishes every device of robot `robot` as `dir/<name>`, creating
    /// `dir` if needed.
    pub fn open_robot(dir: &Path, sim: &Simulation, robot: RobotId) -> Result<Self, PtyError> {
        std::fs::create_dir_all(dir).map_err(|source| PtyError::Dir { dir: dir.to_path_buf(), source })?;
        let devices = DeviceKind::for_model(sim.robot(robot).model())
            .into_iter()
            .map(|k| PtyDevice::open(k, &dir.join(k.name())))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { dir: dir.to_path_buf(), robot, devices })
    }

    /// The robot whose devices these are.
    pub fn robot(&self) -> RobotId {
        self.robot
    }

    /// The directory holding the links.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The devices.
    pub fn devices(&self) -> &[PtyDevice] {
        &self.devices
    }

    /// The device of `kind`, if the robot has one.
    pub fn device(&self, kind: DeviceKind) -> Option<&PtyDevice> {
        self.devices.iter().find(|d| d.kind() == kind)
    }

    /// Commands in, one simulation step, reports out (a simulation whose
    /// only robot is this hub's).
    pub fn step(&mut self, sim: &mut Simulation) {
        self.apply_commands(sim);
        sim.step();
        self.send_reports(sim);
    }

    /// Reads the hosts' commands and applies them to this hub's robot.
    pub fn apply_commands(&mut self, sim: &mut Simulation) {
        let mut robot = sim.robot_mut(self.robot);
        for dev in &mut self.devices {
            for msg in dev.poll() {
                match (dev.kind(), msg) {
                    (DeviceKind::Motor, Message::WheelCommand(c)) => robot.command_wheels(&c),
                    (DeviceKind::Head, Message::HeadCommand(c)) => robot.command_head(&c),
                    (DeviceKind::Arm, Message::ArmCommand(c)) => robot.command_arm(&c),
                    (DeviceKind::Arm, Message::GraspCommand(c)) => {
                        tracing::info!(robot = robot.as_ref().name(), action = ?c.action, "grasp command");
                        robot.command_grasp(c.action);
                    }
                    (kind, other) => tracing::debug!(
                        device = %kind,
                        message = ?other.message_type(),
                        "ignoring a message this device does not accept"
                    ),
                }
            }
        }
    }

    /// Sends every report of this hub's robot whose period is due after
    /// the step the simulation just took.
    pub fn send_reports(&mut self, sim: &mut Simulation) {
        let steps = sim.steps();
        let dt = sim.dt();
        let due = |hz: f64| steps.is_multiple_of(period_steps(hz, dt));
        let (sonar, enc, head, ir, arm) =
            (due(SONAR_RATE_HZ), due(ENCODER_RATE_HZ), due(HEAD_RATE_HZ), due(IR_RATE_HZ), due(ARM_RATE_HZ));
        if !(sonar || enc || head || ir || arm) {
            return;
        }
        let time_ms = (sim.time() * 1000.0).round() as u64 as u32;
        let seq = |hz: f64| (steps / period_steps(hz, dt)) as u16;
        let mut robot = sim.robot_mut(self.robot);
        for i in 0..self.devices.len() {
            let kind = self.devices[i].kind();
            let msg: Option<Message> = match kind {
                DeviceKind::Sonar if sonar => {
                    Some(SonarScan { seq: seq(SONAR_RATE_HZ), ranges_mm: robot.sonar_scan() }.into())
                }
                DeviceKind::Motor if enc => {
                    let (left, right) = robot.as_ref().encoder_counts();
                    Some(EncoderReport { seq: seq(ENCODER_RATE_HZ), time_ms, left, right }.into())
                }
                DeviceKind::Head if head => {
                    let (p, t) = robot.as_ref().head_position();
                    Some(HeadState { seq: seq(HEAD_RATE_HZ), pan_cdeg: cdeg(p), tilt_cdeg: cdeg(t) }.into())
                }
                DeviceKind::Ir if ir => Some(IrReport { seq: seq(IR_RATE_HZ), sighting: robot.ir_sighting() }.into()),
                DeviceKind::Arm if arm => {
                    let j = robot.as_ref().arm_position();
                    let state = ArmState { seq: seq(ARM_RATE_HZ), joints_cdeg: [cdeg(j[0]), cdeg(j[1]), cdeg(j[2])] };
                    self.devices[i].send(&state.into());
                    Some(robot.as_ref().grasp_state(seq(ARM_RATE_HZ)).into())
                }
                _ => None,
            };
            if let Some(m) = msg {
                self.devices[i].send(&m);
            }
        }
    }
}

/// A device period in simulation steps; report `n` (its seq, wrapping) is
/// sent at step `n * period`.
fn period_steps(hz: f64, dt: f64) -> u64 {
    ((1.0 / hz) / dt).round().max(1.0) as u64
}
