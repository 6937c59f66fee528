//! Scenario `record`: what recording costs the robot (issue 14).
//!
//! * **hop**: the one-hop round trip of SDK agents (`ping → pong → ping`,
//!   as in `pipeline`) with `nerve record --all` running and without it,
//!   batch by batch interleaved; target: the median with it at most 1.05x
//!   the median without.
//! * **images**: a camera agent (test pattern) at 640x480 and 30 fps, then
//!   1920x1080 and 15 fps, recorded with `nerve record cam/frames` for 60 s
//!   (10 s with `--quick`): the frames it wrote and dropped, MB/s to disk,
//!   and the recorder's CPU (its user + system time over the wall time, from
//!   `/proc/PID/stat`).
//! * **echo**: the CPU of `nerve echo --count N --json` on a built-in type
//!   (`nerve::Tick`) and on a type nerve was not built with
//!   (`acme::Gripper`, the test crate's `nerve-gripper`), both at 50 Hz,
//!   interleaved: a custom type should cost no more.

use crate::machine::Machine;
use crate::observed::{ObservedHop, WithObserver, hop_with_and_without, print_table};
use crate::procs::{ChildGuard, Robot};
use crate::report::Report;
use crate::stats::{Rounds, Summary, median_f64};
use anyhow::{Context as _, Result, bail};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

/// The recorder may make the round trip this much slower.
pub const TARGET_RATIO: f64 = 1.05;

/// Options of the record scenario.
#[derive(Debug, Clone)]
pub struct RecordOpts {
    /// smoke run
    pub quick: bool,
    /// payload sizes of the hop (bytes)
    pub sizes: Vec<usize>,
    /// measured rounds of the hop
    pub rounds: usize,
    /// seconds per image recording
    pub image_seconds: f64,
    /// echo runs per type
    pub echo_runs: usize,
    /// show children's output
    pub verbose: bool,
    /// where batch files and recordings go
    pub work: PathBuf,
}

/// The hop with and without the recorder, one size.
pub type HopCost = ObservedHop<WithRecorder>;

/// Round trips while `nerve record --all` runs, ns (`with_recorder` in the JSON).
#[derive(Debug, Clone, Serialize)]
pub struct WithRecorder {
    /// round trips while `nerve record --all` runs, ns
    pub with_recorder: Summary,
}

impl WithObserver for WithRecorder {
    fn new(with_recorder: Summary) -> Self {
        WithRecorder { with_recorder }
    }

    fn summary(&self) -> &Summary {
        &self.with_recorder
    }
}

/// One image recording.
#[derive(Debug, Clone, Serialize)]
pub struct ImageRun {
    /// WxH
    pub resolution: String,
    /// frames per second asked of the camera
    pub fps: f64,
    /// seconds recorded
    pub seconds: f64,
    /// notices the recorder read (frames the camera announced)
    pub notices: u64,
    /// frames written as images
    pub frames: u64,
    /// frames lost: overwritten in the ring before the recorder read them, plus notices missed
    pub dropped: u64,
    /// what the camera delivered, frames/s
    pub camera_fps: f64,
    /// MB written per second
    pub mb_per_s: f64,
    /// the recorder's CPU, percent of one core
    pub recorder_cpu_percent: f64,
    /// the file's size, MB
    pub file_mb: f64,
}

/// `nerve echo` of one type.
#[derive(Debug, Clone, Serialize)]
pub struct EchoCost {
    /// the port
    pub port: String,
    /// its type
    pub type_name: String,
    /// samples printed per run
    pub samples: u64,
    /// CPU of each run (user + system), ms
    pub cpu_ms: Vec<f64>,
    /// median CPU per run, ms
    pub cpu_ms_p50: f64,
}

/// The record report: the [`Head`](crate::report::Head) and [`RecordResults`].
pub type RecordReport = Report<RecordResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Clone, Serialize)]
pub struct RecordResults {
    /// measured hop rounds
    pub rounds: usize,
    /// the hop with and without the recorder
    pub hop: Vec<HopCost>,
    /// target of the hop ratio
    pub target_ratio: f64,
    /// the image recordings
    pub images: Vec<ImageRun>,
    /// echo of a built-in and a custom type
    pub echo: Vec<EchoCost>,
    /// custom / built-in, median CPU per run
    pub echo_custom_vs_builtin: f64,
    /// wall time, s
    pub seconds: f64,
}

/// User + system CPU seconds of a live process, from `/proc/PID/stat`.
pub(crate) fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // after the command name in parentheses: field 14 and 15 are utime, stime
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / crate::machine::clock_ticks())
}

/// CPU seconds of the children reaped so far (user + system).
fn children_cpu() -> f64 {
    // SAFETY: an all-zero rusage is a valid value (plain integers)
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage writes into the struct we own
    if unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut ru) } != 0 {
        return 0.0;
    }
    let t = |tv: libc::timeval| tv.tv_sec as f64 + tv.tv_usec as f64 / 1e6;
    t(ru.ru_utime) + t(ru.ru_stime)
}

/// The hop with and without `nerve record --all`.
fn hop(opts: &RecordOpts, robot: &Robot) -> Result<Vec<HopCost>> {
    let file = opts.work.join("hop.mcap");
    let mut record = || -> Result<Vec<ChildGuard>> {
        let _ = std::fs::remove_file(&file);
        let mut cmd = robot.nerve();
        cmd.arg("record").arg("--all").arg("-o").arg(&file).arg("-q").stdin(Stdio::null());
        robot.quiet(&mut cmd);
        let g = ChildGuard::spawn("nerve record", cmd)?;
        // it has opened every port well before this
        std::thread::sleep(Duration::from_millis(1500));
        Ok(vec![g])
    };
    let measured = hop_with_and_without(robot, &opts.sizes, opts.rounds, opts.quick, &opts.work, "r", &mut record)?;
    let _ = std::fs::remove_file(&file);
    Ok(measured.into_iter().map(|m| HopCost::of(m, TARGET_RATIO)).collect())
}

/// The figures of `nerve record`'s summary line for `topic`: (count, dropped).
fn summary_figures(out: &str, topic: &str, unit: &str) -> (u64, u64) {
    let Some(line) = out.lines().find(|l| l.split_whitespace().next() == Some(topic)) else { return (0, 0) };
    let words: Vec<&str> = line.split_whitespace().collect();
    let count = words.windows(2).find(|w| w[1].trim_end_matches(',') == unit).and_then(|w| w[0].parse().ok());
    let dropped = words.windows(2).find(|w| w[1] == "dropped").and_then(|w| w[0].parse().ok());
    (count.unwrap_or(0), dropped.unwrap_or(0))
}

/// One camera recorded for `seconds`.
fn image_run(opts: &RecordOpts, robot: &Robot, w: u32, h: u32, fps: f64) -> Result<ImageRun> {
    let name = format!("cam{w}");
    robot.run(&[
        "start",
        "camera",
        "--name",
        &name,
        "--",
        "--source",
        "test-pattern",
        "--width",
        &w.to_string(),
        "--height",
        &h.to_string(),
        "--fps",
        &fps.to_string(),
        "--ring",
        &format!("c{w}"),
    ])?;
    robot.wait_registered(&[&name], Duration::from_secs(20))?;
    std::thread::sleep(Duration::from_secs(1));
    let file = opts.work.join(format!("{name}.mcap"));
    let mut cmd = robot.nerve();
    cmd.args(["record", &format!("{name}/frames"), "-q", "--duration", &opts.image_seconds.to_string(), "-o"])
        .arg(&file)
        .stdin(Stdio::null())
        .stdout(Stdio::piped());
    if !opts.verbose {
        cmd.stderr(Stdio::null());
    }
    let t0 = Instant::now();
    let child = cmd.spawn().context("cannot start nerve record")?;
    let pid = child.id();
    let mut cpu = 0.0;
    let out = {
        let waiter = std::thread::spawn(move || child.wait_with_output());
        while !waiter.is_finished() {
            if let Some(c) = cpu_seconds(pid) {
                cpu = c;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        waiter.join().map_err(|_| anyhow::anyhow!("the recorder's waiter panicked"))??
    };
    let wall = t0.elapsed().as_secs_f64();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    if !out.status.success() {
        bail!("nerve record failed ({}): {text}", out.status);
    }
    let (notices, missed) = summary_figures(&text, &format!("{name}/frames"), "messages");
    let (frames, lost) = summary_figures(&text, &format!("{name}/frames/image"), "frames");
    let file_mb = std::fs::metadata(&file).map(|m| m.len() as f64 / 1e6).unwrap_or(0.0);
    let _ = std::fs::remove_file(&file);
    robot.run(&["stop", &name])?;
    Ok(ImageRun {
        resolution: format!("{w}x{h}"),
        fps,
        seconds: opts.image_seconds,
        notices,
        frames,
        dropped: missed + lost,
        camera_fps: (notices + missed) as f64 / opts.image_seconds,
        mb_per_s: file_mb / opts.image_seconds,
        recorder_cpu_percent: 100.0 * cpu / wall,
        file_mb,
    })
}

/// `nerve echo` CPU on a built-in and a custom type.
fn echo(opts: &RecordOpts, robot: &Robot) -> Result<Vec<EchoCost>> {
    robot.run(&["start", "ticker", "--name", "et", "--period", "20ms"])?;
    robot.run(&["start", "gripper", "--name", "eg"]).context(
        "the custom type's agent is the test crate's nerve-gripper: build it with `cargo build --release -p nerve-tests --bins`",
    )?;
    robot.wait_registered(&["et", "eg"], Duration::from_secs(20))?;
    let samples: u64 = if opts.quick { 20 } else { 100 };
    let mut costs = vec![
        EchoCost { port: "et/tick".into(), type_name: "nerve::Tick".into(), samples, cpu_ms: vec![], cpu_ms_p50: 0.0 },
        EchoCost {
            port: "eg/state".into(),
            type_name: "acme::Gripper".into(),
            samples,
            cpu_ms: vec![],
            cpu_ms_p50: 0.0,
        },
    ];
    for run in 0..opts.echo_runs {
        for i in Rounds::order(&[0, 1], run) {
            let before = children_cpu();
            let out: std::process::Output = robot
                .nerve()
                .args(["echo", &costs[i].port, "--count", &samples.to_string(), "--json", "--timeout", "10"])
                .stdin(Stdio::null())
                .output()
                .context("cannot run nerve echo")?;
            if !out.status.success() {
                bail!("nerve echo {} failed: {}", costs[i].port, String::from_utf8_lossy(&out.stderr));
            }
            let lines = out.stdout.split(|b| *b == b'\n').filter(|l| !l.is_empty()).count() as u64;
            if lines != samples {
                bail!("nerve echo {} printed {lines} samples, not {samples}", costs[i].port);
            }
            costs[i].cpu_ms.push((children_cpu() - before) * 1e3);
        }
    }
    for c in &mut costs {
        c.cpu_ms_p50 = median_f64(&c.cpu_ms);
    }
    robot.run(&["stop", "et"])?;
    robot.run(&["stop", "eg"])?;
    Ok(costs)
}

/// Runs the scenario.
pub fn run(opts: &RecordOpts) -> Result<RecordReport> {
    let started = Instant::now();
    let machine = Machine::probe();
    std::fs::create_dir_all(&opts.work).with_context(|| format!("cannot create {}", opts.work.display()))?;
    let robot = Robot::new("r", opts.verbose)?;
    eprintln!("record: robot {} (hop sizes {:?}, {} rounds)", robot.name, opts.sizes, opts.rounds);
    let router = robot.start_router()?;
    let hop = hop(opts, &robot)?;
    let mut images = Vec::new();
    for (w, h, fps) in [(640u32, 480u32, 30.0), (1920, 1080, 15.0)] {
        eprintln!("record: {w}x{h} at {fps} fps for {} s", opts.image_seconds);
        images.push(image_run(opts, &robot, w, h, fps)?);
    }
    eprintln!("record: echo, {} runs per type", opts.echo_runs);
    let echo = echo(opts, &robot)?;
    drop(router);
    drop(robot);
    let echo_custom_vs_builtin = echo[1].cpu_ms_p50 / echo[0].cpu_ms_p50.max(1e-9);
    Ok(Report::new(
        "record",
        machine,
        RecordResults {
            rounds: opts.rounds,
            hop,
            target_ratio: TARGET_RATIO,
            images,
            echo,
            echo_custom_vs_builtin,
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
}

/// Prints the tables (markdown).
pub fn print_tables(r: &RecordReport) {
    let rows = r.hop.iter().map(HopCost::row);
    print_table("One hop with `nerve record --all` running (round trip, µs)", TARGET_RATIO, rows);
    println!("\n### Images recorded from a camera's ring\n");
    println!("| resolution | fps asked | camera fps | seconds | frames | dropped | MB/s | recorder CPU | file MB |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for i in &r.images {
        println!(
            "| {} | {} | {:.1} | {} | {} | {} | {:.1} | {:.1}% | {:.0} |",
            i.resolution,
            i.fps,
            i.camera_fps,
            i.seconds,
            i.frames,
            i.dropped,
            i.mb_per_s,
            i.recorder_cpu_percent,
            i.file_mb
        );
    }
    println!("\n### `nerve echo --json` of a built-in and a custom type (CPU per run)\n");
    println!("| port | type | samples | CPU p50 (ms) | runs (ms) |");
    println!("|---|---|---|---|---|");
    for e in &r.echo {
        let runs: Vec<String> = e.cpu_ms.iter().map(|c| format!("{c:.1}")).collect();
        println!("| {} | {} | {} | {:.1} | {} |", e.port, e.type_name, e.samples, e.cpu_ms_p50, runs.join(", "));
    }
    println!("\ncustom / built-in: {:.2}", r.echo_custom_vs_builtin);
}

/// Where the scenario's files go.
pub fn work_dir(out: &Path) -> PathBuf {
    out.join(format!("record-work-{}", std::process::id()))
}
