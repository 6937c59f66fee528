//! Scenario `foxglove`: what `nerve foxglove` costs (issue 45), side by side
//! in one run, with Foxglove's own protocol library as the client (npm
//! `@foxglove/ws-protocol`, the script `tests/js/foxglove/client.js`):
//!
//! - the one-hop round trip of SDK agents while `nerve foxglove` serves a
//!   client subscribed to every channel (the hop's own ports included, each
//!   sample decoded to JSON and sent) vs without them, batch by batch
//!   interleaved; target: the median with them at most 1.05x without;
//! - a 640x480 camera (the camera agent's test pattern) at 30 fps to one
//!   client reading its frames as `foxglove.RawImage`: the server's CPU per
//!   frame delivered, and the frames announced (the ring notices' sequence
//!   numbers) vs the images delivered.

use crate::machine::Machine;
use crate::observed::{ObservedHop, WithObserver, hop_with_and_without, print_table};
use crate::procs::{ChildGuard, Robot};
use crate::recording::cpu_seconds;
use crate::report::Report;
use crate::stats::Summary;
use anyhow::{Context as _, Result, bail};
use serde::Serialize;
use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

/// The client may make the round trip this much slower.
pub const TARGET_RATIO: f64 = 1.05;
/// The camera's frames.
const CAMERA: (u32, u32, f64) = (640, 480, 30.0);

/// Options of the foxglove scenario.
#[derive(Debug, Clone)]
pub struct FoxOpts {
    /// smoke run
    pub quick: bool,
    /// payload sizes of the hop (bytes)
    pub sizes: Vec<usize>,
    /// measured rounds
    pub rounds: usize,
    /// seconds the camera's frames are counted
    pub camera_seconds: f64,
    /// the client script (`tests/js/foxglove/client.js`, its packages installed)
    pub client: PathBuf,
    /// show children's output
    pub verbose: bool,
    /// where batch files go
    pub work: PathBuf,
}

/// The hop with and without the client, one size.
pub type FoxHop = ObservedHop<WithFoxglove>;

/// Round trips while `nerve foxglove` serves a client subscribed to every
/// channel (`with_foxglove` in the JSON).
#[derive(Debug, Clone, Serialize)]
pub struct WithFoxglove {
    /// round trips while `nerve foxglove` serves a client subscribed to every channel, ns
    pub with_foxglove: Summary,
}

impl WithObserver for WithFoxglove {
    fn new(with_foxglove: Summary) -> Self {
        WithFoxglove { with_foxglove }
    }

    fn summary(&self) -> &Summary {
        &self.with_foxglove
    }
}

/// A camera's frames to one reading client.
#[derive(Debug, Clone, Serialize)]
pub struct CameraCost {
    /// frame width, pixels
    pub width: u32,
    /// frame height, pixels
    pub height: u32,
    /// the camera's rate, frames per second
    pub fps: f64,
    /// how long the client counted, s
    pub seconds: f64,
    /// frames the camera announced while the client counted (ring notices' sequence numbers, last - first + 1)
    pub announced: u64,
    /// ring notices the client received
    pub notices: u64,
    /// `foxglove.RawImage` messages the client received
    pub delivered: u64,
    /// announced - delivered
    pub dropped: u64,
    /// bytes of the image messages (JSON, the pixels in base64)
    pub bytes: u64,
    /// CPU of `nerve foxglove` while the client counted, s (user + system)
    pub server_cpu_s: f64,
    /// server CPU per frame delivered, ms
    pub server_cpu_ms_per_frame: f64,
    /// server CPU, percent of one core
    pub server_cpu_percent: f64,
}

/// The foxglove report: the [`Head`](crate::report::Head) and [`FoxResults`].
pub type FoxReport = Report<FoxResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Clone, Serialize)]
pub struct FoxResults {
    /// measured rounds
    pub rounds: usize,
    /// the hop with and without the client
    pub hop: Vec<FoxHop>,
    /// the target
    pub target_ratio: f64,
    /// the channels the client subscribed to during the hop
    pub hop_channels: Vec<String>,
    /// the camera to one client
    pub camera: CameraCost,
    /// node's version
    pub node: String,
    /// wall time
    pub seconds: f64,
}

fn free_addr() -> Result<String> {
    Ok(format!("127.0.0.1:{}", std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port()))
}

/// `nerve foxglove` on a free loopback port, listening.
fn start_server(robot: &Robot) -> Result<(ChildGuard, String)> {
    let addr = free_addr()?;
    let mut cmd = robot.nerve();
    cmd.args(["foxglove", "--bind", &addr]).stdin(Stdio::null());
    robot.quiet(&mut cmd);
    let mut server = ChildGuard::spawn("nerve foxglove", cmd)?;
    let t0 = Instant::now();
    while std::net::TcpStream::connect(&addr).is_err() {
        server.check_alive()?;
        if t0.elapsed() > Duration::from_secs(10) {
            bail!("nerve foxglove did not listen on {addr} within 10 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok((server, format!("ws://{addr}")))
}

/// `node client.js ARGS` with its stdout piped (its stderr shown with `--verbose`).
fn start_client(opts: &FoxOpts, args: &[&str]) -> Result<(ChildGuard, BufReader<ChildStdout>)> {
    let mut cmd = Command::new("node");
    cmd.arg(&opts.client).args(args).stdin(Stdio::null()).stdout(Stdio::piped());
    if !opts.verbose {
        cmd.stderr(Stdio::null());
    }
    let mut client = ChildGuard::spawn("node client.js", cmd).context("cannot run node")?;
    let out = client.stdout().context("the client's stdout")?;
    Ok((client, BufReader::new(out)))
}

/// The client's next JSON line (it bounds its own run, so this ends).
fn next_line(client: &mut ChildGuard, out: &mut BufReader<ChildStdout>) -> Result<serde_json::Value> {
    let mut line = String::new();
    let n = out.read_line(&mut line).context("cannot read the client's output")?;
    if n == 0 {
        client.check_alive()?;
        bail!("the client ended without a word");
    }
    let v: serde_json::Value =
        serde_json::from_str(&line).with_context(|| format!("the client printed no JSON: {line:?}"))?;
    if let Some(e) = v.get("error") {
        bail!("the client failed: {e}");
    }
    Ok(v)
}

/// `nerve foxglove` and a client subscribed to every channel; the channels.
fn open_client(robot: &Robot, opts: &FoxOpts) -> Result<(Vec<ChildGuard>, Vec<String>)> {
    let (server, url) = start_server(robot)?;
    // read until killed at the end of the batch (an hour at most)
    let (mut client, mut out) = start_client(opts, &["all", &url, "3600000"])?;
    let said = next_line(&mut client, &mut out)?;
    let topics: Vec<String> = said["subscribed"]
        .as_array()
        .map(|a| a.iter().filter_map(|t| t.as_str().map(str::to_owned)).collect())
        .unwrap_or_default();
    // the serving thread opens the subscribed ports on its next wake-up; the batch settles 100 ms first
    std::thread::sleep(Duration::from_millis(300));
    // its output is not read again: the pipe's 64 kB hold its one last line
    drop(out);
    Ok((vec![client, server], topics))
}

/// The camera at [`CAMERA`] on its test pattern, `nerve foxglove` and a
/// client counting its frames for `seconds`.
fn camera(robot: &Robot, opts: &FoxOpts) -> Result<CameraCost> {
    let (w, h, fps) = CAMERA;
    let (ws, hs, fs) = (w.to_string(), h.to_string(), fps.to_string());
    let args = ["start", "camera", "--name", "fcam", "--", "--source", "test-pattern", "--width", &ws, "--height", &hs];
    robot.run(&[&args[..], &["--fps", &fs]].concat())?;
    robot.wait_registered(&["fcam"], Duration::from_secs(20))?;
    let (mut server, url) = start_server(robot)?;
    let ms = (opts.camera_seconds * 1000.0).round().to_string();
    let (mut client, mut out) = start_client(opts, &["camera", &url, "/fcam/frames", &ms])?;
    let said = next_line(&mut client, &mut out)?;
    if said["counting"] != true {
        bail!("the camera client said {said}");
    }
    let cpu0 = cpu_seconds(server.id()).context("the server's CPU time")?;
    let end = next_line(&mut client, &mut out)?;
    let cpu1 = cpu_seconds(server.id()).context("the server's CPU time")?;
    server.check_alive().context("nerve foxglove died while serving the camera")?;
    client.stop(Duration::from_secs(2));
    server.stop(Duration::from_secs(5));
    robot.run(&["stop", "fcam"])?;
    let num = |k: &str| end[k].as_u64().unwrap_or(0);
    let seconds = end["seconds"].as_f64().unwrap_or(0.0);
    let (announced, delivered) = (num("announced"), num("images"));
    let cpu = (cpu1 - cpu0).max(0.0);
    Ok(CameraCost {
        width: u32::try_from(num("width")).unwrap_or(0),
        height: u32::try_from(num("height")).unwrap_or(0),
        fps,
        seconds,
        announced,
        notices: num("notices"),
        delivered,
        dropped: announced.saturating_sub(delivered),
        bytes: num("bytes"),
        server_cpu_s: cpu,
        server_cpu_ms_per_frame: if delivered > 0 { cpu * 1000.0 / delivered as f64 } else { 0.0 },
        server_cpu_percent: if seconds > 0.0 { cpu * 100.0 / seconds } else { 0.0 },
    })
}

/// Runs the scenario.
pub fn run(opts: &FoxOpts) -> Result<FoxReport> {
    let started = Instant::now();
    let machine = Machine::probe();
    std::fs::create_dir_all(&opts.work).with_context(|| format!("cannot create {}", opts.work.display()))?;
    let packages = opts.client.with_file_name("node_modules").join("@foxglove").join("ws-protocol");
    if !packages.is_dir() {
        bail!(
            "the client's packages are missing ({}): run `npm ci --prefix {}`",
            packages.display(),
            opts.client.parent().map_or_else(String::new, |p| p.display().to_string())
        );
    }
    let node = Command::new("node")
        .arg("--version")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
        .context("cannot run node")?;
    let robot = Robot::new("f", opts.verbose)?;
    eprintln!(
        "foxglove: robot {} (hop sizes {:?}, {} rounds, camera {} s, node {node})",
        robot.name, opts.sizes, opts.rounds, opts.camera_seconds
    );
    let router = robot.start_router()?;
    let mut hop_channels = Vec::new();
    let mut observe = || {
        let (children, topics) = open_client(&robot, opts)?;
        hop_channels = topics;
        Ok(children)
    };
    let measured = hop_with_and_without(&robot, &opts.sizes, opts.rounds, opts.quick, &opts.work, "f", &mut observe)?;
    let camera = camera(&robot, opts)?;
    drop(router);
    drop(robot);
    Ok(Report::new(
        "foxglove",
        machine,
        FoxResults {
            rounds: opts.rounds,
            hop: measured.into_iter().map(|m| FoxHop::of(m, TARGET_RATIO)).collect(),
            target_ratio: TARGET_RATIO,
            hop_channels,
            camera,
            node,
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
}

/// Prints the tables (markdown).
pub fn print_tables(r: &FoxReport) {
    let rows = r.hop.iter().map(FoxHop::row);
    let title = format!(
        "One hop while `nerve foxglove` serves a client subscribed to all {} channels (round trip, µs)",
        r.hop_channels.len()
    );
    print_table(&title, TARGET_RATIO, rows);
    let c = &r.camera;
    println!("\n### A {}x{} camera at {} fps to one Foxglove client\n", c.width, c.height, c.fps);
    println!("| seconds | frames announced | delivered | dropped | server CPU per frame | server CPU |");
    println!("|---|---|---|---|---|---|");
    println!(
        "| {:.1} | {} | {} | {} | {:.2} ms | {:.1} % |",
        c.seconds, c.announced, c.delivered, c.dropped, c.server_cpu_ms_per_frame, c.server_cpu_percent
    );
}

/// Where the scenario's files go.
pub fn work_dir(out: &Path) -> PathBuf {
    out.join("foxglove-work")
}

/// The client script of the repository this benchmark was built from.
pub fn default_client() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("tests").join("js").join("foxglove").join("client.js")
}
