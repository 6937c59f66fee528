//! `motor`: the foot motor agent — the actuator pattern of the thesis'
//! Fig. 2-4 in front of the wheel board.
//!
//! Inputs (fan-in from any number of agents; the sample header names the
//! sender, and the latest command of each sender is kept):
//! * `cmd` — `nerve::VelocityCommand`, numeric (v, ω);
//! * `say` — `nerve::LinguisticCommand`, e.g. "turn right a little";
//! * `stop` — `nerve::SafetyStop`, which always wins.
//!
//! Every cycle (periodic, default 50 ms) the commands go through the filter,
//! the fuzzy rule base and the weighted fusion of `nerve_motor`; the result
//! is ramped to the base's limits, turned into wheel speeds and sent to the
//! motor board over the serial port `-- --device PATH`. The board's encoder
//! reports (20 Hz) are integrated into odometry.
//!
//! Outputs: `odom` (`nerve::Odometry`, per encoder report) and `applied`
//! (`nerve::VelocityCommand`, what was sent to the wheels, every cycle).
//!
//! Parameters: `weights` (`sender:weight,...`), `default_weight`, `v_max`,
//! `omega_max`, `accel_max`, `stale_ms`, `cruise`; figures (read-only counters)
//! `accepted`, `refused` and the device link's counters. Agent arguments:
//! `--device PATH` (required), `--robot-model h1|h2` (geometry and limits,
//! default h1), `--start X,Y,THETA_DEG` (odometry start pose, default 0,0,0).
//!
//! When the board vanishes the agent logs it, keeps deciding (so a stop is
//! never missed) and reopens the port with exponential backoff; the first
//! command after recovery is the current decision. On stop it commands the
//! wheels to zero (the board has no command timeout).

use agent_sdk::device::{Count, CounterFigures, DeviceEvent, DeviceLink};
use agent_sdk::params::positive;
use agent_sdk::{Agent, AgentError, Context, Input, Output, Param, Setup, Task};
use nerve_devices::{DiffDriveGeometry, Message, Pose2, WheelCommand, wrap_angle};
use nerve_motor::{Fusion, Limits, Weights, drive::wheel_speeds, refusals::Refusals};
use shm_schemas::payloads::{LinguisticCommand, Odometry, SafetyStop, VelocityCommand};
use std::path::PathBuf;
use std::time::Duration;

/// What `start` says when no `--device` was given.
const NO_DEVICE: &str = "no device: give the motor board's serial port after `--`, e.g. `nerve start motor -- --device /dev/ttyUSB1` \
                 (with the simulator: `-- --device <state dir>/dev/motor`)";

/// Arguments after `--`.
#[derive(Debug, clap::Parser)]
struct Args {
    /// Serial device of the motor board.
    #[arg(long)]
    device: Option<PathBuf>,
    /// Robot model: h1 or h2 (wheel geometry and limits).
    #[arg(long, default_value = "h1", value_parser = ["h1", "h2"])]
    robot_model: String,
    /// Odometry start pose: X,Y,THETA_DEG.
    #[arg(long, value_parser = parse_pose)]
    start: Option<Pose2>,
}

fn parse_pose(s: &str) -> Result<Pose2, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|_| format!("{x:?} is not a number")))
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [x, y, deg] if v.iter().all(|a| a.is_finite()) => {
            Ok(Pose2 { x: *x, y: *y, theta: wrap_angle(deg.to_radians()) })
        }
        _ => Err("write X,Y,THETA_DEG, e.g. 1.0,2.0,90".into()),
    }
}

struct Motor {
    device: Option<PathBuf>,
    link: Option<DeviceLink>,
    cmd: Input<VelocityCommand>,
    say: Input<LinguisticCommand>,
    stop: Input<SafetyStop>,
    odom_out: Output<Odometry>,
    applied_out: Output<VelocityCommand>,
    weights: Param<String>,
    /// the `weights` text last parsed, and what it parsed to: the string
    /// is parsed again only when `nerve param set` changed it
    weights_seen: (String, Weights),
    default_weight: Param<f64>,
    v_max: Param<f64>,
    omega_max: Param<f64>,
    accel_max: Param<f64>,
    stale_ms: Param<u64>,
    cruise: Param<f64>,
    accepted: Count,
    refused: Count,
    counters: CounterFigures,
    base_limits: Limits,
    geometry: DiffDriveGeometry,
    wheel_max_mm_s: f64,
    fusion: Fusion,
    odometry: nerve_devices::Odometry,
    last_report: Option<(u32, Pose2)>,
    refusals_by_sender: Refusals,
    last_stopped_by: Option<String>,
    was_idle: bool,
    last_step_ns: u64,
}

impl Motor {
    fn limits(&self) -> Limits {
        Limits {
            v_max: self.v_max.get(),
            omega_max: self.omega_max.get(),
            accel_max: self.accel_max.get(),
            stale_ns: self.stale_ms.get() * 1_000_000,
            ..self.base_limits
        }
    }

    fn refused_from(&mut self, sender: &str, what: &str, why: &dyn std::fmt::Display, now_ns: u64) {
        self.refused.add(1);
        let n = self.refusals_by_sender.record(sender, now_ns);
        if n.is_power_of_two() {
            tracing::warn!("refused {what} from {sender} ({n} so far from it): {why}");
        }
    }

    fn on_encoder(&mut self, r: &nerve_devices::EncoderReport, stamp_ns: u64) -> Result<(), AgentError> {
        let pose = self.odometry.update(r);
        let (mut v, mut omega) = (0.0, 0.0);
        if let Some((t0, p0)) = self.last_report {
            let dt = f64::from(r.time_ms.wrapping_sub(t0)) / 1000.0;
            if dt > 1e-3 && dt < 5.0 {
                let (dx, dy) = (pose.x - p0.x, pose.y - p0.y);
                let mid = p0.theta + 0.5 * wrap_angle(pose.theta - p0.theta);
                v = (dx * mid.cos() + dy * mid.sin()) / dt;
                omega = wrap_angle(pose.theta - p0.theta) / dt;
            }
        }
        self.last_report = Some((r.time_ms, pose));
        self.odom_out.send(Odometry { x: pose.x, y: pose.y, theta: pose.theta, v, omega, stamp_ns })?;
        Ok(())
    }
}

impl Agent for Motor {
    const KIND: &'static str = "motor";

    fn task() -> Task {
        Task::Periodic(Duration::from_millis(50))
    }

    fn new(setup: &mut Setup) -> Result<Self, AgentError> {
        let args: Args = setup.args()?;
        let (limits, geometry, wheel_max) = match args.robot_model.as_str() {
            "h2" => (Limits::H2, DiffDriveGeometry::H2, 600.0),
            _ => (Limits::H1, DiffDriveGeometry::H1, 800.0),
        };
        // read-only counters: figures, after the device link's
        let (accepted, refused) = (Count::default(), Count::default());
        let (a, r) = (accepted.clone(), refused.clone());
        let counters =
            agent_sdk::device::counter_figures(setup, move || vec![a.figure("accepted"), r.figure("refused")]);
        let (v_lim, w_lim) = (limits.v_max, limits.omega_max);
        Ok(Motor {
            device: args.device,
            link: None,
            cmd: setup.input("cmd")?,
            say: setup.input("say")?,
            stop: setup.input("stop")?,
            odom_out: setup.output("odom")?,
            applied_out: setup.output("applied")?,
            weights: setup.param_checked("weights", String::new(), |s: &String| Weights::parse(s).map(|_| ())),
            default_weight: setup.param_checked("default_weight", 1.0, |v: &f64| {
                if v.is_finite() && *v >= 0.0 { Ok(()) } else { Err("must be a finite number >= 0".into()) }
            }),
            v_max: setup.param_checked("v_max", v_lim, move |v: &f64| {
                if v.is_finite() && *v > 0.0 && *v <= v_lim {
                    Ok(())
                } else {
                    Err(format!("must be in (0, {v_lim}], the board's limit"))
                }
            }),
            omega_max: setup.param_checked("omega_max", w_lim, move |v: &f64| {
                if v.is_finite() && *v > 0.0 && *v <= w_lim { Ok(()) } else { Err(format!("must be in (0, {w_lim}]")) }
            }),
            accel_max: setup.param_checked("accel_max", limits.accel_max, positive),
            stale_ms: setup.param_checked("stale_ms", limits.stale_ns / 1_000_000, |v: &u64| {
                if (10..=60_000).contains(v) { Ok(()) } else { Err("must be between 10 and 60000 ms".into()) }
            }),
            cruise: setup.param_checked("cruise", 0.3, positive),
            accepted,
            refused,
            counters,
            base_limits: limits,
            geometry,
            wheel_max_mm_s: wheel_max,
            fusion: Fusion::new(0.3),
            odometry: nerve_devices::Odometry::new(geometry, args.start.unwrap_or_default()),
            last_report: None,
            refusals_by_sender: Refusals::default(),
            last_stopped_by: None,
            weights_seen: (String::new(), Weights::default()),
            was_idle: true,
            last_step_ns: 0,
        })
    }

    fn start(&mut self, _ctx: &mut Context) -> Result<(), AgentError> {
        self.link = Some(agent_sdk::device::open_link(&self.device, "motor", NO_DEVICE)?);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context) -> Result<(), AgentError> {
        let now = ctx.now_ns();
        let mut result: Result<(), AgentError> = Ok(());
        // the board: encoder reports
        let mut reports = Vec::new();
        if let Some(link) = &self.link {
            while let Some(ev) = link.try_recv() {
                match ev {
                    DeviceEvent::Message(Message::EncoderReport(r), at) => {
                        reports.push((r, now.saturating_sub(agent_sdk::clock::elapsed_ns(at))))
                    }
                    DeviceEvent::Connected => self.last_report = None,
                    _ => {}
                }
            }
        }
        for (r, stamp) in reports {
            if let Err(e) = self.on_encoder(&r, stamp) {
                result = Err(e);
            }
        }

        // the filter: every command of every sender
        let limits = self.limits();
        let mut offered = Vec::new();
        self.cmd.drain(|m, c| offered.push((m.sender.as_str().to_owned(), Ok(*c))));
        self.say.drain(|m, c| offered.push((m.sender.as_str().to_owned(), Err(*c))));
        for (sender, c) in offered {
            let r = match c {
                Ok(c) => self.fusion.offer_numeric(&sender, &c, now, &limits).map_err(|e| ("command", e)),
                Err(c) => self
                    .fusion
                    .offer_linguistic(&sender, &c, now, &limits)
                    .map(|_| ())
                    .map_err(|e| ("linguistic command", e)),
            };
            match r {
                Ok(()) => self.accepted.add(1),
                Err((what, e)) => self.refused_from(&sender, what, &e, now),
            }
        }
        let mut stops = Vec::new();
        self.stop.drain(|m, s| stops.push((m.sender.as_str().to_owned(), *s)));
        for (sender, s) in stops {
            self.fusion.offer_stop(&sender, &s, now);
        }

        // fusion, control, wheels
        self.fusion.cruise = self.cruise.get();
        if self.weights.with(|w| *w != self.weights_seen.0) {
            let text = self.weights.get();
            // the parameter's check refuses what does not parse
            self.weights_seen = (text.clone(), Weights::parse(&text).unwrap_or_default());
        }
        let weights = &self.weights_seen.1;
        let dt = if self.last_step_ns == 0 {
            ctx.period().map_or(0.05, |p| p.as_secs_f64())
        } else {
            (now.saturating_sub(self.last_step_ns)) as f64 / 1e9
        };
        self.last_step_ns = now;
        let d = self.fusion.decide(now, dt, &limits, weights, self.default_weight.get());
        if d.stopped_by != self.last_stopped_by {
            match &d.stopped_by {
                Some(s) => tracing::warn!("safety stop from {s}: the base stops"),
                None => tracing::info!("safety stop released"),
            }
            self.last_stopped_by = d.stopped_by.clone();
        }
        let idle = d.weighted == 0;
        if idle && !self.was_idle {
            if d.sources == 0 {
                tracing::info!("no fresh command from any source: stopping (dead man)");
            } else {
                tracing::info!("{} fresh source(s), none with a positive weight: stopping", d.sources);
            }
        }
        self.was_idle = idle;
        let (left, right) = wheel_speeds(d.v, d.omega, self.geometry.wheel_base_mm / 1000.0, self.wheel_max_mm_s);
        if let Some(link) = &self.link {
            link.send(WheelCommand { left_mm_s: left, right_mm_s: right }.into());
            self.counters.update(&link.stats(), "motor");
        }
        self.applied_out.send(VelocityCommand { v: d.v, omega: d.omega, stamp_ns: now })?;
        result
    }

    fn stop(&mut self, _ctx: &mut Context) {
        if let Some(link) = &self.link
            && link.stats().connected
        {
            link.send(WheelCommand::default().into());
            // the device thread writes within its 20 ms poll
            std::thread::sleep(Duration::from_millis(60));
            tracing::info!("wheels commanded to zero");
        }
    }
}

fn main() -> std::process::ExitCode {
    agent_sdk::run::<Motor>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_sdk::testing::Harness;
    use nerve_devices::FrameDecoder;
    use std::io::Read;
    use std::os::fd::OwnedFd;
    use std::time::Instant;

    /// A pseudo-terminal standing in for the wheel board (raw mode): the
    /// agent opens the slave, the test reads what it sends from the master.
    struct Board {
        master: std::fs::File,
        _slave: OwnedFd,
        tty: PathBuf,
        decoder: FrameDecoder,
    }

    impl Board {
        fn new() -> Board {
            let (master, slave, tty) = agent_sdk::device::raw_pty().expect("a pseudo-terminal in raw mode");
            let master = std::fs::File::from(master);
            let flags = nix::fcntl::fcntl(&master, nix::fcntl::FcntlArg::F_GETFL).expect("flags");
            let flags = nix::fcntl::OFlag::from_bits_truncate(flags) | nix::fcntl::OFlag::O_NONBLOCK;
            nix::fcntl::fcntl(&master, nix::fcntl::FcntlArg::F_SETFL(flags)).expect("non-blocking");
            Board { master, _slave: slave, tty, decoder: FrameDecoder::new() }
        }

        /// The wheel commands the agent wrote, read until one satisfies
        /// `enough` (at most 5 s).
        fn wheels_until(&mut self, enough: impl Fn(&WheelCommand) -> bool) -> Vec<WheelCommand> {
            let mut got: Vec<WheelCommand> = Vec::new();
            let end = Instant::now() + Duration::from_secs(5);
            let mut buf = [0u8; 256];
            while !got.iter().any(&enough) && Instant::now() < end {
                match self.master.read(&mut buf) {
                    Ok(n) if n > 0 => got.extend(self.decoder.push(&buf[..n]).filter_map(|m| match m {
                        Message::WheelCommand(w) => Some(w),
                        _ => None,
                    })),
                    _ => std::thread::sleep(Duration::from_millis(5)),
                }
            }
            got
        }
    }

    fn cmd(v: f64, omega: f64, stamp_ns: u64) -> VelocityCommand {
        VelocityCommand { v, omega, stamp_ns }
    }

    /// The motor agent as it runs, on a pseudo-terminal board: commands of
    /// two senders are fused by the weights set at run time and ramp up
    /// within the acceleration limit; a safety stop brakes to zero whatever
    /// they say; stale commands stop the base (dead man); and the wheel
    /// commands reach the board.
    #[test]
    fn commands_are_fused_by_weight_a_stop_wins_and_the_board_hears_the_wheels() {
        let mut board = Board::new();
        let tty = board.tty.display().to_string();
        let mut h = Harness::<Motor>::builder()
            .args(["--device", tty.as_str()])
            .param("weights", "planner:3,joystick:1")
            .start()
            .expect("the motor starts on the board");
        let period = h.period().expect("periodic");
        assert_eq!(period, Duration::from_millis(50));
        // the device thread opens the line on its own: wait for it (5 s at most)
        let end = Instant::now() + Duration::from_secs(5);
        while !h.agent().link.as_ref().is_some_and(|l| l.stats().connected) && Instant::now() < end {
            std::thread::sleep(Duration::from_millis(5));
        }

        // two senders, each at its own speed, every cycle for 2 s
        let mut applied = Vec::new();
        for _ in 0..40 {
            let t = h.now_ns() + agent_sdk::clock::nanos(period);
            h.send_from("cmd", "planner", cmd(0.4, 0.0, t)).expect("send");
            h.send_from("cmd", "joystick", cmd(0.0, 0.0, t)).expect("send");
            h.step().expect("step");
            applied.extend(h.output::<VelocityCommand>("applied").expect("applied").iter().map(|c| c.v));
        }
        assert_eq!(applied.len(), 40);
        let fused = (3.0 * 0.4 + 0.0) / 4.0;
        assert!((applied[39] - fused).abs() < 1e-6, "weighted 3:1 -> {fused}: {applied:?}");
        for w in applied.windows(2) {
            assert!(w[1] - w[0] <= Limits::H1.accel_max * 0.05 + 1e-9, "ramped within accel_max: {applied:?}");
        }
        assert_eq!(h.param("accepted").as_deref(), Ok("80"));

        // the board hears the wheels turning forward, both alike
        let wheels = board.wheels_until(|w| w.left_mm_s > 0);
        let forward = wheels.iter().find(|w| w.left_mm_s > 0);
        assert!(forward.is_some_and(|w| w.left_mm_s == w.right_mm_s), "{wheels:?}");

        // a safety stop brakes to zero, whatever the senders say
        for _ in 0..20 {
            let t = h.now_ns() + agent_sdk::clock::nanos(period);
            h.send_from("cmd", "planner", cmd(0.4, 0.0, t)).expect("send");
            h.send_from(
                "stop",
                "safety",
                SafetyStop { active: 1, allow_turn: 0, reserved: [0; 2], hold_ms: 500, stamp_ns: t },
            )
            .expect("stop");
            h.step().expect("step");
        }
        let v = h.output::<VelocityCommand>("applied").expect("applied").last().map(|c| c.v);
        assert_eq!(v, Some(0.0));

        // released, then silence: after stale_ms the base stops by itself
        h.set_param("stale_ms", "200").expect("stale_ms");
        for _ in 0..10 {
            let t = h.now_ns() + agent_sdk::clock::nanos(period);
            h.send_from("stop", "safety", SafetyStop { active: 0, stamp_ns: t, ..Default::default() })
                .expect("release");
            h.send_from("cmd", "planner", cmd(0.4, 0.0, t)).expect("send");
            h.step().expect("step");
        }
        let moving = h.output::<VelocityCommand>("applied").expect("applied");
        assert!(moving.last().is_some_and(|c| c.v > 0.2), "driving again: {moving:?}");
        h.advance(Duration::from_secs(2)).expect("silence");
        let v = h.output::<VelocityCommand>("applied").expect("applied").last().map(|c| c.v);
        assert_eq!(v, Some(0.0), "dead man");

        // a command that is too old is refused and counted
        let refused = h.param("refused").expect("refused");
        h.send_from("cmd", "late", cmd(0.3, 0.0, h.now_ns().saturating_sub(1_000_000_000))).expect("send");
        h.step().expect("step");
        assert_ne!(h.param("refused").expect("refused"), refused);
        // stopping zeroes the wheels on the board
        drop(h.stop());
        let wheels = board.wheels_until(|w| w.left_mm_s == 0 && w.right_mm_s == 0);
        assert!(wheels.iter().any(|w| (w.left_mm_s, w.right_mm_s) == (0, 0)), "{wheels:?}");
    }

    /// Without a device the agent is declared (described, tested) but does
    /// not start, and says what to give.
    #[test]
    fn without_a_device_the_start_says_what_to_give() {
        match Harness::<Motor>::new() {
            Err(e) => assert!(e.to_string().contains("--device /dev/ttyUSB1"), "{e}"),
            Ok(_) => panic!("a motor without a device started"),
        }
    }
}
