//! Scenario `ui`: what `nerve ui` costs the robot while a browser shows its
//! page (issue 16). The one-hop round trip of SDK agents with `nerve ui`
//! serving a headless Chromium (the page open, its event stream reading the
//! graph every 0.5 s, as a person watching would) and without them, batch
//! by batch interleaved; target: the median with them at most 1.05x the
//! median without.

use crate::machine::Machine;
use crate::observed::{ObservedHop, WithObserver, hop_with_and_without, print_table};
use crate::procs::{ChildGuard, Robot};
use crate::report::Report;
use crate::stats::Summary;
use anyhow::{Context as _, Result, bail};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The page may make the round trip this much slower.
pub const TARGET_RATIO: f64 = 1.05;
const TOKEN: &str = "bench-token-0123456789";

/// Options of the ui scenario.
#[derive(Debug, Clone)]
pub struct UiOpts {
    /// smoke run
    pub quick: bool,
    /// payload sizes of the hop (bytes)
    pub sizes: Vec<usize>,
    /// measured rounds
    pub rounds: usize,
    /// show children's output
    pub verbose: bool,
    /// where batch files and the browser's profile go
    pub work: PathBuf,
}

/// The hop with and without the page, one size.
pub type UiHop = ObservedHop<WithUi>;

/// Round trips while `nerve ui` serves a browser, ns (`with_ui` in the JSON).
#[derive(Debug, Clone, Serialize)]
pub struct WithUi {
    /// round trips while `nerve ui` serves a browser, ns
    pub with_ui: Summary,
}

impl WithObserver for WithUi {
    fn new(with_ui: Summary) -> Self {
        WithUi { with_ui }
    }

    fn summary(&self) -> &Summary {
        &self.with_ui
    }
}

/// The ui report: the [`Head`](crate::report::Head) and [`UiResults`].
pub type UiReport = Report<UiResults>;

/// The results of the scenario, after the report's [`Head`](crate::report::Head).
#[derive(Debug, Clone, Serialize)]
pub struct UiResults {
    /// measured rounds
    pub rounds: usize,
    /// the hop with and without the page
    pub hop: Vec<UiHop>,
    /// the target
    pub target_ratio: f64,
    /// the browser's version
    pub browser: String,
    /// wall time
    pub seconds: f64,
}

fn free_port() -> Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// `nerve ui` and a headless Chromium showing its page.
fn open_page(robot: &Robot, work: &Path) -> Result<Vec<ChildGuard>> {
    let addr = format!("127.0.0.1:{}", free_port()?);
    let mut cmd = robot.nerve();
    cmd.args(["ui", "--bind", &addr]).env("NERVE_UI_TOKEN", TOKEN).stdin(Stdio::null());
    robot.quiet(&mut cmd);
    let ui = ChildGuard::spawn("nerve ui", cmd)?;
    let t0 = Instant::now();
    while std::net::TcpStream::connect(&addr).is_err() {
        if t0.elapsed() > Duration::from_secs(10) {
            bail!("nerve ui did not listen on {addr} within 10 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let profile = work.join("chromium");
    let mut cmd = Command::new("chromium");
    cmd.args(["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1400,900"])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("http://{addr}/?token={TOKEN}"))
        .stdin(Stdio::null());
    robot.quiet(&mut cmd);
    let browser = ChildGuard::spawn("chromium", cmd)
        .context("cannot run chromium: install chromium (scripts/setup.sh --bench does)")?;
    // the page is loaded and its event stream open well before this
    std::thread::sleep(Duration::from_millis(2500));
    Ok(vec![browser, ui])
}

/// Runs the scenario.
pub fn run(opts: &UiOpts) -> Result<UiReport> {
    let started = Instant::now();
    let machine = Machine::probe();
    std::fs::create_dir_all(&opts.work).with_context(|| format!("cannot create {}", opts.work.display()))?;
    let browser = Command::new("chromium")
        .arg("--version")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
        .context("cannot run chromium: install chromium (scripts/setup.sh --bench does)")?;
    let robot = Robot::new("u", opts.verbose)?;
    eprintln!("ui: robot {} (hop sizes {:?}, {} rounds, {browser})", robot.name, opts.sizes, opts.rounds);
    let router = robot.start_router()?;
    let mut observe = || open_page(&robot, &opts.work);
    let measured = hop_with_and_without(&robot, &opts.sizes, opts.rounds, opts.quick, &opts.work, "u", &mut observe)?;
    drop(router);
    drop(robot);
    Ok(Report::new(
        "ui",
        machine,
        UiResults {
            rounds: opts.rounds,
            hop: measured.into_iter().map(|m| UiHop::of(m, TARGET_RATIO)).collect(),
            target_ratio: TARGET_RATIO,
            browser,
            seconds: started.elapsed().as_secs_f64(),
        },
    ))
}

/// Prints the table (markdown).
pub fn print_tables(r: &UiReport) {
    let rows = r.hop.iter().map(UiHop::row);
    let title = format!("One hop while `nerve ui` serves a browser (round trip, µs; {})", r.browser);
    print_table(&title, TARGET_RATIO, rows);
}

/// Where the scenario's files go.
pub fn work_dir(out: &Path) -> PathBuf {
    out.join("ui-work")
}
