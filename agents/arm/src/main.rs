//! `arm`: H2's arm agent — the "external control module" robot 2 hands its
//! control to at the target (thesis section 4.3.2.3), in front of the arm
//! board (`GraspCommand` 0x52 / `GraspState` 0x53, `ArmCommand` /
//! `ArmState`; docs/devices.md).
//!
//! Input `cmd` (`nerve::GraspRequest`): grasp (with an optional guess of
//! where the target is, robot frame) or release; a request is keyed by its
//! id, so a sender may repeat it. Output `state` (`nerve::ArmGraspState`):
//! the phase (open, moving, closing, holding, missed with a reason), the
//! joints and the proximity reading, at every board report (10 Hz) and at
//! every change of phase.
//!
//! The grasp (probe three points, locate the target, reach, close) is the
//! library `nerve_arm`. Periodic (default 50 ms). Parameters: `probe_m`
//! (0.06), `guess_x_m` (0.35), `settle_deg` (1.5), `timeout_ms` (4000);
//! read-only figures `grasps`, `held`, `missed`, and the device link's
//! counters. A board that vanishes is reopened with exponential backoff; a
//! grasp under way then ends as missed (`device-lost`).

use agent_sdk::device::{CounterFigures, DeviceEvent, DeviceLink};
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use nerve_arm::{Command, Grasper, Gripper, Outcome, Settings};
use nerve_devices::{ArmCommand, GRASP_NOTHING, GraspCommand, GripperPhase, Message};
use shm_schemas::payloads::{ArmGraspState, GraspAction, GraspMiss, GraspPhase, GraspRequest, HELD_NOTHING};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

/// What `start` says when no `--device` was given.
const NO_DEVICE: &str =
    "no device: give the arm board's serial port after `--`, e.g. `nerve start arm -- --device /dev/ttyUSB4`";

/// Arguments after `--`.
#[derive(Debug, clap::Parser)]
struct Args {
    /// Serial device of the arm board.
    #[arg(long)]
    device: Option<PathBuf>,
}

#[derive(Debug, Default)]
struct Figures {
    grasps: AtomicU64,
    held: AtomicU64,
    missed: AtomicU64,
}

struct Arm {
    device: Option<PathBuf>,
    link: Option<DeviceLink>,
    cmd: Input<GraspRequest>,
    out: Output<ArmGraspState>,
    probe_m: Param<f64>,
    guess_x_m: Param<f64>,
    settle_deg: Param<f64>,
    timeout_ms: Param<u64>,
    counters: CounterFigures,
    figures: Arc<Figures>,
    grasper: Grasper,
    /// The last state published (joints, nearest, connected), for the next report.
    state: ArmGraspState,
    last_phase: Option<(GraspPhase, u32)>,
}

fn in_range(lo: f64, hi: f64) -> impl Fn(&f64) -> Result<(), String> + Send + Sync + 'static {
    move |v| if (lo..=hi).contains(v) { Ok(()) } else { Err(format!("{v} is outside {lo} … {hi}")) }
}

fn cdeg(rad: f64) -> i16 {
    (rad.to_degrees() * 100.0).round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

fn rad(cdeg: i16) -> f64 {
    (f64::from(cdeg) / 100.0).to_radians()
}

impl Arm {
    fn settings(&self) -> Settings {
        Settings {
            default_guess: (self.guess_x_m.get(), 0.0),
            probe_m: self.probe_m.get(),
            settle_rad: self.settle_deg.get().to_radians(),
            phase_timeout_ns: self.timeout_ms.get().saturating_mul(1_000_000),
            ..Settings::default()
        }
    }

    fn to_board(&self, cmds: Vec<Command>) {
        let Some(link) = &self.link else { return };
        for c in cmds {
            let msg: Message = match c {
                Command::Joints(j) => ArmCommand { joints_cdeg: [cdeg(j[0]), cdeg(j[1]), cdeg(j[2])] }.into(),
                Command::Close => GraspCommand { action: nerve_devices::GraspAction::Grasp }.into(),
                Command::Open => GraspCommand { action: nerve_devices::GraspAction::Release }.into(),
            };
            if !link.send(msg) {
                tracing::warn!(command = ?c, "the arm board did not take a command (absent or busy)");
            }
        }
    }

    /// Publishes the state; logs and counts a change of phase.
    fn publish(&mut self, now: u64) -> Result<(), AgentError> {
        let phase = self.grasper.phase();
        let id = self.grasper.request_id();
        let (held, reason) = match self.grasper.outcome() {
            Some(Outcome::Holding(h)) => (h, GraspMiss::None),
            Some(Outcome::Missed(r)) => (HELD_NOTHING, r),
            _ => (HELD_NOTHING, GraspMiss::None),
        };
        if self.last_phase != Some((phase, id)) {
            let located = self.grasper.located();
            match phase {
                GraspPhase::Holding => {
                    self.figures.held.fetch_add(1, Ordering::Relaxed);
                    tracing::info!(request = id, held, located = ?located, "holding the target");
                }
                GraspPhase::Missed => {
                    self.figures.missed.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!(request = id, reason = reason.name(), located = ?located, "grasp missed");
                }
                p => tracing::info!(request = id, phase = p.name(), "arm"),
            }
            self.last_phase = Some((phase, id));
        }
        self.state = ArmGraspState {
            stamp_ns: now,
            request_id: id,
            phase: phase as u8,
            held_id: held,
            reason: reason as u8,
            ..self.state
        };
        self.out.send(self.state)?;
        Ok(())
    }
}

impl Agent for Arm {
    const KIND: &'static str = "arm";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(50))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let d = Settings::default();
        let figures = Arc::new(Figures::default());
        let f2 = figures.clone();
        // its own figures after the device link's
        let counters = agent_sdk::device::counter_figures(setup, move || {
            let g = |a: &AtomicU64| a.load(Ordering::Relaxed).to_string();
            vec![("grasps".into(), g(&f2.grasps)), ("held".into(), g(&f2.held)), ("missed".into(), g(&f2.missed))]
        });
        Ok(Arm {
            device: args.device,
            link: None,
            cmd: setup.input("cmd")?,
            out: setup.output("state")?,
            probe_m: setup.param_checked("probe_m", d.probe_m, in_range(0.02, 0.15)),
            guess_x_m: setup.param_checked("guess_x_m", d.default_guess.0, in_range(0.2, 0.5)),
            settle_deg: setup.param_checked("settle_deg", 1.5, in_range(0.1, 10.0)),
            timeout_ms: setup.param_checked("timeout_ms", 4000u64, |v| {
                if (500..=60_000).contains(v) { Ok(()) } else { Err("timeout_ms is 500 … 60000".into()) }
            }),
            counters,
            figures,
            grasper: Grasper::new(d),
            state: ArmGraspState { nearest_m: -1.0, held_id: HELD_NOTHING, ..Default::default() },
            last_phase: None,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        self.link = Some(agent_sdk::device::open_link(&self.device, "arm", NO_DEVICE)?);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        self.grasper.set_settings(self.settings());
        let mut requests = Vec::new();
        self.cmd.drain(|m, r| requests.push((m.sender.to_string(), *r)));
        for (sender, r) in requests {
            let cmds = match r.action() {
                Some(GraspAction::Grasp) => {
                    let guess = (r.has_point == 1).then_some((r.x, r.y));
                    if r.request_id != self.grasper.request_id() {
                        self.figures.grasps.fetch_add(1, Ordering::Relaxed);
                        tracing::info!(request = r.request_id, guess = ?guess, %sender, "grasp");
                    }
                    self.grasper.grasp(r.request_id, guess, now)
                }
                Some(GraspAction::Release) => {
                    if r.request_id != self.grasper.request_id() {
                        tracing::info!(request = r.request_id, %sender, "release");
                    }
                    self.grasper.release(r.request_id, now)
                }
                None => {
                    tracing::warn!(action = r.action, %sender, "grasp request of unknown action; ignored");
                    Vec::new()
                }
            };
            self.to_board(cmds);
        }
        let mut events = Vec::new();
        if let Some(link) = &self.link {
            while let Some(ev) = link.try_recv() {
                events.push(ev);
            }
        }
        let mut reported = false;
        for ev in events {
            let cmds = match ev {
                DeviceEvent::Message(Message::ArmState(s), _) => {
                    let j = [rad(s.joints_cdeg[0]), rad(s.joints_cdeg[1]), rad(s.joints_cdeg[2])];
                    self.state.joints_rad = [j[0] as f32, j[1] as f32, j[2] as f32];
                    self.grasper.on_joints(j, now)
                }
                DeviceEvent::Message(Message::GraspState(g), _) => {
                    let gripper = match g.phase {
                        GripperPhase::Open => Gripper::Open,
                        GripperPhase::Closing => Gripper::Closing,
                        GripperPhase::Holding if g.held_id != GRASP_NOTHING => Gripper::Holding(g.held_id),
                        GripperPhase::Holding | GripperPhase::Missed => Gripper::Missed,
                    };
                    let nearest = (g.nearest_mm != u16::MAX).then(|| f64::from(g.nearest_mm) / 1000.0);
                    self.state.nearest_m = nearest.map_or(-1.0, |n| n as f32);
                    let cmds = self.grasper.on_gripper(gripper, nearest, now);
                    reported = true;
                    cmds
                }
                DeviceEvent::Connected => {
                    self.state.connected = 1;
                    Vec::new()
                }
                DeviceEvent::Lost => {
                    self.state.connected = 0;
                    self.grasper.on_device_lost(now)
                }
                DeviceEvent::Message(..) => Vec::new(),
            };
            self.to_board(cmds);
        }
        let cmds = self.grasper.tick(now);
        self.to_board(cmds);
        let changed = self.last_phase != Some((self.grasper.phase(), self.grasper.request_id()));
        let result = if reported || changed { self.publish(now) } else { Ok(()) };
        if let Some(link) = &self.link {
            self.counters.update(&link.stats(), "arm");
        }
        result
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Arm>()
}

#[cfg(test)]
mod tests {
    //! The agent's glue, through the SDK's harness, on a pseudo-terminal
    //! board: a grasp request to the board's commands and to `state`
    //! through `step`, the phase timeout set by a parameter, a refused
    //! parameter and the refusal to start without a device. The grasp
    //! itself is tested in the library.

    use super::*;
    use agent_sdk::testing::Harness;
    use nerve_devices::FrameDecoder;
    use std::io::Read;
    use std::sync::mpsc::{Receiver, channel};

    /// A pseudo-terminal standing in for the arm board: a thread decodes
    /// what the agent writes until the line closes.
    struct Board {
        tty: PathBuf,
        _slave: std::os::fd::OwnedFd,
        heard: Receiver<Message>,
    }

    impl Board {
        fn new() -> Board {
            let (master, slave, tty) = agent_sdk::device::raw_pty().expect("a pseudo-terminal in raw mode");
            let mut master = std::fs::File::from(master);
            let (tx, heard) = channel();
            std::thread::spawn(move || {
                let (mut decoder, mut buf) = (FrameDecoder::new(), [0u8; 256]);
                // ends when the line closes (EIO) or the test is gone
                while let Ok(n @ 1..) = master.read(&mut buf) {
                    if decoder.push(&buf[..n]).try_for_each(|m| tx.send(m)).is_err() {
                        return;
                    }
                }
            });
            Board { tty, _slave: slave, heard }
        }

        /// The first message the agent sent that `pick` accepts (at most 5 s).
        fn first<T>(&self, pick: impl Fn(Message) -> Option<T>) -> Option<T> {
            let end = std::time::Instant::now() + Duration::from_secs(5);
            while let Some(left) = end.checked_duration_since(std::time::Instant::now()) {
                match self.heard.recv_timeout(left) {
                    Ok(m) => {
                        if let Some(t) = pick(m) {
                            return Some(t);
                        }
                    }
                    Err(_) => return None,
                }
            }
            None
        }
    }

    fn grasp(id: u32) -> GraspRequest {
        GraspRequest { request_id: id, action: GraspAction::Grasp as u8, ..Default::default() }
    }

    #[test]
    fn without_a_device_the_arm_does_not_start_and_says_what_to_give() {
        let e = Harness::<Arm>::new().expect_err("no --device").to_string();
        assert!(e.contains("start") && e.contains("--device"), "{e}");
    }

    #[test]
    fn a_grasp_opens_the_gripper_and_times_out_as_missed_when_the_board_is_silent() {
        let board = Board::new();
        let tty = board.tty.display().to_string();
        let mut h = Harness::<Arm>::builder()
            .args(["--device", tty.as_str()])
            .param("timeout_ms", "500")
            .start()
            .expect("the arm starts on the board");
        let e = h.set_param("timeout_ms", "100").expect_err("too short");
        assert!(e.contains("500"), "{e}");
        // the device thread opens the line on its own: wait for it (5 s at most)
        let end = std::time::Instant::now() + Duration::from_secs(5);
        while !h.agent().link.as_ref().is_some_and(|l| l.stats().connected) && std::time::Instant::now() < end {
            std::thread::sleep(Duration::from_millis(5));
        }

        h.send_from("cmd", "decision", grasp(3)).expect("grasp");
        h.step().expect("step");
        let s = *h.output::<ArmGraspState>("state").expect("state").last().expect("the phase changed: a state");
        assert_eq!((s.request_id, GraspPhase::from_code(s.phase)), (3, Some(GraspPhase::Moving)), "{s:?}");
        assert_eq!(h.param("grasps").as_deref(), Ok("1"));
        let opened = board.first(|m| match m {
            Message::GraspCommand(g) => Some(g.action),
            _ => None,
        });
        assert_eq!(opened, Some(nerve_devices::GraspAction::Release), "the gripper is opened first");

        // the board never reports: the phase ends after timeout_ms
        h.advance(Duration::from_millis(600)).expect("steps");
        let s = *h.output::<ArmGraspState>("state").expect("state").last().expect("missed: a state");
        assert_eq!(GraspPhase::from_code(s.phase), Some(GraspPhase::Missed), "{s:?}");
        assert_eq!(s.reason, GraspMiss::Timeout as u8, "{s:?}");
        assert_eq!(h.param("missed").as_deref(), Ok("1"));
        // the device link's counters are figures beside the arm's own
        assert_eq!(h.param("device_opens").as_deref().map(|n| n.parse::<u64>().is_ok()), Ok(true));
    }
}
