//! `nerve cmd AGENT ...`: send one command to an actuator agent from the
//! terminal.
//!
//! ```text
//! nerve cmd motor "turn right a little"          # linguistic -> input `say`
//! nerve cmd motor --v 0.2 --w 0.0                # numeric    -> input `cmd`
//! nerve cmd motor --stop [--allow-turn]          # safety stop -> input `stop`
//! nerve cmd motor --release                      # release the CLI's stop
//! nerve cmd head --pan 30 --tilt -10             # head set-point (degrees) -> `cmd`
//! nerve cmd motor --v 0.2 --hold 3s              # repeat every 100 ms for 3 s
//! ```
//!
//! **How it reaches the agent: through the router, like any source.** The
//! command line is not an agent, so `nerve cmd` publishes on a port of its
//! own, `nerve/<robot>/cli-<pid>/<input>` (made with the SDK's
//! `port_service`/`port_event`, so its settings match every agent's), and
//! asks the router to attach it to the input (`CliRequest::Attach`). The
//! router checks the input and the type (a head command to the motor is
//! refused with the router's message, as `nerve connect` would be), has the
//! agent subscribe, and shows the edge in `nerve graph` as transient. The
//! sample header's sender is `--sender` (default `cli`; actuators keep one
//! command per sender and weight senders by name). `nerve cmd` waits until
//! the agent's statistics (`CliRequest::Agent`) show it received what was
//! sent, then detaches. The edge is never saved; if `nerve cmd` is killed
//! first, the router removes it when it sees the process gone.
//!
//! Commands are stamped now. Actuators drop commands after their `stale_ms`
//! (500 ms by default), so a single command moves the robot only briefly;
//! `--hold DURATION` repeats it every 100 ms for that long. Unknown phrases
//! are refused with the list of known ones.

use crate::client::RouterSession;
use agent_sdk::World;
use agent_sdk::clock::now_ns;
use agent_sdk::ports::{port_event, port_service};
use anyhow::{Context as _, Result, anyhow, bail};
use shm_schemas::control::cli_to_router::CliRequest;
use shm_schemas::payloads::{HeadCommand, LinguisticCommand, LinguisticTerm, SafetyStop, VelocityCommand};
use shm_schemas::{AgentName, FixedName, Payload, PortRef, SampleHeader};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use crate::cmd::publish::DELIVERY_TIMEOUT;

/// Interval of `--hold` repetitions.
const REPEAT: Duration = Duration::from_millis(100);

/// Arguments of `nerve cmd`.
#[derive(Debug, clap::Args)]
#[command(about = "Send one command to an actuator agent (motor, head) from the terminal")]
pub struct CmdArgs {
    /// The actuator agent, e.g. `motor`.
    pub agent: String,
    /// A linguistic command, e.g. "turn right a little" (sent to input `say`).
    pub text: Option<String>,
    /// Forward speed, m/s (numeric command to input `cmd`, with --w).
    #[arg(long, allow_hyphen_values = true)]
    pub v: Option<f64>,
    /// Turn rate, rad/s, positive to the left (numeric command, with --v).
    #[arg(long, allow_hyphen_values = true)]
    pub w: Option<f64>,
    /// Head pan, degrees, positive to the left (head set-point, with --tilt).
    #[arg(long, allow_hyphen_values = true)]
    pub pan: Option<f64>,
    /// Head tilt, degrees, positive up (head set-point, with --pan).
    #[arg(long, allow_hyphen_values = true)]
    pub tilt: Option<f64>,
    /// Intensity of a linguistic command, 0..1.
    #[arg(long, default_value_t = 1.0)]
    pub intensity: f32,
    /// Send a safety stop (input `stop`): the base stops whatever else it is told.
    #[arg(long)]
    pub stop: bool,
    /// With --stop: stop moving but allow turning on the spot.
    #[arg(long, requires = "stop")]
    pub allow_turn: bool,
    /// Release the stop this sender gave earlier.
    #[arg(long, conflicts_with = "stop")]
    pub release: bool,
    /// Repeat the command every 100 ms for this long (e.g. 3s); default: send once.
    #[arg(long)]
    pub hold: Option<String>,
    /// Sender name the agent sees (its weight is looked up by this name).
    #[arg(long, default_value = "cli")]
    pub sender: String,
    /// Input port to send to (default: `say`, `cmd` or `stop` by the kind of command).
    #[arg(long)]
    pub input: Option<String>,
}

/// What to send.
#[derive(Debug, Clone, Copy)]
enum Command {
    Velocity(VelocityCommand),
    Say(LinguisticCommand),
    Stop(SafetyStop),
    Head(HeadCommand),
}

impl Command {
    fn restamp(&mut self, now: u64) {
        match self {
            Command::Velocity(c) => c.stamp_ns = now,
            Command::Say(c) => c.stamp_ns = now,
            Command::Stop(c) => c.stamp_ns = now,
            Command::Head(c) => c.stamp_ns = now,
        }
    }

    fn default_input(&self) -> &'static str {
        match self {
            Command::Say(_) => "say",
            Command::Stop(_) => "stop",
            Command::Velocity(_) | Command::Head(_) => "cmd",
        }
    }
}

fn parse(a: &CmdArgs) -> Result<Command> {
    let now = now_ns();
    let kinds =
        [a.text.is_some(), a.v.is_some() || a.w.is_some(), a.pan.is_some() || a.tilt.is_some(), a.stop || a.release]
            .iter()
            .filter(|b| **b)
            .count();
    if kinds != 1 {
        bail!(
            "say what to send, one kind at a time: a phrase (\"turn right a little\"), --v/--w, --pan/--tilt, --stop or --release"
        );
    }
    if let Some(text) = &a.text {
        let Some(term) = LinguisticTerm::parse(text) else {
            bail!("unknown command {text:?}; known phrases: {}", LinguisticTerm::known_phrases().join(", "));
        };
        if !(a.intensity.is_finite() && (0.0..=1.0).contains(&a.intensity)) {
            bail!("--intensity {} must be between 0 and 1", a.intensity);
        }
        return Ok(Command::Say(LinguisticCommand::new(term, a.intensity, now)));
    }
    if a.v.is_some() || a.w.is_some() {
        let (v, w) = (a.v.unwrap_or(0.0), a.w.unwrap_or(0.0));
        if !(v.is_finite() && w.is_finite()) {
            bail!("--v and --w must be finite numbers");
        }
        return Ok(Command::Velocity(VelocityCommand { v, omega: w, stamp_ns: now }));
    }
    if a.pan.is_some() || a.tilt.is_some() {
        let (p, t) = (a.pan.unwrap_or(0.0), a.tilt.unwrap_or(0.0));
        if !(p.is_finite() && t.is_finite()) {
            bail!("--pan and --tilt must be finite numbers (degrees)");
        }
        return Ok(Command::Head(HeadCommand { pan_rad: p.to_radians(), tilt_rad: t.to_radians(), stamp_ns: now }));
    }
    Ok(Command::Stop(SafetyStop {
        active: u8::from(a.stop),
        allow_turn: u8::from(a.allow_turn),
        reserved: [0; 2],
        hold_ms: 0,
        stamp_ns: now,
    }))
}

/// `nerve cmd`: see the module documentation.
pub fn cmd(world: &World, a: CmdArgs) -> Result<ExitCode> {
    let command = parse(&a)?;
    let agent = AgentName::new(&a.agent).with_context(|| format!("agent name {:?}", a.agent))?;
    if a.sender.is_empty() || a.sender.len() > shm_schemas::fixed::FIXED_NAME_CAPACITY {
        bail!("--sender must be 1 to {} bytes", shm_schemas::fixed::FIXED_NAME_CAPACITY);
    }
    let hold = match &a.hold {
        Some(h) => Some(agent_sdk::clock::parse_duration(h).map_err(anyhow::Error::msg).context("--hold")?),
        None => None,
    };
    let input = a.input.clone().unwrap_or_else(|| command.default_input().to_owned());
    match command {
        Command::Velocity(c) => send(world, &agent, &input, &a.sender, Command::Velocity(c), c, hold),
        Command::Say(c) => send(world, &agent, &input, &a.sender, Command::Say(c), c, hold),
        Command::Stop(c) => send(world, &agent, &input, &a.sender, Command::Stop(c), c, hold),
        Command::Head(c) => send(world, &agent, &input, &a.sender, Command::Head(c), c, hold),
    }
}

fn send<T: Payload>(
    world: &World,
    agent: &AgentName,
    input: &str,
    sender: &str,
    mut command: Command,
    first: T,
    hold: Option<Duration>,
) -> Result<ExitCode> {
    let session = RouterSession::open(world)?;
    let from = PortRef::new(&format!("cli-{}", std::process::id()), input).context("the command line's port")?;
    let to = PortRef::new(agent.as_str(), input).with_context(|| format!("input {input:?}"))?;
    let service = world.robot().port_service(from.agent.as_str(), input);
    let publisher = port_service::<T>(session.node()?, &service)?
        .publisher_builder()
        .create()
        .map_err(|e| anyhow!("cannot create a publisher on {service}: {e:?}"))?;
    let notifier = port_event(session.node()?, &service)?
        .notifier_builder()
        .create()
        .map_err(|e| anyhow!("cannot create a notifier on {service}: {e:?}"))?;
    session.ok(CliRequest::Attach {
        from: from.clone(),
        pid: std::process::id(),
        type_name: T::stable_type_name().to_owned(),
        fingerprint: T::layout_fingerprint(),
        to: to.clone(),
    })?;

    let result = (|| -> Result<u64> {
        let fixed_sender = FixedName::new(sender);
        let mut seq = 0u64;
        let t0 = Instant::now();
        let publish = |value: T, seq: &mut u64| -> Result<usize> {
            let mut sample =
                publisher.loan_uninit().map_err(|e| anyhow!("cannot loan a sample on {service}: {e:?}"))?;
            *sample.user_header_mut() = SampleHeader { sender: fixed_sender, seq: *seq + 1, stamp_ns: now_ns() };
            let n = sample.write_payload(value).send().map_err(|e| anyhow!("cannot send on {service}: {e:?}"))?;
            if n > 0 {
                *seq += 1;
                let _ = notifier.notify();
            }
            Ok(n)
        };
        // the agent answered once subscribed; the publisher may see it a moment later
        let mut value = first;
        loop {
            if publish(value, &mut seq)? > 0 {
                break;
            }
            if t0.elapsed() > DELIVERY_TIMEOUT {
                bail!("{to} did not subscribe within {DELIVERY_TIMEOUT:?}");
            }
            std::thread::sleep(Duration::from_millis(5));
            command.restamp(now_ns());
            value = restamped::<T>(&command).unwrap_or(value);
        }
        if let Some(hold) = hold {
            while t0.elapsed() < hold {
                std::thread::sleep(REPEAT);
                command.restamp(now_ns());
                if let Some(v) = restamped::<T>(&command) {
                    publish(v, &mut seq)?;
                }
            }
        }
        Ok(seq)
    })();

    // wait until the agent has taken what we sent, then detach
    let sent = result.as_ref().copied().unwrap_or(0);
    let received = crate::cmd::publish::wait_taken_and_detach(&session, &from, &to, sent);
    let sent = result?;
    if received < sent {
        bail!(
            "{to} took {received} of {sent} command(s) within {DELIVERY_TIMEOUT:?}; is its task running (`nerve ps`)?"
        );
    }
    let what = match command {
        Command::Velocity(c) => format!("v {:.3} m/s, w {:.3} rad/s", c.v, c.omega),
        Command::Say(c) => format!("\"{}\" (intensity {})", c.term().map_or("?", |t| t.phrase()), c.intensity),
        Command::Stop(c) if c.active != 0 => {
            format!("safety stop{}", if c.allow_turn != 0 { " (turning allowed)" } else { "" })
        }
        Command::Stop(_) => "release of the stop".to_owned(),
        Command::Head(c) => format!("pan {:.1}°, tilt {:.1}°", c.pan_rad.to_degrees(), c.tilt_rad.to_degrees()),
    };
    println!(
        "{agent}/{input} <- {what} from {sender:?}{}",
        if sent > 1 { format!(" ({sent} times)") } else { String::new() }
    );
    Ok(ExitCode::SUCCESS)
}

/// The command as `T` (the type this invocation sends), freshly stamped.
fn restamped<T: Payload>(c: &Command) -> Option<T> {
    use std::any::Any;
    let any: Box<dyn Any> = match *c {
        Command::Velocity(v) => Box::new(v),
        Command::Say(v) => Box::new(v),
        Command::Stop(v) => Box::new(v),
        Command::Head(v) => Box::new(v),
    };
    any.downcast::<T>().ok().map(|b| *b)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(text: Option<&str>) -> CmdArgs {
        CmdArgs {
            agent: "motor".into(),
            text: text.map(str::to_owned),
            v: None,
            w: None,
            pan: None,
            tilt: None,
            intensity: 1.0,
            stop: false,
            allow_turn: false,
            release: false,
            hold: None,
            sender: "cli".into(),
            input: None,
        }
    }

    #[test]
    fn phrases_and_refusals() {
        assert!(matches!(parse(&args(Some("turn right a little"))), Ok(Command::Say(_))));
        let e = parse(&args(Some("dance"))).expect_err("unknown").to_string();
        assert!(e.contains("known phrases") && e.contains("turn right a little"), "{e}");
        assert!(parse(&args(None)).is_err());
        let mut a = args(None);
        a.v = Some(0.2);
        assert!(matches!(parse(&a), Ok(Command::Velocity(VelocityCommand { v, .. })) if v == 0.2));
        a.text = Some("stop".into());
        assert!(parse(&a).is_err(), "two kinds at once");
    }
}
