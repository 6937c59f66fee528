//! Scenario `ros2` (issue 44's two measures): what the `ros2` agent costs on
//! rmw_zenoh's wire, the real agent (`nerve-ros2`) in a robot, a Zenoh
//! router (`nerve-ros2-router`, what `rmw_zenohd` is) on loopback, and the
//! ROS 2 side played by plain Zenoh sessions in this process
//! ([`wire`]). Every time is the epoch clock (CLOCK_REALTIME) of this one
//! machine: the clock of the ROS header stamps and of rmw_zenoh's
//! attachment.
//!
//! An SDK agent ([`source`]) sends, at pseudo-random gaps of 25-45 ms
//! (every phase of the agent's periodic step), in turn a 640x480 rgb8 frame
//! into its short-term-memory ring, and a `VelocityCommand` on a port
//! followed by a tiny "clock" frame into a second ring, all wired to the
//! `ros2` agent, which publishes them as `sensor_msgs/Image` and
//! `geometry_msgs/Twist` (CDR, attachment) through the router. Side by
//! side, a second Zenoh session of this process puts in turn the same
//! Image and Twist CDR bytes through the same router on keys of its own.
//!
//! The spans (each a median and p99 over the events, the first
//! [`DISCARD`] dropped):
//!
//! * Image `step → received`: from the start of the agent's step that took
//!   the frame (the Image's header stamp: the frame is stamped ahead, see
//!   [`source`]) until the bench's subscriber has it: the ring read in
//!   place, the CDR encoding (the one copy), the hand-over to the link
//!   thread, the attachment, the put, the router, the subscriber. Issue 44's
//!   "from the ring to a CDR Image on the wire" (target ≤ 2 ms);
//! * Image `written → received`: from the frame stored and announced in
//!   the ring: the above plus the agent's wake-up (it is event-driven);
//! * Image `step → put` and `put → received` (the attachment's timestamp):
//!   the agent's share and the wire's; raw Image `put → received`: the
//!   wire's floor for the same bytes;
//! * Twist through the agent, `step → received` (the step that took the
//!   command and its clock frame, when one step took both: the Twist's
//!   input comes first) and `sent → received` (from the command on the
//!   nerve port: the agent's wake-up, its step and put, the wire; the task
//!   puts a Twist itself, `nerve_ros2::route`); its parts `sent → step`
//!   (the wake-up) and `step → put` (the agent's share); raw `put →
//!   received`; the ratios of the medians (target ≤ 1.2x, issue 44's "one
//!   way through the agent": `sent → received`).

mod source;
mod wire;

pub use source::run_agent;

use crate::machine::Machine;
use crate::procs::{ChildGuard, Robot, self_command, wait_file};
use crate::report::Report;
use crate::stats::{Summary, ratio};
use anyhow::{Context as _, Result, bail};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Events dropped at the start (the session's first messages).
pub const DISCARD: usize = 5;
/// Issue 44: a 640x480 rgb8 Image from the ring onto the wire, median.
pub const TARGET_IMAGE_MS: f64 = 2.0;
/// Issue 44: Twist through the agent against a raw put, ratio of medians.
pub const TARGET_RATIO: f64 = 1.2;
/// The topics of the agent's configuration.
const IMAGE_TOPIC: &str = "/bench/image_raw";
const CLOCK_TOPIC: &str = "/bench/step";
const TWIST_TOPIC: &str = "/bench/cmd_vel";
const RAW_IMAGE_TOPIC: &str = "/bench/image_raw_raw";
const RAW_TWIST_TOPIC: &str = "/bench/cmd_vel_raw";

/// Options of the scenario.
#[derive(Debug, Clone)]
pub struct Ros2Opts {
    /// image events, as many Twist events, and as many raw puts of each
    pub count: usize,
    /// show the children's output
    pub verbose: bool,
    /// where the configuration and the source's file go
    pub work: PathBuf,
}

/// The work directory under `out`.
pub fn work_dir(out: &Path) -> PathBuf {
    out.join(format!("ros2-work-{}", std::process::id()))
}

/// The scenario's results.
#[derive(Debug, Clone, Serialize)]
pub struct Ros2Results {
    /// image events, as many Twist events (and raw puts of each)
    pub events: usize,
    /// events dropped at the start
    pub discarded: usize,
    /// how the ros2 agent's task runs ("event-driven": on its inputs and
    /// its waker; it ran every 20 ms before the SDK's waker)
    pub agent_task: String,
    /// the Image spans
    pub image: ImageSpans,
    /// the Twist spans
    pub twist: TwistSpans,
    /// issue 44's targets
    pub target_image_ms: f64,
    /// Twist through the agent / raw put, at most
    pub target_ratio: f64,
    /// what each span covers
    pub spans: Vec<(String, String)>,
    /// wall time of the run, s
    pub seconds: f64,
}

/// 640x480 rgb8 frames from the ring to the subscriber.
#[derive(Debug, Clone, Serialize)]
pub struct ImageSpans {
    /// Images received (of `events`), every one of the expected geometry
    pub received: usize,
    /// received Images whose geometry or size was wrong
    pub malformed: usize,
    /// start of the agent's step → received
    pub step_to_received: Summary,
    /// frame stored in the ring → received
    pub written_to_received: Summary,
    /// start of the step → the put (read, encode, hand-over)
    pub step_to_put: Summary,
    /// the put → received (Zenoh, the router)
    pub put_to_received: Summary,
    /// raw Images received (of `events`)
    pub raw_received: usize,
    /// the raw put of the same CDR → received
    pub raw_put_to_received: Summary,
    /// step → received / raw put → received (medians)
    pub ratio_step: f64,
}

/// Twist one way, through the agent and raw.
#[derive(Debug, Clone, Serialize)]
pub struct TwistSpans {
    /// Twists received through the agent (of `events`)
    pub received: usize,
    /// of them, taken in the same step as their clock frame (the `step` rows)
    pub paired: usize,
    /// raw puts received (of `events`)
    pub raw_received: usize,
    /// start of the agent's step → received
    pub agent_step_to_received: Summary,
    /// the command on the nerve port → received (with the wait for the step)
    pub agent_sent_to_received: Summary,
    /// the command on the nerve port → the start of the step that took it
    /// (the agent's wake-up; paired events only)
    pub agent_sent_to_step: Summary,
    /// the start of that step → the agent's put (the attachment's stamp:
    /// conversion, CDR, the put's own work in the task; paired
    /// events only)
    pub agent_step_to_put: Summary,
    /// the agent's put → received
    pub agent_put_to_received: Summary,
    /// the raw put → received
    pub raw_put_to_received: Summary,
    /// agent step → received / raw put → received (medians)
    pub ratio_step: f64,
    /// agent sent → received / raw put → received (medians)
    pub ratio_sent: f64,
    /// agent put → received / raw put → received (medians)
    pub ratio_put: f64,
}

/// The report written to `ros2.json`.
pub type Ros2Report = Report<Ros2Results>;

/// The agent's configuration: a client of the router at `endpoint`.
fn agent_config(endpoint: &str) -> String {
    format!(
        "# the ros2 scenario's agent (nerve-bench ros2)\n\
         node = \"nerve_bench\"\ndomain = 0\ndistro = \"jazzy\"\nmode = \"client\"\nconnect = [\"{endpoint}\"]\n\
         # first: the Twist is handed over before its clock frame is read\n\
         [[publish]]\ninput = \"cmd\"\nfrom = \"nerve::VelocityCommand\"\ntopic = \"{TWIST_TOPIC}\"\n\
         type = \"geometry_msgs/msg/Twist\"\n\
         [[publish]]\ninput = \"clock\"\nfrom = \"nerve::RingNotice\"\ntopic = \"{CLOCK_TOPIC}\"\n\
         type = \"sensor_msgs/msg/Image\"\n\
         [[publish]]\ninput = \"image\"\nfrom = \"nerve::RingNotice\"\ntopic = \"{IMAGE_TOPIC}\"\n\
         type = \"sensor_msgs/msg/Image\"\nframe_id = \"camera\"\nreliability = \"best_effort\"\n"
    )
}

/// The rmw_zenoh data key of `topic` of type `ros_type` in domain 0 (Jazzy).
fn key(ros_type: &str, topic: &str) -> Result<String> {
    let dds = nerve_ros2::wire::dds_type_name(ros_type).with_context(|| format!("{ros_type}: no DDS name"))?;
    let hash = nerve_ros2::type_hash(ros_type).with_context(|| format!("{ros_type}: no type hash"))?;
    Ok(nerve_ros2::wire::topic_key(0, topic, &dds, hash))
}

/// A span in ns (0 when the clock says it ran backwards).
fn span(from: i64, to: i64) -> u64 {
    u64::try_from(to.saturating_sub(from)).unwrap_or(0)
}

/// The images of `recs` among the kept events: `(i, rec)`.
fn kept<'a>(recs: &'a [wire::Received], n: usize) -> impl Iterator<Item = (usize, &'a wire::Received)> + 'a {
    recs.iter()
        .filter(|r| r.ok)
        .filter_map(move |r| usize::try_from(r.seq).ok().filter(|&i| i >= DISCARD && i < n).map(|i| (i, r)))
}

/// The spans of the events from `DISCARD` on.
fn spans(src: &source::Schedule, got: &wire::Received3) -> (ImageSpans, TwistSpans) {
    let (n_img, n_tw) = (src.images.len(), src.twists.len());
    let (mut s_recv, mut w_recv, mut s_put, mut p_recv) = (vec![], vec![], vec![], vec![]);
    for (i, r) in kept(&got.image, n_img) {
        s_recv.push(span(r.t_stamp, r.t_recv));
        w_recv.push(span(src.images[i], r.t_recv));
        s_put.push(span(r.t_stamp, r.t_put));
        p_recv.push(span(r.t_put, r.t_recv));
    }
    let raw_img: Vec<u64> = kept(&got.raw_image, n_img).map(|(_, r)| span(r.t_put, r.t_recv)).collect();
    let (step, raw_img) = (Summary::of(&s_recv), Summary::of(&raw_img));
    let image = ImageSpans {
        received: got.image.len(),
        malformed: got.image.iter().filter(|r| !r.ok).count(),
        ratio_step: ratio(step.p50_ns, raw_img.p50_ns),
        step_to_received: step,
        written_to_received: Summary::of(&w_recv),
        step_to_put: Summary::of(&s_put),
        put_to_received: Summary::of(&p_recv),
        raw_received: got.raw_image.len(),
        raw_put_to_received: raw_img,
    };
    let mut step_of = vec![None; n_tw];
    for (i, r) in kept(&got.clock, n_tw) {
        step_of[i] = Some(r.t_stamp);
    }
    let (mut a_step, mut a_sent, mut a_put) = (vec![], vec![], vec![]);
    let (mut a_wake, mut a_share) = (vec![], vec![]);
    for (i, r) in kept(&got.twist, n_tw) {
        let t_send = src.twists[i].0;
        a_sent.push(span(t_send, r.t_recv));
        a_put.push(span(r.t_put, r.t_recv));
        // the step that took the command took its clock frame too when it
        // began after the command was sent and before the Twist was put
        if let Some(step) = step_of[i].filter(|&s| s >= t_send && s <= r.t_put) {
            a_step.push(span(step, r.t_recv));
            a_wake.push(span(t_send, step));
            a_share.push(span(step, r.t_put));
        }
    }
    let raw: Vec<u64> = kept(&got.raw, n_tw).map(|(_, r)| span(r.t_put, r.t_recv)).collect();
    let (step, sent, put, raw_s) = (Summary::of(&a_step), Summary::of(&a_sent), Summary::of(&a_put), Summary::of(&raw));
    let twist = TwistSpans {
        received: got.twist.len(),
        paired: a_step.len(),
        raw_received: got.raw.len(),
        ratio_step: ratio(step.p50_ns, raw_s.p50_ns),
        ratio_sent: ratio(sent.p50_ns, raw_s.p50_ns),
        ratio_put: ratio(put.p50_ns, raw_s.p50_ns),
        agent_step_to_received: step,
        agent_sent_to_received: sent,
        agent_sent_to_step: Summary::of(&a_wake),
        agent_step_to_put: Summary::of(&a_share),
        agent_put_to_received: put,
        raw_put_to_received: raw_s,
    };
    (image, twist)
}

/// `nerve-ros2-router` on a free loopback port.
fn start_zenoh_router(robot: &Robot, verbose: bool) -> Result<(ChildGuard, String)> {
    let endpoint = format!("tcp/127.0.0.1:{}", crate::fleet::free_port()?);
    let router = crate::fleet::start_router(robot, &endpoint, verbose)?;
    Ok((router, endpoint))
}

/// Runs the scenario.
pub fn run(opts: &Ros2Opts) -> Result<Ros2Report> {
    let started = Instant::now();
    let machine = Machine::probe();
    if opts.count <= DISCARD {
        bail!("--count {}: more than the {DISCARD} events dropped at the start", opts.count);
    }
    std::fs::create_dir_all(&opts.work).with_context(|| format!("cannot create {}", opts.work.display()))?;
    let robot = Robot::new("ros2", opts.verbose)?;
    let _router = robot.start_router()?;
    let (mut zrouter, endpoint) = start_zenoh_router(&robot, opts.verbose)?;
    eprintln!("ros2: robot {}, Zenoh router on {endpoint}, {} events", robot.name, opts.count);
    let cfg_path = opts.work.join("ros2.toml");
    let cfg_text = agent_config(&endpoint);
    std::fs::write(&cfg_path, &cfg_text).with_context(|| format!("cannot write {}", cfg_path.display()))?;
    let cfg = nerve_ros2::config::parse(&cfg_path, &cfg_text, "ros2").map_err(|e| anyhow::anyhow!("{e}"))?;
    let cfg_arg = cfg_path.display().to_string();
    robot.run(&["start", "ros2", "--name", "ros2", "--", "--config", &cfg_arg])?;
    let mut src = self_command("__agent-ros2-src")?;
    src.args(["--robot", &robot.name, "--name", "src", "--suspended", "--"]);
    src.args(["--count", &opts.count.to_string(), "--out"]).arg(&opts.work);
    src.env("NERVE_HOME", &robot.home);
    robot.quiet(&mut src);
    let mut src = ChildGuard::spawn("agent src", src)?;
    robot.wait_registered(&["ros2", "src"], Duration::from_secs(20))?;
    robot.run(&["connect", "src/cmd", "ros2/cmd"])?;
    robot.run(&["connect", "src/frames", "ros2/image"])?;
    robot.run(&["connect", "src/clock", "ros2/clock"])?;
    let (image, twist) = ("sensor_msgs/msg/Image", "geometry_msgs/msg/Twist");
    let keys = wire::Keys {
        image: key(image, IMAGE_TOPIC)?,
        clock: key(image, CLOCK_TOPIC)?,
        twist: key(twist, TWIST_TOPIC)?,
        raw_image: key(image, RAW_IMAGE_TOPIC)?,
        raw_twist: key(twist, RAW_TWIST_TOPIC)?,
    };
    let collector = wire::Collector::new(&cfg, &keys)?;
    collector.wait_publishers(&[IMAGE_TOPIC, CLOCK_TOPIC, TWIST_TOPIC], Duration::from_secs(20))?;
    // the router learns of the subscribers; the connections settle
    std::thread::sleep(Duration::from_millis(500));
    let raw = {
        let (cfg, keys, count) = (cfg.clone(), keys.clone(), opts.count);
        std::thread::Builder::new()
            .name("raw-put".into())
            .spawn(move || wire::raw_puts(&cfg, &keys, count, source::Gaps::new(2, 25_000, 45_000)))
            .context("cannot start the raw publisher's thread")?
    };
    robot.run(&["resume", "src"])?;
    let done = opts.work.join("src.txt");
    let budget = Duration::from_millis(90 * opts.count as u64) + Duration::from_secs(30);
    if !wait_file(&done, budget, &mut [&mut src, &mut zrouter])? {
        bail!("the source agent did not finish its {} events within {budget:?}", opts.count);
    }
    raw.join().map_err(|_| anyhow::anyhow!("the raw publisher's thread panicked"))??;
    // the last messages arrive
    std::thread::sleep(Duration::from_millis(500));
    let got = collector.finish();
    zrouter.check_alive().context("the Zenoh router ended during the run")?;
    let src_rows = source::read_rows(&done)?;
    let (image, twist) = spans(&src_rows, &got);
    Ok(Report::new(
        "ros2",
        machine,
        Ros2Results {
            events: opts.count,
            discarded: DISCARD,
            agent_task: "event-driven".into(),
            image,
            twist,
            target_image_ms: TARGET_IMAGE_MS,
            target_ratio: TARGET_RATIO,
            spans: span_notes(),
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
}

fn span_notes() -> Vec<(String, String)> {
    [
        (
            "step → received",
            "from the start of the ros2 agent's step that took the frame (the Image's header stamp) to the subscriber: ring read in place, CDR encoding (one copy), hand-over to the link thread, attachment, put, router, subscriber",
        ),
        ("written → received", "from the frame stored and announced in the ring: the above plus the event-driven agent's wake-up"),
        ("step → put", "the agent's share: read, encode, hand-over, attachment (its put stamp)"),
        ("put → received", "the wire's share: Zenoh through the router to the subscriber"),
        ("raw Image put → received", "a second Zenoh session of the bench puts the same Image CDR (encoded before) through the same router"),
        (
            "Twist step → received",
            "from the start of the step that took the command (its clock frame's header stamp; the Twist's input first) to the subscriber",
        ),
        ("Twist sent → step", "from the command sent on the nerve port to the start of the step that took it: the agent's wake-up on its input"),
        ("Twist step → put", "from the start of that step to the agent's put (the attachment's stamp): conversion, CDR, the attachment (the task puts a Twist itself; it handed it to the link thread before issue 44's change)"),
        ("Twist sent → received", "from the command sent on the nerve port: the agent's wake-up on its input, its step and put, the wire (issue 44's one way through the agent)"),
        ("raw put → received", "a second Zenoh session of the bench puts the same Twist CDR and an attachment through the same router"),
    ]
    .iter()
    .map(|(a, b)| ((*a).to_owned(), (*b).to_owned()))
    .collect()
}

fn ms(ns: u64) -> f64 {
    ns as f64 / 1e6
}

/// The results as tables.
pub fn print_tables(r: &Ros2Report) {
    let row = |name: &str, s: &Summary| {
        println!("| {name} | {} | {:.3} | {:.3} | {:.3} |", s.n, ms(s.p50_ns), ms(s.p99_ns), ms(s.max_ns));
    };
    println!(
        "ros2 agent on rmw_zenoh's wire through a Zenoh router ({} events of each kind, agent {}; targets: Image step → received ≤ {} ms, Twist ≤ {}x raw)\n",
        r.events, r.agent_task, r.target_image_ms, r.target_ratio
    );
    println!(
        "| 640x480 rgb8 Image ({} of {} received) | n | median ms | p99 ms | max ms |",
        r.image.received, r.events
    );
    println!("|---|---:|---:|---:|---:|");
    row("step → received", &r.image.step_to_received);
    row("written → received", &r.image.written_to_received);
    row("step → put (agent)", &r.image.step_to_put);
    row("put → received (wire)", &r.image.put_to_received);
    row("raw put → received", &r.image.raw_put_to_received);
    println!("\nImage step → received / raw put → received (medians): {:.2}x\n", r.image.ratio_step);
    println!("| Twist one way | n | median ms | p99 ms | max ms |");
    println!("|---|---:|---:|---:|---:|");
    row("agent: step → received", &r.twist.agent_step_to_received);
    row("agent: sent → received", &r.twist.agent_sent_to_received);
    row("agent: sent → step (wake-up)", &r.twist.agent_sent_to_step);
    row("agent: step → put (agent)", &r.twist.agent_step_to_put);
    row("agent: put → received", &r.twist.agent_put_to_received);
    row("raw put → received", &r.twist.raw_put_to_received);
    println!(
        "\nTwist through the agent / raw put (medians): {:.2}x from the send (one way through the agent), {:.2}x from the step, {:.2}x from the agent's put",
        r.twist.ratio_sent, r.twist.ratio_step, r.twist.ratio_put
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(seq: u64, t_recv: i64, t_put: i64, t_stamp: i64) -> wire::Received {
        wire::Received { seq, t_recv, t_put, t_stamp, ok: true }
    }

    /// The spans of hand-made events: a Twist is paired with its clock
    /// frame's step only when that step began between its send and its put.
    #[test]
    fn spans_pair_a_twist_with_its_clock_frames_step() {
        let n = DISCARD + 2;
        let (a, b) = (DISCARD as u64, DISCARD as u64 + 1);
        let (ta, tb) = (DISCARD as i64 * 1000, DISCARD as i64 * 1000 + 1000);
        let src = source::Schedule {
            images: (0..n as i64).map(|i| i * 1000 + 10).collect(),
            twists: (0..n as i64).map(|i| (i * 1000, i * 1000 + 5)).collect(),
        };
        let got = wire::Received3 {
            // frame a taken in a step at +100, frame b at +50
            image: vec![rec(0, 1, 1, 1), rec(a, ta + 600, ta + 300, ta + 100), rec(b, tb + 450, tb + 250, tb + 50)],
            clock: vec![rec(a, ta + 300, ta + 200, ta + 100), rec(b, tb + 300, tb + 200, tb + 50)],
            // twist a put after its clock's step began; twist b put before (an earlier step)
            twist: vec![rec(a, ta + 200, ta + 150, 0), rec(b, tb + 40, tb + 30, 0)],
            raw_image: vec![rec(a, 900, 100, 0)],
            raw: vec![rec(a, 75, 0, 0), rec(b, 125, 1, 0)],
        };
        let (img, tw) = spans(&src, &got);
        assert_eq!(img.step_to_received.n, 2, "event 0 is dropped");
        assert_eq!((img.step_to_received.min_ns, img.step_to_received.max_ns), (400, 500));
        assert_eq!((img.written_to_received.min_ns, img.written_to_received.max_ns), (440, 590));
        assert_eq!(img.raw_put_to_received.p50_ns, 800);
        assert_eq!(tw.paired, 1);
        assert_eq!(tw.agent_step_to_received.p50_ns, 100);
        // twist a: sent at ta, its step at ta + 100, put at ta + 150
        assert_eq!((tw.agent_sent_to_step.n, tw.agent_sent_to_step.p50_ns), (1, 100));
        assert_eq!(tw.agent_step_to_put.p50_ns, 50);
        assert_eq!(tw.agent_sent_to_received.n, 2);
        assert_eq!((tw.raw_put_to_received.min_ns, tw.raw_put_to_received.max_ns), (75, 124));
        assert!(agent_config("tcp/127.0.0.1:7447").contains("[[publish]]"));
    }
}
