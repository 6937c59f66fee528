//! `nerve calibrate checkpoint` (Appendix A) end to end: from a samples
//! file (no simulator), and from a real simulator run — the simulator and
//! the motor agent as processes, frames read from the simulator's ring in
//! shared memory, the robot driven by `nerve cmd` — each ending with a
//! calibration file that the checkpoint agent itself accepts, its figures,
//! and nothing left behind. Each test has its own robot (the harness's
//! `Robot`), brought down and removed even when the test fails.
//!
//! Needs the binaries: `cargo build --workspace --bins`.

use nerve_tests::{Robot, wait_until};
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

/// Appendix A's model: `Z = D·f/d + Σ α_k (d−h)^−(k+1)`.
fn model(df: f64, h: f64, alpha: [f64; 4], d: f64) -> f64 {
    let x = 1.0 / (d - h);
    df / d + alpha.iter().enumerate().map(|(k, a)| a * x.powi(k as i32 + 2)).sum::<f64>()
}

fn text(out: &Output) -> (String, String) {
    (String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// `nerve calibrate checkpoint ARGS` on robot `r`; panics unless it succeeds; returns stdout.
fn calibrate(r: &Robot, args: &[&str]) -> String {
    let out = r.command("nerve").args(["calibrate", "checkpoint"]).args(args).output().expect("run nerve calibrate");
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "`nerve calibrate checkpoint {}` failed:\n{stdout}\n{stderr}", args.join(" "));
    stdout
}

/// The two RMS errors printed: (pinhole, fitted), millimetres.
fn rms_mm(stdout: &str) -> (f64, f64) {
    let line = stdout.lines().find(|l| l.starts_with("RMS error")).unwrap_or_else(|| panic!("no RMS line: {stdout}"));
    let nums: Vec<f64> = line.split_whitespace().filter_map(|w| w.parse::<f64>().ok()).collect();
    match nums.as_slice() {
        [p, f] => (*p, *f),
        _ => panic!("cannot read the RMS line {line:?}"),
    }
}

/// Checks `fit.png` and `fit.svg` in `dir`: a real picture with both colours of points.
fn check_figures(dir: &Path) {
    let file = std::fs::File::open(dir.join("fit.png")).expect("fit.png");
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().expect("png header");
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("png frame");
    assert_eq!((info.width, info.height), (1000, 900));
    let px: Vec<&[u8]> = buf[..info.buffer_size()].chunks_exact(3).collect();
    let near = |p: &[u8], c: [u8; 3]| p.iter().zip(c).all(|(a, b)| a.abs_diff(b) < 40);
    let (pinhole, fitted) =
        (px.iter().filter(|p| near(p, [210, 120, 20])).count(), px.iter().filter(|p| near(p, [30, 90, 200])).count());
    assert!(pinhole > 300 && fitted > 300, "points of both series: {pinhole} orange, {fitted} blue pixels");
    let svg = std::fs::read_to_string(dir.join("fit.svg")).expect("fit.svg");
    assert!(svg.starts_with("<svg") && svg.contains("pinhole term") && svg.contains("fitted model"));
    assert!(svg.matches("<circle").count() > 20, "the svg holds the samples");
}

/// Starts the checkpoint agent with `--calibration FILE` on `r` (router running).
fn start_checkpoint(r: &Robot, name: &str, calibration: &Path) -> Output {
    let path = calibration.to_str().expect("utf-8 path");
    r.nerve(&["start", "checkpoint", "--name", name, "--", "--calibration", path])
}

/// The checkpoint agent started with the calibration takes it: it runs, and
/// does not say it ranges with the pinhole term alone.
fn agent_accepts(r: &Robot, calibration: &Path) {
    let out = start_checkpoint(r, "checkpoint", calibration);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "the checkpoint agent refused {}:\n{stdout}\n{stderr}", calibration.display());
    let log = r.home.join(&r.name).join("logs").join("checkpoint.log");
    assert!(
        wait_until(Duration::from_secs(5), || std::fs::read_to_string(&log).is_ok_and(|l| !l.is_empty())),
        "the checkpoint agent wrote no log"
    );
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(!text.contains("no Appendix A calibration"), "{text}");
}

/// Synthetic samples of a known model, from a TOML samples file: the fit
/// finds it (RMS far below the pinhole's), the calibration is written where
/// `--out` says, `samples.csv` and both figures next to it; the checkpoint
/// agent accepts the calibration and refuses a broken one.
#[test]
fn a_samples_file_gives_a_calibration_the_agent_accepts() {
    let r = Robot::new("calfile");
    let (d_spacing, f) = (0.2, 160.0 / 30f64.to_radians().tan());
    let (h, alpha) = (4.0, [25.0, -180.0, 900.0, -2500.0]);
    let mut toml = format!("band_spacing_m = {d_spacing}\nfocal_px = {f}\n");
    for i in 0..40 {
        let d = 17.0 + 1.3 * f64::from(i);
        toml += &format!("[[sample]]\nd_px = {d}\nz_m = {}\n", model(d_spacing * f, h, alpha, d));
    }
    let samples = nerve_tests::write_file(&r.home, "samples.toml", &toml);
    let dir = r.home.join("out");
    let cal = r.home.join("cal").join("checkpoint.toml");
    let stdout = calibrate(
        &r,
        &[
            "--samples",
            samples.to_str().expect("utf-8"),
            "--dir",
            dir.to_str().expect("utf-8"),
            "--out",
            cal.to_str().expect("utf-8"),
        ],
    );
    assert!(stdout.contains("fitted 40 samples"), "{stdout}");
    let (pinhole, fitted) = rms_mm(&stdout);
    assert!(fitted < 0.1 && pinhole > 5.0, "pinhole {pinhole} mm, fitted {fitted} mm");
    let written = std::fs::read_to_string(&cal).expect("the calibration file");
    let h_fitted: f64 = written
        .lines()
        .find_map(|l| l.strip_prefix("h_px = ")?.parse().ok())
        .unwrap_or_else(|| panic!("no h_px in {written}"));
    assert!((h_fitted - h).abs() < 0.1, "h = {h_fitted} px, the samples' model has {h}");
    let csv = std::fs::read_to_string(dir.join("samples.csv")).expect("samples.csv");
    assert_eq!(csv.lines().filter(|l| !l.starts_with('#') && !l.starts_with("d_px")).count(), 40);
    check_figures(&dir);

    // CSV samples need D and f, and say so
    let csv_path = dir.join("samples.csv");
    let out = r
        .command("nerve")
        .args(["calibrate", "checkpoint", "--samples"])
        .arg(&csv_path)
        .arg("--dir")
        .arg(&dir)
        .output()
        .expect("run");
    assert!(!out.status.success() && text(&out).1.contains("--band-spacing"), "{:?}", text(&out));
    // ... and fit again with them
    let stdout = calibrate(
        &r,
        &[
            "--samples",
            csv_path.to_str().expect("utf-8"),
            "--band-spacing",
            "0.2",
            "--focal",
            &f.to_string(),
            "--dir",
            dir.to_str().expect("utf-8"),
        ],
    );
    assert!(stdout.contains("fitted 40 samples"), "{stdout}");

    // the agent's own loader: it starts with the calibration, and refuses a broken one
    r.router();
    agent_accepts(&r, &cal);
    let broken = nerve_tests::write_file(
        &r.home,
        "broken.toml",
        &written.replace("band_spacing_m = 0.2", "band_spacing_m = -0.2"),
    );
    let out = start_checkpoint(&r, "checkpoint2", &broken);
    assert!(!out.status.success() && text(&out).1.contains("band_spacing_m"), "{:?}", text(&out));
    r.down_and_check_clean();
}

/// The simulator path for real: H1 driven at the tube from 3.5 m to 0.8 m
/// at 0.5 m/s (a few seconds); the samples are many and cover the range,
/// the fit is no worse than the pinhole term, the checkpoint agent accepts
/// the calibration, and the run left no process and no shared memory.
#[test]
fn a_simulator_run_calibrates_h1() {
    let r = Robot::new("calsim");
    let dir: PathBuf = r.home.join("out");
    let stdout = calibrate(&r, &["--dir", dir.to_str().expect("utf-8"), "--speed", "0.5"]);
    // progress lines while driving, then the verdict
    assert!(stdout.lines().filter(|l| l.trim_start().starts_with("t ")).count() >= 3, "{stdout}");
    let n: usize = stdout
        .lines()
        .find_map(|l| l.strip_prefix("fitted ").and_then(|r| r.split_whitespace().next()).and_then(|n| n.parse().ok()))
        .unwrap_or_else(|| panic!("no 'fitted N samples' line: {stdout}"));
    assert!(n >= 50, "{n} samples from a 2.7 m drive at 15 frames per second: {stdout}");
    let (pinhole, fitted) = rms_mm(&stdout);
    assert!(fitted <= pinhole + 1e-9, "the fit ({fitted} mm) is worse than the pinhole term ({pinhole} mm)");
    assert!(pinhole < 60.0, "the simulator's camera is a pinhole: {pinhole} mm");

    // the samples span the range, true distances from the ground truth
    let csv = std::fs::read_to_string(dir.join("samples.csv")).expect("samples.csv");
    let z: Vec<f64> = csv
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("d_px"))
        .filter_map(|l| l.split(',').nth(1)?.parse().ok())
        .collect();
    assert_eq!(z.len(), n);
    let (lo, hi) = z.iter().fold((f64::INFINITY, 0f64), |(l, h), v| (l.min(*v), h.max(*v)));
    assert!(lo < 1.2 && hi > 3.2 && hi <= 3.5 && lo >= 0.8, "samples from {lo} to {hi} m");
    check_figures(&dir);
    for f in ["world.toml", "launch.toml", "logs/sim.log", "logs/motor.log"] {
        assert!(dir.join(f).exists(), "{f} missing from {}", dir.display());
    }

    // nothing of the run is left
    assert!(r.shm_files().is_empty(), "left in /dev/shm: {:?}", r.shm_files());
    let pids = r.home.join(&r.name).join("pids");
    let left: Vec<_> = std::fs::read_dir(&pids).map(|rd| rd.flatten().map(|e| e.path()).collect()).unwrap_or_default();
    assert!(left.is_empty(), "pid files left: {left:?}");

    r.router();
    agent_accepts(&r, &dir.join("calibration.toml"));
    r.down_and_check_clean();
}
