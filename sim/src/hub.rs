//! The device hub: the robot's boards, answering their protocols over ptys.
//!
//! Once per simulation step, [`DeviceHub::step`] reads the hosts' commands
//! (wheel, head, arm set-points) and applies them, advances the simulation
//! one step, and sends each device's periodic report when its period is due
//! (sonar 4 Hz, encoders 20 Hz, head 10 Hz, IR 10 Hz, arm 10 Hz; counted in
//! simulation steps, so the rates are exact in simulated time). Sensor
//! readings are drawn every period whether or not a host listens, so a run
//! is reproducible from its seed however agents come and go.

use std::path::{Path, PathBuf};

use nerve_devices::{
    ARM_RATE_HZ, ArmState, ENCODER_RATE_HZ, EncoderReport, HEAD_RATE_HZ, HeadState, IR_RATE_HZ, IrReport, Message,
    SONAR_RATE_HZ, SonarScan,
};

use crate::pty::{DeviceKind, PtyDevice, PtyError};
use crate::sim::Simulation;

fn cdeg(rad: f64) -> i16 {
    (rad.to_degrees() * 100.0).round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

/// All devices of one robot, published in one directory.
#[derive(Debug)]
pub struct DeviceHub {
    dir: PathBuf,
    devices: Vec<PtyDevice>,
}

impl DeviceHub {
    /// Publishes every device of the simulated robot as `dir/<name>`,
    /// creating `dir` if needed.
    pub fn open(dir: &Path, sim: &Simulation) -> Result<Self, PtyError> {
        std::fs::create_dir_all(dir).map_err(|source| PtyError::Dir { dir: dir.to_path_buf(), source })?;
        let devices = DeviceKind::for_model(sim.model())
            .into_iter()
            .map(|k| PtyDevice::open(k, &dir.join(k.name())))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { dir: dir.to_path_buf(), devices })
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

    /// Commands in, one simulation step, reports out.
    pub fn step(&mut self, sim: &mut Simulation) {
        for dev in &mut self.devices {
            for msg in dev.poll() {
                match (dev.kind(), msg) {
                    (DeviceKind::Motor, Message::WheelCommand(c)) => sim.command_wheels(&c),
                    (DeviceKind::Head, Message::HeadCommand(c)) => sim.command_head(&c),
                    (DeviceKind::Arm, Message::ArmCommand(c)) => sim.command_arm(&c),
                    (kind, other) => tracing::debug!(
                        device = %kind,
                        message = ?other.message_type(),
                        "ignoring a message this device does not accept"
                    ),
                }
            }
        }
        sim.step();
        let steps = sim.steps();
        let due = |hz: f64| steps % period_steps(hz, sim.dt()) == 0;
        let (sonar, enc, head, ir, arm) =
            (due(SONAR_RATE_HZ), due(ENCODER_RATE_HZ), due(HEAD_RATE_HZ), due(IR_RATE_HZ), due(ARM_RATE_HZ));
        if !(sonar || enc || head || ir || arm) {
            return;
        }
        let time_ms = (sim.time() * 1000.0).round() as u64 as u32;
        for i in 0..self.devices.len() {
            let kind = self.devices[i].kind();
            let msg: Option<Message> = match kind {
                DeviceKind::Sonar if sonar => Some(
                    SonarScan {
                        seq: (steps / period_steps(SONAR_RATE_HZ, sim.dt())) as u16,
                        ranges_mm: sim.sonar_scan(),
                    }
                    .into(),
                ),
                DeviceKind::Motor if enc => {
                    let (left, right) = sim.encoder_counts();
                    Some(
                        EncoderReport {
                            seq: (steps / period_steps(ENCODER_RATE_HZ, sim.dt())) as u16,
                            time_ms,
                            left,
                            right,
                        }
                        .into(),
                    )
                }
                DeviceKind::Head if head => {
                    let (p, t) = sim.head_position();
                    Some(
                        HeadState {
                            seq: (steps / period_steps(HEAD_RATE_HZ, sim.dt())) as u16,
                            pan_cdeg: cdeg(p),
                            tilt_cdeg: cdeg(t),
                        }
                        .into(),
                    )
                }
                DeviceKind::Ir if ir => Some(
                    IrReport { seq: (steps / period_steps(IR_RATE_HZ, sim.dt())) as u16, sighting: sim.ir_sighting() }
                        .into(),
                ),
                DeviceKind::Arm if arm => {
                    let j = sim.arm_position();
                    Some(
                        ArmState {
                            seq: (steps / period_steps(ARM_RATE_HZ, sim.dt())) as u16,
                            joints_cdeg: [cdeg(j[0]), cdeg(j[1]), cdeg(j[2])],
                        }
                        .into(),
                    )
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
