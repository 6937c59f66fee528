//! Scenario `images`: the short-term-memory path with 1, 4 and 8 readers.
//!
//! One writer publishes RGB frames (320x240, 640x480, 1920x1080) to `n`
//! reader processes, each blocked until woken; three transports side by
//! side, interleaved batch by batch (the order rotates every round):
//!
//! * `stm`: nerve's short-term memory, SDK agents in a robot with a router
//!   (`images/stm.rs`): the writer stores each frame in place in a ring
//!   (`RingOutput::write_with`) and announces it with a `RingNotice` on a
//!   port; readers, wired with `nerve connect`, wake on the notice and read
//!   the frame in place (`RingInput::read_notice_with`, seqlock verified);
//! * `iox2-slice`: raw iceoryx2 publish-subscribe of `[u8]` slices, a
//!   WaitSet per reader (`images/iox2.rs`);
//! * `uds`: the writer copies the frame to each reader over a Unix stream
//!   socket (`images/uds.rs`).
//!
//! Every frame is filled and checked the same way for all three
//! (`images/frame.rs`: one 64-byte line per 4 KiB page written by the writer
//! and checked by every reader). Each (resolution, readers) runs twice per
//! round: `paced` (a fixed rate: latency, per-frame cost, frames per second
//! sustained) and `max` (closed loop: the next frame as soon as every reader
//! acknowledged the last one: the most frames per second with every reader
//! reading every frame). The first frames of each batch are dropped, and a
//! whole first (shorter) round is warm-up.

mod frame;
mod iox2;
mod stm;
mod uds;

pub use iox2::reader_main as iox2_reader_main;
pub use stm::run_agent;
pub use uds::reader_main as uds_reader_main;

use crate::machine::Machine;
use crate::procs::{ChildGuard, Robot, normal_priority, realtime_like_an_agent, self_command, wait_file};
use crate::report::Report;
use crate::stats::{Summary, median_f64, ratio, us};
use anyhow::{Context as _, Result, bail};
use frame::{Acks, BatchReq, FramePub, Mode, ReaderRec, Res, WriterBatch};
use serde::Serialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

/// Frames dropped at the start of every batch.
const DISCARD: usize = 5;
/// The transports, in the order of the tables.
pub const TRANSPORTS: [&str; 3] = ["stm", "iox2-slice", "uds"];
/// Issue #4's target: the per-frame cost with 8 readers within this much of 1 reader.
pub const TARGET_RATIO: f64 = 1.5;
/// What every reader reads of a frame (and the writer writes).
const TOUCHED: &str = "the header line and one 64-byte line per 4 KiB page (1/64 of the frame: 57, 225 and 1519 lines), written by the writer into the transport's memory and checked word by word by every reader";

/// Options of the images scenario.
#[derive(Debug, Clone)]
pub struct ImagesOpts {
    /// smoke run
    pub quick: bool,
    /// e.g. `640x480`
    pub resolutions: Vec<String>,
    /// reader counts (1..=8)
    pub readers: Vec<usize>,
    /// measured rounds
    pub rounds: usize,
    /// paced rate, frames per second
    pub rate: f64,
    /// seconds of a paced batch
    pub paced_seconds: f64,
    /// seconds of a closed-loop batch
    pub max_seconds: f64,
    /// show children's output
    pub verbose: bool,
    /// where the processes' files go
    pub work: PathBuf,
}

/// Results of one transport at one resolution, reader count and mode.
#[derive(Debug, Clone, Serialize)]
pub struct ImagesResult {
    /// transport
    pub transport: String,
    /// `paced` or `max`
    pub mode: &'static str,
    /// `640x480`
    pub resolution: String,
    /// bytes per frame
    pub bytes: usize,
    /// readers
    pub readers: usize,
    /// measured batches
    pub batches: usize,
    /// frames written and kept (warm-up frames dropped)
    pub frames: usize,
    /// writer's stamp → a reader has read and checked the frame; all readers' frames pooled
    pub latency: Summary,
    /// writer's stamp → the last of the readers has read the frame (frames every reader read)
    pub latency_last: Summary,
    /// the writer's publishing time per frame (to all readers; frame filling excluded)
    pub publish: Summary,
    /// a reader's time from wake-up to read and checked, per reader and frame
    pub read: Summary,
    /// per frame: publish + the mean over its readers of read
    pub cost: Summary,
    /// per frame every reader read: publish + the sum of the readers' read times (the work of the whole machine)
    pub total: Summary,
    /// frames per second each reader read intact (median over readers, then over batches)
    pub reader_fps: f64,
    /// frames per second the writer published (median over batches)
    pub writer_fps: f64,
    /// lowest fraction of the kept frames a reader read intact, over readers and batches
    pub delivered: f64,
    /// frames announced but not read intact (overwritten, or lines not matching)
    pub bad: u64,
    /// paced: deadlines the writer skipped because a frame took longer than a period
    pub skipped: u64,
    /// closed loop: frames not acknowledged by every reader within 1 s
    pub stalls: u64,
    /// median cost of each round, ns
    pub round_cost_p50_ns: Vec<u64>,
    /// median latency of each round, ns
    pub round_latency_p50_ns: Vec<u64>,
}

/// Issue #4's target: cost with the most readers against the fewest, per transport and resolution (paced).
#[derive(Debug, Clone, Serialize)]
pub struct ScaleRatio {
    /// transport
    pub transport: String,
    /// resolution
    pub resolution: String,
    /// fewest readers (1)
    pub readers_lo: usize,
    /// most readers (8)
    pub readers_hi: usize,
    /// cost p50 (hi) / cost p50 (lo), pooled
    pub cost_p50: f64,
    /// median over rounds of the per-round ratio
    pub cost_p50_round_median: f64,
    /// cost p99 ratio
    pub cost_p99: f64,
    /// total p50 ratio (publish + every reader's read)
    pub total_p50: f64,
    /// publish p50 ratio
    pub publish_p50: f64,
    /// read p50 ratio
    pub read_p50: f64,
    /// latency p50 ratio
    pub latency_p50: f64,
    /// latency to the last reader, p50 ratio
    pub latency_last_p50: f64,
    /// cost_p50 ≤ target
    pub target_met: bool,
}

/// The transports against `stm` at one point.
#[derive(Debug, Clone, Serialize)]
pub struct CompareRow {
    /// resolution
    pub resolution: String,
    /// readers
    pub readers: usize,
    /// paced latency p50, iox2-slice / stm
    pub latency_iox2_vs_stm: f64,
    /// paced latency p50, uds / stm
    pub latency_uds_vs_stm: f64,
    /// paced latency to the last reader p50, uds / stm
    pub latency_last_uds_vs_stm: f64,
    /// paced cost p50, iox2-slice / stm
    pub cost_iox2_vs_stm: f64,
    /// paced cost p50, uds / stm
    pub cost_uds_vs_stm: f64,
    /// closed-loop frames per second per reader: stm, iox2-slice, uds
    pub max_fps: [f64; 3],
}

/// The images report: the [`Head`](crate::report::Head) and [`ImagesResults`].
pub type ImagesReport = Report<ImagesResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Clone, Serialize)]
pub struct ImagesResults {
    /// measured rounds (after one warm-up round, except --quick)
    pub rounds: usize,
    /// paced rate, frames per second
    pub rate_fps: f64,
    /// seconds per paced batch
    pub paced_seconds: f64,
    /// seconds per closed-loop batch
    pub max_seconds: f64,
    /// frames dropped at the start of every batch
    pub discard: usize,
    /// what writer and readers touch of each frame
    pub touched: &'static str,
    /// per transport, mode, resolution and readers
    pub results: Vec<ImagesResult>,
    /// cost with the most readers against the fewest
    pub scaling: Vec<ScaleRatio>,
    /// the transports against stm
    pub compare: Vec<CompareRow>,
    /// target of cost_p50 in `scaling`
    pub target_ratio: f64,
    /// wall time of the run, s
    pub seconds: f64,
}

/// One batch boiled down.
#[derive(Debug, Default)]
struct BatchStats {
    latency: Vec<u64>,
    last: Vec<u64>,
    publish: Vec<u64>,
    read: Vec<u64>,
    cost: Vec<u64>,
    total: Vec<u64>,
    reader_fps: f64,
    writer_fps: f64,
    delivered: f64,
    bad: u64,
    frames: usize,
}

fn per_second(count: usize, first: u64, last: u64) -> f64 {
    if count < 2 || last <= first { 0.0 } else { (count - 1) as f64 * 1e9 / (last - first) as f64 }
}

/// Joins the writer's and the `n` readers' records of one batch, dropping its first `discard` frames.
fn aggregate(w: &WriterBatch, readers: &[Vec<ReaderRec>], discard: usize) -> BatchStats {
    let kept = &w.recs[discard.min(w.recs.len())..];
    let by_seq: HashMap<u64, usize> = kept.iter().enumerate().map(|(i, r)| (r.seq, i)).collect();
    // per kept frame: readers that read it, sum of their read times, latest done
    let mut frames: Vec<(usize, u64, u64)> = vec![(0, 0, 0); kept.len()];
    let mut s =
        BatchStats { frames: kept.len(), delivered: if readers.is_empty() { 0.0 } else { 1.0 }, ..Default::default() };
    let mut fps = Vec::new();
    for r in readers {
        let (mut ok, mut first, mut last) = (0usize, u64::MAX, 0u64);
        for rec in r {
            let Some(&i) = by_seq.get(&rec.seq) else { continue };
            if !rec.ok {
                s.bad += 1;
                continue;
            }
            let read = rec.done.saturating_sub(rec.begin);
            s.latency.push(rec.done.saturating_sub(kept[i].stamp));
            s.read.push(read);
            let f = &mut frames[i];
            *f = (f.0 + 1, f.1 + read, f.2.max(rec.done));
            ok += 1;
            first = first.min(rec.done);
            last = last.max(rec.done);
        }
        fps.push(per_second(ok, first, last));
        s.delivered = s.delivered.min(if kept.is_empty() { 0.0 } else { ok as f64 / kept.len() as f64 });
    }
    for (w, &(count, read_sum, done)) in kept.iter().zip(&frames) {
        s.publish.push(w.publish);
        if count > 0 {
            s.cost.push(w.publish + read_sum / count as u64);
        }
        if count == readers.len() && count > 0 {
            s.last.push(done.saturating_sub(w.stamp));
            s.total.push(w.publish + read_sum);
        }
    }
    s.reader_fps = median_f64(&fps);
    s.writer_fps = match (kept.first(), kept.last()) {
        (Some(a), Some(b)) => per_second(kept.len(), a.stamp, b.stamp),
        _ => 0.0,
    };
    s
}

/// Everything measured of one (transport, resolution, readers, mode).
#[derive(Debug, Default)]
struct Acc {
    latency: Vec<u64>,
    last: Vec<u64>,
    publish: Vec<u64>,
    read: Vec<u64>,
    cost: Vec<u64>,
    total: Vec<u64>,
    reader_fps: Vec<f64>,
    writer_fps: Vec<f64>,
    delivered: Vec<f64>,
    bad: u64,
    skipped: u64,
    stalls: u64,
    frames: usize,
    batches: usize,
    round_cost: Vec<u64>,
    round_latency: Vec<u64>,
}

impl Acc {
    fn add(&mut self, s: BatchStats, w: &WriterBatch) {
        self.round_cost.push(Summary::of(&s.cost).p50_ns);
        self.round_latency.push(Summary::of(&s.latency).p50_ns);
        self.latency.extend(s.latency);
        self.last.extend(s.last);
        self.publish.extend(s.publish);
        self.read.extend(s.read);
        self.cost.extend(s.cost);
        self.total.extend(s.total);
        self.reader_fps.push(s.reader_fps);
        self.writer_fps.push(s.writer_fps);
        self.delivered.push(s.delivered);
        self.bad += s.bad;
        self.skipped += w.skipped;
        self.stalls += w.stalls;
        self.frames += s.frames;
        self.batches += 1;
    }
}

/// Who writes a lane's frames.
enum Writer {
    /// the SDK writer agent, started by `nerve suspend` + `nerve resume`
    Agent { name: String },
    /// a writer in this process
    Local(Box<dyn FramePub>),
}

/// One transport at one resolution: its writer and the directory its readers write to.
struct Lane {
    transport: &'static str,
    res: Res,
    writer: Writer,
    dir: PathBuf,
    seq: u64,
}

fn mkdir(p: &Path) -> Result<()> {
    std::fs::create_dir_all(p).with_context(|| format!("cannot create {}", p.display()))
}

fn stm_writer_name(res: Res) -> String {
    format!("iw-{}", res.key)
}

fn stm_reader_name(res: Res, i: usize) -> String {
    format!("ir-{}-{i}", res.key)
}

/// `nerve ARGS`, tried up to three times: on this shared 2-core machine a
/// control call has been seen failing once in a long run (the router reported
/// as absent while it ran), which should not lose the whole run.
fn nerve_retrying(robot: &Robot, args: &[&str]) -> Result<()> {
    let mut attempt = 1;
    loop {
        match robot.run(args) {
            Ok(_) => return Ok(()),
            Err(e) if attempt < 3 => {
                eprintln!("  warning: {e:#}; trying again");
                std::thread::sleep(Duration::from_millis(500));
                attempt += 1;
            }
            Err(e) => return Err(e),
        }
    }
}

/// Runs one batch of `lane` and returns what its writer and readers recorded.
fn run_lane(lane: &mut Lane, robot: &Robot, req: &BatchReq, acks: &Acks) -> Result<(WriterBatch, Vec<Vec<ReaderRec>>)> {
    let w = match &mut lane.writer {
        Writer::Local(p) => frame::run_batch(p.as_mut(), req, acks, &mut lane.seq)?,
        Writer::Agent { name } => {
            frame::write_atomic(&frame::request_file(&lane.dir), &req.to_line()).context("batch request")?;
            let path = frame::writer_file(&lane.dir, req.batch);
            nerve_retrying(robot, &["suspend", name])?;
            nerve_retrying(robot, &["resume", name])?;
            if !wait_file(&path, Duration::from_secs(30) + Duration::from_secs_f64(req.seconds), &mut [])? {
                bail!(
                    "the ring writer agent {name} wrote no results of batch {}; see its log with --verbose",
                    req.batch
                );
            }
            let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
            let _ = std::fs::remove_file(&path);
            WriterBatch::parse(&text).with_context(|| format!("in {}", path.display()))?
        }
    };
    let mut readers = Vec::with_capacity(req.n);
    for i in 0..req.n {
        let path = frame::reader_file(&lane.dir, i, req.batch);
        if wait_file(&path, Duration::from_secs(5), &mut [])? {
            let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
            let _ = std::fs::remove_file(&path);
            readers.push(frame::parse_reader(&text).with_context(|| format!("in {}", path.display()))?);
        } else {
            eprintln!("  warning: {} reader {i} reported nothing for batch {}", lane.transport, req.batch);
            readers.push(Vec::new());
        }
    }
    Ok((w, readers))
}

/// Runs the images scenario.
pub fn run(opts: &ImagesOpts) -> Result<ImagesReport> {
    let started = Instant::now();
    let machine = Machine::probe();
    let ress = opts.resolutions.iter().map(|s| Res::parse(s)).collect::<Result<Vec<_>>>()?;
    let mut counts = opts.readers.clone();
    counts.sort_unstable();
    counts.dedup();
    if counts.is_empty() || counts.iter().any(|&n| !(1..=iox2::MAX_READERS).contains(&n)) {
        bail!("reader counts must be 1 to {}", iox2::MAX_READERS);
    }
    let maxn = counts.iter().copied().max().unwrap_or(1);
    let counts_arg = counts.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(",");

    // the robot first: dropped last, so `nerve down` runs after every child stopped
    let robot = Robot::new("i", opts.verbose)?;
    eprintln!(
        "images: robot {} ({} x readers {counts:?}, {} rounds{})",
        robot.name,
        ress.iter().map(Res::label).collect::<Vec<_>>().join(", "),
        opts.rounds,
        if opts.quick { "" } else { " + warm-up" }
    );
    let _router = robot.start_router()?;
    let acks_path = robot.home.join("acks");
    Acks::create_file(&acks_path)?;
    let acks = Acks::open(&acks_path)?;
    let acks_arg = acks_path.display().to_string();
    let mut children: Vec<ChildGuard> = Vec::new();

    // the SDK agents of the stm lanes
    let mut names = Vec::new();
    for &res in &ress {
        let dir = opts.work.join(format!("stm-{}", res.key));
        mkdir(&dir)?;
        let dir_arg = dir.display().to_string();
        let mut agents = vec![(stm_writer_name(res), "__agent-img-writer", None)];
        agents.extend((0..maxn).map(|i| (stm_reader_name(res, i), "__agent-img-reader", Some(i))));
        for (name, sub, index) in agents {
            let mut cmd = self_command(sub)?;
            cmd.args(["--robot", &robot.name, "--name", &name]);
            if index.is_none() {
                cmd.arg("--suspended");
            }
            cmd.args(["--", "--res", &res.label(), "--dir", &dir_arg, "--acks", &acks_arg, "--counts", &counts_arg]);
            cmd.args(["--index", &index.unwrap_or(0).to_string()]);
            cmd.env("NERVE_HOME", &robot.home);
            robot.quiet(&mut cmd);
            children.push(ChildGuard::spawn(&format!("agent {name}"), cmd)?);
            names.push(name);
        }
    }

    // the raw iceoryx2 and socket readers
    let mut uds_paths: HashMap<char, Vec<PathBuf>> = HashMap::new();
    let mut pending = Vec::new();
    for &res in &ress {
        for (t, sub) in [("iox2", "__img-iox2-reader"), ("uds", "__img-uds-reader")] {
            let dir = opts.work.join(format!("{t}-{}", res.key));
            mkdir(&dir)?;
            for i in 0..maxn {
                let mut cmd = self_command(sub)?;
                cmd.args(["--res", &res.label(), "--index", &i.to_string(), "--acks", &acks_arg]);
                cmd.arg("--dir").arg(&dir);
                if t == "iox2" {
                    cmd.args(["--robot", &robot.name, "--counts", &counts_arg]).env("NERVE_HOME", &robot.home);
                } else {
                    let path = robot.home.join(format!("uds-{}-{i}.sock", res.key));
                    cmd.arg("--path").arg(&path);
                    uds_paths.entry(res.key).or_default().push(path);
                }
                cmd.stdout(Stdio::piped());
                if !opts.verbose {
                    cmd.stderr(Stdio::null());
                }
                pending.push(ChildGuard::spawn(&format!("{t} reader {} {i}", res.label()), cmd)?);
            }
        }
    }
    for mut c in pending {
        c.await_ready("image reader")?;
        children.push(c);
    }
    let name_refs: Vec<&str> = names.iter().map(String::as_str).collect();
    robot.wait_registered(&name_refs, Duration::from_secs(60))?;
    for &res in &ress {
        for &n in &counts {
            for i in 0..n {
                let from = format!("{}/f{n}", stm_writer_name(res));
                robot.run(&["connect", &from, &format!("{}/in", stm_reader_name(res, i))])?;
            }
        }
    }
    // let the readers' message checkers make the subscriptions
    std::thread::sleep(Duration::from_millis(300));
    eprintln!(
        "images: {} processes running, stm readers connected ({:.1} s)",
        children.len() + 1,
        started.elapsed().as_secs_f64()
    );

    // the lanes; from here on this thread runs like an agent's task
    let mut lanes: Vec<Lane> = Vec::new();
    for &res in &ress {
        lanes.push(Lane {
            transport: "stm",
            res,
            writer: Writer::Agent { name: stm_writer_name(res) },
            dir: opts.work.join(format!("stm-{}", res.key)),
            seq: 0,
        });
        lanes.push(Lane {
            transport: "iox2-slice",
            res,
            writer: Writer::Local(Box::new(iox2::Iox2Writer::open(&robot.name, res, &counts)?)),
            dir: opts.work.join(format!("iox2-{}", res.key)),
            seq: 0,
        });
        let paths = uds_paths.get(&res.key).cloned().unwrap_or_default();
        lanes.push(Lane {
            transport: "uds",
            res,
            writer: Writer::Local(Box::new(uds::UdsWriter::connect(&paths, res)?)),
            dir: opts.work.join(format!("uds-{}", res.key)),
            seq: 0,
        });
    }
    realtime_like_an_agent(20);

    let mut accs: HashMap<(&'static str, char, usize, Mode), Acc> = HashMap::new();
    let mut batch = 0u64;
    let result = (|| -> Result<()> {
        for round in usize::from(opts.quick)..=opts.rounds {
            let t_round = Instant::now();
            let warm = round == 0;
            for &res in &ress {
                let idx: Vec<usize> = (0..lanes.len()).filter(|&i| lanes[i].res == res).collect();
                for (ci, &n) in counts.iter().enumerate() {
                    for mode in [Mode::Paced, Mode::Max] {
                        let seconds = match (mode, warm) {
                            (Mode::Paced, false) => opts.paced_seconds,
                            (Mode::Max, false) => opts.max_seconds,
                            (_, true) => 0.15,
                        };
                        // rotate the order so that no transport always runs first
                        for k in 0..idx.len() {
                            let lane = &mut lanes[idx[(k + round + ci) % idx.len()]];
                            batch += 1;
                            let req = BatchReq { batch, n, mode, rate: opts.rate, seconds };
                            let (w, readers) = run_lane(lane, &robot, &req, &acks).with_context(|| {
                                format!(
                                    "{} at {} with {n} readers ({}), round {round}",
                                    lane.transport,
                                    res.label(),
                                    mode.as_str()
                                )
                            })?;
                            if !warm {
                                // slow lanes (sockets at 1080p) write few frames: keep at least 80 %
                                let s = aggregate(&w, &readers, DISCARD.min(w.recs.len() / 5));
                                accs.entry((lane.transport, res.key, n, mode)).or_default().add(s, &w);
                            }
                        }
                    }
                }
                if !warm {
                    let line: Vec<String> = counts
                        .iter()
                        .flat_map(|&n| TRANSPORTS.iter().map(move |&t| (t, n)))
                        .filter_map(|(t, n)| {
                            let a = accs.get(&(t, res.key, n, Mode::Paced))?;
                            Some(format!("{t}/{n} {:.0}us", a.round_latency.last().copied().unwrap_or(0) as f64 / 1e3))
                        })
                        .collect();
                    eprintln!("  {:>9}: {}", res.label(), line.join(", "));
                }
            }
            let what = if warm { "warm-up".to_owned() } else { format!("round {round}/{}", opts.rounds) };
            eprintln!("images: {what} done in {:.1} s", t_round.elapsed().as_secs_f64());
        }
        Ok(())
    })();
    normal_priority();
    drop(lanes);
    for mut c in children.drain(..) {
        c.stop(Duration::from_secs(2));
    }
    result?;

    let mut results = Vec::new();
    for mode in [Mode::Paced, Mode::Max] {
        for &res in &ress {
            for &n in &counts {
                for t in TRANSPORTS {
                    let Some(a) = accs.get(&(t, res.key, n, mode)) else { continue };
                    results.push(ImagesResult {
                        transport: t.into(),
                        mode: mode.as_str(),
                        resolution: res.label(),
                        bytes: res.bytes(),
                        readers: n,
                        batches: a.batches,
                        frames: a.frames,
                        latency: Summary::of(&a.latency),
                        latency_last: Summary::of(&a.last),
                        publish: Summary::of(&a.publish),
                        read: Summary::of(&a.read),
                        cost: Summary::of(&a.cost),
                        total: Summary::of(&a.total),
                        reader_fps: median_f64(&a.reader_fps),
                        writer_fps: median_f64(&a.writer_fps),
                        delivered: a.delivered.iter().copied().fold(1.0, f64::min),
                        bad: a.bad,
                        skipped: a.skipped,
                        stalls: a.stalls,
                        round_cost_p50_ns: a.round_cost.clone(),
                        round_latency_p50_ns: a.round_latency.clone(),
                    });
                }
            }
        }
    }
    let (scaling, compare) = ratios(&results, &ress, &counts);
    drop(_router);
    drop(robot);
    Ok(Report::new(
        "images",
        machine,
        ImagesResults {
            rounds: opts.rounds,
            rate_fps: opts.rate,
            paced_seconds: opts.paced_seconds,
            max_seconds: opts.max_seconds,
            discard: DISCARD,
            touched: TOUCHED,
            results,
            scaling,
            compare,
            target_ratio: TARGET_RATIO,
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
}

fn ratios(results: &[ImagesResult], ress: &[Res], counts: &[usize]) -> (Vec<ScaleRatio>, Vec<CompareRow>) {
    let find = |t: &str, mode: &str, res: &str, n: usize| {
        results.iter().find(|r| r.transport == t && r.mode == mode && r.resolution == res && r.readers == n)
    };
    let mut scaling = Vec::new();
    let mut compare = Vec::new();
    let (Some(&lo), Some(&hi)) = (counts.first(), counts.last()) else { return (scaling, compare) };
    for res in ress {
        let label = res.label();
        for t in TRANSPORTS {
            if lo == hi {
                break;
            }
            let (Some(a), Some(b)) = (find(t, "paced", &label, lo), find(t, "paced", &label, hi)) else { continue };
            let per_round: Vec<f64> =
                b.round_cost_p50_ns.iter().zip(&a.round_cost_p50_ns).map(|(x, y)| ratio(*x, *y)).collect();
            let r = ratio(b.cost.p50_ns, a.cost.p50_ns);
            scaling.push(ScaleRatio {
                transport: t.into(),
                resolution: label.clone(),
                readers_lo: lo,
                readers_hi: hi,
                cost_p50: r,
                cost_p50_round_median: median_f64(&per_round),
                cost_p99: ratio(b.cost.p99_ns, a.cost.p99_ns),
                total_p50: ratio(b.total.p50_ns, a.total.p50_ns),
                publish_p50: ratio(b.publish.p50_ns, a.publish.p50_ns),
                read_p50: ratio(b.read.p50_ns, a.read.p50_ns),
                latency_p50: ratio(b.latency.p50_ns, a.latency.p50_ns),
                latency_last_p50: ratio(b.latency_last.p50_ns, a.latency_last.p50_ns),
                target_met: r <= TARGET_RATIO,
            });
        }
        for &n in counts {
            let (Some(s), Some(i), Some(u)) = (
                find("stm", "paced", &label, n),
                find("iox2-slice", "paced", &label, n),
                find("uds", "paced", &label, n),
            ) else {
                continue;
            };
            let fps = |t: &str| find(t, "max", &label, n).map(|r| r.reader_fps).unwrap_or(0.0);
            compare.push(CompareRow {
                resolution: label.clone(),
                readers: n,
                latency_iox2_vs_stm: ratio(i.latency.p50_ns, s.latency.p50_ns),
                latency_uds_vs_stm: ratio(u.latency.p50_ns, s.latency.p50_ns),
                latency_last_uds_vs_stm: ratio(u.latency_last.p50_ns, s.latency_last.p50_ns),
                cost_iox2_vs_stm: ratio(i.cost.p50_ns, s.cost.p50_ns),
                cost_uds_vs_stm: ratio(u.cost.p50_ns, s.cost.p50_ns),
                max_fps: [fps("stm"), fps("iox2-slice"), fps("uds")],
            });
        }
    }
    (scaling, compare)
}

/// Prints the tables of an images report (markdown).
pub fn print_tables(r: &ImagesReport) {
    println!(
        "Paced at {} frames/s ({} s per batch): latency, writer's stamp → read and checked (µs)",
        r.rate_fps, r.paced_seconds
    );
    println!();
    println!(
        "| resolution | readers | transport | n | median | p99 | max | last reader median | p99 | max | fps per reader | delivered |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for x in r.results.iter().filter(|x| x.mode == "paced") {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.0} | {:.3} |",
            x.resolution,
            x.readers,
            x.transport,
            x.latency.n,
            us(x.latency.p50_ns),
            us(x.latency.p99_ns),
            us(x.latency.max_ns),
            us(x.latency_last.p50_ns),
            us(x.latency_last.p99_ns),
            us(x.latency_last.max_ns),
            x.reader_fps,
            x.delivered
        );
    }
    println!();
    println!(
        "Per-frame cost, paced (µs): publish = the writer's time to hand one frame to all readers; read = a reader's wake-up → read and checked; cost = publish + mean read of the frame's readers; total = publish + every reader's read"
    );
    println!();
    println!(
        "| resolution | readers | transport | publish median | p99 | read median | p99 | cost median | p99 | max | total median |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for x in r.results.iter().filter(|x| x.mode == "paced") {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            x.resolution,
            x.readers,
            x.transport,
            us(x.publish.p50_ns),
            us(x.publish.p99_ns),
            us(x.read.p50_ns),
            us(x.read.p99_ns),
            us(x.cost.p50_ns),
            us(x.cost.p99_ns),
            us(x.cost.max_ns),
            us(x.total.p50_ns)
        );
    }
    println!();
    println!("Closed loop ({} s per batch): the next frame as soon as every reader has read the last", r.max_seconds);
    println!();
    println!(
        "| resolution | readers | transport | frames/s per reader | latency median µs | p99 | last reader median µs | stalls |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|");
    for x in r.results.iter().filter(|x| x.mode == "max") {
        println!(
            "| {} | {} | {} | {:.0} | {} | {} | {} | {} |",
            x.resolution,
            x.readers,
            x.transport,
            x.reader_fps,
            us(x.latency.p50_ns),
            us(x.latency.p99_ns),
            us(x.latency_last.p50_ns),
            x.stalls
        );
    }
    println!();
    if let Some(s) = r.scaling.first() {
        println!(
            "| resolution | transport | cost {hi}/{lo} p50 | (median of rounds) | p99 | total {hi}/{lo} | publish {hi}/{lo} | read {hi}/{lo} | latency {hi}/{lo} | last reader {hi}/{lo} | target ≤{} |",
            TARGET_RATIO,
            hi = s.readers_hi,
            lo = s.readers_lo
        );
        println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    }
    for s in &r.scaling {
        println!(
            "| {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} |",
            s.resolution,
            s.transport,
            s.cost_p50,
            s.cost_p50_round_median,
            s.cost_p99,
            s.total_p50,
            s.publish_p50,
            s.read_p50,
            s.latency_p50,
            s.latency_last_p50,
            if s.target_met { "met" } else { "missed" }
        );
    }
    println!();
    println!(
        "| resolution | readers | latency iox2-slice/stm | uds/stm | last reader uds/stm | cost iox2-slice/stm | uds/stm | closed-loop fps stm | iox2-slice | uds |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for c in &r.compare {
        println!(
            "| {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.0} | {:.0} | {:.0} |",
            c.resolution,
            c.readers,
            c.latency_iox2_vs_stm,
            c.latency_uds_vs_stm,
            c.latency_last_uds_vs_stm,
            c.cost_iox2_vs_stm,
            c.cost_uds_vs_stm,
            c.max_fps[0],
            c.max_fps[1],
            c.max_fps[2]
        );
    }
    let bad: u64 = r.results.iter().map(|x| x.bad).sum();
    println!();
    println!("frames not read intact: {bad}; touched per frame: {}", r.touched);
}

/// Where the processes' files of a run go.
pub fn work_dir(out: &Path) -> PathBuf {
    out.join(format!("images-work-{}", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use frame::WriterRec;

    fn w(seq: u64, stamp: u64, publish: u64) -> WriterRec {
        WriterRec { seq, stamp, publish }
    }

    fn r(seq: u64, begin: u64, done: u64, ok: bool) -> ReaderRec {
        ReaderRec { seq, begin, done, ok }
    }

    #[test]
    fn aggregate_joins_writer_and_readers() {
        let wb = WriterBatch {
            recs: vec![w(1, 0, 99), w(2, 1000, 10), w(3, 2000, 20), w(4, 3000, 30)],
            skipped: 0,
            stalls: 0,
        };
        // frame 1 is dropped; reader 1 misses frame 4 and reads frame 3 torn
        let readers = vec![
            vec![r(1, 0, 5, true), r(2, 1100, 1150, true), r(3, 2100, 2200, true), r(4, 3100, 3110, true)],
            vec![r(2, 1200, 1300, true), r(3, 2300, 2400, false)],
        ];
        let s = aggregate(&wb, &readers, 1);
        assert_eq!(s.frames, 3);
        assert_eq!(s.bad, 1);
        let mut lat = s.latency.clone();
        lat.sort_unstable();
        assert_eq!(lat, vec![110, 150, 200, 300]);
        // only frame 2 was read by both readers: the last one at 1300
        assert_eq!(s.last, vec![300]);
        assert_eq!(s.publish, vec![10, 20, 30]);
        // frame 2: 10 + (50 + 100) / 2; frame 3: 20 + 100; frame 4: 30 + 10
        assert_eq!(s.cost, vec![85, 120, 40]);
        assert_eq!(s.total, vec![160]);
        assert!((s.delivered - 1.0 / 3.0).abs() < 1e-9);
        // 2 frames in 2000 ns apart for the writer: 3 frames / 2 us
        assert!((s.writer_fps - 1e6).abs() < 1.0);
        let e = aggregate(&wb, &[], 10);
        assert_eq!((e.frames, e.reader_fps, e.delivered), (0, 0.0, 0.0));
    }
}
